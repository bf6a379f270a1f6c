"""A study file's second person, mismatched motion and captions (CONTRACTS §10): the keys of a two-person or
captioned study, and what each design needs of the rest of the file."""

from moglow_eval.core import colours
from rendering.framing import PAIR_ASPECT

from . import designs
from .placing import PLACEMENTS
from .study_keys import err, file, folder, number, unknown

# The designs that need stimuli of their own, and what each needs, are in designs/ (one module each).
STIMULUS_DESIGNS = tuple(designs.DESIGNS)
INTERLOCUTOR_KEYS = {"folder", "placement", "distance", "open", "colour"}
CAPTION_KEYS = {"folder", "interlocutor", "keywords"}


def read_people_keys(path, data, spec):
    """sources, [interlocutor], [mismatched] and [captions]: the second person, the mismatched motion and the
    captions of a two-person or captioned study."""
    if "sources" in data:
        spec.sources = file(path, "sources", data["sources"])
    table = data.get("interlocutor")
    if table is not None:
        if not isinstance(table, dict):
            raise err(path, "[interlocutor]", "must be a table")
        unknown(path, "interlocutor", table, INTERLOCUTOR_KEYS)
        if "folder" not in table:
            raise err(path, "[interlocutor] folder", "missing: the folder of the real interlocutor's ITEM files")
        spec.interlocutor = folder(path, "[interlocutor] folder", table["folder"])
        spec.placement = table.get("placement", "facing")
        if spec.placement not in PLACEMENTS:
            raise err(path, "[interlocutor] placement", f"must be {' or '.join(PLACEMENTS)}, got {spec.placement!r}")
        if "distance" in table:
            spec.distance = number(path, "[interlocutor] distance", table["distance"], 0.3, 10)
        if "open" in table:
            spec.opened = number(path, "[interlocutor] open", table["open"], -60, 60)
        if "colour" in table:
            spec.colour = _colour(path, table["colour"])
    table = data.get("mismatched", {})
    if not isinstance(table, dict):
        raise err(path, "[mismatched]", "must be a table of condition = folder")
    for name, where in table.items():
        if name not in spec.conditions:
            raise err(path, f"[mismatched] {name}", f"not one of [conditions] ({', '.join(spec.conditions)})")
        spec.mismatched[name] = folder(path, f"[mismatched] {name}", where)
    _captions(path, data.get("captions"), spec)


def _colour(path, value):
    try:
        return colours.from_hex(value)
    except ValueError as e:
        raise err(path, "[interlocutor] colour", str(e)) from None


def _captions(path, table, spec):
    if table is None:
        return
    if not isinstance(table, dict):
        raise err(path, "[captions]", "must be a table")
    unknown(path, "captions", table, CAPTION_KEYS)
    if "folder" not in table:
        raise err(path, "[captions] folder", "missing: the folder of the agent's ITEM.json or ITEM.tsv transcripts")
    spec.captions = folder(path, "[captions] folder", table["folder"])
    if "interlocutor" in table:
        spec.interlocutor_captions = folder(path, "[captions] interlocutor", table["interlocutor"])
    if "keywords" in table:
        spec.keywords = file(path, "[captions] keywords", table["keywords"])


def check_needs(path, spec):
    """What each design needs from the rest of the study file; the view's, the framing's and the aspect's defaults
    (two people: upper, 3:1; one person with speech, captions or an SMPL-family body: front and auto, square)."""
    if spec.interlocutor is None and spec.view is None and (spec.audio_folder or spec.captions or spec.smpl_model):
        # A speech or gesture study: the built-in study's walking camera sees a keyword's gesture edge-on. From the
        # front, and from the hips up where the feet stay put (auto: a speaker who walks keeps the full body).
        spec.view = "front"
        spec.framing = spec.framing or "auto"
    if spec.framing is None:
        spec.framing = "upper" if spec.interlocutor is not None else "full"
    if spec.aspect is None:  # two people side by side in a wide frame, as GENEA 2026's visualiser films them
        spec.aspect = PAIR_ASPECT if spec.interlocutor is not None else 1.0
    design = designs.get(spec.design)
    design.check(path, spec)
    if spec.mismatched and not design.mismatched_folders:
        takes = " or ".join(f'"{d.name}"' for d in designs.DESIGNS.values() if d.mismatched_folders)
        raise err(path, "[mismatched]", f"only design = {takes} shows motion made for a mismatched interlocutor")
    if spec.interlocutor_audio is not None and spec.interlocutor is None:
        raise err(path, "[audio] interlocutor", "the interlocutor's voice needs the [interlocutor] table")
