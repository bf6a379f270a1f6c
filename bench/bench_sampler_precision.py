"""MG's sampler precision on this CPU (issue 46, item 7): what generation.sampling.precision would pick, and why.

    python bench/bench_sampler_precision.py [--rounds 5] [--frames 150] [--threads 2]

Measures the shipped MG sampling 30 held-out streams (the default job's batch) in float32 and bfloat16, in
`--rounds` rounds (each the pick's own measurement: the two precisions taking turns frame by frame, their gain the
median of the paired ratios), computes the quality guard's figures of MG in both precisions
(generation.sampling.pretrained.quality) and the guard's failures in bfloat16, says what each round would pick,
then runs the pick itself on the round of median gain into a throwaway cache (the user's cache is left alone).
Prints one JSON document: the CPU key, the load average before and after, every round, the figures and the pick.
"""

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation.sampling import precision, pretrained  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    load_before = os.getloadavg()
    rounds = [pretrained.measure_speed(frames=a.frames, early=False) for _ in range(a.rounds)]
    t0 = time.perf_counter()
    figures = {p: pretrained.quality(precision=p, models=("MG",))["MG"] for p in ("float32", "bfloat16")}
    quality_s = time.perf_counter() - t0
    failures = pretrained.quality_failures({"MG": figures["bfloat16"]})
    # The round whose gain is the median one: what a first use of the pick typically measures here.
    typical = sorted(rounds, key=precision.speed_gain)[len(rounds) // 2]
    with tempfile.TemporaryDirectory() as tmp:
        picked = precision.pick(
            "cpu", None, lambda: typical, lambda: failures, cache=Path(tmp) / "p.json", env={}, key="bench"
        )
        why = json.loads((Path(tmp) / "p.json").read_text())["bench"]["why"]
    doc = {
        "cpu": precision.cpu_key(),
        "threads": a.threads,
        "load_before": [round(x, 2) for x in load_before],
        "load_after": [round(x, 2) for x in os.getloadavg()],
        "rounds": [{k: round(v, 3) for k, v in r.items()} for r in rounds],
        "picks_per_round": [precision.decide(r, failures)[0] for r in rounds],
        "typical_round": {k: round(v, 3) for k, v in typical.items()},
        "mg_quality": {p: {k: round(v, 4) for k, v in f.items()} for p, f in figures.items()},
        "quality_s_both": round(quality_s, 1),
        "guard_failures_bfloat16": failures,
        "pick": picked,
        "why": why,
    }
    print(json.dumps(doc, indent=1))


if __name__ == "__main__":
    main()
