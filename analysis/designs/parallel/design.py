"""parallel (CONTRACTS §8, MUSHRA-like): a ratings.csv with `page_id`; condition means and medians with bootstrap
intervals, page-paired Wilcoxon tests and a linear mixed model (analysis/designs/parallel/mushra.py), and a box plot."""

import html

from ...page import design_figures
from ...page.report_html import mixed_html, table
from ...stats import agreement
from ..base import FailedCatchDesign, Standings, ranked
from . import mushra


class Parallel(FailedCatchDesign):
    name = "parallel"
    methods_task = "rated every condition of an item on one page, side by side, on a 0-100 scale (MUSHRA-like)"
    methods_catch = "rated a deliberately broken clip (BAD) at or above the real motion on the same page"
    methods_stats = (
        "Wilcoxon signed-rank tests on page-paired ratings (Holm-adjusted), a linear mixed model with crossed random "
        "intercepts for raters and items, and intervals of each condition's mean from a bootstrap over raters"
    )
    methods_mixed = ", a linear mixed model with crossed random intercepts for raters and items,"

    def detects(self, columns):
        return "page_id" in columns and "preference" not in columns  # both: a pairs.csv (pairwise's)

    def load(self, path):
        return mushra.load_pages(path)

    def failed_raters(self, df):
        return mushra.failed_raters(df)

    def analyse_rows(self, df, options):
        res = mushra.analyse(df, n_boot=options.n_boot, seed=options.seed, alpha=options.alpha, mixed=options.mixed)
        return {**res, "agreement": agreement.agreement(df, n_boot=options.n_boot, seed=options.seed)}

    def figures(self, data, kept, everyone, folder):
        test = data.kept[data.kept["role"] == "test"]
        path = folder / "ratings_boxplot.png"
        return {"ratings_boxplot": design_figures.parallel_boxplot(test, kept["summary"], path)}

    def section_json(self, res):
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
            "agreement": res["agreement"],
        }

    def section_html(self, res):
        return [
            f"<p>{res['n_test_ratings']} test ratings from {res['n_raters']} raters on {res['n_pages']} "
            "pages.</p><h3>Per condition (95% intervals: bootstrap over raters)</h3>",
            table(res["summary"]),
            "<h3>Wilcoxon signed-rank on page-paired ratings, Holm</h3>",
            table(res["wilcoxon"], ("p", "p_holm")),
            "<h3>Linear mixed model</h3>",
            mixed_html(res["mixed"]),
            f"<h3>Rater agreement</h3><p>{html.escape(agreement.agreement_text(res['agreement']))}</p>",
        ]

    def standings(self, doc):
        summary, counts = doc["condition_summary"], doc["condition_counts"]
        rows = [
            {"system": c, "score": m, "low": summary[c]["mean_low"], "high": summary[c]["mean_high"], "n": counts[c]}
            for c, m in doc["condition_means"].items()
        ]
        means = doc["condition_means"]  # a pair the test tells apart is ordered by the score the board shows
        better = {
            (w["group2"], w["group1"]) if means[w["group2"]] > means[w["group1"]] else (w["group1"], w["group2"])
            for w in doc["wilcoxon"]
            if w["reject"] and means[w["group2"]] != means[w["group1"]]
        }
        about = (
            "The mean rating (0 to 100) with its 95% bootstrap interval (raters resampled). A system ranks above "
            "another only where the Wilcoxon signed-rank test on page-paired ratings (Holm-adjusted) tells them apart."
        )
        return Standings("mean rating", about, "ratings", ranked(rows, better))

    def console_lines(self, kept):
        s = kept["summary"]
        lines = [f"{'condition':<10}{'n':>6}{'mean':>8}{'median':>8}"]
        lines += [f"{c:<10}{int(s.at[c, 'n']):>6}{s.at[c, 'mean']:>8.1f}{s.at[c, 'median']:>8.1f}" for c in s.index]
        lines += ["", agreement.agreement_text(kept["agreement"]), ""]
        for _, r in kept["wilcoxon"].iterrows():
            p = "n/a" if r["p_holm"] != r["p_holm"] else f"{r['p_holm']:.3g}"
            lines.append(f"Wilcoxon {r['group2']}-{r['group1']}: median diff {r['median_diff']:.1f}, p (Holm) {p}")
        return lines
