"""The solid body: shaded capsules for the bones and a sphere for the head, rasterised with numpy.

Every bone is a capsule (a cylinder with round ends) of a radius in metres: the trunk's thickest, the limbs'
thinner and the fingers' and face's thin (`Style`). Per frame, all capsules are rasterised at once: every pixel
of every capsule's bounding box is one row of flat arrays (no Python loop over bones); a squared-distance test
to the bone's axis on screen culls the pixels outside the capsule before any square root, and the rest get
their coverage and depth (the axis's depth less the capsule's bulge towards the camera). A z-buffer (one
`np.minimum.at` per frame) keeps the nearest capsule's pixel, so a hand in front of the chest is in front of it,
and only those pixels get a normal and a Lambert shade from a light above, left and in front. On every frame
pixel (`Style.solid_grid` = 1) they are written into the rasteriser's RGBA buffer as packed words, which
`FrameDrawer` blends into the video frame. On a grid of half the frame's resolution (2, the default) a quarter of
the pixels are rasterised, each one 2x2 block of the frame that `FrameDrawer` writes straight into the yuv420p
planes (one chroma sample a block); near a capsule's edge each of the block's pixels gets its own coverage, so
the silhouette is smooth at the frame's resolution, while where one capsule meets another the edge steps by two
pixels.
bench/bench_render_solid.py measures it against the stick figure.
"""

import numpy as np

from .camera import frame_size

LIGHT = np.array([-0.35, 0.55, -0.76])  # towards the light in camera axes (x right, y up, z away from the camera)
LIGHT = LIGHT / np.linalg.norm(LIGHT)
AMBIENT, DIFFUSE = 0.55, 0.6  # shade = AMBIENT + DIFFUSE * max(0, normal . LIGHT), capped at 1.1
f32 = np.float32


class SolidBody:
    """Rasterises capsules into a frame of `size` pixels (a side, or (width, height)), seen through a camera of
    `focal` pixels, on a grid of `scale` frame pixels per grid pixel across and down (1: every pixel; 2: a quarter
    of the work, each grid pixel written to its 2x2 frame pixels, the edges stepped by two pixels)."""

    def __init__(self, size, focal, scale=1):
        width, height = frame_size(size)
        self.full, self.scale = width, scale  # (full: a frame row's pixels)
        self.grid = np.array([width // scale, height // scale])  # the grid the capsules are rasterised on
        self.size, self.focal = int(self.grid[0]), focal / scale  # (size: a grid row's pixels)
        self.zbuf = np.full(int(self.grid.prod()), np.inf, np.float32)
        step = np.arange(scale)
        self.block = (step[:, None] * width + step[None]).reshape(-1)  # a grid pixel's frame pixels from its first
        self.blocks = None

    def draw(self, rgba_flat, a, b, radii, colours, to_rows, capped=None):
        """Rasterise capsules a->b (camera coordinates [N, 3], depth > 0) of `radii` (metres) and `colours`
        into `rgba_flat` ([height*width, 4] uint8, straight alpha; None on a grid of 2: `blocks` then holds each
        grid pixel's 2x2 block of the frame, its colour (0-255) and coverage); `to_rows`: camera points [N, 3] -> image
        (column, row); `capped` [N] bool: whether a capsule has its round end at b (None: all have; a bone needs
        none at a joint that another capsule at least as thick ends at). Returns the (column, row)
        bounding box corners drawn, or None."""
        sa, sb = to_rows(a) / self.scale, to_rows(b) / self.scale
        ra, rb = self.focal * radii / a[:, 2], self.focal * radii / b[:, 2]  # radii in pixels
        capped = np.ones(len(a), bool) if capped is None else np.asarray(capped, bool)
        pad = np.maximum(ra, rb)[:, None] + 1
        # Without its round end at b, a capsule reaches past b only across its axis: by the radius times the axis's
        # other component.
        across = np.abs((sb - sa)[:, ::-1]) / np.maximum(np.linalg.norm(sb - sa, axis=1), 1e-9)[:, None]
        frags = self._fragments(sa, sb, pad, np.where(capped[:, None], pad, pad * across + 1))
        if frags is None:
            return None
        k, col, row, lo, hi = frags
        hit = self._cover(k, col, row, sa, sb, ra, rb, capped)
        if hit is None:
            return lo * self.scale, hi * self.scale
        k, flat, t, ox, oy, dist, rad, cover = hit
        inv = f32(1) / np.maximum(rad, f32(1e-6))
        u = np.minimum(dist * inv, f32(1))
        bulge = np.sqrt(f32(1) - u * u)  # the normal's component towards the camera
        za, dz, rk = np.take(np.stack([a[:, 2], b[:, 2] - a[:, 2], radii]).astype(f32), k, axis=1)
        depth = za + t * dz - rk * bulge
        self.zbuf[flat] = np.inf
        np.minimum.at(self.zbuf, flat, depth)
        front = np.flatnonzero(depth <= self.zbuf[flat])
        flat, k, ox, oy, inv, bulge, cover, dist, rad = (
            x[front] for x in (flat, k, ox, oy, inv, bulge, cover, dist, rad)
        )
        light = (ox * f32(LIGHT[0]) - oy * f32(LIGHT[1])) * inv - bulge * f32(LIGHT[2])  # rows grow downwards
        shade = np.minimum(f32(AMBIENT) + f32(DIFFUSE) * np.maximum(light, f32(0)), f32(1.1))
        rgb = np.minimum(colours.astype(f32)[k] * (shade * f32(255))[:, None] + f32(0.5), f32(255))
        if self.scale == 2 and rgba_flat is None:  # the caller writes them into the yuv420p planes itself
            self.blocks = flat, rgb, _block_cover(ox, oy, dist, rad)
            return lo * self.scale, hi * self.scale
        rgb = rgb.astype(np.uint32)
        alpha = (cover * f32(255)).astype(np.uint32)
        word = rgb[:, 0] | rgb[:, 1] << 8 | rgb[:, 2] << 16 | alpha << 24
        row, col = np.divmod(flat, self.size)
        first = (row * self.full + col) * self.scale  # the grid pixel's first frame pixel
        _composite(rgba_flat.view(np.uint32).reshape(-1), (first[:, None] + self.block).reshape(-1), word)
        return lo * self.scale, hi * self.scale

    def _fragments(self, sa, sb, pad_a, pad_b):
        """The pixels near each capsule (screen ends sa, sb [N, 2], `pad_a`, `pad_b` [N, 2] pixels around each):
        per row of its bounding box, the columns within the larger pad of the axis's stretch over the rows within
        that pad (a diagonal arm's box is mostly empty). Returns (capsule index, column, row, the boxes' union's
        low corner, its high corner), or None where none."""
        lo = np.floor(np.minimum(sa - pad_a, sb - pad_b)).clip(0, self.grid).astype(np.int64)
        hi = np.ceil(np.maximum(sa + pad_a, sb + pad_b)).clip(0, self.grid).astype(np.int64)
        h = np.where(hi[:, 0] > lo[:, 0], np.maximum(hi[:, 1] - lo[:, 1], 0), 0)
        if h.sum() == 0:
            return None
        kr = np.repeat(np.arange(len(h)), h)  # one (capsule, row) pair a row of its box
        y = lo[kr, 1] + np.arange(len(kr)) - np.repeat(np.cumsum(h) - h, h)
        pad = np.maximum(pad_a, pad_b).max(1)[kr]
        d = (sb - sa)[kr]
        steep = np.abs(d[:, 1]) > 1e-6
        dy = np.where(steep, d[:, 1], 1.0)
        t0 = np.where(steep, (y - pad - sa[kr, 1]) / dy, 0.0).clip(0, 1)
        t1 = np.where(steep, (y + 1 + pad - sa[kr, 1]) / dy, 1.0).clip(0, 1)
        x0, x1 = sa[kr, 0] + t0 * d[:, 0], sa[kr, 0] + t1 * d[:, 0]
        xlo = np.maximum(np.floor(np.minimum(x0, x1) - pad), lo[kr, 0]).astype(np.int64)
        xhi = np.minimum(np.ceil(np.maximum(x0, x1) + pad), hi[kr, 0]).astype(np.int64)
        n = np.maximum(xhi - xlo, 0)
        total = int(n.sum())
        if total == 0:
            return None
        pair = np.repeat(np.arange(len(n), dtype=np.int32), n)
        col = (np.arange(total) - np.repeat(np.cumsum(n) - n, n) + np.repeat(xlo, n)).astype(np.int32)
        return kr[pair].astype(np.int32), col, y[pair].astype(np.int32), lo.min(0), hi.max(0)

    def _cover(self, k, col, row, sa, sb, ra, rb, capped):
        """The fragments a capsule covers: (capsule, flat pixel, t along the axis, the offset from the axis
        (x, y), its length, the radius there, the coverage), all in pixels; None where none is covered. A
        squared-distance test culls the rest before any square root."""
        ax, ay = (sb - sa).T
        length2 = np.maximum(ax * ax + ay * ay, 1e-9)
        # Per capsule, gathered for every fragment in one take: [8, M] rows.
        per = np.stack([0.5 - sa[:, 0], 0.5 - sa[:, 1], ax, ay, ax / length2, ay / length2, ra, rb - ra, capped])
        x0, y0, axk, ayk, axn, ayn, rak, drk, cap = np.take(per.astype(f32), k, axis=1)
        rx = col.astype(f32) + x0
        ry = row.astype(f32) + y0
        t = rx * axn + ry * ayn
        keep = t <= f32(1)
        keep |= cap > 0  # a capsule without its round end at b covers nothing beyond b
        np.clip(t, f32(0), f32(1), out=t)
        ox, oy = rx - t * axk, ry - t * ayk  # from the axis's nearest point to the pixel, on screen
        d2 = ox * ox + oy * oy
        rad = rak + t * drk
        reach = rad + f32(0.5)
        keep &= d2 < reach * reach
        inside = np.flatnonzero(keep)
        if len(inside) == 0:
            return None
        k, t, ox, oy, d2, rad = (x[inside] for x in (k, t, ox, oy, d2, rad))
        dist = np.sqrt(d2)
        cover = np.minimum(rad - dist + f32(0.5), f32(1))
        flat = row[inside].astype(np.int64) * self.size + col[inside]
        return k, flat, t, ox, oy, dist, rad, cover


# The 2x2 frame pixels' centres from their grid pixel's centre (column, row; in grid pixels), in the order
# FrameDrawer.quad takes them: top left, top right, bottom left, bottom right.
SUB = np.array([[-0.25, -0.25], [0.25, -0.25], [-0.25, 0.25], [0.25, 0.25]], np.float32)


def _block_cover(ox, oy, dist, rad):
    """Each frame pixel's coverage [M, 4] in the 2x2 blocks of grid pixels at offset (ox, oy) [M] and distance
    `dist` from their capsule's axis of radius `rad` (grid pixels): the distance moved along the offset's
    direction, so that the silhouette's edge is smooth at the frame's resolution, not stepped by the grid's."""
    cover = np.ones((len(dist), 4), f32)
    edge = np.flatnonzero(dist > rad - f32(1))  # further in, every frame pixel is covered
    ox, oy, dist, rad = ox[edge], oy[edge], dist[edge], rad[edge]
    inv = f32(1) / np.maximum(dist, f32(1e-6))
    d = dist[:, None] + (ox * inv)[:, None] * SUB[:, 0] + (oy * inv)[:, None] * SUB[:, 1]
    cover[edge] = np.clip((rad[:, None] - d) * f32(2) + f32(0.5), f32(0), f32(1))
    return cover


def _composite(words, flat, word):
    """Write shaded pixels `word` [M] (RGBA packed in one little-endian word, the alpha the coverage) to each
    of their frame pixels `flat` [M * scale**2] of `words` (the frame's RGBA as words): over nothing, the word
    itself; over the shadow, the colour mixed with it by the coverage and the larger alpha."""
    word = np.repeat(word, len(flat) // len(word))
    old = words[flat]
    over = np.flatnonzero(old)
    if len(over):
        new, was = (w[over].view(np.uint8).reshape(-1, 4).astype(f32) for w in (word, old))
        c = new[:, 3:] * f32(1 / 255)
        mixed = c * new + (f32(1) - c) * was + f32(0.5)
        mixed[:, 3] = np.maximum(new[:, 3], was[:, 3])
        word[over] = mixed.astype(np.uint8).view(np.uint32).reshape(-1)
    words[flat] = word
