"""The ordinal mixed model and the Satterthwaite df against R (ordinal::clmm, lmerTest), frozen in
tests/data/analysis/r_reference.json by r_reference.R -- CI never needs R."""

import json

import numpy as np
import pandas as pd
import pytest
from helpers.paths import TEST_DATA

from analysis.data.filtering import exclude_raters, only_test_rows
from analysis.data.load import load_ratings
from analysis.stats import ordinal, rating_models

DATA = TEST_DATA / "analysis"
R = json.loads((DATA / "r_reference.json").read_text())


@pytest.fixture(scope="module")
def rows():
    t = only_test_rows(exclude_raters(load_ratings(DATA / "ratings_r_reference.csv"))[0])
    assert (
        (len(t), t["rater_id"].nunique(), t["clip_id"].nunique())
        == (R["data"]["n"], R["data"]["n_raters"], R["data"]["n_clips"])
        == (2970, 66, 90)
    )
    return t


@pytest.fixture(scope="module")
def fit(rows):
    return rating_models.ordinal_model(rows)


def test_ordinal_model_matches_clmm(fit):
    ref = R["clmm"]
    assert fit["reference"] == "NAT" and fit["converged"]
    assert list(fit["thresholds"]) == ["1|2", "2|3", "3|4", "4|5"]
    for k, v in ref["fixed_effects"].items():
        assert fit["fixed_effects"][k] == pytest.approx(v, abs=2e-3), k
        assert fit["std_errors"][k] == pytest.approx(ref["std_errors"][k], rel=1e-2), k
    for k, v in ref["thresholds"].items():
        assert fit["thresholds"][k] == pytest.approx(v, abs=2e-3), k
    assert fit["sd_rater"] == pytest.approx(ref["sd_rater"], abs=5e-3)
    assert fit["sd_clip"] == pytest.approx(ref["sd_clip"], abs=5e-3)
    assert fit["log_likelihood"] == pytest.approx(ref["log_likelihood"], abs=1e-2)
    # clmm stops with |gradient| up to ~5e-3; our optimum must be at least as good
    assert fit["log_likelihood"] >= ref["log_likelihood"] - 1e-6


def test_ordinal_odds_ratios_and_fitted_distribution(fit, rows):
    for k, b in fit["fixed_effects"].items():
        assert fit["odds_ratios"][k] == pytest.approx(np.exp(b))
        assert fit["or_ci_low"][k] < fit["odds_ratios"][k] < fit["or_ci_high"][k]
        assert np.log(fit["or_ci_high"][k]) - b == pytest.approx(1.959964 * fit["std_errors"][k], rel=1e-5)
    for c, dist in fit["fitted_distribution"].items():
        assert sum(dist.values()) == pytest.approx(1, abs=1e-12)
        obs = rows.loc[rows["condition"] == c, "rating"].value_counts(normalize=True)
        # a good fit of a model-generated file: population-averaged shares within a few points of the data
        assert max(abs(dist[str(k)] - obs.get(k, 0)) for k in range(1, 6)) < 0.05, c
        assert fit["observed_distribution"][c]["3"] == pytest.approx(obs[3])


def test_laplace_gradient_is_exact(rows):
    """The analytic gradient (envelope + log|H| terms through the implicit mode) equals central differences
    of log L; a missing third-derivative or implicit term shows up here at 1e-3 or worse."""
    y = rows["rating"].to_numpy().astype(int) - 1
    cond = rows["condition"].to_numpy()
    X = np.column_stack([(cond == c).astype(float) for c in ("FL", "MG")])
    d = ordinal._Design(y, X, pd.factorize(rows["rater_id"])[0], pd.factorize(rows["clip_id"])[0], 5)
    lap = ordinal._Laplace(d)
    phi = np.array([-2.5, -1.1, 0.2, 1.7, -1.4, -0.5, np.log(0.7), np.log(0.4)])
    _, grad = lap.value_and_grad(phi)
    for k in range(len(phi)):
        e = np.zeros(len(phi))
        e[k] = 1e-5
        num = (lap.value_and_grad(phi + e)[0] - lap.value_and_grad(phi - e)[0]) / 2e-5
        assert grad[k] == pytest.approx(num, rel=1e-6, abs=1e-5), k


def test_ordinal_recovers_a_known_model():
    """Simulated from the model itself (thresholds, effects, SDs known): every estimate lands within 3 of its
    standard errors of the truth (the SEs are the Hessian's, so this also checks they are not too small)."""
    rng = np.random.default_rng(3)
    R_, C = 80, 90
    r, c = np.meshgrid(np.arange(R_), np.arange(C), indexing="ij")
    r, c = r.ravel(), c.ravel()
    cond = np.array(["NAT", "MG", "FL"])[c % 3]
    eta = np.array([0.0, -0.7, -1.5])[c % 3] + rng.normal(0, 0.9, R_)[r] + rng.normal(0, 0.3, C)[c]
    y = 1 + (eta[:, None] + rng.logistic(size=len(r))[:, None] > np.array([-2, -0.7, 0.6, 2.0])).sum(1)
    m = rating_models.ordinal_model(pd.DataFrame({"rating": y, "condition": cond, "rater_id": r, "clip_id": c}))
    for k, truth in (("condition[T.MG]", -0.7), ("condition[T.FL]", -1.5)):
        assert abs(m["fixed_effects"][k] - truth) < 3 * m["std_errors"][k], k
    for k, truth in zip(["1|2", "2|3", "3|4", "4|5"], [-2, -0.7, 0.6, 2.0]):
        assert abs(m["thresholds"][k] - truth) < 3 * m["threshold_std_errors"][k], k
    assert m["sd_rater"] == pytest.approx(0.9, abs=0.2)


def test_a_parameter_the_ratings_do_not_identify_leaves_the_standard_errors_undefined():
    """Each rater rates one clip of their own, four times: the rater and clip intercepts are one effect, so only
    the sum of their variances is identified and the information matrix is singular along their split. It was
    inverted whole (a LinAlgWarning, standard errors of round-off); now they are undefined and the fit's warnings
    say why, as clmm leaves them. A crossed design has them all."""
    import warnings

    rng = np.random.default_rng(2)
    n = 30
    who = np.repeat(np.arange(n), 4)
    cond = np.array(["NAT", "MG", "FL"])[who % 3]
    eta = np.array([0.0, -0.8, -1.6])[who % 3] + rng.normal(0, 0.8, n)[who]
    y = 1 + (eta[:, None] + rng.logistic(size=len(who))[:, None] > np.array([-2, -0.7, 0.6, 2.0])).sum(1)
    df = pd.DataFrame({"rating": y, "condition": cond, "rater_id": who, "clip_id": who})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no LinAlgWarning
        m = rating_models.ordinal_model(df)
    assert "the information matrix is singular: standard errors undefined" in m["warnings"], m["warnings"]
    assert all(np.isnan(v) for v in m["std_errors"].values()) and not m["converged"]
    crossed = rating_models.ordinal_model(df.assign(clip_id=np.tile(np.arange(4), n)))
    assert crossed["converged"] and crossed["warnings"] == []
    assert all(np.isfinite(v) for v in crossed["std_errors"].values())


def test_unused_rating_level_has_no_threshold(rows):
    """As clmm: the thresholds are between adjacent observed levels."""
    t = rows.assign(rating=rows["rating"].replace({5: 4}))
    m = rating_models.ordinal_model(t)
    assert list(m["thresholds"]) == ["1|2", "2|3", "3|4"]


def test_satterthwaite_matches_lmertest(rows):
    ref = R["lmer"]
    m = rating_models.mixed_model(rows)
    assert set(m["df"]) == set(ref["df"])
    for k in ref["df"]:
        assert m["df"][k] == pytest.approx(ref["df"][k], abs=1e-2), k
        assert m["p_values"][k] == pytest.approx(ref["p_values"][k], rel=1e-4), k
        assert m["std_errors"][k] == pytest.approx(ref["std_errors"][k], rel=1e-5), k
        assert m["t"][k] == pytest.approx(ref["t"][k], rel=1e-5), k
    for k, v in ref["variance_components"].items():
        assert m["variance_components"][k] == pytest.approx(v, rel=1e-4)
    assert m["reml_log_likelihood"] == pytest.approx(ref["reml_log_likelihood"], abs=1e-6)
    # the intervals are t intervals on those df (wider than the old normal ones)
    from scipy import stats as sps

    k = "condition[T.MG]"
    half = sps.t.ppf(0.975, ref["df"][k]) * ref["std_errors"][k]
    assert m["ci_high"][k] - m["fixed_effects"][k] == pytest.approx(half, rel=1e-4)


def test_satterthwaite_df_near_the_number_of_clips(rows):
    """Conditions are between clips, so a condition effect has about (clips - conditions) df, not ratings - 3:
    the reason a z test was anti-conservative."""
    m = rating_models.mixed_model(rows)
    assert 80 < m["df"]["condition[T.FL]"] < 95
