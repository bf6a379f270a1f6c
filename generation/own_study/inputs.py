"""The inputs of a study of your own motion: the condition folders' files, matched by item, read and checked.

Every file is read and checked before anything is written (generation.own_study.builder): items in every
condition, one skeleton per item, no NaN, a person's height, long enough. The study's frame rate is settled first:
the study file's `fps`, or else the reference's own, up to MAX_DEFAULT_FPS. Each problem is one line naming the
file.
"""

import dataclasses
import logging
import math
import random
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from moglow_eval.core import study

from ..data.motion_files import Skeleton, motion_stem, native_fps, read_motion
from ..stimuli.files import StimuliError
from .study_file import MAX_DEFAULT_FPS, check_joint_names

log = logging.getLogger(__name__)
MIN_SECONDS = 1.0  # a clip shorter than this shows nothing a rater can judge
MIN_FPS = 5.0  # the lowest frame rate a study file may set, kept when the reference's own is lower


def seconds_text(seconds):
    """A length to two decimals, rounded down: a clip 0.999 s long is "0.99 s", never the "1.00 s" it falls short
    of."""
    return f"{math.floor(seconds * 100 + 1e-9) / 100:.2f} s"


def with_study_fps(spec, files):
    """The spec with its frame rate settled: the study file's `fps`, else the highest of the reference files' own
    rates (read from their headers), at most MAX_DEFAULT_FPS, so that motion captured at 30 fps stays at 30."""
    if spec.fps is not None:
        return spec
    rates = [native_fps(p, spec.source_fps) for p in files[spec.reference].values()]
    fps = min(max(max(rates), MIN_FPS), MAX_DEFAULT_FPS)
    log.info(f"study: {fps:g} fps, the reference's frame rate (set fps in the study file to change it)")
    return dataclasses.replace(spec, fps=fps)


def read_options(spec):
    """read_motion's keyword arguments for this study's files."""
    skeleton = Skeleton.load(spec.skeleton_file) if spec.skeleton_file else None
    return dict(
        fps=spec.fps,
        units=spec.units,
        up=spec.up,
        skeleton=skeleton,
        source_fps=spec.source_fps,
        smpl_model=spec.smpl_model,
        smpl_type=spec.smpl_type,
        hand_mean=spec.hand_mean,
    )


def folder_files(name, folder):
    """{stem: path} of the motion files in a condition's folder; StimuliError for an empty folder or a stem
    given twice."""
    found = {}
    for p in sorted(Path(folder).iterdir()):
        stem = motion_stem(p)
        if stem is None or not p.is_file():
            continue
        if stem in found:
            raise StimuliError(f"{folder}: two files for item {stem}: {found[stem].name} and {p.name}")
        found[stem] = p
    if not found:
        raise StimuliError(f"{folder}: condition {name} has no motion files (.bvh, .bvh.gz, .npy or .npz)")
    return found


def condition_samples(name, folder):
    """{item: {sample: path}} of a condition that gives several samples per item (a stochastic system): a folder
    per item, ITEM/SAMPLE.EXT, as a challenge's intake takes them (docs/challenge.md); None for a folder of
    ITEM.EXT files. StimuliError for a folder that mixes the two, an item without samples, a sample name that is
    not plain, or items with different numbers of samples (every item is drawn from as many)."""
    folder = Path(folder)
    subs = sorted(p for p in folder.iterdir() if p.is_dir() and not p.is_symlink())
    if not subs:
        return None
    flat = [p for p in folder.iterdir() if p.is_file() and motion_stem(p) is not None]
    if flat:
        raise StimuliError(
            f"{flat[0]}: condition {name} has folders of samples (ITEM/SAMPLE.EXT) and files (ITEM.EXT); give "
            "every item one way"
        )
    out = {}
    for sub in subs:
        found = folder_files(name, sub)
        bad = next((s for s in found if not study.SAMPLE_NAME.fullmatch(s)), None)
        if bad is not None:
            raise StimuliError(f"{found[bad]}: sample name {bad!r} is not letters, digits, _, . or - (at most 64)")
        out[sub.name] = found
    counts = {len(v) for v in out.values()}
    if len(counts) > 1:
        fewest = min(out, key=lambda i: len(out[i]))
        raise StimuliError(
            f"{folder / fewest}: {len(out[fewest])} samples, where other items of condition {name} have "
            f"{max(counts)}; give every item the same number"
        )
    return out


def drawn_sample(seed, condition, item, names):
    """The sample of `item` a condition shows where one is drawn per item: seeded by the study's seed, the
    condition and the item alone, so that adding a condition or an item never changes another's draw."""
    return random.Random(f"{seed}\0{condition}\0{item}").choice(sorted(names))


def match_items(spec):
    """({condition: {item: path}}, {condition: {item: {sample: path}}}): every condition holding exactly the
    reference's items; a condition that gives several samples per item is in the second, and in the first with
    the sample drawn for each item (drawn_sample), which its training, catch and mismatched clips show."""
    files, samples = {}, {}
    for name, folder in spec.conditions.items():
        by_item = condition_samples(name, folder)
        if by_item is None:
            files[name] = folder_files(name, folder)
            continue
        if name == spec.reference:
            raise StimuliError(f"{folder}: the reference {name} is real motion, one file per item (ITEM.EXT)")
        samples[name] = by_item
        files[name] = {i: found[drawn_sample(spec.seed, name, i, found)] for i, found in by_item.items()}
    items = files[spec.reference]
    for name, found in files.items():
        missing = [i for i in items if i not in found]
        if missing:
            raise StimuliError(
                f"{spec.conditions[name]}: no file for item {missing[0]} of the reference "
                f"({items[missing[0]].name}) in condition {name}"
            )
        extra = [i for i in found if i not in items]
        if extra:
            raise StimuliError(
                f"{found[extra[0]]}: item {extra[0]} is not in the reference folder {spec.conditions[spec.reference]}"
            )
    return files, samples


# ---------------------------------------------------------------- reading and checking
def read_all(spec, files, progress):
    """{condition: {item: Motion}}, every file read and checked, skeletons matched across each item."""
    read = read_options(spec)
    jobs = [(name, item, path) for name, found in files.items() for item, path in found.items()]
    motions = {name: {} for name in files}
    with tqdm(jobs, desc="read", unit="file", file=sys.stderr, disable=not progress) as bar:
        for k, (name, item, path) in enumerate(bar):
            m = _read_checked(spec, path, read)
            if k == 0:
                check_joint_names(spec, m.names, path)
            motions[name][item] = m
    ref = motions[spec.reference]
    for by_item in motions.values():
        for item, m in by_item.items():
            check_same_skeleton(m, ref[item])
    return motions


def read_samples(spec, samples, files, ref, progress):
    """{condition: {item: {sample: Motion}}} of every sample that `files` does not already hold (the drawn one),
    for a study that draws a sample per rater and unit: each read and checked as the drawn ones are, against the
    reference's skeleton `ref` ({item: Motion})."""
    read = read_options(spec)
    jobs = [
        (name, item, sample, path)
        for name, by_item in samples.items()
        for item, found in by_item.items()
        for sample, path in found.items()
        if path != files[name][item]
    ]
    out = {name: {item: {} for item in by_item} for name, by_item in samples.items()}
    for name, item, sample, path in tqdm(jobs, desc="samples", unit="file", file=sys.stderr, disable=not progress):
        m = _read_checked(spec, path, read)
        check_same_skeleton(m, ref[item])
        out[name][item][sample] = m
    return out


def _read_checked(spec, path, read):
    m = read_motion(path, **read)
    if m.seconds < MIN_SECONDS:
        raise StimuliError(f"{path}: {seconds_text(m.seconds)} long; a clip needs at least {MIN_SECONDS:g} s")
    if spec.length_s and m.seconds + 0.5 / spec.fps < spec.length_s:
        raise StimuliError(
            f"{path}: {seconds_text(m.seconds)} long, shorter than the study's length_s {spec.length_s:g}"
        )
    return m


def check_valid(m, n):
    """StimuliError naming the file and the frames when the first n frames of a motion that marks frames invalid
    (Seamless Interaction's `is_valid`) hold one: invalid frames never reach a rater."""
    if m.valid is None or m.valid[:n].all():
        return
    from ..data.seamless_files import invalid_spans, spans_text

    spans = invalid_spans(m.valid[:n])
    raise StimuliError(
        f"{m.path}: frames {spans_text(spans)} (at {m.fps:g} fps) are marked invalid (smplh:is_valid) within the "
        f"clip's {n / m.fps:.2f} s; cut the item around them (python -m generation.own_study.conversations)"
    )


def check_same_skeleton(m, ref):
    """StimuliError naming both files and what differs: the joints each has that the other lacks, else the first
    joint whose place (order or parent) differs."""
    if m.names == ref.names and np.array_equal(m.parents, ref.parents):
        return
    in_m, in_ref = set(m.names), set(ref.names)
    only_m = [n for n in m.names if n not in in_ref]
    only_ref = [n for n in ref.names if n not in in_m]
    if only_m or only_ref:
        what = "; ".join(
            f"{_joint_list(names)} only in {'/'.join(Path(where).parts[-2:])}"
            for names, where in ((only_m, m.path), (only_ref, ref.path))
            if names
        )
    else:
        j = next(j for j, (a, b) in enumerate(zip(m.names, ref.names)) if a != b or _parent(m, j) != _parent(ref, j))
        what = (
            f"the same {len(m.names)} joints, but joint {j} is {m.names[j]} (parent {_parent(m, j)}) here and "
            f"{ref.names[j]} (parent {_parent(ref, j)}) there"
        )
    raise StimuliError(f"{m.path}: skeleton differs from {ref.path}: {what}")


def _parent(m, j):
    p = int(m.parents[j])
    return "none" if p < 0 else m.names[p]


def _joint_list(names, most=8):
    shown = ", ".join(names[:most])
    return f"{len(names)} joint{'s' if len(names) > 1 else ''} ({shown}{', ...' if len(names) > most else ''})"
