"""Seeded generator of a realistic ratings.csv (CONTRACTS.md §6) for the analysis tests and benchmark.

Written once to freeze tests/data/analysis/ratings_small.csv (`python tests/data/analysis/make_ratings.py`);
the benchmark imports make_ratings() for its large inputs. The model is a crowd test like MoGlow's: every
clip has a quality (condition mean + clip effect), every rater a leniency, each response is the latent score
plus noise cut into the 1-5 scale; a share of careless raters answer at random (and mostly fail the catch
trials), and attentive raters now and then give a catch clip a 3.
"""

import argparse
import string

import numpy as np
import pandas as pd

CONDITION_MEANS = {"NAT": 4.05, "MG": 3.55, "FL": 2.45}
CATCH_MEAN = 1.25


def _tokens(rng, n, length=12):
    alphabet = np.array(list(string.ascii_lowercase + string.digits))
    out, seen = [], set()
    while len(out) < n:
        tok = "".join(rng.choice(alphabet, length))
        if tok not in seen:
            seen.add(tok)
            out.append(tok)
    return out


def make_ratings(
    n_raters=20,
    clips_per_condition=30,
    n_catch=4,
    careless_share=0.1,
    clips_per_rater=None,
    seed=0,
    clip_sd=0.35,
    rater_sd=0.35,
    noise_sd=0.75,
):
    rng = np.random.default_rng(seed)
    conds = list(CONDITION_MEANS)
    clip_cond = np.repeat(conds + ["BAD"], [clips_per_condition] * len(conds) + [n_catch])
    clip_item = np.concatenate([np.arange(clips_per_condition)] * len(conds) + [np.arange(n_catch)])
    n_clips = len(clip_cond)
    clip_ids = np.array(_tokens(rng, n_clips))
    item_effect = rng.normal(0, clip_sd * 0.5, clips_per_condition)  # shared control trajectory difficulty
    quality = np.array([CONDITION_MEANS.get(c, CATCH_MEAN) for c in clip_cond]) + rng.normal(0, clip_sd, n_clips)
    quality[clip_cond != "BAD"] += item_effect[clip_item[clip_cond != "BAD"]]
    leniency = rng.normal(0, rater_sd, n_raters)
    careless = rng.random(n_raters) < careless_share
    per = n_clips if clips_per_rater is None else clips_per_rater
    # Each rater sees `per` clips (all catch clips always, the rest at random) in a random order.
    test_idx = np.flatnonzero(clip_cond != "BAD")
    catch_idx = np.flatnonzero(clip_cond == "BAD")
    if per >= n_clips:
        chosen = np.tile(np.arange(n_clips), (n_raters, 1))
    else:
        keys = rng.random((n_raters, len(test_idx)))
        pick = test_idx[np.argsort(keys, axis=1)[:, : per - len(catch_idx)]]
        chosen = np.concatenate([pick, np.tile(catch_idx, (n_raters, 1))], axis=1)
    chosen = np.take_along_axis(chosen, np.argsort(rng.random(chosen.shape), axis=1), axis=1)
    rater = np.repeat(np.arange(n_raters), chosen.shape[1])
    clip = chosen.ravel()
    latent = quality[clip] + leniency[rater] + rng.normal(0, noise_sd, len(clip))
    rating = np.clip(np.rint(latent), 1, 5).astype(int)
    rand = careless[rater]
    rating[rand] = rng.integers(1, 6, rand.sum())
    trial = np.tile(np.arange(chosen.shape[1]), n_raters)
    watched = (4000 + rng.gamma(2.0, 400.0, len(clip))).astype(int)
    start = np.datetime64("2024-05-06T09:00:00") + (rng.random(n_raters) * 7 * 86400).astype("timedelta64[s]")
    when = start[rater] + (trial * 12 + rng.integers(0, 8, len(clip))).astype("timedelta64[s]")
    rater_ids = np.array([f"r{i:05d}" for i in range(n_raters)])
    return pd.DataFrame(
        {
            "rater_id": rater_ids[rater],
            "clip_id": clip_ids[clip],
            "condition": clip_cond[clip],
            "rating": rating,
            "role": np.where(clip_cond[clip] == "BAD", "catch", "test"),
            "item": clip_item[clip],
            "trial_index": trial,
            "watched_ms": watched,
            "submitted_at": pd.to_datetime(when).strftime("%Y-%m-%dT%H:%M:%SZ"),
        }
    )


def make_metrics(ratings, seed=0):
    """A metrics.csv for the rated clips: objective scores loosely tied to the clips' mean rating."""
    rng = np.random.default_rng(seed + 1)
    clips = (
        ratings[ratings["role"] == "test"]
        .groupby("clip_id")
        .agg(condition=("condition", "first"), item=("item", "first"), mean=("rating", "mean"))
        .reset_index()
    )
    q = clips["mean"].to_numpy()
    n = len(clips)
    return pd.DataFrame(
        {
            "clip_id": clips["clip_id"],
            "condition": clips["condition"],
            "role": "test",
            "item": clips["item"],
            "foot_skating": np.round(np.maximum(0.0, 0.5 - 0.1 * q + rng.normal(0, 0.05, n)), 6),
            "bone_length_std": np.round(np.abs(rng.normal(0.004, 0.002, n)) * (clips["condition"] != "NAT"), 6),
            "jerk": np.round(np.exp(rng.normal(5.0 - 0.2 * q, 0.2)), 4),
            "control_error": np.round(np.abs(rng.normal(0.1, 0.05, n)) * (clips["condition"] != "NAT"), 6),
        }
    )


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="tests/data/analysis/ratings_small.csv")
    ap.add_argument("--metrics-out", default="tests/data/analysis/metrics_small.csv")
    ap.add_argument("--raters", type=int, default=20)
    ap.add_argument("--seed", type=int, default=6)
    args = ap.parse_args()
    df = make_ratings(n_raters=args.raters, seed=args.seed)
    df.to_csv(args.out, index=False)
    make_metrics(df, seed=args.seed).to_csv(args.metrics_out, index=False)
    print(f"wrote {args.out}: {len(df)} ratings")
