"""A study of your own motion (issue 31): folders of any skeleton and format -> stimuli -> app -> report.

The study is built from the real Bandai-Namco actions (not locomotion) with a 70-joint finger-and-face skeleton
(tests/helpers/own_study_data.py): the reference as BVH, one made-up system as Z-up centimetre .npy arrays with a
skeleton JSON, another as BVH."""

import csv
import hashlib
import json
import subprocess
import sys

import numpy as np
import pytest
from helpers.browser import acr_rater_flow
from helpers.own_study_data import action_takes, make_study
from helpers.paths import ROOT

from generation.data.motion_files import read_motion
from generation.make_stimuli import main as make_stimuli
from generation.metrics import c2st
from generation.metrics.c2st_features import GROUPS
from generation.stimuli.catch_kinds import make_catch, unlike_any_pose
from moglow_eval.core.clip import load_clip
from moglow_eval.core.skeleton_names import body_root, body_skeleton
from rendering.camera import framing_camera
from rendering.raster import FrameDrawer

pytestmark = pytest.mark.full  # the full tier: the real actions in ../shared


def _rows(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def own_study(tmp_path_factory):
    """(study file, stimulus folder) of a small study built once for the module."""
    root = tmp_path_factory.mktemp("own")
    study = make_study(root / "in", n_items=8, n_catch=3)
    # 1.5-s clips: the browser test below plays them in real time
    args = ["--study", str(study), "--out", str(root / "out"), "--size", "160", "--quiet", "--length-s", "1.5"]
    assert make_stimuli(args) == 0
    return study, root / "out"


# ---------------------------------------------------------------- reading any format
def test_bvh_with_fingers_and_npy_give_the_same_motion(tmp_path):
    make_study(tmp_path, n_items=1, n_catch=0)
    bvh = read_motion(tmp_path / "real" / "item00.bvh.gz", fps=20.0)  # units and up detected
    assert len(bvh.names) == 70 and sum("Index" in n for n in bvh.names) == 8
    assert 1.4 < float(np.median(bvh.joints[..., 1].max(1))) < 2.0  # centimetres found: a person in metres
    # The same motion as a Z-up centimetre array with its skeleton in JSON reads back to the same positions.
    zup_cm = np.stack([bvh.joints[..., 0], -bvh.joints[..., 2], bvh.joints[..., 1]], -1) * 100
    np.save(tmp_path / "same.npy", zup_cm)
    from generation.data.motion_files import Skeleton

    skel = Skeleton.load(tmp_path / "skeleton.json")
    arr = read_motion(tmp_path / "same.npy", fps=20.0, skeleton=skel, source_fps=20.0)
    assert arr.names == bvh.names and np.array_equal(arr.parents, bvh.parents)
    assert np.abs(arr.joints - bvh.joints).max() < 1e-4


def test_clips_of_any_length_are_kept_whole_or_cut(tmp_path):
    study = make_study(tmp_path, n_items=4, n_catch=1)
    rc = make_stimuli(["--study", str(study), "--out", str(tmp_path / "whole"), "--size", "64", "--quiet"])
    assert rc == 0
    frames = {}
    for r in _rows(tmp_path / "whole" / "manifest.csv"):
        frames.setdefault(r["item"], set()).add(int(r["frames"]))
    assert all(len(f) == 1 for f in frames.values())  # every clip of an item is as long as the others
    assert len({f.pop() for f in frames.values()}) > 1  # ... and items keep their own lengths
    rc = make_stimuli(
        ["--study", str(study), "--out", str(tmp_path / "cut"), "--size", "64", "--quiet", "--length-s", "2.5"]
    )
    assert rc == 0 and {r["frames"] for r in _rows(tmp_path / "cut" / "manifest.csv")} == {"50"}


# ---------------------------------------------------------------- the stimulus folder
def test_study_folder_follows_the_contract(own_study):
    _, out = own_study
    manifest = _rows(out / "manifest.csv")
    conds = {r["condition"] for r in manifest}
    assert conds == {"NAT", "SYS_A", "SYS_B", "BAD"}  # the reference plays NAT's role
    # ... and keeps its own name beside the manifest, for the app's export and the report (CONTRACTS §4)
    assert json.loads((out / "study.json").read_text()) == {"reference_name": "real"}
    roles = {r["role"] for r in manifest}
    assert roles == {"test", "catch", "training"}
    catch_items = {r["item"] for r in manifest if r["condition"] == "BAD"}
    assert len(catch_items) == 3
    for item in catch_items:  # each catch item also holds its clips in every condition, role catch
        assert {r["condition"] for r in manifest if r["item"] == item and r["role"] == "catch"} == conds
    assert {r["seed"] for r in manifest if r["condition"] == "BAD"} == {"jitter", "freeze", "swap"}
    sizes = {}
    for r in manifest:
        sizes.setdefault(r["item"], set()).add((out / r["video"]).stat().st_size)
    assert all(len(s) == 1 for s in sizes.values())  # blind: an item's videos are one size (items differ in length)
    hashes = [hashlib.sha256((out / r["video"]).read_bytes()).hexdigest() for r in manifest]
    assert len(set(hashes)) == len(hashes)  # no two videos alike, catch copies included
    clip = load_clip(out / manifest[0]["motion"])
    assert clip["joints"].shape[1] == 70
    metrics = _rows(out / "metrics.csv")
    assert {"jerk", "acceleration", "bone_length_std", "foot_skating"} <= set(metrics[0])
    nat = [r for r in metrics if r["condition"] == "NAT"]
    assert all(float(r["bone_length_std"]) < 1e-3 and np.isfinite(float(r["foot_skating"])) for r in nat)
    assert all(r["control_error"] == "nan" for r in metrics)  # no control in a study of your own motion
    table = {r["condition"]: r for r in _rows(out / "c2st.csv")}
    assert set(table) == {"NAT:split", "SYS_A", "SYS_B", "BAD"}
    features = _rows(out / "c2st_features.csv")  # what tells each condition apart, named by the study's own joints
    assert {r["condition"] for r in features} == {"SYS_A", "SYS_B", "BAD"}
    assert {r["group"] for r in features if r["kind"] == "group"} == set(GROUPS)
    names = {r["feature"] for r in features if r["kind"] == "feature"}
    assert f"{clip['joint_names'][1]} jerk" in names
    assert all(0.5 <= float(r["auc"]) <= 1 for r in features if r["kind"] == "feature")


# ---------------------------------------------------------------- catch clips and the C2ST
@pytest.fixture(scope="module")
def action_features():
    """{take: (joints, features, parents, root, body)} of 40 real action takes (22 joints), at 20 fps: the C2ST's
    features of the body without its root marker, and the catch clips carried by the hips, as a study makes them."""
    out = {}
    for take in action_takes(69):
        m = read_motion(take, fps=20.0)
        if len(m.names) == 22 and len(out) < 40:  # (a few takes carry End Sites of their own)
            body, _, body_parents = body_skeleton(m.names, m.parents)
            features = c2st.clip_features(m.joints[:, body], 20.0, body_parents)
            out[take.name] = (m.joints, features, m.parents, body_root(m.names, m.parents), (body, body_parents))
    assert len(out) == 40
    return out


def test_c2st_near_chance_for_the_reference_against_itself(action_features):
    feats = {k: f for k, (_, f, *_) in action_features.items()}
    assert c2st.c2st_self(feats)["auc"] <= 0.6


@pytest.mark.parametrize("kind", ["jitter", "freeze", "swap"])
def test_c2st_near_one_for_catch_clips(action_features, kind):
    ref = {k: f for k, (_, f, *_) in action_features.items()}
    bad = {
        k: c2st.clip_features(make_catch(j, kind, seed=i, root=root)[:, body], 20.0, body_parents)
        for i, (k, (j, _, _, root, (body, body_parents))) in enumerate(action_features.items())
    }
    assert c2st.c2st(ref, bad)["auc"] >= 0.9


def test_catch_kinds_are_clearly_broken(action_features):
    from generation.metrics.objective import acceleration, jerk

    joints, _, _, root, _ = next(iter(action_features.values()))
    jit, frz, swp = (make_catch(joints, k, seed=0, root=root) for k in ("jitter", "freeze", "swap"))
    assert jerk(jit, 20.0) > 10 * jerk(joints, 20.0)
    assert acceleration(jit, 20.0) > 5 * acceleration(joints, 20.0)
    frozen = frz[len(frz) // 2 :] - frz[len(frz) // 2 :, root : root + 1]
    assert np.abs(np.diff(frozen, axis=0)).max() < 1e-6  # the body holds still
    assert jerk(swp, 20.0) > 1.5 * jerk(joints, 20.0)  # the trunk jumps where it wraps round
    # On every take, calm ones too (a wave, a bow: legs that hardly move), the swapped body holds poses the take
    # never does, most of the time; out of step alone, a wave's upper body was the wave played later.
    for i, (j, _, _, r, _) in enumerate(action_features.values()):
        unlike = unlike_any_pose(make_catch(j, "swap", seed=i, root=r), j, r)
        assert np.median(unlike) > 0.05, i


# ---------------------------------------------------------------- rendering any skeleton, on pixels
def test_unusual_skeleton_renders_tall_both_sides_coloured_fingers_thinner(tmp_path):
    make_study(tmp_path, n_items=1, n_catch=0)
    m = read_motion(tmp_path / "real" / "item00.bvh.gz", fps=20.0)
    joints = m.joints - np.array([m.joints[0, 0, 0], 0, m.joints[0, 0, 2]])
    cam = framing_camera([joints])
    size = 320

    def frame(**kw):
        d = FrameDrawer(m.parents, m.names, size, camera=cam, **kw)
        target = np.array([joints[0, 0, 0], cam.height, joints[0, 0, 2]])
        d.draw(joints[0], target)
        return d.rgb().astype(int)

    rgb = frame()
    grey = (np.abs(rgb[..., 0] - rgb[..., 1]) < 12) & (np.abs(rgb[..., 1] - rgb[..., 2]) < 12)
    blue = (rgb[..., 2] > rgb[..., 0] + 60) & ~grey
    red = (rgb[..., 0] > rgb[..., 2] + 60) & ~grey
    dark = rgb.sum(-1) < 200  # trunk and head
    figure_rows = np.flatnonzero((blue | red | dark).any(1))
    assert figure_rows.max() - figure_rows.min() >= size / 2  # at least half the frame height
    assert blue.sum() > 50 and red.sum() > 50  # both sides coloured
    thick = frame(thin=())  # fingers drawn as thick as the rest
    hidden = frame(
        hide=[n for n in m.names if "Index" in n or "Thumb" in n or "Middle" in n or "Ring" in n or "Pinky" in n]
    )
    coloured = lambda im: int((np.abs(im[..., 0] - im[..., 2]) > 60).sum())  # noqa: E731
    assert coloured(hidden) < coloured(rgb) < coloured(thick)


# ---------------------------------------------------------------- bad input
def _fails(args, capsys, needle):
    rc = make_stimuli(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err and err[-1].startswith("error: ") and needle in err[-1], err
    return err[-1]


def _out(tmp_path):
    return ["--out", str(tmp_path / "out"), "--size", "64", "--quiet"]


def test_bad_study_input_is_one_line_and_leaves_no_manifest(tmp_path, capsys):
    study = make_study(tmp_path / "s", n_items=3, n_catch=1)
    base = ["--study", str(study), *_out(tmp_path)]
    root = study.parent
    # an item missing in one condition
    (root / "sys_b" / "item01.bvh").rename(root / "item01.bvh")
    _fails(base, capsys, "no file for item item01")
    (root / "item01.bvh").rename(root / "sys_b" / "item01.bvh")
    # NaN in a .npy
    good = np.load(root / "sys_a" / "item02.npy")
    bad = good.copy()
    bad[5, 3] = np.nan
    np.save(root / "sys_a" / "item02.npy", bad)
    _fails(base, capsys, "item02.npy: positions contain NaN")
    # absurd units (a body 1.6 km tall)
    np.save(root / "sys_a" / "item02.npy", good * 1e5)
    _fails(base, capsys, "item02.npy: the body is")
    # a skeleton mismatch: one joint fewer, with a matching skeleton file of its own
    np.save(root / "sys_a" / "item02.npy", good)
    # a clip too short for length_s
    _fails([*base, "--length-s", "60"], capsys, "shorter than the study's length_s 60")
    assert not (tmp_path / "out" / "manifest.csv").exists()
    # an --out that is a file: said before any motion is read (a broken file above would be named otherwise)
    np.save(root / "sys_a" / "item02.npy", bad)
    (tmp_path / "taken.csv").write_text("x\n")
    line = _fails(["--study", str(study), "--out", str(tmp_path / "taken.csv"), "--quiet"], capsys, "a file")
    assert line == f"error: --out {tmp_path / 'taken.csv'}: a file, not a folder", line


def test_skeleton_mismatch_names_both_files(tmp_path, capsys):
    study = make_study(tmp_path / "s", n_items=2, n_catch=0)
    root = study.parent
    from helpers.own_study_data import write_bvh

    from generation.motion.bvh import read_bvh

    b = read_bvh(root / "sys_b" / "item01.bvh")
    keep = [j for j, n in enumerate(b.names) if n != "Lid_L"]
    cols = np.concatenate(
        [np.arange(c, c + len(b.channels[j])) for j, c in enumerate(b.channel_columns()) if j in keep]
    )
    write_bvh(
        root / "sys_b" / "item01.bvh",
        [b.names[j] for j in keep],
        list(b.parents[keep]),
        b.offsets[keep],
        [b.channels[j] for j in keep],
        b.motion[:, cols],
        b.frame_time,
    )
    line = _fails(["--study", str(study), *_out(tmp_path)], capsys, "sys_b/item01.bvh: skeleton")
    assert "real/item01.bvh.gz" in line


@pytest.mark.parametrize(
    "edit, needle",
    [
        ('hide = ["NoSuchJoint"]', "[skeleton] hide: unknown joint name 'NoSuchJoint'"),
        ('units = "furlong"', "[skeleton] units"),
        ('colour = "red"', "[skeleton] colour: unknown key"),
        ('feet = ["Foot_L"]', "[skeleton] feet: name 2 joints"),
    ],
)
def test_bad_study_file_keys(tmp_path, capsys, edit, needle):
    study = make_study(tmp_path / "s", n_items=2, n_catch=0, extra_toml=edit + "\n")
    _fails(["--study", str(study), *_out(tmp_path)], capsys, needle)
    assert not (tmp_path / "out" / "manifest.csv").exists()


def test_empty_condition_folder(tmp_path, capsys):
    study = make_study(tmp_path / "s", n_items=2, n_catch=0)
    for f in (study.parent / "sys_b").iterdir():
        f.unlink()
    _fails(["--study", str(study), *_out(tmp_path)], capsys, "condition SYS_B has no motion files")


# ---------------------------------------------------------------- the built-in study is unchanged
def test_builtin_study_output_unchanged(tmp_path):
    """The same manifest rows (but the random ids) and, for NAT, the same motion files as before the study from
    folders came (tests/data/builtin_stimuli_digest.json, written by the code before it). MG, FL and BAD are
    sampled, whose bits depend on the CPU kind (docs/models.md), so only their rows are compared."""
    out = tmp_path / "builtin"
    args = ["--out", str(out), "--n-items", "3", "--n-catch", "2", "--n-training", "1", "--seed", "5"]
    args += ["--catch-kinds", "mg-early"]  # the paper's catch clips, as before (issue 37 mixes in a freeze by default)
    assert make_stimuli([*args, "--size", "64", "--workers", "1", "--quiet"]) == 0
    want = json.loads((ROOT / "tests" / "data" / "builtin_stimuli_digest.json").read_text())
    got = []
    for r in _rows(out / "manifest.csv"):
        # postprocess came later (MG's and FL's hips put on the root, then their bones set to the actor's), only
        # for MG and FL
        assert r["postprocess"] == ("root_hips+rigid_skeleton" if r["condition"] in ("MG", "FL") else "")
        row = {k: v for k, v in r.items() if k not in ("clip_id", "video", "motion", "postprocess")}
        if r["condition"] == "NAT":
            h = hashlib.sha256()
            with np.load(out / r["motion"]) as z:
                for k in sorted(z.files):
                    h.update(k.encode())
                    h.update(np.ascontiguousarray(z[k]).tobytes())
            row["motion_sha256"] = h.hexdigest()
        got.append(row)
    assert got == want


# ---------------------------------------------------------------- end to end
@pytest.mark.parametrize("db", ["postgres"])  # the database is the app's concern, tested there on both
def test_own_study_end_to_end(own_study, tmp_path, db, request):
    """Study from folders -> app -> simulated crowd -> export -> report, on PostgreSQL."""
    _, stimuli = own_study
    url = f"sqlite:///{tmp_path / 'r.sqlite'}" if db == "sqlite" else request.getfixturevalue("pg_database")
    out = tmp_path / "demo"
    cmd = [sys.executable, "-m", "analysis.demo", "--out", str(out), "--stimuli", str(stimuli), "--db", url]
    r = subprocess.run([*cmd, "--raters", "60", "--seed", "3"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    stats = json.loads((out / "report" / "stats.json").read_text())
    # The reference keeps the study file's name ("real") from the stimulus folder through the app's export to
    # the report's tables, with no flag given.
    assert set(stats["condition_means"]) == {"real", "SYS_A", "SYS_B"}
    assert {row["reference_name"] for row in csv.DictReader(open(out / "ratings.csv"))} == {"real"}
    # The simulated raters follow the metrics: the trembling system (SYS_B) is rated lowest.
    assert min(stats["condition_means"], key=stats["condition_means"].get) == "SYS_B"
    assert {row["condition"] for row in stats["c2st"]} == {"real:split", "SYS_A", "SYS_B", "BAD"}
    assert "Classifier two-sample test" in (out / "report" / "report.html").read_text()


# ---------------------------------------------------------------- the page, in a real browser
@pytest.fixture(scope="module")
def app_stimuli(own_study):
    """The app's stimuli for the browser test below: the study from folders."""
    return str(own_study[1] / "manifest.csv")


# The page does not depend on the database (the API suite covers both); one browser run, as the ACR page's own test.
@pytest.mark.parametrize("app_db_url", ["postgres"], indirect=True)
def test_own_study_in_a_real_browser(live_server, browser):
    """The rater's whole flow (helpers.browser.acr_rater_flow), served with the study above."""
    acr_rater_flow(live_server, browser)


def test_users_own_catch_folder(tmp_path):
    """[catch] folder: the user's own bad clips, one per item stem, become the BAD clips of those items."""
    study = make_study(tmp_path / "s", n_items=3, n_catch=1)
    root = study.parent
    (root / "bad").mkdir()
    for stem in ("item00", "item02"):
        (root / "bad" / f"{stem}.bvh").write_bytes((root / "sys_b" / f"{stem}.bvh").read_bytes())
    text = study.read_text().replace('make = ["jitter", "freeze", "swap"]\nn = 1', 'folder = "bad"')
    study.write_text(text)
    assert make_stimuli(["--study", str(study), "--out", str(tmp_path / "out"), "--size", "64", "--quiet"]) == 0
    bad = [r for r in _rows(tmp_path / "out" / "manifest.csv") if r["condition"] == "BAD"]
    assert sorted(r["item"] for r in bad) == ["item00", "item02"] and {r["seed"] for r in bad} == {"own"}


def test_a_skeleton_whose_first_joint_is_not_the_root(tmp_path):
    from generation.data.motion_files import MotionError, Skeleton

    (tmp_path / "s.json").write_text('{"names": ["Spine", "Hips"], "parents": ["Hips", null]}')
    np.save(tmp_path / "a.npy", np.tile(np.array([[0, 1.2, 0], [0, 0.9, 0]], np.float32), (30, 1, 1)) * [1, 1.5, 1])
    with pytest.raises(MotionError, match="the first joint .Spine. must be the root"):
        read_motion(tmp_path / "a.npy", 20.0, skeleton=Skeleton.load(tmp_path / "s.json"), source_fps=30.0)


@pytest.mark.parametrize(
    "extra, view, framing",
    [
        ("", None, "full"),  # motion alone: the built-in study's camera
        ('[audio]\nfolder = "audio"\n', "front", "auto"),  # speech: a gesture seen from the front (issue 65)
        ('[audio]\nfolder = "audio"\n[render]\nview = "side"\n', "side", "full"),  # what the file says stands
        ('[skeleton]\nsmpl_model = "model.npz"\n', "front", "auto"),  # an SMPL-family body
    ],
)
def test_a_speech_or_gesture_study_is_filmed_from_the_front(tmp_path, extra, view, framing):
    from generation.own_study.study_file import read_study_file

    for sub in ("real", "sys", "audio"):
        (tmp_path / sub).mkdir()
    (tmp_path / "model.npz").write_bytes(b"")
    study = tmp_path / "study.toml"
    study.write_text(f'reference = "real"\n[conditions]\nreal = "real"\nSYS = "sys"\n{extra}')
    spec = read_study_file(study)
    assert (spec.view, spec.framing) == (view, framing)
