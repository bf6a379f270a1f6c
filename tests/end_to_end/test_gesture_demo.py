"""A gesture study end to end through `analysis.demo --stimuli` (the app, the simulated crowd, the export and the
report, as processes): an acr study drawn in two styles, filmed from the front, hips up. The report names the
reference as the study file does and tests condition x style. The appropriateness design with speech goes through
the demo in tests/rendering/test_audio.py (the demo's own study with sound), which this file ran a second time on a
study from folders until the two were found to check the same things."""

import json
import subprocess
import sys

import pytest
from helpers.own_study_data import make_study

from generation.make_stimuli import main as make_stimuli

pytestmark = pytest.mark.full  # make_study's takes are in ../shared

RENDER = '[render]\nview = "front"\nframing = "upper"\n'


def build(root, style):
    study = make_study(root / "in", n_items=6, n_catch=2)
    text = study.read_text().replace("n_training = 1", "n_training = 1\nlength_s = 2")
    study.write_text(text + RENDER + style)
    assert make_stimuli(["--study", str(study), "--out", str(root / "out"), "--size", "96", "--quiet"]) == 0
    return root / "out"


def demo(stimuli, out, design):
    """The demo on `stimuli`, 6 answers a unit: the checks below ask for every condition (and style) in the
    statistics, not for their precision, and the demo's default, the paper's 20, took the two-style study's crowd and
    report 1.7 times as long."""
    cmd = [sys.executable, "-m", "analysis.demo", "--out", str(out), "--stimuli", str(stimuli), "--design", design]
    more = ["--raters", "40", "--seed", "2", "--ratings-per-clip", "6"]
    r = subprocess.run([*cmd, *more], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    return json.loads((out / "report" / "stats.json").read_text())


def test_a_two_style_acr_study_through_the_demo(tmp_path):
    stimuli = build(tmp_path / "s", 'style = ["stick", "solid"]\n')
    stats = demo(stimuli, tmp_path / "demo_s", "acr")
    assert "real" in stats["condition_means"] and "NAT" not in stats["condition_means"]  # the study's own name
    assert stats["style"]["styles"] == ["stick", "solid"]
    assert "condition:style" in stats["style"]["anova"]["terms"]
    assert "interaction_test" in stats["style"]["mixed_model"]
    assert (tmp_path / "demo_s" / "report" / "figures" / "style_means.png").stat().st_size > 1000
    assert "methods" in stats and stats["agreement"]["krippendorff"] is not None
