"""The main job: data -> models -> stimulus folder for the rating test (CONTRACTS.md §4).

    python -m generation.make_stimuli [--out stimuli/] [--quick] [--mg-checkpoint CKPT --fl-checkpoint CKPT]
                                      [--system NAME=DIR ...] [--export-items DIR]

1. Data: the held-out windows shipped in generation/pretrained/ (heldout.npz); with --retrain (or --quick,
   --data, --dataset) ../shared/data/bandai-namco-locomotion prepared into a cached dataset (runs/dataset.npz).
2. Items: held-out 4-s test windows, balanced over locomotion categories (round robin, distinct takes
   first), seeded: `--n-items` test items, `--n-catch` catch items and `--n-training` familiarisation
   items (from other windows).
3. Models: MG and FL checkpoints as given, else the shipped ones (generation/pretrained/: MG, FL and the early
   MG checkpoint that makes the BAD clips), else (--retrain, --quick, --config, --precision) trained (configs
   `cpu`, `tiny` with --quick) into runs/ (an existing run there is resumed or reused); BAD clips then come from
   the earliest MG checkpoint.
4. Clips: per test item NAT (the real window through features.to_world, the same inverse the models'
   output goes through), MG (seeded with the item's real preceding frames) and FL with the same control;
   every imported system's file for the item; BAD, NAT, MG and FL clips on the catch items (NAT is the
   reference of the pairwise and parallel catch trials, MG and FL fill a parallel catch page to a test page's
   size; an acr study shows only BAD); each training item in every condition
   except BAD. Every clip is placed to start at the origin facing +Z.
5. Videos (in parallel, one process per core), contact sheets, metrics.csv, fmd.csv, c2st.csv and
   c2st_features.csv (the classifier two-sample test, and what tells each condition apart), manifest.csv, items.csv.
"""

import argparse
import logging
import os
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from moglow_eval.core import cli, study
from moglow_eval.core.clip import save_clip
from moglow_eval.core.tables import C2ST_COLUMNS
from rendering.mesh import set_gl_environment
from rendering.render import size_flag

from .data.dataset import read_heldout
from .data.systems import canonical_placement, find_system_files, load_system_motion, parse_system_spec
from .metrics import c2st
from .metrics.c2st_features import FEATURE_COLUMNS, feature_table
from .metrics.objective import clip_metrics
from .motion import invariants, skeleton
from .motion.features import to_features, to_world
from .sampling import pretrained
from .stimuli.catch_kinds import KINDS as TOOL_CATCH_KINDS
from .stimuli.catch_kinds import make_catch
from .stimuli.checkpoints import ensure_dataset, ensure_model, sampler_precision
from .stimuli.files import (
    StimuliError,
    clip_files,
    manifest_row,
    nothing_left_on_failure,
    prepare_out,
    refuse_existing,
    write_csv,
    write_items,
    write_tables,
)
from .stimuli.items import CATCH, TEST, TRAINING, category_counts, item_arrays, positions, select_items
from .stimuli.render_pool import render_stimuli
from .stimuli.summary import condition_fmd, print_summary

# torch is never imported at module level here (training, sampling and the motion encoder import it inside the
# functions that run them): --help, --export-items and the checks of imported systems need no models, and
# tests/generation/test_stimuli.py keeps `import generation.make_stimuli` torch-free.

log = logging.getLogger(__name__)
MG, FL = study.GENERATED
MG_EARLY = "mg-early"  # the paper's catch clips: samples of the earliest MG checkpoint (--bad-checkpoint)
# Sampling seeds are offsets of --seed, one per sampled condition, so each condition's noise is its own.
SEED_OFFSET = {MG: 1, FL: 2, study.CATCH: 3}


def sample_condition(kind, ckpt, arrays, idx, temperature, seed, device, precision="float32"):
    """Features x [B, T, 63] sampled by the `kind` model in `ckpt` for the items at `idx` (MG's sampler in
    `precision`)."""
    from .sampling.sample import load_model, require_finite, sample_windows

    model = load_model(ckpt, device=device)
    if model.kind != kind:
        raise StimuliError(f"{ckpt}: an {model.kind.upper()} checkpoint where {kind.upper()} is needed")
    c, hist, hist_c = arrays["c"][idx], arrays["hist"][idx], arrays["hist_c"][idx]
    x = sample_windows(model, c, hist, hist_c, temperature, seed, precision)
    x = np.asarray(x, dtype=np.float32)
    if x.shape != arrays["x"][idx].shape:
        raise StimuliError(f"{ckpt}: sampled {x.shape}, expected {arrays['x'][idx].shape}")
    return require_finite(x, ckpt)


def postprocess(cond, args):
    """The manifest's `postprocess` of a condition's clips (CONTRACTS §4): for the generated test conditions, the hips
    put back on the root (generation.motion.invariants) and, unless --free-bones, the poses put onto the item's
    actor's bones (generation.motion.rigid); nothing for NAT (real) nor BAD (broken on purpose)."""
    if cond not in (MG, FL):
        return ""
    return invariants.ROOT_HIPS if args.free_bones else invariants.POSTPROCESS


def apply_postprocess(x, cond, args, history):
    """Sampled windows x [B, T, 63] of `cond` post-processed as `postprocess` says, with the bones of each item's
    actor read from its real `history` [B, tau, 63]."""
    if not postprocess(cond, args):
        return x
    return invariants.root_hips(x) if args.free_bones else invariants.fit_to_actor(x, history)


# ---------------------------------------------------------------- the pipeline's stages
def import_systems(systems, items, fps, window, progress):
    """{name: {item position: joints}} of every imported system; before any training, so that its errors come
    first."""
    gen_items = positions(items, TEST, TRAINING)
    imported = {}
    for name, folder in systems.items():
        files = find_system_files(folder, [items[k]["id"] for k in gen_items])
        imported[name] = {}
        with tqdm(gen_items, desc=f"import {name}", unit="file", file=sys.stderr, disable=not progress) as bar:
            for k in bar:  # (the with-block closes the bar before an error message is printed)
                imported[name][k] = load_system_motion(files[items[k]["id"]], fps, window)
    return imported


def sample_clips(args, dataset, items, arrays):
    """(condition, item position, joints, seed) of NAT and of every sampled condition, models trained first
    where needed."""
    from .training.threads import torch_threads  # torch (see above)

    with torch_threads(args.threads):
        mg_ckpt, mg_early = ensure_model("mg", args, dataset)
        fl_ckpt, _ = ensure_model("fl", args, dataset)
        bad_ckpt = Path(args.bad_checkpoint) if args.bad_checkpoint else mg_early
        if not bad_ckpt.is_file():
            raise StimuliError(f"--bad-checkpoint {bad_ckpt}: no such file")
        log.info(f"models: MG {mg_ckpt}, FL {fl_ckpt}, BAD {bad_ckpt}")
        precision = sampler_precision(args)
        gen_items, catch = positions(items, TEST, TRAINING), positions(items, CATCH)
        # (condition, (model kind, checkpoint) or None for the real motion, item positions): one batch each.
        # NAT, MG and FL of the catch items too (role catch): NAT is the reference a pairwise or parallel catch
        # trial shows beside BAD, and a parallel catch page is filled up with MG and FL so that its size is a
        # test page's.
        plan = [
            (study.NATURAL, None, gen_items + catch),
            (MG, ("mg", mg_ckpt), gen_items + catch),
            (FL, ("fl", fl_ckpt), gen_items + catch),
        ]
        kind = {k: args.catch_kinds[j % len(args.catch_kinds)] for j, k in enumerate(catch)}
        sampled = [k for k in catch if kind[k] == MG_EARLY]
        if sampled:
            plan.append((study.CATCH, ("mg", bad_ckpt), sampled))
        clips = []
        for cond, model, idx in tqdm(plan, desc="sample", unit="condition", file=sys.stderr, disable=not args.progress):
            x, seed = arrays["x"][idx], ""
            if model is not None:
                seed = args.seed + SEED_OFFSET[cond]
                temperature = pretrained.TEMPERATURE[cond] if args.temperature is None else args.temperature
                x = sample_condition(*model, arrays, idx, temperature, seed, args.device, precision)
            x = apply_postprocess(x, cond, args, arrays["hist"][idx])  # hips on the root, the actor's bones
            joints = to_world(x, arrays["c"][idx])
            clips += [(cond, k, joints[j], seed) for j, k in enumerate(idx)]
    # The other catch kinds break the catch item's real motion (generation.stimuli.catch_kinds): a mix of kinds spreads
    # the catch clips' look and coded size on both sides of the test clips' (CONTRACTS §4).
    natural = {k: j for cond, k, j, _ in clips if cond == study.NATURAL}
    for n, k in enumerate(catch):
        if kind[k] != MG_EARLY:
            clips.append((study.CATCH, k, make_catch(natural[k], kind[k], args.seed * 1000 + n), kind[k]))
    return clips


def write_clips(out, clips, items, arrays, fps, args, forbidden):
    """Clip files, manifest and metrics rows, render jobs, the test clips' root-frame poses (for the FMD) and their
    C2ST features (c2st.collect).

    Clips are written (and rendered) in a random order, so that nothing about the files (creation order, inode
    numbers) follows the condition; ids are random and never contain a condition name (`forbidden`)."""
    rng = np.random.default_rng(args.seed)
    clips = [clips[i] for i in rng.permutation(len(clips))]
    taken, manifest, metrics_rows, jobs, poses, feats = set(), [], [], [], {}, {}
    for cond, k, joints, seed in tqdm(clips, desc="clips", unit="clip", file=sys.stderr, disable=not args.progress):
        it = items[k]
        cid = study.new_clip_id(taken, forbidden)
        joints = canonical_placement(joints, fps)
        control = arrays["c"][k]
        motion, video, sheet = clip_files(out, cid)
        save_clip(motion, joints, skeleton.PARENTS, skeleton.JOINT_NAMES, fps, control=control)
        jobs.append((str(motion), str(video), str(sheet), args.size, args.preset))
        row = manifest_row(cid, cond, it, seed, len(joints), fps, args.size)
        manifest.append({**row, "postprocess": postprocess(cond, args)})
        m = clip_metrics(joints, fps, control)
        metrics_rows.append(dict(clip_id=cid, condition=cond, role=it["role"], item=it["id"], **m))
        if it["role"] == TEST:
            poses.setdefault(cond, []).append((to_features(joints, fps)[0], it["category"]))
        c2st.collect(feats, cond, it["role"], it["id"], joints, fps, skeleton.PARENTS)
    return manifest, metrics_rows, jobs, poses, feats


def run(args):
    t0 = time.perf_counter()
    systems = dict(parse_system_spec(s) for s in args.system)
    if len(systems) != len(args.system):
        raise StimuliError("--system: the same NAME is given twice")
    if not args.export_items:
        refuse_existing(args.out, args.force)  # before any work, not after it
    dataset = ensure_dataset(args)
    splits, fps, window = read_heldout(dataset)
    items = select_items(splits, args.n_items, args.n_catch, args.n_training, args.seed)
    out = None if args.export_items else prepare_out(args.out, args.force)  # once the items are known to exist
    arrays = item_arrays(splits, items)
    log.info(
        f"items: {args.n_items} test, {args.n_catch} catch, {args.n_training} training; "
        f"categories {category_counts(items)}"
    )
    if args.export_items:
        write_items(args.export_items, items, arrays, fps)
        log.info(
            f"wrote {Path(args.export_items) / 'items.csv'} and items/ ({sum(it['role'] != CATCH for it in items)} "
            "items); generate one ITEM.bvh or ITEM.npz per item, then pass --system NAME=DIR"
        )
        return 0

    imported = import_systems(systems, items, fps, window, args.progress)
    clips = sample_clips(args, dataset, items, arrays)
    for name, motions in imported.items():
        clips += [(name, k, joints, "") for k, joints in motions.items()]
    manifest, metrics_rows, jobs, poses, feats = write_clips(
        out, clips, items, arrays, fps, args, [*study.RESERVED, *systems]
    )
    render_stimuli(jobs, args.workers, args.progress)
    fmd = condition_fmd(poses)
    c2st_rows = (c2st.c2st_table(feats), feature_table(feats, skeleton.JOINT_NAMES, skeleton.PARENTS))
    write_csv(Path(out) / "c2st.csv", C2ST_COLUMNS, c2st_rows[0])
    write_csv(Path(out) / "c2st_features.csv", FEATURE_COLUMNS, c2st_rows[1])
    write_tables(out, manifest, metrics_rows, fmd)
    write_items(out, items, arrays, fps)
    print_summary(out, manifest, metrics_rows, fmd, c2st_rows, time.perf_counter() - t0)
    return 0


# ---------------------------------------------------------------- command line
def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m generation.make_stimuli", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="stimuli", help="stimulus folder to write (default stimuli)")
    ap.add_argument(
        "--study",
        metavar="STUDY.toml",
        help="a study of your own motion: one folder of motion files per condition, named in a study file "
        "(CONTRACTS §10); --seed, --n-training, --n-catch and --length-s override the file's keys",
    )
    ap.add_argument(
        "--length-s",
        type=cli.number(float, 0.5, 600),
        help="with --study: keep the first LENGTH_S seconds of every clip (default: the study file's, else whole)",
    )
    _model_flags(ap)
    _item_flags(ap)
    _output_flags(ap)
    return ap


def _model_flags(ap):
    """Where the models come from: shipped, given, or trained (and from which data), and how MG samples."""
    ap.add_argument("--quick", action="store_true", help="tiny models on a subset of takes: a few minutes in all")
    ap.add_argument(
        "--retrain",
        action="store_true",
        help="prepare the data and train MG and FL from the mocap instead of using the shipped models",
    )
    ap.add_argument("--data", help="folder of BVH takes (default ../shared/data/bandai-namco-locomotion)")
    ap.add_argument("--runs", default="runs", help="folder for the cached dataset and training runs (default runs)")
    ap.add_argument(
        "--dataset",
        help="prepared dataset .npz to use or create (default RUNS/dataset.npz, RUNS/dataset_quick.npz with --quick)",
    )
    ap.add_argument(
        "--config", help="training config for both models: tiny | cpu | paper (default cpu; tiny with --quick)"
    )
    ap.add_argument("--train-steps", type=cli.number(int, 1), help="override the config's training steps")
    ap.add_argument(
        "--precision",
        help="override the config's for training: float32 | bfloat16 (the coupling networks in bfloat16: faster on "
        "some CPU kinds, slower on others; docs/models.md, Mixed precision)",
    )
    ap.add_argument(
        "--sample-precision",
        choices=("auto", "float32", "bfloat16"),
        default=None,
        help="MG's sampler: auto (the default, or $MOGLOW_SAMPLER_PRECISION) measures both once per CPU and takes "
        "bfloat16 where it is faster and the quality guard holds (generation.sampling.precision)",
    )
    ap.add_argument("--mg-checkpoint", help="MG checkpoint to sample from (skips MG training)")
    ap.add_argument("--fl-checkpoint", help="FL checkpoint to sample from (skips FL training)")
    ap.add_argument("--bad-checkpoint", help="checkpoint for the BAD catch clips (default: the earliest MG one)")


def _item_flags(ap):
    """What the set holds: the items, the catch clips, imported systems, and how the generated clips are made."""
    ap.add_argument(
        "--catch-kinds",
        default=f"{MG_EARLY},freeze",
        help=f"the kinds of BAD clip, dealt to the catch items in turn: {MG_EARLY} (the paper's: the earliest MG "
        f"checkpoint's samples) and the tool's {', '.join(TOOL_CATCH_KINDS)} of the item's real motion (default "
        f"{MG_EARLY},freeze: the mix keeps the catch clips' coded size among the test clips', CONTRACTS §4; "
        f"{MG_EARLY} alone is the paper's design)",
    )
    ap.add_argument(
        "--system",
        action="append",
        default=[],
        metavar="NAME=DIR",
        help="import another system's output (one ITEM.bvh[.gz] or ITEM.npz per item) as condition NAME",
    )
    ap.add_argument(
        "--export-items",
        metavar="DIR",
        help="only write DIR/items.csv and DIR/items/ (what another system must generate), then stop",
    )
    ap.add_argument(
        "--n-items",
        type=cli.number(int, 1, 10_000),
        default=30,
        help="test items (each in NAT, MG, FL and every system; default 30)",
    )
    ap.add_argument(
        "--n-catch",
        type=cli.number(int, 0, 10_000),
        help="catch items, each with a BAD clip (default 12, 4 with --quick: a pool from which each rater gets "
        "CATCH_PER_RATER, 4 by default, so that a catch clip reaches about the share of raters a test clip does "
        "at 30 of 90 test clips per rater; CONTRACTS §5)",
    )
    ap.add_argument(
        "--n-training",
        type=cli.number(int, 0, 10_000),
        help="familiarisation items, each shown in every condition but BAD (default 1)",
    )
    ap.add_argument(
        "--temperature",
        type=cli.number(float, 0, 10),
        help="sampling temperature of MG, FL and the bad examples (default: MG 0.5, FL 1.0, BAD 1.0: "
        "generation.sampling.pretrained.TEMPERATURE)",
    )
    ap.add_argument(
        "--free-bones",
        action="store_true",
        help="keep MG's and FL's bones as sampled (default: set to the item's actor's lengths, motion.rigid; the hips "
        "go back on the root either way, motion.invariants)",
    )
    ap.add_argument("--seed", type=cli.number(int, 0), help="item selection, sampling and manifest order (default 0)")


def _output_flags(ap):
    """How the videos are made and how the job runs."""
    ap.add_argument(
        "--size",
        type=size_flag,
        help="video height in pixels, even (default 640; 320 with --quick); the width by [render] aspect",
    )
    ap.add_argument(
        "--preset",
        default="ultrafast",
        help="x264 preset (default ultrafast: fastest, no visible loss on stick figures; every preset gets the rate "
        "control that makes every frame one size)",
    )
    ap.add_argument(
        "--workers",
        type=cli.number(int, 1, 1024),
        default=os.cpu_count() or 1,
        help="rendering processes (default: one per core)",
    )
    ap.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="--study: render on the Dask cluster whose scheduler is at ADDRESS (tcp://host:8786) instead of local "
        "processes; its workers see the same files at the same paths (docs/hosting.md, Rendering on other machines)",
    )
    # The flag's earlier name, still accepted; --workers is what every command of the project calls a pool's size.
    ap.add_argument(
        "--jobs", dest="workers", type=cli.number(int, 1, 1024), default=argparse.SUPPRESS, help=argparse.SUPPRESS
    )
    ap.add_argument("--device", help="torch device (default: cuda when present, else cpu)")
    ap.add_argument(
        "--threads",
        type=cli.number(int, 1, 1024),
        help="torch CPU threads for training and sampling (default: the "
        "cores other processes leave free for training, torch's choice for "
        "sampling; 1 with --quick, where tiny models gain nothing from more)",
    )
    ap.add_argument("--force", action="store_true", help="replace an existing stimulus set in --out")
    ap.add_argument("--quiet", action="store_true", help="no progress bars or diagnostics; the summary only")


def parse_args(argv):
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.study:
        return _study_args(args, parser)
    if args.length_s is not None:
        raise StimuliError("--length-s: only with --study (the built-in study's clips are 4-s windows)")
    args.seed = 0 if args.seed is None else args.seed
    args.n_catch = (4 if args.quick else 12) if args.n_catch is None else args.n_catch
    args.catch_kinds = [k.strip() for k in args.catch_kinds.split(",") if k.strip()]
    unknown = [k for k in args.catch_kinds if k not in (MG_EARLY, *TOOL_CATCH_KINDS)]
    if unknown or not args.catch_kinds:
        raise StimuliError(
            f"--catch-kinds: {unknown[0] if unknown else 'none given'}; "
            f"choose from {MG_EARLY}, {', '.join(TOOL_CATCH_KINDS)}"
        )
    args.n_training = 1 if args.n_training is None else args.n_training
    args.shipped = (
        not (args.retrain or args.quick or args.config or args.train_steps or args.precision or args.data)
        and pretrained.available()
    )
    args.config = args.config or ("tiny" if args.quick else "cpu")
    args.size = args.size or (320 if args.quick else 640)
    args.threads = args.threads or (1 if args.quick else None)
    if args.shipped and not args.dataset:
        args.dataset = str(pretrained.HELDOUT)
    args.dataset = args.dataset or str(Path(args.runs) / ("dataset_quick.npz" if args.quick else "dataset.npz"))
    args.progress = not args.quiet
    if args.data and not Path(args.data).is_dir():
        raise StimuliError(f"--data {args.data}: folder not found")
    return args


# Flags of the built-in study that a study from folders has no use for: given with --study, they are an error.
_BUILTIN_ONLY = (  # the built-in study's flags; a study file sets its own (catch kinds: [catch] make)
    "--quick",
    "--retrain",
    "--data",
    "--dataset",
    "--config",
    "--train-steps",
    "--precision",
    "--sample-precision",
    "--mg-checkpoint",
    "--fl-checkpoint",
    "--bad-checkpoint",
    "--system",
    "--export-items",
    "--n-items",
    "--temperature",
    "--free-bones",
    "--device",
    "--threads",
    "--runs",
    "--catch-kinds",
)


def _study_args(args, parser):
    """args for a study from folders: the study file read, with the flags given overriding its keys."""
    from .own_study.study_file import read_study_file

    # A flag counts as given where its value is not its default, however it was written (`--retr`, `--n-items=5`)
    # and whether the command line came as argv or from `python -m` (sys.argv).
    action = {flag: a for a in parser._actions for flag in a.option_strings}
    given = [f for f in _BUILTIN_ONLY if getattr(args, action[f].dest) != action[f].default]
    if given:
        raise StimuliError(f"{given[0]}: not used by a study from folders (--study); set it in the study file")
    spec = read_study_file(args.study)
    for flag, key in (("seed", "seed"), ("n_training", "n_training"), ("n_catch", "catch_n"), ("length_s", "length_s")):
        if getattr(args, flag) is not None:
            setattr(spec, key, getattr(args, flag))
    args.spec, args.size, args.progress = spec, args.size or 640, not args.quiet
    return args


class _Elapsed(logging.Formatter):
    """Diagnostics as '[  12 s] message': seconds since the start, for a job that runs minutes to an hour."""

    def format(self, record):
        return f"[{record.relativeCreated / 1000:5.0f} s] {record.getMessage()}"


def _main(argv):
    args = parse_args(argv)
    cli.log_to_stderr(args.quiet, _Elapsed())
    with nothing_left_on_failure(args.export_items or args.out):
        if args.study:
            from .own_study.builder import build_study

            return build_study(
                args.spec, args.out, args.size, args.preset, args.workers, args.force, args.progress, args.scheduler
            )
        return run(args)


def main(argv=None):
    set_gl_environment()  # the process's own setting: the mesh style draws here, or in workers that inherit it
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
