"""The software rasteriser: one clip's frames drawn as yuv420p, ready for the encoder.

Speed: we keep the grey background and floor grid in the luma plane (the blank floor is computed once per size
and cached; grid lines are Wu lines drawn with numpy), draw only the figure with a bare matplotlib Agg renderer
(no figure, axes or artists, and no global backend switch), and blend just the 2x2 pixel blocks it touched into
the Y/U/V planes. bench/bench_render.py compares the whole pipeline with a matplotlib FuncAnimation + ffmpeg
writer.
"""

import functools
from dataclasses import dataclass, replace

import numpy as np
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.path import Path
from matplotlib.transforms import IdentityTransform

from moglow_eval.core import skeleton_names

from .camera import DEFAULT_CAMERA, NEAR, Projector, clip_to_frustum, frame_size
from .errors import RenderError
from .mesh import MeshPainter, Painted, over
from .solid import SolidBody
from .yuv import BLOCK_TO_UV, RGBA_TO_Y, TO_U, TO_V, TO_Y, grey_to_y, yuv_to_rgb


@dataclass(frozen=True)
class Style:
    # Background, floor, grid and shadow are grey levels (FrameDrawer keeps them in the luma plane).
    background: float = 0.97
    floor: float = 0.88
    grid: float = 0.55
    shadow: float = 0.74
    centre: tuple = (0.15, 0.15, 0.15)
    left: tuple = (0.15, 0.35, 0.75)
    right: tuple = (0.75, 0.25, 0.15)
    grid_spacing: float = 1.0  # metres between grid lines
    grid_radius: float = 8.0  # metres of floor drawn around the look-at point (fading out)
    bone_width: float = 1 / 150  # line width as a fraction of the frame height
    head_radius: float = 0.08  # metres
    thin: float = 0.45  # finger and face bones' line width, as a fraction of the others'
    body: str = "stick"  # "stick": lines and a head disc; "solid": shaded capsules and a head sphere (solid.py);
    # "mesh": an SMPL-family body's skinned mesh, one plain colour, the face masked (mesh.py)
    trunk_radius: float = 0.07  # metres: the solid body's trunk capsules (the bones no side's name tells)
    limb_radius: float = 0.045  # metres: its arms and legs
    thin_radius: float = 0.011  # metres: its fingers and face
    sphere_radius: float = 0.1  # metres: its head
    solid_grid: int = 2  # frame pixels per pixel of the grid the solid body is rasterised on (solid.SolidBody)
    mesh_colour: tuple = (0.42, 0.55, 0.78)  # the mesh body's one colour (a person's; the agent's in a dyadic video)
    mesh_grid: int = 2  # frame pixels per pixel of the grid the mesh is drawn on (as solid_grid; 1: every pixel)


DEFAULT_STYLE = Style()
STYLES = {"stick": DEFAULT_STYLE, "solid": Style(body="solid"), "mesh": Style(body="mesh")}  # [render] style
MESH_INPUTS = "SMPL-family parameter files (SMPL, SMPL-H, SMPL-X)"  # what the mesh style can draw
# The second person of a two-person video (the real interlocutor) is one colour, no side told: a muted green that
# no side colour, grey of the floor or caption shares.
PARTNER_COLOUR = (0.40, 0.60, 0.44)


def one_colour(style, colour=PARTNER_COLOUR):
    """`style` with every bone and the head in `colour`: the interlocutor's drawing in any style."""
    return replace(style, centre=tuple(colour), left=tuple(colour), right=tuple(colour), mesh_colour=tuple(colour))


def _wu_lines(flat, width, a, b, value, alpha):
    """Draw antialiased 1-px lines a->b [N, 2] (x=column, y=row, inside [0, width-2]) of `value` into a
    flat uint8 plane of row length `width` (the luma plane: the lines and the floor under them are grey).

    Xiaolin Wu's method, vectorised over every pixel column (or row, for steep lines) of every line:
    each sample covers the two pixels straddling the line with weights 1-f and f, times alpha (flat, the
    grid's fade). A sample's pixels are u*su + v*sv in the flat plane, with (su, sv) = (1, width) for
    shallow lines (stepping along columns) and (width, 1) for steep ones (stepping along rows).
    """
    d = b - a
    steep = np.abs(d[:, 1]) > np.abs(d[:, 0])
    au, av = np.where(steep, a[:, 1], a[:, 0]), np.where(steep, a[:, 0], a[:, 1])  # u: the stepping coordinate
    du, dv = np.where(steep, d[:, 1], d[:, 0]), np.where(steep, d[:, 0], d[:, 1])
    # (A rounding margin, so that an end clipped to the plane's edge always gets its edge sample.)
    start = np.ceil(np.minimum(au, au + du) - 1e-6)
    n = np.maximum(np.floor(np.maximum(au, au + du) + 1e-6) - start + 1, 0).astype(np.int64)
    total = int(n.sum())
    if total == 0:
        return
    slope = dv / np.where(du == 0, 1.0, du)
    # Per line, then per sample: u = k + (start - first k of the line), v = icpt + u slope, strides su, sv.
    per_line = np.stack(
        [start - (np.cumsum(n) - n), av - au * slope, slope, np.where(steep, width, 1), np.where(steep, 1, width)]
    )
    ku, icpt, slope, su, sv = np.repeat(per_line, n, axis=1)
    u = ku + np.arange(total)
    v = icpt + u * slope
    v0 = np.trunc(v)  # v > -1e-6: the floor (or 0 at the edge)
    p = (u * su + v0 * sv).astype(np.int64)  # flat index of the sample's first pixel
    idx = np.concatenate([p, p + sv.astype(np.int64)])  # ... and of its second (v <= width-2)
    al = alpha[p]
    w1 = (v - v0).astype(np.float32) * al
    w = np.concatenate([al - w1, w1])
    y = flat[idx].astype(np.float32)
    flat[idx] = (y + w * (np.float32(value) - y) + np.float32(0.5)).astype(np.uint8)


class FrameDrawer:
    """Draws the frames of one clip as yuv420p (what the encoder wants); reused for every frame.

    The camera only translates (its orientation and height are fixed), so which floor point each pixel
    sees, relative to the look-at point, never changes: the floor disc and the grid's distance fade are
    computed once per size. Everything but the limbs is grey, so the background and grid live in the luma
    plane alone and the chroma planes are flat except where the figure is. Per frame: copy the blank luma
    plane, draw the world-fixed grid lines into it with numpy (Wu lines), draw the shadow, bones and head
    with Agg on a transparent buffer, and blend only the 2x2 pixel blocks the figure touched into the three
    planes (the figure covers a few percent of its bounding box). This saves ffmpeg the RGBA -> yuv420p
    conversion and the pipe 60% of the bytes.

    Any skeleton: every bone of the hierarchy is drawn, coloured by its child joint's side as its name tells it
    (core.skeleton_names; neutral where none can be told), finger and face bones (`thin`: joint names, or None
    to tell them from the names) at `style.thin` of the line width. Bones of a joint in `hide` are not drawn,
    nor those from a root joint named like a root (`joint_Root`, `b_root`: a floor marker, not a bone).

    `size` is the frame's side (square) or (width, height): a two-person video's frame is wide. Sizes in the
    style (line widths) are shares of the height, as the camera's field of view is.
    """

    def __init__(
        self,
        parents,
        joint_names,
        size,
        camera=DEFAULT_CAMERA,
        style=DEFAULT_STYLE,
        hide=(),
        thin=None,
        frame=None,
        meshes=None,
    ):
        width, height = frame_size(size)
        if width % 2 or height % 2:
            raise RenderError(f"width and height must be even for yuv420p, got {width}x{height}")
        self.width, self.height, self.camera, self.style = width, height, camera, style
        self.proj = Projector(camera, width, height)
        self.renderer = RendererAgg(width, height, 72)
        self.rgba = np.asarray(self.renderer.buffer_rgba())  # the figure, on transparent black
        self.rgba.fill(0)
        self.px = self.rgba.view(np.uint32).reshape(height, width)  # one word per pixel: nonzero where drawn
        self.px_flat = self.px.reshape(-1)
        n = width * height
        # The yuv420p frame written to the encoder; a second person's drawer draws into the first's (`frame`).
        self.frame = np.empty(n * 3 // 2, np.uint8) if frame is None else frame
        self.y = self.frame[:n].reshape(height, width)
        self.y_flat = self.frame[:n]
        self.uv = self.frame[n:].reshape(2, height // 2, width // 2)
        self.u_flat, self.v_flat = self.frame[n : n + n // 4], self.frame[n + n // 4 :]
        self.quad = np.array([0, 1, width, width + 1])  # a 2x2 block's pixels from its top left
        self.parents = np.asarray(parents)
        self._bones(joint_names, hide, thin)
        self.head = head_joint(joint_names)
        self.circle = Path.unit_circle()
        self.line = style.bone_width * height
        self.gcs = {}
        colours = {
            "shadow": (style.shadow,) * 3,
            "head": style.centre,
            "centre": style.centre,
            "left": style.left,
            "right": style.right,
        }
        for key in ("shadow", "head", *self.sides):
            gc = self.renderer.new_gc()
            gc.set_foreground(colours[key[0] if isinstance(key, tuple) else key])
            gc.set_linewidth(self.line * (style.thin if isinstance(key, tuple) and key[1] else 1.0))
            gc.set_antialiased(True)
            gc.set_capstyle("round")
            gc.set_joinstyle("round")
            self.gcs[key] = gc
        self.blank_y, self.grid_alpha = _background(camera, style, width, height)
        # The floor kept, and the look-at point it was drawn from: the point stays put while the body stays within
        # the camera's lag (a study's item cameras, two people, a figure in place), and each such frame starts from
        # a copy of that floor instead of drawing its grid again (the same bytes, about a third of the frame's
        # time: bench/RESULTS.md, rendering). A floor is kept once a point comes twice in a row, so a camera that
        # moves every frame pays no copy.
        self.floor_y, self.floor_at, self.last_at = np.empty_like(self.blank_y), None, None
        # Floor lines are clipped in camera space (x, y, z) to depth >= NEAR and to image columns [0, width-2]
        # and rows [0, height-2], so that both pixels of every Wu sample are inside the plane:
        # column = cx + f x / z, row = height - cy - f y / z.
        (cx, cy), f = self.proj.centre, self.proj.focal
        self.frustum = np.array(
            [[0, 0, 1, -NEAR], [f, 0, cx, 0], [-f, 0, width - 2 - cx, 0], [0, -f, height - cy, 0], [0, f, cy - 2, 0]],
            np.float64,
        )
        self.grid_y = grey_to_y(style.grid)
        self.solid = SolidBody((width, height), self.proj.focal, style.solid_grid) if style.body == "solid" else None
        if self.solid:
            self._capsules()
        self.mesh, self.meshes = None, meshes  # (mesh: a MeshPainter, made when this thread first draws vertices)
        if style.body == "mesh" and not meshes:
            raise RenderError(f"the mesh style draws {MESH_INPUTS}; other motion can use stick or solid")
        self.mesh_blocks = None  # (set by _mesh_figure on a grid of 2: the body's blocks, colours and cover)

    def mesh_painter(self):
        """A MeshPainter for this drawer's person, for the calling thread (rendering.render's skinning thread draws
        the next frames' meshes with one while this drawer composes the frame before)."""
        # On a grid of 2 a quarter of the pixels are drawn, each one 2x2 block of the frame (as the solid body's).
        frame, style = (self.width, self.height), self.style
        return MeshPainter(self.meshes[0], frame, self.proj, style.mesh_colour, style.mesh_grid)

    def close(self):
        """Free what the drawer holds beyond memory (the mesh body's GL objects)."""
        if self.mesh is not None:
            self.mesh.release()
            self.mesh = None

    def _capsules(self):
        """The solid body's capsules (self.bone_ends' bones, then the head's sphere): radii and colours."""
        colour = {"left": self.style.left, "right": self.style.right, "centre": self.style.centre}
        n = len(self.bone_ends)
        self.capsule_radius = np.full(n + 1, self.style.sphere_radius)
        self.capsule_colour = np.tile(np.array(self.style.centre, np.float32), (n + 1, 1))
        for (side, thin), (bones, _) in self.sides.items():
            limb = self.style.limb_radius if side != "centre" else self.style.trunk_radius
            self.capsule_radius[bones] = self.style.thin_radius if thin else limb
            self.capsule_colour[bones] = colour[side]
        # A bone's capsule needs no round end at its parent joint where a bone at least as thick ends there.
        end_radius = np.zeros(len(self.parents))
        np.maximum.at(end_radius, self.bone_ends[:, 0], self.capsule_radius[:n])
        self.capsule_capped = np.append(end_radius[self.bone_ends[:, 1]] < self.capsule_radius[:n], True)

    def _bones(self, joint_names, hide, thin):
        """The bones to draw (child, parent) grouped by (side, thin), each group one slice of self.bone_ends."""
        parents, names = self.parents, list(joint_names)
        hidden = {j for j, n in enumerate(names) if n in set(hide)}
        hidden |= set(skeleton_names.root_markers(names, parents))
        child = np.array([j for j in np.nonzero(parents >= 0)[0] if j not in hidden and parents[j] not in hidden])
        child = child.astype(np.int64)
        sides = [skeleton_names.side(names[j]) for j in child]
        bone_side = np.array([{"left": -1, "right": 1}.get(s, 0) for s in sides], dtype=np.int64)
        detail = set(thin) if thin is not None else {n for n in names if skeleton_names.is_detail(n)}
        bone_thin = np.array([names[j] in detail for j in child], dtype=np.int64)
        # Bones ordered left, centre, right (thick, then thin within a side), so that each group's bones are one
        # slice of the projected ends.
        group = 2 * (bone_side + 1) + bone_thin
        order = np.argsort(group, kind="stable")
        self.bone_ends = np.stack([child, parents[child]], 1).reshape(-1, 2)[order]
        # The joints drawn, which must be in front of the camera: a hidden root marker may pass behind it.
        self.drawn = np.unique(self.bone_ends)
        self.codes = np.tile(np.array([Path.MOVETO, Path.LINETO], dtype=Path.code_type), len(child))
        keys = [(s, t) for s in ("left", "centre", "right") for t in (False, True)]
        counts = [int((group == g).sum()) for g in range(6)]
        edges = np.cumsum([0] + counts)
        # (side, thin) -> (its bones' slice, its path codes), for the groups that have bones
        self.sides = {
            key: (slice(edges[g], edges[g + 1]), self.codes[: 2 * counts[g]]) for g, key in enumerate(keys) if counts[g]
        }

    def _grid(self, target, eye):
        s, r = self.style.grid_spacing, self.style.grid_radius
        # World-fixed lines x = k s and z = k s, each only where it crosses the disc of radius r around the
        # look-at point (the grid fades out there: see _background).
        xs = np.arange(np.ceil((target[0] - r) / s), np.floor((target[0] + r) / s) + 1) * s
        zs = np.arange(np.ceil((target[2] - r) / s), np.floor((target[2] + r) / s) + 1) * s
        hx = np.sqrt(np.maximum(r * r - (xs - target[0]) ** 2, 0))  # half-chord of each line
        hz = np.sqrt(np.maximum(r * r - (zs - target[2]) ** 2, 0))
        a = np.concatenate([np.stack([xs, 0 * xs, target[2] - hx], 1), np.stack([target[0] - hz, 0 * zs, zs], 1)])
        b = np.concatenate([np.stack([xs, 0 * xs, target[2] + hx], 1), np.stack([target[0] + hz, 0 * zs, zs], 1)])
        a, b = clip_to_frustum(self.proj.to_camera(a, eye), self.proj.to_camera(b, eye), self.frustum)
        edge = np.array([self.width - 2, self.height - 2])
        a, b = (np.clip(self._rows(self.proj.to_screen(p)), 0, edge) for p in (a, b))
        _wu_lines(self.y_flat, self.width, a, b, self.grid_y, self.grid_alpha)

    def _rows(self, xy):
        """Agg display coordinates (y up) -> image (column, row)."""
        return xy * np.array([1.0, -1.0]) + np.array([0.0, self.height])

    def _figure(self, joints, eye, vertices=None):
        """Draw shadow, bones and head with Agg (on the cleared buffer); returns the screen points drawn and
        the head radius."""
        r, t = self.renderer, IdentityTransform()
        cam = self.proj.to_camera(joints, eye)
        scam = cam - self.proj.rot[:, 1] * joints[:, 1:2]  # the joints dropped onto the floor
        points, radius = [], 0.0
        if (scam[self.drawn, 2] > NEAR).all():
            seg = self.proj.to_screen(scam[self.bone_ends])
            r.draw_path(self.gcs["shadow"], Path(seg.reshape(-1, 2), self.codes), t)
            points.append(seg.reshape(-1, 2))
        if self.style.body == "mesh":
            return self._mesh_figure(vertices[0], eye, points)
        if self.solid is not None and (cam[self.drawn, 2] > NEAR).all():
            return self._solid_figure(joints, cam, eye, points)
        if (cam[self.drawn, 2] > NEAR).all():
            seg = self.proj.to_screen(cam[self.bone_ends])
            points.append(seg.reshape(-1, 2))
            depth = cam[self.bone_ends, 2]
            d_side = {
                side: np.mean([depth[b].mean() for (s, _), (b, _) in self.sides.items() if s == side] or [0.0])
                for side in ("left", "right")
            }
            # Painter's order: the farther limb side first, then the trunk, then the nearer side.
            order = ("left", "centre", "right") if d_side["left"] >= d_side["right"] else ("right", "centre", "left")
            for key in [(side, thin) for side in order for thin in (False, True)]:
                if key in self.sides:
                    bones, codes = self.sides[key]
                    r.draw_path(self.gcs[key], Path(seg[bones].reshape(-1, 2), codes), t)
            if self.head is not None and self.parents[self.head] >= 0:
                # Head: a disc of fixed size in metres, just beyond the head joint along the neck bone.
                neck = joints[self.head] - joints[self.parents[self.head]]
                centre = joints[self.head] + self.style.head_radius * neck / max(np.linalg.norm(neck), 1e-6)
                hc = self.proj.to_camera(centre, eye)
                if hc[2] > NEAR:
                    radius = self.proj.focal * self.style.head_radius / hc[2]
                    centre = self.proj.to_screen(hc)
                    disc = Path(self.circle.vertices * radius + centre, self.circle.codes)
                    r.draw_path(self.gcs["head"], disc, t, rgbFace=self.style.centre)
                    points.append(centre[None])
        return (np.concatenate(points) if points else np.zeros((0, 2))), radius

    def _solid_figure(self, joints, cam, eye, points):
        """The solid body (rendering.solid) over the shadow: the bones' capsules and the head's sphere, just
        beyond the head joint along the neck. Returns what _figure does."""
        a, b = cam[self.bone_ends[:, 0]], cam[self.bone_ends[:, 1]]
        radii, colours, capped = self.capsule_radius, self.capsule_colour, self.capsule_capped
        if self.head is not None and self.parents[self.head] >= 0:
            neck = joints[self.head] - joints[self.parents[self.head]]
            centre = joints[self.head] + 0.8 * self.style.sphere_radius * neck / max(np.linalg.norm(neck), 1e-6)
            hc = self.proj.to_camera(centre, eye)[None]
            a, b = np.concatenate([a, hc]), np.concatenate([b, hc])
        else:
            radii, colours, capped = radii[:-1], colours[:-1], capped[:-1]
        keep = (a[:, 2] > NEAR) & (b[:, 2] > NEAR)
        box = self.solid.draw(
            None if self.solid.scale == 2 else self.rgba.reshape(-1, 4),
            a[keep],
            b[keep],
            radii[keep],
            colours[keep],
            lambda p: self._rows(self.proj.to_screen(p)),
            capped[keep],
        )
        if box is not None:
            points.append(self._rows(np.array(box, np.float64)))
        return (np.concatenate(points) if points else np.zeros((0, 2))), 0.0

    def _mesh_figure(self, person, eye, points):
        """The mesh body (rendering.mesh) over the shadow: the person's vertices [V, 3] (world) in the style's
        colour, or their Painted frame (drawn ahead on another thread), composited over the Agg buffer in the body's
        box. Returns what _figure does."""
        if not isinstance(person, Painted):
            if self.mesh is None:
                self.mesh = self.mesh_painter()
            person = self.mesh(person, None, eye)
        if person.blocks is not None:  # on a grid of 2: blocks written straight into the planes (_blend_blocks)
            self.mesh_blocks = person.blocks
        elif person.rgba is not None:
            c0, r0, c1, r1 = person.box
            over(self.rgba[r0:r1, c0:c1], person.rgba)
            points.append(self._rows(np.array([[c0, r0], [c1, r1]], np.float64)))
        return (np.concatenate(points) if points else np.zeros((0, 2))), 0.0

    def draw(self, joints, target, vertices=None):
        """Render one frame (joints [J, 3], look-at target [3]; with the mesh style, `vertices`: the person's
        [V, 3] in the joints' world, or their Painted frame, in a list); returns the yuv420p frame (flat uint8
        view)."""
        self.background(target)
        return self.add_figure(joints, target, vertices)

    def background(self, target):
        """Start a frame: the sky, the floor and its grid seen from the look-at point `target` [3]."""
        self.uv.fill(128)
        at = np.asarray(target, np.float64).tobytes()
        if at == self.floor_at:
            np.copyto(self.y, self.floor_y)
        else:
            np.copyto(self.y, self.blank_y)
            self._grid(target, target + self.proj.offset)
            if at == self.last_at:
                np.copyto(self.floor_y, self.y)
                self.floor_at = at
        self.last_at = at

    def depth(self, joints, target):
        """How far the body (joints [J, 3], their mean) is in front of the camera looking at `target`: the farther
        of two people is drawn first."""
        return float(self.proj.to_camera(joints.mean(0), target + self.proj.offset)[2])

    def add_figure(self, joints, target, vertices=None):
        """Draw the body (joints [J, 3]; with the mesh style also its vertices, as `draw` takes them) over what the
        frame holds, seen from the look-at point `target` [3]; returns the yuv420p frame."""
        eye = target + self.proj.offset
        if self.solid is not None:
            self.solid.blocks = None  # (set by _figure where it draws the solid body on a grid of 2)
        self.mesh_blocks = None
        points, radius = self._figure(joints, eye, vertices)
        if len(points):
            # The figure's bounding box in image rows/columns, on even pixels (for the 2x2 chroma blocks).
            pad = radius + self.line + 2
            xy, edge = self._rows(points), np.array([self.width, self.height])
            c0, r0 = (np.floor((xy.min(0) - pad) / 2) * 2).clip(0, edge).astype(int)
            c1, r1 = (np.ceil((xy.max(0) + pad) / 2) * 2).clip(0, edge).astype(int)
            if c1 > c0 and r1 > r0:
                self._blend(r0, r1, c0, c1)
        if self.solid is not None and self.solid.blocks is not None:
            self._blend_blocks(*self.solid.blocks)
        if self.mesh_blocks is not None:
            self._blend_blocks(*self.mesh_blocks)
        return self.frame

    def _blend_blocks(self, blocks, rgb, cover):
        """Composite a body drawn on a grid of 2 over the planes: each of its pixels [M] (a 2x2 block's index, as the
        chroma planes count them) of colour `rgb` [M, 3] (0-255) and its frame pixels' coverage `cover` [M, 4] (in
        self.quad's order; the solid body's), or [M] (one for the whole block: the mesh body's)."""
        br, bc = np.divmod(blocks, self.width // 2)
        luma = rgb @ TO_Y + np.float32(16.5)
        if cover.ndim == 1:
            whole, block_cover = cover >= 1, cover
        else:
            c0, c1, c2, c3 = cover.T  # (an axis-1 reduction over 4 is slow in numpy)
            whole = np.minimum(np.minimum(c0, c1), np.minimum(c2, c3)) >= 1
            block_cover = (c0 + c1 + c2 + c3) * np.float32(0.25)
        pairs = self.y_flat.view(np.uint16)  # a block's two pixels in a row are one word
        top = (self.width * br + bc)[whole]
        pairs[top] = pairs[top + self.width // 2] = luma[whole].astype(np.uint16) * 257
        part = np.flatnonzero(~whole)
        idx = (2 * self.width * br[part] + 2 * bc[part])[:, None] + self.quad
        y = self.y_flat[idx].astype(np.float32)
        part_cover = cover[part, None] if cover.ndim == 1 else cover[part]
        blend = y + part_cover * (luma[part, None] - np.float32(0.5) - y) + np.float32(0.5)
        self.y_flat[idx] = blend.astype(np.uint8)
        for plane, to in ((self.u_flat, TO_U), (self.v_flat, TO_V)):
            old = plane[blocks].astype(np.float32)
            plane[blocks] = (old + block_cover * (rgb @ to + 128 - old) + np.float32(0.5)).astype(np.uint8)

    def _blend(self, r0, r1, c0, c1):
        """Composite the Agg figure (straight alpha) over the planes in the 2x2 blocks it touched inside rows
        r0:r1, columns c0:c1 (even bounds), and clear those blocks of the Agg buffer for the next frame."""
        box = self.px[r0:r1, c0:c1]
        pairs = box[0::2] | box[1::2]  # two rows in one: [h/2, w] words
        blocks = np.flatnonzero(pairs.view(np.uint64) != 0)  # 2x2 blocks with any drawn pixel
        if len(blocks) == 0:
            return
        br, bc = np.divmod(blocks, (c1 - c0) // 2)
        br += r0 // 2
        bc += c0 // 2
        idx = (2 * self.width * br + 2 * bc)[:, None] + self.quad  # [N, 4] flat pixel indices
        px = self.px_flat[idx]
        self.px_flat[idx] = 0
        px = px.view(np.uint8).reshape(4 * len(blocks), 4).astype(np.float32)
        a = px[:, 3] * np.float32(1 / 255)
        y = self.y_flat[idx].reshape(-1).astype(np.float32)
        self.y_flat[idx] = (y + a * (px @ RGBA_TO_Y + 16 - y) + np.float32(0.5)).astype(np.uint8).reshape(-1, 4)
        # Over the grey background (chroma 128) the chroma is 128 + a * (the figure's), averaged per 2x2 block:
        # one product of the block's 4 alpha-weighted RGBA pixels [N, 16] with the stacked chroma rows [16, 2].
        c = (px * a[:, None]).reshape(-1, 16) @ BLOCK_TO_UV + np.float32(128.5)
        b = br * (self.width // 2) + bc
        self.u_flat[b] = c[:, 0].astype(np.uint8)
        self.v_flat[b] = c[:, 1].astype(np.uint8)

    def rgb(self, half=False):
        """The current frame as RGB [height, width, 3] (for contact sheets and tests); with `half`, at half the
        width and height (yuv.yuv_to_rgb)."""
        return yuv_to_rgb(self.frame, (self.width, self.height), half)


def head_joint(names):
    """Index of the head joint (its last name token is 'head': Head, mixamorig:Head, b_head), or None."""
    for j, name in enumerate(names):
        words = skeleton_names.tokens(name)
        if words and words[-1] == "head":
            return j
    return None


@functools.lru_cache(maxsize=4)
def _background(camera, style, width, height):
    """The blank luma plane [height, width] (sky, a grey floor disc fading out around the look-at point) and the
    grid's alpha map (flat), both read-only; cached, since every clip of a run shares them.

    The camera's x axis is horizontal, so a pixel row's ray has one downward slope: the distance along the
    ray to the floor depends on the row alone, and the floor point (relative to the look-at point) is
    affine in the column within a row.
    """
    proj = Projector(camera, width, height)
    right, up, fwd = proj.rot
    xc = (np.arange(width) + 0.5 - proj.centre[0]) / proj.focal  # per column
    yc = (height - (np.arange(height) + 0.5) - proj.centre[1]) / proj.focal  # per row
    ray_y = yc * up[1] + fwd[1]
    down = ray_y < -1e-9
    t = np.where(down, (proj.offset[1] + camera.height) / np.where(down, -ray_y, 1.0), 0.0)
    hx = proj.offset[0] + t * (yc * up[0] + fwd[0])
    hz = proj.offset[2] + t * (yc * up[2] + fwd[2])
    hit_x = (hx[:, None] + (t * right[0])[:, None] * xc[None]).astype(np.float32)
    hit_z = (hz[:, None] + (t * right[2])[:, None] * xc[None]).astype(np.float32)
    dist = np.sqrt(hit_x * hit_x + hit_z * hit_z)
    dist[~down] = np.inf
    r = np.float32(style.grid_radius)
    floor_a = np.clip((1.2 * r - dist) / (0.6 * r), 0, 1)
    grid_a = np.clip((r - dist) / (0.5 * r), 0, 1)
    grey = style.background + floor_a * np.float32(style.floor - style.background)
    blank = np.round(grey_to_y(grey)).astype(np.uint8)
    grid_a = grid_a.reshape(-1)
    blank.flags.writeable = grid_a.flags.writeable = False
    return blank, grid_a
