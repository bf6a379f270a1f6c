"""The mesh of an SMPL-family motion, skinned on demand (`style = "mesh"`): smplx's skinning, written out in numpy,
with the user's body model, a chunk of frames at a time.

`smpl_mesh` reads an SMPL-family parameter file as smpl_files reads it for its joints (the same hand rule,
smpl_files.apply_hand_mean, and the same SMPL-X expressions), so the mesh and the joints agree; `mesh_source` takes
poses already read (Seamless Interaction's files, generation.data.seamless_files). A MeshSource gives frames a..b's
vertices through `smplx.lbs.lbs`'s arithmetic (shape and pose blend shapes, then linear blend skinning) and which
vertices the face mask covers; rendering.mesh draws them, and generation.stimuli.mesh_track carries them onto a
clip's joints. Beyond the four arrays the joints need, the skinning reads the model's posedirs, weights and faces,
each checked against its vertices and joints, and refuses a model of more than MAX_MESH_VERTICES vertices before it
loads them. The body model's arrays are read once per process and file. Neither torch nor smplx is imported here.
"""

import functools
from pathlib import Path

import numpy as np

from moglow_eval.core.clip import MAX_MESH_VERTICES

from .smpl_files import (
    WHERE_TO_GET,
    SmplError,
    apply_hand_mean,
    load_arrays,
    read_expression,
    read_model,
    read_parameters,
    shape_and_expression,
    shape_components,
)

MESH_BATCH = 32  # frames per pass through the skinning: bounds the vertices held at once (32 x 10k x 3 floats)
# Metres added to surface_reach's bound: the pose blend shapes move the surface by a centimetre or so (a bent elbow,
# a raised shoulder), which the rest shape does not show.
POSE_SHAPE_MARGIN = 0.015


def smpl_mesh(path, model, smpl_type=None, source_fps=None, face="mask", hand_mean="auto"):
    """The skinned mesh of an SMPL-family parameter file (`style = "mesh"`): a MeshSource whose `vertices(a, b)`
    gives frames a..b's vertices [n, V, 3] (metres, the model's axes, float32) through smplx's skinning
    (`smplx.lbs.lbs`'s: shape and pose blend shapes, then linear blend skinning) with the user's model file and the
    motion's betas, a chunk at a time, so memory does not grow with the clip. `face`: "mask" (the face's vertices
    flagged for the mask, rendering.mesh) or "none"; `hand_mean` as smpl_positions takes it, and the file's SMPL-X
    expressions, so that the mesh and the joints agree. SmplError naming the file otherwise."""
    if model is None or not Path(model).is_file():  # before the hand mean reads it
        raise SmplError(f"{model or path}: no body model file for the mesh style; {WHERE_TO_GET}")
    poses, trans, betas, fps = read_parameters(path, source_fps)
    poses = apply_hand_mean(poses, model, smpl_type, path, hand_mean)
    expression = read_expression(path, len(poses))
    return mesh_source(poses, trans, betas, fps, model, smpl_type, face, path, expression)


def mesh_source(poses, trans, betas, fps, model, smpl_type, face, where, expression=None):
    """The MeshSource of poses [T, 3J], translations [T, 3] and `betas` (empty: the mean shape) at `fps`, through
    the body model file `model` (smpl_mesh; Seamless Interaction's files through generation.stimuli.mesh_track).
    SmplError naming `where` or the model."""
    if model is None or not Path(model).is_file():
        raise SmplError(f"{model or where}: no body model file for the mesh style; {WHERE_TO_GET}")
    template, shapedirs, regressor, parents, kind = _read_model(*_file_version(model), smpl_type)
    if poses.shape[1] != 3 * len(parents):
        raise SmplError(
            f"{where}: 'poses' has {poses.shape[1]} values a frame; the {kind} model {model} takes {3 * len(parents)}"
        )
    skin = _read_skin(model, len(template), len(parents))
    n_shape = min(len(betas), shape_components(kind, shapedirs.shape[2]))
    shape = (*shape_and_expression(kind, shapedirs, betas, expression), n_shape)
    return MeshSource(where, poses, trans, fps, template, shape, regressor, parents, kind, skin, face)


class MeshSource:
    """An SMPL-family clip's mesh, skinned on demand (see smpl_mesh): what rendering.mesh draws (`faces` [F, 3],
    `mask` [V]: the face mask's vertices), `fps`, `n_frames` and `vertices(a, b)`."""

    def __init__(self, path, poses, trans, fps, template, shape, regressor, parents, kind, skin, face):
        """`shape`: (directions [V, 3, K], coefficients [1 or T, K], how many of them are the body's shape) as
        shape_and_expression gives them: the body shape's, then, per frame, SMPL-X's expression's."""
        self.path, self.poses, self.trans, self.fps, self.kind = path, poses, trans, fps, kind
        self.n_frames = len(poses)
        self.template, self.regressor = template.astype(np.float32), regressor.astype(np.float32)
        self.shapedirs, self.coef = (x.astype(np.float32) for x in shape[:2])
        self.n_shape = shape[2]
        self.parents = parents
        self.posedirs, self.weights, self.faces = skin
        self._one_shape = self._sparse_weights = None  # made on first use: the skinning's, once a clip
        none = np.zeros(len(template), bool)
        self.mask = face_vertices(self.shaped(), self.rest_joints()) if face == "mask" else none

    def shaped(self):
        """The rest vertices [V, 3] in this motion's shape."""
        k = self.n_shape
        return self.template + self.shapedirs[:, :, :k] @ self.coef[0, :k]

    def rest_joints(self):
        return self.regressor @ self.shaped()

    def vertices(self, a, b):
        """Frames a..b's vertices [b - a, V, 3] float32, in metres, the root translation applied."""
        return self.posed(a, b)[0]

    def posed(self, a, b):
        """(vertices [b - a, V, 3], joints [b - a, J, 3]) of frames a..b, float32, the root translation applied:
        smplx's forward pass (`smplx.lbs.lbs`: shape and pose blend shapes, then linear blend skinning), written out in
        numpy, a chunk of MESH_BATCH frames at a time.

        The same arithmetic in float32 as smplx's (tests/rendering/test_render_mesh.py holds the two together), but
        for what a clip does not need again: the rest shape and its joints made once for a clip of one shape, each
        vertex blending only the joints whose weight is not zero (an SMPL body's vertex follows a few of its 52).
        smplx's lbs spent several times as long, most of it in torch's thread pool waiting on the cores that compose
        and encode the frames; a render worker that draws the mesh now loads no torch."""
        n_joints = len(self.parents)
        verts = np.empty((b - a, len(self.template), 3), np.float32)
        joints = np.empty((b - a, n_joints, 3), np.float32)
        eye = np.eye(3, dtype=np.float32)
        for s in range(a, b, MESH_BATCH):
            e = min(b, s + MESH_BATCH)
            shaped, rest = self._shaped(s, e)  # [1 or e - s, V, 3], [1 or e - s, J, 3]
            rot = rodrigues(self.poses[s:e].astype(np.float32).reshape(-1, 3)).reshape(e - s, n_joints, 3, 3)
            placed, moves = rigid_transforms(rot, rest, self.parents)
            feature = (rot[:, 1:] - eye).reshape(e - s, -1)
            v_posed = (feature @ self.posedirs).reshape(e - s, -1, 3) + shaped
            shift = self.trans[s:e, None].astype(np.float32)
            verts[s - a : e - a] = self._skin(v_posed, moves) + shift
            joints[s - a : e - a] = placed + shift
        return verts, joints

    def _shaped(self, s, e):
        """The rest vertices [1 or e - s, V, 3] of frames s..e in the body's shape (and SMPL-X's expression), and
        their joints [1 or e - s, J, 3]: made once when every frame shares them."""
        if len(self.coef) > 1:  # one matrix product each, the frames along the columns
            n_vertices, n = len(self.template), e - s
            offsets = self.shapedirs.reshape(n_vertices * 3, -1) @ self.coef[s:e].T  # [V * 3, n]
            shaped = self.template + offsets.reshape(n_vertices, 3, n).transpose(2, 0, 1)
            rest = self.regressor @ shaped.transpose(1, 0, 2).reshape(n_vertices, -1)  # [J, n * 3]
            return shaped, rest.reshape(-1, n, 3).transpose(1, 0, 2)
        if self._one_shape is None:
            shaped = self.template + self.shapedirs @ self.coef[0]
            self._one_shape = shaped[None], (self.regressor @ shaped)[None]
        return self._one_shape

    def _skin(self, v_posed, moves):
        """Linear blend skinning: vertices [n, V, 3] moved by their joints' transforms `moves` [n, J, 3, 4] ([R | t]),
        blended by the weights [V, J]."""
        if self._sparse_weights is None:
            from scipy.sparse import csr_matrix  # here: the builder imports this module without skinning anything

            self._sparse_weights = csr_matrix(self.weights)
        n, n_joints = moves.shape[:2]
        # Frames last, so that every product below runs along contiguous memory (twice as fast as frames first).
        rows = moves.transpose(1, 2, 3, 0).reshape(n_joints, 12 * n)  # each joint's [R | t] in every frame
        blend = (self._sparse_weights @ rows).reshape(-1, 3, 4, n)  # [V, 3, 4, n]
        at = np.ascontiguousarray(v_posed.transpose(1, 2, 0))  # [V, 3, n]
        x, y, z = (at[:, None, k] for k in range(3))  # each [V, 1, n]
        return (blend[:, :, 3] + blend[:, :, 0] * x + blend[:, :, 1] * y + blend[:, :, 2] * z).transpose(2, 0, 1)


def rodrigues(rot_vecs):
    """Rotation matrices [N, 3, 3] of axis-angle vectors [N, 3] (float32): smplx.lbs.batch_rodrigues in numpy."""
    angle = np.linalg.norm(rot_vecs + np.float32(1e-8), axis=1, keepdims=True)
    x, y, z = (rot_vecs / angle).T
    zero = np.zeros_like(x)
    k = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], 1).reshape(-1, 3, 3)
    return np.eye(3, dtype=np.float32) + np.sin(angle)[:, :, None] * k + (1 - np.cos(angle))[:, :, None] * (k @ k)


def rigid_transforms(rot, rest, parents):
    """(posed joints [n, J, 3], each joint's transform of the rest body [n, J, 3, 4] as [R | t]) of local rotations
    `rot` [n, J, 3, 3] about the rest joints `rest` [1 or n, J, 3] down the tree `parents` [J] (parents before their
    children): smplx.lbs.batch_rigid_transform in numpy."""
    n, n_joints = rot.shape[:2]
    rest = np.broadcast_to(rest, (n, n_joints, 3))
    offset = rest.copy()
    offset[:, 1:] -= rest[:, parents[1:]]
    turn = np.empty_like(rot)
    placed = np.empty((n, n_joints, 3), rot.dtype)
    turn[:, 0], placed[:, 0] = rot[:, 0], offset[:, 0]
    for j in range(1, n_joints):
        p = parents[j]
        turn[:, j] = turn[:, p] @ rot[:, j]
        placed[:, j] = (turn[:, p] @ offset[:, j, :, None])[..., 0] + placed[:, p]
    moves = np.concatenate([turn, (placed - (turn @ rest[..., None])[..., 0])[..., None]], -1)
    return placed, moves


@functools.lru_cache(maxsize=4)
def _rest_model(model, mtime_ns, size, smpl_type):
    """(v_template, shapedirs, J_regressor, kind, weights [V, J]) of a body model, read once per process and file
    version: the four arrays through _read_model's cache, which the skinning shares."""
    template, shapedirs, regressor, parents, kind = _read_model(model, mtime_ns, size, smpl_type)
    weights = np.asarray(load_arrays(Path(model), ("weights",), "a body model")["weights"], np.float64)
    if weights.shape != (len(template), len(parents)):
        raise SmplError(
            f"{model}: weights {weights.shape} do not fit its {len(template)} vertices and {len(parents)} joints"
        )
    return template, shapedirs, regressor, kind, weights


def surface_reach(model, smpl_type, betas):
    """How far the mesh's surface reaches from each joint [J], in metres, in any pose: what a camera must frame
    around the joints to keep the whole mesh in view (rendering.framing.framed_points' `reach`): a fingertip beyond
    the last finger joint, the top of the head above the head joint, the flesh around a limb.

    Each vertex belongs to the joint that weighs most in its skinning. Linear blend skinning moves it by its
    joints' transforms, weighted; by the triangle inequality it stays within sum_k w_k (|v - J_k| + |J_k - J|)
    of its joint J in every pose, where the distances are the rest shape's (`betas`: the body's shape; empty: the
    mean) and |J_k - J| is a bone's length for the neighbouring joints that skin it. A joint's reach is the
    largest bound of its vertices, with POSE_SHAPE_MARGIN for the pose blend shapes; 0 for a joint that owns none."""
    template, shapedirs, regressor, kind, weights = _rest_model(*_file_version(model), smpl_type)
    dirs, coef = shape_and_expression(kind, shapedirs, np.asarray(betas, np.float64).reshape(-1), None)
    shaped = template + (dirs @ coef[0] if dirs.shape[2] else 0.0)
    joints = regressor @ shaped
    owner = weights.argmax(1)
    bound = np.zeros(len(shaped))
    for k in np.unique(np.nonzero(weights > 0)[1]):  # the joints that skin any vertex: few against the vertices
        w = weights[:, k]
        on = w > 0
        far = np.linalg.norm(shaped[on] - joints[k], axis=1) + np.linalg.norm(joints[k] - joints[owner[on]], axis=1)
        bound[on] += w[on] * far
    reach = np.zeros(len(joints))
    np.maximum.at(reach, owner, bound)
    return np.where(reach > 0, reach + POSE_SHAPE_MARGIN, 0.0)


def face_vertices(shaped, joints):
    """Which rest vertices [V] the face mask covers: those within 15 cm of the head joint (15 in every SMPL layout),
    in front of it (the models face +Z at rest) by more than 4 cm, and above the chin (7 cm below the joint)."""
    r = shaped - joints[15]
    return (np.linalg.norm(r, axis=1) < 0.15) & (r[:, 2] > 0.04) & (r[:, 1] > -0.07)


# A mesh clip's motion file is read for each clip, its body model once a process: reading the model and laying out
# its pose blend shapes (40 MB for SMPL-H) cost a render worker about a fifth of a second a person a clip. Keyed by
# the file as it is on disk now (its path, time and size); what is kept is read-only, shared by every clip.
def _file_version(model):
    stat = Path(model).stat()
    return str(model), stat.st_mtime_ns, stat.st_size


@functools.lru_cache(maxsize=2)
def _read_model(model, mtime_ns, size, smpl_type):
    """smpl_files.read_model's arrays of a body model, read-only."""
    arrays = read_model(model, smpl_type)
    for array in arrays[:4]:
        array.flags.writeable = False
    return arrays


def _read_skin(model, n_vertices, n_joints):
    """(posedirs [(J-1)*9, V*3] as smplx's lbs takes them, weights [V, J], faces [F, 3] int64) of a body model,
    refused with one line where they do not fit its vertices and joints; read-only."""
    if n_vertices > MAX_MESH_VERTICES:
        raise SmplError(f"{model}: {n_vertices} vertices, more than a body mesh has (at most {MAX_MESH_VERTICES})")
    return _skin_arrays(*_file_version(model), n_vertices, n_joints)


@functools.lru_cache(maxsize=2)
def _skin_arrays(model, mtime_ns, size, n_vertices, n_joints):
    model = Path(model)
    d = load_arrays(model, ("posedirs", "weights", "f"), "a body model")
    posedirs, weights, faces = np.asarray(d["posedirs"], np.float32), np.asarray(d["weights"], np.float32), d["f"]
    if posedirs.shape != (n_vertices, 3, (n_joints - 1) * 9) or weights.shape != (n_vertices, n_joints):
        raise SmplError(
            f"{model}: posedirs {posedirs.shape} and weights {weights.shape} do not fit its {n_vertices} vertices and "
            f"{n_joints} joints"
        )
    faces = np.asarray(faces)
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu" or len(faces) == 0:
        raise SmplError(f"{model}: 'f' must be integer triangles [F, 3], got {faces.shape} {faces.dtype}")
    if faces.min() < 0 or faces.max() >= n_vertices:
        raise SmplError(f"{model}: 'f' indexes vertices outside the model's {n_vertices}")
    skin = posedirs.reshape(n_vertices * 3, -1).T.copy(), weights, faces.astype(np.int64)
    for array in skin:
        array.flags.writeable = False
    return skin
