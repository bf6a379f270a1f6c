"""What a video costs a rater and how it looks: the default rate control's bitrate and its image quality against
the drawn frames (a lossless reference), on locomotion clips of a stimulus set and on 30-fps gesture takes.

    python bench/video_rate.py STIMULI [--n 6] [--gestures 5]

For each clip the frames are drawn once (as render_clip draws them), then encoded at the default rate control and,
as the same-run baseline, at the rate before it (FRAME_BITS_PER_ROW = 320 bits per row of frame height per frame,
so 4.1 Mb/s at 640x640 and 20 fps, 6.1 Mb/s at 30 fps); ffmpeg's ssim and psnr filters compare each encode with
the drawn frames. The issue's bar: at most 1.5 Mb/s for a 640-px, 30-fps video with SSIM at least 0.98.
"""

import argparse
import csv
import glob
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT / "tests"))

import numpy as np  # noqa: E402
from bench_blind_sizes import _drawn, _encode, _psnr_ssim  # noqa: E402
from helpers.own_study_data import ACTIONS  # noqa: E402

from generation.data.motion_files import read_motion  # noqa: E402
from moglow_eval.core.clip import load_clip  # noqa: E402
from rendering import encode  # noqa: E402

BEFORE = 320  # bits per row of frame height per frame: the rate control before the rate became per second


def clips(stimuli, n, n_gestures):
    """(label, clip dict) for the first n test clips of the set and n_gestures action takes at 30 fps (8 s)."""
    with open(stimuli / "manifest.csv", newline="", encoding="utf-8") as f:
        rows = [r for r in csv.DictReader(f) if r["role"] == "test"][:n]
    out = [("locomotion", load_clip(stimuli / r["motion"])) for r in rows]
    for path in sorted(glob.glob(str(ACTIONS / "*.bvh.gz")))[::12][:n_gestures]:
        m = read_motion(path, 30)
        out.append(("gesture", dict(joints=m.joints[:240], parents=m.parents, joint_names=m.names, fps=30.0)))
    return out


def measure(clip, size, tmp):
    """{rate: (PSNR dB, SSIM, Mb/s)} of one clip's drawn frames encoded now and before."""
    fps = float(clip["fps"])
    raw = _drawn(clip, size)
    (tmp / "raw.yuv").write_bytes(raw)
    seconds = len(clip["joints"]) / fps
    out, now = {}, encode.RATE_BITS_PER_ROW
    for label, per_second in (("now", now), ("before", BEFORE * fps)):
        encode.RATE_BITS_PER_ROW = per_second
        try:
            _encode(raw, tmp / "v.mp4", size, fps)
        finally:
            encode.RATE_BITS_PER_ROW = now
        psnr, ssim = _psnr_ssim(tmp / "raw.yuv", tmp / "v.mp4", size, fps)
        out[label] = (psnr, ssim, (tmp / "v.mp4").stat().st_size * 8 / seconds / 1e6)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("stimuli", type=Path)
    ap.add_argument("--n", type=int, default=6)
    ap.add_argument("--gestures", type=int, default=5)
    ap.add_argument("--size", type=int, default=640)
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp())
    got = {}
    for kind, clip in clips(args.stimuli, args.n, args.gestures):
        for label, v in measure(clip, args.size, tmp).items():
            got.setdefault((kind, float(clip["fps"]), label), []).append(v)
    print(f"{'clips':<12}{'fps':>5}{'rate':>8}{'n':>4}{'Mb/s':>8}{'PSNR dB':>9}{'SSIM mean':>11}{'SSIM min':>10}")
    for (kind, fps, label), v in sorted(got.items()):
        a = np.array(v)
        print(
            f"{kind:<12}{fps:>5g}{label:>8}{len(a):>4}{a[:, 2].mean():>8.2f}{a[:, 0].mean():>9.2f}"
            f"{a[:, 1].mean():>11.5f}{a[:, 1].min():>10.5f}"
        )


if __name__ == "__main__":
    main()
