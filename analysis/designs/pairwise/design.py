"""pairwise (CONTRACTS §8): pairs.csv without `matched`; wins, ties and sign tests per condition pair and
Bradley-Terry strengths (preference.py beside this file), with the preference bars and the strengths as
figures."""

import html

import numpy as np
import pandas as pd

from ...data.load import AnalysisError
from ...page import design_figures
from ...page.report_html import table
from ..appropriateness import mas
from ..base import FailedCatchDesign, Standings
from . import elo_ranks, partisans, preference, reasons, rounds


def _renamed_nat(df, name):
    """The reference's own name where the rows carry it (NAT renamed): it stays the default anchor."""
    return name if name and name in set(df["condition_a"]) | set(df["condition_b"]) else None


class Pairwise(FailedCatchDesign):
    name = "pairwise"
    reads = frozenset({"reference", "indifference"})
    methods_task = (
        "watched two clips of the same item from two conditions and chose the one that looked more natural on a "
        "five-level scale (clearly, slightly, no preference)"
    )
    methods_stats = (
        "two-sided sign tests per pair (Holm-adjusted) and a Bradley-Terry model with Davidson's tie parameter, "
        "reported on an Elo scale (400 points per factor of ten in the odds), with intervals and rank intervals "
        "from a bootstrap over raters"
    )

    def answers_per_unit(self, test):
        lo = np.minimum(test["condition_a"], test["condition_b"])
        hi = np.maximum(test["condition_a"], test["condition_b"])
        return "votes per pair of conditions", test.groupby([lo, hi]).size()

    def detects(self, columns):
        return "preference" in columns and mas.MATCHED not in columns  # that column: appropriateness

    def load(self, path):
        return preference.load_pairs(path)

    def failed_raters(self, df):
        return preference.failed_raters(df)

    def analyse_rows(self, df, options):
        res = self._fit(df, options)
        res["reasons_when_lost"] = reasons.when_lost(df)  # None when the votes carry no reasons
        res["rounds"] = rounds.per_round(df)  # None for a file without rounds
        # Raters who favour one condition far beyond the crowd (partisans.py): flagged, and the ranking shown
        # without them beside the ranking with them; nobody is excluded by it.
        res["partisans"] = partisans.flag(preference.oriented(df))
        res["ranking_without_partisans"] = None
        flagged = set(res["partisans"]["rater_id"])
        if flagged:
            try:
                res["ranking_without_partisans"] = self._fit(df[~df["rater_id"].isin(flagged)], options)["ranking"]
            except AnalysisError:  # too little left to rank
                pass
        return res

    def _fit(self, df, options):
        return preference.analyse(
            df,
            n_boot=options.n_boot,
            seed=options.seed,
            alpha=options.alpha,
            reference=options.reference or _renamed_nat(df, options.reference_name),
            margin_elo=options.indifference,
        )

    def figures(self, data, kept, everyone, folder):
        order = list(kept["ranking"]["condition"])  # strongest first
        rate, p = elo_ranks.win_rates(kept["pairs"], order)
        return {
            "preference_bars": design_figures.preference_bars(kept["pairs"], folder / "preference_bars.png"),
            "bradley_terry": design_figures.bradley_terry(kept["bradley_terry"], folder / "bradley_terry.png"),
            "win_matrix": design_figures.win_rate_figure(rate, p, order, folder / "win_matrix.png"),
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
                **{
                    k: bt[k]
                    for k in ("reference", "nu", "log_likelihood", "converged", "method", "n_boot", "seed", "level")
                },
                "nu": bt["nu"] if bt["nu_estimable"] else None,  # not a number the data gave
                "separated": bt["separated"],
                "nu_estimable": bt["nu_estimable"],
            },
            "ranking": res["ranking"].to_dict(orient="records"),
            "elo": dict(zip(res["ranking"]["condition"], res["ranking"]["elo"])),
            "reliability": res["reliability"],
            **self._votes_json(res),
        }

    def _votes_json(self, res):
        """What the votes carry beside the preference: their rounds and their reasons, when the file has them;
        the raters who favour one condition far beyond the crowd, and the ranking without them."""
        without = res.get("ranking_without_partisans")
        out = {
            "partisan_raters": {
                "rule": partisans.rule_text(),
                "flagged": res["partisans"].to_dict(orient="records"),
                "ranking_without_them": None if without is None else without.to_dict(orient="records"),
            }
        }
        out = out if res.get("rounds") is None else {**out, "rounds": res["rounds"]}
        lost = res.get("reasons_when_lost")
        return out if lost is None else {**out, "reasons_when_lost": reasons.as_json(lost)}

    def _votes_html(self, res):
        out = partisans_html(res)
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
            f"<b>{html.escape(bt['reference'])}</b> = 0; {html.escape(tie_text(bt))}.</p>",
            *([f"<p class=flag>{html.escape(fit_warning(res))}</p>"] if fit_warning(res) else []),
            table(pd.DataFrame(strengths).T),
            *ranking_html(res),
            *self._votes_html(res),
        ]

    def standings(self, doc):
        votes = {}
        for p in doc["pairwise"]:
            for c in (p["condition_a"], p["condition_b"]):
                votes[c] = votes.get(c, 0) + p["n"]
        rows = [
            {
                "system": r["condition"],
                "score": r["elo"],
                "low": r["elo_low"],
                "high": r["elo_high"],
                "n": votes.get(r["condition"], 0),
                "rank_low": int(r["rank_low"]),
                "rank_high": int(r["rank_high"]),
                "group": int(r["group"]),
            }
            for r in doc["ranking"]  # strongest first
        ]
        about = (
            "The Bradley-Terry strength on the Elo scale (400 points per factor of ten in the odds of winning, "
            f"{doc['bradley_terry_fit']['reference']} at 1000) with its 95% bootstrap interval (raters resampled). "
            "Rank intervals come from the same bootstrap."
        )
        return Standings("Elo", about, "votes", rows)

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
        rank = kept["ranking"]
        ranked = "; ".join(
            f"{r.rank_range} {r.condition} {r.elo:.0f} [{r.elo_low:.0f}, {r.elo_high:.0f}]"
            + (f" ({r.note})" if r.note else "")
            for r in rank.itertuples()
        )
        lines += ["", f"Bradley-Terry log strengths ({bt['reference']} = 0; {tie_text(bt)}): " + strengths]
        if fit_warning(kept):
            lines.append(fit_warning(kept))
        flagged = kept["partisans"]
        if not flagged.empty:
            who = ", ".join(f"{r.rater_id} ({r.condition}, {r.share:.0%} against the crowd's {r.crowd_share:.0%})"
                            for r in flagged.itertuples())  # fmt: skip
            lines.append(f"Raters who favour one condition far beyond the crowd: {who}")
        lines += ["", f"Ranking, Elo ({bt['reference']} = 1000) [95%]; a shared rank = intervals overlap: " + ranked]
        rel = kept["reliability"]
        if rel:
            lines.append(reliability_text(rel))
        return lines


def partisans_html(res) -> list[str]:
    """The raters flagged for favouring one condition far beyond the crowd, and the ranking without them."""
    flagged = res["partisans"]
    head = "<h3>Raters who favour one condition far beyond the crowd</h3>"
    rule = f"<p>The rule: {html.escape(partisans.rule_text())}.</p>"
    if flagged.empty:
        return [head, rule, "<p>None flagged.</p>"]
    out = [head, rule, table(flagged.set_index("rater_id"), ())]
    without = res.get("ranking_without_partisans")
    if without is not None:
        cols = ["condition", "rank_range", "elo", "elo_low", "elo_high", "group"]
        out += ["<p>The ranking without the flagged raters (the ranking above keeps them):</p>"]
        out += [table(without[cols].set_index("condition"), ())]
    return out


def tie_text(bt) -> str:
    if bt["nu_estimable"]:
        return f"tie parameter ν = {bt['nu']:.3f}"
    return (
        "tie parameter ν not estimable (every vote between conditions the votes can compare was a tie; the "
        f"strengths are fitted with ν = {bt['nu']:g})"
    )


def fit_warning(res) -> str:
    """What the report says when the fit has no maximum likelihood: the conditions that won or lost every vote
    (separated votes; their strengths are bounds the ridge holds), or ties alone between the others."""
    bt = res["bradley_terry"]
    if not bt["separated"]:
        return ""
    notes = elo_ranks.unbounded(res["pairs"])
    named = "; ".join(f"{c} {n.split(':')[0]}" for c, n in sorted(notes.items()))
    return (
        f"No maximum-likelihood fit: the votes are separated ({named or 'some conditions never beat others'}), "
        "so those strengths have no finite estimate and their Elo is a bound, not a value."
    )


def reliability_text(rel) -> str:
    return (
        f"Split-half reliability over {rel['n_splits']} random halves of the {rel['n_raters']} raters: Kendall's "
        f"tau {rel['tau_median']:.2f} (95% of splits {rel['tau_low']:.2f} to {rel['tau_high']:.2f}); "
        f"{100 * rel['same_order']:.0f}% of splits give both halves the same order."
    )


def ranking_html(res) -> list[str]:
    """The ranking's table (Elo, intervals, rank intervals, groups) and the reliability sentence."""
    rank = (
        res["ranking"]
        .rename(
            columns={
                "rank_range": "rank",
                "rank": "rank (point)",
                "elo_low": "Elo 95% low",
                "elo_high": "Elo 95% high",
                "rank_low": "rank 95% low",
                "rank_high": "rank 95% high",
                "log_strength": "log strength",
                "elo": "Elo",
            }
        )
        .set_index("condition")
    )
    cols = ["rank", "Elo", "Elo 95% low", "Elo 95% high", "log strength", "rank 95% low", "rank 95% high", "group"]
    cols += ["note"] if rank["note"].any() else []
    rel = res["reliability"]
    return [
        "<h3>Ranking</h3><p>Elo: 400 points per factor of ten in the odds of winning, the reference at 1000. "
        "Conditions share a rank (and a group) while their bootstrap rank intervals overlap: the data do not "
        "order them.</p>",
        table(rank[cols]),
        f"<p>{html.escape(reliability_text(rel))}</p>"
        if rel
        else "<p>Split-half reliability: too few raters (fewer than 4) or conditions (fewer than 3).</p>",
    ]
