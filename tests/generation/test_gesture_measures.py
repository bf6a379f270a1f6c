"""The gesture measures (docs/metrics.md) on real motion and on sound made for a known answer: BeatAlign is higher
with a motion's own speech than with another item's, jitter moves the hands' Hellinger distance far from 0 while the
reference against itself stays near it, a held-out half of the reference has a small FGD while catch clips have a
large one, and a listener who nods while the other speaks scores above one who is still. Bad input (a silent voice,
a skeleton without hands) is nan with a reason, never an exception."""

import numpy as np
import pytest
from helpers.own_study_data import action_takes
from helpers.paths import TEST_DATA
from helpers.syllables import RATE, speech_over, syllables

from generation.data.motion_files import read_motion
from generation.metrics import gesture, gesture_fgd, gesture_timing, joint_groups, motion_histograms, voice
from generation.metrics.fmd import frechet_distance
from generation.stimuli.catch_kinds import make_catch

FPS = 30.0


@pytest.fixture(scope="module")
def walk():
    """A real walk of 242 frames (8 s at 30 fps, 22 joints) from tests/data: the fast tier's motion."""
    return read_motion(TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz", FPS)


@pytest.fixture(scope="module")
def actions():
    """Real gestures and actions of one skeleton (22 joints at 30 fps), the first 30 takes by kind and style."""
    takes = [read_motion(p, FPS) for p in action_takes(34)]
    return [m for m in takes if len(m.names) == 22][:30]


# ---------------------------------------------------------------- the parts, on known inputs (fast tier)
def test_onsets_are_where_the_syllables_start_and_silence_has_none():
    times = [0.4, 0.9, 1.5, 1.75, 2.6]
    found = voice.onsets(syllables(times, 3.0), RATE)
    assert len(found) == len(times)
    assert np.abs(found - times).max() < 0.04  # a frame or so early: backtracked to where the sound begins
    assert len(voice.onsets(np.zeros(3 * RATE), RATE)) == 0
    assert len(voice.onsets(1e-4 * np.random.default_rng(0).standard_normal(3 * RATE), RATE)) == 0  # hiss alone


def test_beat_align_is_the_papers_formula():
    beats = np.array([0.5, 2.0, 4.0])
    assert gesture_timing.beat_align(beats, beats) == pytest.approx(1.0)
    sigma = gesture_timing.SIGMA
    assert gesture_timing.beat_align(beats, beats + sigma) == pytest.approx(np.exp(-0.5))
    # each motion beat counts once against its nearest onset, whatever the other onsets
    assert gesture_timing.beat_align(beats, [0.5, 2.0, 4.0 + 2 * sigma, 9.0]) == pytest.approx((2 + np.exp(-2)) / 3)
    with pytest.raises(gesture_timing.Undefined, match="no onset"):
        gesture_timing.beat_align(beats, [])


def test_hellinger_is_zero_for_the_same_shape_and_one_for_disjoint_histograms():
    p = np.array([1.0, 4.0, 2.0, 0.0])
    assert motion_histograms.hellinger(p, 3 * p) == pytest.approx(0.0, abs=1e-7)
    assert motion_histograms.hellinger([1, 1, 0, 0], [0, 0, 5, 1]) == pytest.approx(1.0)
    assert np.isnan(motion_histograms.hellinger(p, np.zeros(4)))


def test_the_frechet_distance_is_fmds_where_both_work_and_exact_where_a_covariance_is_singular():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(400, 6)), rng.normal(0.5, 2.0, size=(300, 6))
    ga, gb = gesture_fgd.gaussian(gesture_fgd.moments(a)), gesture_fgd.gaussian(gesture_fgd.moments(b))
    assert gesture_fgd.frechet(ga, gb) == pytest.approx(frechet_distance(*ga, *gb), rel=1e-6)
    # three points in six dimensions: the Gaussians' distance to themselves is still 0, and not nan
    few = gesture_fgd.gaussian(gesture_fgd.moments(a[:3]))
    assert gesture_fgd.frechet(few, few) == pytest.approx(0.0, abs=1e-6)
    assert gesture_fgd.fgd(a[:3], b) > gesture_fgd.fgd(a, b) * 0.5


def test_joint_groups_are_found_by_name_in_any_skeleton(walk):
    names = ["pelvis", "left_collar", "left_shoulder", "left_elbow", "left_wrist", "left_index1", "neck", "jaw"]
    assert joint_groups.groups(names) == {"arms": [1, 2, 3], "hands": [4, 5], "head": [6, 7]}
    assert [names[j] for j in joint_groups.wrists(names)] == ["left_wrist"]
    found = joint_groups.groups(walk.names)
    assert [walk.names[j] for j in found["hands"]] == ["Hand_L", "Hand_R"]
    assert [walk.names[j] for j in found["head"]] == ["Neck", "Head"]


def test_a_listener_who_nods_while_the_other_speaks_scores_above_one_who_is_still(walk):
    """The agent speaks over the first 3 s and moves as the real walk does; the other speaks over the last 3 s, while
    the agent either nods (the head about the neck, 2 Hz, 15 degrees) or holds still."""
    n, t0 = 180, 90  # 6 s; the agent listens from frame 90 on
    agent, other = speech_over((0.2, 2.8), 6.0, f0=120.0), speech_over((3.2, 5.8), 6.0, f0=220.0)
    still = walk.joints[:n].astype(np.float64).copy()
    still[t0:] = still[t0]
    nodding = still.copy()
    neck, head = walk.names.index("Neck"), walk.names.index("Head")
    angle = np.radians(15) * np.sin(2 * np.pi * 2.0 * np.arange(n - t0) / FPS)
    bone = nodding[t0, head] - nodding[t0, neck]
    c, s = np.cos(angle), np.sin(angle)
    nodding[t0:, head] = nodding[t0, neck] + np.stack(
        [bone[0] * np.ones_like(c), bone[1] * c - bone[2] * s, bone[1] * s + bone[2] * c], axis=-1
    )  # about the x axis: a nod
    args = (walk.names, walk.parents, voice.speaking(agent, RATE), voice.speaking(other, RATE))
    score_still = gesture_timing.listener_response(still, FPS, *args)
    score_nod = gesture_timing.listener_response(nodding, FPS, *args)
    assert score_still == pytest.approx(0.0, abs=1e-9)
    assert score_nod > score_still + 0.01
    # ... and one voice, or none heard, is no answer
    with pytest.raises(gesture_timing.Undefined, match="interlocutor speaks alone"):
        silent = voice.speaking(np.zeros_like(other), RATE)
        gesture_timing.listener_response(nodding, FPS, walk.names, walk.parents, voice.speaking(agent, RATE), silent)


def test_a_silent_voice_and_a_skeleton_without_hands_are_nan_with_a_reason(walk):
    joints = walk.joints[:120].astype(np.float64)
    no_hands = [n.replace("Hand", "Paw") for n in walk.names]
    applies = gesture.plan(no_hands, sound=True, two_voices=False)
    assert applies["hellinger_speed_hands"] == "no hands joint found by name"
    assert applies["beat_align"] == "no hand or wrist joint found by name"
    assert applies["listener_response"].startswith("needs two voices")
    assert applies["hellinger_speed_arms"] is None and applies["fgd"] is None
    clips = [gesture.Clip("NAT", "test", f"i{k}", True, joints[20 * k : 20 * k + 30]) for k in range(3)]
    voices = gesture.Voices(RATE, {f"i{k}": np.zeros(2 * RATE) for k in range(3)})
    result = gesture.measure(clips, walk.names, walk.parents, FPS, voices, gesture.plan(walk.names, True, False),
                             cache=False)  # fmt: skip
    assert all(np.isnan(v["beat_align"]) for v in result.clips)
    assert result.reasons["beat_align"] == {"no onset in the agent's voice": 3}
    assert "two reference clips" in next(iter(result.reasons["fgd"]))  # 30 frames: shorter than a chunk
    assert all(np.isfinite(v["hellinger_speed_hands"]) for v in result.clips)  # the rest is measured


# ---------------------------------------------------------------- known answers on real gestures (../shared)
def beat_speech(m, seconds):
    """The onsets of speech whose syllables start at the motion's beats."""
    return voice.onsets(syllables(gesture_timing.motion_beats(m.joints, FPS, m.names, m.parents), seconds), RATE)


@pytest.mark.full
def test_real_motion_aligns_better_with_its_own_speech_than_with_another_items(actions):
    own, other = [], []
    for k, m in enumerate(actions[:8]):
        seconds = len(m.joints) / FPS
        partner = actions[(k + 3) % 8]
        own.append(gesture_timing.clip_beat_align(m.joints, FPS, m.names, m.parents, beat_speech(m, seconds)))
        theirs = beat_speech(partner, seconds)
        other.append(gesture_timing.clip_beat_align(m.joints, FPS, m.names, m.parents, theirs))
    assert all(a > b for a, b in zip(own, other)), (own, other)
    assert min(own) > 0.95 and np.mean(own) - np.mean(other) > 0.15


@pytest.mark.full
@pytest.mark.parametrize("kind", motion_histograms.KINDS)
def test_jitter_moves_the_hands_hellinger_far_from_zero_and_the_reference_stays_near_it(actions, kind):
    hands = joint_groups.groups(actions[0].names)["hands"]

    def pooled(clips):
        return sum(motion_histograms.histograms(j, FPS, hands, actions[0].parents)[kind] for j in clips)

    half_a, half_b = [m.joints for m in actions[0::2]], [m.joints for m in actions[1::2]]
    rng = np.random.default_rng(0)
    jittered = [j + rng.normal(0, 0.01, j.shape) for j in half_b]  # 1 cm of noise per joint and frame
    assert motion_histograms.hellinger(pooled(half_a), pooled(half_a)) == pytest.approx(0.0, abs=1e-7)
    # another half of the reference: other takes of other gestures, the same hands
    floor = motion_histograms.hellinger(pooled(half_b), pooled(half_a))
    assert floor < 0.3
    assert motion_histograms.hellinger(pooled(jittered), pooled(half_a)) > max(0.45, 2 * floor)


@pytest.mark.full
def test_fgd_of_a_held_out_half_is_small_and_of_catch_clips_large(actions):
    parents = actions[0].parents
    train, held = [m.joints for m in actions[0::2]], [m.joints for m in actions[1::2]]
    encoder = gesture_fgd.GestureEncoder.train(train, parents, FPS, seed=0, steps=300, cache=False)
    reference = np.concatenate([encoder.features(j) for j in train])
    floor = gesture_fgd.fgd(np.concatenate([encoder.features(j) for j in held]), reference)
    jitter = gesture_fgd.fgd(np.concatenate([encoder.features(make_catch(j, "jitter", k)) for k, j in
                                             enumerate(held)]), reference)  # fmt: skip
    assert jitter > 4 * floor, (floor, jitter)
    # one clip: its catch version is farther from the reference than it is, clip by clip
    for k, j in enumerate(held[:5]):
        mine = gesture_fgd.fgd(encoder.features(j), reference)
        assert gesture_fgd.fgd(encoder.features(make_catch(j, "jitter", k)), reference) > 2 * mine


@pytest.mark.full
def test_the_encoder_is_cached_and_the_same_seed_trains_the_same_one(actions, tmp_path):
    clips, parents = [m.joints for m in actions[:6]], actions[0].parents
    first = gesture_fgd.GestureEncoder.train(clips, parents, FPS, seed=3, steps=20, cache=tmp_path)
    assert len(list(tmp_path.glob("*.pt"))) == 1
    again = gesture_fgd.GestureEncoder.train(clips, parents, FPS, seed=3, steps=20, cache=tmp_path)
    fresh = gesture_fgd.GestureEncoder.train(clips, parents, FPS, seed=3, steps=20, cache=False)
    f = [e.features(clips[0]) for e in (first, again, fresh)]
    assert np.array_equal(f[0], f[1]) and np.allclose(f[0], f[2], atol=1e-5)
    (next(tmp_path.glob("*.pt"))).write_bytes(b"not a torch file")  # a damaged cache: trained past, not fatal
    damaged = gesture_fgd.GestureEncoder.train(clips, parents, FPS, seed=3, steps=20, cache=tmp_path)
    assert np.allclose(damaged.features(clips[0]), f[0], atol=1e-5)
