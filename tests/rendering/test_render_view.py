"""The study file's [render] table: the view (an azimuth from the body's mean facing), the framing (full, upper,
auto) and the style keys, checked on the camera's projection of a ZeroEGGS-like speaker."""

import numpy as np
import pytest
from helpers.bvh_fixtures import SPEAKER, write_family_study, write_zeroeggs
from helpers.figure_pixels import classes, decode
from helpers.own_study_data import NO_GESTURE_MEASURES
from helpers.paths import TEST_DATA

from generation.data.motion_files import read_motion
from generation.motion.features import rotate_y
from generation.own_study.scene import place
from generation.own_study.study_file import StudyFileError, read_study_file
from moglow_eval.core.skeleton_names import body_root
from rendering.camera import DEFAULT_CAMERA, Projector, camera_targets
from rendering.framing import HEAD_TOP, hips_ancestors, item_camera, leg_joints, mean_facing
from rendering.render import RenderOptions, render_clip


@pytest.fixture(scope="module")
def speaker(tmp_path_factory):
    """(joints [T, J, 3] placed, names, parents) of a ZeroEGGS-like speaker, read with units = "auto"."""
    path = write_zeroeggs(tmp_path_factory.mktemp("z") / "take.bvh", frames=60, turns=SPEAKER, degrees=2.0)
    m = read_motion(path, fps=30.0)
    return place(m.joints, m.names, m.parents).astype(np.float64), list(m.names), np.asarray(m.parents)


def _screen(joints, camera, fps=30.0, root=0):
    """Every joint's position on the frame [T, J, 2], in half-frames from the centre (y up), the camera following
    joint `root`."""
    proj = Projector(camera, 2, 2)
    eye = camera_targets(joints, fps, camera, root) + proj.offset
    cam = proj.to_camera(joints, eye[:, None])
    return cam[..., :2] / cam[..., 2:3] / np.tan(np.radians(camera.fov) / 2)


def test_no_view_keeps_the_fixed_camera_and_front_faces_the_mean_facing(speaker):
    joints, names, parents = speaker
    assert item_camera([joints], names, parents, 30.0).azimuth == DEFAULT_CAMERA.azimuth
    turned = rotate_y(joints, np.radians(30.0))  # the body turned 30 degrees about +Y
    facing = mean_facing([turned], names)
    assert abs(facing - mean_facing([joints], names) - 30.0) < 1.0
    front = item_camera([turned], names, parents, 30.0, view="front")
    assert abs(front.azimuth - facing) < 1e-6
    side = item_camera([turned], names, parents, 30.0, view="side")
    assert abs((side.azimuth - front.azimuth) % 360 - 90.0) < 1e-6
    # front: the left hand is on the frame's right (the body faces the camera), and the hands' depths match
    s = _screen(turned, front)
    assert (s[:, names.index("LeftHand"), 0] > s[:, names.index("RightHand"), 0]).all()


def test_upper_framing_keeps_every_hand_in_frame_and_fills_it(speaker):
    joints, names, parents = speaker
    full = item_camera([joints], names, parents, 30.0, view="front", framing="full")
    upper = item_camera([joints], names, parents, 30.0, view="front", framing="upper")
    legs = set(leg_joints(names, parents))
    assert {names[j] for j in legs} >= {"LeftFoot", "RightUpLeg", "LeftToeBaseEnd"}
    assert not legs & {names.index(n) for n in ("Hips", "LeftHand", "RightHandPinky4", "Head")}
    s = _screen(joints, upper)
    hands = [j for j, n in enumerate(names) if "Hand" in n]
    assert np.abs(s[:, hands]).max() <= 1.0  # every hand and finger joint in every frame
    head, neck = names.index("Head"), names.index("Neck1")
    up = joints[:, head] - joints[:, neck]
    top = joints[:, head] + HEAD_TOP * up / np.linalg.norm(up, axis=1, keepdims=True)  # the drawn head's top
    with_top = np.concatenate([joints, top[:, None]], 1)

    def share(cam):  # from the hips to the drawn head's top, of the frame's height
        s = _screen(with_top, cam)
        return (s[:, -1, 1] - s[:, 0, 1]) / 2

    assert share(upper).min() > 1.5 * share(full).max()  # hips to head far larger than in the full framing
    assert share(upper).min() >= 2 / 3  # in every frame, though the fingertips hang below the hips


def test_upper_framing_leaves_out_a_root_on_the_floor():
    """Bandai-Namco's skeleton hangs the hips under `joint_Root`, a joint on the floor: it is no part of the upper
    body, so the upper framing's frame ends near the hips, not at the floor (the take of tests/data/bvh)."""
    m = read_motion(TEST_DATA / "bvh" / "bandai_dash_normal_001.bvh.gz", fps=30.0)
    names, parents = list(m.names), np.asarray(m.parents)
    joints = place(m.joints, names, parents).astype(np.float64)
    assert hips_ancestors(parents, set(leg_joints(names, parents))) == {names.index("joint_Root")}
    upper = item_camera([joints], names, parents, 30.0, view="front", framing="upper")
    s = _screen(joints, upper, root=body_root(names, parents))
    assert s[:, names.index("joint_Root"), 1].max() < -1.0  # the floor below the frame
    assert np.abs(s[:, [names.index(n) for n in ("Hips", "Head", "Hand_L", "Hand_R")]]).max() <= 1.0


def test_a_body_under_a_root_marker_is_followed_and_framed(tmp_path):
    """Bandai-Namco's `joint_Root` stays at the scene's origin in dataset 2 while a walk goes metres away from it
    (tests/data/bvh's walk). The camera frames and follows the body, not the marker: the cameras are those of the
    walk with the marker under the hips, its video the same bytes wherever the marker is (it is not drawn, and the
    body is drawn when it passes behind the camera), and the figure is in every frame, nearly as large in each."""
    m = read_motion(TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz", fps=30.0)
    names, parents = list(m.names), np.asarray(m.parents)
    hips = names.index("Hips")
    assert np.abs(m.joints[:, 0]).max() == 0.0  # the marker at the origin, as recorded
    joints = place(m.joints[:80], names, parents).astype(np.float64)
    assert body_root(names, parents) == hips
    assert np.linalg.norm(joints[:, hips, [0, 2]] - joints[:, 0, [0, 2]], axis=1).max() > 2.0  # metres apart
    under = joints.copy()
    under[:, 0] = joints[:, hips] * [1.0, 0.0, 1.0]
    for framing in ("full", "upper"):
        camera = item_camera([joints], names, parents, 30.0, framing=framing)
        assert camera == item_camera([under], names, parents, 30.0, framing=framing), framing
    behind = joints.copy()  # the marker behind the camera in every frame
    behind[:, 0] = camera_targets(joints, 30.0, camera, hips) + 1.5 * Projector(camera, 2, 2).offset
    for name, clip in (("origin", joints), ("under", under), ("behind", behind)):
        clip = {"joints": clip, "parents": parents, "joint_names": names, "fps": 30.0}
        render_clip(clip, tmp_path / f"{name}.mp4", RenderOptions(size=96, camera=camera, rate_seed=0, threads=1))
    videos = {(tmp_path / f"{name}.mp4").read_bytes() for name in ("origin", "under", "behind")}
    assert len(videos) == 1
    figure = [sum(c.sum() for c in classes(f)) for f in decode(tmp_path / "origin.mp4")[0]]
    assert min(figure) > 0.5 * max(figure), figure


def test_auto_framing_is_upper_for_a_speaker_and_full_for_a_walker(speaker):
    joints, names, parents = speaker
    upper = item_camera([joints], names, parents, 30.0, view="front", framing="upper")
    assert item_camera([joints], names, parents, 30.0, view="front", framing="auto") == upper
    walker = joints + np.linspace(0, 2.0, len(joints))[:, None, None] * np.array([0, 0, 1.0])
    full = item_camera([walker], names, parents, 30.0, view="front", framing="full")
    assert item_camera([walker], names, parents, 30.0, view="front", framing="auto") == full


@pytest.mark.parametrize(
    "table, needle",
    [
        ('view = "back"', "[render] view: must be front, three-quarter, side or an azimuth"),
        ("view = 400", "[render] view: must be a number from -360 to 360"),
        ('framing = "knees"', "[render] framing: must be full, upper, auto"),
        ('style = "cartoon"', "[render] style: must be"),
        ("style = []", "[render] style: must be"),
        ('camera = "front"', "[render] camera: unknown key"),
        ('aspect = "wide"', '[render] aspect: must be "W:H" (as "3:1") or a number'),
        ('aspect = "3:0"', "[render] aspect: must be"),
        ("aspect = 9", "[render] aspect: must be"),
        ("aspect = true", "[render] aspect: must be"),
    ],
)
def test_bad_render_keys_are_one_line(tmp_path, table, needle):
    study = write_family_study(tmp_path, n_items=2, tables="[render]\n" + table + "\n")
    with pytest.raises(StudyFileError) as e:
        read_study_file(study)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_render_keys_are_read(tmp_path):
    study = write_family_study(tmp_path, n_items=2, tables='[render]\nview = 15\nframing = "auto"\naspect = "16:9"\n')
    spec = read_study_file(study)
    assert (spec.view, spec.framing, spec.styles, spec.aspect) == (15.0, "auto", ["stick"], 16 / 9)
    plain = read_study_file(write_family_study(tmp_path / "plain", n_items=2))
    assert (plain.view, plain.framing, plain.styles, plain.aspect) == (None, "full", ["stick"], 1.0)


@pytest.mark.full  # a study built in two styles and its videos decoded: the full tier (the fast tier stays short)
def test_two_styles_each_clip_its_own_stimulus_on_pixels(tmp_path):
    """A ZeroEGGS-like speaker (75 joints, fingers, cm, 30 fps) built with units = "auto", view = "front",
    framing = "upper" and style = ["stick", "solid"]: every clip in both styles under ids of its own, one video
    size per item, 30 fps, the hands never at the frame's edge, the solid body several times the stick's pixels,
    left and right told apart."""
    import csv

    from helpers.figure_pixels import classes, decode, height_share, touches_edge

    from generation.make_stimuli import main as make_stimuli

    for k in range(2):
        for sub, seed in (("real", k), ("sys_a", 100 + k)):
            (tmp_path / sub).mkdir(exist_ok=True)
            write_zeroeggs(tmp_path / sub / f"item{k:02d}.bvh", frames=45, seed=seed, turns=SPEAKER, degrees=2.0)
    study = tmp_path / "study.toml"
    study.write_text(
        'reference = "speaker"\nseed = 1\nn_training = 0\n[conditions]\nspeaker = "real"\nSYS_A = "sys_a"\n'
        '[catch]\nn = 0\n[skeleton]\nunits = "auto"\n'
        '[render]\nview = "front"\nframing = "upper"\nstyle = ["stick", "solid"]\n' + NO_GESTURE_MEASURES
    )
    out = tmp_path / "out"
    assert make_stimuli(["--study", str(study), "--out", str(out), "--size", "240", "--quiet", "--workers", "1"]) == 0
    rows = list(csv.DictReader(open(out / "manifest.csv")))
    assert sorted(r["style"] for r in rows) == ["solid"] * 4 + ["stick"] * 4
    assert len({r["clip_id"] for r in rows}) == 8
    pixels = {"stick": [], "solid": []}
    for r in rows:
        frames, fps = decode(out / r["video"])
        assert fps == 30.0 and len(frames) == 45
        for f in frames[::5]:
            trunk, left, right = classes(f)
            assert left.sum() > 20 and right.sum() > 20  # both sides, in their own colours
            assert not touches_edge(left) and not touches_edge(right)  # no hand leaves the frame
            assert height_share(f) > (0.7 if r["style"] == "solid" else 0.62)  # the stick's head disc is smaller
            pixels[r["style"]].append(int((trunk | left | right).sum()))
    assert np.mean(pixels["solid"]) > 3 * np.mean(pixels["stick"])
    by_item = {}
    for r in rows:
        by_item.setdefault(r["item"], set()).add((out / r["video"]).stat().st_size)
    assert all(len(sizes) == 1 for sizes in by_item.values())  # blinding: one size per item, across styles


def test_solid_on_a_coarser_grid_keeps_the_body(speaker):
    """The solid body rasterised on a grid of half the frame's resolution (Style.solid_grid = 2) covers the
    full grid's pixels in each colour, but for its edges."""
    from dataclasses import replace

    from helpers.figure_pixels import classes

    from rendering.camera import camera_targets as targets
    from rendering.raster import STYLES, FrameDrawer

    joints, names, parents = speaker
    camera = item_camera([joints], names, parents, 30.0, view="front", framing="upper")
    target = targets(joints, 30.0, camera)[10]
    masks = []
    for grid in (1, 2):
        drawer = FrameDrawer(parents, names, 240, camera, replace(STYLES["solid"], solid_grid=grid))
        drawer.draw(joints[10], target)
        masks.append(classes(drawer.rgb()))
    for fine, coarse in zip(*masks):
        assert fine.sum() > 200 and (fine ^ coarse).sum() < 0.1 * fine.sum()
