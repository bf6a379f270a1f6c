"""Rendering speed: our renderer against a plain matplotlib FuncAnimation + ffmpeg writer, same run.

    python bench/bench_render.py [--size 1000] [--repeats 3] [--core 0]

Both render the same real 80-frame walk (4 s at 20 fps) at size x size to H.264 (libx264, one thread)
with the process and its ffmpeg child pinned to one core. Reported per clip: wall time and CPU time
(this process + ffmpeg), the best of `repeats`; ours with its default x264 settings (ultrafast, every frame one
size: rendering.encode) and with the default before issue 37 (ultrafast, qp 17) against the baseline at ultrafast,
and with the older default (superfast, crf 20) against it at superfast.
The baseline is what one writes first: an mplot3d figure with a floor grid, one Line3D per bone updated
in FuncAnimation, saved with FFMpegWriter.
"""

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import imageio_ffmpeg  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.animation import FFMpegWriter, FuncAnimation  # noqa: E402

from generation.motion import skeleton  # noqa: E402
from generation.motion.features import load_take  # noqa: E402
from rendering.camera import camera_targets  # noqa: E402
from rendering.raster import FrameDrawer, _background  # noqa: E402
from rendering.render import RenderOptions, render_clip  # noqa: E402

WALK = (
    Path(__file__).resolve().parents[2]
    / "shared/data/bandai-namco-locomotion/dataset-1/data/dataset-1_walk_angry_002.bvh.gz"
)


def cpu_seconds():
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def baseline(joints, out, size, preset):
    """The plain way: mplot3d axes, floor grid, a line per bone, FuncAnimation, FFMpegWriter."""
    matplotlib.rcParams["animation.ffmpeg_path"] = imageio_ffmpeg.get_ffmpeg_exe()
    fig = plt.figure(figsize=(size / 100, size / 100), dpi=100)
    ax = fig.add_subplot(projection="3d")
    ax.view_init(elev=12, azim=40)
    ax.set_axis_off()
    child = np.nonzero(skeleton.PARENTS >= 0)[0]
    lines = [ax.plot([], [], [], lw=4)[0] for _ in child]
    grid = np.arange(-10, 11, 1.0)

    def update(t):
        x, z = joints[t, 0, 0], joints[t, 0, 2]
        ax.set_xlim(x - 2, x + 2)
        ax.set_ylim(z - 2, z + 2)
        ax.set_zlim(0, 2)
        for line, j in zip(lines, child):
            p = joints[t, [j, skeleton.PARENTS[j]]]
            line.set_data_3d(p[:, 0], p[:, 2], p[:, 1])
        return lines

    for g in grid:  # the floor grid, drawn once as artists (redrawn every frame by the animation)
        ax.plot([g, g], [-10, 10], [0, 0], color="0.6", lw=1)
        ax.plot([-10, 10], [g, g], [0, 0], color="0.6", lw=1)
    anim = FuncAnimation(fig, update, frames=len(joints), blit=False)
    writer = FFMpegWriter(
        fps=20,
        codec="libx264",
        extra_args=["-preset", preset, "-pix_fmt", "yuv420p", "-threads", "1", "-movflags", "+faststart"],
    )
    anim.save(out, writer=writer, dpi=100)
    plt.close(fig)


def measure(fn, repeats):
    walls, cpus = [], []
    for _ in range(repeats):
        c0, w0 = cpu_seconds(), time.perf_counter()
        fn()
        walls.append(time.perf_counter() - w0)
        cpus.append(cpu_seconds() - c0)
    return min(walls), min(cpus)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--core", type=int, default=0, help="CPU core to pin to (ffmpeg inherits it)")
    args = ap.parse_args(argv)
    os.sched_setaffinity(0, {args.core})
    joints = load_take(WALK, 20.0)[:80].astype(np.float64)
    clip = dict(joints=joints, parents=skeleton.PARENTS, joint_names=skeleton.JOINT_NAMES, fps=20.0)
    tmp = Path(tempfile.mkdtemp())
    # (label, our render_clip options, the baseline's x264 preset)
    configs = [
        ("default: ultrafast, one frame size", dict(preset="ultrafast"), "ultrafast"),
        ("ultrafast qp 17 (until issue 37)", dict(preset="ultrafast", qp=17), "ultrafast"),
        ("superfast crf 20 (older default)", dict(preset="superfast", crf=20), "superfast"),
    ]
    rows = []
    for label, kw, preset in configs:
        options = RenderOptions(args.size, threads=1, **kw)
        ours = measure(lambda o=options: render_clip(clip, tmp / "ours.mp4", o), args.repeats)
        base = measure(lambda: baseline(joints, str(tmp / "base.mp4"), args.size, preset), args.repeats)
        rows.append((label, ours, base))

    def cold():  # the first clip of a process also computes the cached blank floor / grid fade maps
        _background.cache_clear()
        render_clip(clip, tmp / "cold.mp4", RenderOptions(args.size, threads=1))

    first = measure(cold, 1)

    def draw_only():
        drawer = FrameDrawer(skeleton.PARENTS, skeleton.JOINT_NAMES, args.size)
        for t, target in enumerate(camera_targets(joints, 20.0)):
            drawer.draw(joints[t], target)

    draw = measure(draw_only, args.repeats)
    ours640 = measure(lambda: render_clip(clip, tmp / "o640.mp4", RenderOptions(640, threads=1)), args.repeats)
    qp640 = measure(lambda: render_clip(clip, tmp / "q640.mp4", RenderOptions(640, threads=1, qp=17)), args.repeats)
    load = os.getloadavg()[0]
    print(
        f"80-frame clip, {args.size}x{args.size}, one core (#{args.core}), best of {args.repeats}; "
        f"load average {load:.1f} on {os.cpu_count()} cores"
    )
    print(
        f"{'ours (x264)':<32}{'ours wall':>10}{'ours cpu':>10}{'baseline wall':>15}{'baseline cpu':>14}"
        f"{'speed-up wall':>15}{'speed-up cpu':>14}"
    )
    for label, (ow, oc), (bw, bc) in rows:
        print(f"{label:<32}{ow:>9.3f}s{oc:>9.3f}s{bw:>14.3f}s{bc:>13.3f}s{bw / ow:>14.1f}x{bc / oc:>13.1f}x")
    print(f"target: <= 0.3 s where the baseline takes ~2.1 s (a quiet machine), i.e. a speed-up >= {2.1 / 0.3:.1f}x")
    (dw, dc), (qw, qc) = rows[0][1], rows[1][1]
    print(f"default against ultrafast qp 17 (the default until issue 37): wall {dw / qw:.2f}x, cpu {dc / qc:.2f}x")
    print(f"first clip of a process (computes the floor maps): wall {first[0]:.3f} s, cpu {first[1]:.3f} s")
    print(
        f"of which drawing the 80 frames (no encoding): wall {draw[0]:.3f} s, cpu {draw[1]:.3f} s; the rest is "
        "the pipe and ffmpeg (libx264; the frames arrive as yuv420p)"
    )
    print(
        f"ours at 640x640 (the stimulus size, default x264 settings): wall {ours640[0]:.3f} s, cpu {ours640[1]:.3f} s; "
        f"at qp 17 {qp640[0]:.3f} s, {qp640[1]:.3f} s (default / qp 17: wall {ours640[0] / qp640[0]:.2f}x, "
        f"cpu {ours640[1] / qp640[1]:.2f}x)"
    )


if __name__ == "__main__":
    main()
