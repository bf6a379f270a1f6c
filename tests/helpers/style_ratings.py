"""Ratings of a study drawn in two styles, made up with a known condition x style interaction (the style analysis'
tests and the report's)."""

import numpy as np
import pandas as pd


def synthetic(interaction, seed=0, n_raters=24, clips_per_cell=6):
    """Ratings 1..5 of two conditions (REAL, SYS) drawn in two styles; SYS is worse by 1; `interaction` is added
    to SYS's solid clips only."""
    rng = np.random.default_rng(seed)
    clips = [
        (f"{c}-{s}-{i}", c, s, rng.normal(0, 0.15))
        for c in ("REAL", "SYS")
        for s in ("stick", "solid")
        for i in range(clips_per_cell)
    ]
    rows = []
    for r in range(n_raters):
        u = rng.normal(0, 0.4)
        for cid, c, s, v in clips:
            mu = 4.0 - (c == "SYS") + interaction * (c == "SYS" and s == "solid") + u + v
            rows.append((f"r{r}", cid, c, s, int(np.clip(np.rint(mu + rng.normal(0, 0.7)), 1, 5))))
    return pd.DataFrame(rows, columns=["rater_id", "clip_id", "condition", "style", "rating"])
