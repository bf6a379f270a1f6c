"""Training configs: one frozen dataclass per model kind, its model's fields (models.fl.FLConfig,
models.moglow.MGConfig) and the training fields every kind shares (TrainConfig).

The configs themselves stay plain JSON in generation/configs/ (nanoGPT-style: data, not code), and a run's
config.json and every checkpoint hold the config as a plain dict (`as_dict`), so shipped checkpoints load with
torch's weights-only reader. Reading one checks every field against its dataclass field: known, of the field's
type, within the bounds in its metadata ("min", "max", "choices"); then the fields that depend on each other.
Anything wrong is one line naming the file and the field.
"""

import math
import types
import typing
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from moglow_eval.core import user_files
from moglow_eval.core.cli import UserError

from ..models import flows
from ..models.fl import FLConfig
from ..models.moglow import MGConfig

CONFIG_DIR = Path(__file__).resolve().parents[1] / "configs"
CONFIG_BYTES = 1 << 20  # a config is a few dozen fields
_ZERO_UP, _ONE_UP = {"min": 0}, {"min": 1}


class TrainError(UserError):
    """Bad training input (config, model name, diverged run); one-line message."""


@dataclass(frozen=True)
class TrainConfig:
    """The optimiser, its schedule, the crop, the training noise, the stance-foot loss and its posture terms, the
    category balance and the arithmetic: what docs/models.md "Configs" describes, field by field."""

    model: str = ""  # 'fl' or 'mg': the kind's class sets it
    name: str | None = None
    note: str | None = None  # what the config is for, one line; why its values: docs/models.md
    comments: dict[str, str] | None = None  # one short comment per value, for the reader of the JSON file
    batch_size: int = field(default=32, metadata=_ONE_UP)
    lr: float = field(default=1e-3, metadata=_ZERO_UP)
    lr_min: float | None = field(default=None, metadata=_ZERO_UP)
    warmup: int = field(default=200, metadata=_ONE_UP)
    clip_grad: float = field(default=5.0, metadata=_ZERO_UP)
    steps: int = field(default=10000, metadata=_ONE_UP)
    valid_every: int = field(default=500, metadata=_ONE_UP)
    valid_windows: int = field(default=256, metadata=_ONE_UP)
    ckpt_every: int = field(default=2000, metadata=_ONE_UP)
    early_ckpts: tuple[int, ...] = (50, 100, 200, 500)
    train_window: int | None = field(default=None, metadata=_ONE_UP)
    noise: float = field(default=0.01, metadata=_ZERO_UP)
    history_noise: float = field(default=0.0, metadata=_ZERO_UP)  # MG only: noise on the history alone
    restart_step: int | None = None
    restart_lr: float | None = field(default=None, metadata=_ZERO_UP)
    restart_lr_min: float | None = field(default=None, metadata=_ZERO_UP)
    stance_weight: float = field(default=0.0, metadata=_ZERO_UP)
    stance_start: int = field(default=0, metadata=_ZERO_UP)
    stance_temperature: float = field(default=0.0, metadata=_ZERO_UP)
    # stance.posture_offset and stance.posture_spread, added to the stance loss (m^2 per joint, times the weight)
    posture_weight: float = field(default=0.0, metadata=_ZERO_UP)
    spread_weight: float = field(default=0.0, metadata=_ZERO_UP)
    posture_by_category: bool = False  # posture_offset matched within each locomotion category of the batch
    # stance.stance_height, added to the stance loss (m, times the weight): the planted feet at the real feet's height
    foot_height_weight: float = field(default=0.0, metadata=_ZERO_UP)
    category_balance: float = field(default=0.0, metadata=_ZERO_UP)
    # 'bfloat16': the coupling networks run under autocast (flows.set_net_precision); faster than float32 on some
    # CPU kinds and slower on others (bench/RESULTS.md#train-speed); not yet measured on a GPU.
    precision: str = field(default="float32", metadata={"choices": sorted(flows.PRECISIONS)})


@dataclass(frozen=True)
class FLTraining(FLConfig, TrainConfig):
    model: str = "fl"


@dataclass(frozen=True)
class MGTraining(MGConfig, TrainConfig):
    model: str = "mg"


KINDS = {"fl": FLTraining, "mg": MGTraining}
MODEL_FIELDS = {"fl": FLConfig, "mg": MGConfig}


def load_config(model, config):
    """`config`: a config, a dict of fields, 'tiny'/'cpu'/'paper' (meaning configs/{model}_{name}.json) or a JSON
    file path -> the kind's frozen config, every field checked."""
    if model not in KINDS:
        raise TrainError(f"--model must be one of {sorted(KINDS)}, got '{model}'")
    if isinstance(config, TrainConfig):
        config = as_dict(config)
    if isinstance(config, dict):
        return checked(model, config, "config")
    path = Path(config)
    if not path.suffix and not path.exists():
        path = CONFIG_DIR / f"{model}_{config}.json"
    if not path.is_file():
        raise TrainError(f"config '{config}' not found (tried {path})")
    values = user_files.read_json(path, CONFIG_BYTES, TrainError, "config file")
    if not isinstance(values, dict):
        raise TrainError(f"{path}: expected a JSON object of fields")
    return checked(model, values, str(path))


def checked(model, values, where):
    """The `model` kind's config from a dict of fields (the rest at their defaults); TrainError, one line naming
    `where` and the field, for an unknown field, a value of the wrong type or out of bounds, or fields that
    disagree."""
    if values.get("model", model) != model:
        raise TrainError(f"{where}: field 'model' is '{values['model']}' but --model is '{model}'")
    kind = KINDS[model]
    hints = typing.get_type_hints(kind)
    known = {f.name: f for f in fields(kind)}
    out = {}
    for key, value in values.items():
        if key not in known:
            raise TrainError(f"{where}: unknown field '{key}'")
        if key == "comments":
            out[key] = _comments(where, value, known)
            continue
        out[key] = _field_value(where, key, value, hints[key], known[key].metadata)
    return _agreeing(kind(**{**out, "model": model}), where)


def with_changes(cfg, where, **changes):
    """`cfg` with some fields changed (a flag's override), checked as a config file's fields are."""
    return checked(cfg.model, {**as_dict(cfg), **changes}, where)


def as_dict(cfg):
    """The config as plain data (lists, not tuples): what config.json and every checkpoint hold."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(cfg).items()}


def model_config(cfg):
    """The model's own fields of a training config: the dict the model is built from and its checkpoint holds."""
    return {f.name: getattr(cfg, f.name) for f in fields(MODEL_FIELDS[cfg.model])}


_WORDS = {bool: "true or false", int: "a whole number", float: "a number", str: "a string"}


def _field_value(where, key, value, hint, meta):
    """`value` as the field `key` of type `hint` holds it (a whole float as an int), once it is of that type and
    within the bounds in `meta`."""
    kinds = typing.get_args(hint) if isinstance(hint, types.UnionType) else (hint,)
    if value is None and type(None) in kinds:
        return None
    base = next(k for k in kinds if k is not type(None))
    if typing.get_origin(base) is tuple:
        if not isinstance(value, (list, tuple)) or not all(_is_whole(v) for v in value):
            raise TrainError(f"{where}: field '{key}' must be a list of whole numbers, got {value!r}")
        return tuple(int(v) for v in value)
    if not _of_kind(value, base):
        raise TrainError(f"{where}: field '{key}' must be {_WORDS[base]}, got {value!r}")
    if "choices" in meta and value not in meta["choices"]:
        raise TrainError(f"{where}: field '{key}' must be one of {meta['choices']}, got {value!r}")
    if "min" in meta and value < meta["min"]:
        raise TrainError(f"{where}: field '{key}' must be at least {meta['min']}, got {value!r}")
    if "max" in meta and value > meta["max"]:
        raise TrainError(f"{where}: field '{key}' must be at most {meta['max']}, got {value!r}")
    return int(value) if base is int else value


COMMENT_LIMIT = 100  # characters: a comment says what a value is; why it is so goes into docs/models.md


def _comments(where, value, known):
    """The config's comments {field: text}, once every key is a field and every text a short string."""
    if value is None:
        return None
    if not isinstance(value, dict) or not all(isinstance(v, str) for v in value.values()):
        raise TrainError(f"{where}: field 'comments' must map field names to short strings")
    for key, text in value.items():
        if key not in known:
            raise TrainError(f"{where}: field 'comments' names an unknown field '{key}'")
        if len(text) > COMMENT_LIMIT:
            raise TrainError(
                f"{where}: field 'comments': the comment on '{key}' is over {COMMENT_LIMIT} characters "
                "(say why in docs/models.md)"
            )
    return dict(value)


def _of_kind(value, base):
    if base is bool or base is str:
        return isinstance(value, base)
    if base is int:
        return _is_whole(value)
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _is_whole(value):
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    return number and math.isfinite(value) and value == int(value)


def _agreeing(cfg, where):
    """`cfg` itself, once the fields that depend on each other agree: the restart and the MG options."""
    if cfg.restart_step is not None:
        if not 0 < cfg.restart_step < cfg.steps:
            raise TrainError(f"{where}: field 'restart_step' must lie between 0 and 'steps' ({cfg.steps})")
        for key in ("restart_lr", "restart_lr_min"):
            if getattr(cfg, key) is None:
                raise TrainError(f"{where}: field 'restart_step' needs '{key}' too")
    if getattr(cfg, "carry_feet", False) and not cfg.residual:
        raise TrainError(f"{where}: field 'carry_feet' needs 'residual' true")
    if getattr(cfg, "style_span", 0) and not cfg.history_style:
        raise TrainError(f"{where}: field 'style_span' needs 'history_style' true")
    return cfg


def shortened(cfg, steps):
    """`cfg` run for `steps` steps (--steps): a run too short for its warm restart skips it and decays over one
    cosine phase to `steps`, as before the restart existed."""
    restart = cfg.restart_step if cfg.restart_step is not None and cfg.restart_step < steps else None
    return replace(cfg, steps=int(steps), restart_step=restart)
