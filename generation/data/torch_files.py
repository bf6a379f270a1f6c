"""Reading torch files a user can name (checkpoints, OUT/resume.pt, a motion encoder) without running their code.

`torch.load` unpickles: a file that pickles a Python object can make the reader call any function while it loads
(a `__reduce__` that deletes files, say). So every such file is read with `weights_only=True`, which admits only
tensors and plain data (dicts, lists, tuples, strings, numbers, None); our writers save nothing else. A file that
holds anything more is refused with one line, and nothing in it runs.

torch is imported inside the function: sampling.pretrained imports this module, and make_stimuli imports that
one, whose `--help` and render workers stay torch-free (docs/ARCHITECTURE.md).
"""

import re

from moglow_eval.core.cli import UserError


def load_torch_file(path, map_location="cpu", error=UserError, allow=()):
    """The contents of the torch file at `path`, tensors on `map_location`; `error` (a UserError subclass), one
    line naming the file, when it is missing, unreadable or holds more than tensors and plain data. `allow`:
    globals (or (global, its pickled name) pairs) to admit beside those, for an older format whose
    reconstruction is known to run no code of the file's choosing."""
    import torch  # here: make_stimuli imports this module (through sampling.pretrained) and stays torch-free

    try:
        with torch.serialization.safe_globals(list(allow)):
            return torch.load(path, map_location=map_location, weights_only=True)
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except Exception as e:  # a foreign or truncated file fails in many ways inside torch; each is one line
        text = str(e)
        # torch's weights-only message is several lines of advice to load the file unsafely: one line, without it.
        found = re.search(r"Unsupported global: GLOBAL (\S+)|Can only build .* but got <class '([^']+)'>", text)
        if found:
            raise error(
                f"{path}: holds Python objects beyond tensors and plain data ({found[1] or found[2]}); refused "
                "without loading them (re-export it with this version's tools)"
            ) from None
        detail = text.split("WeightsUnpickler error:")[-1].strip().splitlines()
        raise error(f"{path}: not a readable torch file ({type(e).__name__}: {(detail or [''])[0]})") from None
