"""How far raters agree on a clip's rating (acr and parallel designs): Krippendorff's alpha and the ICC.

- **Krippendorff's alpha, interval metric** (Krippendorff 2004): 1 - observed / expected disagreement, over
  every pair of ratings of one clip (observed) and every pair of ratings at all (expected). It takes the missing
  cells of a study where each rater sees only some clips as they are. The point estimate is the `krippendorff`
  library's; its interval comes from a bootstrap over clips (Hayes & Krippendorff 2007 resample the units), for
  which alpha is computed here in closed form from per-clip sums, as the library would take a second per resample
  (the test checks the two agree).
- **ICC** (McGraw & Wong 1996): the share of a rating's variance that belongs to the clip, from the variance
  components of the crossed random-effects model (rater and clip intercepts, analysis.stats.mixed.fit_crossed, REML).
  ICC(A,1) = clip / (clip + rater + residual) is the absolute agreement of one rater's rating; ICC(A,k), with k the
  mean number of ratings per clip, that of a clip's mean rating. On a complete rater x clip table these equal
  pingouin's ICC2 and ICC2k (its ANOVA estimates; the test checks it); unlike those, they also hold for the
  incomplete tables of a crowd study. The interval comes from a bootstrap over raters, as elsewhere in the report.
"""

import numpy as np
import pandas as pd

from ..data.filtering import only_test_rows
from .mixed import fit_crossed

FIT_ERRORS = (ValueError, ZeroDivisionError, FloatingPointError, np.linalg.LinAlgError)
ICC_BOOT_MAX = 100  # REML refits of an incomplete table; each takes a few hundredths of a second


def _codes(series):
    return pd.factorize(series, sort=True)[0]


def alpha_from_sums(n_u, s_u, q_u):
    """Interval alpha from per-unit counts, sums and sums of squares of the pairable values (units with at least
    two values); arrays may carry a leading batch axis. Returns nan where there is no variance at all."""
    n_u, s_u, q_u = (np.asarray(a, dtype=float) for a in (n_u, s_u, q_u))
    ok = n_u >= 2
    # sum over ordered pairs i != j within a unit of (x_i - x_j)^2 = 2 (m q - s^2)
    within = np.where(ok, 2 * (n_u * q_u - s_u**2) / np.where(ok, n_u - 1, 1), 0.0).sum(axis=-1)
    n = np.where(ok, n_u, 0).sum(axis=-1)
    s = np.where(ok, s_u, 0).sum(axis=-1)
    q = np.where(ok, q_u, 0).sum(axis=-1)
    d_o = within / n
    d_e = 2 * (n * q - s**2) / (n * (n - 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        return 1 - d_o / d_e


def krippendorff_alpha(df, unit="clip_id", value="rating", n_boot=1000, seed=0, level=0.95):
    """Krippendorff's alpha (interval) of `value` with `unit` as the unit rated and rater_id as the coder.

    Returns
    -------
    dict
        alpha (the library's), ci [low, high] (bootstrap over units), n_units (with two ratings or more),
        n_ratings, n_boot, seed, level, method; None with fewer than 2 units that have two ratings.
    """
    import krippendorff

    d = df[[unit, "rater_id", value]].dropna()
    n_u = d.groupby(unit)[value].size()
    units = n_u.index[n_u >= 2]
    if len(units) < 2 or d[value].nunique() < 2:  # alpha is 0/0 when every rating is the same
        return None
    d = d[d[unit].isin(units)]
    table = d.pivot_table(index="rater_id", columns=unit, values=value, aggfunc="mean")
    alpha = float(krippendorff.alpha(reliability_data=table.to_numpy(float), level_of_measurement="interval"))
    g = d.groupby(unit)[value]
    n, s, q = g.size().to_numpy(), g.sum().to_numpy(), g.apply(lambda x: float((x**2).sum())).to_numpy()
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, len(n), (n_boot, len(n)))
    boot = alpha_from_sums(n[pick], s[pick], q[pick])
    lo, hi = np.nanpercentile(boot, [100 * (1 - level) / 2, 100 * (1 + level) / 2])
    return {
        "alpha": alpha,
        "ci": [float(lo), float(hi)],
        "n_units": int(len(n)),
        "n_ratings": int(n.sum()),
        "n_boot": int(n_boot),
        "seed": int(seed),
        "level": level,
        "method": "Krippendorff's alpha, interval metric (krippendorff library); percentile interval from a "
        "bootstrap over clips",
    }


def _icc(y, rater, clip, k, start=None):
    """(ICC(A,1), ICC(A,k), the variance components); `start`: the components a resample's search begins from.

    ModelUndefined (fit_crossed's) where raters and clips fit every rating exactly: a bootstrap resample of a small
    study often is such a table."""
    if start is not None:  # as relative SDs, the model's own parameters
        start = [(start["rater"] / start["residual"]) ** 0.5, (start["clip"] / start["residual"]) ** 0.5]
    with np.errstate(
        divide="raise", invalid="raise"
    ):  # a degenerate fit raises (FIT_ERRORS) instead of warning its way to a NaN
        fit = fit_crossed(y, np.ones((len(y), 1)), rater, clip, ["(Intercept)"], tests=False, start=start)
        vc = fit["variance_components"]
    total = vc["clip"] + vc["rater"] + vc["residual"]
    return vc["clip"] / total, vc["clip"] / (vc["clip"] + (vc["rater"] + vc["residual"]) / k), vc


def _icc_complete(d, unit, value):
    """pingouin's ICC2 and ICC2k with their F-based intervals, for a complete rater x unit table."""
    import warnings

    import pingouin

    with warnings.catch_warnings():  # pingouin 0.7 calls pandas APIs that pandas 3 deprecates; the values hold
        warnings.simplefilter("ignore")
        t = pingouin.intraclass_corr(d, targets=unit, raters="rater_id", ratings=value).set_index("Type")
    a1, ak = t.loc["ICC(A,1)"], t.loc["ICC(A,k)"]
    return {
        "icc_a1": float(a1["ICC"]),
        "icc_a1_ci": [float(v) for v in a1["CI95"]],
        "icc_ak": float(ak["ICC"]),
        "icc_ak_ci": [float(v) for v in ak["CI95"]],
        "method": "ICC(A,1) and ICC(A,k) (McGraw & Wong), two-way ANOVA on the complete rater x clip table "
        "(pingouin), with F-based 95% intervals",
    }


def _icc_bootstrap(y, rater, clip, k, n_boot, seed, level, start=None):
    """Percentile intervals of ICC(A,1), ICC(A,k) from resampling raters and clips at once, each draw a level of
    its own: both are random samples, and the clips' sampling is most of an ICC's uncertainty. Each resample's
    fit starts at `start` (the whole sample's variance components), near where it ends."""
    rng = np.random.default_rng(seed)
    by_r = [np.flatnonzero(rater == r) for r in range(rater.max() + 1)]
    n_c = clip.max() + 1
    boot = []
    for _ in range(n_boot):
        draw_r, draw_c = rng.integers(0, len(by_r), len(by_r)), rng.integers(0, n_c, n_c)
        idx = np.concatenate([by_r[r] for r in draw_r])
        r_code = np.repeat(np.arange(len(draw_r)), [len(by_r[r]) for r in draw_r])
        # Each row appears once per draw of its clip, coded by that draw's position in draw_c.
        times = np.bincount(draw_c, minlength=n_c)
        slots = np.argsort(draw_c, kind="stable")  # the draws' positions, grouped by clip
        first = np.concatenate([[0], np.cumsum(times)[:-1]])  # where each clip's group starts in `slots`
        rep = times[clip[idx]]
        idx, r_code = np.repeat(idx, rep), np.repeat(r_code, rep)
        j = np.arange(len(idx)) - np.repeat(np.cumsum(rep) - rep, rep)  # which draw of its clip this copy is
        c_code = pd.factorize(slots[first[clip[idx]] + j], sort=True)[0]
        if len(np.unique(r_code)) >= 2 and c_code.max() >= 1:
            try:
                boot.append(_icc(y[idx], r_code, c_code, k, start)[:2])
            except FIT_ERRORS:  # a degenerate resample (e.g. no residual variance left) has no ICC: skip it
                pass
    if not boot:  # no resample had an estimate: the interval is unknown, not made up
        return None, None, 0
    boot = np.array(boot).reshape(-1, 2)
    q = [100 * (1 - level) / 2, 100 * (1 + level) / 2]
    ci1, cik = ([float(v) for v in np.percentile(boot[:, j], q)] for j in (0, 1))
    return ci1, cik, len(boot)


def icc(df, unit="clip_id", value="rating", n_boot=ICC_BOOT_MAX, seed=0, level=0.95):
    """ICC(A,1) and ICC(A,k) of `value` per `unit`.

    Returns
    -------
    dict
        icc_a1, icc_a1_ci, icc_ak, icc_ak_ci, k (mean ratings per unit), complete (whether every rater rated
        every unit: then pingouin's ANOVA estimates and F intervals; else REML variance components and a
        bootstrap over raters and clips, at most ICC_BOOT_MAX resamples), n_boot, n_fitted (the resamples that
        had an estimate; bootstrapped only), seed, level, method; None with
        fewer than 3 raters or 3 units.
    """
    d = df[[unit, "rater_id", value]].dropna()
    d = d.groupby([unit, "rater_id"], as_index=False)[value].mean()  # a repeated rating counts once, averaged
    if d["rater_id"].nunique() < 3 or d[unit].nunique() < 3 or d[value].nunique() < 2:
        return None
    k = float(len(d) / d[unit].nunique())
    complete = len(d) == d["rater_id"].nunique() * d[unit].nunique()
    y = d[value].to_numpy(float)
    rater, clip = _codes(d["rater_id"]), _codes(d[unit])
    a1, ak, vc = _icc(y, rater, clip, k)
    out = {"k": k, "complete": bool(complete), "variance_components": {key: float(v) for key, v in vc.items()}}
    if complete:
        return {**out, **_icc_complete(d, unit, value), "n_boot": 0, "seed": int(seed), "level": 0.95}
    n_boot = min(n_boot, ICC_BOOT_MAX)
    ci1, cik, n_fitted = _icc_bootstrap(y, rater, clip, k, n_boot, seed, level, vc)
    return {
        **out,
        "icc_a1": float(a1),
        "icc_a1_ci": ci1,
        "icc_ak": float(ak),
        "icc_ak_ci": cik,
        "n_boot": int(n_boot),
        "n_fitted": int(n_fitted),
        "seed": int(seed),
        "level": level,
        "method": "ICC(A,1) and ICC(A,k) (McGraw & Wong) from REML variance components of crossed rater and "
        "clip intercepts (the table is incomplete); percentile intervals from a bootstrap over raters and clips "
        "(n_fitted of the n_boot resamples: one that raters and clips fit exactly has no estimate)",
    }


def agreement(df, unit="clip_id", value="rating", n_boot=1000, seed=0):
    """Both measures over the test rows: {"krippendorff": ..., "icc": ...}."""
    test = only_test_rows(df)
    measures = {  # the ICC's bootstrap refits a model per resample: at most ICC_BOOT_MAX of them
        "krippendorff": lambda: krippendorff_alpha(test, unit, value, n_boot=n_boot, seed=seed),
        "icc": lambda: icc(test, unit, value, n_boot=n_boot, seed=seed),
    }
    out = {}
    for name, measure in measures.items():
        try:
            out[name] = measure()
        except FIT_ERRORS:  # degenerate data (no variance within clips or at all): the measure is undefined
            out[name] = None
    return out


def agreement_text(ag) -> str:
    """One sentence for the report and the console."""
    parts = []
    ka, ic = ag.get("krippendorff"), ag.get("icc")
    if ka:
        parts.append(
            f"Krippendorff's alpha (interval) {ka['alpha']:.2f} [{ka['ci'][0]:.2f}, {ka['ci'][1]:.2f}] "
            f"over {ka['n_units']} clips"
        )
    if ic:

        def ci(v):  # None: no bootstrap resample had an estimate
            return "(no interval)" if v is None else f"[{v[0]:.2f}, {v[1]:.2f}]"

        parts.append(
            f"ICC(A,1) {ic['icc_a1']:.2f} {ci(ic['icc_a1_ci'])}, "
            f"ICC(A,k) of a clip's mean of k = {ic['k']:.1f} ratings {ic['icc_ak']:.2f} {ci(ic['icc_ak_ci'])}"
        )
    return ("Rater agreement: " + "; ".join(parts) + ".") if parts else "Rater agreement: too few raters or clips."
