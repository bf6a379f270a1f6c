"""The report end to end: the paper's exclusion rule on a hand-made file, and a frozen ratings.csv -> stats.json."""

import json
import math
import re

import pytest
from helpers.cli import fails_with
from helpers.paths import TEST_DATA

from analysis.data.filtering import exclude_raters
from analysis.data.load import load_ratings
from analysis.designs import Options
from analysis.report import build_report, main

DATA = TEST_DATA / "analysis"
CONTRACT_KEYS = [
    "n_ratings_total",
    "n_ratings_removed",
    "n_ratings_kept",
    "n_raters_total",
    "n_raters_excluded",
    "condition_means",
    "condition_counts",
    "anova",
    "tukey",
    "mixed_model",
]


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
    doc = build_report(DATA / "exclusion.csv", tmp_path, Options(n_boot=50), progress=False, quiet=True)
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
    assert (
        main(
            [
                str(DATA / "exclusion.csv"),
                "--out",
                str(tmp_path),
                "--threshold",
                "4",
                "--n-boot",
                "50",
                "--no-mixed",
                "--quiet",
            ]
        )
        == 0
    )
    doc = json.loads((tmp_path / "stats.json").read_text())
    assert doc["excluded_raters"] == ["erin"] and doc["n_ratings_removed"] == 4
    assert doc["mixed_model"]["skipped"] == "--no-mixed"


# ---------------------------------------------------------------------------------------------- frozen fixture
@pytest.fixture(scope="module")
def frozen_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    doc = build_report(
        DATA / "ratings_small.csv", out, Options(metrics_path=DATA / "metrics_small.csv"), progress=False, quiet=True
    )
    return out, doc


VOLATILE = {
    "generated_at",
    "input",
    "max_abs_gradient",
    "n_evaluations",
    "methods",
}  # optimiser diagnostics; prose (the tool version)


def _compare(got, want, path=""):
    """Every number within a tight tolerance; every string, bool, key and list length identical."""
    # the REML optimum is found to ~1e-9 in the variance ratios, the Laplace-ML one to ~1e-8 (its standard errors
    # from central differences of the gradient, its far-tail p-values amplify that): allow for rounding there only.
    # The ICC comes from the same REML fit, so its variance components move with the CPU's BLAS as the mixed
    # model's do (1.6e-7 apart between an Intel and an AMD host).
    rel = 1e-9
    for model, tol in (("mixed_model", 1e-6), ("agreement.icc", 1e-6), ("ordinal_model", 1e-5)):
        if path.startswith((model, f"without_exclusion.{model}")):
            rel = tol
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
    for name in [
        "ratings_histogram",
        "per_clip_means",
        "condition_means",
        "metric_scatter",
        "ordinal_fit",
        "ordinal_fit_all",
    ]:
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
    doc = build_report(
        DATA / "exclusion.csv", tmp_path, Options(n_boot=20, mixed_max_levels=2), progress=False, quiet=True
    )
    assert doc["mixed_model"]["fixed_effects"] == {}
    assert doc["mixed_model"]["skipped"] == "3 raters and 3 clips: both above --mixed-max-levels 2"
    assert "Not fitted: 3 raters and 3 clips" in (tmp_path / "report.html").read_text()


# ---------------------------------------------------------------------------------------------- issue 11, 14
H = "rater_id,clip_id,condition,rating,role\n"


def _csv(tmp_path, name, rows):
    path = tmp_path / f"{name}.csv"
    path.write_text(H + "".join(f"{r},{c},{cond},{y},test\n" for r, c, cond, y in rows))
    return path


def test_identical_ratings_are_no_variance_not_significant(tmp_path):
    """Every rating 3: the old report printed F = inf, p < 1e-16 and Tukey reject with meandiff 0."""
    path = _csv(tmp_path, "same", [(f"r{r}", f"c{c}", ["NAT", "MG"][c % 2], 3) for r in range(15) for c in range(2)])
    doc = build_report(path, tmp_path / "rep", Options(n_boot=50), progress=False, quiet=True)
    assert doc["anova"]["F"] is None and doc["anova"]["p"] is None
    assert "no variance" in doc["anova"]["undefined"]
    assert [t["reject"] for t in doc["tukey"]] == [False] and doc["tukey"][0]["p_adj"] is None
    for test in ("anova", "tukey", "kruskal", "mannwhitney", "mixed_model", "ordinal_model"):
        assert "no variance" in doc["undefined"][test] or "same" in doc["undefined"][test], test
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "F(1, 28)" not in page and "no variance" in page and "differing at the 0.05 family-wise level" not in page


def test_no_variance_within_conditions_is_undefined(tmp_path):
    """Each condition constant (5 vs 2): F = x / 0 is not evidence; the models are not fitted either."""
    path = _csv(
        tmp_path, "flat", [(f"r{r}", f"c{c}", ["NAT", "MG"][c % 2], [5, 2][c % 2]) for r in range(4) for c in range(4)]
    )
    doc = build_report(path, tmp_path / "rep", Options(n_boot=50), progress=False, quiet=True)
    assert doc["anova"]["p"] is None and not any(t["reject"] for t in doc["tukey"])
    assert {"anova", "tukey", "mixed_model", "ordinal_model"} <= set(doc["undefined"])
    assert doc["mixed_model"]["fixed_effects"] == {} and doc["ordinal_model"]["fixed_effects"] == {}


@pytest.mark.parametrize(
    "name,rows,expect",
    [
        (
            "single_rater",
            [("r1", f"c{c}", ["NAT", "MG", "FL"][c % 3], 1 + c % 5) for c in range(12)],
            {"mixed_model": "single rater", "ordinal_model": "single rater", "bootstrap": "one rater"},
        ),
        (
            "one_clip_per_condition",
            [(f"r{r}", f"c{c}", ["NAT", "MG", "FL"][c], 1 + (r + c) % 5) for r in range(6) for c in range(3)],
            {
                "mixed_model": "one clip per condition",
                "ordinal_model": "one clip per condition",
                "bootstrap": "one clip per condition",
            },
        ),
        (
            "separation",
            [
                (f"r{r}", f"c{c}", ["NAT", "MG", "FL"][c % 3], 5 if c % 3 == 0 else 1 + (r * c) % 4)
                for r in range(8)
                for c in range(9)
            ],
            {"ordinal_model": "separation"},
        ),
    ],
)
def test_degenerate_designs_give_statements(tmp_path, name, rows, expect):
    path = _csv(tmp_path, name, rows)
    assert main([str(path), "--out", str(tmp_path / "rep"), "--n-boot", "50", "--quiet"]) == 0
    doc = json.loads((tmp_path / "rep" / "stats.json").read_text())
    for test, words in expect.items():
        assert words in doc["undefined"][test], (test, doc["undefined"])
    for model in ("mixed_model", "ordinal_model"):
        if model in expect:
            assert doc[model]["fixed_effects"] == {} and expect[model] in doc[model]["undefined"]
    page = (tmp_path / "rep" / "report.html").read_text()
    assert all(html_escape(w) in page for w in expect.values())


def html_escape(text):
    import html

    return html.escape(text)


def test_condition_names_are_escaped_in_the_html(tmp_path):
    evil = "<script>alert(1)</script>"
    rows = [
        (f"r{r}", f"c{c}", [evil, "MG&co", "<b>FL</b>"][c % 3], [5, 3, 1][c % 3] if r % 4 else 3)
        for r in range(8)
        for c in range(9)
    ]
    path = _csv(tmp_path, "evil", rows)
    doc = build_report(path, tmp_path / "rep", Options(n_boot=50), progress=False, quiet=True)
    assert any(t["reject"] for t in doc["tukey"])  # the names reach the summary's Tukey sentence
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "<script" not in page and "<b>FL</b>" not in page and "MG&co" not in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page and "MG&amp;co" in page


@pytest.mark.parametrize(
    "args,pattern",
    [
        (["--seed", "-1"], r"--seed: must be >= 0"),
        (["--n-boot", "5"], r"--n-boot: must be >= 10"),
        (["--alpha", "0"], r"--alpha: must be > 0"),
    ],
)
def test_bad_flags_one_line_exit_2(tmp_path, args, pattern, capsys):
    """The command's main in-process (helpers/cli.py); its own process: test_analysis_load.py's module test."""
    line = fails_with(main, [str(DATA / "exclusion.csv"), "--quiet", "--out", str(tmp_path / "rep"), *args], capsys, "")
    assert re.search(pattern, line)


def test_too_few_ratings_and_bad_out_are_one_line_errors(tmp_path, capsys):
    two = _csv(tmp_path, "two", [("r1", "a", "NAT", 3), ("r2", "b", "MG", 4)])
    a_file = tmp_path / "taken"
    a_file.write_text("not a folder")
    cases = [
        ([str(two)], f"{two}: 2 test ratings in 2 conditions"),
        ([str(DATA / "exclusion.csv"), "--out", str(a_file)], f"--out {a_file}: a file, not a folder"),
        ([str(DATA / "exclusion.csv"), "--out", ""], "python -m analysis.report: argument --out: empty; give a"),
        ([str(DATA / "exclusion.csv"), "--out", str(a_file / "sub")], f"--out {a_file / 'sub'}: {a_file} is a file"),
    ]
    for args, start in cases:
        argv = [*args, "--quiet", "--n-boot", "20"] + ([] if "--out" in args else ["--out", str(tmp_path / "rep")])
        assert fails_with(main, argv, capsys, "").startswith(f"error: {start}")
    assert a_file.read_text() == "not a folder"


def test_tiny_tukey_p_values_are_bounds(frozen_run):
    """Beyond what the studentized-range integral resolves, p is an upper bound, printed as one: the three
    pairs no longer share one meaningless floor value."""
    doc = frozen_run[1]
    bounds = [(t["p_adj"], t["p_adj_bound"]) for t in doc["tukey"]]
    assert all(b for _, b in bounds) and len({p for p, _ in bounds}) == 3
    assert all(p <= 1e-9 for p, _ in bounds)
    page = (frozen_run[0] / "report.html").read_text()
    assert f"&lt;{bounds[1][0]:.0e}" in page or f"<{bounds[1][0]:.0e}" in page


def test_tukey_bound_is_a_true_upper_bound():
    from scipy import stats as sps

    from analysis.stats.anova import tukey_p

    for q in (6.0, 8.0, 9.5, 10.5):  # where the numerical tail is still accurate, the bound holds above it
        exact = float(sps.studentized_range.sf(q, 3, 200))
        p, bound = tukey_p(q, 3, 200)
        assert p >= exact * (1 - 1e-9) and (bound or p == exact)
    assert tukey_p(40.0, 3, 1437) == (pytest.approx(1e-139, rel=1), True)


def test_no_ordinal_flag_and_report_sections(tmp_path, frozen_run):
    assert main([str(DATA / "exclusion.csv"), "--out", str(tmp_path), "--no-ordinal", "--n-boot", "20", "--quiet"]) == 0
    assert json.loads((tmp_path / "stats.json").read_text())["ordinal_model"]["skipped"] == "--no-ordinal"
    assert (
        main(
            [
                str(DATA / "exclusion.csv"),
                "--out",
                str(tmp_path),
                "--ordinal-max-ratings",
                "5",
                "--n-boot",
                "20",
                "--quiet",
            ]
        )
        == 0
    )
    skipped = json.loads((tmp_path / "stats.json").read_text())["ordinal_model"]["skipped"]
    assert skipped == "9 ratings: above --ordinal-max-ratings 5"
    out, doc = frozen_run
    o = doc["ordinal_model"]
    assert set(o["thresholds"]) == {"1|2", "2|3", "3|4", "4|5"} and o["reference"] == "NAT" and o["converged"]
    assert set(o["fixed_effects"]) == {"condition[T.MG]", "condition[T.FL]"} == set(o["odds_ratios"])
    assert doc["without_exclusion"]["ordinal_model"]["n"] == 1800
    assert set(doc["mixed_model"]["df"]) == set(doc["mixed_model"]["fixed_effects"])
    page = (out / "report.html").read_text()
    assert "Ordinal mixed model" in page and "odds ratio" in page and "Satterthwaite" in page


def test_console_shows_ordinal_and_df(tmp_path, capsys):
    assert main([str(DATA / "ratings_small.csv"), "--out", str(tmp_path), "--n-boot", "50"]) == 0
    out = capsys.readouterr().out
    assert "Ordinal mixed model" in out and "odds ratio" in out and "df 87.0" in out and "<" in out


# ---------------------------------------------------------------------------------------------- issue 46
def _with_target(tmp_path, value):
    """ratings_small.csv as the app exports it today: every row also names the raters the study needs."""
    lines = (DATA / "ratings_small.csv").read_text().splitlines()
    path = tmp_path / "ratings.csv"
    path.write_text("\n".join([lines[0] + ",target_raters", *(f"{x},{value}" for x in lines[1:])]) + "\n")
    return path


@pytest.mark.full  # the full tier: two whole reports
def test_an_export_from_fewer_raters_than_its_target_is_noted_and_one_from_enough_is_not(tmp_path, capsys):
    n = json.loads((DATA / "expected_stats.json").read_text())["n_raters_total"]
    for target, noted in ((n + 40, True), (n, False)):
        out = tmp_path / str(target)
        assert main([str(_with_target(tmp_path, target)), "--out", str(out), "--no-mixed", "--n-boot", "20"]) == 0
        console = capsys.readouterr().out
        note = f"ratings from {n} raters, fewer than the {target} this study needs to fill"
        assert (note in console) is noted and (note in (out / "report.html").read_text()) is noted
        stats = json.loads((out / "stats.json").read_text())
        assert stats["target_raters"] == target and bool(stats["notes"]) is noted
    # an export without the column (every one before it) has neither the note nor the keys
    doc = build_report(
        DATA / "ratings_small.csv", tmp_path / "old", Options(n_boot=20, mixed=False), progress=False, quiet=True
    )
    assert "target_raters" not in doc and "notes" not in doc


@pytest.mark.parametrize("value", ["lots", "²", "9" * 5000], ids=["word", "superscript", "huge"])
def test_a_bad_target_raters_is_one_line(tmp_path, capsys, value):
    assert main([str(_with_target(tmp_path, value)), "--out", str(tmp_path / "r"), "--no-mixed", "--n-boot", "20"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "ratings.csv:2: target_raters" in err and "\n" not in err
