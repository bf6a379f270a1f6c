"""The key frame's budget (rendering.encode.KEY_FRAME_BUDGET): each frame's SSIM against the drawn frames, the key
frame's and the rest's, at one frame's budget (as before) and at the shipped budget, on real takes drawn as a stick
figure and a solid body and on a synthetic SMPL-H body drawn as the mesh, at 640 px; and the bytes a clip costs.
Each clip is encoded at its set's rate (rendering.render.rate_for_set: the mesh at encode.MESH_RATE_BITS_PER_ROW, the
others at encode.RATE_BITS_PER_ROW), or at each rate of `--rates` (bits per second per row), to choose the mesh's.

SSIM is ffmpeg's ssim filter: "All" (Y, U and V weighted 4:1:1, as bench_blind_sizes and bench/RESULTS.md quote it)
and Y alone. Nothing here is timed, so the load does not matter.

    PYTHONPATH=$PWD python bench/bench_key_frame.py [--size 640] [--seconds 4] [--seeds 3]
        [--styles stick,solid,mesh] [--rates 2300,2800] [--budgets 1,3]
"""

import argparse
import itertools
import subprocess
import sys
import tempfile
from pathlib import Path

import imageio_ffmpeg
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from helpers import smpl_fixtures  # noqa: E402
from helpers.own_study_data import ACTIONS  # noqa: E402

from generation.data.skinning import smpl_mesh  # noqa: E402
from generation.data.smpl_files import smpl_positions  # noqa: E402
from generation.motion import skeleton  # noqa: E402
from generation.motion.features import load_take  # noqa: E402
from rendering import encode  # noqa: E402
from rendering.camera import camera_targets  # noqa: E402
from rendering.framing import item_camera  # noqa: E402
from rendering.raster import STYLES, FrameDrawer  # noqa: E402
from rendering.render import rate_for_set  # noqa: E402

TAKES = ("dataset-1_punch_normal_001", "dataset-1_dance-short_normal_001", "dataset-1_bow_active_001")
FPS = 30.0


def bvh_clip(name, seconds):
    path = ACTIONS / f"{name}.bvh.gz"
    if not path.exists():  # the repository's own walk, without ../shared
        path = ROOT / "tests" / "data" / "bvh" / "bandai_walk_angry_002.bvh.gz"
    joints = load_take(path, FPS)[: int(seconds * FPS)].astype(np.float64)
    return dict(joints=joints, parents=skeleton.PARENTS, joint_names=list(skeleton.JOINT_NAMES), fps=FPS)


def drawn(clip, size, style, mesh=None, camera=None):
    """The clip's frames as the renderer draws them, raw yuv420p (the lossless reference)."""
    kw = {} if camera is None else dict(camera=camera)
    drawer = FrameDrawer(clip["parents"], clip["joint_names"], size, style=STYLES[style], meshes=mesh, **kw)
    targets = camera_targets(clip["joints"], clip["fps"], *([camera] if camera is not None else []))
    verts = mesh[0].vertices(0, len(clip["joints"])) if mesh else None
    frames = [
        bytes(drawer.draw(clip["joints"][t], targets[t], None if verts is None else [verts[t]]))
        for t in range(len(clip["joints"]))
    ]
    drawer.close()
    return b"".join(frames)


def encode_raw(raw, out, size, seed, bits_per_row=None):
    frames = len(raw) // (size * size * 3 // 2)
    proc = encode.ffmpeg_writer(out, size, FPS, threads=1, frames=frames, seed=seed, bits_per_row=bits_per_row)
    _, err = proc.communicate(raw)
    if proc.returncode:
        raise RuntimeError(err.decode(errors="replace"))


def frame_ssim(raw_file, mp4, size):
    """[(All, Y)] per frame of `mp4` against the raw frames."""
    ff = imageio_ffmpeg.get_ffmpeg_exe()
    raw = ["-f", "rawvideo", "-pix_fmt", "yuv420p", "-s", f"{size}x{size}", "-r", f"{FPS:g}", "-i", str(raw_file)]
    log = subprocess.run(
        [ff, "-hide_banner", *raw, "-i", str(mp4), "-lavfi", "[1:v][0:v]ssim=stats_file=-", "-f", "null", "-"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    rows = [line for line in log.splitlines() if "All:" in line]
    return np.array([[float(r.split("All:")[1].split()[0]), float(r.split("Y:")[1].split()[0])] for r in rows])


def clips(folder, seconds, styles):
    for name in TAKES:
        for style in ("stick", "solid"):
            if style in styles:
                yield f"{name.split('_', 1)[1].rsplit('_', 1)[0]} ({style})", bvh_clip(name, seconds), style, None, None
    if "mesh" not in styles:
        return
    model = folder / "SMPLH_NEUTRAL.npz"
    smpl_fixtures.write_body_model(model, "smplh", rings=7, segments=18, head_rings=22)
    motion = smpl_fixtures.write_motion(folder / "take.npz", "smplh", frames=int(seconds * FPS), fps=FPS)
    joints, names, parents, fps = smpl_positions(motion, model)
    clip = dict(joints=joints, parents=parents, joint_names=names, fps=fps)
    camera = item_camera([joints], names, parents, fps, "front", "upper")
    yield "synthetic SMPL-H (mesh, front, upper)", clip, "mesh", [smpl_mesh(motion, model)], camera


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=640)
    p.add_argument("--seconds", type=float, default=4.0)
    p.add_argument("--seeds", type=int, default=3, help="draws of the rate's dither per clip")
    p.add_argument("--styles", default="stick,solid,mesh", help="the clips' styles, comma-separated")
    p.add_argument("--rates", default="", help="bits per second per row, comma-separated (default: each set's)")
    p.add_argument("--budgets", default=f"1,{encode.KEY_FRAME_BUDGET}", help="key frame budgets, in frames")
    args = p.parse_args()
    size = args.size
    budgets = [int(b) for b in args.budgets.split(",")]
    rates = [int(r) for r in args.rates.split(",") if r]
    shipped = encode.KEY_FRAME_BUDGET
    print(f"{size} px, {FPS:g} fps, {args.seconds:g} s, {args.seeds} dither seeds; SSIM All (Y)")
    head = f"{'clip':<40}{'rate':>6}{'budget':>7}{'frame 0':>16}{'frame 1':>16}{'min, rest':>16}{'< 0.98':>8}{'MB':>7}"
    print(head)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for label, clip, style, mesh, camera in clips(folder, args.seconds, args.styles.split(",")):
            raw = drawn(clip, size, style, mesh, camera)
            (folder / "raw.yuv").write_bytes(raw)
            own = rate_for_set([STYLES[style]]) or encode.RATE_BITS_PER_ROW
            for rate, budget in itertools.product(rates or [own], budgets):
                encode.KEY_FRAME_BUDGET = budget
                got, mb = [], []
                for seed in range(args.seeds):
                    encode_raw(raw, folder / "v.mp4", size, seed, rate)
                    got.append(frame_ssim(folder / "raw.yuv", folder / "v.mp4", size))
                    mb.append((folder / "v.mp4").stat().st_size / 1e6)
                s = np.stack(got)  # [seed, frame, (All, Y)]
                low = s[:, :, 0].min(axis=0)

                def cell(v):
                    return f"{v[0]:.4f} ({v[1]:.4f})"

                print(
                    f"{label:<40}{rate:>6}{budget:>7}{cell(s[:, 0].min(0)):>16}{cell(s[:, 1].min(0)):>16}"
                    f"{cell(s[:, 2:].min((0, 1))):>16}{int((low < 0.98).sum()):>8}{np.mean(mb):>7.3f}"
                )
            encode.KEY_FRAME_BUDGET = shipped


if __name__ == "__main__":
    main()
