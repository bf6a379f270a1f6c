"""A study of your own motion: a stimulus folder (CONTRACTS §4) from one folder of motion files per condition.

    python -m generation.make_stimuli --study STUDY.toml --out DIR

The study file (generation.own_study.study_file, CONTRACTS §10) names the conditions' folders and the reference, the
condition that holds the real motion. Items are the reference folder's file stems; every other condition must
hold a file of the same stem (BVH of any skeleton, a .npy joint-position array, or a clip .npz:
generation.data.motion_files). The pipeline:

1. Read and check every file before anything is written: the same skeleton across an item's conditions, no NaN,
   plausible units, long enough. Each problem is one line naming the file (exit 2) and leaves no manifest.
2. Cut each item's clips to the study's length_s, or else to the item's shortest clip; place each clip with its
   root at the origin (and facing +Z, where the joint names tell left from right).
3. Items: n_training familiarisation items taken out of the test items; n catch items drawn from the items (a
   broken clip is its own stimulus, so a catch item may be a test item too). Each catch item gets a catch clip,
   condition BAD: the user's own (`[catch] folder`) or one the tool makes (`[catch] make`,
   generation.stimuli.catch_kinds, the kinds dealt in turn), plus copies of the item's clips in every condition with
   role catch (the pairwise and parallel designs show BAD beside the reference). The reference condition is
   written as NAT, the role it plays in the app and the analysis.
4. Render with one camera per item that frames all its clips (rendering.framing: [render] view, framing), every bone of
   the skeleton drawn, finger and face bones thinner; pad and stamp every video alike.
5. metrics.csv (jerk, acceleration, bone-length variation, foot skating where feet are found), c2st.csv (the
   classifier two-sample test of each condition against the reference, generation.metrics.c2st) and
   c2st_features.csv (which features tell it apart, generation.metrics.c2st_features), items.csv, and
   manifest.csv last.
"""

import json
import logging
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from moglow_eval.core import colours, study
from moglow_eval.core.clip import save_clip
from moglow_eval.core.skeleton_names import body_root, body_skeleton
from moglow_eval.core.tables import C2ST_COLUMNS
from rendering.captions import ROOM as CAPTION_ROOM
from rendering.raster import PARTNER_COLOUR, STYLES
from rendering.render import frame_width, rate_for_set

from ..data.motion_files import read_motion
from ..metrics import c2st
from ..metrics.c2st_features import FEATURE_COLUMNS, feature_table, feature_text
from ..metrics.objective import any_clip_metrics, find_feet
from ..stimuli.build_index import BuildIndex, keyed_id
from ..stimuli.catch_kinds import KINDS as CATCH_KINDS
from ..stimuli.catch_kinds import VISIBLE, make_visible_catch, strays
from ..stimuli.files import (
    StimuliError,
    clip_files,
    manifest_row,
    prepare_out,
    refuse_existing,
    summary_text,
    write_csv,
    write_tables,
)
from ..stimuli.render_pool import render_stimuli
from ..stimuli.summary import blinding_warning
from . import designs
from .designs import mismatch_partners  # noqa: F401  (its home before the designs had theirs; tests import it)
from .dyad import read_people_motion
from .inputs import (
    check_same_skeleton,
    check_valid,
    folder_files,
    match_items,
    read_all,
    read_options,
    read_samples,
    seconds_text,
    with_study_fps,
)
from .measures import study_measures
from .mesh_clips import check_mesh_inputs, clip_reach, file_reach, mesh_spec, partner_mesh_spec, wants_mesh
from .scene import stage
from .speech import item_captions, prepare_audio, read_sources

log = logging.getLogger(__name__)
TEST, CATCH, TRAINING = study.ROLES
ITEM_COLUMNS = ["item", "role", "frames", "fps", "catch"]


def cut_items(motions, spec, extra=()):
    """Every clip of an item cut to length_s, or to the item's shortest clip; `extra` [{item: Motion}] cut alike
    (the interlocutor, the mismatched motion). StimuliError naming a clip that would show an invalid frame."""
    for item in motions[study.NATURAL]:
        clips = [by_item[item] for by_item in [*motions.values(), *extra] if item in by_item]
        n = int(round(spec.length_s * spec.fps)) if spec.length_s else min(len(m.joints) for m in clips)
        for m in clips:
            check_valid(m, n)
            m.joints = m.joints[:n]


# ---------------------------------------------------------------- sound
AUDIO_CHECK_SAMPLES = 6  # spoken digit sequences for the raters' audio check (ITU-T P.808 style)
AUDIO_CHECK_DIGITS = 3
AUDIO_CHECK_COLUMNS = ["file", "answer"]
_DIGIT_WORDS = ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine")


def write_audio_check(out, spec):
    """audio_check.csv and audio_check/*.wav: AUDIO_CHECK_SAMPLES sequences of AUDIO_CHECK_DIGITS spoken digits,
    synthesised with Debian's espeak-ng and normalised to the study's loudness. The app plays one to each rater
    with sound, who types the digits (CONTRACTS §5); the file names are drawn from the study's seed (the same in
    every build, and unpredictable without it), and only the app reads the answers."""
    import shutil
    import subprocess
    import wave

    from rendering import audio

    if shutil.which("espeak-ng") is None:
        raise StimuliError("the raters' audio check is spoken by espeak-ng: install it (apt-get install espeak-ng)")
    rng = np.random.default_rng(spec.seed + 104729)
    folder = Path(out) / "audio_check"
    folder.mkdir(exist_ok=True)
    rows, taken = [], set()
    for _ in range(AUDIO_CHECK_SAMPLES):
        digits = "".join(str(d) for d in rng.integers(0, 10, AUDIO_CHECK_DIGITS))
        words = ", ".join(_DIGIT_WORDS[int(d)] for d in digits)
        raw = subprocess.run(["espeak-ng", "--stdout", "-s", "140", words], capture_output=True, check=True).stdout
        tmp = folder / "tmp.wav"
        tmp.write_bytes(raw)
        samples = audio.normalise(audio.read_audio(tmp), spec.loudness)
        tmp.unlink()
        name = f"{keyed_id(spec.seed, f'audio check {len(rows)}', taken)}.wav"  # one seed, the same names
        with wave.open(str(folder / name), "wb") as w:
            w.setnchannels(samples.shape[1])
            w.setsampwidth(2)
            w.setframerate(audio.RATE)
            w.writeframes((np.clip(samples, -1, 1) * 32767).astype("<i2").tobytes())
        rows.append(dict(file=f"audio_check/{name}", answer=digits))
    write_csv(Path(out) / "audio_check.csv", AUDIO_CHECK_COLUMNS, rows)


# ---------------------------------------------------------------- items and clips
def assign_roles(items, spec, n_catch):
    """({item: role}, catch items in order): n_training items for familiarisation, the rest test items; catch
    items drawn from all items (the user's catch folder's stems, when given)."""
    rng = np.random.default_rng(spec.seed)
    order = [items[i] for i in rng.permutation(len(items))]
    if spec.n_training >= len(items):
        raise StimuliError(f"{spec.path}: n_training {spec.n_training} leaves no test item of {len(items)}")
    roles = {i: (TRAINING if k < spec.n_training else TEST) for k, i in enumerate(order)}
    if n_catch > len(items):
        raise StimuliError(f"{spec.path}: [catch] n {n_catch} is more than the {len(items)} items")
    catch = [i for i in order[spec.n_training :] + order[: spec.n_training]][:n_catch]
    return roles, sorted(catch, key=order.index)


def catch_clips(spec, motions, catch_items, progress):
    """{item: (joints, kind)} of the BAD clip of each catch item: the user's own file, or one the tool makes."""
    ref = motions[study.NATURAL]
    out = {}
    if spec.catch_folder:
        files = folder_files(study.CATCH, spec.catch_folder)
        for item in catch_items:
            m = read_motion(files[item], **read_options(spec))
            check_same_skeleton(m, ref[item])
            n = len(ref[item].joints)
            if len(m.joints) < n:
                raise StimuliError(f"{m.path}: {seconds_text(m.seconds)} long, shorter than the item's other clips")
            out[item] = (m.joints[:n], "own")
            if strays(out[item][0], ref[item].joints, body_root(m.names, m.parents)) < VISIBLE:  # the user's choice
                log.warning(
                    f"{m.path}: catch clip of item {item} strays under {VISIBLE * 100:g} cm from its reference "
                    "clip: raters may take it for the real motion, and be excluded for it"
                )
        return out
    for k, item in enumerate(catch_items):
        m, j = ref[item], k % len(spec.catch_make)
        kinds = spec.catch_make[j:] + spec.catch_make[:j]  # the item's kind in the mix, then the mix's others
        out[item] = make_visible_catch(m.joints, kinds, spec.seed * 1000 + k, body_root(m.names, m.parents))
        if out[item] is None:
            others = " or ".join(kind for kind in CATCH_KINDS if kind not in kinds)  # the kinds the study left out
            raise StimuliError(
                f"{m.path}: catch item {item}: a {' or '.join(kinds)} of it would look like the motion itself (no "
                f"joint strays {VISIBLE * 100:g} cm from it); {f'add {others} to [catch] make, or ' if others else ''}"
                "give the catch clips yourself ([catch] folder)"
            )
        if out[item][1] != kinds[0]:
            log.info(
                f"catch item {item}: made a {out[item][1]}, as a {kinds[0]} of it would look like the motion itself"
            )
    return out


def _catch_items(spec, items):
    """The catch items: the stems of the user's catch folder that are items (all of them), else [catch] n."""
    if not spec.catch_folder:
        return spec.catch_n, None
    files = folder_files(study.CATCH, spec.catch_folder)
    unknown = [s for s in files if s not in items]
    if unknown:
        raise StimuliError(
            f"{files[unknown[0]]}: catch clip of item {unknown[0]}, which is not in the reference folder"
        )
    return len(files), sorted(files)


@dataclass
class StudyClip:
    condition: str
    item: str  # the item it stands for (whose sound it carries)
    role: str
    joints: np.ndarray
    note: str = ""  # the manifest's seed column: the catch kind of a BAD clip
    motion_item: str = ""  # appropriateness: the other item whose motion a mismatched clip shows
    start: int = 0  # the motion's frame the clip starts at (a catch copy's: 1)
    path: str = ""  # the file its motion came from, where no condition's folder of its item holds it (dyadic)
    sample: str = ""  # a stochastic system's sample it shows (manifest `sample`, CONTRACTS §10)


def build_clips(spec, motions, roles, catch_items, bad, people=None, samples=None):
    """Every clip: each item in every condition with its role; per catch item its BAD clip and copies of its clips
    in every condition with role catch; and the design's mismatched clips (designs/: appropriateness and semantic,
    each condition's motion for a partner item with this item's sound; dyadic, the motion it made for a mismatched
    interlocutor, from `people`, shown with this item's). A catch copy starts one frame
    later (its last frame held), so that no two videos of the set are the same bytes (a repeated content hash
    would point at the catch trial).

    `samples` (Samples): a stochastic system's clips name the sample they show; where the app draws one per rater
    and unit, every other sample of a test item is a test clip too."""
    clips = []
    for item, role in roles.items():
        for name, by_item in motions.items():
            clips.append(StudyClip(name, item, role, by_item[item].joints))
    clips += [StudyClip(**c) for c in designs.get(spec.design).mismatched_clips(spec, motions, roles, people)]
    for item in catch_items:
        for name, by_item in motions.items():
            joints = by_item[item].joints
            clips.append(StudyClip(name, item, CATCH, np.concatenate([joints[1:], joints[-1:]]), start=1))
        clips.append(StudyClip(study.CATCH, item, CATCH, bad[item][0], bad[item][1]))
    if samples is None:
        return clips
    for c in clips:
        if c.condition in samples.drawn and not c.path:
            c.sample = samples.drawn[c.condition][c.motion_item or c.item]
    for name, by_item in samples.more.items():
        for item, by_sample in by_item.items():
            if roles[item] == TEST:
                clips += [
                    StudyClip(name, item, TEST, m.joints, path=str(m.path), sample=s) for s, m in by_sample.items()
                ]
    return clips


@dataclass
class Samples:
    """A study's stochastic systems: the sample drawn per item ({condition: {item: sample}}, what its training,
    catch and mismatched clips show, and all it shows with `[samples] draw = "item"`), and with draw = "rater"
    every other sample ({condition: {item: {sample: Motion}}})."""

    drawn: dict
    more: dict

    def extra(self):
        """Every other sample as [{item: Motion}], to be cut with its item (cut_items)."""
        return [{item: m} for by_item in self.more.values() for item, ms in by_item.items() for m in ms.values()]


def read_study_samples(spec, files, samples, motions, progress):
    """The study's Samples, or None where no condition gives several samples per item."""
    if not samples:
        return None
    drawn = {
        name: {item: next(s for s, p in found.items() if p == files[name][item]) for item, found in by_item.items()}
        for name, by_item in samples.items()
    }
    more = read_samples(spec, samples, files, motions[spec.reference], progress) if spec.sample_draw == "rater" else {}
    return Samples(drawn, more)


def clip_identity(c, style):
    """What a clip is, as its id is drawn from it (build_index.keyed_id): the same clip of the same study has the
    same id in every build, and a condition that joins changes no other clip's."""
    return "\0".join(map(str, (c.condition, c.item, c.role, style, c.sample, c.motion_item, c.note, c.start)))


def skeleton_of(motions):
    """(joint names, parents) of the study's motion (the reference's; every condition's is checked to match)."""
    any_ref = next(iter(motions[study.NATURAL].values()))
    return any_ref.names, any_ref.parents


def render_settings(spec):
    """The render settings every clip of the study shares (generation.stimuli.render_pool: RenderOptions' fields)."""
    options = dict(hide=tuple(spec.hide), thin=None if spec.thin == "auto" else tuple(spec.thin))
    # One rate for the whole set, whatever each clip's style: a set with a mesh body takes the mesh's higher rate in
    # every video, so that an item's videos stay one size. Named in the job (and so in its key) only where it is not
    # the default, so that a set without a mesh has the jobs it had.
    rate = rate_for_set([STYLES[s] for s in spec.styles])
    if rate is not None:
        options["bits_per_row"] = rate
    return options


def write_study_clips(out, clips, motions, spec, size, preset, progress, sound=None, scene=None, captions=None):
    """Clip files (random order and ids), manifest and metrics rows (with, per row, the index of its clip in `clips`),
    render jobs, and C2ST features; the clips placed and each item's camera (and other person) in `scene`
    (generation.own_study.scene.stage)."""
    rng = np.random.default_rng(spec.seed)
    names, parents = skeleton_of(motions)
    body, _, body_parents = body_skeleton(names, parents)  # the C2ST's features: the body without its root markers
    feet = find_feet(names) if spec.feet == "auto" else [names.index(n) for n in spec.feet]
    if feet is not None and len(feet) == 2:  # one joint per foot: it is both the foot's ankle and its toe
        feet = [feet[0], feet[0], feet[1], feet[1]]
    taken, manifest, metrics_rows, jobs, groups, feats, row_clips = set(), [], [], [], [], {}, []
    forbidden = [*study.RESERVED, *spec.conditions]
    options = render_settings(spec)
    # Every clip in every style: each styled clip is a stimulus of its own, with its own random id.
    styled = [(c, style) for c in clips for style in spec.styles]
    sampled = any(c.sample for c in clips)  # a stochastic system's: every row names its sample, if any
    for k in tqdm(rng.permutation(len(styled)), desc="clips", unit="clip", file=sys.stderr, disable=not progress):
        c, style = styled[k] if len(spec.styles) > 1 else (clips[k], spec.styles[0])
        row_clips.append(k // len(spec.styles))
        cond, item, role, joints = c.condition, c.item, c.role, c.joints
        cid = keyed_id(spec.seed, clip_identity(c, style), taken, forbidden)  # one seed, the same ids
        motion, video, sheet = clip_files(out, cid)
        save_clip(motion, joints, parents, names, spec.fps)
        job = dict(**scene.job(item, style), **options)
        if captions:
            job["captions"] = captions[item]  # the same phrases in every clip of the item
        if STYLES[style].body == "mesh":
            job["mesh"] = mesh_spec(c, joints, motions, spec)
            if item in scene.partners:
                job["partner_mesh"] = partner_mesh_spec(scene, item, spec)
        if sound:
            # Every clip of an item carries the same sound bytes, a catch copy (one frame late) too: an audio track
            # of its own would tell a catch copy from the item's test clip.
            job["audio"] = (str(sound[item]), 0.0, len(joints) / spec.fps)
        jobs.append((str(motion), str(video), str(sheet), size, preset, job))
        groups.append(item)  # an item's videos share a length and a sound, so they must be one size
        row = manifest_row(cid, cond, dict(id=item, role=role), c.note, len(joints), spec.fps, size)
        row["width"] = frame_width(size, scene.aspect)
        if spec.design:
            row["motion_item"] = c.motion_item
        if sound:
            row["audio"] = "1"
        if spec.styles != ["stick"]:
            row["style"] = style
        if sampled:
            row["sample"] = c.sample
        manifest.append(row)
        m = any_clip_metrics(joints, spec.fps, names, parents, feet)
        metrics_rows.append(dict(clip_id=cid, condition=cond, role=role, item=item, **m))
        if c.motion_item or style != spec.styles[0] or (c.sample and c.path):
            continue  # the figures are of each condition's own motion, once (its drawn sample's)
        c2st.collect(feats, cond, role, item, joints[:, body], spec.fps, body_parents)
    return manifest, (metrics_rows, row_clips), jobs, groups, feats


# ---------------------------------------------------------------- the job
def build_study(spec, out, size, preset, workers, force, progress, scheduler=None):
    """Build the stimulus folder of a study of your own motion, as `python -m generation.make_stimuli --study` does.

    Every file is read and checked before anything is written; then the clips are cut, the catch clips made,
    every clip rendered, and metrics.csv, c2st.csv, items.csv and manifest.csv (last) written to `out`. The
    summary (objective metrics and the two-sample tests) is printed to stdout.

    Parameters
    ----------
    spec : StudySpec
        The study, as from `read_study_file`.
    out : str or Path
        The stimulus folder to write.
    size : int
        Video height in pixels (even); the width by `[render] aspect` (rendering.render.frame_width).
    preset : str
        The x264 speed preset (make_stimuli's default is ultrafast).
    workers : int
        Rendering processes.
    force : bool
        Replace a stimulus set already in `out`.
    progress : bool
        Show progress bars on stderr.
    scheduler : str or None
        A Dask scheduler's address: the clips are rendered on its workers (render_pool.render_all), which see the
        same files at the same paths; the build's own temporary files are then written inside `out`.

    Returns
    -------
    int
        0, the exit status of the command.

    Raises
    ------
    StimuliError
        One line naming the folder or file: no matching files, a stem given twice, clips too short, an
        existing set without `force`, and the like.
    MotionError
        A motion file that cannot be read or is implausible.
    StudyFileError
        A joint named in the study file's [skeleton] table that the motion does not have.
    RenderError
        A sound file that cannot be read or muxed, or a render that fails.
    """
    t0 = time.perf_counter()
    refuse_existing(out, force)  # before any motion is read
    files, sampled = match_items(spec)
    spec = with_study_fps(spec, files)
    n_catch, own_catch = _catch_items(spec, files[spec.reference])
    motions = read_all(spec, files, progress)
    samples = read_study_samples(spec, files, sampled, motions, progress)
    motions = {(study.NATURAL if n == spec.reference else n): m for n, m in motions.items()}
    sources = read_sources(spec, set(motions[study.NATURAL]))
    people = read_people_motion(spec, motions[study.NATURAL], progress, sources[1])
    cut_items(motions, spec, [*people.extra(), *(samples.extra() if samples else [])])
    if wants_mesh(spec):
        more = [*people.extra(), *(samples.extra() if samples else [])]
        check_mesh_inputs(spec, {**motions, **dict(enumerate(more))})  # before anything is written
    items = sorted(motions[study.NATURAL])
    roles, catch_items = assign_roles(items, spec, n_catch)
    if own_catch is not None:
        catch_items = own_catch
    bad = catch_clips(spec, motions, catch_items, progress)
    if spec.reference != study.NATURAL:
        log.info(f"study: the reference condition {spec.reference} is written as {study.NATURAL} in the manifest")
    # A cluster's workers read the sound and the other person from these files: inside `out`, which they share.
    here = None if scheduler is None else Path(out).absolute()
    if here is not None:
        here.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=here, prefix=".build-") as tmp:
        # Everything is placed, framed, heard and captioned before anything is written.
        clips = build_clips(spec, motions, roles, catch_items, bad, people, samples)
        lengths = {i: len(m.joints) for i, m in motions[study.NATURAL].items()}
        captions = item_captions(spec, lengths, size)
        room = CAPTION_ROOM if captions else 0.0
        # With the mesh style each camera frames the meshes' surfaces: their fingertips and the tops of their heads.
        reach = None
        if wants_mesh(spec):
            reach = (lambda c: clip_reach(c, motions, spec)), (lambda m: file_reach(m.path, spec))
        scene = stage(clips, skeleton_of(motions), spec, people.partners, Path(tmp), room, reach)
        sound = prepare_audio(spec, lengths, Path(tmp), scene.sides)
        out = prepare_out(out, force, keep_videos=True)
        manifest, (metrics_rows, row_clips), jobs, groups, feats = write_study_clips(
            out, clips, motions, spec, size, preset, progress, sound, scene, captions
        )
        render_stimuli(jobs, workers, progress, groups, index=BuildIndex(out), scheduler=scheduler)
        if sound:
            write_audio_check(out, spec)
    c2st_table = c2st.c2st_table(feats), feature_table(feats, *body_skeleton(*skeleton_of(motions))[1:])
    write_csv(out / "c2st.csv", C2ST_COLUMNS, c2st_table[0])
    write_csv(out / "c2st_features.csv", FEATURE_COLUMNS, c2st_table[1])
    write_csv(
        out / "items.csv",
        ITEM_COLUMNS,
        [
            dict(
                item=i,
                role=roles[i],
                frames=len(motions[study.NATURAL][i].joints),
                fps=f"{spec.fps:g}",
                catch=bad[i][1] if i in bad else "",
            )
            for i in items
        ],
    )
    if sources[0]:
        write_csv(out / "sources.csv", sources[0], sources[1])  # where each item came from (CONTRACTS §10)
    # The reference's own name for the app's export and the report (CONTRACTS §4); the manifest calls it NAT. A
    # two-person study adds the interlocutor's colour as the renderer draws it, which the rater's page names.
    names = {study.REFERENCE_NAME: spec.reference}
    if spec.interlocutor is not None:
        names[study.INTERLOCUTOR_COLOUR] = colours.to_hex(spec.colour or PARTNER_COLOUR)
    (out / study.STUDY_NAMES_FILE).write_text(json.dumps(names) + "\n")
    extra, gesture_text = study_measures(spec, clips, row_clips, metrics_rows, skeleton_of(motions), lengths, out)
    write_tables(out, manifest, metrics_rows, [], extra)  # manifest.csv last: a folder without one is no stimulus set
    print_study_summary(out, manifest, metrics_rows, c2st_table, time.perf_counter() - t0, gesture_text)
    warning = blinding_warning(out, manifest)
    if warning:
        log.warning(warning)
    return 0


def print_study_summary(out, manifest, metrics_rows, c2st_table, seconds, gesture_text=None):
    n = {r: sum(m["role"] == r for m in manifest) for r in study.ROLES}
    print(
        "\nobjective metrics, mean (sd) per condition: foot_skating m/s, bone_length_std m, jerk m/s^3, "
        f"acceleration m/s^2\n{summary_text(metrics_rows)}"
    )
    if gesture_text:
        print("\n" + gesture_text)
    print("\n" + c2st.c2st_text(c2st_table[0]) + "\n" + feature_text(c2st_table[1]))
    print(
        f"\nwrote {Path(out) / 'manifest.csv'}: {len(manifest)} clips ({n['test']} test, {n['catch']} catch, "
        f"{n['training']} training) in {seconds:.0f} s"
    )
