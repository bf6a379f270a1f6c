"""The mesh body: an SMPL-family skinned mesh, smooth-shaded, one plain colour per person, the face under a mask.

GENEA's studies show raters a skinned body, not a stick figure (the 2026 challenge renders the SMPL-H mesh with a
plain mask over the face, since its data has no facial animation). The vertices come from the body model's own
skinning (generation.data.smpl_files); this module draws them.

It draws with OpenGL through moderngl on a headless EGL context: on a machine without a GPU, Mesa's llvmpipe
rasterises on the CPU's cores; where a GPU driver is installed, the same code runs on it. bench/bench_render_mesh.py
measured it against pyrender over OSMesa and against the project's own rasteriser extended to triangles (RESULTS
`mesh-body`). Per frame the vertices (camera coordinates) and their normals (the mean of the faces' around each
vertex, one sparse product) are uploaded, drawn with a depth test into a window the size of the body's box, its
silhouette antialiased by an edge pass (_EDGES), and read back as straight-alpha RGBA for FrameDrawer to composite
over the floor.

The shading is the solid body's (rendering.solid: Lambert from a light above, left and in front, over an ambient
term), so an arm in front of the chest is lit apart from it and drawn in front of it by the depth test. Vertices
flagged `mask` take the mask's plain colour, unlit but for a faint shade, so the face reads as one plain shape.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from .errors import RenderError
from .solid import AMBIENT, DIFFUSE, LIGHT

NEAR_PLANE, FAR_PLANE = 0.05, 100.0  # metres: the depth range of the mesh's projection
WINDOW_STEP = 64  # pixels: the drawn window's sides are multiples of this
MASK_COLOUR = (0.93, 0.84, 0.72)  # a plain light mask over the face, as GENEA 2026 covers it: no features
MAX_VERTICES = 200_000  # a bound on one person's mesh (SMPL-X has 10,475 vertices): beyond it, one line

_VERTEX = """
#version 330
uniform vec2 focal;  // pixels per unit of x/z and y/z, over half the drawn window
uniform vec2 shift;  // the window's centre's offset from the frame's, in the window's clip units
in vec3 in_pos;      // camera coordinates: x right, y up, z depth
in vec3 in_normal;
in vec4 in_colour;   // rgb, and 1 where the face mask covers
out vec3 normal;
out vec3 position;
out vec4 colour;
void main() {
    float z = in_pos.z;
    float a = (FAR + NEAR) / (FAR - NEAR), b = -2.0 * FAR * NEAR / (FAR - NEAR);
    gl_Position = vec4(focal.x * in_pos.x - shift.x * z, focal.y * in_pos.y - shift.y * z, a * z + b, z);
    normal = in_normal;
    position = in_pos;
    colour = in_colour;
}
"""

_FRAGMENT = """
#version 330
uniform vec3 light;   // towards the light, in camera axes (x right, y up, z away from the camera)
uniform vec3 mask;    // the mask's colour
in vec3 normal;
in vec3 position;
in vec4 colour;
out vec4 out_colour;
void main() {
    vec3 n = normalize(normal);
    if (dot(n, position) > 0.0) n = -n;  // a surface seen from inside (a sleeve, a mouth): lit as its outside
    float lit = max(dot(n, light), 0.0);
    float shade = min(AMBIENT + DIFFUSE * lit, 1.1);
    vec3 body = colour.rgb * shade;
    vec3 plain = mask * (0.92 + 0.08 * shade);
    out_colour = vec4(mix(body, plain, colour.a), 1.0);
}
"""


# The edge pass: the body drawn once per pixel (multisampling costs llvmpipe two to three times the whole draw), then
# each pixel's coverage is its 3x3 neighbourhood's (weights 1 2 1 / 2 4 2 / 1 2 1), and a pixel just outside takes its
# covered neighbours' colour: the silhouette is antialiased over about a pixel, as the solid body's and Agg's are.
_QUAD = """
#version 330
in vec2 in_xy;
void main() { gl_Position = vec4(in_xy, 0.0, 1.0); }
"""

_EDGES = """
#version 330
uniform sampler2D body;
out vec4 out_colour;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    ivec2 last = textureSize(body, 0) - 1;
    vec4 here = texelFetch(body, p, 0);
    float cover = 0.0, weight = 0.0;
    vec3 sum = vec3(0.0);
    for (int dy = -1; dy <= 1; dy++) {
        for (int dx = -1; dx <= 1; dx++) {
            float w = float((2 - abs(dx)) * (2 - abs(dy))) / 16.0;
            vec4 s = texelFetch(body, clamp(p + ivec2(dx, dy), ivec2(0), last), 0);
            cover += w * s.a;
            sum += w * s.a * s.rgb;
            weight += w * s.a;
        }
    }
    vec3 rgb = here.a > 0.0 ? here.rgb : (weight > 0.0 ? sum / weight : vec3(0.0));
    out_colour = vec4(rgb, cover);
}
"""


@dataclass(frozen=True)
class Mesh:
    """What the mesh body needs of a person's body model: its triangles [F, 3] (vertex indices) and which of its
    vertices the face mask covers [V] (bool; none for face = "none"). Any object with these two attributes will do
    (generation.data.smpl_files.MeshSource is one)."""

    faces: np.ndarray
    mask: np.ndarray


_CONTEXT = threading.local()  # one GL context per thread (a process of the render pool has one)


def gl_context():
    """The thread's headless OpenGL context (EGL; the default platform where EGL has none), made once.
    RenderError, one line, when neither gives one."""
    ctx = getattr(_CONTEXT, "ctx", None)
    if ctx is not None:
        return ctx
    try:
        import moderngl
    except ImportError:
        raise RenderError('the mesh style needs moderngl: pip install -e "." (it is a dependency)') from None
    errors = []
    for kw in ({"backend": "egl"}, {}):
        try:
            ctx = moderngl.create_context(standalone=True, require=330, **kw)
            break
        except Exception as e:  # noqa: BLE001 -- every failure of a platform is tried past and reported below
            errors.append(str(e).splitlines()[0] if str(e) else type(e).__name__)
    else:
        raise RenderError(
            "the mesh style found no OpenGL 3.3 context (EGL, then the default): "
            f"{'; '.join(errors)}; scripts/install-system-deps.sh installs Mesa's EGL"
        )
    _CONTEXT.ctx = ctx
    return ctx


def vertex_normals_operator(faces, n_vertices):
    """A sparse [V, F] matrix that sums each vertex's faces' (area-weighted) normals: normals = op @ face_normals."""
    from scipy.sparse import csr_matrix

    rows = faces.reshape(-1)
    cols = np.repeat(np.arange(len(faces)), 3)
    return csr_matrix((np.ones(len(rows), np.float32), (rows, cols)), shape=(n_vertices, len(faces)))


class MeshBody:
    """Draws one or more people's meshes into a frame of `size` pixels square seen through a pinhole of `focal`
    pixels (rendering.camera.Projector's), each person in one plain colour.

    `draw(people)`: people is a list of (camera-space vertices [V, 3], colour rgb 0..1); returns (rgba, box) where
    rgba is [h, w, 4] uint8 straight alpha of the frame's box (column0, row0, column1, row1), or (None, None) when
    no person is in front of the camera."""

    def __init__(self, meshes, size, focal):
        for m in meshes:
            if len(m.mask) > MAX_VERTICES or not len(m.faces):
                raise RenderError(f"a mesh of {len(m.mask)} vertices and {len(m.faces)} faces (at most {MAX_VERTICES})")
            if m.faces.min() < 0 or m.faces.max() >= len(m.mask):
                raise RenderError(f"a mesh's faces index vertices outside its {len(m.mask)}")
        self.size, self.focal = size, float(focal)
        self.meshes = list(meshes)
        ctx = self.ctx = gl_context()
        defines = {"FAR": FAR_PLANE, "NEAR": NEAR_PLANE, "AMBIENT": AMBIENT, "DIFFUSE": DIFFUSE}
        head = "".join(f"#define {k} {float(v)!r}\n" for k, v in defines.items())
        self.prog = ctx.program(
            vertex_shader=_VERTEX.replace("#version 330\n", "#version 330\n" + head),
            fragment_shader=_FRAGMENT.replace("#version 330\n", "#version 330\n" + head),
        )
        self.prog["light"].value = tuple(float(x) for x in LIGHT)
        self.prog["mask"].value = MASK_COLOUR
        self.people = []
        for m in self.meshes:
            faces = np.ascontiguousarray(m.faces, np.int32)
            pos = ctx.buffer(reserve=len(m.mask) * 12, dynamic=True)
            nrm = ctx.buffer(reserve=len(m.mask) * 12, dynamic=True)
            col = ctx.buffer(reserve=len(m.mask) * 16, dynamic=True)
            vao = ctx.vertex_array(
                self.prog,
                [(pos, "3f", "in_pos"), (nrm, "3f", "in_normal"), (col, "4f", "in_colour")],
                index_buffer=ctx.buffer(faces.tobytes()),
            )
            self.people.append((m, faces, vertex_normals_operator(faces, len(m.mask)), pos, nrm, col, vao, [None]))
        self.edges = ctx.program(vertex_shader=_QUAD, fragment_shader=_EDGES)
        quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], np.float32).tobytes())
        self.quad = ctx.vertex_array(self.edges, [(quad, "2f", "in_xy")])
        self.quad_buffer = quad
        self.windows = {}  # (width, height) -> (the body's framebuffer, its colour texture, the edge pass's)

    def window(self, w, h):
        """The framebuffers the body's box is drawn in, of at least w x h pixels (rounded up to WINDOW_STEP, so
        that a box that grows or shrinks a little reuses them): drawing, resolving and reading only the box costs a
        fraction of the whole frame."""
        key = (-(-w // WINDOW_STEP) * WINDOW_STEP, -(-h // WINDOW_STEP) * WINDOW_STEP)
        if key not in self.windows:
            ctx = self.ctx
            tex = ctx.texture(key, 4)
            tex.filter = (ctx.NEAREST, ctx.NEAREST)
            body = ctx.framebuffer(color_attachments=[tex], depth_attachment=ctx.depth_renderbuffer(key))
            self.windows[key] = (body, tex, ctx.framebuffer(color_attachments=[ctx.renderbuffer(key, 4)]))
        return key, self.windows[key]

    def release(self):
        """Free the GL objects (the context stays, for the next clip of this thread)."""
        for _, _, _, pos, nrm, col, vao, _ in self.people:
            for obj in (vao, pos, nrm, col):
                obj.release()
        for body, tex, out in self.windows.values():
            for obj in (body, tex, out):
                obj.release()
        for obj in (self.quad, self.quad_buffer, self.edges, self.prog):
            obj.release()

    def box(self, cams):
        """The frame's pixel box (column0, row0, column1, row1; even, clipped) the people's vertices project into,
        or None."""
        pts = []
        for cam in cams:
            front = cam[cam[:, 2] > NEAR_PLANE]
            if len(front):
                pts.append(front[:, :2] * (self.focal / front[:, 2:3]))
        if not pts:
            return None
        xy = np.concatenate(pts)
        half = self.size / 2
        c0, c1 = xy[:, 0].min() + half, xy[:, 0].max() + half
        r0, r1 = half - xy[:, 1].max(), half - xy[:, 1].min()  # rows grow downwards
        lo = np.floor(np.array([c0, r0]) / 2 - 1) * 2
        hi = np.ceil(np.array([c1, r1]) / 2 + 1) * 2
        c0, r0 = np.clip(lo, 0, self.size).astype(int)
        c1, r1 = np.clip(hi, 0, self.size).astype(int)
        return (c0, r0, c1, r1) if c1 > c0 and r1 > r0 else None

    def draw(self, people):
        cams = [np.asarray(v, np.float32) for v, _ in people]
        box = self.box(cams)
        if box is None:
            return None, None
        ctx = self.ctx
        c0, r0, c1, r1 = box
        w, h = c1 - c0, r1 - r0
        (ww, wh), (body, tex, out) = self.window(w, h)
        # The window's pixel (0, 0) is the box's bottom-left corner (GL counts rows from the bottom): a camera
        # point at frame pixel (column, row) lands at window pixel (column - c0, size - row - (size - r1)).
        half = self.size / 2
        self.prog["focal"].value = (self.focal / (ww / 2), self.focal / (wh / 2))
        self.prog["shift"].value = ((c0 + ww / 2 - half) / (ww / 2), ((self.size - r1) + wh / 2 - half) / (wh / 2))
        body.use()
        ctx.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        for (m, faces, op, pos, nrm, col, vao, last), cam, (_, colour) in zip(self.people, cams, people):
            if cam.shape != (len(m.mask), 3):
                raise RenderError(f"a person's vertices are {cam.shape}, their mesh has {len(m.mask)}")
            a, b, c = cam[faces[:, 0]], cam[faces[:, 1]], cam[faces[:, 2]]
            # Camera axes are a mirror of the world's (x right, y up, z away), so the outward normal of a face
            # wound counter-clockwise in the world is (c - a) x (b - a) here.
            normals = np.asarray(op @ np.cross(c - a, b - a), np.float32)
            pos.write(np.ascontiguousarray(cam))
            nrm.write(np.ascontiguousarray(normals))
            if last[0] != tuple(colour):  # the colours change only with the person's colour
                rgba = np.empty((len(m.mask), 4), np.float32)
                rgba[:, :3] = colour
                rgba[:, 3] = m.mask
                col.write(rgba.tobytes())
                last[0] = tuple(colour)
            vao.render()
        ctx.disable(ctx.DEPTH_TEST)
        out.use()
        tex.use(0)
        self.quad.render(ctx.TRIANGLE_STRIP)
        raw = out.read(viewport=(0, 0, w, h), components=4, alignment=1)
        return np.frombuffer(raw, np.uint8).reshape(h, w, 4)[::-1], box  # straight alpha, rows from the top


def grid_blocks(rgba, box, row):
    """(blocks, rgb [M, 3] 0-255, cover [M, 4]) of the body drawn on a grid of 2 (rgba [h, w, 4] at the box's
    (column, row) in grid pixels, rows of `row` grid pixels): each drawn grid pixel is one 2x2 block of the frame,
    as FrameDrawer._blend_blocks writes the solid body's."""
    rows, cols = np.nonzero(rgba[..., 3])
    cover = rgba[rows, cols, 3].astype(np.float32) * np.float32(1 / 255)
    blocks = (rows + box[1]) * row + (cols + box[0])
    return blocks, rgba[rows, cols, :3].astype(np.float32), np.repeat(cover[:, None], 4, 1)


def over(under, rgba):
    """Composite the body (straight-alpha rgba) over `under` (the same box of Agg's straight-alpha buffer, where
    the shadow may be), in place: a copy where nothing lies under it, "over" on the body's pixels elsewhere."""
    drawn = rgba[..., 3] != 0
    if not ((under[..., 3] != 0) & drawn).any():
        np.copyto(under, rgba, where=drawn[..., None])
        return
    new, old = rgba[drawn], under[drawn]
    am = new[:, 3:].astype(np.float32) * np.float32(1 / 255)
    au = old[:, 3:].astype(np.float32) * np.float32(1 / 255) * (1 - am)
    out_a = am + au
    rgb = (new[:, :3] * am + old[:, :3] * au) / np.maximum(out_a, np.float32(1e-6))
    under[drawn] = np.concatenate([rgb + np.float32(0.5), out_a * 255 + np.float32(0.5)], 1).astype(np.uint8)
