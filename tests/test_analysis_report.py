"""The report end to end: the paper's exclusion rule on a hand-made file, and a frozen ratings.csv -> stats.json."""
import json
import math
from pathlib import Path

import pytest

from analysis.filtering import exclude_raters
from analysis.load import load_ratings
from analysis.report import build_report, main

DATA = Path(__file__).parent / "data" / "analysis"
CONTRACT_KEYS = ["n_ratings_total", "n_ratings_removed", "n_ratings_kept", "n_raters_total", "n_raters_excluded",
                 "condition_means", "condition_counts", "anova", "tukey", "mixed_model"]


# ---------------------------------------------------------------------------------------------- exclusion rule
def test_exclusion_rule_on_hand_made_file():
    df = load_ratings(DATA / "exclusion.csv")
    kept, counts = exclude_raters(df, threshold=3)
    # bob's catch 3 and erin's catch 5 reach the threshold; alice (1, 2), carol (2, 1) and dave (no catch) stay
    assert counts["excluded_raters"] == ["bob", "erin"]
    assert (counts["n_ratings_total"], counts["n_ratings_removed"], counts["n_ratings_kept"]) == (21, 8, 13)
    assert (counts["n_raters_total"], counts["n_raters_excluded"], counts["n_raters_kept"]) == (5, 2, 3)
    assert counts["n_raters_without_catch"] == 1 and counts["n_test_ratings_kept"] == 9
    assert sorted(kept["rater_id"].unique()) == ["alice", "carol", "dave"]
    assert exclude_raters(df, threshold=2)[1]["excluded_raters"] == ["alice", "bob", "carol", "erin"]
    assert exclude_raters(df, threshold=4)[1]["excluded_raters"] == ["erin"]
    assert exclude_raters(df, threshold=6)[1]["n_ratings_removed"] == 0


def test_exclusion_report_uses_kept_test_rows_only(tmp_path):
    doc = build_report(DATA / "exclusion.csv", tmp_path, n_boot=50, progress=False, quiet=True)
    assert (doc["n_ratings_total"], doc["n_ratings_removed"], doc["n_ratings_kept"]) == (21, 8, 13)
    assert (doc["n_raters_total"], doc["n_raters_excluded"]) == (5, 2)
    # kept test ratings: NAT 5,4,3  MG 4,3,5  FL 2,3,1 (catch rows never enter the statistics)
    assert doc["condition_means"] == {"NAT": 4.0, "MG": 4.0, "FL": 2.0}
    assert doc["condition_counts"] == {"NAT": 3, "MG": 3, "FL": 3}
    assert doc["anova"]["df_between"] == 2 and doc["anova"]["df_within"] == 6
    assert doc["anova"]["F"] == pytest.approx((8 / 2) / (6 / 6))  # SSB = 3 (4/9 + 4/9 + 16/9) = 8, SSW = 2+2+2
    # every rater's test ratings: each condition averages 3
    assert doc["without_exclusion"]["condition_means"] == {"NAT": 3.0, "MG": 3.0, "FL": 3.0}
    assert doc["without_exclusion"]["condition_counts"] == {"NAT": 5, "MG": 5, "FL": 5}
    assert "BAD" not in doc["rating_histogram"]


def test_threshold_option_changes_the_exclusion(tmp_path):
    assert main([str(DATA / "exclusion.csv"), "--out", str(tmp_path), "--threshold", "4", "--n-boot", "50",
                 "--no-mixed", "--quiet"]) == 0
    doc = json.loads((tmp_path / "stats.json").read_text())
    assert doc["excluded_raters"] == ["erin"] and doc["n_ratings_removed"] == 4
    assert doc["mixed_model"]["skipped"] == "--no-mixed"


# ---------------------------------------------------------------------------------------------- frozen fixture
@pytest.fixture(scope="module")
def frozen_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    doc = build_report(DATA / "ratings_small.csv", out, metrics_path=DATA / "metrics_small.csv", progress=False,
                       quiet=True)
    return out, doc


VOLATILE = {"generated_at", "input"}


def _compare(got, want, path=""):
    """Every number within a tight tolerance; every string, bool, key and list length identical."""
    # the REML and Laplace-ML optima are found to ~1e-9 in their parameters; allow for BLAS rounding there only
    models = ("mixed_model", "ordinal_model")
    rel = 1e-6 if path.startswith(models + tuple(f"without_exclusion.{m}" for m in models)) else 1e-9
    if isinstance(want, dict):
        assert set(got) == set(want), f"{path}: keys differ: {set(got) ^ set(want)}"
        for k in want:
            if k not in VOLATILE:
                _compare(got[k], want[k], f"{path}.{k}" if path else k)
    elif isinstance(want, list):
        assert len(got) == len(want), f"{path}: length {len(got)} != {len(want)}"
        for i, (g, w) in enumerate(zip(got, want)):
            _compare(g, w, f"{path}[{i}]")
    elif isinstance(want, bool) or want is None or isinstance(want, str):
        assert got == want, f"{path}: {got!r} != {want!r}"
    else:
        assert isinstance(got, (int, float)) and not isinstance(got, bool), f"{path}: {got!r}"
        assert math.isclose(got, want, rel_tol=rel, abs_tol=1e-12), f"{path}: {got!r} != {want!r}"


def test_frozen_stats_json(frozen_run):
    out, doc = frozen_run
    written = json.loads((out / "stats.json").read_text())
    assert written == doc
    want = json.loads((DATA / "expected_stats.json").read_text())
    _compare(written, want)


def test_frozen_fixture_headline_numbers(frozen_run):
    """The key numbers spelled out, so a reader sees what the frozen file pins down."""
    doc = frozen_run[1]
    for key in CONTRACT_KEYS:
        assert key in doc
    assert (doc["n_ratings_total"], doc["n_ratings_removed"], doc["n_ratings_kept"]) == (1880, 376, 1504)
    assert doc["n_raters_excluded"] == 4 and doc["condition_counts"] == {"NAT": 480, "MG": 480, "FL": 480}
    assert doc["condition_means"]["NAT"] == pytest.approx(1925 / 480)
    assert [(t["group1"], t["group2"]) for t in doc["tukey"]] == [("FL", "MG"), ("FL", "NAT"), ("MG", "NAT")]
    t = doc["tukey"][0]
    assert t["meandiff"] == pytest.approx(doc["condition_means"]["MG"] - doc["condition_means"]["FL"])
    assert set(doc["mixed_model"]["fixed_effects"]) == {"Intercept", "condition[T.MG]", "condition[T.FL]"}
    assert doc["mixed_model"]["fixed_effects"]["Intercept"] == pytest.approx(doc["condition_means"]["NAT"])
    assert len(doc["metric_correlations"]) == 4 * 4
    assert doc["without_exclusion"]["n_test_ratings"] == 1800


def test_report_folder_contents(frozen_run):
    out, _ = frozen_run
    for name in ["ratings_histogram", "per_clip_means", "condition_means", "metric_scatter", "ordinal_fit",
                 "ordinal_fit_all"]:
        png = out / "figures" / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") == 6  # embedded: opens offline (2 ordinal-fit figures)
    assert "http://" not in page and "https://" not in page and "<script" not in page
    assert "Tukey HSD" in page and "Without the exclusion" in page and "F(2, 1437)" in page


def test_console_summary(tmp_path, capsys):
    assert main([str(DATA / "ratings_small.csv"), "--out", str(tmp_path), "--no-mixed", "--n-boot", "100"]) == 0
    out = capsys.readouterr().out
    assert "Ratings: 1880 total, 376 removed, 1504 kept" in out
    assert "One-way ANOVA: F(2, 1437)" in out and "NAT-FL" in out and "Mixed model: --no-mixed" in out


def test_frozen_comparison_catches_a_tiny_change():
    """The comparison itself must fail on any change in the numbers (here 1e-7 relative in one bound)."""
    want = json.loads((DATA / "expected_stats.json").read_text())
    got = json.loads(json.dumps(want))
    got["without_exclusion"]["bootstrap"]["differences"][1]["boot_low"] *= 1 + 1e-7
    with pytest.raises(AssertionError, match="without_exclusion.bootstrap.differences"):
        _compare(got, want)
    got = json.loads(json.dumps(want))
    got["tukey"][2]["reject"] = not got["tukey"][2]["reject"]
    with pytest.raises(AssertionError, match=r"tukey\[2\].reject"):
        _compare(got, want)


def test_mixed_model_skipped_beyond_max_levels(tmp_path):
    doc = build_report(DATA / "exclusion.csv", tmp_path, n_boot=20, mixed_max_levels=2, progress=False, quiet=True)
    assert doc["mixed_model"]["fixed_effects"] == {}
    assert doc["mixed_model"]["skipped"] == "3 raters and 3 clips: both above --mixed-max-levels 2"
    assert "Not fitted: 3 raters and 3 clips" in (tmp_path / "report.html").read_text()
