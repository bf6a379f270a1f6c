"""Mixed-effects models of ratings on a scale: the linear mixed model and the cumulative-link (ordinal) mixed
model, each  rating ~ condition + (1|rater) + (1|clip), with the checks that say when the data cannot identify one.

Pure functions on the long table of ratings returning dicts; the fitting engines are mixed.py and ordinal.py.
"""

import math

import numpy as np
import pandas as pd
from scipy import stats as sps

from moglow_eval.core import study
from moglow_eval.core.study import condition_order

from .mixed import ModelUndefined, fit_crossed


def random_effects_problem(df, dv="rating", between="condition", rater="rater_id", clip="clip_id"):
    """Why  dv ~ between + (1|rater) + (1|clip)  cannot be fitted on these rows, or None. Each case would
    otherwise give numbers that look like results: a 0/0 residual variance, a rater variance from one rater,
    or a clip variance that is the condition effect itself (one clip per condition)."""
    if df[dv].nunique() < 2:
        return "no variance (every rating is the same): model undefined"
    if df[rater].nunique() < 2:
        return "a single rater: the rater variance cannot be estimated; model not fitted"
    if df.groupby(between, observed=True)[clip].nunique().max() < 2:
        return "one clip per condition: the clip variance is confounded with the condition; model not fitted"
    if df.groupby(between, observed=True)[dv].nunique().max() < 2:
        return "no variance within conditions (every condition's ratings are all the same): model undefined"
    return None


def mixed_model(df, dv="rating", between="condition", rater="rater_id", clip="clip_id", reference=None):
    """Linear mixed model  dv ~ between + (1|rater) + (1|clip)  with crossed random intercepts, fitted by REML.

    Parameters
    ----------
    df : DataFrame
        One row per test rating.
    dv : str
        The column of the ratings.
    between : str
        The column of the conditions.
    rater : str
        The column of the rater ids.
    clip : str
        The column of the clip ids.
    reference : str or None
        The condition the effects are measured against; None: NAT when present (effects read as "vs natural
        motion"), else the first condition alphabetically.

    Returns
    -------
    dict
        formula, method, reference; fixed_effects {Intercept, condition[T.X]: estimate} (treatment coding),
        std_errors, df (Satterthwaite), t, p_values, ci_low and ci_high (95%) per fixed effect;
        variance_components {rater, clip, residual}; condition_means (model-based); reml_log_likelihood,
        converged, n, n_raters, n_clips and warnings (the optimiser's, and variances the ratings do not identify).

    Raises
    ------
    ModelUndefined
        The rows cannot identify the model: no variance, a single rater, or one clip per condition.

    Notes
    -----
    The engine (analysis/stats/mixed.py) minimises lme4's profiled criterion from sufficient statistics; the tests
    check it against statsmodels' MixedLM. The fixed effects are tested with t tests on Satterthwaite degrees of
    freedom.
    """
    problem = random_effects_problem(df, dv, between, rater, clip)
    if problem:
        raise ModelUndefined(problem)
    levels = sorted(df[between].unique())
    if reference is None:
        reference = study.NATURAL if study.NATURAL in levels else levels[0]
    others = [c for c in levels if c != reference]
    cond = df[between].to_numpy()
    X = np.column_stack([np.ones(len(df))] + [(cond == c).astype(float) for c in others])
    names = ["Intercept"] + [f"{between}[T.{c}]" for c in others]
    rater_codes = pd.factorize(df[rater])[0]
    clip_codes = pd.factorize(df[clip])[0]
    fit = fit_crossed(df[dv].to_numpy(dtype=float), X, rater_codes, clip_codes, names)
    flat = fit.pop("flat_directions")  # said in the warnings, as stats.json carries them
    fe = fit["fixed_effects"]
    means = {reference: fe["Intercept"], **{c: fe["Intercept"] + fe[f"{between}[T.{c}]"] for c in others}}
    warnings = [] if fit["converged"] else ["optimiser did not report convergence"]
    if flat:
        warnings.append(
            f"the REML criterion is flat along {flat} direction(s) of the variances (the ratings do not identify "
            "them all); the Satterthwaite df leave those out"
        )
    return {
        "formula": f"{dv} ~ {between} + (1|{rater}) + (1|{clip})",
        "method": "REML, crossed random intercepts (profiled criterion, L-BFGS-B then Nelder-Mead polish); "
        "t tests on Satterthwaite df",
        "reference": reference,
        **fit,
        "condition_means": {c: means[c] for c in condition_order(means)},
        "n": int(len(df)),
        "n_raters": int(rater_codes.max() + 1),
        "n_clips": int(clip_codes.max() + 1),
        "warnings": warnings,
    }


# ---------------------------------------------------------------------------------------------- ordinal model
def ordinal_model(df, dv="rating", between="condition", rater="rater_id", clip="clip_id", reference=None, level=0.95):
    """Cumulative-link (logit) mixed model  factor(dv) ~ between + (1|rater) + (1|clip), fitted by ML with the
    Laplace approximation, as R's ordinal::clmm.

    Parameters
    ----------
    df : DataFrame
        One row per test rating.
    dv : str
        The column of the ratings.
    between : str
        The column of the conditions.
    rater : str
        The column of the rater ids.
    clip : str
        The column of the clip ids.
    reference : str or None
        The condition the effects are measured against; None: NAT when present (effects read as "vs natural
        motion"), else the first condition alphabetically.
    level : float
        The coverage of the odds ratios' intervals.

    Returns
    -------
    dict
        formula, method, reference, fixed_effects, std_errors, z, p_values (Wald), odds_ratios, or_ci_low,
        or_ci_high, thresholds, threshold_std_errors, sd_rater, sd_clip, log_likelihood, converged,
        fitted_distribution and observed_distribution {COND: {level: proportion}}, n, n_raters, n_clips and
        warnings.

    Raises
    ------
    ModelUndefined
        The rows cannot identify the model (as for `mixed_model`), a condition's ratings all sit in the top or
        bottom category (separation), or the estimates run off to infinity (quasi-separation).

    Notes
    -----
    Effects are log-odds of a higher rating against the reference, so exp(effect) is an odds ratio: 0.5 means
    half the odds of a rating above any cut point. Thresholds are named by adjacent observed levels ("1|2" ...
    "4|5" when every level occurs; an unused level has no cut point, as in clmm). The engine is
    analysis/stats/ordinal.py; the tests match it to clmm.
    """
    from .ordinal import fit_clmm, marginal_probabilities

    _check_ordinal_identified(df, dv, between, rater, clip)
    levels = sorted(df[between].unique())
    if reference is None:
        reference = study.NATURAL if study.NATURAL in levels else levels[0]
    others = [c for c in levels if c != reference]
    cond = df[between].to_numpy()
    X = np.column_stack([(cond == c).astype(float) for c in others])
    names = [f"{between}[T.{c}]" for c in others]
    y_codes, y_levels = pd.factorize(df[dv], sort=True)
    y_levels = [int(v) if float(v).is_integer() else v for v in y_levels]
    fit = fit_clmm(
        y_codes,
        X,
        pd.factorize(df[rater])[0],
        pd.factorize(df[clip])[0],
        names,
        len(y_levels),
        [str(v) for v in y_levels],
    )
    fit.pop("random_effects")
    b = np.array(list(fit["fixed_effects"].values()))
    se = np.array(list(fit["std_errors"].values()))
    th = np.array(list(fit["thresholds"].values()))
    _check_ordinal_estimates(fit, b, th)
    zq = sps.norm.ppf(0.5 + level / 2)
    probs = marginal_probabilities(th, np.array([0.0] + list(b)), math.hypot(fit["sd_rater"], fit["sd_clip"]))
    order = [reference] + others
    observed = pd.crosstab(df[between], df[dv], normalize="index").reindex(columns=y_levels, fill_value=0.0)
    with np.errstate(over="ignore"):  # an unidentified effect's interval overflows to inf (JSON null), no warning
        ors = [np.exp(b).tolist(), np.exp(b - zq * se).tolist(), np.exp(b + zq * se).tolist()]
    return {
        "formula": f"{dv} ~ {between} + (1|{rater}) + (1|{clip})  (cumulative logit)",
        "method": "ML, Laplace approximation, crossed random intercepts (as ordinal::clmm)",
        "reference": reference,
        **fit,
        "odds_ratios": dict(zip(names, ors[0])),
        "or_ci_low": dict(zip(names, ors[1])),
        "or_ci_high": dict(zip(names, ors[2])),
        "fitted_distribution": {
            c: dict(zip(map(str, y_levels), probs[order.index(c)].tolist())) for c in condition_order(levels)
        },
        "observed_distribution": {
            c: {str(k): float(v) for k, v in observed.loc[c].items()} for c in condition_order(levels)
        },
        "n": int(len(df)),
        "n_raters": int(df[rater].nunique()),
        "n_clips": int(df[clip].nunique()),
        "warnings": _ordinal_warnings(fit, se),
    }


def _check_ordinal_identified(df, dv, between, rater, clip):
    """Raise ModelUndefined where the ordinal model has no estimate before fitting it."""
    problem = random_effects_problem(df, dv, between, rater, clip)
    if problem:
        raise ModelUndefined(problem)
    lo, hi = df[dv].min(), df[dv].max()
    for c, g in df.groupby(between, observed=True)[dv]:
        if g.nunique() == 1 and g.iloc[0] in (lo, hi):
            # the likelihood rises forever as that condition's effect runs to +-infinity: no estimate exists
            raise ModelUndefined(
                f"every rating of {c} is {g.iloc[0]}, the {'top' if g.iloc[0] == hi else 'bottom'} "
                "category: its effect is infinite (separation); model not fitted"
            )


def _check_ordinal_estimates(fit, b, th):
    """Raise ModelUndefined where the fitted estimates ran off to infinity."""
    if (
        np.any(np.abs(b) > 15)
        or max(fit["sd_rater"], fit["sd_clip"]) > 20
        or np.ptp(th) > 60
        or not np.all(np.isfinite(b))
    ):
        # the likelihood keeps rising as an effect, an SD or the cut points run off to infinity (quasi-separation:
        # some condition, rater or clip sits in an end category), so no estimate or interval means anything
        raise ModelUndefined(
            "estimates run off to infinity (quasi-separation: ratings of some condition, rater "
            "or clip sit in an end category); model not identified"
        )


def _ordinal_warnings(fit, se):
    warnings = []
    if not fit["converged"]:
        warnings.append(f"optimiser did not converge (max |gradient| {fit['max_abs_gradient']:.2g})")
    if not np.all(np.isfinite(se)):
        warnings.append("the information matrix is singular: standard errors undefined")
    return warnings
