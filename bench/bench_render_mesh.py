"""The mesh body's renderer, chosen by measurement (issue 54): the same SMPL-H clip (a synthetic body model of the
smplx layout with about the real SMPL-H's 6890 vertices, 8 s at 30 fps, 640 px, front view, upper framing) drawn by

- the stick figure, the baseline of the target (a mesh clip within 3 times a stick clip's time, whole clips to MP4);
- `mesh`: the project's renderer (rendering.mesh: moderngl over headless EGL, Mesa's llvmpipe on this CPU), whole
  clips to MP4, and its drawing alone per frame (with its edge pass, on every pixel of the frame, as pyrender's);
- pyrender over OSMesa, what the field's visualisers use, drawing alone per frame (`--pyrender-python`: a Python
  with pyrender and PyOpenGL >= 3.1.4, e.g. a virtual environment; not a dependency of the project);
- the project's own software rasteriser extended to triangles (`triangles_numpy` below: flat shading, a z-buffer,
  numpy only, the same fragment scheme as rendering.solid), drawing alone per frame;

and the peak memory of a whole mesh clip of 8 s and of 64 s (in fresh processes), which the chunked skinning keeps
flat (`--memory`), and what the mesh clip costs a rater (`--quality`): its bitrate at the default rate control and
its PSNR and SSIM against the drawn frames (a lossless reference; bench_blind_sizes' encoder and measures). Prints
medians over repeats, each time with the load average beside it.

    PYTHONPATH=$PWD python bench/bench_render_mesh.py [--repeats 3] [--pyrender-python /tmp/pyr/bin/python]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from helpers import smpl_fixtures  # noqa: E402

from generation.data.skinning import smpl_mesh  # noqa: E402
from generation.data.smpl_files import smpl_positions  # noqa: E402
from rendering.camera import Projector, camera_targets  # noqa: E402
from rendering.framing import item_camera  # noqa: E402
from rendering.mesh import MeshBody, straight  # noqa: E402
from rendering.raster import STYLES  # noqa: E402
from rendering.render import RenderOptions, render_clip  # noqa: E402

SIZE, FPS = 640, 30.0


def make_take(folder, seconds):
    """(model, motion) files of a synthetic SMPL-H body (rings and segments chosen for about 6890 vertices)."""
    model = folder / "SMPLH_NEUTRAL.npz"
    if not model.exists():
        smpl_fixtures.write_body_model(model, "smplh", rings=7, segments=18, head_rings=22)
    motion = smpl_fixtures.write_motion(folder / f"take_{seconds}.npz", "smplh", frames=int(seconds * FPS), fps=FPS)
    return model, motion


def scene(model, motion):
    joints, names, parents, fps = smpl_positions(motion, model)
    clip = dict(joints=joints, parents=parents, joint_names=names, fps=fps)
    camera = item_camera([joints], names, parents, fps, "front", "upper")
    return clip, camera


def camera_vertices(source, clip, camera, frames):
    """Each frame's vertices in camera coordinates, as FrameDrawer hands them to the mesh body."""
    proj = Projector(camera, SIZE, SIZE)
    targets = camera_targets(clip["joints"], clip["fps"], camera)
    verts = source.vertices(0, frames)
    return [proj.to_camera(verts[t].astype(np.float64), targets[t] + proj.offset) for t in range(frames)], proj


def triangles_numpy(cam, faces, focal, size):
    """A z-buffered, flat-shaded triangle rasteriser in numpy (a lower bound on the cost of extending rendering.solid's
    scheme to triangles): every pixel of every front triangle's box a row of flat arrays, an edge-function test, the
    nearest depth per pixel by np.minimum.at. Returns the RGB frame."""
    xy = np.stack([size / 2 + focal * cam[:, 0] / cam[:, 2], size / 2 - focal * cam[:, 1] / cam[:, 2]], 1)
    a, b, c = xy[faces[:, 0]], xy[faces[:, 1]], xy[faces[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    keep = np.abs(area) > 1e-9
    a, b, c, area, f = a[keep], b[keep], c[keep], area[keep], faces[keep]
    lo = np.floor(np.minimum(np.minimum(a, b), c)).clip(0, size - 1).astype(np.int64)
    hi = np.ceil(np.maximum(np.maximum(a, b), c)).clip(0, size - 1).astype(np.int64)
    w, h = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    n = w * h
    k = np.repeat(np.arange(len(n)), n)
    i = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    px, py = lo[k, 0] + i % w[k] + 0.5, lo[k, 1] + i // w[k] + 0.5
    ak, bk, ck = a[k], b[k], c[k]
    w0 = ((bk[:, 0] - px) * (ck[:, 1] - py) - (bk[:, 1] - py) * (ck[:, 0] - px)) / area[k]
    w1 = ((ck[:, 0] - px) * (ak[:, 1] - py) - (ck[:, 1] - py) * (ak[:, 0] - px)) / area[k]
    w2 = 1 - w0 - w1
    inside = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
    k, px, py, w0, w1, w2 = k[inside], px[inside], py[inside], w0[inside], w1[inside], w2[inside]
    z = w0 * cam[f[k, 0], 2] + w1 * cam[f[k, 1], 2] + w2 * cam[f[k, 2], 2]
    flat = py.astype(np.int64) * size + px.astype(np.int64)
    zbuf = np.full(size * size, np.inf)
    np.minimum.at(zbuf, flat, z)
    front = z <= zbuf[flat]
    normal = np.cross(cam[f[:, 2]] - cam[f[:, 0]], cam[f[:, 1]] - cam[f[:, 0]])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    shade = 0.55 + 0.6 * np.abs(normal @ np.array([-0.35, 0.55, -0.76]))
    rgb = np.zeros((size * size, 3), np.uint8)
    rgb[flat[front]] = (np.outer(shade[k[front]], (107, 140, 199))).clip(0, 255).astype(np.uint8)
    return rgb.reshape(size, size, 3)


def per_frame(draw, frames, repeats):
    """The median over repeats of the mean time per frame of draw(t), in ms."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for t in range(frames):
            draw(t)
        times.append((time.perf_counter() - t0) / frames * 1000)
    return float(np.median(times))


def pyrender_per_frame(python, folder, cams, faces, focal, repeats):
    """pyrender over OSMesa in `python`, drawing the same camera-space vertices (saved to a file) per frame."""
    np.savez(folder / "cams.npz", cams=np.stack(cams).astype(np.float32), faces=faces)
    code = f"""
import os, time, json, numpy as np
os.environ["PYOPENGL_PLATFORM"] = "osmesa"
import pyrender, trimesh
d = np.load({str(folder / "cams.npz")!r}); cams, faces = d["cams"], d["faces"]
# Camera coordinates (x right, y up, z away) to OpenGL's (z towards the viewer): mirror z.
cams = cams * np.array([1, 1, -1], np.float32)
r = pyrender.OffscreenRenderer({SIZE}, {SIZE})
s = pyrender.Scene(bg_color=[0, 0, 0, 0], ambient_light=[0.5, 0.5, 0.5])
s.add(pyrender.IntrinsicsCamera({focal}, {focal}, {SIZE / 2}, {SIZE / 2}, znear=0.05, zfar=100))
s.add(pyrender.DirectionalLight(intensity=2.0))
times = []
for _ in range({repeats}):
    t0 = time.perf_counter()
    for c in cams:
        node = s.add(pyrender.Mesh.from_trimesh(trimesh.Trimesh(c, faces, process=False), smooth=True))
        r.render(s)
        s.remove_node(node)
    times.append((time.perf_counter() - t0) / len(cams) * 1000)
print(json.dumps(float(np.median(times))))
"""
    out = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=1800)
    if out.returncode:
        return f"failed: {out.stderr.strip().splitlines()[-1] if out.stderr.strip() else out.returncode}"
    return json.loads(out.stdout.strip().splitlines()[-1])


def peak_memory(seconds, folder):
    """Peak resident memory (MB) of a fresh process rendering a whole mesh clip of `seconds`."""
    code = f"""
import resource, sys
sys.path.insert(0, {str(ROOT / "tests")!r})
sys.argv = ["x"]
from pathlib import Path
import bench_render_mesh as b
model, motion = b.make_take(Path({str(folder)!r}), {seconds})
clip, camera = b.scene(model, motion)
options = b.RenderOptions(b.SIZE, camera, b.STYLES["mesh"], threads=1, rate_seed=0)
b.render_clip(clip, Path({str(folder)!r}) / "m.mp4", options, mesh=b.smpl_mesh(motion, model))
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
"""
    env = {**os.environ, "PYTHONPATH": f"{ROOT}:{ROOT / 'bench'}"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=1800)
    return float(out.stdout.strip().splitlines()[-1]) if out.returncode == 0 else f"failed: {out.stderr[-200:]}"


def mesh_quality(source, clip, camera, folder):
    """(PSNR dB, SSIM, Mb/s) of the mesh clip's drawn frames encoded at the default rate control."""
    from bench_blind_sizes import _encode, _psnr_ssim

    from rendering.raster import FrameDrawer

    drawer = FrameDrawer(clip["parents"], clip["joint_names"], SIZE, camera, STYLES["mesh"], meshes=[source])
    targets = camera_targets(clip["joints"], clip["fps"], camera)
    verts = source.vertices(0, len(clip["joints"]))
    raw = b"".join(bytes(drawer.draw(clip["joints"][t], targets[t], [verts[t]])) for t in range(len(verts)))
    drawer.close()
    (folder / "raw.yuv").write_bytes(raw)
    _encode(raw, folder / "q.mp4", SIZE, clip["fps"])
    psnr, ssim = _psnr_ssim(folder / "raw.yuv", folder / "q.mp4", SIZE, clip["fps"])
    return psnr, ssim, (folder / "q.mp4").stat().st_size * 8 / (len(verts) / clip["fps"]) / 1e6


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--pyrender-python", help="a Python with pyrender, for the OSMesa candidate")
    ap.add_argument("--memory", action="store_true", help="also the peak memory of 8-s and 64-s mesh clips")
    ap.add_argument("--quality", action="store_true", help="also the mesh clip's bitrate, PSNR and SSIM")
    ap.add_argument("--skip-times", action="store_true", help="measure no time (with --quality or --memory)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model, motion = make_take(folder, args.seconds)
        clip, camera = scene(model, motion)
        source = smpl_mesh(motion, model)
        frames = len(clip["joints"])
        print(f"{frames} frames at {SIZE}x{SIZE}, {len(source.mask)} vertices, {len(source.faces)} faces")
        if args.quality:
            psnr, ssim, rate = mesh_quality(source, clip, camera, folder)
            print(f"mesh clip at the default rate control: {rate:.2f} Mb/s, PSNR {psnr:.2f} dB, SSIM {ssim:.5f}")
        if args.skip_times:
            for seconds in (8, 64) if args.memory else ():
                print(f"peak memory, a {seconds}-s mesh clip: {peak_memory(seconds, folder)} MB")
            return
        clips = {}
        for _ in range(args.repeats):  # whole clips, in turn
            for name in ("stick", "mesh"):
                t0 = time.perf_counter()
                options = RenderOptions(SIZE, camera, STYLES[name], threads=1, rate_seed=0)
                render_clip(clip, folder / f"{name}.mp4", options, mesh=source if name == "mesh" else None)
                clips.setdefault(name, []).append(time.perf_counter() - t0)
        load = os.getloadavg()[0]
        stick, mesh = (float(np.median(clips[k])) for k in ("stick", "mesh"))
        ratios = np.array(clips["mesh"]) / np.array(clips["stick"])  # each repeat's pair, run one after the other
        print(f"whole clip, load {load:.1f}: stick {stick:.2f} s, mesh {mesh:.2f} s, mesh / stick = {mesh / stick:.2f} "
              f"(each repeat's: median {np.median(ratios):.2f}, {ratios.min():.2f}-{ratios.max():.2f})")  # fmt: skip
        n = min(frames, 90)
        cams, proj = camera_vertices(source, clip, camera, n)
        body = MeshBody([source], SIZE, proj.focal)
        ours = per_frame(lambda t: straight(body.draw([(cams[t], (0.42, 0.55, 0.78))])[0]), n, args.repeats)
        body.release()
        faces = np.asarray(source.faces)
        numpy_ms = per_frame(lambda t: triangles_numpy(cams[t], faces, proj.focal, SIZE), min(n, 20), 1)
        print(f"drawing alone per frame, load {os.getloadavg()[0]:.1f}: moderngl over EGL (llvmpipe) {ours:.1f} ms, "
              f"numpy triangles {numpy_ms:.1f} ms")  # fmt: skip
        if args.pyrender_python:
            pyr = pyrender_per_frame(args.pyrender_python, folder, cams, faces, proj.focal, args.repeats)
            shown = pyr if isinstance(pyr, str) else f"{pyr:.1f} ms"
            print(f"pyrender over OSMesa, load {os.getloadavg()[0]:.1f}: {shown}")
        if args.memory:
            for seconds in (8, 64):
                print(f"peak memory, a {seconds}-s mesh clip: {peak_memory(seconds, folder)} MB")


if __name__ == "__main__":
    main()
