"""The floor of the rate's dither (rendering.encode.DITHER_RANGE): what the coded sizes tell about a clip, and how
the frames the dither starves look, with each frame's share of the rate clipped at a quarter of the mean and at a
half (or any --floors).

    python bench/bench_dither_floor.py [STIMULI] [--floors 0.25 0.5] [--seeds 3] [--size 640] [--boot 1000]
        [--clips N] [--cache FILE.npz] [--ssim]

Sizes (STIMULI: a stimulus folder whose manifest has many BAD catch clips and test clips, e.g. the gesture set of
bench/RESULTS.md#blinded-sizes): every BAD and test clip is drawn once as a stick figure at --size (as
bench_blind_sizes draws for its quality part) and encoded with the default rate control at each floor under the
same --seeds seeds (one set per clip, shared by the floors, so a frame's draw differs only where a floor clips it).
Of each encoding every size a parser reads (`rendering.mp4_layout.size_signals`) is taken, and each signal gives
an AUC (`moglow_eval.core.ranks.auc`) of every comparison of bench_blind_sizes (BAD against test, each pair of
conditions, matched against mismatched where the set has them) over all encodings, a clip's seeds pooled. Per
family of signals the worst AUC (furthest from 0.5) is printed with its signal and a 95% bootstrap interval over
clips (each group's clips resampled, a clip's encodings together), then the paired bootstrap of the change in the
family's worst distance from 0.5 between the floors (the same resampled clips at both). --clips N keeps the
first N clips of each group (a quick look); --cache keeps the encodings' signals, and a run with the same clips and
seeds reads them back instead of encoding again.

SSIM (--ssim): bench_key_frame's clips (three takes as stick and solid, the synthetic SMPL-H body as the mesh;
640 px, 4 s) at each floor, each frame against the drawn frames: the key frame, frame 1, the worst later frame and
how many later frames fall below 0.98 in any of three seeds. Nothing here is timed.
"""

import argparse
import csv
import os
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import bench_key_frame as key_frame  # noqa: E402
import numpy as np  # noqa: E402
from bench_blind_sizes import _drawn, _encode, comparisons, family, groups  # noqa: E402

from moglow_eval.core.clip import load_clip  # noqa: E402
from moglow_eval.core.ranks import auc  # noqa: E402
from rendering import encode  # noqa: E402
from rendering.blinding import SIZE_AUC_BAND  # noqa: E402
from rendering.mp4_layout import read_layout, size_signals  # noqa: E402


@contextmanager
def floor_at(floor):
    """DITHER_RANGE with its floor at `floor` (the ceiling kept) inside the block."""
    kept = encode.DITHER_RANGE
    encode.DITHER_RANGE = (floor, kept[1])
    try:
        yield
    finally:
        encode.DITHER_RANGE = kept


def encoded_signals(folder, rows, floors, seeds, size):
    """{floor: {signal: [clip, seed] values}} of `rows`' clips, drawn once each and encoded at every floor."""
    got = {f: [] for f in floors}
    with tempfile.TemporaryDirectory() as tmp:
        video = Path(tmp) / "v.mp4"
        for k, r in enumerate(rows):
            clip = load_clip(folder / r["motion"])
            raw = _drawn(clip, size)
            for f in floors:
                with floor_at(f):
                    per_seed = []
                    for s in range(seeds):
                        _encode(raw, video, size, float(clip["fps"]), seed=1000 * k + s)
                        per_seed.append(size_signals(read_layout(video)))
                got[f].append(per_seed)
            print(f"  {k + 1}/{len(rows)} clips encoded", file=sys.stderr, end="\r")
    print(file=sys.stderr)
    out = {}
    for f, clips in got.items():
        names = list(dict.fromkeys(n for per_seed in clips for s in per_seed for n in s))
        out[f] = {n: np.array([[s.get(n, -1) for s in per_seed] for per_seed in clips], float) for n in names}
    return out


def worst(values):
    """The value furthest from 0.5 (the first of equals)."""
    return max(values, key=lambda v: abs(v - 0.5))


def family_worst(table, index, pairs, pick=None):
    """{(family, pair): (worst AUC, its signal)} over `table` {signal: [clip, seed]}; `pick` {group: rows of the
    clips} resamples the groups (None: as they are)."""
    out = {}
    for name, v in table.items():
        same = v.min() == v.max()  # tells nothing in any resample
        for a, b in pairs:
            ia, ib = (index[a], index[b]) if pick is None else (pick[a], pick[b])
            value = 0.5 if same else auc(v[ia].ravel(), v[ib].ravel())
            key = (family(name), (a, b))
            if key not in out or abs(value - 0.5) > abs(out[key][0] - 0.5):
                out[key] = (value, name)
    return out


def size_report(folder, rows, floors, seeds, size, boot, n_clips, cache=None):
    g = groups(rows)
    if n_clips:
        g = {k: v[:n_clips] for k, v in g.items()}
    pairs = comparisons(g)
    by_id = {r["clip_id"]: r for r in rows}
    ids = list(dict.fromkeys(c for a, b in pairs for c in (*g[a], *g[b])))
    index = {k: np.array([ids.index(c) for c in v], int) for k, v in g.items()}
    print(f"{len(ids)} clips at {size} px, {seeds} seeds each; " + ", ".join(f"{k} {len(v)}" for k, v in g.items()))
    run = dict(ids=ids, floors=list(floors), seeds=seeds, size=size)
    if cache and Path(cache).exists():  # the encodings' signals of an earlier run, to look at them again
        saved = np.load(cache, allow_pickle=True)["run"].item()
        if any(saved[k] != v for k, v in run.items()):
            sys.exit(f"{cache}: encoded for other clips, floors, seeds or size; remove it to encode again")
        tables = saved["tables"]
    else:
        tables = encoded_signals(folder, [by_id[c] for c in ids], floors, seeds, size)
        if cache:
            np.savez(cache, run=np.array({**run, "tables": tables}, dtype=object))
    point = {f: family_worst(tables[f], index, pairs) for f in floors}
    reps = {f: [family_worst(tables[f], index, pairs, pick) for pick in _picks(index, boot)] for f in floors}
    for a, b in pairs:
        print_pair(g, (a, b), floors, tables, point, reps, index, boot)
    low, high = SIZE_AUC_BAND
    print()
    for f in floors:
        w = worst(v for v, _ in point[f].values())
        inside = low <= w <= high
        print(f"floor {f:g}: every AUC in [{low}, {high}]: {'yes' if inside else 'no'} (the worst: {w:.3f})")


def print_pair(g, pair, floors, tables, point, reps, index, boot):
    """One comparison's table: per family the worst AUC at each floor with its signal's 95% interval, and the
    paired change of the family's worst distance from 0.5 from each floor to the next."""
    a, b = pair
    n_a, n_b = len(g[a]), len(g[b])
    chance = 1.96 * ((n_a + n_b + 1) / (12 * n_a * n_b)) ** 0.5
    print(f"\n{a} vs {b}: {n_a} and {n_b} clips (a signal that tells nothing: 0.5 +- {chance:.3f} in 95% of sets)")
    changes = [f"{format(f1, 'g')} - {format(f0, 'g')}" for f0, f1 in zip(floors, floors[1:])]
    print(
        f"{'family':<30}"
        + "".join(f"{'floor ' + format(f, 'g'):>24}" for f in floors)
        + "".join(f"{c:>24}" for c in changes)
        + "   worst signal per floor"
    )
    for fam in dict.fromkeys(fam for fam, p in point[floors[0]] if p == pair):
        key = (fam, pair)
        cells, names = [], []
        for f in floors:
            value, name = point[f][key]
            # the worst signal's own interval: its AUC in every resample of the clips
            v = tables[f][name]
            spread = [auc(v[p[a]].ravel(), v[p[b]].ravel()) for p in _picks(index, boot)]
            lo, hi = np.percentile(spread, [2.5, 97.5])
            cells.append(f"{value:.3f} [{lo:.3f}, {hi:.3f}]")
            names.append(name)
        for f0, f1 in zip(floors, floors[1:]):
            d = [abs(r1[key][0] - 0.5) - abs(r0[key][0] - 0.5) for r0, r1 in zip(reps[f0], reps[f1])]
            lo, hi = np.percentile(d, [2.5, 97.5])
            dp = abs(point[f1][key][0] - 0.5) - abs(point[f0][key][0] - 0.5)
            cells.append(f"{dp:+.3f} [{lo:+.3f}, {hi:+.3f}]")
        print(f"{fam:<30}" + "".join(f"{c:>24}" for c in cells) + "   " + " / ".join(names))


def _picks(index, boot):
    """The same `boot` resamples of every group's clips, each time it is called."""
    rng = np.random.default_rng(1)
    for _ in range(boot):
        yield {k: v[rng.integers(len(v), size=len(v))] for k, v in index.items() if len(v)}


def ssim_report(floors, seeds, size=640, seconds=4.0):
    print(f"\nSSIM All against the drawn frames, {size} px, {seconds:g} s, {seeds} seeds (min over seeds)")
    print(f"{'clip':<40}{'floor':>7}{'frame 0':>10}{'frame 1':>10}{'min, rest':>11}{'< 0.98':>8}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for label, clip, style, mesh, camera in key_frame.clips(folder, seconds):
            raw = key_frame.drawn(clip, size, style, mesh, camera)
            (folder / "raw.yuv").write_bytes(raw)
            for f in floors:
                with floor_at(f):
                    got = []
                    for seed in range(seeds):
                        key_frame.encode_raw(raw, folder / "v.mp4", size, seed)
                        got.append(key_frame.frame_ssim(folder / "raw.yuv", folder / "v.mp4", size)[:, 0])
                low = np.min(got, axis=0)
                print(
                    f"{label:<40}{f:>7g}{low[0]:>10.4f}{low[1]:>10.4f}{low[2:].min():>11.4f}"
                    f"{int((low[2:] < 0.98).sum()):>8}"
                )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("stimuli", type=Path, nargs="?", help="a stimulus folder (manifest.csv, motion/)")
    ap.add_argument("--floors", type=float, nargs="+", default=[0.25, 0.5], help="dither floors (of the mean)")
    ap.add_argument("--seeds", type=int, default=3, help="encodings per clip and floor")
    ap.add_argument("--size", type=int, default=640, help="frame size the clips are drawn at")
    ap.add_argument("--boot", type=int, default=1000, help="bootstrap resamples of the clips")
    ap.add_argument("--clips", type=int, default=0, help="only the first N clips of each group (0: all)")
    ap.add_argument("--cache", type=Path, help="an .npz keeping the encodings' signals (read back when it exists)")
    ap.add_argument("--ssim", action="store_true", help="also the per-frame SSIM of bench_key_frame's clips")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; DITHER_SD {encode.DITHER_SD}")
    if args.stimuli:
        with open(args.stimuli / "manifest.csv", newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
        print(args.stimuli)
        size_report(args.stimuli, rows, args.floors, args.seeds, args.size, args.boot, args.clips, args.cache)
    if args.ssim:
        ssim_report(args.floors, 3)


if __name__ == "__main__":
    main()
