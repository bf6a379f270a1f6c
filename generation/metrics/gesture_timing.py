"""The gesture measures that set motion against the voices' timing: BeatAlign and a listener's response.

- BeatAlign (Li et al. 2021, as BEAT used it, Liu et al. 2022): the motion's beats are the local minima of the wrists'
  speed (joint_groups.wrists, about the root; summed over the wrists), each frame lower than every other within
  ORDER_S on either side (BEAT: two frames at 15 fps). Against the onsets of the agent's own voice
  (generation.metrics.voice.onsets),

      BeatAlign = 1/|B_m| * sum over motion beats t of exp(-min over onsets o of (t - o)^2 / (2 SIGMA^2)),

  the papers' formula, averaged over the motion's beats (BEAT's released code averages over the onsets instead:
  bench/RESULTS.md "gesture-anchors"), SIGMA = 0.3 s as BEAT's code sets it. 1: every motion beat falls on an onset;
  near 0: none near one. Undefined (nan) without a motion beat or without an onset.
- Listener response (a two-person study): the mean speed (m/s, about the root) of the agent's head and hand joints
  over the frames in which the interlocutor speaks and the agent does not, A_listen, and over those in which the agent
  speaks and the interlocutor does not, A_speak (generation.metrics.voice.speaking):
  response = A_listen / (A_listen + A_speak). 0.5: as active listening as speaking; near 0: still while the other
  speaks. Undefined with less than MIN_SPAN_S of either, or a body that never moves.
"""

import numpy as np

from . import joint_groups, voice

SIGMA = 0.3  # s, BEAT's
ORDER_S = 2 / 15  # s either side of a motion beat: BEAT's order of two frames at its 15 fps
MIN_SPAN_S = 0.5  # of listening and of speaking, for the listener response


class Undefined(ValueError):
    """A measure that cannot be computed for a clip; the message is the reason, for measures.csv."""


def joint_speed(joints, fps, idx, parents):
    """The speed (m/s) of each of the joints `idx` about the root per frame pair [T-1, len(idx)]."""
    rel = joint_groups.about_root(joints, parents)[:, idx]
    return np.linalg.norm(np.diff(rel, axis=0), axis=-1) * fps


def motion_beats(joints, fps, names, parents):
    """The motion's beats (s): local minima of the wrists' summed speed (see the module's docstring)."""
    idx = joint_groups.wrists(names)
    if not idx:
        raise Undefined("no hand or wrist joint found by name")
    speed = joint_speed(joints, fps, idx, parents).sum(axis=1)
    order = max(1, int(round(ORDER_S * fps)))
    if len(speed) < 2 * order + 1:
        raise Undefined(f"shorter than a beat's neighbourhood ({2 * order + 2} frames)")
    inner = np.arange(order, len(speed) - order)
    lower = np.ones(len(inner), bool)
    for k in range(1, order + 1):
        lower &= (speed[inner] < speed[inner - k]) & (speed[inner] < speed[inner + k])
    # speed[t] is between frames t and t+1: the beat is at the middle of the pair
    return (inner[lower] + 0.5) / fps


def beat_align(beats, onset_times, sigma=SIGMA):
    """BeatAlign of motion beats against audio onsets (both in s): the mean over the beats of the Gaussian of the
    distance to the nearest onset."""
    beats, onset_times = np.asarray(beats, float), np.sort(np.asarray(onset_times, float))
    if not len(beats):
        raise Undefined("no motion beat (the wrists' speed has no local minimum)")
    if not len(onset_times):
        raise Undefined("no onset in the agent's voice")
    nearest = np.abs(beats[:, None] - onset_times[None, :]).min(axis=1)
    return float(np.mean(np.exp(-(nearest**2) / (2 * sigma**2))))


def clip_beat_align(joints, fps, names, parents, onset_times, sigma=SIGMA):
    """A clip's BeatAlign against its voice's onsets (s from the clip's first frame: voice.onsets of the item's
    voice); Undefined says why it has none. Onsets after the clip's last frame do not count."""
    onset_times = np.asarray(onset_times, float)
    return beat_align(motion_beats(joints, fps, names, parents), onset_times[onset_times <= len(joints) / fps], sigma)


def listener_response(joints, fps, names, parents, agent_speaks, other_speaks):
    """A two-person clip's listener response (see the module's docstring) from when the agent and the interlocutor
    speak (voice.speaking of each voice); Undefined says why it has none."""
    found = joint_groups.groups(names)
    idx = sorted(found.get("head", []) + found.get("hands", []))
    if not idx:
        raise Undefined("no head or hand joint found by name")
    n = len(joints)
    a, o = (voice.at_frames(s, n, fps) for s in (agent_speaks, other_speaks))
    pair_a, pair_o = a[1:] & a[:-1], o[1:] & o[:-1]  # a frame pair counts where both of its frames do
    listening, talking = pair_o & ~pair_a, pair_a & ~pair_o
    for what, mask in (("the interlocutor speaks alone", listening), ("the agent speaks alone", talking)):
        if mask.sum() < MIN_SPAN_S * fps:
            raise Undefined(f"{what} for {mask.sum() / fps:.2f} s, under {MIN_SPAN_S:g} s")
    speed = joint_speed(joints, fps, idx, parents).mean(axis=1)
    listen, speak = float(speed[listening].mean()), float(speed[talking].mean())
    if listen + speak <= 0:
        raise Undefined("the head and hands never move")
    return listen / (listen + speak)
