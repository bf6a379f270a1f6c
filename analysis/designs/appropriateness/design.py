"""appropriateness (CONTRACTS §8, GENEA 2023): pairs.csv with `matched`; the mean appropriateness score per system
with its interval, shares and sign test (analysis/designs/appropriateness/mas.py), and its bar figure."""

from moglow_eval.core import study

from ...page import design_figures
from ...page.report_html import table
from ..base import FailedCatchDesign, Standings, ranked
from ..pairwise import preference
from . import mas


class Appropriateness(FailedCatchDesign):
    """Also the base of the dyadic and semantic designs: the same answers and statistics, each named for its
    question (`score`, `heading`) and told apart by the column naming what the mismatched motion was made for
    (moglow_eval.core.study.MISMATCH_COLUMN)."""

    name = "appropriateness"
    methods_task = (
        "watched a system's motion for the speech they heard and its motion for other speech, with the same "
        "audio, and chose the one that fitted the speech better on a five-level scale"
    )
    methods_stats = (
        "the mean appropriateness score with Student-t intervals and sign tests against chance, Holm-adjusted"
    )
    methods_resamples = False  # t intervals and sign tests (and the dyadic and semantic designs'): none resampled

    def answers_per_unit(self, test):
        return "votes per system", test.groupby("condition_a").size()

    score = "mean appropriateness score (MAS)"
    heading = (
        "Mean appropriateness score (MAS: +2 = the matched motion clearly preferred, -2 = the mismatched "
        "one; 0 = chance)"
    )

    def detects(self, columns):
        others = [c for d, c in study.MISMATCH_COLUMN.items() if d != self.name]
        return "preference" in columns and mas.MATCHED in columns and not any(c in columns for c in others)

    def load(self, path):
        return mas.load_answers(path)

    def failed_raters(self, df):
        return preference.failed_raters(df)  # the pairwise rule: preferring BAD to the reference

    def analyse_rows(self, df, options):
        return mas.analyse(df, alpha=options.alpha)

    def figures(self, data, kept, everyone, folder):
        return {"mas": design_figures.mas_bars(kept["mas"], folder / "mas.png", score=self.score)}

    def section_json(self, res):
        t = res["mas"].set_index("condition")
        return {
            "n_test_answers": res["n_test_answers"],
            "n_raters": res["n_raters"],
            "n_items": res["n_items"],
            "mas": {c: {k: t.at[c, k] for k in t.columns} for c in t.index},
        }

    def section_html(self, res):
        return [
            f"<p>{res['n_test_answers']} test answers from {res['n_raters']} raters on {res['n_items']} "
            f"items.</p><h3>{self.heading}, 95% Student-t interval, shares of preferences, sign test against chance "
            "(ties dropped), Holm</h3>",
            table(res["mas"], ("p", "p_holm")),
        ]

    short = "MAS"  # the score's short name, a board's column heading

    def standings(self, doc):
        rows = [
            {"system": c, "score": m["mas"], "low": m["ci_low"], "high": m["ci_high"], "n": m["n"]}
            for c, m in doc["mas"].items()
        ]
        # The report tests each system against chance, not against each other: two systems are ordered only where
        # their intervals do not overlap, a conservative order.
        better = {
            (a["system"], b["system"])
            for a in rows
            for b in rows
            if a["low"] is not None and b["high"] is not None and a["low"] > b["high"]
        }
        about = (
            f"{self.heading}, with its 95% Student-t interval. A system ranks above another only where their "
            "intervals do not overlap (the report tests each system against chance, not against each other)."
        )
        return Standings(self.short, about, "votes", ranked(rows, better))

    def console_lines(self, kept):
        lines = [f"{'system':<14}{'n':>6}{'MAS':>8}{'95% interval':>18}{'matched %':>11}{'p (Holm)':>10}"]
        for _, r in kept["mas"].iterrows():
            ci = f"[{r['ci_low']:.2f}, {r['ci_high']:.2f}]"
            lines.append(
                f"{r['condition']:<14}{r['n']:>6}{r['mas']:>8.2f}{ci:>18}{r['percent_matched']:>11.1f}"
                f"{r['p_holm']:>10.3g}"
            )
        return lines
