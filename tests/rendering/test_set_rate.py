"""The rate of a stimulus set (rendering.encode): a set with a mesh body among its styles encodes every video at the
mesh's higher rate (MESH_RATE_BITS_PER_ROW), one size whatever each video's style; any other set at the default
rate, with the jobs and frame sizes it had. `python -m rendering.reencode` reads the frame budget from the study's own
video, so a video that joins a mesh set comes out that set's size as one that joins a stick set does."""

from types import SimpleNamespace

import pytest
from helpers import smpl_fixtures
from helpers.paths import TEST_DATA

from generation.data.skinning import smpl_mesh
from generation.motion import skeleton
from generation.motion.features import load_take
from generation.own_study.builder import render_settings
from generation.stimuli.build_index import job_key
from rendering import encode
from rendering.blinding import check_one_size
from rendering.mp4_layout import read_layout
from rendering.raster import STYLES
from rendering.reencode import frame_budget, reencode
from rendering.render import RenderOptions, rate_for_set, render_clip

SIZE, FRAMES = 96, 20
WALK = TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz"


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    """(mesh source, clip): the synthetic SMPL-H take, 30 fps."""
    folder = tmp_path_factory.mktemp("rate")
    model, motion, clip = smpl_fixtures.smplh_take(folder, frames=FRAMES)
    return smpl_mesh(motion, model), clip


def walk(fps):
    joints = load_take(WALK, fps)[:FRAMES]
    return dict(joints=joints, parents=skeleton.PARENTS, joint_names=list(skeleton.JOINT_NAMES), fps=fps)


def later_frames(path):
    """The sizes of the frames after the key frame and the one after it (one size: the frame budget)."""
    return set(read_layout(path).sample_sizes[2:])


@pytest.mark.parametrize(
    "styles, mesh", [(["stick"], False), (["solid", "stick"], False), (["mesh"], True), (["stick", "mesh"], True)]
)
def test_a_set_with_a_mesh_body_takes_the_mesh_rate_in_every_job(styles, mesh):
    spec = SimpleNamespace(styles=styles, hide=[], thin="auto")
    rate = rate_for_set([STYLES[s] for s in styles])
    assert rate == (encode.MESH_RATE_BITS_PER_ROW if mesh else None)
    settings = render_settings(spec)
    # A set without a mesh names no rate: its jobs (and so their keys and rate seeds) are what they were.
    assert settings == (dict(hide=(), thin=None, bits_per_row=rate) if mesh else dict(hide=(), thin=None))
    job = ("m.npz", "v.mp4", "s.png", SIZE, "ultrafast", dict(settings, style=STYLES[styles[0]]))
    plain = (*job[:5], {k: v for k, v in job[5].items() if k != "bits_per_row"})
    assert (job_key(job) != job_key(plain)) == mesh  # a rebuild at another rate renders again


def test_a_mesh_set_is_one_size_at_the_higher_budget_and_a_stick_set_keeps_its_own(take, tmp_path):
    source, clip = take
    rate = rate_for_set([STYLES["stick"], STYLES["mesh"]])
    mesh_set = []
    for k, style in enumerate(("mesh", "stick", "mesh")):
        out = tmp_path / f"set_{k}.mp4"
        options = RenderOptions(SIZE, style=STYLES[style], rate_seed=k, threads=1, bits_per_row=rate)
        render_clip(clip, out, options, mesh=source if style == "mesh" else None)
        mesh_set.append(out)
    stick = tmp_path / "stick.mp4"
    render_clip(clip, stick, RenderOptions(SIZE, rate_seed=0, threads=1))
    check_one_size(mesh_set)  # every video of the mesh set one size, the stick one among them
    high, low = encode.frame_bits(SIZE, clip["fps"], rate) // 8, encode.frame_bits(SIZE, clip["fps"]) // 8
    assert high > low
    (frame,) = later_frames(mesh_set[0])
    assert 0 <= frame - high <= 16, (frame, high)
    (frame,) = later_frames(stick)
    assert 0 <= frame - low <= 16, (frame, low)
    sizes = read_layout(mesh_set[0]).sample_sizes
    assert abs(sizes[0] - encode.KEY_FRAME_BUDGET * high) <= 16  # the key frame at its budget of the higher rate


@pytest.mark.parametrize("fps, rate", [(30.0, None), (30.0, encode.MESH_RATE_BITS_PER_ROW), (29.97, None)])
def test_reencode_keeps_the_size_of_the_study_video_at_either_rate(take, tmp_path, fps, rate):
    """The study's video `like` at the set's rate (the mesh's, drawn as the mesh); a submitted video of the same
    frames at a constant quantiser is encoded again to `like`'s frame sizes, read from `like` itself."""
    source, clip = take
    clip = clip if fps == 30.0 else walk(fps)
    style = "mesh" if rate else "stick"
    like, src, out = tmp_path / "like.mp4", tmp_path / "src.mp4", tmp_path / "out.mp4"
    options = RenderOptions(SIZE, style=STYLES[style], rate_seed=1, threads=1, bits_per_row=rate)
    render_clip(clip, like, options, mesh=source if rate else None)
    render_clip(clip, src, RenderOptions(SIZE, qp=20, threads=1))
    sizes = read_layout(like).sample_sizes
    assert frame_budget(sizes, fps) == encode.frame_bits(SIZE, fps, rate)
    reencode(src, out, like, seed=7)
    assert read_layout(out).sample_sizes == sizes
    check_one_size([like, out])
