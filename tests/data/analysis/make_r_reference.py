"""Seeded generator of ratings_r_reference.csv: the file our ordinal and linear mixed models are checked on
against R (r_reference.R -> r_reference.json).

Written once (`python tests/data/analysis/make_r_reference.py`). A crowd test sized like a real one: 70 raters
each rate 45 of 90 test clips (30 per NAT/MG/FL) and 4 catch clips; 4 careless raters answer at random and
fail a catch trial, so 66 raters and 2,970 test ratings are kept. Responses come from a cumulative-logit model
with crossed rater and clip intercepts -- the model the ordinal fit assumes -- so the R comparison exercises
a well-posed fit with moderate effects (MG a little, FL clearly below NAT), not a degenerate one.
"""

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).parent
EFFECTS = {"NAT": 0.0, "MG": -0.6, "FL": -1.5}  # log-odds of a higher rating, against NAT
THRESHOLDS = np.array([-2.6, -1.2, 0.3, 1.9])  # latent cut points between 1|2, 2|3, 3|4, 4|5
SD_RATER, SD_CLIP = 0.8, 0.6


def make(seed=2024, n_attentive=66, n_careless=4, clips_per_condition=30, clips_per_rater=45, n_catch=4):
    rng = np.random.default_rng(seed)
    conds = list(EFFECTS)
    clip_cond = np.repeat(conds, clips_per_condition)
    n_clips = len(clip_cond)
    clip_ids = np.array(
        [f"{c.lower()}{i:02d}" for c, i in zip(clip_cond, np.tile(np.arange(clips_per_condition), len(conds)))]
    )
    clip_eff = rng.normal(0, SD_CLIP, n_clips)
    n_raters = n_attentive + n_careless
    rater_ids = np.array([f"w{i:03d}" for i in rng.permutation(n_raters)])
    careless = np.zeros(n_raters, bool)
    careless[rng.choice(n_raters, n_careless, replace=False)] = True
    rater_eff = rng.normal(0, SD_RATER, n_raters)
    rows = []
    for r in range(n_raters):
        clips = rng.permutation(n_clips)[:clips_per_rater]
        eta = np.array([EFFECTS[c] for c in clip_cond[clips]]) + clip_eff[clips] + rater_eff[r]
        latent = eta + rng.logistic(size=len(clips))
        rating = 1 + (latent[:, None] > THRESHOLDS).sum(axis=1)
        if careless[r]:
            rating = rng.integers(1, 6, len(clips))
        catch = rng.integers(1, 3, n_catch)  # attentive raters give the broken clips a 1 or 2 ...
        if careless[r]:
            catch[rng.integers(n_catch)] = rng.integers(3, 6)  # ... careless ones rate one of them 3 or more
        trials = [(rater_ids[r], clip_ids[c], clip_cond[c], int(y), "test") for c, y in zip(clips, rating)]
        trials += [(rater_ids[r], f"bad{j}", "BAD", int(y), "catch") for j, y in enumerate(catch)]
        order = rng.permutation(len(trials))
        rows += [trials[i] + (k,) for k, i in enumerate(order)]
    return pd.DataFrame(rows, columns=["rater_id", "clip_id", "condition", "rating", "role", "trial_index"])


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE / "ratings_r_reference.csv"))
    args = ap.parse_args()
    df = make()
    df.to_csv(args.out, index=False)
    print(f"wrote {args.out}: {len(df)} rows")
