"""The main job: data -> models -> stimulus folder for the rating test (CONTRACTS.md §4).

    python -m generation.make_stimuli [--out stimuli/] [--quick] [--mg-checkpoint CKPT --fl-checkpoint CKPT]
                                      [--system NAME=DIR ...] [--export-items DIR]

1. Data: the held-out windows shipped in generation/pretrained/ (heldout.npz); with --retrain (or --quick,
   --data, --dataset) ../shared/data/bandai-namco-locomotion prepared into a cached dataset (runs/dataset.npz).
2. Items: held-out 4-s test windows, balanced over locomotion categories (round robin, distinct takes
   first), seeded: `--n-items` test items, `--n-catch` catch items and `--n-training` familiarisation
   items (from other windows).
3. Models: MG and FL checkpoints as given, else the shipped ones (generation/pretrained/: MG, FL and the early
   MG checkpoint that makes the BAD clips), else (--retrain, --quick, --config) trained (configs `cpu`, `tiny`
   with --quick) into runs/ (an existing run there is resumed or reused); BAD clips then come from the
   earliest MG checkpoint.
4. Clips: per test item NAT (the real window through features.to_world, the same inverse the models'
   output goes through), MG (seeded with the item's real preceding frames) and FL with the same control;
   every imported system's file for the item; BAD, NAT, MG and FL clips on the catch items (NAT is the
   reference of the pairwise and parallel catch trials, MG and FL fill a parallel catch page to a test page's
   size; an acr study shows only BAD); each training item in every condition
   except BAD. Every clip is placed to start at the origin facing +Z.
5. Videos (in parallel, one process per core), contact sheets, metrics.csv, manifest.csv, items.csv.
"""

import csv
import os
import re
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

import numpy as np
from tqdm import tqdm

from core import cli, study
from core.cli import UserError
from core.clip import save_clip
from rendering.blinding import pad_to_common_size, same_mtime
from rendering.render import render_clip, size_flag

from . import pretrained, skeleton
from .features import to_features, to_world
from .metrics import clip_metrics
from .systems import canonical_placement, find_system_files, load_system_motion, parse_system_spec

MANIFEST_COLUMNS = [
    "clip_id",
    "condition",
    "role",
    "item",
    "video",
    "motion",
    "seed",
    "frames",
    "fps",
    "width",
    "height",
]
METRICS_COLUMNS = [*study.METRIC_KEYS, *study.METRIC_NAMES]
ITEMS_COLUMNS = ["item", "role", "category", "take", "start_frame", "frames", "fps", "control"]


class StimuliError(UserError):
    """Bad input to make_stimuli; one line naming the file or option."""


_T0 = time.perf_counter()


def log(msg):
    print(f"[{time.perf_counter() - _T0:5.0f} s] {msg}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------- data
def ensure_dataset(args):
    """The prepared dataset path: --dataset if it exists, else prepared there from --data."""
    from .prepare_data import default_data_dir, longest_takes, prepare, summary_table

    path = Path(args.dataset)
    if path.is_file():
        log(f"data: using the prepared dataset {path}")
        return path
    data = Path(args.data) if args.data else default_data_dir()
    if data is None or not data.is_dir():
        raise StimuliError(
            f"data folder {args.data or '../shared/data/bandai-namco-locomotion'} not found; "
            "pass --data DIR (a folder of .bvh/.bvh.gz takes) or --dataset FILE.npz"
        )
    log(f"data: preparing {data} -> {path}" + (" (quick subset)" if args.quick else ""))
    takes = longest_takes(data, per_category=10) if args.quick else None
    summary = prepare(data, path, takes=takes, seed=args.seed, progress=True)
    log(summary_table(summary))
    return path


def load_splits(path):
    """The held-out splits of a prepared dataset as {split: dict of arrays}, plus fps and window."""
    keys = ("x", "c", "labels", "take", "start", "hist", "hist_c")
    try:
        # Only the held-out arrays: the training split is most of the file and is not needed here.
        with np.load(path, allow_pickle=False) as f:
            names = set(f.files)
            splits = {
                s: {k: f[f"{s}_{k}"] for k in keys} for s in ("test", "valid") if all(f"{s}_{k}" in names for k in keys)
            }
            fps, window = float(f["fps"]), int(f["window"])
    except (OSError, ValueError) as e:
        raise StimuliError(f"{path}: not a readable dataset .npz ({e})") from None
    if "test" not in splits:
        raise StimuliError(f"{path}: no test split with history (test_x, test_hist, ...); re-run prepare_data")
    return splits, fps, window


# ---------------------------------------------------------------- items
def balanced_order(labels, takes, rng):
    """All window indices in pick order: categories in turn; within one, a window of every take before
    a second one of any take, takes and windows shuffled."""
    queues = []
    for cat in sorted(set(labels)):
        by_take = {}
        for i in rng.permutation(np.nonzero(labels == cat)[0]):
            by_take.setdefault(takes[i], []).append(int(i))
        groups = list(by_take.values())
        order = [g[r] for r in range(max(map(len, groups))) for g in groups if r < len(g)]
        queues.append(order)
    out = []
    for r in range(max(map(len, queues)) if queues else 0):
        out += [q[r] for q in queues if r < len(q)]
    return out


def select_items(splits, n_items, n_catch, n_training, seed):
    """Items as a list of dicts (id, role, split, index, category, take, start); test items come from the
    test split, catch and training items from its remaining windows, then from the valid split."""
    rng = np.random.default_rng(seed)
    pool = []
    for s in ("test", "valid"):
        if s in splits:
            pool += [(s, i) for i in balanced_order(splits[s]["labels"], splits[s]["take"], rng)]
    n_test_windows = len(splits["test"]["labels"])
    if n_items > n_test_windows:
        raise StimuliError(f"--n-items {n_items}: the dataset's test split has only {n_test_windows} windows")
    need = n_items + n_catch + n_training
    if need > len(pool):
        raise StimuliError(
            f"{need} items needed but the held-out splits have only {len(pool)} windows; "
            "lower --n-items/--n-catch/--n-training"
        )
    test = pool[:n_items]
    rest = pool[n_items:]
    # Catch and training items: other windows, preferring other takes than the test items'.
    used_takes = {splits[s]["take"][i] for s, i in test}
    rest.sort(key=lambda p: splits[p[0]]["take"][p[1]] in used_takes)  # stable: keeps the balanced order
    roles = ["test"] * n_items + ["catch"] * n_catch + ["training"] * n_training
    items = []
    for role, (s, i) in zip(roles, test + rest[: n_catch + n_training]):
        items.append(
            dict(
                id=f"{s}{i:04d}",
                role=role,
                split=s,
                index=i,
                category=str(splits[s]["labels"][i]),
                take=str(splits[s]["take"][i]),
                start=int(splits[s]["start"][i]),
            )
        )
    return items


def item_arrays(splits, items):
    """Stacked window, control and history arrays of `items` (in order)."""
    get = lambda k: np.stack([splits[it["split"]][k][it["index"]] for it in items])  # noqa: E731
    return {k: get(k) for k in ("x", "c", "hist", "hist_c")}


def write_items(folder, items, arrays, fps):
    """items.csv plus items/ITEM.npz (control, real history) for the items another system must generate."""
    folder = Path(folder)
    (folder / "items").mkdir(parents=True, exist_ok=True)
    with open(folder / "items.csv", "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(ITEMS_COLUMNS)
        for k, it in enumerate(items):
            if it["role"] == "catch":
                continue
            rel = f"items/{it['id']}.npz"
            # The real frames just before the window, placed so that the window starts at the origin
            # facing +Z: a system can continue them, as MG does.
            hist_x = np.concatenate([arrays["hist"][k], arrays["x"][k][:1]])
            hist_c = np.concatenate([arrays["hist_c"][k], arrays["c"][k][:1]])
            hist = canonical_placement(to_world(hist_x, hist_c), fps, frame=-1)[:-1]
            np.savez_compressed(
                folder / rel,
                control=arrays["c"][k],
                history=arrays["hist"][k],
                history_control=arrays["hist_c"][k],
                history_joints=hist,
                fps=np.float64(fps),
                frames=np.int64(arrays["c"][k].shape[0]),
                joint_names=np.array(skeleton.JOINT_NAMES),
                parents=skeleton.PARENTS,
            )
            w.writerow(
                [
                    it["id"],
                    it["role"],
                    it["category"],
                    it["take"],
                    it["start"],
                    arrays["c"][k].shape[0],
                    f"{fps:g}",
                    rel,
                ]
            )


# ---------------------------------------------------------------- models
def checkpoints_in(folder):
    """Checkpoint files step_*.pt of a run folder (or its checkpoints/ subfolder), by step."""
    folder = Path(folder)
    if (folder / "checkpoints").is_dir():
        folder = folder / "checkpoints"
    files = [p for p in folder.glob("step_*.pt") if re.fullmatch(r"step_\d+\.pt", p.name)]
    return sorted(files, key=lambda p: int(p.stem.split("_")[1]))


def ensure_model(kind, args, dataset):
    """(final, earliest) checkpoint of `kind`: from --{kind}-checkpoint, else trained into runs/."""
    from .train import train

    given = getattr(args, f"{kind}_checkpoint")
    if given:
        path = Path(given)
        if not path.is_file():
            raise StimuliError(f"--{kind}-checkpoint {path}: no such file")
        siblings = checkpoints_in(path.parent)
        return path, siblings[0] if siblings else path
    if args.shipped:
        return pretrained.CHECKPOINTS[kind], pretrained.CHECKPOINTS["bad"]
    run = Path(args.runs) / f"{kind}_{args.config}"
    resume = (run / "resume.pt").is_file()
    log(f"models: {'resuming' if resume else 'training'} {kind} (config {args.config}) in {run}")
    train(
        kind,
        args.config,
        dataset,
        run,
        steps=args.train_steps,
        seed=args.seed,
        progress=True,
        resume=resume,
        device=args.device,
        threads=args.threads or "auto",
    )
    ckpts = checkpoints_in(run)
    if not ckpts:
        raise StimuliError(f"{run}: training wrote no checkpoint")
    return ckpts[-1], ckpts[0]


def sample_condition(kind, ckpt, arrays, idx, temperature, seed, device):
    """Features x [B, T, 63] sampled by the model in `ckpt` for the items at `idx`."""
    from .sample import load_model, sample_fl, sample_mg

    model = load_model(ckpt, device=device)
    c = arrays["c"][idx]
    if kind == "mg":
        x = sample_mg(model, c, arrays["hist"][idx], arrays["hist_c"][idx], temperature=temperature, seed=seed)
    else:
        x = sample_fl(model, c, temperature=temperature, seed=seed)
    x = np.asarray(x, dtype=np.float32)
    if x.shape != arrays["x"][idx].shape:
        raise StimuliError(f"{ckpt}: sampled {x.shape}, expected {arrays['x'][idx].shape}")
    return x


# ---------------------------------------------------------------- clips, videos, manifest
def _render_job(job):
    # Render workers are spawned and import this module: keep torch out of its module-level imports
    # (sampling, training and the motion encoder import it inside the functions that need it).
    motion, video, sheet, size, preset = job
    return render_clip(motion, video, size=size, sheet=sheet, preset=preset, threads=1)


def render_all(jobs, workers):
    """Render (motion, video, sheet, size, preset) jobs in a process pool, with a progress bar."""
    with tqdm(total=len(jobs), desc="render", unit="clip", file=sys.stderr) as bar:
        if workers <= 1:
            for job in jobs:
                _render_job(job)
                bar.update()
            return
        # spawn: the parent holds torch (threads); forked children of it can hang.
        pool = ProcessPoolExecutor(workers, mp_context=get_context("spawn"))
        try:
            for fut in as_completed([pool.submit(_render_job, job) for job in jobs]):
                fut.result()  # a worker's RenderError is raised here
                bar.update()
        finally:
            pool.shutdown(cancel_futures=True)


def prepare_out(out, force):
    out = Path(out)
    if (out / "manifest.csv").exists() and not force:
        raise StimuliError(f"{out}: already holds a stimulus set (manifest.csv); pass --force to replace it")
    for sub in ("videos", "motion", "sheets", "items"):
        if (out / sub).exists():
            shutil.rmtree(out / sub)
    for name in ("manifest.csv", "metrics.csv", "items.csv"):
        (out / name).unlink(missing_ok=True)
    for sub in ("videos", "motion", "sheets"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    return out


def summary_text(metrics_rows):
    """Per-condition means (sd) of every metric over test and catch clips, as a printable table."""
    import pandas as pd

    df = pd.DataFrame(metrics_rows)
    df = df[df.role != "training"]
    g = df.groupby(["role", "condition"])
    mean, sd = g[list(study.METRIC_NAMES)].mean(), g[list(study.METRIC_NAMES)].std()
    table = mean.map(lambda v: f"{v:.3g}") + " (" + sd.map(lambda v: f"{v:.2g}") + ")"
    table.insert(0, "n", g.size())
    return table.to_string()


# ---------------------------------------------------------------- main
def parse_args(argv):
    ap = cli.ArgumentParser(prog="python -m generation.make_stimuli", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="stimuli", help="stimulus folder to write (default stimuli)")
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
    ap.add_argument("--mg-checkpoint", help="MG checkpoint to sample from (skips MG training)")
    ap.add_argument("--fl-checkpoint", help="FL checkpoint to sample from (skips FL training)")
    ap.add_argument("--bad-checkpoint", help="checkpoint for the BAD catch clips (default: the earliest MG one)")
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
    ap.add_argument("--n-catch", type=cli.number(int, 0, 10_000), default=4, help="BAD catch clips (default 4)")
    ap.add_argument(
        "--n-training",
        type=cli.number(int, 0, 10_000),
        default=1,
        help="familiarisation items, each shown in every condition but BAD (default 1)",
    )
    ap.add_argument(
        "--temperature",
        type=cli.number(float, 0, 10),
        default=1.0,
        help="sampling temperature of MG and FL (default 1.0)",
    )
    ap.add_argument(
        "--seed", type=cli.number(int, 0), default=0, help="item selection, sampling and manifest order (default 0)"
    )
    ap.add_argument(
        "--size", type=size_flag, help="video width = height in pixels, even (default 640; 320 with --quick)"
    )
    ap.add_argument(
        "--preset",
        default="ultrafast",
        help="x264 preset (default ultrafast at constant quantiser 17: fastest, no visible loss on stick figures)",
    )
    ap.add_argument(
        "--jobs",
        type=cli.number(int, 1, 1024),
        default=os.cpu_count() or 1,
        help="rendering processes (default: one per core)",
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
    args = ap.parse_args(argv)
    args.shipped = (
        not (args.retrain or args.quick or args.config or args.train_steps or args.data) and pretrained.available()
    )
    args.config = args.config or ("tiny" if args.quick else "cpu")
    args.size = args.size or (320 if args.quick else 640)
    args.threads = args.threads or (1 if args.quick else None)
    if args.shipped and not args.dataset:
        args.dataset = str(pretrained.HELDOUT)
    args.dataset = args.dataset or str(Path(args.runs) / ("dataset_quick.npz" if args.quick else "dataset.npz"))
    if args.data and not Path(args.data).is_dir():
        raise StimuliError(f"--data {args.data}: folder not found")
    return args


def run(args):
    global _T0
    _T0 = time.perf_counter()
    systems = dict(parse_system_spec(s) for s in args.system)
    if len(systems) != len(args.system):
        raise StimuliError("--system: the same NAME is given twice")
    out = None if args.export_items else prepare_out(args.out, args.force)

    dataset = ensure_dataset(args)
    splits, fps, window = load_splits(dataset)
    items = select_items(splits, args.n_items, args.n_catch, args.n_training, args.seed)
    arrays = item_arrays(splits, items)
    log(
        f"items: {args.n_items} test, {args.n_catch} catch, {args.n_training} training; categories "
        + ", ".join(
            f"{c} {n}"
            for c, n in zip(*np.unique([it["category"] for it in items if it["role"] == "test"], return_counts=True))
        )
    )
    if args.export_items:
        write_items(args.export_items, items, arrays, fps)
        log(
            f"wrote {Path(args.export_items) / 'items.csv'} and items/ ({sum(it['role'] != 'catch' for it in items)} "
            "items); generate one ITEM.bvh or ITEM.npz per item, then pass --system NAME=DIR"
        )
        return 0

    # Imported systems first: their errors should come before any training.
    gen_items = [k for k, it in enumerate(items) if it["role"] != "catch"]
    imported = {}
    for name, folder in systems.items():
        files = find_system_files(folder, [items[k]["id"] for k in gen_items])
        imported[name] = {}
        with tqdm(gen_items, desc=f"import {name}", unit="file", file=sys.stderr) as bar:
            for k in bar:  # (the with-block closes the bar before an error message is printed)
                imported[name][k] = load_system_motion(files[items[k]["id"]], fps, window)

    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    mg_ckpt, mg_early = ensure_model("mg", args, dataset)
    fl_ckpt, _ = ensure_model("fl", args, dataset)
    bad_ckpt = Path(args.bad_checkpoint) if args.bad_checkpoint else mg_early
    if not bad_ckpt.is_file():
        raise StimuliError(f"--bad-checkpoint {bad_ckpt}: no such file")
    log(f"models: MG {mg_ckpt}, FL {fl_ckpt}, BAD {bad_ckpt}")

    # (condition, model or None for the real motion, item positions): one batch per condition.
    catch = [k for k, it in enumerate(items) if it["role"] == "catch"]
    seeds = {"MG": args.seed + 1, "FL": args.seed + 2, "BAD": args.seed + 3}
    # NAT, MG and FL of the catch items too (role catch): NAT is the reference a pairwise or parallel catch trial
    # shows beside BAD, and a parallel catch page is filled up with MG and FL so that its size is a test page's.
    plan = [
        ("NAT", None, gen_items + catch),
        ("MG", ("mg", mg_ckpt), gen_items + catch),
        ("FL", ("fl", fl_ckpt), gen_items + catch),
    ]
    if catch:
        plan.append(("BAD", ("mg", bad_ckpt), catch))
    clips = []  # (condition, item position, joints, seed)
    for cond, model, idx in tqdm(plan, desc="sample", unit="condition", file=sys.stderr):
        if model is None:
            joints = to_world(arrays["x"][idx], arrays["c"][idx])
            seed = ""
        else:
            x = sample_condition(model[0], model[1], arrays, idx, args.temperature, seeds[cond], args.device)
            joints = to_world(x, arrays["c"][idx])
            seed = seeds[cond]
        clips += [(cond, k, joints[j], seed) for j, k in enumerate(idx)]
    for name, motions in imported.items():
        clips += [(name, k, motions[k], "") for k in gen_items]

    # Write clip files and the render jobs in a random order, so that nothing about the files (creation order,
    # inode numbers) follows the condition; ids are random and never contain a condition name.
    rng = np.random.default_rng(args.seed)
    clips = [clips[i] for i in rng.permutation(len(clips))]
    forbidden = [*study.RESERVED, *systems]
    taken, manifest, metrics_rows, jobs, poses = set(), [], [], [], {}
    for cond, k, joints, seed in tqdm(clips, desc="clips", unit="clip", file=sys.stderr):
        it = items[k]
        cid = study.new_clip_id(taken, forbidden)
        joints = canonical_placement(joints, fps)
        control = arrays["c"][k]
        save_clip(out / "motion" / f"{cid}.npz", joints, skeleton.PARENTS, skeleton.JOINT_NAMES, fps, control=control)
        jobs.append(
            (
                str(out / "motion" / f"{cid}.npz"),
                str(out / "videos" / f"{cid}.mp4"),
                str(out / "sheets" / f"{cid}.png"),
                args.size,
                args.preset,
            )
        )
        manifest.append(
            dict(
                clip_id=cid,
                condition=cond,
                role=it["role"],
                item=it["id"],
                video=f"videos/{cid}.mp4",
                motion=f"motion/{cid}.npz",
                seed=seed,
                frames=len(joints),
                fps=f"{fps:g}",
                width=args.size,
                height=args.size,
            )
        )
        m = clip_metrics(joints, fps, control)
        metrics_rows.append(dict(clip_id=cid, condition=cond, role=it["role"], item=it["id"], **m))
        if it["role"] == "test":
            poses.setdefault(cond, []).append((to_features(joints, fps)[0], it["category"]))

    log(f"render: {len(jobs)} clips at {args.size}x{args.size} on {min(args.jobs, len(jobs))} processes")
    render_all(jobs, min(args.jobs, len(jobs)))
    videos = [job[1] for job in jobs]
    size = pad_to_common_size(videos)
    same_mtime([p for job in jobs for p in job[:3]], time.time())
    log(f"render: done; every video padded to {size} bytes and stamped with the same time")

    _write_csv(out / "manifest.csv", MANIFEST_COLUMNS, manifest)  # rows in the random order of the clips
    _write_csv(
        out / "metrics.csv",
        METRICS_COLUMNS,
        [{k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()} for row in metrics_rows],
    )
    write_items(out, items, arrays, fps)
    fmd = condition_fmd(poses)
    if fmd:
        _write_csv(out / "fmd.csv", ["condition", "n_windows", "fmd"], fmd)

    n = {r: sum(m["role"] == r for m in manifest) for r in ("test", "catch", "training")}
    print(
        f"\nobjective metrics, mean (sd) per condition: foot_skating m/s, bone_length_std m, jerk m/s^3, "
        f"control_error m, control_following m\n{summary_text(metrics_rows)}"
    )
    if fmd:
        print(
            "\nFréchet motion distance of the test clips to training motion of their categories "
            "(NAT's is the floor): " + ", ".join(f"{r['condition']} {r['fmd']}" for r in fmd)
        )
    _warn_if_bad_not_bad(metrics_rows)
    print(
        f"\nwrote {out / 'manifest.csv'}: {len(manifest)} clips ({n['test']} test, {n['catch']} catch, "
        f"{n['training']} training) in {time.perf_counter() - _T0:.0f} s"
    )
    return 0


def condition_fmd(poses, encoder=pretrained.MOTION_ENCODER):
    """[{condition, n_windows, fmd}] for root-frame test windows {condition: [(x [T, 63], category), ...]};
    [] (with a note) when the shipped motion encoder is missing."""
    if not Path(encoder).is_file():
        log(f"note: no motion encoder at {encoder}; skipping the Fréchet motion distance")
        return []
    from .motion_encoder import MotionEncoder  # torch: imported here, not at module level (see _render_job)

    enc = MotionEncoder.load(encoder)
    return [
        dict(condition=cond, n_windows=len(w), fmd=f"{enc.fmd(np.stack([x for x, _ in w]), [k for _, k in w]):.4g}")
        for cond, w in poses.items()
    ]


def _warn_if_bad_not_bad(rows):
    """BAD clips should be plainly worse than NAT; say so when no metric shows it."""

    def mean(cond, key):
        v = [r[key] for r in rows if r["condition"] == cond and np.isfinite(r[key])]
        return np.mean(v) if v else np.nan

    if not any(r["condition"] == "BAD" for r in rows):
        return
    worse = [k for k in ("jerk", "bone_length_std", "foot_skating") if mean("BAD", k) > 2 * mean("NAT", k)]
    if not worse:
        log(
            "warning: the BAD clips are not clearly worse than NAT on jerk, bone length or foot skating; "
            "pass an earlier --bad-checkpoint"
        )


def _write_csv(path, columns, rows):
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        w.writerows(rows)


def main(argv=None):
    return cli.run(lambda a: run(parse_args(a)), argv)


if __name__ == "__main__":
    sys.exit(main())
