"""The mesh body's drawing, piece by piece (rendering.mesh): the edge pass against its definition, back faces culled
only where the mesh is closed, a chunk's normals against each frame's, and the thread that skins and draws ahead of
the clip (rendering.render._painted): its errors reach the caller, and it serves clip after clip."""

import threading

import numpy as np
import pytest
from helpers import smpl_fixtures

from generation.data.skinning import smpl_mesh
from rendering.camera import Projector, camera_targets
from rendering.errors import RenderError
from rendering.framing import item_camera
from rendering.mesh import MeshBody, antialias, closed, straight, vertex_normals, vertex_normals_operator
from rendering.raster import STYLES
from rendering.render import RenderOptions, render_clip

MESH_64 = RenderOptions(size=64, style=STYLES["mesh"])


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    model, motion, clip = smpl_fixtures.smplh_take(tmp_path_factory.mktemp("mesh-drawing"), frames=20)
    return smpl_mesh(motion, model), clip


def camera_space(source, clip, size, frames):
    camera = item_camera([clip["joints"]], clip["joint_names"], clip["parents"], clip["fps"], "front", "full")
    proj = Projector(camera, size, size)
    targets = camera_targets(clip["joints"], clip["fps"], camera)
    verts = source.vertices(0, frames)
    return [proj.to_camera(verts[t].astype(np.float64), targets[t] + proj.offset) for t in range(frames)], proj


def test_the_edge_pass_is_the_three_by_three_kernel():
    """Each pixel's cover is the (1 2 1) x (1 2 1) / 16 weighted share of its drawn neighbours (the box's sides
    repeated beyond it), and a pixel just outside takes their weighted mean colour: checked pixel by pixel on a
    random drawing."""
    rng = np.random.default_rng(0)
    h, w = 23, 31
    body = np.zeros((h, w, 4), np.uint8)
    drawn = rng.random((h, w)) < 0.4
    body[drawn, :3] = rng.integers(1, 255, (drawn.sum(), 3))
    body[drawn, 3] = 255
    want = np.zeros_like(body)
    for y in range(h):
        for x in range(w):
            cover, acc = 0, np.zeros(3)
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    yy, xx = min(max(y + dy, 0), h - 1), min(max(x + dx, 0), w - 1)
                    if drawn[yy, xx]:
                        weight = (2 - abs(dx)) * (2 - abs(dy))
                        cover += weight
                        acc += weight * body[yy, xx, :3].astype(float)
            if cover:
                want[y, x, 3] = int(cover / 16 * 255 + 0.5)
                want[y, x, :3] = body[y, x, :3] if drawn[y, x] else (acc / cover + 0.5).astype(np.uint8)
    assert np.array_equal(straight(body), want)
    rows, cols, _, cover = antialias(body)
    assert set(zip(rows.tolist(), cols.tolist())) == set(zip(*np.nonzero(want[..., 3])))
    assert (cover > 0).all() and (cover <= 1).all()


def test_back_faces_are_culled_only_on_a_closed_body(take):
    """The synthetic SMPL-H body is closed (as SMPL's is), so its back faces are culled, and the drawing is the same
    as with them (but for a few pixels where two tubes meet at one depth); a mesh with a hole is drawn whole."""
    source, clip = take
    assert closed(source.faces)
    assert not closed(source.faces[1:])  # one triangle fewer: a hole
    cams, proj = camera_space(source, clip, 320, 3)
    body = MeshBody([source], 320, proj.focal)
    state = body.people[0][7]
    for t in range(3):
        culled, box = body.draw([(cams[t], (0.4, 0.5, 0.7))])
        culled = culled.copy()
        front = state["front"]
        assert front in ("ccw", "cw")
        state.update(closed=False, front=None)  # as an open mesh is drawn
        whole, box_whole = body.draw([(cams[t], (0.4, 0.5, 0.7))])
        state.update(closed=True)
        drawn = whole[..., 3] > 0
        assert box == box_whole and drawn.sum() > 1000
        assert (culled != whole).any(-1).sum() < 0.02 * drawn.sum()
    state.update(front="cw" if front == "ccw" else "ccw")  # the wrong side culled: the inside shows
    inside, _ = body.draw([(cams[2], (0.4, 0.5, 0.7))])
    assert (inside != whole).any(-1).sum() > 0.3 * drawn.sum()
    body.release()


def test_the_readback_is_moderngls(take):
    """The frame read back through EGL's glReadPixels (which lets the process's other threads run while llvmpipe
    rasterises) is moderngl's own read of the same framebuffer, byte for byte."""
    source, clip = take
    cams, proj = camera_space(source, clip, 320, 1)
    body = MeshBody([source], 320, proj.focal)
    assert body.read_pixels is not None  # an EGL context here
    got, box = body.draw([(cams[0], (0.4, 0.5, 0.7))])
    w, h = box[2] - box[0], box[3] - box[1]
    raw = body.window(w, h)[1].read(viewport=(0, 0, w, h), components=4, alignment=1)
    want = np.frombuffer(raw, np.uint8).reshape(h, w, 4)[::-1]
    assert np.array_equal(got, want) and (got[..., 3] == 255).sum() > 1000
    body.release()


def test_a_chunks_normals_are_each_frames(take):
    """vertex_normals over a chunk of frames at once is each frame's sum of its faces' normals."""
    source, _ = take
    verts = source.vertices(0, 5)
    faces = np.asarray(source.faces)
    op = vertex_normals_operator(faces, len(source.mask))
    got = vertex_normals(verts, faces, op)
    for t in range(5):
        a, b, c = (verts[t][faces[:, k]].astype(np.float64) for k in range(3))
        want = op @ np.cross(b - a, c - a)
        assert np.allclose(got[t], want, atol=1e-6 * np.abs(want).max())


def test_the_mesh_thread_reports_errors_and_serves_clip_after_clip(take, tmp_path):
    """An error while skinning on the mesh thread reaches render_clip's caller as itself; the next clip renders,
    skinned on the same thread (its OpenGL context made once)."""
    source, clip = take
    threads = []

    class Broken:
        faces, mask, n_frames = source.faces, source.mask, source.n_frames

        def vertices(self, a, b):
            raise RenderError("take.npz: a broken chunk")

    class Spy(Broken):
        def vertices(self, a, b):
            threads.append(threading.current_thread().name)
            return source.vertices(a, b)

    with pytest.raises(RenderError, match="a broken chunk"):
        render_clip(clip, tmp_path / "broken.mp4", MESH_64, mesh=Broken())
    for k in range(2):
        render_clip(clip, tmp_path / f"ok{k}.mp4", MESH_64, mesh=Spy())
        assert (tmp_path / f"ok{k}.mp4").stat().st_size > 0
    assert threads and len(set(threads)) == 1 and threads[0] != threading.current_thread().name


def test_a_forked_child_renders_meshes_too(take, tmp_path):
    """The mesh thread is the process's: a child forked after a mesh clip (a pool with the fork start method) makes
    its own, where it would otherwise hand its clip to a thread that does not exist there and wait for ever."""
    import os
    import time

    source, clip = take
    render_clip(clip, tmp_path / "parent.mp4", MESH_64, mesh=source)
    pid = os.fork()
    if pid == 0:  # the child: render, and leave without pytest's teardown
        try:
            render_clip(clip, tmp_path / "child.mp4", MESH_64, mesh=source)
            os._exit(0)
        except BaseException:  # noqa: BLE001 -- any failure is the child's exit status
            os._exit(3)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        time.sleep(0.05)
    else:
        os.kill(pid, 9)
        os.waitpid(pid, 0)
        pytest.fail("the forked child's mesh clip never finished")
    assert os.waitstatus_to_exitcode(status) == 0
    assert (tmp_path / "child.mp4").stat().st_size > 0
