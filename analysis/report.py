"""`python -m analysis.report ratings.csv [--out report/]`: the paper's analysis and what reviewers ask now.

Writes OUT/stats.json (CONTRACTS.md §7), OUT/figures/*.png and OUT/report.html (figures embedded, opens
offline), and prints a summary table. Every statistic is computed on the kept test rows (after the catch-trial
rater exclusion) and again on all test rows ("without_exclusion").
"""

import base64
import html
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm import tqdm

from core import cli

from . import figures, stats
from .filtering import DEFAULT_THRESHOLD, exclude_raters, only_test_rows
from .load import AnalysisError, load_c2st, load_metrics, load_ratings

# The REML fit costs ~150 Cholesky factorisations of a (smaller of raters, clips)-square matrix; beyond this
# many levels it is skipped unless forced (1M ratings from 3,226 raters x 310 clips fit in ~10 s).
MIXED_MAX_LEVELS = 2000
# The ordinal fit works on every rating (no sufficient statistics exist for it): ~4 s for 50,000 ratings on a
# busy 2-core machine, twice per report, so beyond this many test ratings it is skipped unless asked for.
ORDINAL_MAX_RATINGS = 50_000


# ---------------------------------------------------------------------------------------------- analysis
def _fit_model(fit, test, enabled, flag, n_raters, n_clips, max_levels, max_ratings=None):
    """One random-effects model, or why it is not there: skipped by a flag or by size, undefined for the data
    (stats.ModelUndefined), or a numerical failure -- always a dict with 'fixed_effects', never an exception."""
    if not enabled:
        return {"skipped": flag, "fixed_effects": {}}
    if min(n_raters, n_clips) > max_levels:
        return {
            "skipped": f"{n_raters} raters and {n_clips} clips: both above --mixed-max-levels {max_levels}",
            "fixed_effects": {},
        }
    if max_ratings is not None and len(test) > max_ratings:
        return {"skipped": f"{len(test)} ratings: above --ordinal-max-ratings {max_ratings}", "fixed_effects": {}}
    try:
        return fit(test)
    except stats.ModelUndefined as exc:
        return {"undefined": str(exc), "fixed_effects": {}}
    except (np.linalg.LinAlgError, ValueError) as exc:  # a degenerate design is reported, not fatal
        return {
            "error": f"the fit failed numerically, too little data for this model? ({type(exc).__name__}: "
            f"{str(exc).splitlines()[0] if str(exc) else ''})",
            "fixed_effects": {},
        }


def undefined_tests(res):
    """{test: why it has no result} for every test that the data leave undefined (zero variance, one rater,
    one clip per condition, ...), so stats.json and the report say so instead of printing a number."""
    out = {}
    if res["anova"].get("undefined"):
        out["anova"] = res["anova"]["undefined"]
    if res["tukey"].attrs.get("undefined"):
        out["tukey"] = res["tukey"].attrs["undefined"]
    if res["kruskal"].get("undefined"):
        out["kruskal"] = res["kruskal"]["undefined"]
    mw = res["mannwhitney"]
    tied = [f"{a}-{b}" for a, b, p in zip(mw["group1"], mw["group2"], mw["p"]) if not np.isfinite(p)]
    if tied:
        out["mannwhitney"] = f"every rating of {', '.join(tied)} is the same: test undefined for that pair"
    for key in ("mixed", "ordinal"):
        if res[key].get("undefined"):
            out["mixed_model" if key == "mixed" else "ordinal_model"] = res[key]["undefined"]
    notes = []
    if res["n_raters"] < 2:
        notes.append("one rater: the intervals do not include rater variation")
    if res["clips"].groupby("condition").size().max() < 2:
        notes.append("one clip per condition: the intervals do not include clip variation")
    if notes:
        out["bootstrap"] = "; ".join(notes)
    if res["summary"]["n"].min() < 2:
        out["t_intervals"] = "a condition with a single rating has no t interval"
    return out


def analyse(
    test,
    *,
    n_boot=2000,
    seed=0,
    alpha=0.05,
    mixed=True,
    ordinal=True,
    mixed_max_levels=MIXED_MAX_LEVELS,
    ordinal_max_ratings=ORDINAL_MAX_RATINGS,
    metrics=None,
    progress=None,
):
    """All analyses of one set of test rows -> dict of tables and dicts (see to_json for the file layout)."""
    step = progress.update if progress is not None else (lambda n=1: None)
    conds = test["condition"].unique()
    if len(conds) < 2:
        raise AnalysisError(
            f"the test rows hold {len(conds)} condition ({', '.join(map(str, conds))}); comparisons need at least 2"
        )
    out = {
        "n_test_ratings": int(len(test)),
        "n_raters": int(test["rater_id"].nunique()),
        "n_clips": int(test["clip_id"].nunique()),
    }
    summary = stats.group_summary(test)
    out["histogram"] = stats.rating_histogram(test)
    out["clips"] = stats.per_clip_means(test)
    step()
    out["anova"] = stats.one_way_anova(test)
    out["tukey"] = stats.tukey_hsd(test, alpha=alpha)
    step()
    out["bootstrap"] = stats.cluster_bootstrap(test, n_boot=n_boot, seed=seed)
    out["summary"] = summary.join(out["bootstrap"]["means"][["boot_low", "boot_high", "boot_se"]])
    step()
    out["kruskal"] = stats.kruskal_wallis(test)
    out["mannwhitney"] = stats.pairwise_mannwhitney(test, alpha=alpha)
    step()
    sizes = (out["n_raters"], out["n_clips"], mixed_max_levels)
    out["mixed"] = _fit_model(stats.mixed_model, test, mixed, "--no-mixed", *sizes)
    out["ordinal"] = _fit_model(stats.ordinal_model, test, ordinal, "--no-ordinal", *sizes, ordinal_max_ratings)
    step()
    if metrics is not None:
        out["metrics"] = stats.metric_correlations(out["clips"], metrics)
    out["undefined"] = undefined_tests(out)
    return out


# ---------------------------------------------------------------------------------------------- stats.json
def _clean(x):
    """numpy scalars -> Python; NaN/inf -> None (JSON has neither)."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        x = float(x)
        return x if math.isfinite(x) else None
    return x


def _records(df):
    return df.to_dict(orient="records")


def section_json(res):
    s = res["summary"]
    boot = res["bootstrap"]
    out = {
        "n_test_ratings": res["n_test_ratings"],
        "n_raters": res["n_raters"],
        "n_clips": res["n_clips"],
        "condition_means": {c: s.at[c, "mean"] for c in s.index},
        "condition_counts": {c: int(s.at[c, "n"]) for c in s.index},
        "condition_summary": {c: {k: s.at[c, k] for k in s.columns if k != "n"} for c in s.index},
        "rating_histogram": {c: {str(k): int(v) for k, v in row.items()} for c, row in res["histogram"].iterrows()},
        "anova": res["anova"],
        "tukey": _records(
            res["tukey"][
                ["group1", "group2", "meandiff", "lower", "upper", "p_adj", "p_adj_bound", "reject", "se", "q"]
            ]
        ),
        "bootstrap": {
            "method": boot["method"],
            "n_boot": boot["n_boot"],
            "seed": boot["seed"],
            "level": boot["level"],
            "n_degenerate": boot["n_degenerate"],
            "differences": _records(boot["differences"]),
        },
        "kruskal": res["kruskal"],
        "mannwhitney": _records(res["mannwhitney"]),
        "mixed_model": res["mixed"],
        "ordinal_model": res["ordinal"],
        "undefined": res["undefined"],
        "per_clip_means": _records(
            res["clips"][["clip_id", "condition", "rank", "n", "mean", "sd", "ci_low", "ci_high"]]
        ),
    }
    if "metrics" in res:
        out["metric_correlations"] = _records(res["metrics"])
    return out


def to_json(counts, kept, everyone, meta):
    doc = {**meta, **counts, **section_json(kept)}
    if kept.get("c2st") is not None:
        doc["c2st"] = _records(kept["c2st"])
    doc["without_exclusion"] = section_json(everyone)
    return _clean(doc)


# ---------------------------------------------------------------------------------------------- console
def _p(p, bound=False):
    """A p-value as text; `bound`: p is an upper bound (a Tukey tail beyond what can be computed), "< 2e-40"."""
    if p is None or not np.isfinite(p):
        return "n/a"
    if bound:
        return f"<{p:.0e}"
    if p == 0:  # a tail below the smallest double
        return "<1e-300"
    return f"{p:.2e}" if p < 1e-4 else f"{p:.4f}"


def _peq(p):
    text = _p(p)
    return f"p {text[0]} {text[1:]}" if text.startswith("<") else f"p = {text}"


def console_summary(counts, kept, everyone):
    lines = [
        f"Ratings: {counts['n_ratings_total']} total, {counts['n_ratings_removed']} removed, "
        f"{counts['n_ratings_kept']} kept  (raters: {counts['n_raters_total']} total, "
        f"{counts['n_raters_excluded']} excluded for a catch rating >= {counts['threshold']})",
        "",
    ]
    s, s_all = kept["summary"], everyone["summary"]
    head = f"{'condition':<10}{'n':>7}{'mean':>8}{'95% CI (t)':>18}{'95% CI (bootstrap)':>22}{'mean, all raters':>18}"
    lines += [head, "-" * len(head)]
    for c in s.index:
        r = s.loc[c]
        all_mean = f"{s_all.at[c, 'mean']:.3f}" if c in s_all.index else "-"
        lines.append(
            f"{c:<10}{int(r['n']):>7}{r['mean']:>8.3f}{f'[{r.t_low:.3f}, {r.t_high:.3f}]':>18}"
            f"{f'[{r.boot_low:.3f}, {r.boot_high:.3f}]':>22}{all_mean:>18}"
        )
    a, kw, undef = kept["anova"], kept["kruskal"], kept["undefined"]
    lines += [
        "",
        f"One-way ANOVA: {undef['anova']}"
        if "anova" in undef
        else f"One-way ANOVA: F({a['df_between']}, {a['df_within']}) = {a['F']:.3f}, {_peq(a['p'])}",
        f"Kruskal-Wallis: {undef['kruskal']}"
        if "kruskal" in undef
        else f"Kruskal-Wallis: H({kw['df']}) = {kw['H']:.3f}, {_peq(kw['p'])}",
        "",
        f"{'Tukey HSD':<14}{'diff':>8}{'95% CI':>20}{'p adj':>11}{'MWU p (Holm)':>14}",
    ]
    mwu = kept["mannwhitney"].set_index(["group1", "group2"])
    for _, t in kept["tukey"].iterrows():
        pair = f"{t.group2}-{t.group1}"
        lines.append(
            f"{pair:<14}{t.meandiff:>8.3f}{f'[{t.lower:.3f}, {t.upper:.3f}]':>20}"
            f"{_p(t.p_adj, t.p_adj_bound):>11}{_p(mwu.at[(t.group1, t.group2), 'p_holm']):>14}"
            f"{'  *' if t.reject else ''}"
        )
    if "tukey" in undef:
        lines.append(f"Tukey HSD: {undef['tukey']}")
    m = kept["mixed"]
    if m.get("fixed_effects"):
        lines += ["", f"Mixed model {m['formula']} (reference {m['reference']}; t tests, Satterthwaite df):"]
        for k, v in m["fixed_effects"].items():
            lines.append(
                f"  {k:<22}{v:>8.3f}  [{m['ci_low'][k]:.3f}, {m['ci_high'][k]:.3f}]  "
                f"df {m['df'][k]:.1f}  {_peq(m['p_values'][k])}"
            )
        vc = m["variance_components"]
        lines.append(f"  variance: rater {vc['rater']:.3f}, clip {vc['clip']:.3f}, residual {vc['residual']:.3f}")
    else:
        lines += ["", f"Mixed model: {_why_not(m)}"]
    o = kept["ordinal"]
    if o.get("fixed_effects"):
        lines += ["", f"Ordinal mixed model {o['formula']} (reference {o['reference']}):"]
        for k, v in o["fixed_effects"].items():
            lines.append(
                f"  {k:<22}{v:>8.3f} log-odds  odds ratio {o['odds_ratios'][k]:.3f} "
                f"[{o['or_ci_low'][k]:.3f}, {o['or_ci_high'][k]:.3f}]  {_peq(o['p_values'][k])}"
            )
        lines.append(
            "  thresholds: "
            + ", ".join(f"{k} {v:.3f}" for k, v in o["thresholds"].items())
            + f"; SD rater {o['sd_rater']:.3f}, clip {o['sd_clip']:.3f}; converged: {o['converged']}"
        )
        lines += [f"  warning: {w}" for w in o["warnings"]]
    else:
        lines += ["", f"Ordinal mixed model: {_why_not(o)}"]
    return "\n".join(lines)


def _why_not(model):
    return model.get("skipped") or model.get("undefined") or model.get("error")


# ---------------------------------------------------------------------------------------------- report.html
CSS = """body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:980px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}h1{font-size:1.6em}h2{font-size:1.2em;margin-top:1.8em;
border-bottom:1px solid #ddd}table{border-collapse:collapse;margin:.6em 0;font-size:.88em}
td,th{border:1px solid #ddd;padding:3px 8px;text-align:right}th{background:#f5f5f5}td:first-child,
th:first-child{text-align:left}img{max-width:min(100%,780px)}.note{color:#555;font-size:.9em}.cols{display:flex;gap:2em;
flex-wrap:wrap}"""


def _fmt_table(df, pcols=()):
    df = df.copy()
    for c in df.columns:
        if c in pcols:
            df[c] = df[c].map(lambda v: _p(v))
        elif df[c].dtype.kind == "f":
            df[c] = df[c].map(lambda v: "" if not np.isfinite(v) else f"{v:.4f}")
    return df.to_html(border=0, escape=True, index=not isinstance(df.index, pd.RangeIndex))


def _img(path):
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(Path(path).stem)}" src="data:image/png;base64,{data}">'


def _mixed_html(m):
    if not m.get("fixed_effects"):
        return f"<p>Not fitted: {html.escape(str(_why_not(m)))}</p>"
    fe = pd.DataFrame(
        {
            "estimate": m["fixed_effects"],
            "std. error": m["std_errors"],
            "df": m["df"],
            "95% low": m["ci_low"],
            "95% high": m["ci_high"],
            "p": m["p_values"],
        }
    )
    vc = pd.DataFrame({"variance": m["variance_components"]})
    warn = f"<p class=note>Fit warnings: {html.escape('; '.join(m['warnings']))}</p>" if m["warnings"] else ""
    return (
        f"<p>{html.escape(m['formula'])}, {html.escape(m['method'])}; reference level "
        f"<b>{html.escape(m['reference'])}</b>; converged: {m['converged']}.</p>"
        f"<div class=cols>{_fmt_table(fe, ('p',))}{_fmt_table(vc)}</div>{warn}"
        "<p class=note>t tests and intervals on Satterthwaite degrees of freedom (as lmerTest).</p>"
    )


def _ordinal_html(o, fig=None):
    if not o.get("fixed_effects"):
        return f"<p>Not fitted: {html.escape(str(_why_not(o)))}</p>"
    fe = pd.DataFrame(
        {
            "log-odds": o["fixed_effects"],
            "std. error": o["std_errors"],
            "p": o["p_values"],
            "odds ratio": o["odds_ratios"],
            "OR 95% low": o["or_ci_low"],
            "OR 95% high": o["or_ci_high"],
        }
    )
    th = pd.DataFrame({"threshold": o["thresholds"], "std. error": o["threshold_std_errors"]})
    sd = pd.DataFrame({"SD": {"rater": o["sd_rater"], "clip": o["sd_clip"]}})
    warn = f"<p class=note>Fit warnings: {html.escape('; '.join(o['warnings']))}</p>" if o["warnings"] else ""
    return (
        f"<p>{html.escape(o['formula'])}, {html.escape(o['method'])}; reference level "
        f"<b>{html.escape(o['reference'])}</b>; log-likelihood {o['log_likelihood']:.3f}; converged: "
        f"{o['converged']}. An odds ratio below 1: lower odds of a higher rating than the reference.</p>"
        f"<div class=cols>{_fmt_table(fe, ('p',))}{_fmt_table(th)}{_fmt_table(sd)}</div>{warn}"
        + (
            f"<p>{_img(fig)}</p><p class=note>Bars: observed share of each rating; dots: the model's "
            "predicted distribution for a new rater on a new clip.</p>"
            if fig
            else ""
        )
    )


def _undefined_html(res):
    if not res["undefined"]:
        return ""
    items = "".join(f"<li>{html.escape(k)}: {html.escape(v)}</li>" for k, v in res["undefined"].items())
    return f"<p><b>Tests without a result on these data:</b></p><ul>{items}</ul>"


def _anova_text(res, digits=4):
    """(ANOVA sentence, Kruskal-Wallis sentence), or the reason each is undefined."""
    a, k, undef = res["anova"], res["kruskal"], res["undefined"]
    anova = (
        f"One-way ANOVA: {html.escape(undef['anova'])}."
        if "anova" in undef
        else f"One-way ANOVA: <b>F({a['df_between']}, {a['df_within']}) = {a['F']:.{digits}f}</b>, {_peq(a['p'])}, "
        f"η² = {a['eta_squared']:.3f}."
    )
    kruskal = (
        f"Kruskal–Wallis: {html.escape(undef['kruskal'])}."
        if "kruskal" in undef
        else f"Kruskal–Wallis: H({k['df']}) = {k['H']:.3f}, {_peq(k['p'])}."
    )
    return anova, kruskal


def _tukey_table(res):
    t = res["tukey"][["group1", "group2", "meandiff", "lower", "upper", "p_adj", "reject"]].copy()
    t["p_adj"] = [_p(p, b) for p, b in zip(res["tukey"]["p_adj"], res["tukey"]["p_adj_bound"])]
    return _fmt_table(t)


def _section_html(res, title, figs=None, ordinal_fig=None):
    parts = [
        f"<h2>{html.escape(title)}</h2>",
        f"<p>{res['n_test_ratings']} test ratings from {res['n_raters']} raters on {res['n_clips']} clips.</p>",
        _undefined_html(res),
        "<h3>Condition means</h3>",
        _fmt_table(
            res["summary"].rename(
                columns={
                    "t_low": "t 95% low",
                    "t_high": "t 95% high",
                    "boot_low": "boot 95% low",
                    "boot_high": "boot 95% high",
                }
            )
        ),
        f"<p>{' '.join(_anova_text(res))}</p>",
        "<h3>Tukey HSD (95% family-wise)</h3>",
        _tukey_table(res),
        "<h3>Pairwise Mann–Whitney U (Holm-adjusted)</h3>",
        _fmt_table(res["mannwhitney"], ("p", "p_holm")),
        f"<h3>Cluster bootstrap of differences ({res['bootstrap']['n_boot']} resamples of raters and clips)</h3>",
        _fmt_table(res["bootstrap"]["differences"], ("boot_p",)),
        "<h3>Linear mixed model</h3>",
        _mixed_html(res["mixed"]),
        "<h3>Ordinal mixed model (cumulative logit)</h3>",
        _ordinal_html(res["ordinal"], ordinal_fig),
    ]
    if figs:
        parts += [f"<p>{_img(f)}</p>" for f in figs]
    if "metrics" in res:
        parts += [
            "<h3>Objective metrics vs per-clip mean rating</h3>",
            _fmt_table(res["metrics"], ("pearson_p", "spearman_p")),
        ]
    if res.get("c2st") is not None:
        parts += [
            "<h3>Classifier two-sample test against the reference</h3>",
            "<p class=note>Out-of-fold AUC of a logistic regression on per-clip motion statistics telling each "
            "condition's clips from the reference's, folds grouped by item (Lopez-Paz &amp; Oquab 2017): 0.5 = "
            "it cannot tell them apart, 1 = it always can. NAT:split is the reference against itself, the "
            "test's floor. A low AUC is no proof of quality: only that these statistics on this many items show "
            "no difference.</p>",
            _fmt_table(res["c2st"], ()),
        ]
    return "\n".join(parts)


def write_html(path, counts, kept, everyone, fig_paths, meta):
    s = kept["summary"]
    # every name below comes from the ratings file: escaped, so a condition called "<b>" stays text
    means = ", ".join(f"{html.escape(str(c))} {s.at[c, 'mean']:.2f}" for c in s.index)
    sig = [html.escape(f"{t.group2}–{t.group1}") for _, t in kept["tukey"].iterrows() if t.reject]
    tukey = (
        f"Tukey HSD: {html.escape(kept['undefined']['tukey'])}."
        if "tukey" in kept["undefined"]
        else f"Tukey HSD pairs differing at the 0.05 family-wise level: {', '.join(sig) if sig else 'none'}."
    )
    body = [
        f"<h1>Perceptual test report</h1><p class=note>{html.escape(meta['input'])} · generated "
        f"{html.escape(meta['generated_at'])} · bootstrap seed {meta['seed']}</p>",
        "<h2>Summary</h2>",
        f"<p>{counts['n_ratings_total']} responses from {counts['n_raters_total']} raters. "
        f"{counts['n_raters_excluded']} raters gave a catch (bad-example) clip a rating ≥ {counts['threshold']} and "
        f"were excluded, removing {counts['n_ratings_removed']} responses; {counts['n_ratings_kept']} were kept "
        f"({counts['n_test_ratings_kept']} test ratings). Mean ratings: {means}. "
        f"{_anova_text(kept, 2)[0]} {tukey}</p>",
        f"<p>{_img(fig_paths['ratings_histogram'])}</p>",
        "<p class=note>Fig. 5 of the paper: responses per scale point and condition; dashed lines at the means.</p>",
        f"<p>{_img(fig_paths['per_clip_means'])}</p>",
        "<p class=note>Fig. 6 of the paper: mean rating of each clip, sorted worst to best within each condition.</p>",
        f"<p>{_img(fig_paths['condition_means'])}</p>",
        _section_html(
            kept,
            "With the rater exclusion (primary analysis)",
            [fig_paths["metric_scatter"]] if "metric_scatter" in fig_paths else None,
            fig_paths.get("ordinal_fit"),
        ),
        _section_html(everyone, "Without the exclusion (all raters)", ordinal_fig=fig_paths.get("ordinal_fit_all")),
        "<h2>Excluded raters</h2><p>" + (html.escape(", ".join(counts["excluded_raters"])) or "none") + "</p>",
    ]
    page = (
        "<!doctype html><html lang=en><head><meta charset=utf-8><title>Perceptual test report</title>"
        f"<style>{CSS}</style></head><body>{''.join(body)}</body></html>"
    )
    Path(path).write_text(page, encoding="utf-8")


# ---------------------------------------------------------------------------------------------- entry point
def _check_enough(path, test):
    """Too few ratings for any statistic is a problem with the input file, said in one line (exit 2)."""
    k = test["condition"].nunique()
    if k < 2:
        conds = ", ".join(map(str, test["condition"].unique()))
        raise AnalysisError(f"{path}: the test rows hold {k} condition ({conds}); comparisons need at least 2")
    if len(test) <= k:
        raise AnalysisError(
            f"{path}: {len(test)} test rating{'s' if len(test) != 1 else ''} in {k} condition"
            f"{'s' if k != 1 else ''}: the statistics need more ratings than conditions"
        )


def _prepare_out(out):
    """The report folder, created; a file in the way or a place we cannot write is the --out flag's problem."""
    if out.exists() and not out.is_dir():
        raise AnalysisError(f"--out {out}: is a file, not a folder")
    try:
        (out / "figures").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AnalysisError(f"--out {out}: cannot create the report folder ({exc.strerror or exc})") from None
    if not os.access(out, os.W_OK | os.X_OK) or not os.access(out / "figures", os.W_OK | os.X_OK):
        raise AnalysisError(f"--out {out}: folder is not writable")


def build_report(
    ratings_path,
    out_dir="report",
    metrics_path=None,
    threshold=DEFAULT_THRESHOLD,
    mixed=True,
    seed=0,
    n_boot=2000,
    alpha=0.05,
    mixed_max_levels=MIXED_MAX_LEVELS,
    progress=True,
    quiet=False,
    ordinal=True,
    ordinal_max_ratings=ORDINAL_MAX_RATINGS,
):
    """Run the whole analysis; returns the stats.json document. A pairwise or parallel file (CONTRACTS §8, told
    by its columns) goes to analysis.design_report."""
    from .design_report import build, detect_design

    design = detect_design(ratings_path)
    if design != "acr":
        return build(ratings_path, out_dir, design, n_boot=n_boot, seed=seed, alpha=alpha, mixed=mixed, quiet=quiet)
    t0 = time.perf_counter()
    df = load_ratings(ratings_path)
    metrics = load_metrics(metrics_path) if metrics_path else None
    c2st_path = Path(metrics_path).parent / "c2st.csv" if metrics_path else None
    c2st = load_c2st(c2st_path) if c2st_path and c2st_path.is_file() else None
    kept_rows, counts = exclude_raters(df, threshold)
    kept_test, all_test = only_test_rows(kept_rows), only_test_rows(df)
    if len(kept_test) == 0:
        raise AnalysisError(
            f"{ratings_path}: every rater failed the catch trials (threshold {threshold}); no test ratings are left"
        )
    _check_enough(ratings_path, kept_test)
    out = Path(out_dir)
    _prepare_out(out)
    bar = tqdm(total=14, desc="analysis", unit="step", disable=not progress, leave=False, file=sys.stderr)
    opts = dict(
        n_boot=n_boot,
        seed=seed,
        alpha=alpha,
        mixed=mixed,
        ordinal=ordinal,
        mixed_max_levels=mixed_max_levels,
        ordinal_max_ratings=ordinal_max_ratings,
        metrics=metrics,
        progress=bar,
    )
    try:
        kept = analyse(kept_test, **opts)
        everyone = analyse(all_test, **opts)
        kept["c2st"] = c2st
    except AnalysisError as exc:
        bar.close()  # leave=False: the bar disappears, the error line stands alone
        raise AnalysisError(f"{ratings_path}: {exc}") from None
    figs = {
        "ratings_histogram": figures.ratings_histogram(
            kept["histogram"], kept["summary"]["mean"].to_dict(), out / "figures" / "ratings_histogram.png"
        ),
        "per_clip_means": figures.per_clip_means(kept["clips"], out / "figures" / "per_clip_means.png"),
        "condition_means": figures.condition_means(
            [("kept raters", kept["summary"]), ("all raters", everyone["summary"])],
            out / "figures" / "condition_means.png",
        ),
    }
    for key, res in (("ordinal_fit", kept), ("ordinal_fit_all", everyone)):
        if res["ordinal"].get("fixed_effects"):
            figs[key] = figures.ordinal_fit(res["ordinal"], out / "figures" / f"{key}.png")
    bar.update(3)
    if metrics is not None:
        figs["metric_scatter"] = figures.metric_scatter(
            kept["clips"], metrics, kept["metrics"], out / "figures" / "metric_scatter.png"
        )
        matched = kept["clips"]["clip_id"].isin(metrics.index)
        counts["n_clips_with_metrics"] = int(matched.sum())
        counts["n_clips_without_metrics"] = int((~matched).sum())
    meta = {
        "input": str(ratings_path),
        "generated_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "seed": seed,
        "alpha": alpha,
        "figures": {k: str(Path(v).relative_to(out)) for k, v in figs.items()},
    }
    write_html(out / "report.html", counts, kept, everyone, figs, meta)
    doc = to_json(counts, kept, everyone, meta)
    (out / "stats.json").write_text(json.dumps(doc, indent=1, allow_nan=False), encoding="utf-8")
    bar.update(1)
    bar.close()
    if not quiet:
        print(console_summary(counts, kept, everyone))
        print(f"\nReport: {out / 'report.html'}  ({time.perf_counter() - t0:.1f} s)")
    return doc


def build_parser():
    """The command's argument parser (also read by tests/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m analysis.report", description=__doc__.splitlines()[0])
    ap.add_argument("ratings", help="ratings.csv exported by the rating app (CONTRACTS.md §6)")
    ap.add_argument("--out", default="report", help="report folder (default: report/)")
    ap.add_argument("--metrics", help="metrics.csv of the stimuli: correlate each metric with the clip mean rating")
    ap.add_argument(
        "--threshold",
        type=cli.number(int, 1, 6),
        default=DEFAULT_THRESHOLD,
        help=f"exclude raters who rated any catch clip at or above this (1-6; default {DEFAULT_THRESHOLD}, as "
        "in the paper; 6 keeps every rater)",
    )
    ap.add_argument("--no-mixed", action="store_true", help="skip the linear mixed model")
    ap.add_argument("--no-ordinal", action="store_true", help="skip the ordinal (cumulative-logit) mixed model")
    ap.add_argument(
        "--mixed-max-levels",
        type=cli.number(int, 1),
        default=MIXED_MAX_LEVELS,
        help="skip the mixed models when raters and clips both exceed this (their cost grows with the "
        f"cube of the smaller; default {MIXED_MAX_LEVELS})",
    )
    ap.add_argument(
        "--ordinal-max-ratings",
        type=cli.number(int, 1),
        default=ORDINAL_MAX_RATINGS,
        help="skip the ordinal model above this many test ratings (its cost grows with every rating; "
        f"default {ORDINAL_MAX_RATINGS})",
    )
    ap.add_argument("--seed", type=cli.number(int, 0, 2**32 - 1), default=0, help="bootstrap seed (default 0)")
    ap.add_argument(
        "--n-boot",
        type=cli.number(int, 10, 1_000_000),
        default=2000,
        help="bootstrap resamples (10-1000000; default 2000)",
    )
    ap.add_argument(
        "--alpha",
        type=cli.number(float, 0, 0.5, lo_open=True),
        default=0.05,
        help="family-wise error rate (0 < alpha <= 0.5; default 0.05)",
    )
    ap.add_argument("--quiet", action="store_true", help="no console summary or progress bar")
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    build_report(
        args.ratings,
        args.out,
        args.metrics,
        args.threshold,
        not args.no_mixed,
        args.seed,
        args.n_boot,
        args.alpha,
        args.mixed_max_levels,
        progress=not args.quiet,
        quiet=args.quiet,
        ordinal=not args.no_ordinal,
        ordinal_max_ratings=args.ordinal_max_ratings,
    )
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
