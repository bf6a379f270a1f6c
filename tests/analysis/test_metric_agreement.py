"""How far each objective measure agrees with people (analysis.stats.metric_agreement) on made-up systems with a
known answer: a measure that orders the systems as people did has Kendall tau +1, one that reverses them -1, each
read the way it is better; and the report, given metrics.csv, shows each system's value and the agreement beside the
design's own score, read through the design's standings."""

import csv
import json

import numpy as np
import pandas as pd
import pytest

from analysis.report import build_report
from analysis.stats.metric_agreement import item_table, kendall_tau_b, orient, rank_agreement, system_values
from moglow_eval.core import study

SYSTEMS = {"NAT": 1.5, "GOOD": 1.0, "FAIR": 0.5, "POOR": 0.0}  # the human score, best first
ITEMS = [f"i{k}" for k in range(8)]


def clips_table(values):
    """Clips of each system on every item with the measures {measure: {system: per-item value}} (+ item noise)."""
    rng = np.random.default_rng(0)
    rows = []
    for s in SYSTEMS:
        for item in ITEMS:
            row = dict(clip_id=f"{s}{item}", condition=s, role="test", item=item, matched=True)
            row.update({m: v[s] + rng.normal(0, 0.01) for m, v in values.items()})
            rows.append(row)
            rows.append({**row, "clip_id": f"{s}{item}x", "matched": False, **dict.fromkeys(values, 99.0)})
    return pd.DataFrame(rows).set_index("clip_id")


def scores():
    return pd.DataFrame(
        [dict(system=s, score=v, low=v - 0.1, high=v + 0.1) for s, v in SYSTEMS.items()]
    )  # intervals apart: the order is sure


def test_kendall_tau_b_is_scipys():
    from scipy.stats import kendalltau

    rng = np.random.default_rng(3)
    x, y = rng.integers(0, 3, (50, 5)).astype(float), rng.integers(0, 4, (50, 5)).astype(float)
    mine = kendall_tau_b(x, y)
    theirs = np.array([kendalltau(a, b).statistic for a, b in zip(x, y)])
    assert np.allclose(mine, theirs, equal_nan=True)


def test_orientation_makes_higher_better():
    v = np.array([1.0, 3.0, 2.0])
    assert list(orient(v, "lower", None)) == [-1, -3, -2]
    assert list(orient(v, "higher", None)) == [1, 3, 2]
    assert list(orient(v, "reference", 0)) == [0, -2, -1]  # the reference's value is best


@pytest.mark.parametrize(
    "measure, per_system, tau",
    [
        ("fgd", {"NAT": 1.0, "GOOD": 5.0, "FAIR": 9.0, "POOR": 20.0}, 1.0),  # lower is better, as people found
        ("fgd", {"NAT": 20.0, "GOOD": 9.0, "FAIR": 5.0, "POOR": 1.0}, -1.0),  # the reverse
        ("beat_align", {"NAT": 0.9, "GOOD": 0.8, "FAIR": 0.7, "POOR": 0.6}, 1.0),  # higher is better
        ("jerk", {"NAT": 30.0, "GOOD": 25.0, "FAIR": 60.0, "POOR": 200.0}, 1.0),  # nearer the reference is better
    ],
)
def test_a_measure_that_orders_systems_as_people_did_agrees(measure, per_system, tau):
    tables = item_table(clips_table({measure: per_system}), [measure])
    agreement = rank_agreement(tables, scores(), "NAT", n_boot=300, seed=1).iloc[0]
    assert agreement["tau"] == pytest.approx(tau)
    assert agreement["n_systems"] == 4 and agreement["low"] <= agreement["tau"] <= agreement["high"]
    values = system_values(tables, n_boot=300).set_index("system")
    for s, v in per_system.items():  # the mismatched clips (99) are left out of a system's value
        assert values.at[s, "value"] == pytest.approx(v, abs=0.02)
        assert values.at[s, "low"] <= values.at[s, "value"] <= values.at[s, "high"]
        assert values.at[s, "n_items"] == len(ITEMS)


def test_uncertain_people_or_a_noisy_measure_widen_the_interval():
    per_system = {"NAT": 1.0, "GOOD": 2.0, "FAIR": 3.0, "POOR": 4.0}
    tables = item_table(clips_table({"fgd": per_system}), ["fgd"])
    sure = rank_agreement(tables, scores(), "NAT", n_boot=400).iloc[0]
    unsure = scores().assign(low=lambda d: d["score"] - 2, high=lambda d: d["score"] + 2)
    wide = rank_agreement(tables, unsure, "NAT", n_boot=400).iloc[0]
    assert sure["low"] == pytest.approx(1.0) and wide["low"] < 0.5


def test_fewer_than_three_systems_have_no_agreement():
    tables = item_table(clips_table({"fgd": {"NAT": 1, "GOOD": 2, "FAIR": 3, "POOR": 4}}), ["fgd"])
    two = scores()[scores()["system"].isin(["NAT", "GOOD"])]
    row = rank_agreement(tables, two, "NAT", n_boot=50).iloc[0]
    assert np.isnan(row["tau"]) and row["n_systems"] == 2


# ---------------------------------------------------------------- through the report
COLUMNS = ["rater_id", "item", "clip_a", "clip_b", "condition_a", "condition_b", "preference", "role", "matched"]
MAS = {"NAT": 1.6, "GOOD": 1.0, "FAIR": 0.4}


def write_study(folder):
    """A matched-against-mismatched export whose systems' mean scores are MAS, and the stimuli's metrics.csv,
    manifest.csv and measures.csv beside it: fgd orders the systems as people do, beat_align reverses them."""
    rng = np.random.default_rng(0)
    folder.mkdir()
    rows = []
    for r in range(24):
        for k, item in enumerate(ITEMS[:6]):
            for s, mas in MAS.items():
                score = int(np.clip(np.round(mas + rng.normal(0, 0.7)), -2, 2))
                side = "a" if (r + k) % 2 else "b"
                rows.append([f"r{r}", item, f"{s}{item}", f"{s}{item}x", s, s, score if side == "a" else -score,
                             "test", side])  # fmt: skip
    with open(folder / "pairs.csv", "w", newline="") as f:
        csv.writer(f).writerows([COLUMNS, *rows])
    fgd = {"NAT": 900.0, "GOOD": 2000.0, "FAIR": 5000.0}
    beat = {"NAT": 0.3, "GOOD": 0.5, "FAIR": 0.7}
    stim = folder / "stimuli"
    stim.mkdir()
    metrics, manifest = [], []
    for s in MAS:
        for item in ITEMS[:6]:
            for cid, mi in ((f"{s}{item}", ""), (f"{s}{item}x", "i7")):
                metrics.append([cid, s, "test", item, 30.0, fgd[s] * (1 + 0.05 * rng.normal()), beat[s], 0.5])
                manifest.append([cid, s, "test", item, f"videos/{cid}.mp4", mi])
    header = ["clip_id", "condition", "role", "item", "jerk", "fgd", "beat_align", "listener_response"]
    with open(stim / "metrics.csv", "w", newline="") as f:
        csv.writer(f).writerows([header, *metrics])
    with open(stim / "manifest.csv", "w", newline="") as f:
        csv.writer(f).writerows([["clip_id", "condition", "role", "item", "video", "motion_item"], *manifest])
    notes = [[m, "measured", 36, "", "sigma 0.3 s" if m == "beat_align" else ""] for m in header[4:]]
    notes.append(["foot_skating", "skipped", 0, "a gesture study: it has speech", ""])
    with open(stim / study.MEASURES_FILE, "w", newline="") as f:
        csv.writer(f).writerows([list(study.MEASURES_COLUMNS), *notes])
    return folder / "pairs.csv", stim / "metrics.csv"


def test_the_report_puts_each_measures_agreement_beside_the_designs_score(tmp_path):
    from analysis.designs import Options

    pairs, metrics = write_study(tmp_path / "study")
    doc = build_report(pairs, tmp_path / "report", Options(metrics_path=str(metrics), n_boot=200), progress=False,
                       quiet=True)  # fmt: skip
    measures = doc["measures"]
    assert measures["score"] == "MAS"
    tau = {r["measure"]: r["tau"] for r in measures["agreement"]}
    assert tau["fgd"] == pytest.approx(1.0) and tau["beat_align"] == pytest.approx(-1.0)
    assert tau["jerk"] is None and tau["listener_response"] is None  # every system alike: no order to agree with
    values = {(r["measure"], r["system"]): r for r in measures["values"]}
    assert values[("fgd", "FAIR")]["value"] == pytest.approx(5000, rel=0.1)
    assert values[("beat_align", "NAT")]["value"] == pytest.approx(0.3)  # its matched clips only
    page = (tmp_path / "report" / "report.html").read_text()
    assert "Objective measures and how far each agrees with people" in page
    assert "foot_skating: a gesture study: it has speech" in page
    methods = json.loads((tmp_path / "report" / "stats.json").read_text())["methods"]
    assert "beat_align (sigma 0.3 s)" in methods and "Kendall's tau-b" in methods
