"""One submitted motion file checked against its test item: read within bounds by the study reader, then its frame
rate, its length against the item's speech, its valid frames, and whether it is a body (docs/challenge.md).

Every check that can still run after another has failed runs, so a team learns every problem of a file at once; a
file that cannot be read at all (unreadable, too large, not finite) stops there, as nothing else can be judged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from moglow_eval.core import skeleton_names

from ..data import motion_files, seamless_files
from ..data.motion_files import MotionError, header_frames, native_fps, read_motion
from ..data.smpl_files import is_smpl_file
from .layout import Problem

MAX_SPEED = 20.0  # m/s: no joint of a person moves faster (a thrown ball's hand reaches about 15 between frames)
MAX_BONE_CHANGE = 0.10  # a bone of joint positions may stretch or shrink this share of its median length, no more
FORMATS = {"bvh": "BVH", "npy": "joint positions (.npy)", "clip": "clip files (.npz)",
           "smpl": "SMPL-family parameters (.npz)", "seamless": "Seamless Interaction smplh:* (.npz)"}  # fmt: skip
POSITIONS = ("npy", "clip")  # formats of joint positions, whose bones nothing holds rigid


@dataclass(frozen=True)
class Rules:
    """What the challenge asks of every file: the dataset's frame rate, the samples per item, the bounds of a body,
    and how the study reader reads the files (read_motion's units, up, skeleton, source_fps, smpl_model, smpl_type)."""

    fps: float
    samples: int = 1
    max_speed: float = MAX_SPEED
    max_bone_change: float = MAX_BONE_CHANGE
    read: dict = field(default_factory=dict)
    # GENEA 2026's rule: `samples` from a stochastic system, one file per item from a deterministic one. With it, a
    # team whose folder holds no item folder is checked as one sample per item.
    or_one: bool = False

    def samples_of(self, folder, items) -> int:
        """The samples per item a team's folder must hold: with `or_one`, one where no folder is named as an item
        (a stray folder, such as an archive's __MACOSX/, is an entry to remove, not a sign of samples)."""
        try:
            named = any(p.name in items and p.is_dir() and not p.is_symlink() for p in Path(folder).iterdir())
        except OSError:  # a folder that cannot be listed: its report says so (layout.read_submission)
            named = True
        return 1 if self.or_one and not named else self.samples


def file_format(path) -> str:
    """The format of a motion file, a key of FORMATS, from its name and (for .npz) its member names alone."""
    name = str(path)
    if name.endswith((".bvh", ".bvh.gz")):
        return "bvh"
    if name.endswith(".npy"):
        return "npy"
    if seamless_files.is_seamless_file(path):
        return "seamless"
    return "smpl" if is_smpl_file(path) else "clip"


# What a reader's refusal means, by the words of its message, and what the team should do about it.
READ_KINDS = (
    ("NaN or infinite", "finite", "export every frame with finite numbers"),
    ("tall after unit conversion", "height", "give positions in metres with the body upright"),
)


# The study reader's advice names what a study's author sets (its study file, import_motion's flags); on the
# intake's page it says what the intake takes instead, or nothing where the intake's own words follow (READ_KINDS,
# "export it").
STUDY_ADVICE = {
    "; check [skeleton] units": "",
    "; set [skeleton] units in the study file": "",
    " (wrong --scale?)": "",
    "set [skeleton] fps in the study file": "the intake's --source-fps gives it",
    "set [skeleton] file in the study file": "the intake's --skeleton gives it",
}


def _refused(path, e: MotionError, item, sample) -> Problem:
    text = str(e)
    for advice, instead in STUDY_ADVICE.items():
        text = text.replace(advice, instead)
    for words, check, todo in READ_KINDS:
        if words in text:
            return Problem(str(path), item, sample, check, f"{text}: {todo}")
    return Problem(str(path), item, sample, "read", f"{text}: export it again in a format the study reader takes")


def check_file(path, item: str, sample: str, seconds: float | None, rules: Rules, fmt: str) -> list[Problem]:
    """The problems of one motion file: `seconds` the length of its item's speech (None: not known), `fmt` its
    format (file_format, which the caller has read once for the team's one-format check)."""
    out = []

    def add(check, text):
        out.append(Problem(str(path), item, sample, check, text))

    try:
        fps = native_fps(path, rules.read.get("source_fps"))
    except MotionError as e:
        return [_refused(path, e, item, sample)]
    if abs(fps - rules.fps) > 1e-3 * rules.fps:
        add("fps", f"{fps:g} fps, where the dataset is {rules.fps:g} fps: export it at {rules.fps:g} fps")

    def length(n):  # the advice at the dataset's rate, which the fps problem (if any) asks for too
        if seconds is not None and abs(n / fps - seconds) > 1.0 / fps + 1e-9:
            want = round(seconds * rules.fps)
            add("length", f"{n} frames ({n / fps:.2f} s), where the item's speech is {seconds:.2f} s: give {want} "
                f"frames at {rules.fps:g} fps")  # fmt: skip

    # A file far longer than its item (its header says so) is refused for that alone, unread: within the reader's
    # bounds it could still take gigabytes and minutes, for a file that is wrong whatever else it holds.
    declared = header_frames(path)
    if declared is not None and seconds is not None and declared > 2 * seconds * fps + fps:
        length(declared)
        return out
    try:
        m = read_motion(path, fps, **rules.read)
    except MotionError as e:
        return out + [_refused(path, e, item, sample)]
    n = len(m.joints)
    length(n)
    valid = np.ones(n, bool) if m.valid is None else np.asarray(m.valid, bool)
    if not valid.all():
        spans = seamless_files.invalid_spans(valid)
        add("valid", f"{int((~valid).sum())} frames marked invalid (is_valid false: frames "
            f"{seamless_files.spans_text(spans)}): give valid motion in every frame")  # fmt: skip
    _body(m, valid, fmt, rules, add)
    return out


def _body(m, valid, fmt, rules, add) -> None:
    """A body's checks, each problem given to `add`: upright along Y, no joint faster than the bound between two
    valid frames, and (joint positions) no bone stretching beyond its bound."""
    parents = np.asarray(m.parents)
    # A point on the floor or at the scene's origin is no part of the body, and its link to the hips moves as the
    # body does: links from a root marker (`joint_Root`) are left out, and so are those from a first joint not named
    # as the hips or pelvis (`Reference`, `world`), often such a point. A first joint named `Hips` or `pelvis` is the
    # body's, and its bones (to the spine and thighs) are checked.
    floor = set(skeleton_names.root_markers(m.names, parents))
    if len(parents) and not skeleton_names.is_hips(m.names[0]):
        floor.add(0)
    # The reader checks the body's height along Y, which a body lying along Z can pass by its depth (a clip is Y up
    # by contract, and is not turned): taller along Z than along Y, as the reader's up detection decides, it lies.
    moving = m.joints[valid]  # the frames every check of the body reads
    body = moving[:, [j for j in range(len(parents)) if j not in floor]]
    if body.size and motion_files.detect_up(body) == "z":
        extent = motion_files.median_extent(body)
        add("height", f"the body is {extent[2]:.2f} m along Z and {extent[1]:.2f} m along Y, the up axis: export it "
            "with Y up (or give --up z)")  # fmt: skip
    if len(m.joints) >= 2:
        speed = np.linalg.norm(np.diff(m.joints, axis=0), axis=-1) * m.fps  # [T-1, J] m/s
        speed[~(valid[1:] & valid[:-1])] = 0.0
        t, j = np.unravel_index(int(np.argmax(speed)), speed.shape)
        if speed[t, j] > rules.max_speed:
            add("speed", f"{m.names[j]} moves at {speed[t, j]:.1f} m/s between frames {t} and {t + 1} (at most "
                f"{rules.max_speed:g} m/s for a person): look for a jump there, or the wrong units")  # fmt: skip
    if fmt not in POSITIONS:  # rotations keep their bones by construction
        return
    child = np.flatnonzero((parents >= 0) & ~np.isin(parents, list(floor)))
    if len(child):
        length = np.linalg.norm(moving[:, child] - moving[:, parents[child]], axis=-1)
        median = np.median(length, axis=0)
        change = np.max(np.abs(length / np.where(median > 0, median, 1.0) - 1.0), axis=0)
        change[median <= 1e-6] = 0.0  # a bone of no length (a joint on its parent) has no length to keep
        worst = int(np.argmax(change))
        if change[worst] > rules.max_bone_change:
            c = child[worst]
            bound = 100 * rules.max_bone_change
            add("bones", f"the bone {m.names[parents[c]]}-{m.names[c]} changes its length by "
                f"{100 * change[worst]:.0f}% (at most {bound:g}%): keep every bone's length")  # fmt: skip
