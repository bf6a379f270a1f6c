"""Resampling joint rotations in time, so that resampled skeletons stay rigid.

Joint positions are never interpolated directly (a linearly interpolated bone is shorter than the bone);
instead every joint's local rotation is turned into a unit quaternion, slerped (and low-passed first
when decimating by 2 or more), and forward kinematics is run on the result.
Quaternions are (w, x, y, z) numpy arrays in the last axis.
"""

import numpy as np
from scipy.ndimage import gaussian_filter1d

from .bvh import AXIS, spans

CHUNK_FRAMES = 4096  # frames worked on at a time where a whole take would need several copies of itself
FILTER_TRUNCATE = 4.0  # the anti-aliasing Gaussian's reach, in sigmas (scipy's default, named to bound a block)


def quat_mul(a, b):
    """Hamilton product a * b, broadcasting over leading axes."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_to_matrix(q):
    """Rotation matrices [..., 3, 3] of unit quaternions [..., 4]."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def local_quaternions(bvh, frames=None):
    """Local rotations as quaternions [T, J, 4] and translations [T, J, 3] of a `bvh.Bvh`.

    Built straight from the Euler channels (product of one quaternion per rotation channel, in file
    order, matching tests/reference/bvh_fk.py), which is cheaper and exact compared with matrix -> quaternion.
    """
    motion = bvh.motion if frames is None else bvh.motion[frames]
    T, J = motion.shape[0], len(bvh.names)
    q = np.zeros((T, J, 4))
    q[..., 0] = 1.0
    trans = np.broadcast_to(bvh.offsets, (T, J, 3)).copy()
    # Joints with the same channel layout are done together (usually one or two groups per file).
    groups = {}
    for j, (chans, col) in enumerate(zip(bvh.channels, bvh.channel_columns())):
        groups.setdefault(tuple(chans), []).append((j, col))
    groups = [(chans, np.array([j for j, _ in m]), np.array([c for _, c in m])) for chans, m in groups.items()]
    # A block of frames at a time: the products' temporaries, several times the result's size when made for every
    # frame at once, stay a few megabytes however long the take (the same arithmetic, frame by frame).
    for part in spans(T, CHUNK_FRAMES):
        for chans, js, cols in groups:
            qg = None
            for k, ch in enumerate(chans):
                axis = AXIS[ch[0]]
                values = motion[part, cols + k]  # [frames, G]
                if ch.endswith("position"):
                    trans[part, js, axis] = values
                    continue
                half = np.radians(values) / 2
                qa = np.zeros(values.shape + (4,))
                qa[..., 0] = np.cos(half)
                qa[..., 1 + axis] = np.sin(half)
                qg = qa if qg is None else quat_mul(qg, qa)
            if qg is not None:
                q[part, js] = qg
    return q, trans


def continuity_flips(q):
    """[T, J] booleans: the quaternions to negate so that each lies in the hemisphere of the one before it in time
    (axis 0), those after an odd number of sign changes.

    Worked a block of frames at a time (the dot products a component at a time, only their signs used), so a long
    take's flips cost an eighth of its quaternions and no copy of them."""
    flips = np.zeros(q.shape[:-1], dtype=bool)
    for part in spans(q.shape[0] - 1, CHUNK_FRAMES):
        a, b = q[1:][part], q[:-1][part]
        dots = a[..., 0] * b[..., 0]
        for i in (1, 2, 3):
            dots += a[..., i] * b[..., i]
        odd = np.logical_xor.accumulate(dots < 0, axis=0)
        flips[1:][part] = odd ^ flips[part.start]  # carried on from the block before
    return flips


def slerp(q0, q1, w):
    """Spherical interpolation between unit quaternions q0, q1 [..., 4] with weights w [...] in [0, 1]."""
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where((dot < 0)[..., None], -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-8
    safe = np.where(small, 1.0, sin)
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / safe)
    b = np.where(small, w, np.sin(w * theta) / safe)
    out = a[..., None] * q0 + b[..., None] * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def same_rate(fps_in, fps_out):
    """Whether two frame rates are one: equal to a billionth, so a resampling would only copy the frames."""
    return abs(fps_in - fps_out) < 1e-9 * fps_out


def resample_times(n_frames, fps_in, fps_out):
    """Fractional input-frame positions of the output frames (covering the same time span)."""
    duration = (n_frames - 1) / fps_in
    n_out = int(np.floor(duration * fps_out + 1e-6)) + 1
    return np.arange(n_out) * (fps_in / fps_out)


def lerp_indices(n_frames, fps_in, fps_out):
    """For each output frame, the input frames i0, i1 [n_out] it lies between and its weight w [n_out] on i1,
    so that a linear resampling is a[i0] * (1 - w) + a[i1] * w (slerp for rotations)."""
    u = resample_times(n_frames, fps_in, fps_out)
    i0 = np.minimum(np.floor(u).astype(np.int64), n_frames - 1)
    i1 = np.minimum(i0 + 1, n_frames - 1)
    return i0, i1, u - i0


def resample_local(q, trans, fps_in, fps_out):
    """Resample local rotations q [T, J, 4] and translations [T, J, 3] from fps_in to fps_out.

    Decimating by a factor r >= 2 first low-passes both with a Gaussian of sigma r/2 input frames
    (anti-aliasing); the quaternions are then renormalised. Any ratio is then sampled by slerp/lerp
    at the exact output times (30 -> 20 fps interpolates between frames instead of dropping any).
    """
    if same_rate(fps_in, fps_out):
        return q, trans
    return _resample_blocks(q.shape[0], lambda lo, hi: (q[lo:hi], trans[lo:hi]), fps_in, fps_out)


def local_quaternions_at(bvh, fps_in, fps_out):
    """local_quaternions of a `bvh.Bvh` resampled from fps_in to fps_out (resample_local), made a block of frames
    at a time: a long take's rotations are never held whole at the file's rate, only at the output's."""
    if same_rate(fps_in, fps_out):
        return local_quaternions(bvh)
    return _resample_blocks(bvh.n_frames, lambda lo, hi: local_quaternions(bvh, slice(lo, hi)), fps_in, fps_out)


def _resample_blocks(n, frames, fps_in, fps_out):
    """resample_local of a take of n frames that `frames(lo, hi)` gives as (q, trans) of its frames lo..hi-1.

    A block of output frames at a time, from the input frames it needs and the filter's reach either side: the
    values are those of the whole take done at once (each frame's sign follows the one before it, carried from
    block to block, and the filter's sums see the same frames in the same order)."""
    ratio = fps_in / fps_out
    sigma = ratio / 2 if ratio >= 2 else None
    reach = int(FILTER_TRUNCATE * sigma + 0.5) if sigma else 0  # gaussian_filter1d's own radius
    i0, i1, w = lerp_indices(n, fps_in, fps_out)
    flips = None  # [n, J]: each input frame's continuity_flips, once a block has reached the frame
    q_out = t_out = None
    for part in spans(len(i0), CHUNK_FRAMES):
        a, b, wp = i0[part], i1[part], w[part, None]
        lo, hi = max(int(a[0]) - reach, 0), min(int(b[-1]) + 1 + reach, n)  # a take's own ends: "nearest" there
        start = max(lo - 1, 0)  # the frame before the block, whose sign the block's first frame follows
        qb, tb = frames(start, hi)
        if flips is None:
            flips = np.zeros((n, qb.shape[1]), dtype=bool)
            q_out = np.empty((len(i0),) + qb.shape[1:])
            t_out = np.empty((len(i0),) + tb.shape[1:])
        flips[start + 1 : hi] = continuity_flips(qb)[1:] ^ flips[start]
        qb, tb = qb[lo - start :].copy(), tb[lo - start :]
        qb[flips[lo:hi]] *= -1
        if sigma:
            qb = gaussian_filter1d(qb, sigma, axis=0, mode="nearest", truncate=FILTER_TRUNCATE)
            qb /= np.linalg.norm(qb, axis=-1, keepdims=True)
            tb = gaussian_filter1d(tb, sigma, axis=0, mode="nearest", truncate=FILTER_TRUNCATE)
        a, b = a - lo, b - lo
        q_out[part] = slerp(qb[a], qb[b], np.broadcast_to(wp, (len(a),) + qb.shape[1:-1]))
        t_out[part] = tb[a] * (1 - wp[..., None]) + tb[b] * wp[..., None]
    return q_out, t_out


def clean_fps(fps):
    """Frame rates stored as rounded frame times (0.0333333 s) snap back to the intended rate."""
    r = round(fps)
    return float(r) if r > 0 and abs(fps - r) < 1e-3 * r else float(fps)
