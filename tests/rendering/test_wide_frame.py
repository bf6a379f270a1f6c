"""Two people in a wide frame, and every body inside the frame (rendering.framing's pair and upper cameras, fitted to
what is drawn around the joints: the stick's head, the mesh's surface; rendering.render's wide frame). The bodies
are synthetic SMPL-H takes (tests/helpers/smpl_fixtures.py) through a body model whose fingers go on beyond their
last joints and whose head reaches above the head joint by more than HEAD_TOP, as a real body's do: the fast tier."""

import numpy as np
import pytest
from helpers import figure_pixels, smpl_fixtures

from generation.data.skinning import surface_reach
from generation.data.smpl_files import smpl_positions
from generation.own_study.placing import place_pair
from generation.own_study.scene import place
from generation.stimuli.mesh_track import MeshSpec, track
from rendering.camera import Projector, camera_targets
from rendering.framing import HEAD_TOP, PAIR_ASPECT, item_camera, pair_camera, steady
from rendering.raster import STYLES, FrameDrawer, one_colour, yuv_to_rgb
from rendering.render import RenderOptions, compose, frame_width, render_clip

FPS, FRAMES, SIZE = 30.0, 12, 160
TIPS, HEAD = 0.03, (0.08, 0.14)  # fingertips 3 cm beyond the last finger joints; the head's top 22 cm above its joint


def _take(path, lowered):
    return smpl_fixtures.write_arms_take(path, lowered, FPS)


@pytest.fixture(scope="module")
def bodies(tmp_path_factory):
    folder = tmp_path_factory.mktemp("wide")
    model = smpl_fixtures.write_body_model(folder / "SMPLH_NEUTRAL.npz", "smplh", tips=TIPS, head=HEAD)
    wave = np.sin(np.linspace(0, 2 * np.pi, FRAMES))
    files = {
        # Spread wide (the wrists 1.2 m apart), then raised above the shoulders and lowered again.
        "spread": _take(folder / "spread.npz", 0.55 - 0.7 * (1 - np.cos(np.linspace(0, 2 * np.pi, FRAMES)))),
        "calm": _take(folder / "calm.npz", 1.2 + 0.1 * wave),
        "calmer": _take(folder / "calmer.npz", 1.2 + 0.05 * wave),  # inside the calm take's reach
    }
    out = {"model": model, "folder": folder, "reach": surface_reach(model, "smplh", np.zeros(10))}
    for name, path in files.items():
        joints, names, parents, _ = smpl_positions(path, model)
        out[name] = dict(path=path, joints=joints, names=list(names), parents=np.asarray(parents))
    return out


def _clip(joints, take):
    return dict(joints=joints, parents=take["parents"], joint_names=take["names"], fps=FPS)


def _mesh(bodies, take, joints):
    return track(MeshSpec(str(take["path"]), str(bodies["model"]), "smplh", "mask", joints, FPS))


def _pair(bodies, agent, partner, reach=True):
    """(agent's joints, partner's joints, camera, target) of two takes placed face to face, the camera of the wide
    frame two people are filmed in."""
    a, p = bodies[agent], bodies[partner]
    placed, other = place_pair([a["joints"]], a["names"], p["joints"], p["names"])
    people = [(a["names"], a["parents"], None), (p["names"], p["parents"], other)]
    around = (bodies["reach"], bodies["reach"]) if reach else (None, None)
    camera, target = pair_camera(placed, people, aspect=PAIR_ASPECT, reach=around)
    return placed[0], other, camera, target


def _top_rows(masks):
    """The highest row of each mask, or None where it is empty."""
    return [int(np.flatnonzero(m.any(1))[0]) if m.any() else None for m in masks]


def _pelvis_row(camera, target, joints, width):
    proj = Projector(camera, width, SIZE)
    return SIZE - proj.to_screen(proj.to_camera(joints[0], target + proj.offset))[1]


def test_each_of_two_people_in_the_wide_frame_is_as_tall_as_one_person_in_an_upper_frame(bodies):
    """In pixels of height, from the pelvis to the top of the drawn head, each of two people (the same calm take
    twice) in the wide frame of a given height is as tall as that take alone in a square upper frame of that height,
    and the frame is 3:1 (GENEA 2026's 1536x512 at 512)."""
    take = bodies["calm"]
    alone = place(take["joints"], take["names"], take["parents"]).astype(np.float64)
    camera = steady(item_camera([alone], take["names"], take["parents"], FPS, view="front", framing="upper"))
    drawer = FrameDrawer(take["parents"], take["names"], SIZE, camera)
    targets = camera_targets(alone, FPS, camera)
    single = []
    for t in range(0, FRAMES, 3):
        rgb = yuv_to_rgb(drawer.draw(alone[t], targets[t]), SIZE)
        single.append(_pelvis_row(camera, targets[t], alone[t], SIZE) - _top_rows([figure_pixels.agent(rgb)])[0])
    agent, partner, camera, target = _pair(bodies, "calm", "calm", reach=False)  # a stick figure's camera
    width = frame_width(SIZE, PAIR_ASPECT)
    assert (width, SIZE) == (3 * SIZE, SIZE)
    first = FrameDrawer(take["parents"], take["names"], (width, SIZE), camera)
    second = FrameDrawer(take["parents"], take["names"], (width, SIZE), camera, one_colour(STYLES["stick"]),
                         frame=first.frame)  # fmt: skip
    people = [(first, agent), (second, partner)]
    for k, t in enumerate(range(0, FRAMES, 3)):
        rgb = yuv_to_rgb(compose(people, t, target), (width, SIZE))
        tops = _top_rows([figure_pixels.agent(rgb), figure_pixels.partner(rgb)])
        for joints, top in zip((agent, partner), tops):
            tall = _pelvis_row(camera, target, joints[t], width) - top
            assert tall >= 0.95 * single[k], (t, tall, single[k])  # was 0.7 of it in a square frame


def _edge_free(frames, width):
    """Assert that no body's pixel (the agent's colours, the partner's green) lies on the frame's left, right or top
    edge in any frame, and return the fewest pixels left free between the bodies and the top edge, and between them
    and a side edge, over the frames (a frame fitted to them leaves few)."""
    top, side = [], []
    for t, rgb in enumerate(frames):
        assert rgb.shape[:2] == (SIZE, width)
        body = figure_pixels.agent(rgb) | figure_pixels.partner(rgb)
        assert not figure_pixels.touches_edge(body, border=1), t
        cols = np.flatnonzero(body.any(0))
        top.append(_top_rows([body])[0])
        side.append(min(cols[0], width - 1 - cols[-1]))
    return min(top), min(side)


@pytest.mark.parametrize("style", ["stick", "mesh"])
def test_two_people_with_arms_spread_stay_inside_the_wide_frame(bodies, tmp_path, style):
    """Both people spread their arms wide and raise them: every fingertip, the mesh's surface and the drawn head stay
    inside the encoded video's frame in every frame, and the bodies still fill it from the top."""
    agent, partner, camera, target = _pair(bodies, "spread", "spread")
    take = bodies["spread"]
    options = RenderOptions(SIZE, camera, STYLES[style], one_colour(STYLES[style]), tuple(target), rate_seed=0,
                            aspect=PAIR_ASPECT)  # fmt: skip
    meshes = {}
    if style == "mesh":
        meshes = dict(mesh=_mesh(bodies, take, agent), partner_mesh=_mesh(bodies, take, partner))
    render_clip(_clip(agent, take), tmp_path / "pair.mp4", options, partner=_clip(partner, take), **meshes)
    frames, _ = figure_pixels.decode(tmp_path / "pair.mp4")
    assert len(frames) == FRAMES
    assert _edge_free(frames, 3 * SIZE)[0] <= 0.08 * SIZE  # the raised hands fill the frame's top


@pytest.mark.parametrize("take", ["spread", "calm"])
@pytest.mark.parametrize("style", ["stick", "solid", "mesh"])
def test_one_person_stays_inside_the_upper_frame(bodies, tmp_path, style, take):
    """One person from the front, from the hips up: the spread arms' fingertips (the mesh's beyond the last finger
    joint) and the top of the head (the mesh's above HEAD_TOP, the neck bent) stay inside the frame."""
    m = bodies[take]
    joints = place(m["joints"], m["names"], m["parents"]).astype(np.float64)
    reach = bodies["reach"] if style == "mesh" else None
    assert reach is None or reach.max() > HEAD_TOP  # the mesh's head reaches further than the stick's
    camera = item_camera([joints], m["names"], m["parents"], FPS, view="front", framing="upper", reach=reach)
    meshes = dict(mesh=_mesh(bodies, m, joints)) if style == "mesh" else {}
    options = RenderOptions(SIZE, camera=camera, style=STYLES[style], rate_seed=0)
    render_clip(_clip(joints, m), tmp_path / "one.mp4", options, **meshes)
    frames, _ = figure_pixels.decode(tmp_path / "one.mp4")
    assert min(_edge_free(frames, SIZE)) <= 0.12 * SIZE  # and it fills the frame, across or down


def test_a_system_inside_the_frame_leaves_the_pair_camera_as_it_was(bodies):
    """The pair camera takes its view and look-at point from the reference's clips and is held to steps (as one
    person's, framing.steady): a system whose body stays inside the frame (the reference's motion, its arms
    swinging less) changes neither, so no video of the others is drawn again; one that reaches further
    (the arms spread) moves the camera back."""
    a, p = bodies["calm"], bodies["calm"]
    joints, smaller, wider = a["joints"], bodies["calmer"]["joints"], bodies["spread"]["joints"]

    def camera(clips):
        placed, other = place_pair(clips, a["names"], p["joints"], p["names"])
        people = [(a["names"], a["parents"], None), (p["names"], p["parents"], other)]
        cam, target = pair_camera(placed, people, aspect=PAIR_ASPECT, facing=placed[:1])
        return cam, tuple(target)

    alone = camera([joints])
    assert camera([joints, smaller]) == alone
    moved = camera([joints, wider])
    assert moved[0].distance > alone[0].distance
