"""Benchmark of `python -m analysis.report` (issue 6 targets).

  1. 1,000,000 ratings, mixed models (linear and ordinal) off: < 20 s. Two designs: a panel (3,226 raters x all
     310 clips: 100 per NAT/MG/FL + 10 catch; the bootstrap uses BLAS on the dense rater x clip table) and a crowd
     (50,000 raters x 20 of 3,004 clips; the sparse path).
  2. 1,880 ratings (the paper's size: 20 raters x 94 clips), everything on (2,000-resample cluster bootstrap,
     the crossed linear and ordinal mixed models, each with and without the exclusion): < 5 s.
The ordinal model alone against R's clmm: bench/bench_stats.py.
Each run is the whole report (read + validate CSV, exclusion, all statistics twice, figures, HTML, JSON).
Also times the cluster bootstrap against a per-replicate loop baseline on the paper-size data.

    python bench/bench_report.py [--quick]
"""

import argparse
import importlib.util
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from analysis.data.filtering import exclude_raters, only_test_rows  # noqa: E402
from analysis.data.load import load_ratings  # noqa: E402
from analysis.designs import Options  # noqa: E402
from analysis.report import build_report  # noqa: E402
from analysis.stats import bootstrap, rating_models  # noqa: E402

spec = importlib.util.spec_from_file_location("make_ratings", ROOT / "tests/data/analysis/make_ratings.py")
gen = importlib.util.module_from_spec(spec)
spec.loader.exec_module(gen)


def timed_report(csv, out, **kw):
    """Wall seconds of one whole report; CPU seconds of this process are kept in CPU[-1] (on a shared machine
    wall time includes waiting for a core)."""
    t, c = time.perf_counter(), time.process_time()
    build_report(csv, out, Options(**kw), progress=False, quiet=True)
    CPU.append(time.process_time() - c)
    return time.perf_counter() - t


CPU = []


def loop_bootstrap(t, n_boot, seed=0):
    """Baseline: one explicit resample per replicate (index raters and clips, recompute the means)."""
    rng = np.random.default_rng(seed)
    raters = t["rater_id"].unique()
    by_cond = {c: g["clip_id"].unique() for c, g in t.groupby("condition")}
    out = []
    for _ in range(n_boot):
        wr = dict(zip(*np.unique(rng.choice(raters, len(raters)), return_counts=True)))
        wc = {}
        for clips in by_cond.values():
            wc.update(zip(*np.unique(rng.choice(clips, len(clips)), return_counts=True)))
        w = t["rater_id"].map(wr).fillna(0).to_numpy() * t["clip_id"].map(wc).fillna(0).to_numpy()
        y = t["rating"].to_numpy()
        out.append({c: (w * y)[m].sum() / w[m].sum() for c in by_cond if (m := (t["condition"] == c).to_numpy()).any()})
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="100k instead of 1M ratings")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_report_"))

    small = tmp / "small.csv"
    gen.make_ratings(n_raters=20, seed=6).to_csv(small, index=False)
    runs = [timed_report(small, tmp / "rs", mixed=True) for _ in range(3)]
    print(
        f"1,880 ratings, everything on (bootstrap 2000 x2, linear and ordinal mixed models x2): "
        f"best {min(runs):.2f} s, median {sorted(runs)[1]:.2f} s wall, {min(CPU[-3:]):.2f} s CPU  (target < 5 s)"
    )
    print(f"load average at start: {os.getloadavg()[0]:.1f} (2 cores shared with other work)")

    t = only_test_rows(exclude_raters(load_ratings(small))[0])
    t0 = time.perf_counter()
    bootstrap.cluster_bootstrap(t, n_boot=2000)
    vec = time.perf_counter() - t0
    t0 = time.perf_counter()
    loop_bootstrap(t, 200)
    loop = (time.perf_counter() - t0) * 10
    print(
        f"cluster bootstrap, 2000 resamples of 1,440 ratings: vectorised {vec:.3f} s, "
        f"per-replicate loop {loop:.1f} s (extrapolated from 200) -> {loop / vec:.0f}x"
    )
    t0 = time.perf_counter()
    rating_models.mixed_model(t)
    print(f"mixed model (REML, 16 raters x 90 clips): {time.perf_counter() - t0:.2f} s")

    scale = 10 if args.quick else 1
    designs = [  # (label, generator arguments): a panel where every rater sees every clip, and a crowd
        ("panel: 3,226 raters x all 310 clips", dict(n_raters=3226 // scale, clips_per_condition=100, n_catch=10)),
        (
            "crowd: 50,000 raters x 20 of 3,004 clips",
            dict(n_raters=50000 // scale, clips_per_condition=1000, n_catch=4, clips_per_rater=20),
        ),
    ]
    for label, kw in designs:
        big = tmp / "big.csv"
        t0 = time.perf_counter()
        gen.make_ratings(seed=1, **kw).to_csv(big, index=False)
        gen_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        df = load_ratings(big)
        load_s = time.perf_counter() - t0
        n = len(df)
        del df
        total = timed_report(big, tmp / "rb", mixed=False, ordinal=False)
        print(
            f"{n:,} ratings ({label}), mixed models off: {total:.2f} s wall, {CPU[-1]:.2f} s CPU "
            f"(read+validate {load_s:.2f} s) (target < 20 s; CSV generated in {gen_s:.0f} s, not timed)"
        )
        if label.startswith("panel"):
            total = timed_report(big, tmp / "rb", mixed=True)
            print(f"{n:,} ratings ({label}), mixed model ON (x2): {total:.2f} s wall, {CPU[-1]:.2f} s CPU (no target)")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
