"""A clip's mesh for the mesh style (rendering.mesh): its SMPL-family file skinned on demand, carried onto the clip.

A study turns a motion file into a clip's joints by steps that know nothing of a mesh: the units and the up axis,
resampling to the study's frame rate, standing the clip at the origin facing +Z (own_study.builder.place), cutting it
to its item's length or holding its last pose, and, for a catch clip, breaking it (stimuli.catch_kinds). Rather than
mirror each step, a MeshTrack follows the clip's joints: for each of its frames it skins the file's frame at the same
time (generation.data.skinning, smplx's skinning), moves that mesh by the similarity (scale, rotation,
translation: Umeyama's least-squares fit) that best takes the file's joints onto the clip's, and adds what is left of
each joint's move to the vertices that joint skins, by their skinning weights. For a clip that is its file moved
about, nothing is left; for a catch clip, what is left is the break, and the mesh breaks with it.

A MeshSpec is what a render worker needs to rebuild the track (it is small and pickles); `track` rebuilds it, reading
each file and body model once per process.
"""

import functools
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MeshSpec:
    path: str  # the SMPL-family parameter file, or a Seamless Interaction participant's
    model: str  # the user's body model (.npz)
    smpl_type: str | None
    face: str  # "mask" or "none"
    joints: np.ndarray  # [T, J, 3] the clip's joints, as drawn
    fps: float  # the clip's frame rate: its frame t is the file's time (start + t) / fps (resampled, cut or held)
    start: int = 0  # the clip's first frame in the file, at the clip's rate (a catch copy starts one late)
    hand_mean: bool | str = "auto"  # as the joints were read (generation.data.smpl_files.HAND_MEAN_LAYOUTS)


@functools.lru_cache(maxsize=4)
def source(path, model, smpl_type, face, hand_mean="auto"):
    """The file's MeshSource (generation.data.skinning), read once per process and file, its hands as its joints'
    (smpl_files.apply_hand_mean, the one rule for both)."""
    from ..data import seamless_files
    from ..data.skinning import mesh_source, smpl_mesh
    from ..data.smpl_files import apply_hand_mean

    if seamless_files.is_seamless_file(path):
        m = seamless_files.read_seamless(path)
        poses = apply_hand_mean(m.poses, model, smpl_type, path, hand_mean)
        return mesh_source(poses, m.trans, np.zeros(0), m.fps, model, smpl_type, face, path)
    return smpl_mesh(path, model, smpl_type, face=face, hand_mean=hand_mean)


def track(spec):
    """The MeshTrack of a MeshSpec: the clip's frame t is the file's frame (start + t) * (its rate / the clip's)."""
    src = source(spec.path, spec.model, spec.smpl_type, spec.face, spec.hand_mean)
    frames = (spec.start + np.arange(len(spec.joints))) * (src.fps / spec.fps)
    return MeshTrack(src, spec.joints, frames)


class MeshTrack:
    """What render_clip's `mesh` takes: `faces`, `mask`, `n_frames` and `vertices(a, b)` of the clip's frames."""

    def __init__(self, source, joints, source_frames):
        self.source = source
        self.joints = np.asarray(joints, np.float64)
        self.frames = np.clip(np.asarray(source_frames, np.float64), 0, source.n_frames - 1)
        self.faces, self.mask, self.n_frames = source.faces, source.mask, len(self.joints)
        if len(self.frames) != self.n_frames:
            raise ValueError(f"{len(self.frames)} source frames for {self.n_frames} frames of joints")

    def vertices(self, a, b):
        """The clip's frames a..b as vertices [b - a, V, 3] float32 in the joints' world."""
        pos = self.frames[a:b]
        lo = np.floor(pos).astype(int)
        w = (pos - lo).astype(np.float32)[:, None, None]
        hi = np.where(w[:, 0, 0] > 0, np.minimum(lo + 1, self.source.n_frames - 1), lo)  # a whole frame: itself
        first, last = int(lo.min()), int(hi.max()) + 1
        verts, joints = self.source.posed(first, last)  # the file's frames the chunk needs, once each
        v, j = verts[lo - first], joints[lo - first]
        if w.any():  # between two of the file's frames (another frame rate)
            v = (1 - w) * v + w * verts[hi - first]
            j = (1 - w) * j + w * joints[hi - first]
        return follow(v, j, self.joints[a:b], self.source.weights)


def follow(verts, joints, target, weights):
    """Vertices [n, V, 3] skinned to `joints` [n, J, 3], carried onto `target` [n, J, 3]: the per-frame similarity that
    best takes joints onto target (Umeyama 1991), then each joint's remaining offset spread by `weights` [V, J].
    The fit in float64 (a few numbers a frame), the vertices moved in float32 (what the drawing takes), by matrix
    products: per vertex this is the skinning's cost again, and einsum in float64 took four times the skinning's."""
    joints, target = np.asarray(joints, np.float64), np.asarray(target, np.float64)
    mj, mt = joints.mean(1, keepdims=True), target.mean(1, keepdims=True)
    x, y = joints - mj, target - mt
    cov = np.einsum("nji,njk->nik", y, x) / joints.shape[1]
    u, d, vt = np.linalg.svd(cov)
    sign = np.ones_like(d)
    sign[:, 2] = np.sign(np.linalg.det(u @ vt))  # a rotation, never a mirror
    rot = u @ (sign[:, :, None] * vt)
    var = (x * x).sum((1, 2)) / joints.shape[1]
    scale = (d * sign).sum(1) / np.maximum(var, 1e-12)
    turn = scale[:, None, None] * rot  # [n, 3, 3]
    placed = np.einsum("nik,njk->nji", turn, x) + mt
    f32 = np.float32
    moved = (np.asarray(verts, f32) - mj.astype(f32)) @ turn.transpose(0, 2, 1).astype(f32) + mt.astype(f32)
    rest = (target - placed).astype(f32).transpose(1, 0, 2).reshape(len(x[0]), -1)  # [J, n * 3]
    moved += (np.asarray(weights, f32) @ rest).reshape(len(weights), -1, 3).transpose(1, 0, 2)  # one product
    return moved
