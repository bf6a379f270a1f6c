"""The pairwise and parallel reports (CONTRACTS §8) against independent computations: counts by hand, the
Bradley-Terry fit against statsmodels (a logistic regression without ties; the same Davidson likelihood maximised
by statsmodels' GenericLikelihoodModel with ties), the sign and Wilcoxon tests against scipy with statsmodels'
Holm; the catch exclusion; bad rows refused with one line naming the row."""

import csv
import json
from itertools import combinations

import numpy as np
import pandas as pd
import pytest
from helpers.cli import fails_with
from scipy import stats as sps

from analysis.data.load import AnalysisError
from analysis.designs import Options, detect_design
from analysis.designs.pairwise import preference as pairwise
from analysis.designs.parallel import mushra as parallel
from analysis.report import build_report
from analysis.report import main as report_main

PAIR_COLS = ["rater_id", "item", "clip_a", "clip_b", "condition_a", "condition_b", "preference", "role"]
PAGE_COLS = ["rater_id", "page_id", "item", "clip_id", "condition", "rating", "role"]


def write(path, cols, rows):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        w.writerows(rows)
    return path


def simulate_pairs(strength, n_raters=40, items=6, nu=0.6, seed=1, catch_fail=()):
    """Rows of pairs.csv from a Davidson model with log strengths `strength`; sides drawn at random."""
    rng = np.random.default_rng(seed)
    conds = sorted(strength)
    rows = []
    for r in range(n_raters):
        for it in range(items):
            for a, b in combinations(conds, 2):
                pa, pb = np.exp(strength[a]), np.exp(strength[b])
                tie = nu * np.sqrt(pa * pb)
                u = rng.random() * (pa + pb + tie)
                out = 1 if u < pa else (-1 if u < pa + pb else 0)
                level = out * int(rng.integers(1, 3))
                if rng.random() < 0.5:
                    a2, b2, level = b, a, -level
                else:
                    a2, b2 = a, b
                rows.append([f"r{r}", f"i{it}", f"c{it}{a2}", f"c{it}{b2}", a2, b2, level, "test"])
        bad_first = rng.random() < 0.5
        pref = (2 if bad_first else -2) if r in catch_fail else (-1 if bad_first else 1)
        rows.append(
            [
                f"r{r}",
                "k0",
                "kb" if bad_first else "kn",
                "kn" if bad_first else "kb",
                "BAD" if bad_first else "NAT",
                "NAT" if bad_first else "BAD",
                pref,
                "catch",
            ]
        )
    return rows


# ---------------------------------------------------------------------------------------------- pairwise
def test_pairwise_counts_by_hand_and_sign_test(tmp_path):
    rows = [  # (rater, A cond, B cond, preference) on item i1; wins counted for the preferred condition
        ("r1", "NAT", "MG", 2),
        ("r2", "MG", "NAT", -1),
        ("r3", "NAT", "MG", 0),
        ("r4", "MG", "NAT", 1),
        ("r5", "NAT", "MG", 1),
        ("r1", "FL", "NAT", -2),
        ("r2", "NAT", "FL", 0),
        ("r3", "FL", "NAT", 0),
        ("r4", "MG", "FL", 2),
        ("r5", "FL", "MG", -1),
        ("r1", "MG", "FL", -1),
    ]
    data = [[r, f"i{k}", f"a{k}", f"b{k}", a, b, p, "test"] for k, (r, a, b, p) in enumerate(rows)]
    data.append(["r2", "k", "x1", "x2", "BAD", "NAT", 1, "catch"])  # r2 prefers BAD: excluded
    f = write(tmp_path / "pairs.csv", PAIR_COLS, data)
    doc = build_report(f, tmp_path / "rep", Options(n_boot=20), quiet=True)
    assert doc["design"] == "pairwise" and doc["excluded_raters"] == ["r2"] and doc["n_raters_excluded"] == 1
    assert (
        "rows from 5 raters. 1 rater failed a catch trial and was excluded"
        in (tmp_path / "rep/report.html").read_text()
    )
    kept = {(p["condition_a"], p["condition_b"]): p for p in doc["pairwise"]}
    everyone = {(p["condition_a"], p["condition_b"]): p for p in doc["without_exclusion"]["pairwise"]}
    # by hand, all raters: FL-MG: MG wins r4 (A, 2) and r5 (B, -1), FL wins r1 (B, -1); FL-NAT: NAT r1, ties r2 r3;
    # MG-NAT: NAT r1 r2 r5, MG r4, tie r3
    assert {k: (v["wins_a"], v["wins_b"], v["ties"], v["n"]) for k, v in everyone.items()} == {
        ("FL", "MG"): (1, 2, 0, 3),
        ("FL", "NAT"): (0, 1, 2, 3),
        ("MG", "NAT"): (1, 3, 1, 5),
    }
    assert {k: (v["wins_a"], v["wins_b"], v["ties"]) for k, v in kept.items()} == {
        ("FL", "MG"): (1, 2, 0),
        ("FL", "NAT"): (0, 1, 1),
        ("MG", "NAT"): (1, 2, 1),
    }
    from statsmodels.stats.multitest import multipletests

    for table in (everyone, kept):
        keys = sorted(table)
        p = [sps.binomtest(table[k]["wins_a"], table[k]["wins_a"] + table[k]["wins_b"], 0.5).pvalue for k in keys]
        holm = multipletests(p, method="holm")[1]
        for k, pk, hk in zip(keys, p, holm):
            assert table[k]["p"] == pytest.approx(pk, rel=1e-12) and table[k]["p_holm"] == pytest.approx(hk, rel=1e-12)
    assert (tmp_path / "rep" / "figures" / "preference_bars.png").stat().st_size > 5000
    assert "Bradley" in (tmp_path / "rep" / "report.html").read_text()


def _design(o, conds, ref):
    """+1 / -1 indicator columns of a Bradley-Terry logistic regression (reference column dropped)."""
    X = np.zeros((len(o), len(conds)))
    for n, (a, b) in enumerate(zip(o["first"], o["second"])):
        X[n, conds.index(a)] += 1
        X[n, conds.index(b)] -= 1
    return np.delete(X, conds.index(ref), axis=1)


def test_bradley_terry_without_ties_is_the_logistic_regression():
    import statsmodels.api as sm

    rows = simulate_pairs({"NAT": 0.0, "MG": -0.5, "FL": -1.2, "X": 0.4}, nu=0.0, n_raters=30)
    df = pd.DataFrame(rows, columns=PAIR_COLS)
    o = pairwise.oriented(df)
    assert (o["pref"] != 0).all()
    conds = sorted(set(o["first"]) | set(o["second"]))
    fit = pairwise.bradley_terry(o, n_boot=10)
    assert fit["nu"] == 0.0
    logit = sm.Logit((o["pref"] > 0).astype(float).to_numpy(), _design(o, conds, "NAT")).fit(disp=0, tol=1e-12)
    others = [c for c in conds if c != "NAT"]
    for c, beta in zip(others, logit.params):
        assert fit["strengths"][c] == pytest.approx(beta, abs=1e-5)
    assert fit["strengths"]["NAT"] == 0.0
    assert fit["log_likelihood"] == pytest.approx(logit.llf, abs=1e-6)


def test_bradley_terry_with_ties_matches_the_same_likelihood_in_statsmodels():
    from statsmodels.base.model import GenericLikelihoodModel

    truth = {"NAT": 0.0, "MG": -0.6, "FL": -1.5}
    rows = simulate_pairs(truth, nu=0.7, n_raters=60, seed=4)
    o = pairwise.oriented(pd.DataFrame(rows, columns=PAIR_COLS))
    conds = sorted(truth)
    X = _design(o, conds, "NAT")
    outcome = np.sign(o["pref"].to_numpy())

    class Davidson(GenericLikelihoodModel):
        def loglikeobs(self, params):
            d = self.exog @ params[:-1]  # theta_first - theta_second
            lognu = params[-1]
            # with theta_second as the baseline: P ~ exp(d), 1, nu exp(d / 2)
            terms = np.stack([d, np.zeros_like(d), lognu + d / 2])
            lse = np.logaddexp.reduce(terms, axis=0)
            return np.choose((outcome < 0) + 2 * (outcome == 0), terms) - lse

    model = Davidson(outcome.astype(float), X, extra_params_names=["lognu"])
    # GenericLikelihoodModel counts a constant that this design (differences of indicators) does not have
    model.df_model, model.df_resid = X.shape[1], len(X) - X.shape[1] - 1
    m = model.fit(start_params=np.zeros(X.shape[1] + 1), method="newton", disp=0, tol=1e-12, maxiter=200)
    assert m.mle_retvals["converged"]
    fit = pairwise.bradley_terry(o, n_boot=200, seed=1)
    for c, beta in zip([c for c in conds if c != "NAT"], m.params[:-1]):
        assert fit["strengths"][c] == pytest.approx(beta, abs=1e-4)
        lo, hi = fit["ci"][c]
        assert lo < fit["strengths"][c] < hi
    assert fit["nu"] == pytest.approx(np.exp(m.params[-1]), rel=1e-3)
    assert fit["strengths"]["MG"] > fit["strengths"]["FL"]  # the order of the truth
    assert fit["ci"]["NAT"] == [0.0, 0.0]


def test_bradley_terry_batch_fits_each_table_as_alone():
    """The bootstrap fits its resamples as one batch: each must come out as it would alone, including a table
    where one condition never wins (the ridge keeps it finite) and one without ties in a model with them."""
    conds, pairs = ["FL", "MG", "NAT"], np.array([[0, 1], [0, 2], [1, 2]])
    tables = np.array(
        [
            [[5, 7, 3], [2, 9, 4], [4, 8, 2]],
            [[0, 6, 0], [0, 7, 0], [3, 3, 3]],  # FL never wins nor ties
            [[6, 4, 0], [3, 5, 0], [2, 6, 0]],
        ],
        dtype=float,
    )
    batch = pairwise.fit_bradley_terry(tables, pairs, conds, "NAT", ties=True)
    for table, together in zip(tables, batch):
        alone = pairwise.fit_bradley_terry(table, pairs, conds, "NAT", ties=True)
        assert together["converged"] and alone["converged"]
        for c in conds:
            assert together["strengths"][c] == pytest.approx(alone["strengths"][c], abs=1e-7)
        assert together["nu"] == pytest.approx(alone["nu"], rel=1e-6)
    assert batch[1]["strengths"]["FL"] < -5  # never wins: far below, but finite
    assert np.isfinite(batch[1]["strengths"]["FL"])


def test_pairwise_catch_exclusion_either_level():
    rows = simulate_pairs({"NAT": 0, "MG": -1}, n_raters=6, items=1, catch_fail=(1, 4))
    df = pd.DataFrame(rows, columns=PAIR_COLS).astype(str)
    df["preference"] = df["preference"].astype(int)
    assert pairwise.failed_raters(df) == ["r1", "r4"]
    df.loc[(df["role"] == "catch") & (df["rater_id"] == "r1"), "preference"] //= 2  # +-1: still preferring BAD
    assert pairwise.failed_raters(df) == ["r1", "r4"]


# ---------------------------------------------------------------------------------------------- parallel
def simulate_pages(means, n_raters=12, items=8, seed=2, fail=()):
    rng = np.random.default_rng(seed)
    rows = []
    for r in range(n_raters):
        bias = rng.normal(0, 5)
        for it in range(items):
            for c, m in means.items():
                v = int(np.clip(round(m + bias + rng.normal(0, 12)), 0, 100))
                rows.append([f"r{r}", f"p{r}_{it}", f"i{it}", f"c{it}{c}", c, v, "test"])
        nat, bad = (40, 40) if r in fail else (80, 10)
        rows += [
            [f"r{r}", f"k{r}", "k0", "kn", "NAT", nat, "catch"],
            [f"r{r}", f"k{r}", "k0", "kb", "BAD", bad, "catch"],
        ]
    return rows


def test_parallel_statistics_against_scipy(tmp_path):
    from statsmodels.stats.multitest import multipletests

    rows = simulate_pages({"NAT": 75, "MG": 60, "FL": 58, "X": 30}, fail=(3,))
    f = write(tmp_path / "ratings.csv", PAGE_COLS, rows)
    doc = build_report(f, tmp_path / "rep", Options(n_boot=50), quiet=True)
    assert doc["design"] == "parallel" and doc["excluded_raters"] == ["r3"]
    # the methods paragraph names what the report computed: the mixed model and the bootstrap, with its count
    assert "a linear mixed model with crossed random intercepts for raters and items" in doc["methods"]
    assert "a bootstrap over raters (50 resamples, seed 0;" in doc["methods"]
    df = pd.DataFrame(rows, columns=PAGE_COLS)
    kept = df[(df["role"] == "test") & (df["rater_id"] != "r3")]
    for c, m in doc["condition_means"].items():
        assert m == pytest.approx(kept.loc[kept["condition"] == c, "rating"].mean())
        assert doc["condition_medians"][c] == pytest.approx(kept.loc[kept["condition"] == c, "rating"].median())
        lo, hi = doc["condition_summary"][c]["mean_low"], doc["condition_summary"][c]["mean_high"]
        assert lo <= m <= hi
    wide = {}
    for _, r in kept.iterrows():
        wide.setdefault(r["page_id"], {})[r["condition"]] = r["rating"]
    ps, got = [], []
    for w in doc["wilcoxon"]:
        a, b = w["group1"], w["group2"]
        x = [p[a] for p in wide.values()]
        y = [p[b] for p in wide.values()]
        ref = sps.wilcoxon(x, y)
        assert w["statistic"] == pytest.approx(ref.statistic) and w["p"] == pytest.approx(ref.pvalue, rel=1e-12)
        assert w["n_pages"] == len(x)
        ps.append(ref.pvalue)
        got.append(w["p_holm"])
    assert got == pytest.approx(list(multipletests(ps, method="holm")[1]), rel=1e-12)
    assert [w["reject"] for w in doc["wilcoxon"]] == [p < 0.05 for p in got]
    mm = doc["mixed_model"]
    assert mm["reference"] == "NAT" and "condition[T.X]" in mm["fixed_effects"] and mm["formula"].endswith("(1|item)")
    assert mm["fixed_effects"]["condition[T.X]"] < -30
    assert doc["without_exclusion"]["n_test_ratings"] == len(df[df["role"] == "test"])
    assert (tmp_path / "rep" / "figures" / "ratings_boxplot.png").stat().st_size > 5000


def test_parallel_catch_failure_is_bad_at_or_above_nat():
    rows = simulate_pages({"NAT": 70, "MG": 50}, n_raters=4, items=1, fail=(2,))
    df = pd.DataFrame(rows, columns=PAGE_COLS)
    assert parallel.failed_raters(df) == ["r2"]  # BAD 40 == NAT 40: at, so failed
    df.loc[(df["rater_id"] == "r0") & (df["condition"] == "BAD") & (df["role"] == "catch"), "rating"] = 79
    assert parallel.failed_raters(df) == ["r2"]  # 79 < 80: passed
    df.loc[(df["rater_id"] == "r0") & (df["condition"] == "BAD") & (df["role"] == "catch"), "rating"] = 81
    assert parallel.failed_raters(df) == ["r0", "r2"]


# ---------------------------------------------------------------------------------------------- files
def test_design_detected_from_the_columns(tmp_path):
    assert detect_design(write(tmp_path / "a.csv", PAIR_COLS, [])) == "pairwise"
    assert detect_design(write(tmp_path / "b.csv", PAGE_COLS, [])) == "parallel"
    assert detect_design(write(tmp_path / "c.csv", ["rater_id", "clip_id", "condition", "rating"], [])) == "acr"


GOOD_PAIR = ["r1", "i1", "ca", "cb", "NAT", "MG", "1", "test"]
GOOD_PAGE = [["r1", "p1", "i1", "ca", "NAT", "70", "test"], ["r1", "p1", "i1", "cb", "MG", "40", "test"]]
PAIR_BAD_ROWS = [
    (["r1", "i1", "ca", "cb", "NAT", "MG", "3", "test"], "preference '3' is not an integer -2..2"),
    (["r1", "i1", "ca", "cb", "NAT", "MG", "0.5", "test"], "preference '0.5'"),
    (["r1", "i1", "ca", "cb", "NAT", "MG", "", "test"], "empty preference"),
    (["r1", "i1", "ca", "cb", "NAT", "NAT", "1", "test"], "condition NAT on both sides"),
    (["r1", "i1", "ca", "ca", "NAT", "MG", "1", "test"], "clip ca on both sides"),
    (["r1", "i1", "cb", "ca", "MG", "NAT", "-1", "test"], "rater r1 compared clips ca and cb twice (first at line 2)"),
    (["r1", "i1", "cx", "cy", "NAT", "MG", "1", "warmup"], "unknown role 'warmup'"),
    (["", "i1", "cx", "cy", "NAT", "MG", "1", "test"], "empty rater_id"),
]
PAGE_BAD_ROWS = [
    (["r1", "p2", "i2", "cc", "NAT", "101", "test"], "rating '101' is not an integer 0-100"),
    (["r1", "p2", "i2", "cc", "NAT", "-1", "test"], "rating '-1'"),
    (["r1", "p2", "i2", "cc", "NAT", "7.5", "test"], "rating '7.5'"),
    (["r1", "p1", "i1", "cc", "NAT", "50", "test"], "condition NAT twice on page p1"),
    (["r1", "p1", "i1", "cb", "FL", "50", "test"], "clip cb twice on page p1"),
    (["r2", "p1", "i1", "cc", "FL", "50", "test"], "page p1 has rater_id 'r2'"),
    (["r1", "p1", "i9", "cc", "FL", "50", "test"], "page p1 has item 'i9'"),
    (["r1", "p2", "i1", "ca", "NAT", "50", "test"], "clip ca rated twice by rater r1"),
    (["r1", "p2", "i2", "cc", "NAT", "50", "bogus"], "unknown role 'bogus'"),
]


@pytest.mark.parametrize("row,needle", PAIR_BAD_ROWS)
def test_bad_pair_rows_are_refused_naming_the_row(tmp_path, row, needle):
    f = write(tmp_path / "pairs.csv", PAIR_COLS, [GOOD_PAIR, row])
    with pytest.raises(AnalysisError, match="pairs.csv:3: " + needle.replace("(", r"\(").replace(")", r"\)")):
        pairwise.load_pairs(f)


@pytest.mark.parametrize("row,needle", PAGE_BAD_ROWS)
def test_bad_page_rows_are_refused_naming_the_row(tmp_path, row, needle):
    f = write(tmp_path / "ratings.csv", PAGE_COLS, [*GOOD_PAGE, row])
    with pytest.raises(AnalysisError, match="ratings.csv:4: " + needle):
        parallel.load_pages(f)


def test_cli_gives_one_line_for_a_bad_row_and_writes_the_report(tmp_path, capsys):
    """analysis.report's main in-process (its own process: tests/analysis/test_analysis_load.py)."""
    f = write(tmp_path / "pairs.csv", PAIR_COLS, [GOOD_PAIR, ["r1", "i2", "cc", "cd", "NAT", "FL", "9", "test"]])
    fails_with(report_main, [str(f), "--out", str(tmp_path / "o")], capsys, f"{f}:3: preference '9'")
    f = write(tmp_path / "ok.csv", PAIR_COLS, simulate_pairs({"NAT": 0, "MG": -1}, n_raters=5, items=2))
    assert report_main([str(f), "--out", str(tmp_path / "o"), "--n-boot", "20"]) == 0
    doc = json.loads((tmp_path / "o" / "stats.json").read_text())
    assert doc["design"] == "pairwise" and set(doc["bradley_terry"]) == {"NAT", "MG"}
    assert doc["bradley_terry"]["NAT"] == 0 and set(doc["bradley_terry_ci"]) == {"NAT", "MG"}
    assert "MG vs NAT" in capsys.readouterr().out


def test_a_condition_that_never_wins_stays_finite():
    rows = [[f"r{r}", f"i{i}", f"n{i}", f"f{i}", "NAT", "FL", 2, "test"] for r in range(5) for i in range(4)]
    rows += [
        [f"r{r}", f"i{i}", f"m{i}", f"n{i}", "MG", "NAT", (-1) ** (r + i), "test"] for r in range(5) for i in range(4)
    ]
    fit = pairwise.bradley_terry(pairwise.oriented(pd.DataFrame(rows, columns=PAIR_COLS)), n_boot=30)
    assert fit["separated"] and not fit["converged"]  # no maximum likelihood: the ridge holds FL (issue 55)
    assert -20 < fit["strengths"]["FL"] < -8 and abs(fit["strengths"]["MG"]) < 1e-6
    assert all(np.isfinite(v).all() for v in fit["ci"].values())
