"""Benchmark of the issue-14 statistics: the ordinal mixed model against R's ordinal::clmm in the same run.

  1. Ordinal fit (cumulative logit, crossed rater and clip intercepts, ML-Laplace) on
     tests/data/analysis/ratings_r_reference.csv (2,970 kept ratings, 66 raters, 90 clips): target <= 1 s.
     When Rscript with the ordinal package is on PATH, clmm is timed on the same rows in the same run (package
     loading and the CSV read excluded, best of --repeat) and the ratio is printed; its fit is compared too.
  2. Satterthwaite df of the linear mixed model on the same rows (lmerTest's numbers are in r_reference.json).
  3. The whole report on tests/data/analysis/ratings_small.csv (1,880 ratings) with everything on (bootstrap,
     linear and ordinal mixed models, each with and without the exclusion): target <= 5 s.
  4. The same on ratings_r_reference.csv, a crowd's incomplete table, where the ICC's interval is a bootstrap of
     mixed-model refits (analysis.stats.agreement): target <= 5 s.
Wall time is printed with the process CPU time: on a shared machine wall time includes waiting for a core.

    python bench/bench_stats.py [--repeat 5] [--no-r]
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from analysis.data.filtering import exclude_raters, only_test_rows  # noqa: E402
from analysis.data.load import load_ratings  # noqa: E402
from analysis.report import build_report  # noqa: E402
from analysis.stats import rating_models  # noqa: E402

DATA = ROOT / "tests" / "data" / "analysis"
REF_CSV = DATA / "ratings_r_reference.csv"

R_SCRIPT = r"""
suppressPackageStartupMessages(library(ordinal))
d <- read.csv(commandArgs(TRUE)[1], stringsAsFactors = FALSE)
bad <- unique(d$rater_id[d$role == "catch" & d$rating >= 3])
d <- d[!(d$rater_id %in% bad) & d$role == "test", ]
d$condition <- relevel(factor(d$condition), ref = "NAT")
times <- c()
for (i in seq_len(as.integer(commandArgs(TRUE)[2]))) {
  t0 <- proc.time()[["elapsed"]]
  o <- clmm(factor(rating, ordered = TRUE) ~ condition + (1 | rater_id) + (1 | clip_id), data = d)
  times <- c(times, proc.time()[["elapsed"]] - t0)
}
cat(sprintf("{\"seconds\": [%s], \"log_likelihood\": %.10f, \"beta\": [%s]}\n", paste(times, collapse = ","),
            as.numeric(logLik(o)), paste(sprintf("%.10f", o$beta), collapse = ",")))
"""


def best_of(fn, repeat):
    """(best wall seconds, CPU seconds of that run, last result)."""
    best, cpu, out = float("inf"), None, None
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        wall = time.perf_counter() - t
        if wall < best:
            best, cpu = wall, time.process_time() - c
    return best, cpu, out


def time_clmm(repeat):
    """R's clmm on the same file: (best seconds, log-likelihood, betas), or None without R/ordinal."""
    if shutil.which("Rscript") is None:
        return None
    with tempfile.NamedTemporaryFile("w", suffix=".R", delete=False) as f:
        f.write(R_SCRIPT)
    try:
        proc = subprocess.run(
            ["Rscript", f.name, str(REF_CSV), str(repeat)], capture_output=True, text=True, timeout=1800
        )
    finally:
        os.unlink(f.name)
    if proc.returncode != 0:
        print(f"  (R's clmm not timed: {proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else 'failed'})")
        return None
    doc = json.loads(proc.stdout.strip().splitlines()[-1])
    return min(doc["seconds"]), doc["log_likelihood"], doc["beta"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="runs of each timing; the best is reported (default 5)")
    ap.add_argument("--no-r", action="store_true", help="do not time R's clmm")
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    crowd = load_ratings(REF_CSV)  # every rating, as the report reads them (item 4)
    rows = only_test_rows(exclude_raters(crowd)[0])
    rating_models.ordinal_model(rows)  # warm-up: imports and first-call costs are not the fit's
    ours, cpu, fit = best_of(lambda: rating_models.ordinal_model(rows), args.repeat)
    print(
        f"ordinal fit, {len(rows):,} ratings ({rows['rater_id'].nunique()} raters x {rows['clip_id'].nunique()} "
        f"clips): best {ours:.3f} s wall, {cpu:.3f} s CPU, {fit['n_evaluations']} Laplace evaluations "
        f"(target <= 1 s)"
    )
    r = None if args.no_r else time_clmm(args.repeat)
    if r is not None:
        r_s, r_ll, r_beta = r
        print(
            f"R ordinal::clmm, same rows: best {r_s:.3f} s  -> ours is {r_s / ours:.1f}x faster; "
            f"log-likelihood ours {fit['log_likelihood']:.4f}, R {r_ll:.4f}; "
            f"max |beta difference| {max(abs(a - b) for a, b in zip(fit['fixed_effects'].values(), r_beta)):.1e}"
        )
    elif not args.no_r:
        print("R ordinal::clmm: Rscript not found; no ratio")
    lmm, cpu, m = best_of(lambda: rating_models.mixed_model(rows), args.repeat)
    print(f"linear mixed model with Satterthwaite df, same rows: best {lmm:.3f} s wall, {cpu:.3f} s CPU")
    tmp = Path(tempfile.mkdtemp(prefix="bench_stats_"))
    try:
        small = DATA / "ratings_small.csv"
        rep, cpu, _ = best_of(lambda: build_report(small, tmp / "r", progress=False, quiet=True), args.repeat)
        print(
            f"whole report, 1,880 ratings, everything on (bootstrap 2000, mixed and ordinal models, each x2): "
            f"best {rep:.2f} s wall, {cpu:.2f} s CPU (target <= 5 s)"
        )
        # A crowd's table is incomplete (each rater rates some clips): the ICC then comes from the mixed model's
        # variance components with a bootstrap of refits, which a complete table does not need.
        rep, cpu, _ = best_of(lambda: build_report(REF_CSV, tmp / "c", progress=False, quiet=True), args.repeat)
        print(
            f"whole report, {len(crowd):,} ratings of an incomplete table ({crowd['rater_id'].nunique()} raters, "
            f"{crowd['clip_id'].nunique()} clips), everything on, with the ICC's bootstrap of refits: best "
            f"{rep:.2f} s wall, {cpu:.2f} s CPU (target <= 5 s)"
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
