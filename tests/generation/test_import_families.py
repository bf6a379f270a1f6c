"""Importing the field's skeletons for a study of your own motion: units from the standing body's height, the
naming families people bring (CMU, Mixamo, ZeroEGGS/BEAT, GENEA/Talking With Hands, LaFAN1, Bandai-Namco),
SMPL-family parameter files through smplx and a synthetic body model, and the study's frame rate.

Every fixture is written here (tests/helpers/bvh_fixtures.py, smpl_fixtures.py): the fast tier."""

import csv
import zipfile

import numpy as np
import pytest
from helpers import smpl_fixtures
from helpers.bvh_fixtures import CMU_UNIT, FAMILIES, write_family, write_family_study, write_zeroeggs
from helpers.cli import fails_with
from helpers.own_study_data import NO_GESTURE_MEASURES
from helpers.paths import TEST_DATA

from generation.data.motion_files import MotionError, read_motion
from generation.data.skeleton_families import family
from generation.data.smpl_files import JOINT_NAMES, smpl_positions
from generation.make_stimuli import main as make_stimuli
from generation.own_study.inputs import with_study_fps
from generation.own_study.study_file import read_study_file
from moglow_eval.core.cli import UserError

FAMILY_NAMES = {
    "cmu": "CMU",
    "mixamo": "Mixamo",
    "zeroeggs": "ZeroEGGS/BEAT",
    "genea": "GENEA 2022/2023 (Talking With Hands)",
    "lafan1": "LaFAN1",
    "bandai": "Bandai-Namco",
}


def _rows(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _fails(argv, capsys, needle):
    return fails_with(make_stimuli, argv, capsys, needle)


# ---------------------------------------------------------------- units with units = "auto"
@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_each_family_is_named_and_read_in_metres(tmp_path, name):
    path, names, per_metre = write_family(tmp_path / f"{name}.bvh", name)
    assert family(names).name == FAMILY_NAMES[name]
    auto = read_motion(path, 30.0)
    given = read_motion(path, 30.0, units=1.0 / per_metre)
    assert np.allclose(auto.joints, given.joints, atol=1e-5)
    height = np.median(auto.joints[..., 1].max(1) - auto.joints[..., 1].min(1))
    assert 1.6 < height < 1.8


def test_a_bandai_walk_is_read_upright_in_centimetres_whatever_its_root_marker():
    """A real Bandai-Namco walk (tests/data/bvh): its `joint_Root` stays at the scene's origin while the body walks
    metres away, so counted as part of the body it made the body deeper than tall (Z taken for up, no unit giving a
    person). Measured without it, the file is read as it is written: Y up, centimetres, the same joints as with
    both given."""
    walk = TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz"
    auto = read_motion(walk, 30.0)
    given = read_motion(walk, 30.0, units="cm", up="y")
    assert np.array_equal(auto.joints, given.joints)
    root = auto.names.index("joint_Root")
    assert np.ptp(auto.joints[:, root], axis=0).max() == 0  # the marker never moves...
    assert np.ptp(auto.joints[:, auto.names.index("Hips")], axis=0).max() > 1.0  # ...while the body walks
    height = np.median(auto.joints[..., 1].max(1) - auto.joints[..., 1].min(1))
    assert 1.2 < height < 1.9


def test_zeroeggs_fixture_is_the_reported_take(tmp_path):
    """75 joints with fingers, centimetres, 30 fps, and every joint name of the old CMU rule."""
    path = write_zeroeggs(tmp_path / "take.bvh")
    m = read_motion(path, 30.0)
    assert len(m.names) == 75 and sum("Index" in n for n in m.names) == 8
    assert {"Hips", "LeftUpLeg", "RightUpLeg", "LeftArm", "RightArm", "Spine1"} <= set(m.names)
    assert "Frame Time: 0.03333333" in path.read_text()
    assert 1.6 < m.joints[..., 1].max() < 1.8  # centimetres, not CMU units (which gave a body 9.7 m tall)


def test_a_family_unit_that_gives_no_person_is_passed_over(tmp_path):
    """A CMU-named skeleton written in centimetres: CMU's own unit makes it 9.8 m tall, so centimetres win."""
    path, _, _ = write_family(tmp_path / "cmu_cm.bvh", "cmu", units_per_metre=100.0)
    assert 1.5 < read_motion(path, 30.0).joints[..., 1].max() < 1.8
    path, _, _ = write_family(tmp_path / "zeggs_in_cmu_units.bvh", "zeroeggs", units_per_metre=1 / CMU_UNIT)
    assert 1.5 < read_motion(path, 30.0).joints[..., 1].max() < 1.8


@pytest.mark.parametrize("units, scale", [("inches", 1 / 0.0254), ("m", 1.0), ("mm", 1000.0)])
def test_other_units_are_found(tmp_path, units, scale):
    path, _, _ = write_family(tmp_path / "b.bvh", "lafan1", units_per_metre=scale)
    assert 1.5 < read_motion(path, 30.0).joints[..., 1].max() < 1.8


def test_no_unit_gives_a_person_names_the_skeleton_and_each_try(tmp_path, capsys):
    study = write_family_study(tmp_path / "s", "zeroeggs", n_items=2)
    for f in (study.parent / "real").iterdir():  # a body 17 units tall: no unit makes a person of it
        write_family(f, "zeroeggs", 45, 30.0, 0, units_per_metre=10.0)
    line = _fails(["--study", str(study), "--out", str(tmp_path / "out"), "--quiet"], capsys, "item00.bvh")
    for needle in ("ZeroEGGS/BEAT skeleton", "cm gives 0.17", "m gives 17", "inches gives 0.4", "set [skeleton] units"):
        assert needle in line
    assert not (tmp_path / "out" / "manifest.csv").exists()


def test_units_in_the_study_file_still_rule(tmp_path):
    path = write_zeroeggs(tmp_path / "take.bvh")
    assert 1.6 < read_motion(path, 30.0, units="cm").joints[..., 1].max() < 1.8
    with pytest.raises(MotionError, match="the body is .* m tall after unit conversion"):
        read_motion(path, 30.0, units="m")


# ---------------------------------------------------------------- the study's frame rate
@pytest.mark.full  # a study built: the full tier (the fast tier stays short)
def test_a_study_keeps_the_reference_frame_rate(tmp_path):
    study = write_family_study(tmp_path / "s", "zeroeggs", n_items=3, frames=45, fps=30.0, tables=NO_GESTURE_MEASURES)
    assert make_stimuli(["--study", str(study), "--out", str(tmp_path / "out"), "--size", "64", "--quiet"]) == 0
    assert {r["fps"] for r in _rows(tmp_path / "out" / "manifest.csv")} == {"30"}
    assert {r["fps"] for r in _rows(tmp_path / "out" / "items.csv")} == {"30"}
    assert {r["frames"] for r in _rows(tmp_path / "out" / "manifest.csv") if r["role"] == "test"} == {"45"}


def test_fps_in_the_study_file_overrides_and_fast_capture_is_capped(tmp_path):
    study = write_family_study(tmp_path / "a", "lafan1", n_items=2, fps=30.0, top="fps = 20")
    spec = read_study_file(study)
    from generation.own_study.inputs import match_items

    assert with_study_fps(spec, match_items(spec)[0]).fps == 20
    study = write_family_study(tmp_path / "b", "lafan1", n_items=2, frames=240, fps=120.0)
    spec = read_study_file(study)
    assert spec.fps is None and with_study_fps(spec, match_items(spec)[0]).fps == 60
    study = write_family_study(tmp_path / "c", "bandai", n_items=2, frames=60, fps=25.0)
    spec = read_study_file(study)
    assert with_study_fps(spec, match_items(spec)[0]).fps == 25


# ---------------------------------------------------------------- SMPL-family parameter files
@pytest.mark.parametrize("kind, width", [("smpl", 72), ("smplh", 156), ("smplx", 165)])
def test_smpl_family_files_become_joints(tmp_path, kind, width):
    model = smpl_fixtures.write_model(tmp_path / f"{kind.upper()}_NEUTRAL.npz", kind)
    motion = smpl_fixtures.write_motion(tmp_path / "take.npz", kind, frames=60, fps=30.0)
    assert np.load(motion)["poses"].shape == (60, width)
    m = read_motion(motion, 30.0, smpl_model=model)
    assert m.names == JOINT_NAMES[kind] and m.joints.shape == (60, len(JOINT_NAMES[kind]), 3)
    assert m.names[:3] == ["pelvis", "left_hip", "right_hip"] and m.names[-1] == "right_thumb3" or kind == "smpl"
    assert 1.4 < np.median(m.joints[..., 1].max(1) - m.joints[..., 1].min(1)) < 1.7  # metres, Y up
    bones = np.linalg.norm(m.joints[:, 1:] - m.joints[:, m.parents[1:]], axis=-1)
    assert np.allclose(bones, bones[:1], atol=1e-5)  # rigid: the kinematics rotate, never stretch
    half = read_motion(motion, 15.0, smpl_model=model)  # resampled to the study's rate
    assert len(half.joints) == 30 and np.allclose(half.joints[1], m.joints[2], atol=1e-5)


def test_smpl_joints_are_what_smplx_forward_gives(tmp_path):
    """The joints match smplx's own SMPL forward pass (its first 24 joints) on a model of the real vertex count."""
    import contextlib
    import io

    import smplx
    import torch
    from smplx.utils import Struct

    arrays = smpl_fixtures.model_arrays("smpl", n_vertices=6890)  # smplx picks extra joints from vertices up to 6787
    np.savez(tmp_path / "model.npz", **arrays)
    mot = smpl_fixtures.motion_arrays("smpl", frames=6)
    np.savez(tmp_path / "take.npz", **mot)
    ours, names, parents, fps = smpl_positions(tmp_path / "take.npz", tmp_path / "model.npz")
    with contextlib.redirect_stdout(io.StringIO()):  # smplx prints a warning for a model of 10 shape components
        model = smplx.SMPL(model_path=str(tmp_path), data_struct=Struct(**arrays), num_betas=10, batch_size=6)
    p = torch.tensor(mot["poses"], dtype=torch.float32)
    betas = torch.tensor(np.repeat(mot["betas"][None], 6, 0), dtype=torch.float32)
    out = model(betas=betas, global_orient=p[:, :3], body_pose=p[:, 3:], transl=torch.tensor(mot["trans"]).float())
    assert np.abs(out.joints[:, :24].detach().numpy() - ours).max() < 1e-5
    assert fps == 30.0 and np.array_equal(parents, smpl_fixtures.SMPL_PARENTS)


def test_an_smpl_file_without_its_model_says_where_to_get_one(tmp_path, capsys):
    smpl_fixtures.write_motion(tmp_path / "take.npz", "smplx")
    with pytest.raises(MotionError) as e:
        read_motion(tmp_path / "take.npz", 30.0)
    line = str(e.value)
    assert "\n" not in line and "take.npz: an SMPL-family parameter file" in line
    for needle in ("licensed and not shipped", "smpl-x.is.tue.mpg.de", "smpl.is.tue.mpg.de", "smpl_model"):
        assert needle in line


@pytest.mark.full  # a study built: the full tier (the fast tier stays short)
def test_an_smpl_study_builds_with_the_model_named_in_the_study_file(tmp_path, capsys):
    root = tmp_path / "s"
    for sub, seed in (("real", 0), ("sys", 1)):
        (root / sub).mkdir(parents=True)
        for k in range(3):
            smpl_fixtures.write_motion(root / sub / f"i{k}.npz", "smplx", frames=40, fps=30.0, seed=seed + 10 * k)
    (root / "models").mkdir()
    smpl_fixtures.write_model(root / "models" / "SMPLX_NEUTRAL.npz", "smplx")
    text = 'reference = "real"\nn_training = 1\n[conditions]\nreal = "real"\nSYS = "sys"\n[catch]\nn = 1\n'
    (root / "study.toml").write_text(text)
    _fails(["--study", str(root / "study.toml"), "--out", str(tmp_path / "o"), "--quiet"], capsys, "smpl-x.is.tue.mpg")
    (root / "study.toml").write_text(
        text + '[skeleton]\nsmpl_model = "models/SMPLX_NEUTRAL.npz"\nsmpl_type = "smplx"\n' + NO_GESTURE_MEASURES
    )
    assert (
        make_stimuli(["--study", str(root / "study.toml"), "--out", str(tmp_path / "o"), "--size", "64", "--quiet"])
        == 0
    )
    rows = _rows(tmp_path / "o" / "manifest.csv")
    assert {r["fps"] for r in rows} == {"30"} and {r["condition"] for r in rows} == {"NAT", "SYS", "BAD"}


def test_smpl_model_mismatches_and_bad_trees_are_one_line(tmp_path):
    model = smpl_fixtures.write_model(tmp_path / "SMPLH.npz", "smplh")
    motion = smpl_fixtures.write_motion(tmp_path / "take.npz", "smplx")
    with pytest.raises(MotionError, match="'poses' has 165 values a frame, but the smplh model .* has 52 joints"):
        read_motion(motion, 30.0, smpl_model=model)
    with pytest.raises(MotionError, match="52 joints in 'kintree_table', but an smplx model has 55"):
        read_motion(motion, 30.0, smpl_model=model, smpl_type="smplx")
    arrays = smpl_fixtures.model_arrays("smplx")
    arrays["kintree_table"][0, 29] = 30  # 29 -> 30 -> 29 (30's parent is 29): a cycle
    np.savez(tmp_path / "loop.npz", **arrays)
    with pytest.raises(MotionError, match="not a tree.*cycle"):
        read_motion(motion, 30.0, smpl_model=tmp_path / "loop.npz")
    del arrays["posedirs"]
    np.savez(tmp_path / "partial.npz", **arrays)
    with pytest.raises(MotionError, match="a body model without 'posedirs'"):
        read_motion(motion, 30.0, smpl_model=tmp_path / "partial.npz")


def test_an_smpl_file_of_absurd_length_is_refused_before_reading(tmp_path):
    """poses whose header claims a billion frames, in a file of a few hundred bytes: refused from the header."""
    model = smpl_fixtures.write_model(tmp_path / "m.npz", "smplx")
    path = tmp_path / "huge.npz"
    with zipfile.ZipFile(path, "w") as z:
        for name, shape in (("poses", (10**9, 165)), ("trans", (10**9, 3)), ("betas", (10,))):
            z.writestr(f"{name}.npy", _npy_header(shape) + b"\0" * 64)
    with pytest.raises((MotionError, UserError), match="huge.npz: .*(limit|frames)"):
        read_motion(path, 30.0, smpl_model=model)


def _npy_header(shape, dtype="<f8"):
    import io

    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, dict(descr=dtype, fortran_order=False, shape=shape))
    return buf.getvalue()  # the magic string and the header, no data


def test_the_hands_rest_pose_follows_the_files_layout(tmp_path):
    """BEAT2's files (mocap_frame_rate) are read as its loaders call smplx (flat_hand_mean=False: the model's mean
    hand pose added to the stored rotations), AMASS's (mocap_framerate) as stored; `hand_mean` overrides either."""
    model = smpl_fixtures.write_model(tmp_path / "SMPLH.npz", "smplh")
    arrays = smpl_fixtures.motion_arrays("smplh", frames=20)
    beat2 = dict(arrays)
    amass = {k: v for k, v in arrays.items() if k != "mocap_frame_rate"} | {"mocap_framerate": np.float64(30.0)}
    np.savez(tmp_path / "beat2.npz", **beat2)
    np.savez(tmp_path / "amass.npz", **amass)
    mean = np.concatenate([np.load(model)["hands_meanl"], np.load(model)["hands_meanr"]])
    added = dict(amass, poses=arrays["poses"].copy())
    added["poses"][:, 66:156] += mean
    np.savez(tmp_path / "added.npz", **added)
    j_beat2, j_amass, j_added = (smpl_positions(tmp_path / f"{n}.npz", model)[0] for n in ("beat2", "amass", "added"))
    fingers = slice(22, 52)
    assert np.allclose(j_beat2, j_added, atol=1e-9) and np.abs(j_beat2 - j_amass)[:, fingers].max() > 1e-3
    assert np.allclose(j_beat2[:, :22], j_amass[:, :22])  # the body is the same; the fingers differ
    assert np.allclose(smpl_positions(tmp_path / "beat2.npz", model, hand_mean=False)[0], j_amass)


def test_smplx_expressions_shape_the_heads_rest_joints(tmp_path):
    """An SMPL-X file's expression coefficients move the rest joints as smplx's forward pass does: the shape
    directions after the body's (10 of 20 here) times each frame's coefficients."""
    arrays = smpl_fixtures.model_arrays("smplx", n_betas=20)
    np.savez(tmp_path / "SMPLX.npz", **arrays)
    motion = smpl_fixtures.motion_arrays("smplx", frames=6)
    motion["poses"][:] = 0.0
    motion["trans"][:] = 0.0
    expr = np.random.default_rng(3).normal(0, 1, (6, 10))
    np.savez(tmp_path / "plain.npz", **motion)
    np.savez(tmp_path / "face.npz", **motion, expressions=expr)
    plain = smpl_positions(tmp_path / "plain.npz", tmp_path / "SMPLX.npz", hand_mean=False)[0]
    face = smpl_positions(tmp_path / "face.npz", tmp_path / "SMPLX.npz", hand_mean=False)[0]
    dirs = arrays["shapedirs"].astype(np.float64)
    shape = arrays["v_template"] + dirs[:, :, :10] @ motion["betas"]
    n = face.shape[1]
    for t in range(6):  # at zero pose every joint is its rest joint, the regressor's vertex
        want = (shape + dirs[:, :, 10:20] @ expr[t])[:n]
        assert np.allclose(face[t], want, atol=1e-6)
    assert np.abs(face - plain).max() > 1e-3


FPS_VALUES = {"empty": np.zeros(0), "two": np.array([30.0, 30.0]), "complex": np.array(30 + 1j), "text": np.array("30")}


@pytest.mark.parametrize("kind", FPS_VALUES)
def test_a_clip_whose_fps_is_not_one_real_number_is_refused_naming_it(tmp_path, kind):
    """A clip's fps key that is empty, several numbers, complex or text: one line naming the file and the key, before
    any frame is read (it was an IndexError from the empty one, a warning and the real part from the complex one)."""
    from generation.data.motion_files import native_fps

    path = tmp_path / "item00.npz"
    joints = np.zeros((4, 2, 3), np.float32)
    np.savez(
        path, joints=joints, parents=np.array([-1, 0]), joint_names=np.array(["Hips", "Spine"]), fps=FPS_VALUES[kind]
    )
    with pytest.raises(MotionError, match=r"item00\.npz: fps must be one real number"):
        native_fps(path)
