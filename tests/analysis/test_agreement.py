"""Rater agreement (acr, parallel): Krippendorff's alpha and the ICC against the libraries that compute them
(krippendorff, pingouin), and the methods paragraph written from the data."""

import numpy as np
import pandas as pd
import pytest

from analysis import report
from analysis.designs import Options
from analysis.page import methods
from analysis.stats import agreement


def panel(raters=12, clips=30, seed=0, missing=0.0, clip_sd=1.0, noise=0.8):
    """Ratings 1..5 of `clips` clips by `raters` raters: a clip effect, a rater bias and noise."""
    rng = np.random.default_rng(seed)
    q, r = rng.normal(3, clip_sd, clips), rng.normal(0, 0.4, raters)
    m = np.clip(np.round(q[None] + r[:, None] + rng.normal(0, noise, (raters, clips))), 1, 5)
    rows = [(f"r{i}", f"c{j}", m[i, j], "test") for i in range(raters) for j in range(clips)]
    df = pd.DataFrame(rows, columns=["rater_id", "clip_id", "rating", "role"])
    return df.sample(frac=1 - missing, random_state=seed) if missing else df


def test_alpha_is_the_librarys_and_the_closed_form_agrees():
    import krippendorff

    df = panel(missing=0.4)
    table = df.pivot_table(index="rater_id", columns="clip_id", values="rating").to_numpy(float)
    lib = krippendorff.alpha(reliability_data=table, level_of_measurement="interval")
    res = agreement.krippendorff_alpha(df, n_boot=200)
    assert res["alpha"] == pytest.approx(lib)
    g = df.groupby("clip_id")["rating"]
    closed = agreement.alpha_from_sums(g.size(), g.sum(), g.apply(lambda x: (x**2).sum()))
    assert closed == pytest.approx(lib, abs=1e-12)
    assert res["ci"][0] < res["alpha"] < res["ci"][1]


@pytest.mark.filterwarnings("ignore:The inplace keyword in DataFrame.dropna")  # pingouin's, as _icc_complete ignores it
def test_icc_is_pingouins_on_a_complete_table_and_the_reml_estimate_matches_it():
    import pingouin

    df = panel()
    t = pingouin.intraclass_corr(df, targets="clip_id", raters="rater_id", ratings="rating").set_index("Type")
    res = agreement.icc(df)
    assert res["complete"] and res["icc_a1"] == pytest.approx(t.at["ICC(A,1)", "ICC"])
    assert res["icc_ak"] == pytest.approx(t.at["ICC(A,k)", "ICC"])
    # the REML variance components give the same values (they are used when the table is incomplete)
    codes = [pd.factorize(df[c], sort=True)[0] for c in ("rater_id", "clip_id")]
    a1, ak, _ = agreement._icc(df["rating"].to_numpy(float), *codes, 12.0)
    assert a1 == pytest.approx(t.at["ICC(A,1)", "ICC"], abs=1e-5) and ak == pytest.approx(
        t.at["ICC(A,k)", "ICC"], abs=1e-5
    )


def test_icc_of_an_incomplete_table_has_a_bootstrap_interval_that_tracks_agreement():
    good = agreement.icc(panel(missing=0.5, raters=10, clips=24, noise=0.4), n_boot=40)
    poor = agreement.icc(panel(missing=0.5, raters=10, clips=24, clip_sd=0.2, noise=1.2, seed=1), n_boot=40)
    assert not good["complete"] and good["n_boot"] == 40
    assert good["icc_a1_ci"][0] <= good["icc_a1"] <= good["icc_a1_ci"][1]
    assert good["icc_a1"] > 0.6 > 0.2 > poor["icc_a1"]


def test_an_exact_fit_has_no_icc():
    # Ratings that a rater bias plus a clip level give exactly: the REML criterion has no minimum, so no ICC (not
    # the arbitrary value a search wandering off among ever larger variances would stop at)...
    df = panel(raters=6, clips=8, missing=0.3, seed=2)
    codes = {c: pd.factorize(df[c], sort=True)[0] for c in ("rater_id", "clip_id")}
    df["rating"] = codes["rater_id"] * 0.5 + codes["clip_id"] * 1.0
    assert agreement.agreement(df)["icc"] is None
    # ...and a bootstrap of a small study, where such resamples are common, leaves them out and says how many
    # resamples it kept
    small = panel(raters=6, clips=8, missing=0.7, seed=4)
    res = agreement.icc(small, n_boot=60)
    assert not res["complete"] and 0 < res["n_fitted"] < 60
    assert res["icc_a1_ci"][0] <= res["icc_a1"] <= res["icc_a1_ci"][1]


def test_too_few_raters_give_none():
    assert agreement.icc(panel(raters=2)) is None
    assert "too few" in agreement.agreement_text({"krippendorff": None, "icc": None})


def test_the_acr_report_has_agreement_and_a_methods_paragraph(tmp_path):
    df = panel(raters=10, clips=12)
    df["condition"] = np.where(df["clip_id"].str[1:].astype(int) < 6, "NAT", "SYS")
    df["item"] = "it" + (df["clip_id"].str[1:].astype(int) % 6).astype(str)
    bad = pd.DataFrame({"rater_id": [f"r{i}" for i in range(10)], "clip_id": "bad0", "rating": [1] * 9 + [5]})
    bad = bad.assign(role="catch", condition="BAD", item="b0")
    path = tmp_path / "ratings.csv"
    pd.concat([df, bad]).astype({"rating": int}).to_csv(path, index=False)
    doc = report.build_report(path, tmp_path / "rep", Options(n_boot=100, seed=7), progress=False, quiet=True)
    ag = doc["agreement"]
    assert ag["krippendorff"]["n_units"] == 12 and ag["icc"]["icc_a1"] > 0
    text = doc["methods"]
    assert text == (tmp_path / "rep" / "methods.txt").read_text().strip()
    assert text.startswith("10 raters took part. 1 was excluded because they rated a deliberately broken clip")
    assert "at 3 or above" in text and "9 raters and 108 test answers" in text
    assert "2 conditions (NAT, SYS) on 6 items" in text and "seed 7" in text and "100 resamples" in text
    assert methods.clip_set_hash(pd.read_csv(path))[:16] in text
    assert f"moglow-eval {methods.tool_version()}" in text
    summary = (tmp_path / "rep" / "report.html").read_text()  # one rater excluded: singular, as a paper would say
    assert "from 10 raters. 1 rater gave a catch (bad-example) clip a rating ≥ 3 and was excluded, removing" in summary


def test_kept_raters_without_a_test_answer_are_counted_in_the_methods(tmp_path):
    """A rater kept who answered only catch trials (their session came when every clip had its answers) is in the
    kept count but in no statistic: the paragraph says so, where the sections count only the raters they use."""
    df = panel(raters=6, clips=8)
    df["condition"] = np.where(df["clip_id"].str[1:].astype(int) < 4, "NAT", "SYS")
    df["item"] = "it" + (df["clip_id"].str[1:].astype(int) % 4).astype(str)
    late = [f"late{i}" for i in range(2)]
    bad = pd.DataFrame({"rater_id": [f"r{i}" for i in range(6)] + late, "clip_id": "bad0", "rating": 1})
    bad = bad.assign(role="catch", condition="BAD", item="b0")
    path = tmp_path / "ratings.csv"
    pd.concat([df, bad]).astype({"rating": int}).to_csv(path, index=False)
    doc = report.build_report(path, tmp_path / "rep", Options(n_boot=50, seed=1), progress=False, quiet=True)
    assert doc["methods"].startswith(
        "8 raters took part. None rated a deliberately broken clip (BAD) at 3 or above in a catch trial, so none was "
        "excluded: 8 raters (2 of them answered no test trial) and 48 test answers."
    )
    assert "48 test ratings from 6 raters" in (tmp_path / "rep" / "report.html").read_text()


def test_the_methods_paragraph_names_a_mixed_model_only_where_one_was_fitted(tmp_path):
    """--no-mixed (or a study past --mixed-max-levels) fits no mixed model, and the paragraph a paper takes then
    names none: it named one whatever the report computed."""
    from analysis.designs import DESIGNS

    assert all(d.methods_mixed in d.methods_stats for d in DESIGNS.values())  # each clause is its design's own
    df = panel(raters=6, clips=8)
    df["condition"] = np.where(df["clip_id"].str[1:].astype(int) < 4, "NAT", "SYS")
    df["item"] = "it" + (df["clip_id"].str[1:].astype(int) % 4).astype(str)
    path = tmp_path / "ratings.csv"
    df.astype({"rating": int}).to_csv(path, index=False)
    fitted = report.build_report(path, tmp_path / "a", Options(n_boot=20), progress=False, quiet=True)
    assert "a one-way ANOVA with Tukey's HSD, a linear mixed model with crossed random" in fitted["methods"]
    plain = report.build_report(path, tmp_path / "b", Options(n_boot=20, mixed=False), progress=False, quiet=True)
    assert "mixed" not in plain["methods"]
    assert "a one-way ANOVA with Tukey's HSD and cluster-bootstrap intervals resampling raters" in plain["methods"]
