"""Which measures a study of your own motion gets (generation.own_study.measures): a study with speech gets the gesture
measures in metrics.csv and gesture.csv, drops foot skating, and says so in measures.csv; a study of walking without
sound keeps foot skating and says the gesture measures were skipped, and why."""

import csv
import subprocess
import sys
from dataclasses import dataclass

import numpy as np
import pytest
from helpers.own_study_data import make_study
from helpers.paths import ROOT

from generation.make_stimuli import main as make_stimuli
from generation.own_study.measures import gesture_study
from moglow_eval.core import study


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@dataclass
class Spec:
    gesture: object = "auto"
    audio_folder: object = None
    smpl_model: object = None


BANDAI = ["joint_Root", "Hips", "UpperLeg_L", "UpperArm_R", "Hand_R", "Head"]
GENEA = ["b_root", "b_spine0", "b_r_upleg", "b_l_arm", "b_l_wrist", "b_head"]


@pytest.mark.parametrize(
    "spec, names, on, why",
    [
        (Spec(), BANDAI, False, "not a gesture study"),
        (Spec(audio_folder="audio"), BANDAI, True, "it has speech"),
        (Spec(smpl_model="m.npz"), BANDAI, True, "an SMPL-family body"),
        (Spec(), GENEA, True, "GENEA"),
        (Spec(gesture=False, audio_folder="audio"), BANDAI, False, "[metrics] gesture = false"),
        (Spec(gesture=True), BANDAI, True, "[metrics] gesture = true"),
    ],
)
def test_a_gesture_study_is_told_by_its_sound_its_body_or_its_skeleton(spec, names, on, why):
    found, reason = gesture_study(spec, names)
    assert found is on and why in reason


@pytest.fixture(scope="module")
def speech_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("gesture_study")
    spec = make_study(root / "in", n_items=4, n_catch=2, audio=True)
    spec.write_text(spec.read_text().replace("n_training = 1", "n_training = 1\nlength_s = 3"))
    assert make_stimuli(["--study", str(spec), "--out", str(root / "out"), "--size", "64", "--quiet"]) == 0
    return root / "out"


@pytest.mark.full  # make_study's takes are in ../shared
def test_a_study_with_speech_gets_the_gesture_measures(speech_study):
    out = speech_study
    metrics = _rows(out / "metrics.csv")
    assert list(metrics[0])[-len(study.GESTURE_METRIC_NAMES) :] == list(study.GESTURE_METRIC_NAMES)
    assert all(r["foot_skating"] == "nan" for r in metrics)  # a speaker's feet are not what is judged
    nat = [r for r in metrics if r["condition"] == "NAT" and r["role"] == "test"]
    assert all(np.isfinite(float(r[m])) for r in nat for m in ("fgd", "beat_align", "hellinger_speed_hands"))
    table = {r["condition"]: r for r in _rows(out / study.GESTURE_FILE)}
    assert list(table) == ["NAT", "SYS_A", "SYS_B", "BAD"]
    # the catch clips (a shaking and a frozen body) are farther from the reference than the smoothed system
    assert float(table["BAD"]["fgd"]) > float(table["SYS_A"]["fgd"])
    assert float(table["BAD"]["hellinger_accel_hands"]) > float(table["SYS_A"]["hellinger_accel_hands"])
    assert table["NAT"]["listener_response"] == "nan"  # one voice
    notes = {r["measure"]: r for r in _rows(out / study.MEASURES_FILE)}
    assert set(notes) == {*study.METRIC_NAMES, *study.GESTURE_METRIC_NAMES}
    assert notes["foot_skating"]["status"] == "skipped" and "it has speech" in notes["foot_skating"]["reason"]
    assert notes["beat_align"]["status"] == "measured" and "sigma 0.3 s" in notes["beat_align"]["settings"]
    assert notes["listener_response"]["status"] == "skipped" and "two voices" in notes["listener_response"]["reason"]
    assert notes["jerk"]["status"] == "measured" and int(notes["jerk"]["clips"]) == len(metrics)


def test_the_gesture_measures_are_taken_about_the_body_not_a_root_marker(tmp_path, monkeypatch):
    """Bandai-Namco's `joint_Root` stays at the scene's origin while the body walks 8 m (tests/data/bvh's walk, from
    dataset 2): a system whose clips are the reference's bodies 5 m further on, the marker left at the origin, moves
    exactly as the reference does, and gets the reference's own values of every measure about the root (the FGD and
    the motion histograms' distances): about the marker, the FGD saw where the body was."""
    from types import SimpleNamespace

    from helpers.paths import TEST_DATA

    from generation.data.motion_files import read_motion
    from generation.metrics import gesture_fgd
    from generation.own_study.measures import study_measures

    # A short training: the values differ from a build's, not whether one clip's equal another's.
    train = gesture_fgd.GestureEncoder.train.__func__
    monkeypatch.setattr(
        gesture_fgd.GestureEncoder, "train", classmethod(lambda cls, *a, **k: train(cls, *a, steps=20, **k))
    )

    m = read_motion(TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz", fps=30.0)
    at_origin = m.joints.astype(np.float64)
    assert np.abs(at_origin[:, 0]).max() == 0.0  # the marker, as recorded
    moved = at_origin + np.array([5.0, 0.0, 0.0])
    moved[:, 0] = 0.0
    takes = {f"item{i}": at_origin[i * 60 : i * 60 + 60] for i in range(4)}  # four 2-s items of one walk
    clips = [
        SimpleNamespace(condition=cond, role="test", item=item, motion_item="", joints=j + shift)
        for cond, shift in ((study.NATURAL, 0.0), ("AHEAD", moved[0] - at_origin[0]))
        for item, j in takes.items()
    ]
    spec = Spec(gesture=True)
    spec.fps, spec.seed = 30.0, 0
    rows = [dict(condition=c.condition) for c in clips]
    study_measures(spec, clips, list(range(len(clips))), rows, (list(m.names), m.parents), {}, tmp_path)
    by = {c: [r for r in rows if r["condition"] == c] for c in (study.NATURAL, "AHEAD")}
    for name in ("fgd", *study.HELLINGER_METRICS):
        ahead, own = ([r[name] for r in by[c]] for c in ("AHEAD", study.NATURAL))
        assert np.isfinite(own).all(), name
        np.testing.assert_allclose(ahead, own, rtol=1e-5, err_msg=name)


@pytest.mark.full  # make_study's takes are in ../shared
def test_a_study_without_the_gesture_measures_is_built_without_torch(tmp_path):
    """The gesture measures' encoder needs torch, whose import takes a second and more memory than the rest of a
    build's: a study that does not get the measures is built without ever importing it."""
    spec = make_study(tmp_path / "in", n_items=2, n_catch=1)
    run = (
        "import sys\nfrom generation.make_stimuli import main\n"
        "code = main(sys.argv[1:])\nprint('torch' in sys.modules)\nsys.exit(code)"
    )
    argv = ["--study", spec, "--out", tmp_path / "out", "--size", "32", "--length-s", "1", "--quiet", "--workers", "1"]
    r = subprocess.run([sys.executable, "-c", run, *map(str, argv)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0 and r.stdout.split()[-1:] == ["False"], (r.stdout[-500:], r.stderr[-2000:])
    measures = {row["measure"]: row["status"] for row in _rows(tmp_path / "out" / study.MEASURES_FILE)}
    assert measures["fgd"] == study.MEASURE_STATUS[2] and measures["jerk"] == study.MEASURE_STATUS[0]
