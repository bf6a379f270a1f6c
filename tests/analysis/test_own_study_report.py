"""The report of a study of the user's own motion (issue 43 item 6): the reference keeps its own name, no
caption cites the MoGlow paper, the summary names only the study's conditions, and the C2ST column says when
there are too few items or an AUC far below 0.5."""

import json

import numpy as np
import pandas as pd
import pytest

from analysis import report
from analysis.data.load import AnalysisError
from analysis.designs import Options
from analysis.page import study_text

PAPER = "of the paper"


def ratings(tmp_path, conditions, seed=0, n_raters=8, clips=4):
    """A ratings.csv: the conditions' test clips (the first condition best) and BAD catch clips."""
    rng = np.random.default_rng(seed)
    rows = []
    for r in range(n_raters):
        for k, cond in enumerate(conditions):
            for i in range(clips):
                q = 4.2 - 0.8 * k + rng.normal(0, 0.6)
                rows.append((f"r{r}", f"{cond.lower()}{i}", cond, int(np.clip(round(q), 1, 5)), "test", f"it{i}"))
        rows.append((f"r{r}", "badclip0", "BAD", 1, "catch", "bad0"))
    path = tmp_path / "ratings.csv"
    pd.DataFrame(rows, columns=["rater_id", "clip_id", "condition", "rating", "role", "item"]).to_csv(path, index=False)
    return path


def with_c2st(tmp_path, rows):
    folder = tmp_path / "stimuli"
    folder.mkdir()
    (folder / "metrics.csv").write_text("clip_id,condition,role,item,jerk\nnat0,NAT,test,it0,30\n")
    pd.DataFrame(rows, columns=["condition", "n_items", "auc", "auc_sd", "accuracy"]).to_csv(
        folder / "c2st.csv", index=False
    )
    return folder / "metrics.csv"


def test_an_own_study_report_names_its_reference_and_cites_no_paper(tmp_path):
    path = ratings(tmp_path, ["NAT", "SYS_A"])
    metrics = with_c2st(
        tmp_path, [("NAT:split", 7, 0.52, 0.1, 0.5), ("SYS_A", 7, 0.24, 0.1, 0.3), ("BAD", 30, 0.0, 0.0, 0.0)]
    )
    doc = report.build_report(
        path,
        tmp_path / "rep",
        Options(metrics_path=metrics, n_boot=20, ordinal=False, reference_name="real"),
        progress=False,
        quiet=True,
    )
    assert set(doc["condition_means"]) == {"real", "SYS_A"}
    assert doc["mixed_model"]["reference"] == "real"
    assert "condition[T.SYS_A]" in doc["mixed_model"]["fixed_effects"]
    page = (tmp_path / "rep" / "report.html").read_text()
    assert PAPER not in page and "Fig. 5" not in page
    summary = page.split("<h2>Summary</h2>")[1].split("</p>")[0]
    assert "real" in summary and "SYS_A" in summary
    assert not any(f" {c} " in summary for c in ("NAT", "MG", "FL"))
    c2st = {r["condition"]: r for r in doc["c2st"]}
    assert set(c2st) == {"real:split", "SYS_A", "BAD"}
    assert "only 7 items" in page and "learned the item, not the system" in page


def test_the_builtin_study_keeps_the_papers_captions(tmp_path):
    doc = report.build_report(
        ratings(tmp_path, ["NAT", "MG", "FL"]),
        tmp_path / "rep",
        Options(n_boot=20, ordinal=False),
        progress=False,
        quiet=True,
    )
    assert doc["mixed_model"]["reference"] == "NAT"
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "Fig. 5 of the paper" in page and "Fig. 6 of the paper" in page


def test_the_study_file_gives_the_reference_name(tmp_path, capsys):
    study_file = tmp_path / "study.toml"
    study_file.write_text('reference = "mocap"\nseed = 1\n[conditions]\nmocap = "real"\nSYS = "sys"\n')
    path = ratings(tmp_path, ["NAT", "SYS"])
    assert report.main([str(path), "--out", str(tmp_path / "rep"), "--study", str(study_file), "--n-boot", "20",
                        "--no-ordinal", "--quiet"]) == 0  # fmt: skip
    doc = json.loads((tmp_path / "rep" / "stats.json").read_text())
    assert set(doc["condition_means"]) == {"mocap", "SYS"}
    assert report.main([str(path), "--out", str(tmp_path / "rep2"), "--study", str(tmp_path / "none.toml")]) == 2
    assert "none.toml" in capsys.readouterr().err


def test_a_reference_name_that_is_already_a_condition_is_an_error(tmp_path):
    with pytest.raises(AnalysisError, match="already has a condition"):
        opts = Options(n_boot=20, reference_name="SYS")
        report.build_report(ratings(tmp_path, ["NAT", "SYS"]), tmp_path / "rep", opts, progress=False, quiet=True)


@pytest.mark.parametrize(
    "conditions,builtin",
    [(["NAT", "MG", "FL"], True), (["NAT", "MG", "FL", "BAD"], True), (["NAT", "MG"], False), (["NAT", "X"], False),
     (["NAT", "MG", "FL", "X"], False)],
)  # fmt: skip
def test_only_the_builtin_study_is_the_papers(conditions, builtin):
    assert study_text.is_builtin_study(conditions) is builtin
    assert (PAPER in study_text.captions(conditions)["ratings_histogram"]) is builtin


def test_c2st_notes():
    note = study_text.c2st_note
    assert note({"n_items": 40, "auc": 0.7}) == ""
    assert "only 7 items" in note({"n_items": 7, "auc": 0.6})
    assert "learned the item" in note({"n_items": 40, "auc": 0.0})
    assert note({"n_items": 10, "auc": 0.3}) == ""  # the bounds themselves are fine
