"""acr (CONTRACTS §6-7, the paper's analysis, and what reviewers ask now): ratings 1..5 of one clip each.

Every statistic is computed on the kept test rows (after the catch-trial rater exclusion: a rater who rated a
bad example at or above the threshold) and again on all test rows ("without_exclusion"): ANOVA, Tukey HSD,
Kruskal-Wallis and Mann-Whitney, a cluster bootstrap over raters and clips, a linear and an ordinal mixed
model (stats/bootstrap.py, stats/rating_models.py), and the objective metrics' correlations. Its report parts
are in sections.py.
"""

from functools import partial
from pathlib import Path

import numpy as np

from moglow_eval.core import study

from ...data.filtering import exclude_raters, only_test_rows
from ...data.load import AnalysisError, load_c2st, load_metrics, load_ratings
from ...page import figures
from ...page.report_html import records
from ...page.study_text import rename_c2st, rename_reference
from ...stats import agreement, anova, bootstrap, rating_models, style
from ..base import MIXED_MAX_LEVELS, ORDINAL_MAX_RATINGS, Design, Prepared, Standings, ranked
from . import sections


def _fit_model(fit, test, enabled, flag, n_raters, n_clips, max_levels, max_ratings=None):
    """One random-effects model, or why it is not there: skipped by a flag or by size, undefined for the data
    (rating_models.ModelUndefined), or a numerical failure -- always a dict with 'fixed_effects', never an exception."""
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
    except rating_models.ModelUndefined as exc:
        return {"undefined": str(exc), "fixed_effects": {}}
    except (np.linalg.LinAlgError, ValueError) as exc:  # a degenerate design is reported, not fatal
        return {
            "error": f"the fit failed numerically, too little data for this model? ({type(exc).__name__}: "
            f"{str(exc).splitlines()[0] if str(exc) else ''})",
            "fixed_effects": {},
        }


def undefined_tests(res):
    """{test: why it has no result} for every test that the data leave undefined (zero variance, one rater,
    one clip per condition, ...), so anova.json and the report say so instead of printing a number."""
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
    reference=None,
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
    summary = anova.group_summary(test)
    out["histogram"] = anova.rating_histogram(test)
    out["clips"] = anova.per_clip_means(test)
    step()
    out["anova"] = anova.one_way_anova(test)
    out["tukey"] = anova.tukey_hsd(test, alpha=alpha)
    step()
    out["bootstrap"] = bootstrap.cluster_bootstrap(test, n_boot=n_boot, seed=seed)
    out["summary"] = summary.join(out["bootstrap"]["means"][["boot_low", "boot_high", "boot_se"]])
    step()
    out["kruskal"] = anova.kruskal_wallis(test)
    out["mannwhitney"] = anova.pairwise_mannwhitney(test, alpha=alpha)
    step()
    sizes = (out["n_raters"], out["n_clips"], mixed_max_levels)
    ref = reference if reference in set(conds) else (study.NATURAL if study.NATURAL in set(conds) else None)
    out["mixed"] = _fit_model(partial(rating_models.mixed_model, reference=ref), test, mixed, "--no-mixed", *sizes)
    out["ordinal"] = _fit_model(
        partial(rating_models.ordinal_model, reference=ref), test, ordinal, "--no-ordinal", *sizes, ordinal_max_ratings
    )
    out["style"] = style.style_analysis(test, ref)  # condition x style, when the clips have more than one style
    out["agreement"] = agreement.agreement(test, n_boot=n_boot, seed=seed)
    step()
    if metrics is not None:
        out["metrics"] = anova.metric_correlations(out["clips"], metrics)
    out["undefined"] = undefined_tests(out)
    return out


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
        "tukey": records(
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
            "differences": records(boot["differences"]),
        },
        "kruskal": res["kruskal"],
        "mannwhitney": records(res["mannwhitney"]),
        "mixed_model": res["mixed"],
        "ordinal_model": res["ordinal"],
        "undefined": res["undefined"],
        "agreement": res["agreement"],
        "per_clip_means": records(
            res["clips"][["clip_id", "condition", "rank", "n", "mean", "sd", "ci_low", "ci_high"]]
        ),
    }
    if "metrics" in res:
        out["metric_correlations"] = records(res["metrics"])
    if res.get("style") is not None:
        out["style"] = style.style_json(res["style"])
    return out


def check_enough(path, test):
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


class Acr(Design):
    name = "acr"
    methods_task = "rated each clip on its own on a five-point scale (1 = bad, 5 = excellent)"
    methods_catch = "rated a deliberately broken clip (BAD) at {threshold} or above"
    methods_stats = (
        "a one-way ANOVA with Tukey's HSD, a linear mixed model with crossed random intercepts for raters and "
        "clips, and cluster-bootstrap intervals resampling raters and clips"
    )
    methods_mixed = ", a linear mixed model with crossed random intercepts for raters and clips,"
    steps = 14  # five per analysis of two, three for the figures, one for the files

    def detects(self, columns):
        return "preference" not in columns and "page_id" not in columns  # the others' columns

    def prepare(self, path, options):
        df = rename_reference(load_ratings(path), options.reference_name)
        metrics = load_metrics(options.metrics_path) if options.metrics_path else None
        c2st_path = Path(options.metrics_path).parent / "c2st.csv" if options.metrics_path else None
        c2st = load_c2st(c2st_path) if c2st_path and c2st_path.is_file() else None
        c2st = rename_c2st(c2st, options.reference_name)
        kept_rows, counts = exclude_raters(df, options.threshold)
        kept_test = only_test_rows(kept_rows)
        if len(kept_test) == 0:
            raise AnalysisError(
                f"{path}: every rater failed the catch trials (threshold {options.threshold}); no test ratings are left"
            )
        check_enough(path, kept_test)
        return Prepared(df, kept_rows, counts, {"metrics": metrics, "c2st": c2st})

    def analyse(self, data, options, progress):
        metrics = data.extra["metrics"]
        opts = dict(
            n_boot=options.n_boot,
            seed=options.seed,
            alpha=options.alpha,
            mixed=options.mixed,
            ordinal=options.ordinal,
            mixed_max_levels=options.mixed_max_levels,
            ordinal_max_ratings=options.ordinal_max_ratings,
            metrics=metrics,
            progress=progress,
            reference=options.reference_name,
        )
        kept = analyse(only_test_rows(data.kept), **opts)
        everyone = analyse(only_test_rows(data.rows), **opts)
        kept["c2st"] = data.extra["c2st"]
        if metrics is not None:
            matched = kept["clips"]["clip_id"].isin(metrics.index)
            data.counts["n_clips_with_metrics"] = int(matched.sum())
            data.counts["n_clips_without_metrics"] = int((~matched).sum())
        return kept, everyone

    def figures(self, data, kept, everyone, folder):
        means = kept["summary"]["mean"].to_dict()
        figs = {
            "ratings_histogram": figures.ratings_histogram(kept["histogram"], means, folder / "ratings_histogram.png"),
            "per_clip_means": figures.per_clip_means(kept["clips"], folder / "per_clip_means.png"),
            "condition_means": figures.condition_means(
                [("kept raters", kept["summary"]), ("all raters", everyone["summary"])],
                folder / "condition_means.png",
            ),
        }
        for key, res in (("ordinal_fit", kept), ("ordinal_fit_all", everyone)):
            if res["ordinal"].get("fixed_effects"):
                figs[key] = figures.ordinal_fit(res["ordinal"], folder / f"{key}.png")
        if kept.get("style") is not None:
            figs["style_means"] = style.style_figure(kept["style"], folder / "style_means.png")
        metrics = data.extra["metrics"]
        if metrics is not None:
            figs["metric_scatter"] = figures.metric_scatter(
                kept["clips"], metrics, kept["metrics"], folder / "metric_scatter.png"
            )
        return figs

    def stats_head(self):
        return {}  # an acr anova.json has no "design" key: absent means acr (CONTRACTS §8)

    def stats_json(self, kept, everyone):
        doc = section_json(kept)
        if kept.get("c2st") is not None:
            doc["c2st"] = records(kept["c2st"])
        doc["without_exclusion"] = section_json(everyone)
        return doc

    def html(self, meta, counts, kept, everyone, figs):
        return sections.html_parts(meta, counts, kept, everyone, figs)

    def console(self, counts, kept, everyone):
        return sections.console_summary(counts, kept, everyone)

    def standings(self, doc):
        summary, counts = doc["condition_summary"], doc["condition_counts"]
        rows = [
            {"system": c, "score": m, "low": summary[c]["boot_low"], "high": summary[c]["boot_high"], "n": counts[c]}
            for c, m in doc["condition_means"].items()
        ]
        # Tukey's rows: meandiff = mean(group2) - mean(group1); a rejected pair is ordered by its sign.
        better = {
            (t["group2"], t["group1"]) if t["meandiff"] > 0 else (t["group1"], t["group2"])
            for t in doc["tukey"]
            if t["reject"]
        }
        about = (
            "The mean opinion score (1 = bad, 5 = excellent) with its 95% cluster-bootstrap interval (raters and "
            "clips resampled). A system ranks above another only where Tukey's HSD tells them apart."
        )
        return Standings("MOS", about, "ratings", ranked(rows, better))
