"""How much a stimulus set's sizes tell about the condition, and what the encoding costs in image quality.

    python bench/bench_blind_sizes.py STIMULI [--quality N] [--size S]

Sizes: every size a parser reads from a video without decoding it (`rendering.mp4_layout.size_signals`: the
file, each box, the frame-size table, each frame's NAL units other than filler), as the AUC of BAD catch clips
against test clips, of the matched against the mismatched test clips where a set has them (the two clips of an
appropriateness, dyadic or semantic trial), and of each pair of conditions' test clips (0.5: the signal tells
nothing; 0 or 1: it separates the two perfectly). A signal equal for every video has AUC 0.5 exactly; the table
lists the others, then the worst AUC of each family. Issue 37 asks for every AUC in [0.25, 0.75].

Quality (--quality N, default 20; 0 skips): the first N test clips of the manifest, drawn again at the set's size
(or --size), encoded the way they were before issue 37 (ultrafast, constant quantiser 17) and with today's
default, each compared with the drawn frames by ffmpeg's psnr and ssim filters.
"""

import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import imageio_ffmpeg  # noqa: E402
import numpy as np  # noqa: E402

from moglow_eval.core import study  # noqa: E402
from moglow_eval.core.clip import load_clip  # noqa: E402
from moglow_eval.core.ranks import auc  # noqa: E402
from rendering.blinding import SIZE_AUC_BAND  # noqa: E402
from rendering.camera import camera_targets  # noqa: E402
from rendering.encode import ffmpeg_writer  # noqa: E402
from rendering.mp4_layout import content_signal, read_layout, size_signals  # noqa: E402
from rendering.raster import FrameDrawer  # noqa: E402

LOW, HIGH = SIZE_AUC_BAND  # the AUC every size signal must stay within


def groups(rows):
    """{name: clip ids}: BAD catch clips, test clips, the test clips of each condition (a study's mismatched clips
    left out), and, where the set has mismatched clips (appropriateness, dyadic, semantic), the matched and the
    mismatched test clips: the two clips of a trial."""
    out = {study.CATCH: [r["clip_id"] for r in rows if r["condition"] == study.CATCH and r["role"] == "catch"]}
    out["test"] = [r["clip_id"] for r in rows if r["role"] == "test"]
    conditions = dict.fromkeys(r["condition"] for r in rows if r["role"] == "test")
    order = [c for c in study.BUILTIN if c in conditions] + sorted(c for c in conditions if c not in study.BUILTIN)
    for cond in order:
        out[cond] = [
            r["clip_id"] for r in rows if r["role"] == "test" and r["condition"] == cond and not r.get("motion_item")
        ]
    if any(r.get("motion_item") for r in rows):
        out["matched"] = [r["clip_id"] for r in rows if r["role"] == "test" and not r.get("motion_item")]
        out["mismatched"] = [r["clip_id"] for r in rows if r["role"] == "test" and r.get("motion_item")]
    return out


def comparisons(g):
    """BAD against test, matched against mismatched, and each pair of conditions."""
    pairs = [(study.CATCH, "test"), ("matched", "mismatched")]
    conditions = [k for k in g if k not in (study.CATCH, "test", "matched", "mismatched")]
    pairs += [(a, b) for i, a in enumerate(conditions) for b in conditions[i + 1 :]]
    return [(a, b) for a, b in pairs if g.get(a) and g.get(b)]


def family(name):
    if name == "file size":
        return "file size"
    if name.startswith("box "):
        return "box sizes"
    if name.startswith("frame "):
        return "frame sizes (stsz)"
    return "coded NAL units (non-filler)" if content_signal(name) else "other"


def size_table(folder, rows):
    signals = {r["clip_id"]: size_signals(read_layout(folder / r["video"])) for r in rows}
    g = groups(rows)
    pairs = comparisons(g)
    names = list(dict.fromkeys(n for s in signals.values() for n in s))
    table = {}
    for name in names:
        values = {cid: s.get(name, -1) for cid, s in signals.items()}
        table[name] = [auc([values[c] for c in g[a]], [values[c] for c in g[b]]) for a, b in pairs]
    header = f"{'signal':<52}" + "".join(f"{a + ' vs ' + b:>13}" for a, b in pairs)
    print(f"{len(rows)} videos; " + ", ".join(f"{k} {len(v)}" for k, v in g.items()))
    print(f"{len(names)} size signals; those not equal for every video (AUC):")
    print(header)
    for name, aucs in table.items():
        if any(v != 0.5 for v in aucs):
            print(f"{name:<52}" + "".join(f"{v:>13.3f}" for v in aucs))
    print("\nworst AUC (furthest from 0.5) of each family of signals:")
    print(header)
    worst_all = 0.5
    for fam in dict.fromkeys(family(n) for n in names):
        members = [table[n] for n in names if family(n) == fam]
        worst = [max((m[i] for m in members), key=lambda v: abs(v - 0.5)) for i in range(len(pairs))]
        worst_all = max([worst_all, *worst], key=lambda v: abs(v - 0.5))
        print(f"{fam:<52}" + "".join(f"{v:>13.3f}" for v in worst))
    chance = [1.96 * ((len(g[a]) + len(g[b]) + 1) / (12 * len(g[a]) * len(g[b]))) ** 0.5 for a, b in pairs]
    print(
        f"{'a signal that tells nothing, 95% of sets within':<52}" + "".join(f"{'0.5 +- %.3f' % c:>13}" for c in chance)
    )
    inside = LOW <= worst_all <= HIGH
    print(f"\nevery AUC in [{LOW}, {HIGH}]: {'yes' if inside else 'no'} (the worst: {worst_all:.3f})")


def _drawn(clip, size):
    drawer = FrameDrawer(clip["parents"], list(clip["joint_names"]), size)
    joints = np.asarray(clip["joints"], dtype=np.float64)
    targets = camera_targets(joints, float(clip["fps"]))
    return b"".join([bytes(drawer.draw(joints[t], targets[t])) for t in range(len(joints))])


def _encode(raw, out, size, fps, **rate):
    frames = len(raw) // (size * size * 3 // 2)  # as render_clip tells the encoder, for the default's dither
    proc = ffmpeg_writer(out, size, fps, "ultrafast", threads=1, frames=frames, **rate)
    proc.stdin.write(raw)
    proc.stdin.close()
    err = proc.stderr.read().decode(errors="replace")
    if proc.wait():
        raise RuntimeError(err)


def _psnr_ssim(raw_file, mp4, size, fps):
    ff = imageio_ffmpeg.get_ffmpeg_exe()
    raw = ["-f", "rawvideo", "-pix_fmt", "yuv420p", "-s", f"{size}x{size}", "-r", f"{fps:g}", "-i", str(raw_file)]
    lavfi = "[1:v][0:v]psnr;[1:v][0:v]ssim"
    r = subprocess.run(
        [ff, "-hide_banner", *raw, "-i", str(mp4), "-lavfi", lavfi, "-f", "null", "-"], capture_output=True, text=True
    )
    psnr = re.search(r"PSNR .*average:([\d.]+|inf)", r.stderr)
    ssim = re.search(r"SSIM .*All:([\d.]+)", r.stderr)
    if r.returncode or not psnr or not ssim:
        raise RuntimeError(r.stderr[-500:])
    return float(psnr.group(1)), float(ssim.group(1))


def quality(folder, rows, n, size):
    tests = [r for r in rows if r["role"] == "test"][:n]
    encodings = {"before (ultrafast qp 17)": dict(qp=17), "now (default rate control)": {}}
    got = {k: [] for k in encodings}
    tmp = Path(tempfile.mkdtemp())
    for r in tests:
        clip = load_clip(folder / r["motion"])
        s = size or int(r.get("width") or 640)
        fps = float(clip["fps"])
        raw = _drawn(clip, s)
        (tmp / "raw.yuv").write_bytes(raw)
        for label, rate in encodings.items():
            _encode(raw, tmp / "v.mp4", s, fps, **rate)
            got[label].append((*_psnr_ssim(tmp / "raw.yuv", tmp / "v.mp4", s, fps), (tmp / "v.mp4").stat().st_size))
    print(f"\nimage quality of {len(tests)} test clips against the drawn frames (mean, min over clips):")
    print(f"{'encoding':<30}{'PSNR dB':>16}{'SSIM':>20}{'MB per clip':>14}")
    for label, v in got.items():
        a = np.array(v)
        print(
            f"{label:<30}{a[:, 0].mean():>9.2f} ({a[:, 0].min():.2f}){a[:, 1].mean():>11.5f} ({a[:, 1].min():.5f})"
            f"{a[:, 2].mean() / 1e6:>14.2f}"
        )
    diff = np.array(got["now (default rate control)"])[:, :2] - np.array(got["before (ultrafast qp 17)"])[:, :2]
    print(
        f"now - before, per clip: PSNR {diff[:, 0].mean():+.2f} dB (min {diff[:, 0].min():+.2f}), "
        f"SSIM {diff[:, 1].mean():+.5f} (min {diff[:, 1].min():+.5f})"
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("stimuli", type=Path, help="a stimulus folder (manifest.csv and its videos)")
    ap.add_argument("--quality", type=int, default=20, help="test clips to re-encode for PSNR/SSIM (0: none)")
    ap.add_argument("--size", type=int, help="frame size for the quality part (default: the set's)")
    args = ap.parse_args(argv)
    with open(args.stimuli / "manifest.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    print(f"{args.stimuli}; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    size_table(args.stimuli, rows)
    if args.quality:
        quality(args.stimuli, rows, args.quality, args.size)


if __name__ == "__main__":
    main()
