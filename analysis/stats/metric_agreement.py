"""How far each objective measure agrees with people: each system's value with a bootstrap interval over items, and
the rank agreement of the measure with the human result (Kendall's tau-b with its interval). Pure functions on
DataFrames.

- A system's value of a measure is the mean over items of its matched test clips' values (an item's several clips,
  its samples or styles, averaged first), over the items where the measure is defined.
- The bootstrap resamples the items with replacement, the same items for every system (items are the unit a study
  samples, and the systems share them), `n_boot` times; an interval is the 2.5th and 97.5th percentiles.
- The rank agreement is Kendall's tau-b between the systems' measure, oriented so that a higher value is better, and
  their human score (the design's: MOS, Elo, the matched-preference score). Orientation (moglow_eval.core.study.
  METRIC_DIRECTION): "lower" negates the value, "higher" keeps it, "reference" takes minus the distance to the
  reference system's value. So +1: the measure orders the systems as people did; -1: the reverse. Its interval comes
  from the same resamples, each resample also drawing every system's human score from a normal distribution fitted
  to its reported 95% interval, so that the interval carries the uncertainty of both sides. Defined over at least
  MIN_SYSTEMS systems with both a value and a score.
"""

import warnings

import numpy as np
import pandas as pd

from moglow_eval.core import study

MIN_SYSTEMS = 3
Z95 = 1.959963984540054


def item_table(clips, measures):
    """{measure: DataFrame items x systems} of each system's per-item mean over its matched test clips; `clips` as
    analysis.data.load.load_measure_clips gives them (the condition column already holding the report's names)."""
    test = clips[(clips["role"] == study.ROLES[0]) & clips["matched"] & (clips["condition"] != study.CATCH)]
    out = {}
    for m in measures:
        table = test.groupby(["item", "condition"])[m].mean().unstack("condition")
        out[m] = table.dropna(how="all")
    return out


def _means(table, rows):
    """Each system's mean over the items at positions `rows` [n_boot, n_items] -> [n_boot, n_systems]."""
    values = table.to_numpy(dtype=float)[rows]  # [n_boot, n_items, n_systems]
    with warnings.catch_warnings():  # a system with no value on any resampled item: nan, as it should be
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(values, axis=-2)


def system_values(tables, n_boot=2000, seed=0):
    """Rows (measure, system, value, low, high, n_items): each system's mean with its bootstrap interval."""
    rng = np.random.default_rng(seed)
    rows = []
    for m, table in tables.items():
        if table.empty:
            continue
        boot = _means(table, rng.integers(0, len(table), (n_boot, len(table))))
        point = _means(table, np.arange(len(table))[None])[0]
        for j, system in enumerate(table.columns):
            lo, hi = _interval(boot[:, j])
            n = int(table[system].notna().sum())
            rows.append(dict(measure=m, system=system, value=point[j], low=lo, high=hi, n_items=n))
    return pd.DataFrame(rows, columns=["measure", "system", "value", "low", "high", "n_items"])


def _interval(x):
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return (float(np.percentile(x, 2.5)), float(np.percentile(x, 97.5))) if len(x) else (np.nan, np.nan)


def orient(values, direction, reference):
    """Values [..., n_systems] turned so that higher is better: `direction` "lower", "higher" or "reference"
    (minus the distance to the column `reference`'s value; None: nan)."""
    values = np.asarray(values, float)
    if direction == "lower":
        return -values
    if direction == "reference":
        if reference is None:
            return np.full_like(values, np.nan)
        return -np.abs(values - values[..., reference : reference + 1])
    return values


def kendall_tau_b(x, y):
    """Kendall's tau-b of each row pair of x and y [n_rows, n] (as scipy.stats.kendalltau), over the systems where
    both are finite; nan for a row with under MIN_SYSTEMS of them or a side all tied."""
    x, y = np.atleast_2d(np.asarray(x, float)), np.atleast_2d(np.asarray(y, float))
    i, j = np.triu_indices(x.shape[1], 1)
    valid = np.isfinite(x[:, i]) & np.isfinite(x[:, j]) & np.isfinite(y[:, i]) & np.isfinite(y[:, j])
    with np.errstate(invalid="ignore"):
        dx, dy = np.sign(x[:, i] - x[:, j]), np.sign(y[:, i] - y[:, j])
    dx, dy = np.where(valid, dx, 0.0), np.where(valid, dy, 0.0)
    pairs = valid.sum(axis=1)
    tied_x, tied_y = (valid & (dx == 0)).sum(axis=1), (valid & (dy == 0)).sum(axis=1)
    denom = np.sqrt((pairs - tied_x) * (pairs - tied_y).astype(float))
    n = (np.isfinite(x) & np.isfinite(y)).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        tau = (dx * dy).sum(axis=1) / denom
    return np.where((n >= MIN_SYSTEMS) & (denom > 0), tau, np.nan)


def rank_agreement(tables, scores, reference, n_boot=2000, seed=0):
    """Rows (measure, direction, tau, low, high, n_systems): Kendall's tau-b between each measure (oriented) and the
    human score. `scores`: DataFrame with system, score, low, high (the design's standings); `reference`: the
    reference system's name as the tables' columns give it."""
    scores = scores.set_index("system")
    rng = np.random.default_rng(seed)
    rows = []
    for m, table in tables.items():
        direction = study.METRIC_DIRECTION.get(m, "higher")
        systems = [s for s in table.columns if s in scores.index and np.isfinite(scores.at[s, "score"])]
        part = table[systems]
        ref = systems.index(reference) if reference in systems else None
        score = scores.loc[systems, "score"].to_numpy(float)
        spread = ((scores.loc[systems, "high"] - scores.loc[systems, "low"]) / (2 * Z95)).to_numpy(float)
        spread = np.where(np.isfinite(spread), spread, 0.0)
        if part.empty or len(systems) < MIN_SYSTEMS:
            rows.append(
                dict(measure=m, direction=direction, tau=np.nan, low=np.nan, high=np.nan, n_systems=len(systems))
            )
            continue
        point = orient(_means(part, np.arange(len(part))[None])[0], direction, ref)
        boot = orient(_means(part, rng.integers(0, len(part), (n_boot, len(part)))), direction, ref)
        drawn = score + spread * rng.standard_normal((n_boot, len(systems)))
        lo, hi = _interval(kendall_tau_b(boot, drawn))
        n = int(np.isfinite(point).sum())
        tau = float(kendall_tau_b(point, score)[0])
        rows.append(dict(measure=m, direction=direction, tau=tau, low=lo, high=hi, n_systems=n))
    return pd.DataFrame(rows, columns=["measure", "direction", "tau", "low", "high", "n_systems"])
