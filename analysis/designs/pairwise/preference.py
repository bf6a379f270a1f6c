"""Statistics of a pairwise preference test (pairs.csv, CONTRACTS §8).

Each answer compares two conditions of one item on a 5-level scale (2 = A clearly .. -2 = B clearly). Per pair of
conditions: wins, ties and losses counted for the condition preferred whichever side it was shown on, the share of
each answer level, and a two-sided sign test of wins against losses (ties dropped, as the sign test does), Holm-
corrected over the pairs. Across pairs: a Bradley-Terry model with Davidson's (1970) extension for ties,

    P(i over j) = pi_i / D,  P(tie) = nu sqrt(pi_i pi_j) / D,  D = pi_i + pi_j + nu sqrt(pi_i pi_j),

fitted by maximum likelihood, with strengths log(pi) reported relative to NAT (or the first condition), so that a
strength of -1 means e^-1 the odds of winning against NAT (a ridge of 1e-6 on the strengths keeps a condition that
never wins finite instead of running off to minus infinity). Its 95% intervals come from a bootstrap over raters
(raters resampled with replacement, all their answers kept together), because one rater's answers are not
independent. Without ties in the data the tie parameter is left out (nu = 0: the plain Bradley-Terry model, which
is a logistic regression on +-1 indicator columns).
"""

import math
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import stats as sps

from moglow_eval.core import pair_posterior, study

from ...data.load import AnalysisError, read_export
from . import elo_ranks, separation

REQUIRED = ("rater_id", "item", "clip_a", "clip_b", "condition_a", "condition_b", "preference", "role")
ROLES = ("test", "catch")
LEVELS = (2, 1, 0, -1, -2)
BAD = study.CATCH
RIDGE = 1e-6  # on the log strengths: a condition that never wins stays finite (about -15)


# ---------------------------------------------------------------------------------------------- file
def load_pairs(path):
    """Read and check a pairs.csv export of a pairwise preference test (CONTRACTS §8).

    Parameters
    ----------
    path : str or Path
        The export: columns rater_id, item, clip_a, clip_b, condition_a, condition_b, preference and role.

    Returns
    -------
    DataFrame
        One row per answer, indexed by its line number in the file; preference an integer -2..2 (2 = A clearly,
        -2 = B clearly), role "test" or "catch" (lower-cased).

    Raises
    ------
    AnalysisError
        One line naming the file and line for each problem: missing columns, empty fields, a preference that is
        not an integer -2..2, an unknown role, the same condition on both sides, the same clip twice, a repeated
        comparison by one rater, no test rows.
    """
    path, df = read_preferences(path, REQUIRED)
    same = df["condition_a"] == df["condition_b"]
    if same.any():
        line = same.idxmax()
        raise AnalysisError(f"{path}:{line}: condition {df.at[line, 'condition_a']} on both sides of a pair")
    same = df["clip_a"] == df["clip_b"]
    if same.any():
        raise AnalysisError(f"{path}:{same.idxmax()}: clip {df.at[same.idxmax(), 'clip_a']} on both sides of a pair")
    lo = np.where(df["clip_a"] < df["clip_b"], df["clip_a"], df["clip_b"])
    hi = np.where(df["clip_a"] < df["clip_b"], df["clip_b"], df["clip_a"])
    key = pd.Series(list(zip(df["rater_id"], lo, hi)), index=df.index)
    dup = key.duplicated()
    if dup.any():
        line = dup.idxmax()
        first = key[key == key[line]].index[0]
        k = df.index.get_loc(line)
        raise AnalysisError(
            f"{path}:{line}: rater {df.at[line, 'rater_id']} compared clips {lo[k]} and {hi[k]} "
            f"twice (first at line {first})"
        )
    if not (df["role"] == "test").any():
        raise AnalysisError(f"{path}: no test answers (every row is a catch trial)")
    return df


def read_preferences(path, required):
    """(path, DataFrame) of an export of preferences (pairwise, appropriateness): the `required` columns, the
    preference an integer -2..2 and the role test or catch (lower-cased), or one AnalysisError naming the line."""
    path, df = read_export(path, required, "answers", strip=True)
    ok = df["preference"].isin([str(v) for v in LEVELS] + ["+1", "+2"])
    if not ok.all():
        line = (~ok).idxmax()
        raise AnalysisError(f"{path}:{line}: preference {df.at[line, 'preference']!r} is not an integer -2..2")
    df["preference"] = df["preference"].astype(int)
    df["role"] = df["role"].str.lower()
    bad_role = ~df["role"].isin(ROLES)
    if bad_role.any():
        line = bad_role.idxmax()
        raise AnalysisError(f"{path}:{line}: unknown role {df.at[line, 'role']!r} (expected test or catch)")
    return path, df


# ---------------------------------------------------------------------------------------------- exclusion
def failed_raters(df):
    """Raters excluded (study.excluded_raters) for preferring the BAD clip of catch pairs (either level)."""
    c = df[df["role"] == "catch"]
    fail = study.pair_catch_failed(c["condition_a"], c["condition_b"], c["preference"])
    return study.excluded_raters(zip(c["rater_id"].tolist(), fail.tolist()))


# ---------------------------------------------------------------------------------------------- counts
def oriented(df):
    """The test rows with each pair put in alphabetical order: columns rater_id, item, first, second, pref
    (positive = `first` preferred)."""
    t = df[df["role"] == "test"]
    swap = (t["condition_a"] > t["condition_b"]).to_numpy()
    return pd.DataFrame(
        {
            "rater_id": t["rater_id"].to_numpy(),
            "item": t["item"].to_numpy(),
            "first": np.where(swap, t["condition_b"], t["condition_a"]),
            "second": np.where(swap, t["condition_a"], t["condition_b"]),
            "pref": np.where(swap, -t["preference"], t["preference"]).astype(int),
        },
        index=t.index,
    )


def pair_counts(o, alpha=0.05):
    """One row per pair of conditions (condition_a < condition_b): wins_a, wins_b, ties, n, the share of each
    answer level (share_a_clearly .. share_b_clearly), and the two-sided sign test p with its Holm correction."""
    rows = []
    for (a, b), g in o.groupby(["first", "second"], sort=True):
        p = g["pref"].to_numpy()
        wins_a, wins_b, ties = int((p > 0).sum()), int((p < 0).sum()), int((p == 0).sum())
        n_sign = wins_a + wins_b
        sign_p = float(sps.binomtest(wins_a, n_sign, 0.5).pvalue) if n_sign else math.nan
        rows.append(
            {
                "condition_a": a,
                "condition_b": b,
                "wins_a": wins_a,
                "wins_b": wins_b,
                "ties": ties,
                "n": int(len(p)),
                "share_a": wins_a / len(p),
                "share_tie": ties / len(p),
                "share_b": wins_b / len(p),
                **{
                    f"share_{name}": float((p == level).mean())
                    for name, level in zip(("a_clearly", "a_slightly", "none", "b_slightly", "b_clearly"), LEVELS)
                },
                "p": sign_p,
            }
        )
    out = pd.DataFrame(rows)
    from ...stats.anova import holm

    ok = out["p"].notna().to_numpy() if len(out) else np.zeros(0, bool)
    out["p_holm"] = np.nan
    if ok.any():
        out.loc[ok, "p_holm"] = holm(out.loc[ok, "p"].to_numpy())
    out["reject"] = out["p_holm"] < alpha
    return out


# ---------------------------------------------------------------------------------------------- Bradley-Terry
def _tables(o, conds):
    """Per rater, per ordered pair (i < j): [wins of i, wins of j, ties] as an array [R, P, 3], plus the pairs."""
    idx = {c: k for k, c in enumerate(conds)}
    pairs = list(combinations(range(len(conds)), 2))
    pos = {p: k for k, p in enumerate(pairs)}
    raters, r_codes = np.unique(o["rater_id"].to_numpy(), return_inverse=True)
    t = np.zeros((len(raters), len(pairs), 3))
    i = o["first"].map(idx).to_numpy()
    j = o["second"].map(idx).to_numpy()
    p = o["pref"].to_numpy()
    col = np.where(p > 0, 0, np.where(p < 0, 1, 2))
    np.add.at(t, (r_codes, [pos[(a, b)] for a, b in zip(i, j)], col), 1)
    return t, np.array(pairs, dtype=int)


def _outcome_map(pairs, k, ref, ties):
    """A [P, K, m]: how the logits of each pair's K outcomes (first wins, second wins, and with ties a tie) depend
    on the m free parameters (the strengths but the reference's, then log nu). P(outcome) = softmax(A @ x)."""
    col = {c: n for n, c in enumerate(c for c in range(k) if c != ref)}
    A = np.zeros((len(pairs), 2 + ties, k - 1 + ties))
    for p, (i, j) in enumerate(pairs):
        for c, row in ((i, 0), (j, 1)):
            if c in col:
                A[p, row, col[c]] = 1.0
                if ties:
                    A[p, 2, col[c]] = 0.5  # the tie's logit: log nu + (theta_i + theta_j) / 2
        if ties:
            A[p, 2, -1] = 1.0
    return A


def _newton(counts, A, ridge, x0, max_iter=200, offset=0.0):
    """Maximum likelihood for a batch of count tables at once: counts [B, P, K], start x0 [m], `offset` added to
    the logits [P, K] (a tie parameter held fixed). The negative log-likelihood is convex in the parameters (a
    log-sum-exp of affine logits less a linear term) and the ridge makes it strictly so, so damped Newton steps
    reach the one optimum. -> (x [B, m], nll [B], grad [B, m])."""
    n = counts.sum(axis=2)

    def evaluate(x):
        logits = np.einsum("pkm,bm->bpk", A, x) + offset
        lse = np.logaddexp.reduce(logits, axis=2)
        nll = (n * lse - (counts * logits).sum(axis=2)).sum(axis=1) + (ridge * x**2).sum(axis=1)
        prob = np.exp(logits - lse[..., None])
        grad = np.einsum("bpk,pkm->bm", n[..., None] * prob - counts, A) + 2 * ridge * x
        return nll, grad, prob

    x = np.broadcast_to(np.asarray(x0, dtype=float), (len(counts), A.shape[2])).copy()
    nll, grad, prob = evaluate(x)
    for _ in range(max_iter):
        todo = np.max(np.abs(grad), axis=1) > 1e-9
        if not todo.any():
            break
        # Hessian: sum over pairs of n A' (diag(p) - p p') A, plus the ridge.
        outer = prob[..., :, None] * prob[..., None, :]
        cov = n[..., None, None] * (prob[..., :, None] * np.eye(prob.shape[2]) - outer)
        hess = np.einsum("pkm,bpkl,pln->bmn", A, cov, A) + np.diag(2 * ridge)
        step = np.linalg.solve(hess, grad[..., None])[..., 0]
        step[~todo] = 0.0
        t = np.ones(len(x))
        for _ in range(30):  # halve the step where it does not lower the objective
            new = x - t[:, None] * step
            new_nll, new_grad, new_prob = evaluate(new)
            worse = new_nll > nll + 1e-12 * np.abs(nll)
            if not worse.any():
                break
            t[worse] /= 2
        x, nll, grad, prob = new, new_nll, new_grad, new_prob
    return x, nll, grad


def fit_bradley_terry(counts, pairs, conds, reference=None, ties=None, x0=None, fixed_nu=None):
    """ML fit on pair counts [P, 3] (wins of the first, wins of the second, ties), or on a batch of them
    [B, P, 3] (the bootstrap) -> {"strengths": {cond: log strength, reference 0}, "nu": tie parameter or 0,
    "log_likelihood", "converged"}, or a list of those for a batch; `x0`: starting parameters (a bootstrap starts
    from the full fit's "params"); `fixed_nu`: the tie parameter held at this value (separation.py), not fitted."""
    k = len(conds)
    ref = conds.index(reference) if reference in conds else 0
    batch = np.asarray(counts, dtype=float)
    single = batch.ndim == 2
    batch = batch[None] if single else batch
    ties = bool(batch[..., 2].sum() > 0) if ties is None else ties
    A = _outcome_map(pairs, k, ref, ties)
    offset = 0.0
    if ties and fixed_nu is not None:  # log nu moves from the parameters into the tie's logit as a constant
        A, offset = A[..., :-1], np.array([0.0, 0.0, math.log(fixed_nu)])
    free_nu = ties and fixed_nu is None
    ridge = np.r_[np.full(k - 1, RIDGE), np.zeros(int(free_nu))]
    start = np.zeros(k - 1 + free_nu) if x0 is None else x0
    x, nll, grad = _newton(batch[..., : 2 + ties], A, ridge, start, offset=offset)
    free = [c for c in range(k) if c != ref]
    fits = []
    for b in range(len(batch)):
        theta = np.zeros(k)
        theta[free] = x[b, : k - 1]
        fits.append(
            {
                "strengths": {c: float(theta[n]) for n, c in enumerate(conds)},
                "nu": float(math.exp(x[b, -1])) if free_nu else (float(fixed_nu) if ties else 0.0),
                "log_likelihood": -float(nll[b] - (ridge * x[b] ** 2).sum()),
                "converged": bool(np.max(np.abs(grad[b]), initial=0.0) < 1e-4),
                "reference": conds[ref],
                "params": x[b],
            }
        )
    return fits[0] if single else fits


def bradley_terry(o, n_boot=1000, seed=0, level=0.95, reference=None):
    """The Davidson-Bradley-Terry fit on the oriented test rows, with percentile intervals from a bootstrap over
    raters.

    Parameters
    ----------
    o : DataFrame
        The oriented test rows (`oriented`): rater_id, item, first, second, pref (positive = first preferred).
    n_boot : int
        The number of bootstrap resamples of the raters.
    seed : int
        The seed of the resampling.
    level : float
        The coverage of the intervals.
    reference : str or None
        The condition whose strength is 0 (`analysis.report --reference`); None: NAT, or else the first.

    Returns
    -------
    dict
        strengths {cond: log strength relative to the reference}, ci {cond: [low, high]}, nu (the tie
        parameter, 0 without ties in the data; separation.NU_FIXED where the data cannot estimate it), reference,
        log_likelihood, converged (False also where no maximum likelihood exists: separated votes, or a tie
        parameter the data cannot estimate), separated, nu_estimable (separation.check), n_boot, seed, level and
        method; and for elo_ranks.py (not in stats.json) boot, the resamples' strengths [n_boot, K] in conds
        order, conds, and tables/pairs, the per-rater counts behind them.

    Notes
    -----
    A rater's answers are not independent, so the bootstrap resamples raters with all their answers; every
    resample is fitted at once.
    """
    conds = sorted(set(o["first"]) | set(o["second"]))
    if reference is not None and reference not in conds:
        raise AnalysisError(f"--reference {reference}: no such condition in the test rows ({', '.join(conds)})")
    reference = reference or pair_posterior.elo_reference(conds)  # the dashboard's anchor too
    tables, pairs = _tables(o, conds)
    total = tables.sum(axis=0)
    ties = bool(total[:, 2].sum() > 0)
    sep = separation.check(total, pairs, len(conds))
    fixed_nu = None if sep["nu_estimable"] else separation.NU_FIXED
    fit = fit_bradley_terry(total, pairs, conds, reference, ties, fixed_nu=fixed_nu)
    # No maximum likelihood where the votes are separated or the tie parameter runs off: the fit is the ridge's.
    fit["converged"] = fit["converged"] and not sep["separated"] and sep["nu_estimable"]
    rng = np.random.default_rng(seed)
    n_r = tables.shape[0]
    # Each resample's counts: how often each rater was drawn, times that rater's table. All fits run at once.
    weights = np.stack([np.bincount(rng.integers(0, n_r, n_r), minlength=n_r) for _ in range(n_boot)]).astype(float)
    resampled = np.einsum("br,rpk->bpk", weights, tables)
    fits = fit_bradley_terry(resampled, pairs, conds, reference, ties, x0=fit["params"], fixed_nu=fixed_nu)
    boot = np.array([[f["strengths"][x] for x in conds] for f in fits]).reshape(n_boot, len(conds))
    lo, hi = 100 * (1 - level) / 2, 100 * (1 + level) / 2
    ci = {c: [float(np.percentile(boot[:, n], lo)), float(np.percentile(boot[:, n], hi))] for n, c in enumerate(conds)}
    fit.pop("params")
    return {
        **fit,
        "ci": ci,
        "boot": boot,
        "conds": conds,
        "tables": tables,
        "pairs": pairs,
        "n_boot": n_boot,
        "seed": seed,
        "level": level,
        "separated": sep["separated"],
        "nu_estimable": sep["nu_estimable"],
        "method": (
            "Bradley-Terry with Davidson's tie parameter, maximum likelihood"
            if ties
            else "Bradley-Terry (no ties in the data), maximum likelihood"
        )
        + "; percentile intervals from a bootstrap over raters",
    }


def analyse(df, n_boot=1000, seed=0, alpha=0.05, reference=None, margin_elo=0.0):
    """All pairwise statistics of the test rows of `df` (catch rows never enter them).

    Parameters
    ----------
    df : DataFrame
        Answers as `load_pairs` returns them.
    n_boot : int
        The number of bootstrap resamples behind the Bradley-Terry intervals.
    seed : int
        The seed of that bootstrap.
    alpha : float
        The level at which the Holm-corrected sign tests reject.
    reference : str or None
        The condition at strength 0 and Elo 1000; None: NAT, or else the first.
    margin_elo : float
        The indifference margin of the ranking's groups (elo_ranks.rank_table; 0: off).

    Returns
    -------
    dict
        n_test_answers, n_raters, n_items; pairs, a DataFrame with one row per pair of conditions (wins, ties,
        the share of each answer level, the sign test p and its Holm correction); bradley_terry, as from
        `bradley_terry`; ranking (elo_ranks.rank_table: Elo, rank intervals, groups); reliability
        (elo_ranks.split_half, None with fewer than 4 raters or 3 conditions).

    Raises
    ------
    AnalysisError
        The test rows compare fewer than 2 conditions.
    """
    o = oriented(df)
    conds = sorted(set(o["first"]) | set(o["second"]))
    if len(conds) < 2:
        raise AnalysisError(f"the test rows compare {len(conds)} condition; comparisons need at least 2")
    counts = pair_counts(o, alpha)
    bt = bradley_terry(o, n_boot=n_boot, seed=seed, reference=reference)
    ties = bool(bt["nu"] > 0)

    def fit(batch):
        fixed = None if bt["nu_estimable"] else bt["nu"]
        return fit_bradley_terry(batch, bt["pairs"], conds, bt["reference"], ties, fixed_nu=fixed)

    return {
        "n_test_answers": int(len(o)),
        "n_raters": int(o["rater_id"].nunique()),
        "n_items": int(o["item"].nunique()),
        "pairs": counts,
        "bradley_terry": bt,
        "ranking": elo_ranks.rank_table(
            bt["strengths"], bt["boot"], conds, bt["reference"], bt["level"], elo_ranks.unbounded(counts), margin_elo
        ),
        "reliability": elo_ranks.split_half(bt["tables"], bt["pairs"], conds, fit, seed=seed),
    }
