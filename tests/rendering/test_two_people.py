"""Two people in one video (rendering.render with a partner, rendering.framing.pair_camera,
generation.own_study.placing), captions burned in (rendering.captions) and two voices mixed
(rendering.audio.mix_voices): pixels of decoded videos and samples of real sound. The people are a conversation in
Seamless Interaction's layout that the test writes (tests/helpers/seamless_fixtures.py) read through a synthetic
SMPL-H model: the fast tier."""

import numpy as np
import pytest
from helpers import figure_pixels, seamless_fixtures

from generation.data.motion_files import read_motion
from generation.data.transcripts import read_transcript
from generation.own_study.placing import place_pair
from rendering.audio import RATE, integrated_loudness, mix_voices
from rendering.blinding import check_one_size
from rendering.camera import Projector
from rendering.captions import ROOM, CaptionLayer, phrases
from rendering.framing import pair_camera
from rendering.raster import STYLES, FrameDrawer, one_colour
from rendering.render import RenderOptions, compose, render_clip

SIZE, START, FRAMES = 320, 135, 90  # frames 135..225 at 30 fps: the second person speaks, the first listens


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    conv = seamless_fixtures.write_conversation(tmp_path_factory.mktemp("pair") / "raw")
    a, b = (read_motion(conv.files[p]["motion"], 30.0, smpl_model=conv.model) for p in seamless_fixtures.PARTICIPANTS)
    agent, partner = a.joints[START : START + FRAMES], b.joints[START : START + FRAMES]
    other = a.joints[START + 180 : START + 180 + FRAMES]  # the agent's motion from elsewhere: another condition
    (agents, placed) = place_pair([agent, other], a.names, partner, b.names)
    cam, target = pair_camera(agents, [(a.names, a.parents, None), (b.names, b.parents, placed)], room=ROOM)
    words = []
    for who, p in enumerate(seamless_fixtures.PARTICIPANTS):
        t = read_transcript(conv.files[p]["transcript"]).cut(START / 30, (START + FRAMES) / 30)
        words += phrases([(w.start, w.end, w.text, w.text == "river") for w in t.words], SIZE, who)
    return dict(conv=conv, a=a, b=b, agents=agents, partner=placed, camera=cam, target=target, captions=words)


def _clip(joints, m):
    return dict(joints=joints, parents=m.parents, joint_names=m.names, fps=30.0)


def _render(pair, k, out, style="stick", captions=True):
    # A fixed share of the rate per frame: the same bytes on every run, so no check rests on one lucky lossy frame.
    options = RenderOptions(SIZE, pair["camera"], STYLES[style], target=pair["target"], rate_seed=0)
    render_clip(
        _clip(pair["agents"][k], pair["a"]), out, options, partner=_clip(pair["partner"], pair["b"]),
        captions=pair["captions"] if captions else None,
    )  # fmt: skip
    return figure_pixels.decode(out)[0]


def test_placing_faces_the_two_towards_each_other_whatever_their_files_say(pair):
    """The second person is stored Y down and metres away, facing as the first: placed, they stand on one floor,
    1.4 m apart, each facing the other (opened a little towards the camera's side)."""
    from rendering.framing import mean_facing

    agent, partner = pair["agents"][0], pair["partner"]
    a, b = agent[:, 0, [0, 2]].mean(0), partner[:, 0, [0, 2]].mean(0)
    assert np.linalg.norm(a - b) == pytest.approx(1.4, abs=1e-3)
    assert (
        np.median(agent[..., 1].min(1)) == pytest.approx(0, abs=1e-3) and abs(np.median(partner[..., 1].min(1))) < 1e-3
    )
    to_partner = np.degrees(np.arctan2(*(b - a)))
    assert abs((mean_facing([agent], pair["a"].names) - to_partner + 180) % 360 - 180) < 30
    assert abs((mean_facing([partner], pair["b"].names) - to_partner - 180 + 180) % 360 - 180) < 30


@pytest.mark.parametrize("placement", ["facing", "recorded"])
def test_two_bodies_under_root_markers_are_placed_by_their_hips(placement):
    """Bandai-Namco's `joint_Root` stays at the scene's origin in dataset 2 while the body walks away
    (tests/data/bvh's walk): two such people are placed by their bodies' roots, the hips
    (core.skeleton_names.body_root), their mean hips 1.4 m apart (facing) or as far apart as recorded, on the line
    along X through the origin; not by the markers, which sit metres from the bodies."""
    from helpers.paths import TEST_DATA

    from generation.own_study.placing import DISTANCE
    from moglow_eval.core.skeleton_names import body_root

    m = read_motion(TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz", 30.0)
    names, parents = list(m.names), np.asarray(m.parents)
    hips = body_root(names, parents)
    agent = m.joints[:120]
    assert np.abs(agent[:, 0]).max() == 0.0  # the marker at the origin, as recorded
    partner = m.joints[120:240][::-1] + np.array([3.0, 0.0, 1.0], np.float32)  # its own way, 3 m along, 1 m across
    partner[:, 0] = 0.0
    (placed,), other = place_pair([agent], names, partner, names, placement, roots=(hips, hips))
    a, b = placed[:, hips, [0, 2]].mean(0), other[:, hips, [0, 2]].mean(0)
    apart = (
        DISTANCE
        if placement == "facing"
        else np.linalg.norm(agent[:, hips, [0, 2]].mean(0) - partner[:, hips, [0, 2]].mean(0))
    )
    assert np.linalg.norm(a - b) == pytest.approx(apart, abs=1e-3)
    assert a[1] == pytest.approx(0, abs=1e-3) and b[1] == pytest.approx(0, abs=1e-3)  # on the line along X
    assert a[0] == pytest.approx(-b[0], abs=1e-3)  # either side of the origin
    assert np.linalg.norm(placed[:, 0, [0, 2]].mean(0) - a) > 1.0  # the marker elsewhere


@pytest.mark.parametrize("style", ["stick", "solid"])
def test_two_figures_the_partner_the_same_in_both_videos(pair, tmp_path, style):
    first = _render(pair, 0, tmp_path / "a.mp4", style)
    second = _render(pair, 1, tmp_path / "b.mp4", style)
    assert check_one_size([tmp_path / "a.mp4", tmp_path / "b.mp4"])  # one byte size, boxes and frame sizes
    # The same partner in both, less the encoder's noise at its edges. Each clip draws its own random rate per
    # frame (rendering.encode.rate_dither), so one frame of a thin stick figure can lose a sixth of its pixels to
    # the colour test (0.83 seen); the mean over the clip stays above 0.91 (six pairs of seeds), and the exact
    # pixels before encoding are test_the_partner_and_the_captions_are_the_same_pixels_whatever_the_agent_does's.
    near = figure_pixels.partner_near(first, second, range(0, 84, 6))
    assert np.mean(near) > 0.88, near
    for t in (10, 45, 80):
        agent, partner = figure_pixels.agent(first[t]), figure_pixels.partner(first[t])
        assert agent.sum() > 150 and partner.sum() > 150, t  # two figures
        cols = lambda m: np.nonzero(m)[1].mean()  # noqa: E731
        assert abs(cols(agent) - cols(partner)) > 0.12 * SIZE  # side by side, not one over the other
        other = figure_pixels.partner(second[t])
        both = partner & other
        assert (
            np.abs(first[t][both].astype(int).mean(0) - second[t][both].astype(int).mean(0)).max() < 6
        )  # the encoder's noise, not another colour (35 and more)
        assert np.abs(first[t][both].astype(int).mean(0) - np.array([102, 153, 112])).max() < 35  # its one colour
        assert (
            np.abs(first[t][agent].astype(int).mean(0) - second[t][figure_pixels.agent(second[t])].mean(0)).max() < 40
        )


def test_the_pair_camera_frames_both_and_keeps_the_captions_room_free(pair):
    cam, target = pair["camera"], pair["target"]
    proj = Projector(cam, SIZE, SIZE)
    keep = [j for j, n in enumerate(pair["a"].names) if n not in ("left_knee", "right_knee", "left_ankle",
            "right_ankle", "left_foot", "right_foot", "left_hip", "right_hip", "pelvis")]  # fmt: skip
    for joints in (*pair["agents"], pair["partner"]):
        xy = proj.to_screen(proj.to_camera(joints[:, keep].reshape(-1, 3), target + proj.offset))
        assert (xy > 0).all() and (xy[:, 0] < SIZE).all() and (xy[:, 1] < SIZE).all()  # in the frame
        assert (xy[:, 1] > ROOM * SIZE).all()  # above the captions' room (y counts up from the bottom)


def test_captions_show_the_current_phrase_and_the_keyword(pair, tmp_path):
    frames = _render(pair, 0, tmp_path / "c.mp4")
    layer = CaptionLayer(pair["captions"], SIZE)
    on = [t for t in range(FRAMES) if layer.active(t / 30)]
    off = [t for t in range(FRAMES) if not layer.active(t / 30)]
    assert on and off
    for t in on[5::20]:
        assert (
            len(figure_pixels.caption_rows(frames[t])) > 0.05 * SIZE
            and figure_pixels.caption_text(frames[t]).sum() > 100
        )
    for t in off[::5]:
        assert len(figure_pixels.caption_rows(frames[t])) == 0
    keyed = [t for t in on if any(k for p in layer.active(t / 30) for _, k in p.words)]
    assert keyed and all(figure_pixels.highlight(frames[t]).sum() > 60 for t in keyed[::10])
    plain = _render(pair, 0, tmp_path / "p.mp4", captions=False)
    assert all(
        figure_pixels.highlight(plain[t]).sum() == 0 and not len(figure_pixels.caption_rows(plain[t])) for t in on[::10]
    )


def test_the_partner_and_the_captions_are_the_same_pixels_whatever_the_agent_does(pair):
    """Before encoding, the partner is the same pixels in every condition's frame wherever the agents are not, and
    the caption's opaque pixels (its text and keyword box) too."""
    a, b = pair["a"], pair["b"]
    layer = CaptionLayer(pair["captions"], SIZE)
    t = next(t for t in range(FRAMES) if layer.active(t / 30))
    frames = []
    for agent in pair["agents"]:
        first = FrameDrawer(a.parents, a.names, SIZE, pair["camera"])
        second = FrameDrawer(b.parents, b.names, SIZE, pair["camera"], one_colour(first.style), frame=first.frame)
        frames.append(compose([(first, agent), (second, pair["partner"])], t, pair["target"], layer, 30.0).copy())
    rgb = [figure_pixels.yuv_rgb(f, SIZE) for f in frames]
    near = figure_pixels.agent(rgb[0]) | figure_pixels.agent(rgb[1])
    near = np.convolve(near.reshape(-1), np.ones(9), "same").reshape(near.shape) > 0  # and their antialiased edges
    mask = figure_pixels.partner(rgb[0]) & ~near
    assert mask.sum() > 150 and np.array_equal(rgb[0][mask], rgb[1][mask])
    r0, _, alpha, _, _ = layer.cache[layer.active(t / 30)]
    y = [f[: SIZE * SIZE].reshape(SIZE, SIZE)[r0 : r0 + len(alpha)] for f in frames]
    opaque = alpha > 0.999
    assert opaque.sum() > 500 and np.array_equal(y[0][opaque], y[1][opaque])


def _band(x, f0):
    """The energy of x [N] around a voice's first three harmonics of f0."""
    spec = np.abs(np.fft.rfft(x)) ** 2
    freqs = np.fft.rfftfreq(len(x), 1 / RATE)
    return sum(spec[(freqs > k * f0 - 8) & (freqs < k * f0 + 8)].sum() for k in (1, 2, 3))


def test_two_voices_mixed_each_heard_at_the_target_loudness():
    t = np.arange(4 * RATE) / RATE
    low = 0.3 * np.sin(2 * np.pi * 140 * t) * (t < 2)
    high = 0.02 * np.sin(2 * np.pi * 235 * t) * (t >= 2)  # a much quieter speaker: levelled before the mix
    mono = mix_voices([low[:, None], high[:, None]], -23.0)
    assert mono.shape == (len(t), 1) and integrated_loudness(mono) == pytest.approx(-23.0, abs=0.1)
    first, second = _band(mono[: 2 * RATE, 0], 140), _band(mono[2 * RATE :, 0], 235)
    assert 0.5 < first / second < 2  # each voice at speech level
    stereo = mix_voices([low[:, None], high[:, None]], -23.0, pans=[-0.6, 0.6])
    assert stereo.shape == (len(t), 2) and integrated_loudness(stereo) == pytest.approx(-23.0, abs=0.1)
    left, right = (stereo[: 2 * RATE, c] for c in (0, 1))
    assert np.sqrt(np.mean(left**2)) > 2 * np.sqrt(np.mean(right**2))  # the first voice on its side
    quiet = mix_voices([low[:, None], 1e-5 * np.sin(2 * np.pi * 235 * t)[:, None]], -23.0)
    assert _band(quiet[:, 0], 235) < 1e-3 * _band(quiet[:, 0], 140)  # a listener's near-silence is never raised


def test_a_video_that_came_out_a_size_off_is_found(pair, tmp_path):
    """The videos a build encodes again (generation.stimuli.render_pool): those whose sizes differ from the
    item's most common, here one encoded at a constant quantiser among two at the default rate control."""
    from rendering.blinding import odd_ones

    paths = [tmp_path / f"{k}.mp4" for k in range(3)]
    for k, path in enumerate(paths):
        options = RenderOptions(64, pair["camera"], qp=20 if k == 1 else None)
        render_clip(_clip(pair["agents"][k % 2], pair["a"]), path, options)
    assert odd_ones(paths) == [1] and odd_ones([paths[0], paths[2]]) == []
