"""The style factor of an acr study whose clips were drawn in more than one style (manifest and export `style`,
CONTRACTS §4, §6): condition × style.

- the mean of every (condition, style) cell with its t interval;
- a two-way ANOVA  rating ~ condition * style  with type II sums of squares (statsmodels' ols and anova_lm): the
  main effects each adjusted for the other, the interaction for both; in a balanced design type II and type III
  agree, and the interaction's test is the same under either;
- the linear mixed model  rating ~ condition * style + (1|rater) + (1|clip)  (treatment coding: the reference
  condition and the first style the baseline), fitted by the engine of `rating_models.mixed_model`, with a Wald
  chi-square test of every interaction effect at once;
- a figure: the cell means with their intervals by condition, one line per style.

Pure functions on the long table of test ratings returning dicts; the figure writes one PNG.
"""

import numpy as np
import pandas as pd
from scipy import linalg
from scipy import stats as sps

from moglow_eval.core.study import condition_order

from .anova import group_summary
from .rating_models import ModelUndefined, random_effects_problem

STYLE = "style"
DEFAULT_STYLE = "stick"  # the baseline style when present (the built-in study's drawing)


def styles_in(test) -> list[str]:
    """The distinct non-empty styles of the rows, the default style first, or [] without a style column."""
    if STYLE not in test.columns:
        return []
    found = sorted({str(s) for s in test[STYLE].dropna() if str(s).strip()})
    return sorted(found, key=lambda s: s != DEFAULT_STYLE)


def cell_means(test, level=0.95) -> pd.DataFrame:
    """One row per (condition, style) with ratings, conditions in their order and the default style first: n,
    mean, sd and the t interval (stats.group_summary's; NaN for a single rating)."""
    cells = group_summary(test.assign(rating=test["rating"].astype(float)), between=["condition", STYLE], level=level)
    cells = cells.reset_index().rename(columns={"t_low": "ci_low", "t_high": "ci_high"})
    styles = styles_in(test)
    cells = cells[cells[STYLE].isin(styles)]
    rank = {c: i for i, c in enumerate(condition_order(test["condition"]))}
    cells = cells.assign(_c=cells["condition"].map(rank), _s=cells[STYLE].map(styles.index))
    cells = cells.sort_values(["_c", "_s"])
    return cells[["condition", STYLE, "n", "mean", "sd", "ci_low", "ci_high"]].reset_index(drop=True)


def two_way_anova(test) -> dict:
    """rating ~ C(condition) * C(style), type II sums of squares: {"type", "terms": {TERM: {df, sum_sq, F, p}},
    "residual": {df, sum_sq}}, or {"undefined": why} when the data leave it without a result."""
    import statsmodels.formula.api as smf
    from statsmodels.stats.anova import anova_lm

    d = pd.DataFrame({"y": test["rating"].astype(float), "c": test["condition"], "s": test[STYLE]})
    n_cells = d.groupby(["c", "s"]).ngroups
    if n_cells < d["c"].nunique() * d["s"].nunique():
        return {"type": "II", "undefined": "a (condition, style) cell has no ratings: interaction not estimable"}
    if len(d) <= n_cells:
        return {"type": "II", "undefined": "no more ratings than (condition, style) cells: no residual variance"}
    fit = smf.ols("y ~ C(c) * C(s)", data=d).fit()
    if not fit.ssr > 1e-12 * max(1.0, float(((d["y"] - d["y"].mean()) ** 2).sum())):
        return {"type": "II", "undefined": "no variance within cells: test undefined"}
    table = anova_lm(fit, typ=2)
    names = {"C(c)": "condition", "C(s)": "style", "C(c):C(s)": "condition:style"}
    terms = {
        names[k]: {"df": int(r["df"]), "sum_sq": float(r["sum_sq"]), "F": float(r["F"]), "p": float(r["PR(>F)"])}
        for k, r in table.iterrows()
        if k in names
    }
    res = table.loc["Residual"]
    return {"type": "II", "terms": terms, "residual": {"df": int(res["df"]), "sum_sq": float(res["sum_sq"])}}


def interaction_design(test, reference, styles):
    """(X, names) of  condition * style  in treatment coding against `reference` and styles[0]."""
    conds = [reference, *[c for c in sorted(test["condition"].unique()) if c != reference]]
    c, s = test["condition"].to_numpy(), test[STYLE].to_numpy()
    cols, names = [np.ones(len(test))], ["Intercept"]
    for k in conds[1:]:
        cols.append((c == k).astype(float))
        names.append(f"condition[T.{k}]")
    for st in styles[1:]:
        cols.append((s == st).astype(float))
        names.append(f"style[T.{st}]")
    for k in conds[1:]:
        for st in styles[1:]:
            cols.append(((c == k) & (s == st)).astype(float))
            names.append(f"condition[T.{k}]:style[T.{st}]")
    return np.column_stack(cols), names


def mixed_model_style(test, reference=None) -> dict:
    """Linear mixed model  rating ~ condition * style + (1|rater_id) + (1|clip_id), REML, as
    `rating_models.mixed_model` (the same engine: Satterthwaite t tests per effect), plus "interaction_test": a
    Wald chi-square of every condition:style effect at once (df = their number). ModelUndefined as there, with
    the cells (condition, style) in place of the conditions."""
    from .mixed import fit_crossed

    styles = styles_in(test)
    cells = test["condition"].astype(str) + "\x00" + test[STYLE].astype(str)
    problem = random_effects_problem(test.assign(_cell=cells), between="_cell")
    if problem:
        raise ModelUndefined(problem.replace("condition", "condition and style"))
    levels = sorted(test["condition"].unique())
    if reference is None or reference not in levels:
        reference = levels[0]
    X, names = interaction_design(test, reference, styles)
    if np.linalg.matrix_rank(X) < X.shape[1]:
        raise ModelUndefined("a (condition, style) cell has no ratings: the interaction is not estimable")
    y = test["rating"].to_numpy(dtype=float)
    rater, clip = pd.factorize(test["rater_id"])[0], pd.factorize(test["clip_id"])[0]
    fit = fit_crossed(y, X, rater, clip, names, with_cov=True)
    cov = fit.pop("covariance")
    idx = [i for i, n in enumerate(names) if ":" in n]
    b = np.array([fit["fixed_effects"][names[i]] for i in idx])
    chi2 = float(b @ linalg.solve(cov[np.ix_(idx, idx)], b))
    return {
        "formula": "rating ~ condition * style + (1|rater_id) + (1|clip_id)",
        "method": "REML, crossed random intercepts; t tests on Satterthwaite df; Wald chi-square for the interaction",
        "reference": reference,
        "style_reference": styles[0],
        **fit,
        "interaction_test": {"chi2": chi2, "df": len(idx), "p": float(sps.chi2.sf(chi2, len(idx)))},
        "n": int(len(test)),
        "warnings": [] if fit["converged"] else ["optimiser did not report convergence"],
    }


def style_analysis(test, reference=None) -> dict | None:
    """The style factor of these test rows, or None when they hold fewer than two styles."""
    styles = styles_in(test)
    if len(styles) < 2:
        return None
    test = test[test[STYLE].isin(styles)]
    try:
        mixed = mixed_model_style(test, reference)
    except ModelUndefined as exc:
        mixed = {"undefined": str(exc), "fixed_effects": {}}
    except (np.linalg.LinAlgError, ValueError) as exc:
        mixed = {"error": f"the fit failed numerically ({type(exc).__name__})", "fixed_effects": {}}
    return {"styles": styles, "cells": cell_means(test), "anova": two_way_anova(test), "mixed_model": mixed}


def style_json(res) -> dict:
    cells = res["cells"].replace({np.nan: None})
    return {
        "styles": res["styles"],
        "cell_means": cells.to_dict(orient="records"),
        "anova": res["anova"],
        "mixed_model": res["mixed_model"],
    }


def style_figure(res, path, reference_label=None):
    """Cell means with their 95% t intervals: conditions along x, one line and colour per style."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = res["cells"]
    conds = list(dict.fromkeys(cells["condition"]))
    fig, ax = plt.subplots(figsize=(1.6 + 1.2 * len(conds), 3.6))
    k = len(res["styles"])
    for j, s in enumerate(res["styles"]):
        c = cells[cells["style"] == s].set_index("condition").reindex(conds)
        x = np.arange(len(conds)) + (j - (k - 1) / 2) * 0.12
        err = np.vstack([c["mean"] - c["ci_low"], c["ci_high"] - c["mean"]])
        ax.errorbar(x, c["mean"], yerr=np.nan_to_num(err), marker="o", capsize=3, label=str(s))
    ax.set_xticks(np.arange(len(conds)), conds)
    ax.set_ylim(1, 5)
    ax.set_ylabel("mean rating (95% t interval)")
    ax.set_title("Condition × style")
    ax.legend(title="style", frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
