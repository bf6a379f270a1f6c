"""pairwise (CONTRACTS §8): pairs.csv without `matched`; wins, ties and sign tests per condition pair and
Bradley-Terry strengths (analysis/pairwise.py), with the preference bars and the strengths as figures."""

import html

import pandas as pd

from .. import appropriateness, design_figures, pairwise, reasons, rounds
from ..report_html import table
from .base import FailedCatchDesign


class Pairwise(FailedCatchDesign):
    name = "pairwise"

    def detects(self, columns):
        return "preference" in columns and appropriateness.MATCHED not in columns  # that column: appropriateness

    def load(self, path):
        return pairwise.load_pairs(path)

    def failed_raters(self, df):
        return pairwise.failed_raters(df)

    def analyse_rows(self, df, options):
        res = pairwise.analyse(df, n_boot=options.n_boot, seed=options.seed, alpha=options.alpha)
        res["reasons_when_lost"] = reasons.when_lost(df)  # None when the votes carry no reasons
        res["rounds"] = rounds.per_round(df)  # None for a file without rounds
        return res

    def figures(self, data, kept, everyone, folder):
        return {
            "preference_bars": design_figures.preference_bars(kept["pairs"], folder / "preference_bars.png"),
            "bradley_terry": design_figures.bradley_terry(kept["bradley_terry"], folder / "bradley_terry.png"),
        }

    def section_json(self, res):
        p, bt = res["pairs"], res["bradley_terry"]
        return {
            "n_test_answers": res["n_test_answers"],
            "n_raters": res["n_raters"],
            "n_items": res["n_items"],
            "pairwise": p.to_dict(orient="records"),
            "bradley_terry": bt["strengths"],
            "bradley_terry_ci": bt["ci"],
            "bradley_terry_fit": {
                k: bt[k]
                for k in ("reference", "nu", "log_likelihood", "converged", "method", "n_boot", "seed", "level")
            },
            **self._votes_json(res),
        }

    def _votes_json(self, res):
        """What the votes carry beside the preference: their rounds and their reasons, when the file has them."""
        out = {} if res.get("rounds") is None else {"rounds": res["rounds"]}
        lost = res.get("reasons_when_lost")
        return out if lost is None else {**out, "reasons_when_lost": reasons.as_json(lost)}

    def _votes_html(self, res):
        out = []
        if res.get("rounds") and len(res["rounds"]) > 1:
            out += [
                "<h3>Rounds: the votes of each, and the conditions it brought in</h3>",
                table(pd.DataFrame(res["rounds"]).assign(new_conditions=lambda d: d.new_conditions.map(", ".join))),
            ]
        lost = res.get("reasons_when_lost")
        if lost is None:
            return out
        return out + [
            "<h3>Why a system lost: the share of its lost votes that gave each reason</h3>",
            table(lost.set_index("condition")),
        ]

    def section_html(self, res):
        bt = res["bradley_terry"]
        pairs = res["pairs"][["condition_a", "condition_b", "wins_a", "wins_b", "ties", "n", "p", "p_holm", "reject"]]
        strengths = {
            c: {"log strength": v, "95% low": bt["ci"][c][0], "95% high": bt["ci"][c][1]}
            for c, v in bt["strengths"].items()
        }
        return [
            f"<p>{res['n_test_answers']} test answers from {res['n_raters']} raters on {res['n_items']} "
            "items.</p><h3>Wins, ties and losses per pair; two-sided sign test (ties dropped), Holm</h3>",
            table(pairs, ("p", "p_holm")),
            f"<h3>Bradley–Terry strengths</h3><p>{html.escape(bt['method'])}; reference "
            f"<b>{html.escape(bt['reference'])}</b> = 0; tie parameter ν = {bt['nu']:.3f}.</p>",
            table(pd.DataFrame(strengths).T),
            *self._votes_html(res),
        ]

    def console_lines(self, kept):
        lines = [f"{'pair':<18}{'wins':>6}{'ties':>6}{'losses':>8}{'sign p (Holm)':>15}"]
        for _, r in kept["pairs"].iterrows():
            p = "n/a" if r["p_holm"] != r["p_holm"] else f"{r['p_holm']:.3g}"
            pair = r["condition_a"] + " vs " + r["condition_b"]
            lines.append(f"{pair:<18}{r['wins_a']:>6}{r['ties']:>6}{r['wins_b']:>8}{p:>15}")
        bt = kept["bradley_terry"]
        strengths = ", ".join(
            f"{c} {v:.2f} [{bt['ci'][c][0]:.2f}, {bt['ci'][c][1]:.2f}]" for c, v in bt["strengths"].items()
        )
        return lines + ["", f"Bradley-Terry log strengths ({bt['reference']} = 0): " + strengths]
