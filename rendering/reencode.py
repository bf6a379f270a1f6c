"""`python -m rendering.reencode IN.mp4 OUT.mp4 --like STUDY.mp4`: a stimulus video encoded again, with fresh
randomness, so that the file served is never the file submitted.

A system that joins a running study (`python -m rating_app add-condition`) brings its own videos; served as they
are, their bytes (or any hash of them) would let whoever submitted them pick out their own system's clips and vote
for it. So the study takes the frames, not the file: each video is decoded and encoded again by the stimulus
encoder (rendering.encode: the one-size rate control, each frame's share of the rate drawn afresh), and its sound,
if any, is copied across as the study's videos carry it. The result has the study's sizes by construction: each
frame's budget is read from `--like`'s own frame sizes (`frame_budget`), so a set encoded at another rate (a set
with a mesh body, rendering.encode.MESH_RATE_BITS_PER_ROW) is matched as the others are. Each encode's frame sizes
are checked against `--like`'s, as a build checks its set's: at a small size a key frame can come out a few bytes
short (rendering.encode.KEY_QP), and is drawn again; the caller checks the files' sizes too.
Only a video of the size, frame rate and number of frames of the study's video `--like` is taken: the decoder reads
a hostile file, and nothing larger than the study's own clips is ever decoded.

The fresh rates change the bytes of a real stimulus at every encode. A video with almost nothing in it (a flat
picture, a bar that moves) is coded at the encoder's finest step whatever its rate, so its bytes can come out as
they went in; such an encode is drawn again (`ATTEMPTS`). What no encode can hide is the picture itself: whoever
made a clip and decodes what a study serves will know it, which is why nothing a client can see before it
downloads a video (its id, URL, size, ETag) may tell them apart.
"""

from __future__ import annotations

import filecmp
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

from moglow_eval.core import cli

from .encode import KEY_FRAME_BUDGET, KEY_QP, ffmpeg_writer, video_rate
from .errors import RenderError
from .mp4_layout import read_layout

TIMEOUT_S = 600  # one clip: decoding and encoding a few hundred frames takes seconds
ATTEMPTS = 8  # encodes drawn before a video that keeps coming out as submitted, or a few bytes short, is refused


def _ffmpeg() -> str:
    import imageio_ffmpeg  # here, as in encode: importing rendering needs no encoder

    return imageio_ffmpeg.get_ffmpeg_exe()


def _probe(src: Path) -> tuple[tuple[int, int], float, bool]:
    """((width, height), fps, has sound) of the video `src`, from ffmpeg's stream listing."""
    import imageio_ffmpeg

    gen = imageio_ffmpeg.read_frames(str(src), pix_fmt="yuv420p")
    try:
        meta = next(gen)
    except (RuntimeError, StopIteration, OSError) as exc:
        last = (str(exc).strip().splitlines() or ["no message"])[-1]
        raise RenderError(f"{src}: not a video ffmpeg can read ({last})") from None
    finally:
        gen.close()
    listing = subprocess.run([_ffmpeg(), "-hide_banner", "-i", str(src)], capture_output=True, text=True)
    return tuple(meta["size"]), float(meta["fps"]), "Audio:" in listing.stderr


def frame_budget(sizes, fps) -> int:
    """The frame budget in bits (rendering.encode.frame_bits) of a video the stimulus encoder wrote, from its frame
    sizes in bytes (the MP4's sample table) at `fps`.

    The encoder caps every frame after the first two at the rate x264 takes in whole kbit/s (K), and tops it up
    with filler: the later frames are one size, a byte over the budget, or, where the budget makes no whole kbit/s,
    alternate between two sizes whose mean K gives. K, read from their mean, leaves a few budgets (a byte apart) that
    give it; of those, the key frame's size (KEY_FRAME_BUDGET budgets, filler included) picks the one whose schedule
    it is. RenderError when the video has too few frames to tell."""
    if len(sizes) < 3:
        raise RenderError(f"{len(sizes)} frames: too few to read the study's frame budget from")
    rate = video_rate(fps)
    later = Fraction(sum(sizes[2:]), len(sizes) - 2) - 1  # the budget in bytes a later frame gets, on average

    def kbit(n):  # x264's rate in whole kbit/s for a budget of n bytes a frame, as rendering.encode hands it over
        return round(8 * n * rate) // 1000

    k = round(8 * later * rate / 1000)
    near = range(max(1, int(later) - 64), int(later) + 64)
    fits = [n for n in near if kbit(n) == k] or [round(later)]
    return 8 * min(fits, key=lambda n: (abs(KEY_FRAME_BUDGET * n - sizes[0]), n))


def reencode(src, dst, like, seed: int | None = None) -> None:
    """Encode the video `src` again into `dst` (stimulus encoder, fresh randomness unless `seed`), as the video
    `like` is: its size, frame rate, number of frames and frame sizes, and never byte for byte `src` (an encode that
    comes out so, or a few bytes short, is drawn again, `seed + 1` after `seed`, with its key frame at the next of
    encode.KEY_QP); RenderError, one line, when `src` differs in any, keeps coming out as it went in or ffmpeg
    fails, and then no `dst`."""
    src, dst = Path(src), Path(dst)
    for given, name in ((src, "the video to encode"), (Path(like), "the study's video (--like)")):
        if dst.exists() and given.exists() and dst.samefile(given):  # a failed encode removes dst: it would be lost
            raise RenderError(f"{dst}: is {name}; write the new encode elsewhere")
    (w, h), fps, _ = _probe(Path(like))
    if w % 2 or h % 2:
        raise RenderError(f"{like}: {w}x{h} pixels; a stimulus video's sides are even (yuv420p)")
    # The study's video's sample table gives its frames (one sample a frame: the encoder writes no B-frames) and
    # their sizes, with no pass of ffmpeg over the file to count them.
    sizes = read_layout(like).sample_sizes
    frames, bits = len(sizes), frame_budget(sizes, fps)
    short = 0  # encodes that came out a few bytes short: each next one takes the next key frame quantiser
    for attempt in range(ATTEMPTS):
        key_qp = KEY_QP[(short - 1) % len(KEY_QP)] if short else None
        try:
            _reencode(src, dst, (w, h), fps, frames, None if seed is None else seed + attempt, bits, key_qp)
            if read_layout(dst).sample_sizes != sizes:
                short += 1
            elif not filecmp.cmp(src, dst, shallow=False):
                return
            dst.unlink()
        except BaseException:
            dst.unlink(missing_ok=True)
            dst.with_name(dst.stem + ".video.mp4").unlink(missing_ok=True)
            raise
    if short == ATTEMPTS:
        raise RenderError(f"{src}: encoded again {ATTEMPTS} times, its frames never came out the study's sizes")
    raise RenderError(f"{src}: encoded again {ATTEMPTS} times, it came out as submitted each time (a flat picture?)")


def _reencode(src: Path, dst: Path, size: tuple, fps: float, frames: int, seed: int | None, bits: int, key_qp) -> None:
    (w, h), src_fps, sound = _probe(src)
    if (w, h) != size or abs(src_fps - fps) > 1e-3:
        raise RenderError(f"{src}: {w}x{h} pixels at {src_fps:g} fps; the study's are {size[0]}x{size[1]} at {fps:g}")
    frame_bytes = w * h * 3 // 2  # yuv420p
    video = dst.with_name(dst.stem + ".video.mp4") if sound else dst
    decode = [_ffmpeg(), "-v", "error", "-i", str(src), "-map", "0:v:0", "-frames:v", str(frames + 1)]
    decode += ["-f", "rawvideo", "-pix_fmt", "yuv420p", "-"]
    reader = subprocess.Popen(decode, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    writer = ffmpeg_writer(video, h, fps, frames=frames, seed=seed, width=w, bits=bits, key_qp=key_qp)
    n = 0
    try:
        while chunk := reader.stdout.read(frame_bytes):
            if len(chunk) < frame_bytes or n == frames:
                raise RenderError(f"{src}: more than {frames} frames, or a partial one; the study's clip has {frames}")
            writer.stdin.write(chunk)
            n += 1
        if n != frames:
            raise RenderError(f"{src}: {n} frames; the study's clips of this item have {frames}")
    finally:
        reader.kill()
        reader.wait()
        writer.stdin.close()
        writer.wait(TIMEOUT_S)
    if writer.returncode != 0:
        raise RenderError(f"{dst}: encoding failed ({writer.stderr.read().decode(errors='replace').strip()[-200:]})")
    if sound:
        _copy_sound(src, video, dst)


def _copy_sound(src: Path, video: Path, dst: Path) -> None:
    """`video` with the sound stream of `src` copied across, as rendering.audio.mux_audio writes a study's."""
    cmd = [_ffmpeg(), "-y", "-v", "error", "-i", str(video), "-i", str(src), "-map", "0:v", "-map", "1:a:0"]
    cmd += ["-c", "copy", "-map_metadata", "-1", "-fflags", "+bitexact", "-movflags", "+faststart", str(dst)]
    out = subprocess.run(cmd, capture_output=True, timeout=TIMEOUT_S)
    video.unlink(missing_ok=True)
    if out.returncode != 0:
        raise RenderError(f"{src}: copying its sound failed ({out.stderr.decode(errors='replace').strip()[-200:]})")


def build_parser():
    p = cli.ArgumentParser(prog="python -m rendering.reencode", description=__doc__.splitlines()[0])
    p.add_argument("video", help="the video to encode again (.mp4)")
    p.add_argument("out", help="where to write it (.mp4)")
    p.add_argument("--like", required=True, help="a video of the study: the size, frame rate and length to keep")
    return p


def _main(argv):
    args = build_parser().parse_args(argv)
    cli.file_to_write(args.out, "the video to write", flag="OUT")  # the video read as OUT: reencode's own check
    reencode(args.video, args.out, args.like)
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
