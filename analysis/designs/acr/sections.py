"""The acr report's parts: the console summary and report.html's sections (figures embedded, opens offline).

Every name in them comes from the ratings file, so it is escaped: a condition called "<b>" stays text.
"""

import html

import pandas as pd

from ...page.report_html import count, excluded_text, img, mixed_html, p_equals, p_text, table, why_not
from ...page.study_text import C2ST_LOW_AUC, C2ST_MIN_ITEMS, c2st_with_notes, captions
from ...stats.agreement import agreement_text


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
    lines += ["", agreement_text(kept["agreement"])]
    lines += [
        "",
        f"One-way ANOVA: {undef['anova']}"
        if "anova" in undef
        else f"One-way ANOVA: F({a['df_between']}, {a['df_within']}) = {a['F']:.3f}, {p_equals(a['p'])}",
        f"Kruskal-Wallis: {undef['kruskal']}"
        if "kruskal" in undef
        else f"Kruskal-Wallis: H({kw['df']}) = {kw['H']:.3f}, {p_equals(kw['p'])}",
        "",
        f"{'Tukey HSD':<14}{'diff':>8}{'95% CI':>20}{'p adj':>11}{'MWU p (Holm)':>14}",
    ]
    mwu = kept["mannwhitney"].set_index(["group1", "group2"])
    for _, t in kept["tukey"].iterrows():
        pair = f"{t.group2}-{t.group1}"
        lines.append(
            f"{pair:<14}{t.meandiff:>8.3f}{f'[{t.lower:.3f}, {t.upper:.3f}]':>20}"
            f"{p_text(t.p_adj, t.p_adj_bound):>11}{p_text(mwu.at[(t.group1, t.group2), 'p_holm']):>14}"
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
                f"df {m['df'][k]:.1f}  {p_equals(m['p_values'][k])}"
            )
        vc = m["variance_components"]
        lines.append(f"  variance: rater {vc['rater']:.3f}, clip {vc['clip']:.3f}, residual {vc['residual']:.3f}")
    else:
        lines += ["", f"Mixed model: {why_not(m)}"]
    o = kept["ordinal"]
    if o.get("fixed_effects"):
        lines += ["", f"Ordinal mixed model {o['formula']} (reference {o['reference']}):"]
        for k, v in o["fixed_effects"].items():
            lines.append(
                f"  {k:<22}{v:>8.3f} log-odds  odds ratio {o['odds_ratios'][k]:.3f} "
                f"[{o['or_ci_low'][k]:.3f}, {o['or_ci_high'][k]:.3f}]  {p_equals(o['p_values'][k])}"
            )
        lines.append(
            "  thresholds: "
            + ", ".join(f"{k} {v:.3f}" for k, v in o["thresholds"].items())
            + f"; SD rater {o['sd_rater']:.3f}, clip {o['sd_clip']:.3f}; converged: {o['converged']}"
        )
        lines += [f"  warning: {w}" for w in o["warnings"]]
    else:
        lines += ["", f"Ordinal mixed model: {why_not(o)}"]
    return "\n".join(lines)


def _ordinal_html(o, fig=None):
    if not o.get("fixed_effects"):
        return f"<p>Not fitted: {html.escape(str(why_not(o)))}</p>"
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
        f"<div class=cols>{table(fe, ('p',))}{table(th)}{table(sd)}</div>{warn}"
        + (
            f"<p>{img(fig)}</p><p class=note>Bars: observed share of each rating; dots: the model's "
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
        else f"One-way ANOVA: <b>F({a['df_between']}, {a['df_within']}) = {a['F']:.{digits}f}</b>, {p_equals(a['p'])}, "
        f"η² = {a['eta_squared']:.3f}."
    )
    kruskal = (
        f"Kruskal–Wallis: {html.escape(undef['kruskal'])}."
        if "kruskal" in undef
        else f"Kruskal–Wallis: H({k['df']}) = {k['H']:.3f}, {p_equals(k['p'])}."
    )
    return anova, kruskal


def _tukey_table(res):
    t = res["tukey"][["group1", "group2", "meandiff", "lower", "upper", "p_adj", "reject"]].copy()
    t["p_adj"] = [p_text(p, b) for p, b in zip(res["tukey"]["p_adj"], res["tukey"]["p_adj_bound"])]
    return table(t)


def style_html(st, fig=None):
    """The condition × style section: the cell means, the two-way ANOVA and the mixed model's interaction."""
    a, m = st["anova"], st["mixed_model"]
    names = ", ".join(html.escape(s) for s in st["styles"])
    if "undefined" in a:
        anova = f"<p>Two-way ANOVA: {html.escape(a['undefined'])}.</p>"
    else:
        rows = pd.DataFrame(a["terms"]).T[["df", "sum_sq", "F", "p"]]
        anova = f"<p>Two-way ANOVA rating ~ condition × style, type II sums of squares:</p>{table(rows, ('p',))}"
    if m.get("fixed_effects"):
        it = m["interaction_test"]
        test = (
            f"<p>Interaction (all condition × style effects at once, Wald): χ²({it['df']}) = {it['chi2']:.3f}, "
            f"{p_equals(it['p'])}. Reference: {html.escape(m['reference'])}, "
            f"{html.escape(m['style_reference'])}.</p>"
        )
        model = f"{mixed_html(m)}{test}"
    else:
        model = f"<p>Mixed model with the interaction: {html.escape(str(why_not(m)))}</p>"
    return (
        f"<h3>Condition × style ({names})</h3>"
        f"{table(st['cells'].set_index(['condition', 'style']))}{anova}{model}"
        + (f"<p>{img(fig)}</p><p class=note>Mean rating per condition and style, 95% t intervals.</p>" if fig else "")
    )


def _section_html(res, title, figs=None, ordinal_fig=None, style_fig=None):
    parts = [
        f"<h2>{html.escape(title)}</h2>",
        f"<p>{res['n_test_ratings']} test ratings from {res['n_raters']} raters on {res['n_clips']} clips.</p>",
        _undefined_html(res),
        "<h3>Condition means</h3>",
        table(
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
        table(res["mannwhitney"], ("p", "p_holm")),
        f"<h3>Cluster bootstrap of differences ({res['bootstrap']['n_boot']} resamples of raters and clips)</h3>",
        table(res["bootstrap"]["differences"], ("boot_p",)),
        "<h3>Linear mixed model</h3>",
        mixed_html(res["mixed"]),
        f"<h3>Rater agreement</h3><p>{html.escape(agreement_text(res['agreement']))}</p>",
        "<h3>Ordinal mixed model (cumulative logit)</h3>",
        _ordinal_html(res["ordinal"], ordinal_fig),
    ]
    if figs:
        parts += [f"<p>{img(f)}</p>" for f in figs]
    if "metrics" in res:
        parts += [
            "<h3>Objective metrics vs per-clip mean rating</h3>",
            table(res["metrics"], ("pearson_p", "spearman_p")),
        ]
    if res.get("style") is not None:
        parts.append(style_html(res["style"], style_fig))
    if res.get("c2st") is not None:
        parts += [
            "<h3>Classifier two-sample test against the reference</h3>",
            "<p class=note>Out-of-fold AUC of a logistic regression on per-clip motion statistics telling each "
            "condition's clips from the reference's, folds grouped by item (Lopez-Paz &amp; Oquab 2017): 0.5 = "
            "it cannot tell them apart, 1 = it always can. NAT:split is the reference against itself, the "
            "test's floor. A low AUC is no proof of quality: only that these statistics on this many items show "
            f"no difference. With fewer than {C2ST_MIN_ITEMS} items the AUC's chance spread is too wide to mean "
            f"much; an AUC below {C2ST_LOW_AUC} means the classifier learned the items, not the systems.</p>",
            table(c2st_with_notes(res["c2st"]), ()),
        ]
    return "\n".join(parts)


def html_parts(meta, counts, kept, everyone, fig_paths) -> list[str]:
    """report.html's parts (report_html.page wraps them)."""
    s = kept["summary"]
    caption = captions(s.index)
    # every name below comes from the ratings file: escaped, so a condition called "<b>" stays text
    means = ", ".join(f"{html.escape(str(c))} {s.at[c, 'mean']:.2f}" for c in s.index)
    sig = [html.escape(f"{t.group2}–{t.group1}") for _, t in kept["tukey"].iterrows() if t.reject]
    tukey = (
        f"Tukey HSD: {html.escape(kept['undefined']['tukey'])}."
        if "tukey" in kept["undefined"]
        else f"Tukey HSD pairs differing at the 0.05 family-wise level: {', '.join(sig) if sig else 'none'}."
    )
    catch = f"gave a catch (bad-example) clip a rating ≥ {counts['threshold']}"
    return [
        f"<h1>Perceptual test report</h1><p class=note>{html.escape(meta['input'])} · generated "
        f"{html.escape(meta['generated_at'])} · bootstrap seed {meta['seed']}</p>",
        "<h2>Summary</h2>",
        f"<p>{counts['n_ratings_total']} responses from {count(counts['n_raters_total'], 'rater')}. "
        f"{excluded_text(counts, catch)}, removing {counts['n_ratings_removed']} responses; "
        f"{counts['n_ratings_kept']} were kept "
        f"({counts['n_test_ratings_kept']} test ratings). Mean ratings: {means}. "
        f"{_anova_text(kept, 2)[0]} {tukey}</p>",
        f"<p>{img(fig_paths['ratings_histogram'])}</p>",
        f"<p class=note>{caption['ratings_histogram']}</p>",
        f"<p>{img(fig_paths['per_clip_means'])}</p>",
        f"<p class=note>{caption['per_clip_means']}</p>",
        f"<p>{img(fig_paths['condition_means'])}</p>",
        _section_html(
            kept,
            "With the rater exclusion (primary analysis)",
            [fig_paths["metric_scatter"]] if "metric_scatter" in fig_paths else None,
            fig_paths.get("ordinal_fit"),
            fig_paths.get("style_means"),
        ),
        _section_html(everyone, "Without the exclusion (all raters)", ordinal_fig=fig_paths.get("ordinal_fit_all")),
        "<h2>Excluded raters</h2><p>" + (html.escape(", ".join(counts["excluded_raters"])) or "none") + "</p>",
    ]
