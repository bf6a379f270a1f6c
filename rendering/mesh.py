"""The mesh body: an SMPL-family skinned mesh, smooth-shaded, one plain colour per person, the face under a mask.

GENEA's studies show raters a skinned body, not a stick figure (the 2026 challenge renders the SMPL-H mesh with a
plain mask over the face, since its data has no facial animation). The vertices come from the body model's own
skinning (generation.data.skinning); this module draws them.

It draws with OpenGL through moderngl on a headless EGL context: on a machine without a GPU, Mesa's llvmpipe
rasterises on the CPU's cores; where a GPU driver is installed, the same code runs on it. bench/bench_render_mesh.py
measured it against pyrender over OSMesa and against the project's own rasteriser extended to triangles (RESULTS
`mesh-body`). Per frame the vertices (camera coordinates) and their normals (the mean of the faces' around each
vertex, one sparse product) are uploaded, drawn with a depth test into a window the size of the body's box, its
silhouette antialiased by an edge pass (antialias) on the read-back box, for FrameDrawer to composite over the
floor.

The shading is the solid body's (rendering.solid: Lambert from a light above, left and in front, over an ambient
term), so an arm in front of the chest is lit apart from it and drawn in front of it by the depth test. Vertices
flagged `mask` take the mask's plain colour, unlit but for a faint shade, so the face reads as one plain shape.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass

import numpy as np

from moglow_eval.core.clip import MAX_MESH_VERTICES

from .camera import frame_size
from .errors import RenderError
from .solid import AMBIENT, DIFFUSE, LIGHT

NEAR_PLANE, FAR_PLANE = 0.05, 100.0  # metres: the depth range of the mesh's projection
WINDOW_STEP = 64  # pixels: the drawn window's sides are multiples of this
MASK_COLOUR = (0.93, 0.84, 0.72)  # a plain light mask over the face, as GENEA 2026 covers it: no features
# Mesa's llvmpipe rasterises on as many threads as there are cores unless told otherwise; here the other cores
# already skin, compose and encode (and a render pool runs a process per core), and drawing in the calling thread
# made whole clips faster on 2 cores (RESULTS mesh-body). A GPU driver ignores it. Library code sets no environment
# variable: the commands that draw (python -m rendering, generation.make_stimuli) and the render workers'
# initialiser set these before any context is made (set_gl_environment), and a user's own setting wins.
GL_ENVIRONMENT = {"LP_NUM_THREADS": "0"}

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


# The edge pass (antialias): the body drawn once per pixel (multisampling costs llvmpipe two to three times the
# whole draw), then each pixel's coverage is its 3x3 neighbourhood's (weights 1 2 1 / 2 4 2 / 1 2 1), and a pixel just
# outside takes its covered neighbours' colour: the silhouette is antialiased over about a pixel, as the solid body's
# and Agg's are. In numpy on the read-back box: as a second GL pass over the box it cost llvmpipe more than the body.


@dataclass(frozen=True)
class Mesh:
    """What the mesh body needs of a person's body model: its triangles [F, 3] (vertex indices) and which of its
    vertices the face mask covers [V] (bool; none for face = "none"). Any object with these two attributes will do
    (generation.data.skinning.MeshSource is one)."""

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
            _CONTEXT.egl = bool(kw)
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


def egl_read_pixels():
    """glReadPixels of the thread's GL context as a ctypes function (EGL's pointer to it), or None where the context
    is not EGL's or EGL gives none. ctypes lets go of the GIL for the call, and the call is where llvmpipe
    rasterises the frame (it draws in the calling thread: GL_ENVIRONMENT): moderngl's own read holds the GIL
    throughout, so no other thread of the process (the other person's mesh, the composing thread) ran meanwhile."""
    if not getattr(_CONTEXT, "egl", False):
        return None
    if "read" not in _EGL:
        import ctypes

        try:
            egl = ctypes.CDLL("libEGL.so.1")
            egl.eglGetProcAddress.restype = ctypes.c_void_p
            egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
            address = egl.eglGetProcAddress(b"glReadPixels")
        except (OSError, AttributeError):
            address = None
        c = ctypes
        signature = c.CFUNCTYPE(None, c.c_int, c.c_int, c.c_int, c.c_int, c.c_uint, c.c_uint, c.c_void_p)
        _EGL["read"] = signature(address) if address else None
    return _EGL["read"]


_EGL = {}  # the process's EGL glReadPixels (egl_read_pixels), looked up once
GL_RGBA, GL_UNSIGNED_BYTE = 0x1908, 0x1401


def set_gl_environment():
    """GL_ENVIRONMENT into this process's environment, where the user has not set them: for a command's `main` or a
    worker process's initialiser only, never from a library call."""
    for name, value in GL_ENVIRONMENT.items():
        os.environ.setdefault(name, value)


def closed(faces):
    """Whether a mesh is closed and consistently wound: every edge a -> b of a face is b -> a in exactly one other.
    Only then can its back faces be culled (about half the triangles: llvmpipe drew a frame in 0.6 of the time)
    without opening a hole where its inside shows."""
    f = np.asarray(faces, np.int64)
    a = f.reshape(-1)
    b = f[:, [1, 2, 0]].reshape(-1)
    n = int(f.max()) + 1
    forward, backward = np.sort(a * n + b), np.sort(b * n + a)
    return bool((np.diff(forward) > 0).all() and np.array_equal(forward, backward))


def signed_volume(vertices, faces):
    """The mesh's signed volume (positive when its faces wind counter-clockwise seen from outside in a right-handed
    frame): which of its faces' sides is the front."""
    a, b, c = (vertices[faces[:, k]].astype(np.float64) for k in range(3))
    return float(np.einsum("ij,ij->", a, np.cross(b, c))) / 6.0


def vertex_normals(vertices, faces, op):
    """Vertex normals [T, V, 3] float32 (unnormalised: the shader normalises) of frames of vertices [T, V, 3]: the
    area-weighted sum of the faces' around each vertex, outward for faces wound counter-clockwise seen from
    outside. A chunk of frames at once, [V, 3, T] in memory (each face's corners gathered once for every frame, each
    product along contiguous frames, one sparse product): a frame at a time took ten times as long, [V, T, 3] twice
    as long. Computed beside the drawing, where the skinning is."""
    frames = len(vertices)
    v = np.ascontiguousarray(np.asarray(vertices, np.float32).transpose(1, 2, 0))  # [V, 3, T]
    a = v[faces[:, 0]]
    e1, e2 = v[faces[:, 1]] - a, v[faces[:, 2]] - a
    n = np.empty_like(e1)  # e1 x e2, written out: np.cross copies its inputs
    n[:, 0] = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
    n[:, 1] = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
    n[:, 2] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    summed = np.asarray(op @ n.reshape(len(faces), -1), np.float32).reshape(-1, 3, frames)  # [V, 3, T]
    return summed.transpose(2, 0, 1)


def vertex_normals_operator(faces, n_vertices):
    """A sparse [V, F] matrix that sums each vertex's faces' (area-weighted) normals: normals = op @ face_normals."""
    from scipy.sparse import csr_matrix

    rows = faces.reshape(-1)
    cols = np.repeat(np.arange(len(faces)), 3)
    return csr_matrix((np.ones(len(rows), np.float32), (rows, cols)), shape=(n_vertices, len(faces)))


class MeshBody:
    """Draws one or more people's meshes into a frame of `size` pixels (a side, or (width, height)) seen through a
    pinhole of `focal` pixels (rendering.camera.Projector's), each person in one plain colour.

    `draw(people)`: people is a list of (camera-space vertices [V, 3], colour rgb 0..1[, their normals [V, 3] in
    camera axes: vertex_normals' rotated into the camera's; computed here when not given]); returns (rgba, box)
    where rgba is [h, w, 4] uint8 of the frame's box (column0, row0, column1, row1), alpha 255 where the body is
    drawn and all 0 elsewhere, for grid_blocks or straight to antialias; or (None, None) when no person is in front
    of the camera."""

    def __init__(self, meshes, size, focal):
        for m in meshes:
            if len(m.mask) > MAX_MESH_VERTICES or not len(m.faces):
                raise RenderError(
                    f"a mesh of {len(m.mask)} vertices and {len(m.faces)} faces (at most {MAX_MESH_VERTICES})"
                )
            if m.faces.min() < 0 or m.faces.max() >= len(m.mask):
                raise RenderError(f"a mesh's faces index vertices outside its {len(m.mask)}")
        self.width, self.height = frame_size(size)
        self.focal = float(focal)
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
            state = {"colour": None, "closed": closed(faces), "front": None}
            self.people.append((m, faces, vertex_normals_operator(faces, len(m.mask)), pos, nrm, col, vao, state))
        self.windows = {}  # (width, height) -> the body's framebuffer
        self.read_pixels = egl_read_pixels()

    def window(self, w, h):
        """The framebuffers the body's box is drawn in, of at least w x h pixels (rounded up to WINDOW_STEP, so
        that a box that grows or shrinks a little reuses them): drawing, resolving and reading only the box costs a
        fraction of the whole frame."""
        key = (-(-w // WINDOW_STEP) * WINDOW_STEP, -(-h // WINDOW_STEP) * WINDOW_STEP)
        if key not in self.windows:
            ctx = self.ctx
            self.windows[key] = ctx.framebuffer(
                color_attachments=[ctx.renderbuffer(key, 4)], depth_attachment=ctx.depth_renderbuffer(key)
            )
        return key, self.windows[key]

    def release(self):
        """Free the GL objects (the context stays, for the next clip of this thread)."""
        for _, _, _, pos, nrm, col, vao, _ in self.people:
            for obj in (vao, pos, nrm, col):
                obj.release()
        for body in self.windows.values():
            body.release()
        self.prog.release()

    def box(self, cams):
        """The frame's pixel box (column0, row0, column1, row1; even, clipped) the people's vertices project into,
        or None."""
        lo, hi = [], []
        for cam in cams:
            front = cam if cam[:, 2].min() > NEAR_PLANE else cam[cam[:, 2] > NEAR_PLANE]
            if len(front):
                # Column by column: numpy's least and most down the two columns of one [V, 2] array took twenty
                # times as long.
                x, y = front[:, 0] / front[:, 2], front[:, 1] / front[:, 2]
                lo.append((x.min(), y.min()))
                hi.append((x.max(), y.max()))
        if not lo:
            return None
        xy = self.focal * np.array([np.min(lo, 0), np.max(hi, 0)], np.float64)  # [[x, y] least, [x, y] most]
        half_w, half_h = self.width / 2, self.height / 2
        c0, c1 = xy[0, 0] + half_w, xy[1, 0] + half_w
        r0, r1 = half_h - xy[1, 1], half_h - xy[0, 1]  # rows grow downwards
        lo = np.floor(np.array([c0, r0]) / 2 - 1) * 2
        hi = np.ceil(np.array([c1, r1]) / 2 + 1) * 2
        edge = np.array([self.width, self.height])
        c0, r0 = np.clip(lo, 0, edge).astype(int)
        c1, r1 = np.clip(hi, 0, edge).astype(int)
        return (c0, r0, c1, r1) if c1 > c0 and r1 > r0 else None

    def draw(self, people):
        cams = [np.asarray(person[0], np.float32) for person in people]
        box = self.box(cams)
        if box is None:
            return None, None
        ctx = self.ctx
        c0, r0, c1, r1 = box
        w, h = c1 - c0, r1 - r0
        (ww, wh), body = self.window(w, h)
        # The window's pixel (0, 0) is the box's bottom-left corner (GL counts rows from the bottom): a camera
        # point at frame pixel (column, row) lands at window pixel (column - c0, height - row - (height - r1)).
        half_w, half_h = self.width / 2, self.height / 2
        self.prog["focal"].value = (self.focal / (ww / 2), self.focal / (wh / 2))
        shift = ((c0 + ww / 2 - half_w) / (ww / 2), ((self.height - r1) + wh / 2 - half_h) / (wh / 2))
        self.prog["shift"].value = shift
        body.use()
        ctx.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        for (m, faces, op, pos, nrm, col, vao, state), cam, person in zip(self.people, cams, people):
            colour, normals = person[1], (person[2] if len(person) > 2 else None)
            if cam.shape != (len(m.mask), 3):
                raise RenderError(f"a person's vertices are {cam.shape}, their mesh has {len(m.mask)}")
            if normals is None:
                # Camera axes are a mirror of the world's (x right, y up, z away), so the outward normal of a face
                # wound counter-clockwise in the world is (c - a) x (b - a) here: vertex_normals' reversed.
                normals = -vertex_normals(cam[None], faces, op)[0]
            pos.write(np.ascontiguousarray(cam))
            nrm.write(np.ascontiguousarray(normals, np.float32))
            if state["colour"] != tuple(colour):  # the colours change only with the person's colour
                rgba = np.empty((len(m.mask), 4), np.float32)
                rgba[:, :3] = colour
                rgba[:, 3] = m.mask
                col.write(rgba.tobytes())
                state["colour"] = tuple(colour)
            if state["closed"] and state["front"] is None:
                # Which winding faces the camera, from the mesh's signed volume in camera axes (a mirror of the
                # world's: a mesh wound counter-clockwise outside has a negative one here, and its front faces
                # wind counter-clockwise on the screen). Left undecided while the mesh has no volume.
                volume = signed_volume(cam, faces)
                if abs(volume) > 1e-9:
                    state["front"] = "ccw" if volume < 0 else "cw"
            if state["front"] is not None:
                ctx.front_face = state["front"]
                ctx.enable(ctx.CULL_FACE)
            vao.render()
            ctx.disable(ctx.CULL_FACE)
        ctx.disable(ctx.DEPTH_TEST)
        if self.read_pixels is None:
            raw = body.read(viewport=(0, 0, w, h), components=4, alignment=1)
            return np.frombuffer(raw, np.uint8).reshape(h, w, 4)[::-1], box  # drawn (alpha 255) or not; rows from top
        rgba = np.empty((h, w, 4), np.uint8)  # rows of w * 4 bytes: packed at any GL_PACK_ALIGNMENT
        self.read_pixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, rgba.ctypes.data)  # the bound framebuffer's
        return rgba[::-1], box


def antialias(body):
    """The edge pass (see above) of a body drawn once per pixel (rgba [h, w, 4] uint8: alpha 255 where drawn, all 0
    elsewhere) -> (rows, columns, rgb [M, 3] float32 0-255, cover [M] float32 0-1) of the pixels it covers at all:
    each pixel's cover its 3x3 neighbourhood's weighted coverage, a pixel outside taking the weighted mean colour of
    its drawn neighbours. Beyond the box's sides the pixels repeat the side's (empty, or the frame's edge cutting
    the body, which stays covered there). Pixels as one word each, found and gathered by flat index: numpy's
    fastest."""
    h, w = body.shape[:2]
    words = np.empty((h + 2, w + 2), np.uint32)  # the pixels, a word each, the sides repeated around them
    words[1:-1, 1:-1] = np.ascontiguousarray(body).view(np.uint32)[..., 0]
    words[0, 1:-1], words[-1, 1:-1] = words[1, 1:-1], words[-2, 1:-1]
    words[:, 0], words[:, -1] = words[:, 1], words[:, -2]
    p = (words != 0).view(np.uint8)
    across = p[:, :-2] + 2 * p[:, 1:-1] + p[:, 2:]
    cover = across[:-2] + 2 * across[1:-1] + across[2:]  # sixteenths, 0-16
    flat_at = np.flatnonzero(cover)
    rows = flat_at // w
    cols = flat_at - rows * w
    sixteenths = cover.reshape(-1)[flat_at].astype(np.float32)
    at = flat_at + 2 * rows + w + 3  # in `words`, flat: (rows + 1) * (w + 2) + cols + 1
    flat = words.reshape(-1)
    here = flat[at]
    rgb = here.view(np.uint8).reshape(-1, 4).astype(np.float32)[:, :3]  # all four bytes: ten times faster
    ring = np.flatnonzero(here == 0)  # just outside: the drawn neighbours' colour
    if len(ring):
        acc = np.zeros((len(ring), 4), np.float32)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                near = flat[at[ring] + dy * (w + 2) + dx].view(np.uint8).reshape(-1, 4)  # 0 where not drawn
                acc += (2 - abs(dx)) * (2 - abs(dy)) * near.astype(np.float32)
        rgb[ring] = acc[:, :3] / sixteenths[ring, None]
    return rows, cols, rgb, sixteenths * np.float32(1 / 16)


def grid_blocks(rgba, box, row):
    """(blocks, rgb [M, 3] 0-255, cover [M]: the whole block's) of a body drawn once per grid pixel on a grid of 2
    (rgba [h, w, 4] as MeshBody.draw gives it, at the box's (column, row) in grid pixels, rows of `row` grid
    pixels), antialiased: each grid pixel is one 2x2 block of the frame, as FrameDrawer._blend_blocks writes the
    solid body's."""
    rows, cols, rgb, cover = antialias(rgba)
    blocks = (rows + box[1]) * row + (cols + box[0])
    return blocks, rgb, cover


def straight(rgba):
    """A body drawn once per pixel (as MeshBody.draw gives it), antialiased, as straight-alpha rgba [h, w, 4]."""
    rows, cols, rgb, cover = antialias(rgba)
    out = np.zeros_like(rgba)
    out[rows, cols, :3] = (rgb + np.float32(0.5)).astype(np.uint8)
    out[rows, cols, 3] = (cover * 255 + np.float32(0.5)).astype(np.uint8)
    return out


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


@dataclass(frozen=True)
class Painted:
    """One person's mesh drawn and antialiased for one frame, as FrameDrawer composites it: on a grid of 2 the
    frame's 2x2 blocks (grid_blocks' triple); on a grid of 1 the box's straight-alpha rgba and the box; all None when
    nothing of the body is in front of the camera."""

    blocks: tuple | None
    rgba: np.ndarray | None
    box: tuple | None


class MeshPainter:
    """Draws one person's mesh frame by frame (Painted), seen through `proj` (rendering.camera.Projector) in a frame
    of `size` pixels (a side, or (width, height)), on a grid of `grid` frame pixels per drawn pixel.

    An OpenGL context belongs to a thread, so a painter is used in the thread that made it: rendering.render makes
    one on its skinning thread, where the drawing and its edge pass run beside the frame's floor, blending and
    encoding."""

    def __init__(self, mesh, size, proj, colour, grid):
        width, height = frame_size(size)
        self.body = MeshBody([mesh], (width // grid, height // grid), proj.focal / grid)
        self.proj, self.colour, self.grid, self.row = proj, tuple(colour), grid, width // 2
        self.rot = proj.rot.T.astype(np.float32)  # into camera axes, as Projector.to_camera turns points

    def vertices_and_normals(self, a, b):
        """Frames a..b of the person's mesh, as its source gives them (`vertices`: skinned there, not here), and
        their normals (vertex_normals, with the body's own operator), both [b - a, V, 3] in world axes, for
        __call__ a frame at a time."""
        mesh, faces, op = self.body.people[0][:3]
        vertices = mesh.vertices(a, b)
        return vertices, vertex_normals(vertices, faces, op)

    def __call__(self, vertices, normals, eye):
        """The person's vertices [V, 3] (world) and their normals (vertex_normals, world axes; None: computed from
        the vertices) seen from `eye` [3] -> Painted."""
        cam = (
            np.asarray(vertices, np.float32) - np.asarray(eye, np.float32)
        ) @ self.rot  # Projector.to_camera, in GL's float32
        person = (cam, self.colour) if normals is None else (cam, self.colour, normals @ self.rot)
        rgba, box = self.body.draw([person])
        if rgba is None:
            return Painted(None, None, None)
        if self.grid == 2:  # each drawn grid pixel a 2x2 block, written straight into the planes
            return Painted(grid_blocks(rgba, box, self.row), None, box)
        return Painted(None, straight(rgba), box)

    def release(self):
        self.body.release()
