"""The power planner (python -m analysis.plan): its estimated power against the observed rejection rate of the
report's own Tukey HSD on studies simulated with a known effect, and its command line."""

import json

import numpy as np
import pandas as pd
import pytest
from helpers.cli import fails_with
from helpers.paths import ROOT

from analysis import plan
from analysis.stats import anova as stats
from analysis.stats import power

DATA = ROOT / "tests" / "data" / "analysis"
TRUE = {"means": {"NAT": 3.3, "MG": 3.0, "FL": 2.4}, "sd_rater": 0.5, "sd_clip": 0.3, "sd_residual": 1.05}
CLIPS_PER_CONDITION, CLIPS_PER_RATER = 30, 45


def simulate_study(rng, n_raters, model=TRUE):
    """One study from the true model, written independently of plan.simulate_power (long table, one row per
    rating, each rater rating CLIPS_PER_RATER clips drawn at random)."""
    conds = list(model["means"])
    clip_cond = np.repeat(conds, CLIPS_PER_CONDITION)
    clip_eff = rng.normal(0, model["sd_clip"], len(clip_cond))
    clips = np.concatenate([rng.choice(len(clip_cond), CLIPS_PER_RATER, replace=False) for _ in range(n_raters)])
    rater = np.repeat(np.arange(n_raters), CLIPS_PER_RATER)
    mu = np.array([model["means"][c] for c in clip_cond])
    y = (
        mu[clips]
        + rng.normal(0, model["sd_rater"], n_raters)[rater]
        + clip_eff[clips]
        + rng.normal(0, model["sd_residual"], len(clips))
    )
    return pd.DataFrame({"rater_id": rater, "clip_id": clips, "condition": clip_cond[clips], "rating": y})


def design_with(means, sd, clips):
    """A planner's design (analysis.plan.pilot_design's dict) with these condition means, the SDs (rater, clip,
    residual) and the clips (per condition, per rater)."""
    (sd_rater, sd_clip, sd_residual), (per_condition, per_rater) = sd, clips
    return {"conditions": list(means), "means": means, "sd_rater": sd_rater, "sd_clip": sd_clip,
            "sd_residual": sd_residual, "clips_per_condition": per_condition, "clips_per_rater": per_rater}  # fmt: skip


def check_planner(n_studies, n_sim, bound):
    """Pilot of 60 raters from the true model -> plan for MG vs NAT at the true difference -> the rejection
    rate of stats.tukey_hsd over n_studies new studies of the planned size must match the estimated power."""
    rng = np.random.default_rng(11)
    pilot = simulate_study(rng, 60)
    design = plan.pilot_design(pilot)
    assert (design["clips_per_condition"], design["clips_per_rater"]) == (CLIPS_PER_CONDITION, CLIPS_PER_RATER)
    pair = ("NAT", "MG")
    design = plan.with_difference(design, pair, TRUE["means"]["MG"] - TRUE["means"]["NAT"])
    res = plan.plan(design, pair, target=0.8, n_sim=n_sim, seed=5, progress=False, clip_test=False)
    n_raters, estimated = res["planned_raters"], res["planned_power"]
    assert n_raters is not None and 0.8 <= estimated < 0.9
    rejected = 0
    for _ in range(n_studies):
        t = stats.tukey_hsd(simulate_study(rng, n_raters))
        row = t[(t.group1 == "MG") & (t.group2 == "NAT")].iloc[0]
        rejected += bool(row.reject)
    observed = rejected / n_studies
    assert abs(estimated - observed) <= bound, (n_raters, estimated, observed)
    return n_raters, estimated, observed


@pytest.mark.full  # the full tier: a power simulation against simulated studies
def test_planned_power_matches_observed_rejection_rate_short():
    """200 studies (Monte Carlo SD of the observed rate ~0.03), bound ±0.10 -- still tight enough to catch a
    planner that left the clip variance out (test_clip_variance_matters). (500 studies and a bound of ±0.05 once
    gave planned 24 raters, estimated 0.805, observed 0.768: `check_planner(500, 4000, 0.05)` by hand.)"""
    check_planner(200, 1000, 0.10)


def test_clip_variance_matters():
    """Same design, no clip variance: higher power. A planner that left out the clips would promise too much."""
    d = design_with(TRUE["means"], sd=(0.5, 0.3, 1.05), clips=(30, 45))
    with_clips = power.simulate_power(d, ("NAT", "MG"), 20, n_sim=2000, seed=1)[0]
    without = power.simulate_power({**d, "sd_clip": 0.0}, ("NAT", "MG"), 20, n_sim=2000, seed=1)[0]
    assert without > with_clips + 0.05


def test_null_rejection_rate_is_alpha_where_tukey_is_exact():
    """Two conditions, no rater or clip variance: Tukey HSD is the two-sample t test, so the simulated
    rejection rate under no difference must be alpha (SD 0.0034 with 4000 studies)."""
    d = design_with({"A": 3.0, "B": 3.0}, sd=(0.0, 0.0, 1.0), clips=(10, 5))
    p, low, high = power.simulate_power(d, ("A", "B"), 6, n_sim=4000, seed=2)
    assert abs(p - 0.05) < 0.012 and low < p < high


def test_the_clip_decision_keeps_its_false_positive_rate_where_the_ratings_lose_theirs():
    """Two conditions, clips that vary, 60 raters a study: the ratings' Tukey (a t test on ratings that share their
    clip's effect) rejects a zero difference far more often than alpha; on the clips' mean ratings it stays at
    alpha (SD 0.005 with 2000 studies)."""
    d = design_with({"A": 3.0, "B": 3.0}, sd=(0.5, 0.3, 1.0), clips=(30, 45))
    on_ratings = power.simulate_power(d, ("A", "B"), 60, n_sim=2000, seed=3)[0]
    on_clips = power.simulate_power(d, ("A", "B"), 60, n_sim=2000, seed=3, unit="clip")[0]
    assert on_ratings > 0.15 and abs(on_clips - 0.05) < 0.017, (on_ratings, on_clips)


@pytest.mark.full  # the full tier: a power simulation against simulated studies
def test_the_clip_decision_matches_tukey_on_clip_means_of_independent_studies():
    """simulate_power(unit="clip") against the report's own Tukey HSD run on the clips' mean ratings of studies
    drawn independently (simulate_study): 200 studies (Monte Carlo SD ~0.035), bound +-0.10."""
    rng = np.random.default_rng(7)
    d = design_with(TRUE["means"], sd=(TRUE["sd_rater"], TRUE["sd_clip"], TRUE["sd_residual"]), clips=(30, 45))
    n_raters = 12
    estimated = power.simulate_power(d, ("NAT", "MG"), n_raters, n_sim=2000, seed=4, unit="clip")[0]
    rejected = 0
    for _ in range(200):
        study = simulate_study(rng, n_raters)
        means = study.groupby("clip_id").agg(condition=("condition", "first"), rating=("rating", "mean"))
        t = stats.tukey_hsd(means)
        rejected += bool(t[(t.group1 == "MG") & (t.group2 == "NAT")].iloc[0].reject)
    assert 0.2 < estimated < 0.95 and abs(estimated - rejected / 200) <= 0.10, (estimated, rejected / 200)


def test_a_plan_says_when_only_more_clips_would_do():
    """A difference the clips' own spread hides (0.4 against a clip SD of 1.0, 5 clips a condition): the ratings'
    Tukey reaches power 0.8 with enough raters, but that is its false positives; the clip decision says no number
    of raters reaches it."""
    d = design_with({"A": 3.0, "B": 3.4, "C": 3.6}, sd=(0.3, 1.0, 0.6), clips=(5, 15))
    res = plan.plan(d, ("A", "B"), target=0.8, n_sim=100, seed=1, progress=False)
    clip = res["clip_test"]
    assert res["planned_raters"] and res["false_positive_rate"] > 0.3, res
    assert clip["planned_raters"] is None and clip["max_power"] < 0.3 and clip["power_at_check"] < 0.3, clip
    text = plan._clip_test_text(clip, 0.8, 5, res["planned_raters"])
    assert "more clips per condition are needed" in text and f"at {res['planned_raters']} raters" in text


def test_plan_cli_writes_curve_and_table(tmp_path, capsys):
    """The command's main in-process (its own process: tests/project/test_console.py)."""
    argv = [str(DATA / "ratings_small.csv"), "--out", str(tmp_path), "--n-sim", "200", "--raters", "6", "--quiet"]
    assert plan.main(argv) == 0
    out = capsys.readouterr().out
    doc = json.loads((tmp_path / "plan.json").read_text())
    assert doc["pair"] == ["NAT", "MG"]  # the pilot's closest pair
    assert doc["planned_raters"] >= 2 and doc["planned_power"] >= 0.8 and "6" in doc["power_at"]
    assert (tmp_path / "power_curve.png").read_bytes()[:4] == b"\x89PNG"
    assert "Power 0.8 needs" in out and "ratings per clip" in out
    clip = doc["clip_test"]  # the decision on the clips' means: the raters it needs, or that clips are short
    rows = doc["curve"]
    assert all(0 <= r["clip_low"] <= r["clip_power"] <= r["clip_high"] <= 1 for r in rows)
    # beside the ratings' decision at every size, never above it by more than chance: the clips' means are less sure
    assert all(r["clip_power"] <= r["power"] + 0.1 for r in rows), rows
    assert 0 < clip["max_power"] <= 1 and "Counting the clips as the sample they are" in out
    assert (clip["planned_raters"] is None) == ("more clips per condition are needed" in out)


@pytest.mark.parametrize(
    "args,start",
    [
        (
            ["--no-pilot", "--sd-rater", "0.5", "--sd-clip", "0.3", "--difference", "0.3"],
            "error: --no-pilot needs --sd-residual",
        ),
        ([str(DATA / "ratings_small.csv"), "--pair", "NAT", "XX"], "error: --pair: condition 'XX'"),
        ([str(DATA / "ratings_small.csv"), "--power", "2"], "error: python -m analysis.plan: argument --power"),
        ([str(DATA / "ratings_small.csv"), "--clips-per-rater", "1000"], "error: --clips-per-rater 1000: the study"),
        ([], "error: give a pilot ratings file"),
    ],
)
def test_plan_cli_errors_are_one_line(tmp_path, args, start, capsys):
    """The command's main in-process, per bad flag (a process each was the full tier's; helpers/cli.py)."""
    assert fails_with(plan.main, [*args, "--out", str(tmp_path), "--quiet"], capsys, "").startswith(start)


def test_an_out_in_the_way_is_refused_before_the_simulation(tmp_path, capsys):
    """It was checked only after the simulation (minutes at the default --n-sim); "" is refused too (by the parser
    every command uses: tests/core/test_flag_checks.py)."""
    (tmp_path / "afile").write_text("x")
    pilot = [str(DATA / "ratings_small.csv"), "--quiet"]
    assert "argument --out: empty" in fails_with(plan.main, [*pilot, "--out", ""], capsys, "")
    out = str(tmp_path / "afile")
    assert fails_with(plan.main, [*pilot, "--out", out], capsys, "").startswith(f"error: --out {out}: a")


def test_a_pilot_its_effects_fit_exactly_is_one_line(tmp_path, capsys):
    """A pilot whose every rating is its condition plus its rater's bias, nothing left over: no mixed model to take
    the variances from, said in one line (it was a ModelUndefined traceback)."""
    df = pd.read_csv(DATA / "ratings_small.csv")
    base = df["condition"].map({"NAT": 4, "MG": 3, "FL": 2}).fillna(1)
    df["rating"] = (base + (df["condition"] != "BAD") * (df["rater_id"].str[-1].astype(int) % 2)).astype(int)
    df.to_csv(tmp_path / "pilot.csv", index=False)
    err = fails_with(plan.main, [str(tmp_path / "pilot.csv"), "--out", str(tmp_path), "--quiet"], capsys, "")
    assert err.startswith("error: ") and "the pilot cannot be fitted" in err and "fit every rating exactly" in err


def test_plan_help_says_acr_only(capsys):
    with pytest.raises(SystemExit) as e:
        plan.main(["--help"])
    out = capsys.readouterr().out
    assert e.value.code == 0 and "acr" in out and "pairwise" in out.lower()
