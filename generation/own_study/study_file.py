"""The study file of a study of your own motion (CONTRACTS §10): TOML, read with the standard library.

    reference = "NAT"            # the condition that holds the real motion
    length_s = 8                 # optional: keep the first length_s seconds of every clip
    fps = 30                     # optional: the study's frame rate (else the reference's, up to 60)
    seed = 1
    n_training = 3               # familiarisation items, taken out of the test items
    design = "appropriateness"   # optional: also make each system's mismatched clips (GENEA 2023's design)
    [conditions]                 # name = folder; files matched by stem across folders
    NAT = "real"
    SYS_A = "system_a"
    [catch]
    make = ["jitter", "freeze", "swap"]  # broken versions of reference clips made by the tool ...
    n = 4                        # ... on this many items
    # folder = "bad"             # ... or the user's own bad clips
    [skeleton]                   # optional
    file = "skeleton.json"       # names + parents, for .npy inputs
    units = "auto"               # "m", "cm", "mm", "auto" or metres per unit
    up = "auto"                  # "y", "z" or "auto"
    hide = []                    # joint names not drawn
    [audio]                      # optional: one ITEM.wav or ITEM.flac per item, in every condition's video
    folder = "audio"
    loudness = -23               # LUFS (EBU R128), the whole set normalised to it
    thin = "auto"                # finger and face joints drawn thinner ("auto"), or a list of names, or []
    feet = "auto"                # foot joints for foot skating: "auto" (from names) or a list of names
    fps = 30                     # the frame rate of .npy arrays (BVH and .npz files carry their own)
    smpl_model = "models/SMPLX_NEUTRAL.npz"  # the body model for SMPL-family .npz files (poses, trans, betas)
    smpl_type = "smplx"          # optional: smpl, smplh or smplx (else told from the model's joints)
    hand_mean = "auto"           # add the model's mean hand pose: true, false, or as the layout does (BEAT2 adds it)
    [render]                     # optional
    view = "front"               # "front", "three-quarter", "side" or degrees from the body's mean facing
    framing = "upper"            # "full" (the default), "upper" (hips up) or "auto" (upper when the feet stay)
    style = ["stick", "mesh"]    # "stick" (the default), "solid", "mesh" (SMPL-family files), or a list of them
    face = "mask"                # the mesh's face: a plain mask over it (the default), or "none"
    aspect = "3:1"               # the frame's width to height: "W:H" or a number (default 3:1 for two people, else 1:1)
    [metrics]                    # optional
    gesture = "auto"             # the gesture measures: "auto" (with speech, an SMPL-family or speech-gesture skeleton)

Two people and captions (generation.own_study.dyad, speech; CONTRACTS §10):

    design = "dyadic"            # or "semantic"
    sources = "items/sources.csv"  # optional: where each item came from (the cutter's table), kept beside the set
    [interlocutor]               # the real other person of every item, in every condition's video
    folder = "items/interlocutor"
    placement = "facing"         # or "recorded"
    distance = 1.4               # metres between the two (facing)
    open = 25                    # degrees each is turned from the other towards the camera (facing)
    colour = "#669970"           # the interlocutor's one colour
    [mismatched]                 # dyadic: each condition's motion made for a mismatched interlocutor
    SYS_A = "system_a_mismatched"
    [audio]
    interlocutor = "items/interlocutor_audio"  # the other person's voice, mixed in
    channels = "mono"            # or "stereo": each voice on its person's side
    [captions]
    folder = "items/agent_transcript"          # the agent's words (ITEM.json, Seamless's layout, or ITEM.tsv)
    interlocutor = "items/interlocutor_transcript"
    keywords = "items/sources.csv"             # item, keyword[, keyword_start, keyword_end]: highlighted

Relative paths are relative to the file. Command-line flags override the top-level keys. Every problem is one
StudyFileError naming the file and key.
"""

from dataclasses import dataclass, field
from pathlib import Path

from moglow_eval.core import study, user_files

from ..data.motion_files import UNITS, UPS
from ..data.smpl_files import TYPES as SMPL_TYPES
from ..stimuli.catch_kinds import KINDS as CATCH_KINDS
from .study_keys import StudyFileError, err, folder, names, number, unknown
from .study_people import STIMULUS_DESIGNS, check_needs, read_people_keys

TOP_KEYS = {
    "reference",
    "length_s",
    "seed",
    "n_training",
    "fps",
    "design",
    "conditions",
    "catch",
    "skeleton",
    "audio",
    "render",
    "sources",
    "interlocutor",
    "mismatched",
    "captions",
    "samples",
    "metrics",
}
SAMPLE_DRAWS = ("item", "rater")  # a stochastic system's samples: one per item, or one per rater and unit (the app)
RENDER_KEYS = {"view", "framing", "style", "face", "aspect"}
FACES = ("mask", "none")  # the mesh style's face: a plain mask over it (GENEA 2026), or the mesh's own
AUDIO_KEYS = {"folder", "loudness", "interlocutor", "channels"}
CATCH_KEYS = {"make", "n", "folder"}
SKELETON_KEYS = {"file", "units", "up", "hide", "thin", "feet", "fps", "smpl_model", "smpl_type", "hand_mean"}
MAX_LENGTH_S = 600.0
MAX_BYTES = 1 << 20  # a study file is a few dozen keys
MAX_DEFAULT_FPS = 60.0  # without `fps`, clips keep the reference's frame rate, up to this (a video's usual most)


@dataclass
class StudySpec:
    path: Path
    reference: str
    conditions: dict  # name -> folder (Path), the reference first
    seed: int = 0
    n_training: int = 1
    length_s: float | None = None
    fps: float | None = None  # None: the reference's frame rate, up to MAX_DEFAULT_FPS (inputs.study_fps)
    catch_make: list = field(default_factory=lambda: ["jitter", "freeze", "swap"])
    catch_n: int = 4
    catch_folder: Path | None = None
    skeleton_file: Path | None = None
    units: object = "auto"
    up: str = "auto"
    hide: list = field(default_factory=list)
    thin: object = "auto"
    feet: object = "auto"
    source_fps: float | None = None
    smpl_model: Path | None = None
    smpl_type: str | None = None
    hand_mean: bool | str = "auto"  # the hands' rest pose: smpl_files.HAND_MEAN_LAYOUTS
    design: str | None = None
    audio_folder: Path | None = None
    loudness: float = -23.0
    view: object = None  # None: the built-in study's fixed camera; else a key of rendering.framing.VIEWS or degrees
    framing: str | None = None  # None: "full" for one person, "upper" for two (study_people.check_needs)
    aspect: float | None = None  # the frame's width / height; None: 3 for two people, 1 for one (check_needs)
    styles: list = field(default_factory=lambda: ["stick"])
    face: str = "mask"
    sources: Path | None = None  # the table of where each item came from
    interlocutor: Path | None = None  # the real other person's folder: a two-person study
    placement: str = "facing"
    distance: float = 1.4
    opened: float = 25.0
    colour: tuple | None = None  # None: rendering.raster.PARTNER_COLOUR
    mismatched: dict = field(default_factory=dict)  # condition -> folder of its motion for a mismatched interlocutor
    interlocutor_audio: Path | None = None
    stereo: bool = False
    captions: Path | None = None  # the agent's transcripts
    interlocutor_captions: Path | None = None
    keywords: Path | None = None
    sample_draw: str = "item"  # a condition with several samples per item (ITEM/SAMPLE.EXT): SAMPLE_DRAWS
    gesture: bool | str = "auto"  # [metrics] gesture: the gesture measures, or "auto" (measures.gesture_study)


def read_study_file(path):
    """Read and check a study file (TOML, CONTRACTS §10).

    Parameters
    ----------
    path : str or Path
        The study file.

    Returns
    -------
    StudySpec
        The study: its reference condition and the conditions' folders (the reference first), and the seed,
        n_training, length_s, fps, design, catch, skeleton and audio settings, the defaults where the file
        gives none.

    Raises
    ------
    StudyFileError
        One line naming the file and the key: an unreadable file, invalid TOML, an unknown key, a reference
        that is not one of the conditions, a condition named NAT that is not the reference, a value out of
        range, or a design that needs a table the file lacks.
    """
    path = Path(path)
    data = user_files.read_toml(path, MAX_BYTES, StudyFileError, "study file")
    unknown(path, "", data, TOP_KEYS)
    conditions = _conditions(path, data.get("conditions"))
    reference = data.get("reference")
    if reference not in conditions:
        raise err(path, "reference", f"{reference!r} is not one of [conditions] ({', '.join(conditions)})")
    if study.NATURAL in conditions and reference != study.NATURAL:
        raise err(
            path,
            f"[conditions] {study.NATURAL}",
            f"{study.NATURAL} is the reference's name in the stimuli; rename this condition or make it the reference",
        )
    spec = StudySpec(path, reference, {reference: conditions.pop(reference), **conditions})
    if "seed" in data:
        spec.seed = number(path, "seed", data["seed"], 0, 2**31 - 1, int)
    if "n_training" in data:
        spec.n_training = number(path, "n_training", data["n_training"], 0, 10_000, int)
    if "length_s" in data:
        spec.length_s = number(path, "length_s", data["length_s"], 0.5, MAX_LENGTH_S)
    if "fps" in data:
        spec.fps = number(path, "fps", data["fps"], 5, 120)
    if "design" in data:
        if data["design"] not in STIMULUS_DESIGNS:
            raise err(
                path,
                "design",
                f"must be {', '.join(STIMULUS_DESIGNS)} (other designs need no stimuli of "
                f"their own), got {data['design']!r}",
            )
        spec.design = data["design"]
    _catch(path, data.get("catch", {}), spec)
    _skeleton(path, data.get("skeleton", {}), spec)
    _audio(path, data.get("audio"), spec)
    _render(path, data.get("render", {}), spec)
    _samples(path, data.get("samples", {}), spec)
    _metrics(path, data.get("metrics", {}), spec)
    read_people_keys(path, data, spec)
    check_needs(path, spec)
    return spec


def _conditions(path, table):
    if not isinstance(table, dict) or not table:
        raise err(path, "[conditions]", 'must name at least two conditions, as NAME = "folder"')
    if len(table) < 2:
        raise err(path, "[conditions]", "a study compares at least two conditions: the reference and a system")
    out = {}
    for name, where in table.items():
        if not study.CONDITION_NAME.fullmatch(name):
            raise err(path, f"[conditions] {name}", "a name is a letter, then letters, digits, _ or - (at most 32)")
        if name.upper() == study.CATCH:
            raise err(path, f"[conditions] {name}", f"{study.CATCH} is the name of the catch clips")
        out[name] = folder(path, f"[conditions] {name}", where)
    return out


def _catch(path, table, spec):
    if not isinstance(table, dict):
        raise err(path, "[catch]", "must be a table")
    unknown(path, "catch", table, CATCH_KEYS)
    if "folder" in table and "make" in table:
        raise err(path, "[catch] folder", "give either folder (your own bad clips) or make, not both")
    if "folder" in table:
        spec.catch_folder, spec.catch_make = folder(path, "[catch] folder", table["folder"]), []
    if "make" in table:
        make = table["make"]
        if not isinstance(make, list) or not make or not all(k in CATCH_KINDS for k in make):
            raise err(path, "[catch] make", f"must be a list of {', '.join(CATCH_KINDS)}, got {make!r}")
        spec.catch_make = list(dict.fromkeys(make))
    if "n" in table:
        spec.catch_n = number(path, "[catch] n", table["n"], 0, 10_000, int)


def _skeleton(path, table, spec):
    if not isinstance(table, dict):
        raise err(path, "[skeleton]", "must be a table")
    unknown(path, "skeleton", table, SKELETON_KEYS)
    if "file" in table:
        f = table["file"]
        if not isinstance(f, str) or not (path.parent / f).is_file():
            raise err(path, "[skeleton] file", f"file {path.parent / str(f)} not found")
        spec.skeleton_file = path.parent / f
    units = table.get("units", "auto")
    if isinstance(units, (int, float)) and not isinstance(units, bool):
        spec.units = number(path, "[skeleton] units", units, 1e-6, 1e3)
    elif units in ("auto", *UNITS):
        spec.units = units
    else:
        raise err(path, "[skeleton] units", f"must be auto, {', '.join(UNITS)} or metres per unit, got {units!r}")
    up = table.get("up", "auto")
    if up not in ("auto", *UPS):
        raise err(path, "[skeleton] up", f"must be auto, {' or '.join(UPS)}, got {up!r}")
    spec.up = up
    spec.hide = names(path, "[skeleton] hide", table.get("hide", []))
    for key in ("thin", "feet"):
        value = table.get(key, "auto")
        setattr(spec, key, value if value == "auto" else names(path, f"[skeleton] {key}", value))
    if spec.feet != "auto" and len(spec.feet) not in (2, 4):
        raise err(
            path,
            "[skeleton] feet",
            "name 2 joints (left foot, right foot) or 4 (left ankle, left toe, "
            f"right ankle, right toe), got {len(spec.feet)}",
        )
    if "fps" in table:
        spec.source_fps = number(path, "[skeleton] fps", table["fps"], 1, 1000)
    _smpl(path, table, spec)


def _smpl(path, table, spec):
    """[skeleton] smpl_model and smpl_type: the user's body model for SMPL-family parameter files."""
    if "smpl_model" in table:
        f = table["smpl_model"]
        if not isinstance(f, str) or not (path.parent / f).is_file():
            raise err(path, "[skeleton] smpl_model", f"file {path.parent / str(f)} not found")
        spec.smpl_model = path.parent / f
    if "smpl_type" in table:
        if table["smpl_type"] not in SMPL_TYPES:
            raise err(path, "[skeleton] smpl_type", f"must be {', '.join(SMPL_TYPES)}, got {table['smpl_type']!r}")
        spec.smpl_type = table["smpl_type"]
    hand_mean = table.get("hand_mean", "auto")
    if hand_mean != "auto" and not isinstance(hand_mean, bool):
        raise err(path, "[skeleton] hand_mean", f'must be true, false or "auto", got {hand_mean!r}')
    spec.hand_mean = hand_mean


def _audio(path, table, spec):
    if table is None:
        return
    if not isinstance(table, dict):
        raise err(path, "[audio]", "must be a table")
    unknown(path, "audio", table, AUDIO_KEYS)
    if "folder" not in table:
        raise err(path, "[audio] folder", "missing: the folder of ITEM.wav / ITEM.flac files")
    spec.audio_folder = folder(path, "[audio] folder", table["folder"])
    if "loudness" in table:
        spec.loudness = number(path, "[audio] loudness", table["loudness"], -70, -5)
    if "interlocutor" in table:
        spec.interlocutor_audio = folder(path, "[audio] interlocutor", table["interlocutor"])
    channels = table.get("channels", "mono")
    if channels not in ("mono", "stereo"):
        raise err(path, "[audio] channels", f"must be mono or stereo, got {channels!r}")
    spec.stereo = channels == "stereo"


def _render(path, table, spec):
    """[render] view, framing, style and aspect: how the videos film and draw the body (rendering.framing, raster)."""
    from rendering.framing import FRAMINGS, VIEWS
    from rendering.raster import STYLES

    if not isinstance(table, dict):
        raise err(path, "[render]", "must be a table")
    unknown(path, "render", table, RENDER_KEYS)
    view = table.get("view")
    if isinstance(view, (int, float)) and not isinstance(view, bool):
        spec.view = number(path, "[render] view", view, -360, 360)
    elif view is None or view in VIEWS:
        spec.view = view
    else:
        raise err(path, "[render] view", f"must be {', '.join(VIEWS)} or an azimuth in degrees, got {view!r}")
    framing = table.get("framing")
    if framing is not None and framing not in FRAMINGS:
        raise err(path, "[render] framing", f"must be {', '.join(FRAMINGS)}, got {framing!r}")
    spec.framing = framing
    style = table.get("style", "stick")
    styles = [style] if isinstance(style, str) else style
    if not isinstance(styles, list) or not styles or not all(s in STYLES for s in styles):
        raise err(path, "[render] style", f"must be {' or '.join(STYLES)}, or a list of them, got {style!r}")
    spec.styles = list(dict.fromkeys(styles))
    face = table.get("face", "mask")
    if face not in FACES:
        raise err(path, "[render] face", f"must be {' or '.join(FACES)}, got {face!r}")
    spec.face = face
    if "aspect" in table:
        spec.aspect = _aspect(path, table["aspect"])


def _aspect(path, value):
    """[render] aspect: "W:H" (as "3:1" or "16:9") or a number, the frame's width over its height."""
    from rendering.render import MAX_ASPECT, MIN_ASPECT

    ratio = None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        ratio = float(value)
    elif isinstance(value, str) and value.count(":") == 1:
        try:
            w, h = (float(x) for x in value.split(":"))
            ratio = w / h if h > 0 and w > 0 else None
        except ValueError:
            ratio = None
    if ratio is None or not MIN_ASPECT <= ratio <= MAX_ASPECT:
        raise err(
            path,
            "[render] aspect",
            f'must be "W:H" (as "3:1") or a number, the width over the height, from {MIN_ASPECT:g} to '
            f"{MAX_ASPECT:g}, got {value!r}",
        )
    return ratio


def _samples(path, table, spec):
    """[samples] draw: how a condition that gives several samples per item (a stochastic system) is shown."""
    if not isinstance(table, dict):
        raise err(path, "[samples]", "must be a table")
    unknown(path, "samples", table, {"draw"})
    draw = table.get("draw", "item")
    if draw not in SAMPLE_DRAWS:
        raise err(path, "[samples] draw", f"must be {' or '.join(map(repr, SAMPLE_DRAWS))}, got {draw!r}")
    spec.sample_draw = draw


def _metrics(path, table, spec):
    """[metrics] gesture: whether metrics.csv gets the gesture measures (generation.own_study.measures)."""
    if not isinstance(table, dict):
        raise err(path, "[metrics]", "must be a table")
    unknown(path, "metrics", table, {"gesture"})
    gesture = table.get("gesture", "auto")
    if gesture != "auto" and not isinstance(gesture, bool):
        raise err(path, "[metrics] gesture", f'must be true, false or "auto", got {gesture!r}')
    spec.gesture = gesture


def check_joint_names(spec, names, where):
    """StudyFileError when a joint name in the study file (hide, thin, feet) is not one of the skeleton's."""
    known = set(names)
    for key in ("hide", "thin", "feet"):
        value = getattr(spec, key)
        for name in [] if value == "auto" else value:
            if name not in known:
                raise err(spec.path, f"[skeleton] {key}", f"unknown joint name {name!r} (not in {where})")
