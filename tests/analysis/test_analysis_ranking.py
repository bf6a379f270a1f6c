"""The ranking report of a pairwise study (CONTRACTS §8): Elo beside the log strengths, rank intervals from the
rater bootstrap, groups that never order what the intervals do not, a win-rate matrix and split-half
reliability; checked on simulated votes with known strengths and on the GENEA leaderboard's released votes
(read in ../shared, never copied)."""

import csv
import json
import math

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm
from helpers.paths import LEADERBOARD

from analysis import report
from analysis.designs import Options
from analysis.designs.pairwise import elo_ranks, partisans
from analysis.designs.pairwise import preference as pairwise
from analysis.import_votes import import_votes

BATTLES = LEADERBOARD / "battles_elo.csv"


def simulated_pairs(path, strengths, n_raters=30, votes=40, seed=0, tie_band=0.0):
    """pairs.csv from raters whose choices follow Bradley-Terry on `strengths` (log scale)."""
    rng = np.random.default_rng(seed)
    conds = list(strengths)
    rows = []
    for r in range(n_raters):
        for v in range(votes):
            a, b = rng.choice(len(conds), 2, replace=False)
            p = 1 / (1 + math.exp(strengths[conds[b]] - strengths[conds[a]]))
            u = rng.random()
            pref = 0 if abs(u - p) < tie_band else (1 if u < p else -1) * (2 if abs(u - p) > 0.3 else 1)
            rows.append([f"r{r}", f"i{v}", f"a{r}x{v}", f"b{r}x{v}", conds[a], conds[b], pref, "test"])
    cols = ["rater_id", "item", "clip_a", "clip_b", "condition_a", "condition_b", "preference", "role"]
    pd.DataFrame(rows, columns=cols).to_csv(path, index=False)
    return path


def test_elo_is_400_points_per_factor_of_ten_in_the_odds():
    assert elo_ranks.elo(0.0) == 1000.0
    assert elo_ranks.elo(math.log(10)) == pytest.approx(1400.0)
    assert elo_ranks.elo(1.0, reference_theta=1.0) == 1000.0


def test_groups_merge_only_overlapping_rank_intervals():
    order = ["a", "b", "c", "d"]
    lo = {"a": 1, "b": 1, "c": 3, "d": 3}
    hi = {"a": 2, "b": 2, "c": 4, "d": 4}
    assert elo_ranks.groups(order, lo, hi) == {"a": 1, "b": 1, "c": 2, "d": 2}
    chain = elo_ranks.groups(order, {"a": 1, "b": 1, "c": 2, "d": 4}, {"a": 2, "b": 3, "c": 3, "d": 4})
    assert chain == {"a": 1, "b": 1, "c": 1, "d": 2}  # b overlaps c: the chain is one group


def test_rank_table_on_known_strengths(tmp_path):
    truth = {"NAT": 0.0, "S1": -0.2, "S2": -1.5, "S3": -1.5, "S4": -3.0}
    path = simulated_pairs(tmp_path / "pairs.csv", truth, n_raters=40, votes=50)
    res = pairwise.analyse(pairwise.load_pairs(path), n_boot=300, seed=1)
    table = res["ranking"].set_index("condition")
    assert table.at["NAT", "elo"] == 1000.0 and res["bradley_terry"]["reference"] == "NAT"
    for c in truth:  # Elo is the log strength on the 400/ln 10 scale
        assert table.at[c, "elo"] == pytest.approx(1000 + 400 / math.log(10) * table.at[c, "log_strength"])
        assert table.at[c, "elo_low"] <= table.at[c, "elo"] <= table.at[c, "elo_high"] or c == "NAT"
        assert table.at[c, "rank_low"] <= table.at[c, "rank"] <= table.at[c, "rank_high"]
    # far apart: different groups; S2 and S3 (equal strengths) share one in nearly every simulated study (a 95%
    # interval may part them by chance: at most one of five studies)
    shared = [table.at["S2", "group"] == table.at["S3", "group"]]
    for seed in range(1, 5):
        other = simulated_pairs(tmp_path / f"p{seed}.csv", truth, n_raters=40, votes=50, seed=seed)
        t = pairwise.analyse(pairwise.load_pairs(other), n_boot=300, seed=seed)["ranking"].set_index("condition")
        shared.append(t.at["S2", "group"] == t.at["S3", "group"])
    assert sum(shared) >= 4, shared
    assert len({table.at["NAT", "group"], table.at["S2", "group"], table.at["S4", "group"]}) == 3
    # conditions in different groups never have overlapping rank intervals
    for a in truth:
        for b in truth:
            if table.at[a, "group"] < table.at[b, "group"]:
                assert table.at[a, "rank_high"] < table.at[b, "rank_low"]
    rel = res["reliability"]
    assert rel["tau_median"] >= 0.6 and rel["n_raters"] == 40 and 0 <= rel["same_order"] <= 1


def test_split_half_finds_no_order_where_there_is_none(tmp_path):
    truth = {c: 0.0 for c in ("A", "B", "C", "D", "E")}
    res = pairwise.analyse(pairwise.load_pairs(simulated_pairs(tmp_path / "p.csv", truth)), n_boot=100)
    assert abs(res["reliability"]["tau_median"]) < 0.35
    assert res["ranking"]["group"].nunique() == 1  # one group: the data order nothing
    assert set(res["ranking"]["rank_range"]) == {"1-5"}


def test_reference_flag_sets_the_anchor(tmp_path):
    truth = {"NAT": 0.0, "S1": -1.0, "S2": -2.0}
    path = simulated_pairs(tmp_path / "pairs.csv", truth, n_raters=10, votes=30)
    doc = report.build_report(path, tmp_path / "rep", Options(n_boot=50, reference="S2"), progress=False, quiet=True)
    assert doc["elo"]["S2"] == 1000.0 and doc["bradley_terry"]["S2"] == 0.0
    assert doc["elo"]["NAT"] > doc["elo"]["S1"] > 1000.0
    from analysis.data.load import AnalysisError

    with pytest.raises(AnalysisError, match="--reference XYZ: no such condition"):
        report.build_report(path, tmp_path / "rep2", Options(n_boot=50, reference="XYZ"), progress=False, quiet=True)


def test_win_rates_from_pair_counts():
    pairs = pd.DataFrame(
        [{"condition_a": "A", "condition_b": "B", "wins_a": 6, "wins_b": 2, "ties": 2, "n": 10, "p_holm": 0.01}]
    )
    rate, p = elo_ranks.win_rates(pairs, ["A", "B", "C"])
    assert rate[0, 1] == pytest.approx(0.7) and rate[1, 0] == pytest.approx(0.3)
    assert np.isnan(rate[0, 2]) and p[1, 0] == 0.01


def test_the_report_shows_the_ranking(tmp_path):
    truth = {"NAT": 0.0, "S1": -0.5, "S2": -2.0}
    path = simulated_pairs(tmp_path / "pairs.csv", truth, n_raters=12, votes=30)
    doc = report.build_report(path, tmp_path / "rep", Options(n_boot=100), progress=False, quiet=True)
    assert [r["condition"] for r in doc["ranking"]] == ["NAT", "S1", "S2"]
    assert {"elo", "elo_low", "elo_high", "rank_low", "rank_high", "group", "rank_range"} <= set(doc["ranking"][0])
    assert (tmp_path / "rep" / "figures" / "win_matrix.png").stat().st_size > 5000
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "Split-half reliability" in page and "Elo 95% low" in page and "Methods, for a paper" in page
    assert doc["reliability"]["n_splits"] == 200


# ------------------------------------------------------------------------- the leaderboard's released votes
@pytest.mark.full
def test_imported_leaderboard_votes_give_an_independent_fits_ranking(tmp_path):
    out = tmp_path / "pairs.csv"
    import_votes(BATTLES, out)
    doc = report.build_report(out, tmp_path / "rep", Options(n_boot=300, reference="BEAT2"), progress=False, quiet=True)
    elo = doc["elo"]
    assert elo["BEAT2"] == 1000.0 and len(elo) == 8
    # An independent fit: plain Bradley-Terry as a logistic regression on +-1 indicator columns (statsmodels),
    # the ties left out, BEAT2's column dropped as the reference.
    votes = list(csv.DictReader(open(BATTLES)))
    conds = sorted({v["model_a"] for v in votes} | {v["model_b"] for v in votes})
    free = [c for c in conds if c != "BEAT2"]
    X, y = [], []
    for v in votes:
        if v["winner"] == "tie":
            continue
        row = np.zeros(len(free))
        for name, sign in ((v["model_a"], 1), (v["model_b"], -1)):
            if name in free:
                row[free.index(name)] = sign
        X.append(row)
        y.append(1 if v["winner"] == "model_a" else 0)
    fit = sm.Logit(np.array(y), np.array(X)).fit(disp=0)
    independent = {"BEAT2": 0.0, **dict(zip(free, fit.params))}
    # our fit of the same votes without ties is the same model: equal strengths
    no_ties = pd.read_csv(out)
    no_ties = no_ties[no_ties["preference"] != 0]
    no_ties.to_csv(tmp_path / "no_ties.csv", index=False)
    ours = report.build_report(
        tmp_path / "no_ties.csv", tmp_path / "rep2", Options(n_boot=20, reference="BEAT2"), progress=False, quiet=True
    )["bradley_terry"]
    for c in conds:
        assert ours[c] == pytest.approx(independent[c], abs=2e-3)
    # with ties (Davidson), the ranking's groups agree with the independent fit's order: the groups' members
    # are consecutive in it, and the two weakest systems stand apart from the six others
    order = sorted(conds, key=lambda c: -independent[c])
    groups = {r["condition"]: r["group"] for r in doc["ranking"]}
    assert [groups[c] for c in order] == sorted(groups[c] for c in order)
    assert {c for c in conds if groups[c] == max(groups.values())} == {"AMUSE", "DiffuseStyleGesture"}
    assert json.loads((tmp_path / "rep" / "stats.json").read_text())["reliability"]["n_raters"] == 20


def test_a_condition_that_never_wins_is_flagged(tmp_path):
    truth = {"NAT": 0.0, "S1": -0.5, "BROKEN": -60.0}
    path = simulated_pairs(tmp_path / "pairs.csv", truth, n_raters=8, votes=20)
    table = pairwise.analyse(pairwise.load_pairs(path), n_boot=50)["ranking"].set_index("condition")
    assert table.at["BROKEN", "note"].startswith("never won a vote")
    assert table.at["NAT", "note"] == "" and table.at["S1", "note"] == ""


def one_winner_three_alike(path, n_raters=8, items=6):
    """pairs.csv of issue 55's degenerate study: W wins every vote it is in; NAT, A and B tie every vote among
    themselves, so the data treats them alike."""
    rows = []
    for r in range(n_raters):
        for i in range(items):
            for a, b in (("W", "NAT"), ("W", "A"), ("B", "W"), ("NAT", "A"), ("A", "B"), ("NAT", "B")):
                pref = 2 if a == "W" else -2 if b == "W" else 0
                rows.append([f"r{r}", f"i{i}", f"{a}{i}".lower() + "x", f"{b}{i}".lower() + "x", a, b, pref, "test"])
    cols = ["rater_id", "item", "clip_a", "clip_b", "condition_a", "condition_b", "preference", "role"]
    pd.DataFrame(rows, columns=cols).to_csv(path, index=False)
    return path


def test_degenerate_votes_are_said_so_and_alike_conditions_share_a_group(tmp_path):
    path = one_winner_three_alike(tmp_path / "pairs.csv")
    doc = report.build_report(path, tmp_path / "rep", Options(n_boot=100), progress=False, quiet=True)
    fit = doc["bradley_terry_fit"]
    # No "converged" fit with a tie parameter of 1e5 or more: the fit says it has no maximum, and no ν is given.
    assert fit["converged"] is False and fit["separated"] is True
    assert fit["nu"] is None and fit["nu_estimable"] is False
    rank = {r["condition"]: r for r in doc["ranking"]}
    assert rank["W"]["rank_range"] == "1" and rank["W"]["note"].startswith("never lost a vote")
    alike = [rank[c] for c in ("NAT", "A", "B")]
    assert {r["group"] for r in alike} == {2} and {r["rank_range"] for r in alike} == {"2-4"}
    assert max(r["elo"] for r in alike) - min(r["elo"] for r in alike) < 0.5
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "No maximum-likelihood fit: the votes are separated (W never lost a vote)" in page
    assert "tie parameter ν not estimable" in page


def test_a_separated_study_with_an_estimable_tie_parameter_says_so_too(tmp_path):
    truth = {"NAT": 0.0, "S1": -0.5, "BROKEN": -60.0}
    path = simulated_pairs(tmp_path / "pairs.csv", truth, n_raters=8, votes=20, tie_band=0.1)
    df = pd.read_csv(path)
    broken = (df["condition_a"] == "BROKEN") | (df["condition_b"] == "BROKEN")
    df.loc[broken, "preference"] = np.where(df.loc[broken, "condition_a"] == "BROKEN", -2, 2)  # never even a tie
    df.to_csv(path, index=False)
    res = pairwise.analyse(pairwise.load_pairs(path), n_boot=50)
    bt = res["bradley_terry"]
    assert bt["separated"] and bt["nu_estimable"] and not bt["converged"] and 0 < bt["nu"] < 10
    table = res["ranking"].set_index("condition")
    assert table.at["BROKEN", "group"] == table["group"].max() and table.at["BROKEN", "rank_range"] == "3"


def test_tied_ranks_share_their_mean_rank_within_the_tolerance():
    assert elo_ranks.tied_ranks([0.0, 1e-5, 2.0, -1.0]).tolist() == [2.5, 2.5, 1.0, 4.0]
    assert elo_ranks.tied_ranks([0.0, 0.5, 1.0]).tolist() == [3.0, 2.0, 1.0]


def with_a_stuffer(path, truth, seed=0, n_raters=30):
    """An honest crowd on `truth`, and one rater who votes clearly for SYS whenever it is shown and "no
    preference" elsewhere (issue 55, failure 3): nothing a catch trial could catch."""
    simulated_pairs(path, truth, n_raters=n_raters, votes=40, seed=seed, tie_band=0.05)
    df = pd.read_csv(path)
    bot = df[df["rater_id"] == "r0"].copy()
    bot["rater_id"] = "stuffer"
    bot["clip_a"] = "s" + bot["clip_a"]
    bot["clip_b"] = "s" + bot["clip_b"]
    bot["preference"] = np.where(bot["condition_a"] == "SYS", 2, np.where(bot["condition_b"] == "SYS", -2, 0))
    pd.concat(
        [df, bot, bot.assign(rater_id="stuffer2", clip_a="t" + bot["clip_a"], clip_b="t" + bot["clip_b"])]
    ).to_csv(path, index=False)
    return path


def test_raters_who_favour_one_condition_far_beyond_the_crowd_are_flagged(tmp_path):
    truth = {"NAT": 0.0, "MG": -0.4, "FL": -0.8, "SYS": -1.2}
    path = with_a_stuffer(tmp_path / "pairs.csv", truth)
    doc = report.build_report(path, tmp_path / "rep", Options(n_boot=100), progress=False, quiet=True)
    part = doc["partisan_raters"]
    assert {(r["rater_id"], r["condition"]) for r in part["flagged"]} == {("stuffer", "SYS"), ("stuffer2", "SYS")}
    assert "Bonferroni" in part["rule"]
    with_them = {r["condition"]: r["elo"] for r in doc["ranking"]}
    without = {r["condition"]: r["elo"] for r in part["ranking_without_them"]}
    assert without["SYS"] < with_them["SYS"] and min(without, key=without.get) == "SYS"
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "Raters who favour one condition far beyond the crowd" in page and "stuffer" in page


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_an_honest_crowd_has_no_partisans(tmp_path, seed):
    truth = {"NAT": 0.0, "MG": -0.4, "FL": -0.8, "SYS": -1.2, "X": 0.3}
    path = simulated_pairs(tmp_path / "pairs.csv", truth, n_raters=40, votes=40, seed=seed, tie_band=0.05)
    res = pairwise.analyse(pairwise.load_pairs(path), n_boot=20)
    o = pairwise.oriented(pairwise.load_pairs(path))
    assert partisans.flag(o).empty and res["n_raters"] == 40


def test_conditions_confidently_within_the_indifference_margin_share_a_group():
    """Two conditions 10 Elo apart, measured so precisely that their rank intervals are disjoint: within an
    indifference margin of 25 Elo in every resample, the report groups them (issue 55 item 8)."""
    rng = np.random.default_rng(0)
    per_elo = 1 / elo_ranks.ELO_PER_LOG
    centre = np.array([0.0, -10 * per_elo, -300 * per_elo])
    boot = centre + rng.normal(0, 2 * per_elo, (400, 3))
    strengths = dict(zip(["A", "B", "C"], centre))
    table = elo_ranks.rank_table(strengths, boot, ["A", "B", "C"], "A", margin_elo=25.0).set_index("condition")
    assert table.at["A", "rank_high"] < table.at["B", "rank_low"]  # the intervals alone would part them
    assert table.at["A", "group"] == table.at["B", "group"] != table.at["C", "group"]
    apart = elo_ranks.rank_table(strengths, boot, ["A", "B", "C"], "A").set_index("condition")  # the default: off
    assert apart.at["A", "group"] != apart.at["B", "group"]
