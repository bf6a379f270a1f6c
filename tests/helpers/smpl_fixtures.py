"""Synthetic SMPL-family body models and parameter files, written by the tests (the real models are licensed).

A model file has the layout smplx's loaders read (v_template, shapedirs, posedirs, J_regressor, weights,
kintree_table, f) and the real models' joint trees (SMPL 24 joints, SMPL-H 52, SMPL-X 55), on a made-up body:
one vertex at each rest joint (the regressor picks it) and a few more, so its joints stand 1.5 m tall as real
SMPL joints do (head joint to feet). A parameter file has poses, trans, betas and mocap_frame_rate, as BEAT2 and
AMASS ship them.
"""

import numpy as np

SMPL_PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]
# Rest joints of the 22 body joints, metres, Y up, facing +Z, left +X (T-pose), the pelvis at the origin.
BODY_REST = [
    (0, 0, 0), (0.06, -0.09, 0), (-0.06, -0.09, 0), (0, 0.11, 0), (0.10, -0.47, 0), (-0.10, -0.47, 0),
    (0, 0.25, 0), (0.09, -0.87, -0.04), (-0.09, -0.87, -0.04), (0, 0.31, 0), (0.12, -0.93, 0.10),
    (-0.12, -0.93, 0.10), (0, 0.52, 0), (0.08, 0.45, 0), (-0.08, 0.45, 0), (0, 0.60, 0.05), (0.17, 0.45, 0),
    (-0.17, 0.45, 0), (0.43, 0.45, 0), (-0.43, 0.45, 0), (0.68, 0.45, 0), (-0.68, 0.45, 0),
]  # fmt: skip


def tree(kind):
    """(parents, rest joints [J, 3]) of a model kind: smpl, smplh or smplx."""
    parents, rest = list(SMPL_PARENTS[:22]), [np.array(p, float) for p in BODY_REST]
    if kind == "smpl":
        return np.array(SMPL_PARENTS), np.array(rest + [rest[20] + (0.08, 0, 0), rest[21] - (0.08, 0, 0)])
    if kind == "smplx":  # jaw and eyes on the head, before the hands
        parents += [15, 15, 15]
        rest += [rest[15] + (0, -0.05, 0.08), rest[15] + (0.03, 0.03, 0.08), rest[15] + (-0.03, 0.03, 0.08)]
    for wrist, s in ((20, 1), (21, -1)):
        for f in range(5):
            parent = wrist
            for k in range(3):
                parents.append(parent)
                rest.append(rest[parent] + (s * (0.05 if k == 0 else 0.025), 0, (f - 2) * 0.015 if k == 0 else 0))
                parent = len(parents) - 1
    return np.array(parents), np.array(rest)


def model_arrays(kind, n_vertices=None, n_betas=10, seed=0):
    """The arrays of a synthetic model (float32, as the published files): vertex j is rest joint j for the first J
    vertices, which J_regressor picks; the rest of the vertices sit around the body."""
    rng = np.random.default_rng(seed)
    parents, rest = tree(kind)
    n = len(parents)
    v = max(n_vertices or 0, n + 8)
    template = np.concatenate([rest, rng.uniform(-0.3, 0.3, (v - n, 3))]).astype(np.float32)
    regressor = np.zeros((n, v), np.float32)
    regressor[np.arange(n), np.arange(n)] = 1.0
    weights = np.zeros((v, n), np.float32)
    weights[np.arange(v), np.minimum(np.arange(v), n - 1)] = 1.0
    kintree = np.stack([parents, np.arange(n)]).astype(np.int64)
    kintree[0, 0] = 2**32 - 1  # as the published files mark the root
    hands = {}
    if kind != "smpl":  # SMPL-H and SMPL-X files carry MANO's mean hand pose, which flat_hand_mean=False adds
        hands = dict(hands_meanl=rng.normal(0, 0.1, 45).astype(np.float32), hands_meanr=rng.normal(0, 0.1, 45))
    return dict(
        **hands,
        v_template=template,
        shapedirs=rng.normal(0, 0.01, (v, 3, n_betas)).astype(np.float32),
        posedirs=np.zeros((v, 3, (n - 1) * 9), np.float32),
        J_regressor=regressor,
        weights=weights,
        kintree_table=kintree,
        f=np.stack([np.arange(v - 2), np.arange(1, v - 1), np.arange(2, v)], 1).astype(np.int64),
    )


def write_model(path, kind, **kw):
    np.savez(path, **model_arrays(kind, **kw))
    return path


def motion_arrays(kind, frames=60, fps=30.0, seed=0):
    """poses [T, 3J] (the root turning slowly, the arms waving), trans [T, 3] (walking forward), betas [10]."""
    rng = np.random.default_rng(seed)
    n = len(tree(kind)[0])
    t = np.arange(frames) / fps
    poses = np.zeros((frames, n, 3))
    poses[:, 0, 1] = 0.3 * t  # yaw about Y
    poses[:, 16, 2] = -1.0 + 0.3 * np.sin(2 * np.pi * t)  # left shoulder down from the T-pose, waving
    poses[:, 17, 2] = 1.0
    trans = np.stack([0.1 * np.sin(t), 0.93 + 0 * t, 0.5 * t], 1)
    return dict(
        poses=poses.reshape(frames, -1), trans=trans, betas=rng.normal(0, 1, 10), mocap_frame_rate=np.float64(fps)
    )


def write_motion(path, kind, **kw):
    np.savez(path, **motion_arrays(kind, **kw))
    return path


# -------------------------------------------------------------------------------- a body-shaped mesh
def _radius(kind, j):
    """A tube's radius for the bone that ends at joint j: the trunk thick, the limbs thinner, the fingers thin."""
    if j >= 22:
        return 0.009  # fingers (and SMPL-X's jaw and eyes, drawn as small tubes too)
    return {3: 0.11, 6: 0.12, 9: 0.12, 12: 0.05, 13: 0.06, 14: 0.06, 1: 0.08, 2: 0.08}.get(j, 0.045)


class _MeshBuilder:
    """Vertices, the joint each is skinned to, and triangles, grown a part at a time."""

    def __init__(self, rest, segments):
        self.verts, self.joint, self.faces = [p for p in rest], list(range(len(rest))), []
        self.around = np.linspace(0, 2 * np.pi, segments, endpoint=False)

    def ring_faces(self, start, rows, flip=False):
        """Two triangles per quad between consecutive rings of `len(around)` vertices from `start`."""
        s_n = len(self.around)
        for k in range(rows - 1):
            for s in range(s_n):
                p, q = start + k * s_n + s, start + k * s_n + (s + 1) % s_n
                tri = [(p, q, q + s_n), (p, q + s_n, p + s_n)]
                self.faces.extend([(a, c, b) for a, b, c in tri] if flip else tri)

    def tube(self, a, b, radius, joint, rings):
        """A closed tube from a to b, every vertex skinned to `joint`."""
        axis = b - a
        d = axis / max(np.linalg.norm(axis), 1e-9)
        u = np.cross(d, [0.0, 0.0, 1.0] if abs(d[2]) < 0.9 else [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(d, u)
        start, s_n = len(self.verts), len(self.around)
        for k in range(rings):
            centre = a + axis * k / (rings - 1)
            self.verts += [centre + radius * (np.cos(t) * u + np.sin(t) * w) for t in self.around]
        self.joint += [joint] * (rings * s_n)
        self.ring_faces(start, rings)
        for end, sign in ((0, -1), (rings - 1, 1)):  # the caps: a fan around a tip
            tip = len(self.verts)
            self.verts.append((a if end == 0 else b) + sign * d * radius * 0.5)
            self.joint.append(joint)
            for s in range(s_n):
                p, q = start + end * s_n + s, start + end * s_n + (s + 1) % s_n
                self.faces.append((tip, q, p) if end == 0 else (tip, p, q))

    def sphere(self, centre, radius, joint, rings):
        lat = np.linspace(0.1, np.pi - 0.1, rings)
        start = len(self.verts)
        for phi in lat:
            self.verts += [centre + radius * np.array([np.sin(phi) * np.sin(t), np.cos(phi), np.sin(phi) * np.cos(t)])
                           for t in self.around]  # fmt: skip
        self.joint += [joint] * (rings * len(self.around))
        self.ring_faces(start, rings, flip=True)
        s_n = len(self.around)
        for end, y in ((0, 1.0), (rings - 1, -1.0)):  # the poles: closed, as SMPL's head is
            pole = len(self.verts)
            self.verts.append(centre + (0.0, y * radius, 0.0))
            self.joint.append(joint)
            for s in range(s_n):
                p, q = start + end * s_n + s, start + end * s_n + (s + 1) % s_n
                self.faces.append((pole, p, q) if end == 0 else (pole, q, p))


def body_model_arrays(kind, rings=4, segments=12, head_rings=10, seed=0, tips=0.0, head=(0.05, 0.1)):
    """A synthetic model of the smplx layout whose mesh is a body: one closed tube around each bone (its vertices
    skinned to the bone's parent joint, as a limb's are in SMPL) and a closed sphere around the head joint, the head's
    vertices on its front (+Z, where SMPL faces) making up the face. The first J vertices are the rest joints, which
    J_regressor picks, as in `model_arrays`. `rings` and `segments` set the vertex count (the real SMPL-H has 6890).
    `tips`: metres each finger goes on beyond its last joint (skinned to it), as a real hand's fingertips do beyond
    SMPL-H's last finger joints; `head`: the head sphere's centre above the head joint and its radius (metres)."""
    arrays = model_arrays(kind, seed=seed)
    parents, rest = tree(kind)
    n = len(parents)
    mesh = _MeshBuilder(rest, segments)
    for j in range(1, n):
        if j != 15:  # the head: a sphere
            mesh.tube(rest[parents[j]], rest[j], _radius(kind, j), parents[j], rings)
        if tips and j >= (25 if kind == "smplx" else 22) and j not in parents:  # a finger's last joint
            along = (rest[j] - rest[parents[j]]) / np.linalg.norm(rest[j] - rest[parents[j]])
            mesh.tube(rest[j], rest[j] + tips * along, _radius(kind, j), j, rings)
    mesh.sphere(rest[15] + (0, head[0], 0), head[1], 15, head_rings)
    v = len(mesh.verts)
    weights = np.zeros((v, n), np.float32)
    weights[np.arange(v), mesh.joint] = 1.0
    regressor = np.zeros((n, v), np.float32)
    regressor[np.arange(n), np.arange(n)] = 1.0
    rng = np.random.default_rng(seed)
    arrays.update(
        v_template=np.array(mesh.verts, np.float32),
        shapedirs=rng.normal(0, 0.002, (v, 3, 10)).astype(np.float32),
        posedirs=np.zeros((v, 3, (n - 1) * 9), np.float32),
        J_regressor=regressor,
        weights=weights,
        f=np.array(mesh.faces, np.int64),
    )
    return arrays


def write_arms_take(path, lowered, fps=30.0, bow=0.6):
    """An SMPL-H parameter file of a body standing still, its arms turned down from the T-pose by `lowered` [T]
    radians (0: spread wide, the wrists 1.36 m apart; negative: raised) and its head bowed by `bow` radians at the
    neck (the top of a ball round the head is then above the neck's line)."""
    lowered = np.asarray(lowered, np.float64)
    poses = np.zeros((len(lowered), 52, 3))
    poses[:, 16, 2], poses[:, 17, 2] = -lowered, lowered  # the left shoulder, the right (tree)
    poses[:, 12, 0] = bow
    trans = np.tile([0.0, 0.93, 0.0], (len(lowered), 1))
    np.savez(path, poses=poses.reshape(len(lowered), -1), trans=trans, betas=np.zeros(10), mocap_frame_rate=fps)
    return path


def write_body_model(path, kind, **kw):
    np.savez(path, **body_model_arrays(kind, **kw))
    return path


def smplh_take(folder, frames, fps=30.0):
    """(model, motion, clip) written into `folder`: the synthetic SMPL-H body model, a take of `frames` frames, and
    its joints as a clip dict (joints, parents, joint_names, fps), as the mesh tests render them."""
    from generation.data.smpl_files import smpl_positions

    model = write_body_model(folder / "SMPLH_NEUTRAL.npz", "smplh")
    motion = write_motion(folder / "take.npz", "smplh", frames=frames, fps=fps)
    joints, names, parents, fps = smpl_positions(motion, model)
    return model, motion, dict(joints=joints, parents=parents, joint_names=names, fps=fps)
