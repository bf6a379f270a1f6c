"""The report of a pairwise or parallel test: `python -m analysis.report FILE` hands such a file here.

The design is recognised from the file's columns (CONTRACTS §8): `preference` -> pairwise (pairs.csv), `page_id`
-> parallel, anything else -> acr (analysis.report). The report folder is the acr one's (§7): stats.json with
"design", figures/ and report.html; every statistic is given with the catch-trial exclusion (raters who failed
any catch trial are dropped) and without it ("without_exclusion").
"""

import csv
import html
import json
import sys
import time
from pathlib import Path

from . import appropriateness, design_figures, pairwise, parallel
from .load import AnalysisError


def detect_design(path) -> str:
    """acr, pairwise or parallel from the header of the CSV file at `path` (AnalysisError if unreadable)."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            header = next(csv.reader(fh), [])
    except FileNotFoundError:
        raise AnalysisError(f"{path}: no such file") from None
    except (UnicodeDecodeError, csv.Error):
        return "acr"  # the acr loader names the problem
    cols = {c.strip() for c in header}
    if "preference" in cols:
        return "appropriateness" if appropriateness.MATCHED in cols else "pairwise"
    return "parallel" if "page_id" in cols else "acr"


def _exclude(df, failed):
    drop = df["rater_id"].isin(failed)
    kept = df[~drop]
    counts = {
        "n_ratings_total": int(len(df)),
        "n_ratings_removed": int(drop.sum()),
        "n_ratings_kept": int(len(kept)),
        "n_raters_total": int(df["rater_id"].nunique()),
        "n_raters_excluded": len(failed),
        "n_raters_kept": int(kept["rater_id"].nunique()),
        "excluded_raters": failed,
        "n_catch_ratings": int((df["role"] == "catch").sum()),
    }
    return kept, counts


def _pairwise_json(res):
    p, bt = res["pairs"], res["bradley_terry"]
    return {
        "n_test_answers": res["n_test_answers"],
        "n_raters": res["n_raters"],
        "n_items": res["n_items"],
        "pairwise": p.to_dict(orient="records"),
        "bradley_terry": bt["strengths"],
        "bradley_terry_ci": bt["ci"],
        "bradley_terry_fit": {
            k: bt[k] for k in ("reference", "nu", "log_likelihood", "converged", "method", "n_boot", "seed", "level")
        },
    }


def _appropriateness_json(res):
    t = res["mas"].set_index("condition")
    return {
        "n_test_answers": res["n_test_answers"],
        "n_raters": res["n_raters"],
        "n_items": res["n_items"],
        "mas": {c: {k: t.at[c, k] for k in t.columns} for c in t.index},
    }


def _parallel_json(res):
    s = res["summary"]
    return {
        "n_test_ratings": res["n_test_ratings"],
        "n_raters": res["n_raters"],
        "n_pages": res["n_pages"],
        "n_items": res["n_items"],
        "condition_means": s["mean"].to_dict(),
        "condition_medians": s["median"].to_dict(),
        "condition_counts": s["n"].astype(int).to_dict(),
        "condition_summary": {c: {k: s.at[c, k] for k in s.columns if k != "n"} for c in s.index},
        "wilcoxon": res["wilcoxon"].to_dict(orient="records"),
        "mixed_model": res["mixed"],
    }


def _html(design, meta, counts, kept, everyone, figs):
    from . import report as acr

    def section(res, title):
        parts = [f"<h2>{html.escape(title)}</h2>"]
        if design == "appropriateness":
            parts += [
                f"<p>{res['n_test_answers']} test answers from {res['n_raters']} raters on {res['n_items']} "
                "items.</p><h3>Mean appropriateness score (MAS: +2 = the matched motion clearly preferred, -2 = the "
                "mismatched one; 0 = chance), 95% Student-t interval, shares of preferences, sign test against "
                "chance (ties dropped), Holm</h3>",
                acr._fmt_table(res["mas"], ("p", "p_holm")),
            ]
        elif design == "pairwise":
            bt = res["bradley_terry"]
            table = res["pairs"][
                ["condition_a", "condition_b", "wins_a", "wins_b", "ties", "n", "p", "p_holm", "reject"]
            ]
            strengths = {
                c: {"log strength": v, "95% low": bt["ci"][c][0], "95% high": bt["ci"][c][1]}
                for c, v in bt["strengths"].items()
            }
            import pandas as pd

            parts += [
                f"<p>{res['n_test_answers']} test answers from {res['n_raters']} raters on {res['n_items']} "
                "items.</p><h3>Wins, ties and losses per pair; two-sided sign test (ties dropped), Holm</h3>",
                acr._fmt_table(table, ("p", "p_holm")),
                f"<h3>Bradley–Terry strengths</h3><p>{html.escape(bt['method'])}; reference "
                f"<b>{html.escape(bt['reference'])}</b> = 0; tie parameter ν = {bt['nu']:.3f}.</p>",
                acr._fmt_table(pd.DataFrame(strengths).T),
            ]
        else:
            parts += [
                f"<p>{res['n_test_ratings']} test ratings from {res['n_raters']} raters on {res['n_pages']} "
                "pages.</p><h3>Per condition (95% intervals: bootstrap over raters)</h3>",
                acr._fmt_table(res["summary"]),
                "<h3>Wilcoxon signed-rank on page-paired ratings, Holm</h3>",
                acr._fmt_table(res["wilcoxon"], ("p", "p_holm")),
                "<h3>Linear mixed model</h3>",
                acr._mixed_html(res["mixed"]),
            ]
        return "\n".join(parts)

    body = [
        f"<h1>Perceptual test report ({design})</h1><p class=note>{html.escape(meta['input'])} · generated "
        f"{html.escape(meta['generated_at'])} · bootstrap seed {meta['seed']}</p>",
        f"<h2>Summary</h2><p>{counts['n_ratings_total']} rows from {counts['n_raters_total']} raters. "
        f"{counts['n_raters_excluded']} raters failed a catch trial and were excluded, removing "
        f"{counts['n_ratings_removed']} rows; {counts['n_ratings_kept']} were kept.</p>",
        *[f"<p>{acr._img(f)}</p>" for f in figs.values()],
        section(kept, "With the rater exclusion (primary analysis)"),
        section(everyone, "Without the exclusion (all raters)"),
        "<h2>Excluded raters</h2><p>" + (html.escape(", ".join(counts["excluded_raters"])) or "none") + "</p>",
    ]
    return (
        "<!doctype html><html lang=en><head><meta charset=utf-8><title>Perceptual test report</title>"
        f"<style>{acr.CSS}</style></head><body>{''.join(body)}</body></html>"
    )


def _console(design, counts, kept):
    lines = [
        f"Design {design}: {counts['n_ratings_total']} rows, {counts['n_ratings_removed']} removed, "
        f"{counts['n_ratings_kept']} kept (raters: {counts['n_raters_total']} total, "
        f"{counts['n_raters_excluded']} excluded for a failed catch trial)",
        "",
    ]
    if design == "appropriateness":
        lines.append(f"{'system':<14}{'n':>6}{'MAS':>8}{'95% interval':>18}{'matched %':>11}{'p (Holm)':>10}")
        for _, r in kept["mas"].iterrows():
            ci = f"[{r['ci_low']:.2f}, {r['ci_high']:.2f}]"
            lines.append(
                f"{r['condition']:<14}{r['n']:>6}{r['mas']:>8.2f}{ci:>18}{r['percent_matched']:>11.1f}"
                f"{r['p_holm']:>10.3g}"
            )
    elif design == "pairwise":
        lines.append(f"{'pair':<18}{'wins':>6}{'ties':>6}{'losses':>8}{'sign p (Holm)':>15}")
        for _, r in kept["pairs"].iterrows():
            p = "n/a" if r["p_holm"] != r["p_holm"] else f"{r['p_holm']:.3g}"
            lines.append(
                f"{r['condition_a'] + ' vs ' + r['condition_b']:<18}{r['wins_a']:>6}{r['ties']:>6}"
                f"{r['wins_b']:>8}{p:>15}"
            )
        bt = kept["bradley_terry"]
        lines += [
            "",
            f"Bradley-Terry log strengths ({bt['reference']} = 0): "
            + ", ".join(
                f"{c} {v:.2f} [{bt['ci'][c][0]:.2f}, {bt['ci'][c][1]:.2f}]" for c, v in bt["strengths"].items()
            ),
        ]
    else:
        s = kept["summary"]
        lines.append(f"{'condition':<10}{'n':>6}{'mean':>8}{'median':>8}")
        lines += [f"{c:<10}{int(s.at[c, 'n']):>6}{s.at[c, 'mean']:>8.1f}{s.at[c, 'median']:>8.1f}" for c in s.index]
        lines.append("")
        for _, r in kept["wilcoxon"].iterrows():
            p = "n/a" if r["p_holm"] != r["p_holm"] else f"{r['p_holm']:.3g}"
            lines.append(f"Wilcoxon {r['group2']}-{r['group1']}: median diff {r['median_diff']:.1f}, p (Holm) {p}")
    return "\n".join(lines)


def build(path, out_dir="report", design=None, n_boot=2000, seed=0, alpha=0.05, mixed=True, quiet=False):
    """Read, check, analyse and write the report of a pairwise or parallel file; returns the stats.json dict."""
    from . import report as acr

    t0 = time.perf_counter()
    design = design or detect_design(path)
    mod = {"pairwise": pairwise, "parallel": parallel, "appropriateness": appropriateness}[design]
    df = {"pairwise": pairwise.load_pairs, "parallel": parallel.load_pages}.get(design, appropriateness.load_answers)(
        path
    )
    kept_rows, counts = _exclude(df, mod.failed_raters(df))
    if not (kept_rows["role"] == "test").any():
        raise AnalysisError(f"{path}: every rater failed the catch trials; no test answers are left")
    out = Path(out_dir)
    acr._prepare_out(out)
    opts = dict(n_boot=n_boot, seed=seed, alpha=alpha)
    if design == "parallel":
        opts["mixed"] = mixed
    if design == "appropriateness":
        opts = dict(alpha=alpha)
    try:
        kept, everyone = mod.analyse(kept_rows, **opts), mod.analyse(df, **opts)
    except AnalysisError as exc:
        raise AnalysisError(f"{path}: {exc}") from None
    fig_dir = out / "figures"
    if design == "appropriateness":
        figs = {"mas": design_figures.mas_bars(kept["mas"], fig_dir / "mas.png")}
        section = _appropriateness_json
    elif design == "pairwise":
        figs = {
            "preference_bars": design_figures.preference_bars(kept["pairs"], fig_dir / "preference_bars.png"),
            "bradley_terry": design_figures.bradley_terry(kept["bradley_terry"], fig_dir / "bradley_terry.png"),
        }
        section = _pairwise_json
    else:
        test = kept_rows[kept_rows["role"] == "test"]
        figs = {
            "ratings_boxplot": design_figures.parallel_boxplot(test, kept["summary"], fig_dir / "ratings_boxplot.png")
        }
        section = _parallel_json
    meta = {
        "design": design,
        "input": str(path),
        "generated_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "seed": seed,
        "alpha": alpha,
        "figures": {k: str(Path(v).relative_to(out)) for k, v in figs.items()},
    }
    doc = acr._clean({**meta, **counts, **section(kept), "without_exclusion": section(everyone)})
    (out / "stats.json").write_text(json.dumps(doc, indent=1, allow_nan=False), encoding="utf-8")
    (out / "report.html").write_text(_html(design, meta, counts, kept, everyone, figs), encoding="utf-8")
    if not quiet:
        print(_console(design, counts, kept))
        print(f"\nReport: {out / 'report.html'}  ({time.perf_counter() - t0:.1f} s)", file=sys.stdout)
    return doc
