"""The style factor (analysis.stats.style): condition × style in a two-way ANOVA and a mixed model, a figure; the
interaction is found where the data hold one and not where they do not."""

import warnings

import numpy as np
import pandas as pd
import pytest
from helpers.style_ratings import synthetic

from analysis.stats import style


def test_an_interaction_is_detected_and_its_absence_is_not():
    present = style.style_analysis(synthetic(-1.5), reference="REAL")
    absent = style.style_analysis(synthetic(0.0, seed=1), reference="REAL")
    assert present["anova"]["type"] == "II"
    assert present["anova"]["terms"]["condition:style"]["p"] < 1e-3
    assert present["mixed_model"]["interaction_test"]["p"] < 0.01
    assert absent["anova"]["terms"]["condition:style"]["p"] > 0.05
    assert absent["mixed_model"]["interaction_test"]["p"] > 0.05
    assert absent["anova"]["terms"]["condition"]["p"] < 1e-6  # the condition effect is there either way
    fe = present["mixed_model"]["fixed_effects"]
    assert -1.8 < fe["condition[T.SYS]:style[T.solid]"] < -0.8  # the floor at 1 shrinks it
    assert present["mixed_model"]["reference"] == "REAL" and present["mixed_model"]["style_reference"] == "stick"
    cells = present["cells"].set_index(["condition", "style"])
    assert cells.at[("SYS", "solid"), "mean"] < cells.at[("SYS", "stick"), "mean"] - 0.7


def test_the_mixed_model_with_the_interaction_matches_statsmodels():
    import statsmodels.formula.api as smf

    t = synthetic(-0.8, seed=3, n_raters=8, clips_per_cell=4)
    ours = style.mixed_model_style(t, reference="REAL")
    data = t.assign(y=t["rating"].astype(float), g=0)
    data["condition"] = pd.Categorical(data["condition"], ["REAL", "SYS"])
    data["style"] = pd.Categorical(data["style"], ["stick", "solid"])
    ref = smf.mixedlm(
        "y ~ condition * style",
        data,
        groups="g",
        re_formula="0",
        vc_formula={"rater": "0 + C(rater_id)", "clip": "0 + C(clip_id)"},
    ).fit(reml=True, method="nm", maxiter=4000)
    assert ours["reml_log_likelihood"] == pytest.approx(ref.llf, abs=1e-5)
    np.testing.assert_allclose(list(ours["fixed_effects"].values()), ref.fe_params.to_numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(list(ours["std_errors"].values()), ref.bse_fe.to_numpy(), rtol=3e-3)
    # the Wald test of the one interaction effect is its z test squared
    name = "condition[T.SYS]:style[T.solid]"
    z = ours["fixed_effects"][name] / ours["std_errors"][name]
    assert ours["interaction_test"]["chi2"] == pytest.approx(z**2, rel=1e-6)


def test_one_style_or_none_gives_no_style_section():
    t = synthetic(0.0)
    assert style.style_analysis(t.assign(style="stick")) is None
    assert style.style_analysis(t.drop(columns="style")) is None


def test_an_empty_cell_leaves_the_interaction_undefined_not_fake():
    t = synthetic(0.0)
    t = t[~((t["condition"] == "SYS") & (t["style"] == "solid"))]
    res = style.style_analysis(t, reference="REAL")
    assert "undefined" in res["anova"] and "undefined" in res["mixed_model"]


def test_ratings_the_cells_and_raters_give_exactly_leave_the_mixed_model_undefined():
    """A tiny study where each rating is its (condition, style) cell plus its rater's bias, nothing left over (the
    two-style browser study's crowd, once the browser's rater fails a catch trial): the mixed model is undefined,
    said in one line, not fitted to round-off with a LinAlgWarning; the ANOVA still reports the interaction."""
    t = synthetic(0.0, n_raters=8, clips_per_cell=3)
    rater = t["rater_id"].str[1:].astype(int)
    t["rating"] = 2 + (t["condition"] == "REAL") + 2 * (t["style"] == "solid") + rater % 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = style.style_analysis(t, reference="REAL")
    assert "fit every rating exactly" in res["mixed_model"]["undefined"]
    assert "condition:style" in res["anova"]["terms"]


def test_the_figure_draws_one_line_per_style(tmp_path):
    res = style.style_analysis(synthetic(-1.0), reference="REAL")
    path = style.style_figure(res, tmp_path / "style.png")
    from PIL import Image

    assert Image.open(path).size[0] > 200
    assert style.style_json(res)["cell_means"][0]["condition"] == "REAL"
