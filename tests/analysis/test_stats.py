"""Regression tests of the statistics against certified and published reference values."""

import re
import warnings
from decimal import Decimal

import numpy as np
import pandas as pd
import pytest
from helpers.paths import TEST_DATA
from reference.anova_exact import one_way_anova_exact

from analysis.data.filtering import exclude_raters, only_test_rows
from analysis.data.load import load_ratings
from analysis.stats import anova as stats
from analysis.stats import bootstrap, mixed, rating_models

DATA = TEST_DATA
NIST = sorted((DATA / "nist_anova").glob("*.dat"))
SMALL = DATA / "analysis" / "ratings_small.csv"


def read_nist(path):
    """Parse a NIST StRD ANOVA .dat file: certified F/df/SS from its table, data lines from its header."""
    text = path.read_text()
    lines = text.splitlines()
    first, last = map(int, re.search(r"Data\s+\(lines (\d+) to (\d+)\)", text).groups())
    between = next(ln.split() for ln in lines if re.match(r"\s*Between\b", ln))
    within = next(ln.split() for ln in lines if re.match(r"\s*Within\b", ln))
    cert = {
        "df_between": int(between[2]),
        "ss_between": float(between[3]),
        "F": float(between[5]),
        "df_within": int(within[2]),
        "ss_within": float(within[3]),
    }
    rows = [ln.split() for ln in lines[first - 1 : last]]
    data = pd.DataFrame({"group": [r[0] for r in rows], "y": [Decimal(r[1]) for r in rows]})
    return data, cert


def sig_digits(value, ref):
    """Log relative error (LRE), the number of matching significant digits NIST uses."""
    if value == ref:
        return 99.0
    return -np.log10(abs(value - ref) / abs(ref))


def test_all_eleven_nist_datasets_present():
    assert [p.stem for p in NIST] == ["AtmWtAg", "SiRstv"] + [f"SmLs{i:02d}" for i in range(1, 10)]


@pytest.mark.parametrize("path", NIST, ids=[p.stem for p in NIST])
def test_anova_table_matches_nist_certified_values(path):
    """Given exact sums of squares, the product's ANOVA table gives the certified values on all eleven sets."""
    data, cert = read_nist(path)
    res = one_way_anova_exact(data, "y", "group")
    assert res["df_between"] == cert["df_between"] and res["df_within"] == cert["df_within"]
    assert sig_digits(res["F"], cert["F"]) >= 9, (res["F"], cert["F"])
    assert sig_digits(res["ss_between"], cert["ss_between"]) >= 9
    assert sig_digits(res["ss_within"], cert["ss_within"]) >= 9


@pytest.mark.parametrize(
    "path", [p for p in NIST if p.stem not in ("SmLs07", "SmLs08", "SmLs09")], ids=lambda p: p.stem
)
def test_anova_float_path_is_stable(path):
    """With float64 input (no decimal), the shifted two-pass algorithm still gives >= 9 digits wherever
    float64 can hold the data. (SmLs07-09 carry 13-15 constant digits: 1000000000000.4 is not a float64, so
    only the exact decimal path can reach the certified F there.)"""
    data, cert = read_nist(path)
    res = stats.one_way_anova(data.assign(y=data["y"].astype(float)), "y", "group")
    assert res["df_between"] == cert["df_between"] and res["df_within"] == cert["df_within"]
    for key in ("F", "ss_between", "ss_within"):
        assert sig_digits(res[key], cert[key]) >= 9, (key, res[key], cert[key])


def test_naive_sum_of_squares_fails_where_we_do_not():
    """The test data are hard: the textbook sum(y^2) - (sum y)^2/n formula loses every digit on SmLs09."""
    data, cert = read_nist(DATA / "nist_anova" / "SmLs09.dat")
    y = data["y"].astype(float).to_numpy()
    g = data["group"].to_numpy()
    ssw = sum((y[g == k] ** 2).sum() - y[g == k].sum() ** 2 / (g == k).sum() for k in np.unique(g))
    assert sig_digits(ssw, cert["ss_within"]) < 3
    assert sig_digits(one_way_anova_exact(data, "y", "group")["F"], cert["F"]) >= 9


# R 4.x, TukeyHSD(aov(weight ~ group, data = PlantGrowth)), as printed (identically) in several public knitted
# R Markdown reports on GitHub (e.g. an "FA8" one-way ANOVA course report run under R 4.3.3) and in the
# visStatistics package documentation (shhschilling.github.io/visStatistics, reference/visstat: its post-hoc
# printout for PlantGrowth). Data = R's datasets::PlantGrowth (Dobson 1983; e.g. wonhyukc/data PlantGrowth.csv):
#               diff        lwr       upr     p adj
#   trt1-ctrl -0.371 -1.0622161 0.3202161 0.3908711
#   trt2-ctrl  0.494 -0.1972161 1.1852161 0.1979960
#   trt2-trt1  0.865  0.1737839 1.5562161 0.0120064
# and summary(aov(...)): group Df 2, Residuals 27, F value 4.846, Pr(>F) 0.0159.
R_TUKEY = [
    ("ctrl", "trt1", -0.371, -1.0622161, 0.3202161, 0.3908711),
    ("ctrl", "trt2", 0.494, -0.1972161, 1.1852161, 0.1979960),
    ("trt1", "trt2", 0.865, 0.1737839, 1.5562161, 0.0120064),
]


def test_tukey_matches_r_tukeyhsd_on_plantgrowth():
    pg = pd.read_csv(DATA / "analysis" / "plantgrowth.csv")
    res = stats.tukey_hsd(pg, "weight", "group")
    assert len(res) == 3
    for row, (g1, g2, diff, lwr, upr, p) in zip(res.itertuples(), R_TUKEY):
        assert (row.group1, row.group2) == (g1, g2)
        # R prints 7 decimals, so agreement to 1e-6 means every printed digit matches
        assert row.meandiff == pytest.approx(diff, abs=1e-6)
        assert row.lower == pytest.approx(lwr, abs=1e-6)
        assert row.upper == pytest.approx(upr, abs=1e-6)
        assert row.p_adj == pytest.approx(p, abs=1e-6)
        assert row.reject == (p < 0.05)
    a = stats.one_way_anova(pg, "weight", "group")
    assert (a["df_between"], a["df_within"]) == (2, 27)
    assert round(a["F"], 3) == 4.846 and round(a["p"], 4) == 0.0159


def test_tukey_unbalanced_matches_statsmodels():
    from statsmodels.stats.multicomp import pairwise_tukeyhsd

    rng = np.random.default_rng(1)
    df = pd.DataFrame({"g": np.repeat(list("dbca"), [5, 9, 14, 7])})
    df["y"] = rng.normal(size=len(df)) + df["g"].map({"a": 0, "b": 0.9, "c": 1.4, "d": 0.2})
    ours = stats.tukey_hsd(df, "y", "g")
    ref = pairwise_tukeyhsd(df["y"], df["g"])
    table = pd.DataFrame(ref.summary().data[1:], columns=ref.summary().data[0])
    assert list(zip(ours.group1, ours.group2)) == list(zip(table.group1, table.group2))
    np.testing.assert_allclose(ours.meandiff, ref.meandiffs, rtol=1e-12)
    np.testing.assert_allclose(ours.lower, ref.confint[:, 0], rtol=1e-6)
    np.testing.assert_allclose(ours.p_adj, ref.pvalues, atol=1e-6)


def test_holm_matches_statsmodels():
    from statsmodels.stats.multitest import multipletests

    p = np.array([0.01, 0.04, 0.03, 0.005, 0.5, 0.04])
    np.testing.assert_allclose(stats.holm(p), multipletests(p, method="holm")[1], rtol=1e-12)


def test_mannwhitney_effect_size_and_holm():
    df = pd.DataFrame({"c": ["A"] * 6 + ["B"] * 5 + ["C"] * 4, "y": [1, 2, 2, 3, 3, 4, 2, 3, 4, 4, 5, 5, 5, 4, 1]})
    res = stats.pairwise_mannwhitney(df, "y", "c")
    assert list(zip(res.group1, res.group2)) == [("A", "B"), ("A", "C"), ("B", "C")]
    for row in res.itertuples():  # cles = P(group2 > group1) + P(tie)/2 by brute force over all pairs
        a = df.loc[df.c == row.group1, "y"].to_numpy()
        b = df.loc[df.c == row.group2, "y"].to_numpy()
        brute = ((b[:, None] > a[None, :]) + 0.5 * (b[:, None] == a[None, :])).mean()
        assert row.cles == pytest.approx(brute)
        assert row.rank_biserial == pytest.approx(2 * brute - 1)
    np.testing.assert_allclose(res.p_holm, stats.holm(res.p))
    assert (res.p_holm >= res.p).all()


@pytest.fixture(scope="module")
def small_test_rows():
    df = load_ratings(SMALL)
    kept, _ = exclude_raters(df)
    return only_test_rows(kept)


def test_cluster_bootstrap_equals_explicit_weighted_means(small_test_rows):
    """The vectorised replicate means equal sum(w y)/sum(w) computed one replicate at a time, for the same
    draws, and dense and sparse paths agree exactly."""
    t = small_test_rows
    B, seed = 7, 3
    fast = bootstrap.cluster_bootstrap(t, n_boot=B, seed=seed)
    sparse = bootstrap.cluster_bootstrap(t, n_boot=B, seed=seed, dense_limit=0)
    pd.testing.assert_frame_equal(fast["means"], sparse["means"], rtol=0, atol=1e-12)
    rng = np.random.default_rng(seed)
    rc, raters = pd.factorize(t["rater_id"])
    cc, clips = pd.factorize(t["clip_id"])
    cond, conds = pd.factorize(t["condition"], sort=True)
    wr = bootstrap._resample_counts(rng, B, len(raters))
    wc = np.zeros((B, len(clips)))
    clip_cond = np.zeros(len(clips), int)
    clip_cond[cc] = cond
    for k in range(len(conds)):
        members = np.flatnonzero(clip_cond == k)
        wc[:, members] = bootstrap._resample_counts(rng, B, len(members))
    y = t["rating"].to_numpy(float)
    reps = np.array(
        [
            [
                np.sum((w := wr[b, rc] * wc[b, cc])[cond == k] * y[cond == k]) / w[cond == k].sum()
                for k in range(len(conds))
            ]
            for b in range(B)
        ]
    )
    expected_se = pd.Series(reps.std(axis=0, ddof=1), index=conds)
    np.testing.assert_allclose(fast["means"]["boot_se"].loc[conds], expected_se, rtol=1e-12)
    lo = pd.Series(np.percentile(reps, 2.5, axis=0), index=conds)
    np.testing.assert_allclose(fast["means"]["boot_low"].loc[conds], lo, rtol=1e-12)


def test_cluster_bootstrap_is_wider_than_t_when_clips_and_raters_vary(small_test_rows):
    """Ratings are correlated within raters and clips, so the cluster bootstrap must not be narrower than the
    naive t interval that treats 480 ratings as independent (the reason to report it)."""
    t = small_test_rows
    boot = bootstrap.cluster_bootstrap(t, n_boot=400, seed=1)["means"]
    summ = stats.group_summary(t)
    assert ((boot.boot_high - boot.boot_low) > 1.5 * (summ.t_high - summ.t_low)).all()
    assert ((boot.boot_low < summ["mean"]) & (summ["mean"] < boot.boot_high)).all()


def test_mixed_model_matches_statsmodels_reml(small_test_rows):
    """Our profiled REML optimum = statsmodels MixedLM's (crossed variance components, Nelder-Mead) optimum."""
    import statsmodels.formula.api as smf

    t = small_test_rows[small_test_rows["rater_id"].isin(sorted(small_test_rows["rater_id"].unique())[:8])]
    ours = rating_models.mixed_model(t, reference="FL")
    data = pd.DataFrame(
        {
            "y": t["rating"].astype(float).to_numpy(),
            "cond": t["condition"].to_numpy(),
            "rater": t["rater_id"].to_numpy(),
            "clip": t["clip_id"].to_numpy(),
            "g": 0,
        }
    )
    ref = smf.mixedlm(
        "y ~ cond", data, groups="g", re_formula="0", vc_formula={"rater": "0 + C(rater)", "clip": "0 + C(clip)"}
    ).fit(reml=True, method="nm", maxiter=4000)
    vc = dict(zip(ref.model.exog_vc.names, ref.vcomp))
    assert ours["reml_log_likelihood"] >= ref.llf - 1e-7  # never a worse optimum
    assert ours["reml_log_likelihood"] == pytest.approx(ref.llf, abs=1e-5)
    assert ours["variance_components"]["rater"] == pytest.approx(vc["rater"], rel=2e-3)
    assert ours["variance_components"]["clip"] == pytest.approx(vc["clip"], rel=2e-3)
    assert ours["variance_components"]["residual"] == pytest.approx(ref.scale, rel=1e-4)
    np.testing.assert_allclose(list(ours["fixed_effects"].values()), ref.fe_params.to_numpy(), rtol=1e-6)
    np.testing.assert_allclose(list(ours["std_errors"].values()), ref.bse_fe.to_numpy(), rtol=2e-3)
    assert list(ours["fixed_effects"]) == ["Intercept", "condition[T.MG]", "condition[T.NAT]"]


def test_mixed_model_recovers_simulated_variances():
    """On a large simulated crossed design the REML estimates land near the true variance components."""
    rng = np.random.default_rng(0)
    R, C = 120, 90
    r, c = np.meshgrid(np.arange(R), np.arange(C), indexing="ij")
    r, c = r.ravel(), c.ravel()
    cond = np.array(["NAT", "MG", "FL"])[c % 3]
    y = (
        np.array([4.0, 3.5, 2.5])[c % 3]
        + rng.normal(0, np.sqrt(0.2), R)[r]
        + rng.normal(0, np.sqrt(0.1), C)[c]
        + rng.normal(0, np.sqrt(0.5), len(r))
    )
    df = pd.DataFrame({"rating": y, "condition": cond, "rater_id": r, "clip_id": c})
    m = rating_models.mixed_model(df)
    assert m["reference"] == "NAT" and m["converged"]
    vc = m["variance_components"]
    assert vc["rater"] == pytest.approx(0.2, rel=0.3)
    assert vc["clip"] == pytest.approx(0.1, rel=0.4)
    assert vc["residual"] == pytest.approx(0.5, rel=0.03)
    # complete balanced design: GLS fixed effects equal the raw condition mean differences
    means = df.groupby("condition")["rating"].mean()
    assert m["fixed_effects"]["condition[T.FL]"] == pytest.approx(means["FL"] - means["NAT"], abs=1e-9)


def test_a_variance_the_ratings_do_not_identify_is_named_and_left_out_of_the_df():
    """Each rater rates one clip of their own, twice: the rater and clip intercepts are one effect, so only the sum
    of their variances is identified, and the REML criterion is flat along their split. The Satterthwaite df leave
    that direction out (its Hessian inverted over the others: it was inverted whole, with an rcond near 1e-30 and a
    LinAlgWarning) and the fit's warnings say so; a crossed design has no such direction."""
    rng = np.random.default_rng(1)
    n = 24
    who = np.repeat(np.arange(n), 2)
    cond = np.array(["NAT", "MG", "FL"])[who % 3]
    y = np.array([4.0, 3.2, 2.6])[who % 3] + rng.normal(0, 0.6, n)[who] + rng.normal(0, 0.5, 2 * n)
    df = pd.DataFrame({"rating": y, "condition": cond, "rater_id": who, "clip_id": who})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no LinAlgWarning, no division by round-off
        m = rating_models.mixed_model(df)
    assert any("flat along 1 direction" in w for w in m["warnings"]), m["warnings"]
    # one random intercept per rater-and-clip unit: its df are the units' less the three fixed effects
    assert m["df"] == pytest.approx(dict.fromkeys(m["df"], n - 3), rel=1e-6)
    crossed = rating_models.mixed_model(df.assign(clip_id=np.tile(np.arange(2), n)))
    assert not any("flat" in w for w in crossed["warnings"])


def test_ratings_the_effects_fit_exactly_leave_the_model_undefined_not_fitted_to_round_off():
    """Every rater rates every clip by their condition plus a bias of their own, with nothing left over: the REML
    criterion then has no minimum (it falls without end as the residual variance goes to 0). The fit stopped at
    a residual variance of 1e-16 with df of 1e14, or, a rounding away, raised a LinAlgError from its Hessian's
    probes. Now it is undefined, said in one line, and a rating off that pattern gives a fit again."""
    rater, clip = np.meshgrid(np.arange(12), np.arange(9), indexing="ij")
    rater, clip = rater.ravel(), clip.ravel()
    cond = np.array(["NAT", "MG", "FL"])[clip % 3]
    y = np.array([4.0, 3.0, 2.0])[clip % 3] + (rater % 2)
    df = pd.DataFrame({"rating": y, "condition": cond, "rater_id": rater, "clip_id": clip})
    for ratings in (y, y + 1e-9 * np.random.default_rng(0).standard_normal(len(y))):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(rating_models.ModelUndefined, match="fit every rating exactly"):
                rating_models.mixed_model(df.assign(rating=ratings))
    y[5] += 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = rating_models.mixed_model(df.assign(rating=y))
    assert m["converged"] and 0 < m["variance_components"]["residual"] < 0.1


@pytest.mark.parametrize("dense_max", [mixed.DENSE_MAX, 0], ids=["dense", "sparse"])
def test_the_fixed_effects_rss_is_least_squares_on_every_effect(dense_max, monkeypatch):
    """mixed.additive_rss, the exact-fit check: the residual sum of squares of y ~ X + rater + clip, all fixed, from
    the fit's sufficient statistics, whichever factor it eliminates, with X the intercept alone or with columns
    partly spanned by the levels; with the count table held dense and sparse."""
    monkeypatch.setattr(mixed, "DENSE_MAX", dense_max)
    rng = np.random.default_rng(3)
    for raters, clips in ((5, 9), (9, 5)):
        rater, clip = rng.integers(0, raters, 80), rng.integers(0, clips, 80)
        rater[:raters], clip[:clips] = np.arange(raters), np.arange(clips)
        X = np.column_stack([np.ones(80), rng.integers(0, 2, 80), clip % 2]).astype(float)
        y = rng.normal(size=80)
        dummies = np.zeros((80, raters + clips))
        dummies[np.arange(80), rater] = dummies[np.arange(80), raters + clip] = 1
        for x, design in ((X[:, :1], dummies), (X, np.column_stack([X, dummies]))):
            fit = np.linalg.lstsq(design, y, rcond=None)[0]
            want = ((design @ fit - y) ** 2).sum()
            assert mixed.additive_rss(mixed._Suff(y, x, rater, clip)) == pytest.approx(want, rel=1e-9)
            # a level with no rating left (as a bootstrap resample can have) changes nothing, and warns of nothing
            with np.errstate(all="raise"):
                gap = mixed.additive_rss(mixed._Suff(y, x, np.where(rater == 0, raters, rater), clip))
            assert gap == pytest.approx(want, rel=1e-9)


def test_a_dense_and_a_sparse_count_table_give_one_fit(monkeypatch):
    """_Suff holds a panel's rater x clip counts dense and a large one's sparse: on an incomplete table whose clips
    have many distinct counts (as a bootstrap resample's do), both give the same per-count Gram matrices, exactly
    (they sum counts), and the same fit."""
    rng = np.random.default_rng(5)
    # 15 clips of codes 0-18 (the others rated by no one), with skewed counts
    rater, clip = rng.integers(0, 12, 300), rng.integers(0, 20, 300) ** 2 // 20
    y = rng.normal(size=300) + 0.5 * rng.normal(size=12)[rater] + 0.7 * rng.normal(size=19)[clip]
    X = np.ones((300, 1))
    dense = mixed._Suff(y, X, rater, clip)
    monkeypatch.setattr(mixed, "DENSE_MAX", 0)
    sparse = mixed._Suff(y, X, rater, clip)
    assert isinstance(dense.A_op, np.ndarray) and not isinstance(sparse.A_op, np.ndarray)
    assert len(dense.gram_counts) > 5 and (dense.gram == sparse.gram).all()
    fits = []
    for limit in (10**9, 0):
        monkeypatch.setattr(mixed, "DENSE_MAX", limit)
        fits.append(mixed.fit_crossed(y, X, rater, clip, ["(Intercept)"]))
    # The same optimum: the criterion to round-off, the variances to the search's tolerance (it is flat there).
    assert fits[0]["reml_log_likelihood"] == pytest.approx(fits[1]["reml_log_likelihood"], rel=1e-12)
    for key in ("variance_components", "fixed_effects"):
        assert fits[0][key] == pytest.approx(fits[1][key], rel=1e-5), key


def test_per_clip_means_sorted_worst_to_best(small_test_rows):
    clips = stats.per_clip_means(small_test_rows)
    assert list(dict.fromkeys(clips.condition)) == ["NAT", "MG", "FL"]
    for _, part in clips.groupby("condition"):
        assert part["mean"].is_monotonic_increasing
        assert list(part["rank"]) == list(range(1, len(part) + 1))
    direct = small_test_rows.groupby("clip_id")["rating"].mean()
    np.testing.assert_allclose(clips.set_index("clip_id")["mean"].loc[direct.index], direct)


def test_metric_correlations_match_scipy(small_test_rows):
    from scipy import stats as sps

    clips = stats.per_clip_means(small_test_rows)
    metrics = pd.DataFrame({"m": np.arange(len(clips), dtype=float) ** 1.5}, index=clips["clip_id"][::-1])
    res = stats.metric_correlations(clips, metrics)
    row = res[(res.metric == "m") & (res.scope == "all")].iloc[0]
    joined = clips.set_index("clip_id").join(metrics)
    assert row.n == len(clips)
    assert row.pearson_r == pytest.approx(sps.pearsonr(joined["m"], joined["mean"])[0])
    assert row.spearman_rho == pytest.approx(sps.spearmanr(joined["m"], joined["mean"])[0])
    assert set(res.scope) == {"all", "NAT", "MG", "FL"}


def test_histogram_counts_every_kept_test_rating(small_test_rows):
    h = stats.rating_histogram(small_test_rows)
    assert list(h.columns) == [1, 2, 3, 4, 5]
    assert h.to_numpy().sum() == len(small_test_rows)
    for c in h.index:
        assert (h.loc[c].to_numpy() * np.arange(1, 6)).sum() / h.loc[c].sum() == pytest.approx(
            small_test_rows.loc[small_test_rows.condition == c, "rating"].mean()
        )


def test_anova_rejects_single_group():
    with pytest.raises(ValueError, match="at least 2 groups"):
        stats.one_way_anova(pd.DataFrame({"condition": ["A"] * 3, "rating": [1, 2, 3]}))
