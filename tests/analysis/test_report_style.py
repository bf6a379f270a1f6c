"""The report of a study drawn in two styles (export `style`, CONTRACTS §6-7): stats.json's "style" section,
report.html's section and the figure; a file without styles has none of them."""

import json

from helpers.style_ratings import synthetic

from analysis.designs import Options
from analysis.report import build_report


def write_ratings(path, df):
    df = df.assign(role="test", item=df["clip_id"].str.rsplit("-", n=1).str[1])
    df.to_csv(path, index=False)
    return path


def test_the_report_of_a_styled_study_has_the_style_factor(tmp_path):
    path = write_ratings(tmp_path / "ratings.csv", synthetic(-1.5, n_raters=10, clips_per_cell=4))
    doc = build_report(path, tmp_path / "rep", Options(n_boot=20, ordinal=False), progress=False, quiet=True)
    st = doc["style"]
    assert st["styles"] == ["stick", "solid"]
    assert st["anova"]["type"] == "II" and st["anova"]["terms"]["condition:style"]["p"] < 0.01
    assert st["mixed_model"]["interaction_test"]["df"] == 1
    assert "style" in doc["without_exclusion"]
    assert doc["figures"]["style_means"] == "figures/style_means.png"
    assert (tmp_path / "rep" / "figures" / "style_means.png").stat().st_size > 1000
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "Condition × style" in page and "type II" in page
    assert json.loads((tmp_path / "rep" / "stats.json").read_text())["style"]["styles"] == ["stick", "solid"]


def test_a_report_without_styles_has_no_style_section(tmp_path):
    path = write_ratings(tmp_path / "ratings.csv", synthetic(0.0, n_raters=6, clips_per_cell=3).drop(columns="style"))
    doc = build_report(path, tmp_path / "rep", Options(n_boot=20, ordinal=False), progress=False, quiet=True)
    assert "style" not in doc and "style_means" not in doc["figures"]
    assert "Condition × style" not in (tmp_path / "rep" / "report.html").read_text()
