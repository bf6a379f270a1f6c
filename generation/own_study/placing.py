"""Where the two people of a two-person item stand: facing each other at a distance, or as recorded.

Seamless Interaction stores each participant in their own camera's frame, so the translations of two people of
one conversation need not put them face to face (nor on one floor). `facing` (the default) stands each body,
every condition's clip of the agent alike, with its mean root position on the floor at its own spot, DISTANCE
apart along X (the agent at -X), turned so that its mean facing over the clip is towards the other, opened by OPEN
degrees towards the +Z side of their line (a shallow V, as a stage turns two people talking, so that a camera on
that side sees both turned a little towards it: rendering.framing.pair_camera), its
lowest joint's median height on the floor. `recorded` keeps the two where the files put
them (every condition's agent in the interlocutor's frame), moved and turned as one so that the line between the
real agent and the interlocutor runs along +X from the midpoint at the origin, the floor under the lower of them.
"""

import numpy as np

from rendering.framing import mean_facing

from ..motion.features import rotate_y

PLACEMENTS = ("facing", "recorded")
DISTANCE = 1.4  # metres between the two roots: a conversation's usual distance
OPEN = 25.0  # degrees each of two people facing each other is turned towards the camera's side of their line


def _floor(joints):
    """The height of a body's lowest joint, its median over frames."""
    return float(np.median(np.asarray(joints)[..., 1].min(axis=1)))


def stand(joints, names, spot, azimuth, root=0):
    """A clip (joints [T, J, 3], Y up) turned so that its mean facing is `azimuth` degrees (from +Z towards +X),
    its body's mean root position (joint `root`) on the floor moved to `spot` (x, z) and its lowest joint's median
    height to 0."""
    out = np.asarray(joints, np.float64)
    out = rotate_y(out, np.radians(azimuth - mean_facing([out], names)))
    out = out - np.array([out[:, root, 0].mean(), _floor(out), out[:, root, 2].mean()])
    return (out + np.array([spot[0], 0.0, spot[1]])).astype(np.float32)


def facing(agents, names, partner, partner_names, distance=DISTANCE, opened=OPEN, roots=(0, 0)):
    """(agent clips, partner joints) standing face to face `distance` apart along X, the agent at -X, each turned
    `opened` degrees from the other towards +Z; `roots`: the agent's and the partner's root joints."""
    half = distance / 2
    placed = [stand(j, names, (-half, 0.0), 90.0 - opened, roots[0]) for j in agents]
    return placed, stand(partner, partner_names, (half, 0.0), 270.0 + opened, roots[1])


def recorded(agents, partner, reference=0, roots=(0, 0)):
    """(agent clips, partner joints) as recorded, moved and turned as one: the midpoint of the real agent's
    (agents[reference]) and the partner's mean root positions (`roots`: their root joints) at the origin, the line
    from the agent to the partner along +X, the floor under the lower of the two."""
    a = np.asarray(agents[reference], np.float64)[:, roots[0], [0, 2]].mean(0)
    b = np.asarray(partner, np.float64)[:, roots[1], [0, 2]].mean(0)
    mid = (a + b) / 2
    line = np.degrees(np.arctan2(b[0] - a[0], b[1] - a[1]))  # its azimuth, from +Z towards +X
    turn = np.radians(90.0 - line)
    floor = min(_floor(partner), _floor(agents[reference]))

    def move(joints):
        out = np.asarray(joints, np.float64) - np.array([mid[0], floor, mid[1]])
        return rotate_y(out, turn).astype(np.float32)

    return [move(j) for j in agents], move(partner)


def place_pair(agents, names, partner, partner_names, placement="facing", distance=DISTANCE, opened=OPEN, roots=(0, 0)):
    """An item's agent clips (every condition's, the real agent's first) and its partner, placed as the study
    file says (PLACEMENTS); `roots`: the agent's and the partner's root joints (core.skeleton_names.body_root)."""
    if placement == "recorded":
        return recorded(agents, partner, roots=roots)
    return facing(agents, names, partner, partner_names, distance, opened, roots)
