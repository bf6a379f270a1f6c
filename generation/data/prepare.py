"""Prepare the MoGlow training data (CONTRACTS.md §2): BVH takes -> windows of features, split by take.

    python -m generation.data.prepare [--data DIR] [--out FILE.npz] [--fps 20] [--window 80] [--stride 20]

Per take: load (21 joints, metres, resampled), features (x [T, 63], c [T, 3]). Takes are split by take,
seeded: from every locomotion category the same number of takes (`held_out`, fewer for small
categories) goes to valid and to test, chosen among takes long enough for one window plus tau frames
of history. Train takes are augmented (mirror, time reversal, both) at the take level, then every
take is cut into windows of `window` frames every `stride` frames, plus one window ending at the last
frame so that short takes lose no tail. Valid/test windows start at frame >= tau and carry the tau
frames before them (`{split}_hist`, `{split}_hist_c`) so that MG can be seeded with real history.
"""

import os
import re
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from moglow_eval.core import cli, whole_files
from moglow_eval.core.cli import UserError
from moglow_eval.core.clip import MAX_FPS, MIN_FPS

from ..motion import skeleton
from ..motion.features import load_take, mirror, reverse, to_features

DEFAULT_DATA = Path("..") / "shared" / "data" / "bandai-namco-locomotion"
SPLITS = ("train", "valid", "test")
AUG_NAMES = ("none", "mirror", "reverse", "mirror+reverse")

# Bandai-Namco content name (from the file name) -> locomotion category (as in shared/data/MANIFEST.csv)
CATEGORY_OF_CONTENT = {
    "walk": "walk",
    "run": "run",
    "dash": "run_fast",
    "walk-back": "walk_backward",
    "walk-left": "sidestep_left",
    "walk-right": "sidestep_right",
    "walk-turn-left": "walk_turn_left",
    "walk-turn-right": "walk_turn_right",
}


class PrepareError(UserError):
    """Bad input to prepare(); the message names the file or option."""


def take_name(path):
    name = Path(path).name
    for ext in (".gz", ".bvh"):
        if name.endswith(ext):
            name = name[: -len(ext)]
    return name


def category_of(path):
    """Locomotion category of a take, from its Bandai-Namco file name `dataset-N_CONTENT_STYLE_NNN`."""
    parts = take_name(path).split("_")
    if len(parts) >= 3 and parts[1] in CATEGORY_OF_CONTENT:
        return CATEGORY_OF_CONTENT[parts[1]]
    return parts[1] if len(parts) >= 3 else "unknown"


def is_other_bandai_content(path):
    """True for a Bandai-Namco take that is not locomotion (bow, bye, dance, wave...): the published repository
    holds those beside the walks and runs, and the locomotion models must not train on them."""
    parts = take_name(path).split("_")
    bandai = len(parts) >= 3 and re.fullmatch(r"dataset-\d+", parts[0]) is not None
    return bandai and parts[1] not in CATEGORY_OF_CONTENT


def find_takes(data_dir):
    """The .bvh and .bvh.gz takes at any depth under `data_dir`: the shared folder, or a clone of the
    Bandai-Namco repository with its data.zip files unpacked (docs/data.md)."""
    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise PrepareError(f"{data_dir}: data directory not found")
    files = sorted(
        p
        for p in data_dir.rglob("*")
        if p.name.endswith((".bvh", ".bvh.gz")) and not p.name.startswith("rest.") and not is_other_bandai_content(p)
    )
    if not files:
        raise PrepareError(f"{data_dir}: no .bvh or .bvh.gz files found")
    return files


def longest_takes(data_dir, per_category):
    """Names of the `per_category` longest takes (by file size) of every locomotion category: a small
    real subset with held-out windows in every category, for quick runs and tests."""
    by_cat = {}
    for f in find_takes(data_dir):
        by_cat.setdefault(category_of(f), []).append(f)
    return sorted(
        take_name(f)
        for files in by_cat.values()
        for f in sorted(files, key=lambda p: (-p.stat().st_size, p.name))[:per_category]
    )


def default_data_dir():
    """../shared/data/bandai-namco-locomotion relative to the cwd, or beside the repository root."""
    for base in (Path.cwd(), Path(__file__).resolve().parents[2]):
        cand = (base / DEFAULT_DATA).resolve()
        if cand.is_dir():
            return cand
    return None


def _load_features(args):
    path, fps = args
    return to_features(load_take(path, fps), fps)


def window_starts(n_frames, window, stride, first=0):
    """Window starts first, first+stride, ... plus one window ending at the last frame (if it fits)."""
    if n_frames - first < window:
        return np.zeros(0, dtype=np.int64)
    starts = list(range(first, n_frames - window + 1, stride))
    if starts[-1] != n_frames - window:
        starts.append(n_frames - window)
    return np.array(starts, dtype=np.int64)


def split_takes(categories, lengths, need, held_out, seed):
    """Split index per take (0 train, 1 valid, 2 test): per category, k takes each to valid and test.

    k = min(held_out, eligible // 3), where eligible takes have at least `need` frames; so every
    category with three or more long-enough takes is represented in both held-out splits equally.
    """
    rng = np.random.default_rng(seed)
    split = np.zeros(len(categories), dtype=np.int64)
    for cat in sorted(set(categories)):
        eligible = [i for i, (cc, n) in enumerate(zip(categories, lengths)) if cc == cat and n >= need]
        k = min(held_out, len(eligible) // 3)
        chosen = rng.permutation(np.array(eligible, dtype=np.int64))[: 2 * k]
        split[chosen[:k]] = 1
        split[chosen[k:]] = 2
    return split


def _mean_std(a, chunk=512):
    """Per-feature mean and std over all windows and frames of a [N, T, D] array, in float64 chunks."""
    flat = a.reshape(-1, a.shape[-1])
    n = len(flat)
    step = chunk * a.shape[1]
    mean = sum(flat[i : i + step].sum(0, dtype=np.float64) for i in range(0, n, step)) / n
    var = sum(np.square(flat[i : i + step] - mean).sum(0) for i in range(0, n, step)) / n
    return mean.astype(np.float32), np.sqrt(var).astype(np.float32)


def prepare(
    data_dir,
    out_path,
    fps=20.0,
    window=80,
    stride=20,
    seed=0,
    takes=None,
    tau=10,
    held_out=4,
    workers=None,
    progress=True,
):
    """Build the dataset .npz at `out_path`; returns a summary dict (see `summary_table`).

    `takes`: optional subset, as paths or take names (with or without extension) under `data_dir`.
    """
    files = _select_files(data_dir, takes)
    if window < 2 or stride < 1 or tau < 0:
        raise PrepareError(f"window must be >= 2, stride >= 1, tau >= 0 (got {window}, {stride}, {tau})")
    feats = _load_all(files, fps, workers, progress)
    names = [take_name(f) for f in files]
    cats = [category_of(f) for f in files]
    lengths = [x.shape[0] for x, _ in feats]
    split = split_takes(cats, lengths, tau + window, held_out, seed)
    arrays = _stack(_cut_windows(feats, split, cats, names, window, stride, tau), window, tau)
    if len(arrays["train_x"]) == 0:
        raise PrepareError(f"{data_dir}: no training windows (takes shorter than window={window} frames?)")
    arrays.update(_standardisation(arrays))
    arrays.update(
        fps=np.float64(fps),
        window=np.int64(window),
        tau=np.int64(tau),
        stride=np.int64(stride),
        seed=np.int64(seed),
        joint_names=np.array(skeleton.JOINT_NAMES, dtype=str),
        parents=skeleton.PARENTS,
        aug_names=np.array(AUG_NAMES, dtype=str),
    )
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    with whole_files.writing(out_path, suffix=".npz") as tmp:
        np.savez(tmp, **arrays)  # uncompressed: mocap floats barely compress and saving stays fast
    return dict(
        out=str(out_path),
        n_takes=len(files),
        rows=_summary_rows(arrays, cats, split, lengths, fps),
        n_windows={s: int(len(arrays[f"{s}_x"])) for s in SPLITS},
    )


def _select_files(data_dir, takes):
    """The take files under `data_dir`, or only those named in `takes`."""
    files = find_takes(data_dir)
    if takes is None:
        return files
    wanted = {take_name(t) for t in takes}
    files = [f for f in files if take_name(f) in wanted]
    missing = wanted - {take_name(f) for f in files}
    if missing:
        raise PrepareError(f"{data_dir}: takes not found: {', '.join(sorted(missing)[:5])}")
    return files


def _load_all(files, fps, workers, progress):
    """Features (x, c) of every take, on `workers` processes (default: one per core, at most one per take)."""
    from tqdm import tqdm

    workers = workers or min(len(files), os.cpu_count() or 1)
    jobs = [(str(f), float(fps)) for f in files]
    feats = []
    with tqdm(total=len(jobs), desc="takes", unit="take", disable=not progress, file=sys.stderr) as bar:
        if workers <= 1:
            for job in jobs:
                feats.append(_load_features(job))
                bar.update()
            return feats
        with ProcessPoolExecutor(workers) as pool:
            for res in pool.map(_load_features, jobs, chunksize=max(1, len(jobs) // (8 * workers))):
                feats.append(res)
                bar.update()
    return feats


def _variants(x, c, s):
    """(x, c, augmentation index) of a take: as it is, plus, for training takes, mirrored, reversed and both."""
    variants = [(x, c, 0)]
    if s == "train":
        xm, cm = mirror(x, c)
        variants += [(xm, cm, 1), (*reverse(x, c), 2), (*reverse(xm, cm), 3)]
    return variants


def _cut_windows(feats, split, cats, names, window, stride, tau):
    """{split: {key: list of per-take arrays or values}}: every take's windows, held-out ones with their history."""
    out = {s: {k: [] for k in ("x", "c", "labels", "take", "start", "aug", "hist", "hist_c")} for s in SPLITS}
    for i, (x, c) in enumerate(feats):
        s = SPLITS[split[i]]
        starts = window_starts(len(x), window, stride, 0 if s == "train" else tau)
        if len(starts) == 0:
            continue
        idx = starts[:, None] + np.arange(window)
        hidx = starts[:, None] - tau + np.arange(tau)
        d = out[s]
        for xv, cv, aug in _variants(x, c, s):
            d["x"].append(xv[idx])
            d["c"].append(cv[idx])
            d["labels"] += [cats[i]] * len(starts)
            d["take"] += [names[i]] * len(starts)
            d["start"].append(starts)
            d["aug"].append(np.full(len(starts), aug))
            if s != "train":
                d["hist"].append(xv[hidx])
                d["hist_c"].append(cv[hidx])
    return out


def _stack(out, window, tau):
    """The per-split lists of _cut_windows as the file's arrays ({split}_{key}); empty splits keep their shapes."""
    empty = dict(
        x=((0, window, skeleton.POSE_DIM), np.float32),
        c=((0, window, skeleton.CONTROL_DIM), np.float32),
        start=((0,), np.int64),
        aug=((0,), np.int64),
        hist=((0, tau, skeleton.POSE_DIM), np.float32),
        hist_c=((0, tau, skeleton.CONTROL_DIM), np.float32),
    )
    arrays = {}
    for s in SPLITS:
        d = out[s]
        arrays[f"{s}_labels"] = np.array(d["labels"], dtype=str)
        arrays[f"{s}_take"] = np.array(d["take"], dtype=str)
        for key, (shape, dtype) in empty.items():
            if s == "train" and key.startswith("hist"):
                continue
            arrays[f"{s}_{key}"] = np.concatenate(d[key]) if d[key] else np.zeros(shape, dtype)
    return arrays


def _standardisation(arrays):
    """Mean and std of x and c from the training split only. Some dimensions are constant by construction
    (the hips' x and z in the root frame are 0), hence the floor on the standard deviation."""
    x_mean, x_std = _mean_std(arrays["train_x"])
    c_mean, c_std = _mean_std(arrays["train_c"])
    return dict(
        x_mean=x_mean,
        x_std=np.maximum(x_std, 1e-3).astype(np.float32),
        c_mean=c_mean,
        c_std=np.maximum(c_std, 1e-3).astype(np.float32),
    )


def _summary_rows(arrays, cats, split, lengths, fps):
    rows = []
    for cat in sorted(set(cats)):
        for si, s in enumerate(SPLITS):
            members = [i for i in range(len(cats)) if cats[i] == cat and split[i] == si]
            n_win = int(np.sum((arrays[f"{s}_labels"] == cat) & (arrays[f"{s}_aug"] == 0)))
            rows.append(
                dict(
                    category=cat,
                    split=s,
                    takes=len(members),
                    minutes=sum(lengths[i] for i in members) / fps / 60,
                    windows=n_win,
                    windows_augmented=int(np.sum(arrays[f"{s}_labels"] == cat)),
                )
            )
    return rows


def summary_table(summary):
    """The closing summary as text: takes, minutes and windows per category and split."""
    import pandas as pd

    df = pd.DataFrame(summary["rows"])
    wide = df.pivot(index="category", columns="split", values=["takes", "minutes", "windows"])
    wide = wide.reindex(columns=[(m, s) for m in ("takes", "minutes", "windows") for s in SPLITS])
    wide.loc["total"] = wide.sum()
    wide.columns = [f"{m}_{s}" for m, s in wide.columns]
    for col in wide.columns:
        wide[col] = wide[col].round(1) if col.startswith("minutes") else wide[col].astype(int)
    n = summary["n_windows"]
    return (
        wide.to_string() + f"\nwindows in file (train incl. mirror/reverse augmentation x4): "
        f"train {n['train']}, valid {n['valid']}, test {n['test']} -> {summary['out']}"
    )


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m generation.data.prepare", description=__doc__.split("\n")[0])
    ap.add_argument("--data", help="folder of BVH takes (default: ../shared/data/bandai-namco-locomotion)")
    ap.add_argument("--out", default="dataset.npz", help="output .npz (default: dataset.npz)")
    ap.add_argument("--fps", type=cli.number(float, MIN_FPS, MAX_FPS), default=20.0)
    ap.add_argument(
        "--window", type=cli.number(int, 2, 100_000), default=80, help="frames per window (default 80 = 4 s)"
    )
    ap.add_argument(
        "--stride", type=cli.number(int, 1, 100_000), default=20, help="frames between window starts (default 20)"
    )
    ap.add_argument("--tau", type=cli.number(int, 0, 1000), default=10, help="history frames before valid/test windows")
    ap.add_argument(
        "--held-out", type=cli.number(int, 0, 10_000), default=4, help="takes per category in valid and in test"
    )
    ap.add_argument("--seed", type=cli.number(int, 0), default=0)
    ap.add_argument("--workers", type=cli.number(int, 1, 1024), default=None, help="processes (default: all cores)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    cli.file_to_write(args.out, "the dataset file to write")  # before the takes are read, not after
    data = args.data
    if data is None:
        data = default_data_dir()
        if data is None:
            raise PrepareError(
                f"no --data given and {DEFAULT_DATA} not found here or beside the "
                "repository; pass --data DIR (a folder of .bvh/.bvh.gz takes)"
            )
    summary = prepare(
        data,
        args.out,
        fps=args.fps,
        window=args.window,
        stride=args.stride,
        seed=args.seed,
        tau=args.tau,
        held_out=args.held_out,
        workers=args.workers,
        progress=not args.quiet,
    )
    print(summary_table(summary))


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
