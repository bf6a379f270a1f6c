"""The reference of a study of your own motion keeps its own name without a flag: study.json beside the manifest
(CONTRACTS §4) -> the app's export column reference_name (§6) -> the report's tables (§7)."""

import csv
import json

import pytest
from helpers.api_client import rate_everything
from helpers.fake_stimuli import write_fake_stimuli

from analysis import report
from analysis.data.load import AnalysisError
from moglow_eval.core import colours
from rating_app.store.manifest import AppError, interlocutor_colour, reference_name


@pytest.fixture
def stimuli(tmp_path):
    return write_fake_stimuli(tmp_path / "stimuli", n_items=3, n_training=1)


def name_it(manifest, doc):
    (manifest.parent / "study.json").write_text(doc if isinstance(doc, str) else json.dumps(doc))


def test_the_export_carries_the_reference_name_and_the_report_uses_it(make_app, stimuli, tmp_path):
    name_it(stimuli, {"reference_name": "mocap"})
    client = make_app(manifest=stimuli, ratings_per_clip=3, min_view=0).test_client()
    for _ in range(3):
        rows = rate_everything(client)
    assert rows and {r["reference_name"] for r in rows} == {"mocap"}
    rows = [{**r, "rating": "1" if r["role"] == "catch" else r["rating"]} for r in rows]  # pass the catch trials
    assert "NAT" in {r["condition"] for r in rows}  # the rows keep NAT: every rule keys on it
    path = tmp_path / "ratings.csv"
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    assert report.study_reference(path) == "mocap"
    assert report.main([str(path), "--out", str(tmp_path / "rep"), "--n-boot", "20", "--no-mixed", "--quiet"]) == 0
    stats = json.loads((tmp_path / "rep" / "stats.json").read_text())
    assert "mocap" in stats["condition_means"] and "NAT" not in stats["condition_means"]
    # a flag still wins over the export
    assert report.main([str(path), "--out", str(tmp_path / "rep2"), "--n-boot", "20", "--no-mixed", "--quiet",
                        "--reference-name", "capture"]) == 0  # fmt: skip
    assert "capture" in json.loads((tmp_path / "rep2" / "stats.json").read_text())["condition_means"]


def test_without_study_json_there_is_no_column(make_app, stimuli):
    rows = rate_everything(make_app(manifest=stimuli, ratings_per_clip=1, min_view=0).test_client())
    assert rows and "reference_name" not in rows[0]
    assert reference_name(stimuli) is None


@pytest.mark.parametrize(
    "doc, needle",
    [
        ("{not json", "not a study names file"),
        ({"other": 1}, "not a study names file"),
        ({"reference_name": "<b>x</b>"}, "must be a condition name"),
        ({"reference_name": 7}, "must be a condition name"),
        ("x" * 5000, r"larger than a study names file can be \(4 KB\)"),
    ],
)
def test_a_malformed_study_json_is_one_line(stimuli, doc, needle):
    name_it(stimuli, doc)
    with pytest.raises(AppError, match=needle) as e:
        reference_name(stimuli)
    assert "study.json" in str(e.value) and "\n" not in str(e.value)


def test_a_hostile_reference_name_in_an_export_is_refused(tmp_path):
    path = tmp_path / "ratings.csv"
    path.write_text("rater_id,clip_id,condition,rating,role,item,reference_name\nr1,c1,NAT,3,test,i1,=cmd()\n")
    with pytest.raises(AnalysisError, match="reference_name"):
        report.study_reference(path)


def test_the_interlocutors_colour_reaches_the_raters_page_from_study_json(make_app, tmp_path):
    stimuli = write_fake_stimuli(tmp_path / "dyadic", n_items=3, n_training=1, mismatched=True, catch_nat=True)
    # The page names the colour the renderer drew (the study's), not a fixed word: here a study that drew its
    # interlocutor orange; without the key the page names no colour.
    name_it(stimuli, {"reference_name": "NAT", "interlocutor_colour": "#E08A1E"})
    assert interlocutor_colour(stimuli) == "#e08a1e"
    page = make_app(manifest=stimuli, design="dyadic", min_view=0).test_client().get("/").get_data(as_text=True)
    assert 'fill="#e08a1e"' in page and ">orange</strong>" in page and "grey" not in page
    name_it(stimuli, {"reference_name": "NAT"})
    page = make_app(manifest=stimuli, design="dyadic", min_view=0).test_client().get("/").get_data(as_text=True)
    assert "swatch" not in page and "the person who stays the\n    same" in page


@pytest.mark.parametrize("value", ["green", "#12345", 7, "#GGGGGG"])
def test_a_bad_interlocutor_colour_is_one_line(stimuli, value):
    name_it(stimuli, {"reference_name": "NAT", "interlocutor_colour": value})
    with pytest.raises(AppError, match='interlocutor_colour must be "#RRGGBB"') as e:
        interlocutor_colour(stimuli)
    assert "study.json" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize(
    "rgb, name",
    [((0.40, 0.60, 0.44), "green"), ((0.42, 0.55, 0.78), "blue"), ((0.75, 0.25, 0.15), "red"),
     ((0.5, 0.5, 0.52), "grey"), ((0.88, 0.54, 0.12), "orange"), ((0.02, 0.02, 0.02), "black")],
)  # fmt: skip
def test_colour_names(rgb, name):
    assert colours.colour_name(rgb) == name
    assert colours.from_hex(colours.to_hex(rgb)) == pytest.approx(rgb, abs=1 / 255)
