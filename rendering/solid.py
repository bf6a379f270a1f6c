"""The solid body: shaded capsules for the bones and a sphere for the head, rasterised with numpy.

Every bone is a capsule (a cylinder with round ends) of a radius in metres: the trunk's thickest, the limbs'
thinner and the fingers' and face's thin (`Style`). Per frame, all capsules are rasterised at once: every pixel
of every capsule's bounding box is one row of flat arrays (no Python loop over bones), its distance to the
bone's axis on screen gives its coverage, its depth (the axis's depth less the capsule's bulge towards the
camera) and its normal, hence its Lambert shade from a light above, left and in front. A z-buffer (one
`np.minimum.at` per frame) keeps the nearest capsule's pixel, so a hand in front of the chest is in front of
it. The pixels are written into the rasteriser's RGBA buffer, which `FrameDrawer` blends into the video frame.
bench/bench_render_solid.py measures it against the stick figure.
"""

import numpy as np

LIGHT = np.array([-0.35, 0.55, -0.76])  # towards the light in camera axes (x right, y up, z away from the camera)
LIGHT = LIGHT / np.linalg.norm(LIGHT)
AMBIENT, DIFFUSE = 0.55, 0.6  # shade = AMBIENT + DIFFUSE * max(0, normal . LIGHT), capped at 1.1


class SolidBody:
    """Rasterises capsules into a frame of `size` pixels square, seen through a camera of `focal` pixels."""

    def __init__(self, size, focal):
        self.size, self.focal = size, focal
        self.zbuf = np.full(size * size, np.inf, np.float32)

    def draw(self, rgba_flat, a, b, radii, colours, to_rows):
        """Rasterise capsules a->b (camera coordinates [N, 3], depth > 0) of `radii` (metres) and `colours`
        into `rgba_flat` ([size*size, 4] uint8, straight alpha); `to_rows`: camera points [N, 3] -> image
        (column, row). Returns the (column, row) bounding box corners drawn, or None."""
        size = self.size
        sa, sb = to_rows(a), to_rows(b)
        ra, rb = self.focal * radii / a[:, 2], self.focal * radii / b[:, 2]  # radii in pixels
        pad = np.maximum(ra, rb) + 1
        lo = np.floor(np.minimum(sa, sb) - pad[:, None]).clip(0, size).astype(np.int64)
        hi = np.ceil(np.maximum(sa, sb) + pad[:, None]).clip(0, size).astype(np.int64)
        w, h = hi[:, 0] - lo[:, 0], hi[:, 1] - lo[:, 1]
        n = np.where((w > 0) & (h > 0), w * h, 0)
        total = int(n.sum())
        if total == 0:
            return None
        k = np.repeat(np.arange(len(n)), n)
        local = np.arange(total) - np.repeat(np.cumsum(n) - n, n)
        wk = w[k]
        row, col = np.divmod(local, wk)
        col += lo[k, 0]
        row += lo[k, 1]
        f32 = np.float32
        ax, ay = (sb - sa).astype(f32).T
        length2 = np.maximum(ax * ax + ay * ay, f32(1e-9))
        rx = col.astype(f32) + f32(0.5) - sa[:, 0].astype(f32)[k]
        ry = row.astype(f32) + f32(0.5) - sa[:, 1].astype(f32)[k]
        t = np.clip((rx * ax[k] + ry * ay[k]) / length2[k], f32(0), f32(1))
        ox, oy = rx - t * ax[k], ry - t * ay[k]  # from the axis's nearest point to the pixel, on screen
        dist = np.sqrt(ox * ox + oy * oy)
        ra32, rb32 = ra.astype(f32), rb.astype(f32)
        rad = ra32[k] + t * (rb32 - ra32)[k]
        cover = np.clip(rad - dist + f32(0.5), f32(0), f32(1))
        inside = np.flatnonzero(cover > 0)
        k, col, row, t, ox, oy, dist, rad, cover = (x[inside] for x in (k, col, row, t, ox, oy, dist, rad, cover))
        inv = f32(1) / np.maximum(rad, f32(1e-6))
        u = np.minimum(dist * inv, f32(1))
        bulge = np.sqrt(f32(1) - u * u)  # the normal's component towards the camera
        za, zb = a[:, 2].astype(f32), b[:, 2].astype(f32)
        depth = za[k] + t * (zb - za)[k] - radii.astype(f32)[k] * bulge
        light = (ox * f32(LIGHT[0]) - oy * f32(LIGHT[1])) * inv - bulge * f32(LIGHT[2])  # rows grow downwards
        shade = np.minimum(f32(AMBIENT) + f32(DIFFUSE) * np.maximum(light, f32(0)), f32(1.1))
        flat = row * size + col
        self.zbuf[flat] = np.inf
        np.minimum.at(self.zbuf, flat, depth)
        front = depth <= self.zbuf[flat]
        flat, k, shade, cover = flat[front], k[front], shade[front], cover[front]
        rgb = np.clip(colours[k] * shade[:, None] * 255.0 + 0.5, 0, 255)
        old = rgba_flat[flat].astype(np.float32)
        c = cover[:, None].astype(np.float32)
        alpha = np.maximum(c[:, 0] * 255.0, old[:, 3])
        c = np.where(old[:, 3:] > 0, c, 1.0)  # over the shadow: mixed with it; over nothing: alpha alone
        rgba_flat[flat, :3] = (c * rgb + (1 - c) * old[:, :3]).astype(np.uint8)
        rgba_flat[flat, 3] = alpha.astype(np.uint8)
        return lo.min(0), hi.max(0)
