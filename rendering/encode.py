"""The encoder: raw yuv420p frames piped into ffmpeg's libx264, out as an H.264 MP4 for browsers."""

import random
import subprocess
from fractions import Fraction

# The default rate control gives every frame of a video the same size: a rate of this many bits per second per row
# of the frame's height, filler included (line drawings cost bits along their lines, so in proportion to the side,
# not the area), spread evenly over the frames. At 640x640 that is 1.47 Mb/s at any frame rate: what a rater
# downloads on a phone (a set with a mesh body: MESH_RATE_BITS_PER_ROW). Its image quality against the drawn
# frames, and what the sizes tell, are measured in bench/RESULTS.md#video-rate.
RATE_BITS_PER_ROW = 2300
# The rate of every video of a set with a mesh body among its styles (rendering.render.rate_for_set, decided once
# for the whole set: an item's videos are one size whatever their style); 2.11 Mb/s at 640x640. A skinned mesh's
# shaded surface costs more bits than lines or capsules: at RATE_BITS_PER_ROW the frames the dither gives a low share
# of the rate fell short of the SSIM every frame of the other styles reaches against a lossless encode, and raising
# the dither's floor instead lets the coded sizes tell more of the content. The smallest rate in steps of 100 at
# which every frame of the bench's mesh clip keeps a margin above that SSIM (bench/RESULTS.md#key-frame).
MESH_RATE_BITS_PER_ROW = 3300
# The share of that rate x264 aims to spend on the picture on average; the filler data pays for the rest.
CODED_SHARE = 0.9
# Each frame's share of the rate is drawn at random (log-normal, this spread, within DITHER_RANGE of the mean):
# how much x264 spends on a frame otherwise swings with how much the picture changed, more in a jittery clip.
DITHER_SD = 1.0
DITHER_RANGE = (0.25, 4.0)
MAX_ZONES = 100  # about 6 kB of x264 options in the first frame, which the caller strips
# The first frame is coded from nothing, and it is the poster a rater looks at while the other video of a pair
# plays: at one frame's budget its static floor comes out blocky and sharpens only over the next frames. So it is
# given this many frames' worth of bits, in every video alike: the set keeps one schedule of frame sizes, the same
# for every video of a size and frame rate, and the key frame reaches the quality of the frames after it
# (bench/RESULTS.md#key-frame).
KEY_FRAME_BUDGET = 3
# Where a key frame's budget is more than its picture needs (a small frame: at 64 px x264 spends it all at a quantiser
# near 0), its picture codes to within a few bytes of the budget, and the filler unit that tops a frame up cannot be
# smaller than six: such a video comes out a few bytes short, whatever the dither of the frames after it. Encoded
# again for that (generation.stimuli.render_pool, rendering.reencode), its key frame takes the next of these
# quantisers, near a small frame's other frames': its picture codes to another size, smaller as the quantiser rises,
# and the filler tops it up as before.
KEY_QP = (10, 14, 18)


def video_rate(fps) -> Fraction:
    """The frame rate as ffmpeg is given it: the NTSC rates (24000/1001, ...) as they are, others as they read."""
    for ntsc in (Fraction(24000, 1001), Fraction(30000, 1001), Fraction(60000, 1001)):
        if abs(fps - ntsc) < 1e-3:
            return ntsc
    return Fraction(fps).limit_denominator(1001)


def frame_bits(size, fps, bits_per_row=None):
    """The size of every frame at the default rate control, in bits (filler included), for a size x size video at
    `fps` frames per second: near bits_per_row * size / fps (None: RATE_BITS_PER_ROW), in whole bytes, and where it
    can be, such that the rate it makes is a whole number of kbit/s. x264 takes its maximum rate in kbit/s and gives
    each frame that rate over the frame rate; a frame budget with a fraction of a byte makes the filler alternate
    between two frame sizes (by frame number, whatever the picture: it tells nothing, but one size is simpler to
    check)."""
    bits_per_row = RATE_BITS_PER_ROW if bits_per_row is None else bits_per_row
    rate = video_rate(fps)
    target = bits_per_row * size / 1000
    for kbit in sorted(range(max(1, int(target * 0.8)), int(target * 1.2) + 2), key=lambda k: abs(k - target)):
        bits = Fraction(kbit * 1000) / rate
        if bits.denominator == 1 and bits.numerator % 8 == 0:
            return bits.numerator
    return 8 * round(bits_per_row * size / fps / 8)


def rate_dither(frames, seed=None, after_key="", key_qp=None):
    """x264 zones giving each of `frames` frames a random multiple of the rate (seed None: fresh randomness).

    Every multiple is written with the same number of characters, so that x264's options (written into the
    first frame, and stripped from it by the caller) are as long for every clip; a long clip gets its multiples
    in runs of frames, at most MAX_ZONES of them, so that they stay a small part of the first frame.
    after_key: x264 options for every frame after the first, which keeps the options it starts with (a zone
    of its own at the mean rate, or at the quantiser `key_qp`: a zone a few characters shorter, in a video encoded
    again, whose options the caller strips as it strips every video's); "" gives no such zone.
    """
    run = -(-frames // MAX_ZONES)
    starts = range(0, frames, run)
    rng = random.Random(seed)
    m = [rng.lognormvariate(0.0, DITHER_SD) for _ in starts]
    mean = sum(m) / len(m)
    lo, hi = DITHER_RANGE
    first = 1 if after_key else 0
    zones = [(max(a, first), min(a + run, frames) - 1, min(max(x / mean, lo), hi)) for a, x in zip(starts, m)]
    extra = f",{after_key}" if after_key else ""
    dither = [f"{a},{b},b={x:.3f}{extra}" for a, b, x in zones if a <= b]
    key = "0,0,b=1.000" if key_qp is None else f"0,0,q={key_qp}"
    return "/".join(([key] if after_key else []) + dither)


def _rate_control(size, fps, qp, crf, frames, seed, bits, key_qp=None):
    """(ffmpeg options, x264 parameters) of the rate control; `bits`: each frame's budget (frame_bits);
    `key_qp`: the key frame's quantiser, None for the rate control's own (ffmpeg_writer)."""
    if crf is not None:
        return ["-crf", str(crf)], []
    if qp is not None:
        return ["-qp", str(qp)], []
    # x264 aims at CODED_SHARE of the rate on average over the clip (each frame at its random multiple), and its
    # buffer (one frame, filled at the full rate) caps each frame; a frame that codes smaller is topped up with
    # filler data inside the same sample, so every frame of every clip is one size, whatever it shows. The
    # average rate, not a per-frame cap that each clip fills to its own degree, sets how many bytes the picture
    # gets, so the total of the coded (non-filler) NAL units hardly varies with the content either. No scene-cut
    # keyframes and no B-frames: where x264 puts them follows the content, and the boxes would show it. The SEI
    # units (x264's options, the dither among them) are removed, so no parser reads the frames' multiples.
    cap = round(bits * video_rate(fps))
    aim = round(CODED_SHARE * bits * video_rate(fps))
    x264 = ["filler=1", "qcomp=0", "scenecut=0", "bframes=0"]
    buffer, top = bits, cap
    if frames:
        # The key frame's budget: the buffer starts full at KEY_FRAME_BUDGET frames and fills at that much a frame,
        # so filler tops the key frame up to it whatever it shows. From frame 1 on, a zone sets buffer and rate back
        # to one frame's (in kbit, as ffmpeg hands x264 the global ones); x264 applies them from frame 2, so frame 1
        # also comes out near the key frame's budget: one fixed schedule of sizes, the same for every clip.
        buffer, top = KEY_FRAME_BUDGET * bits, KEY_FRAME_BUDGET * cap
        # x264 aims at an average over the clip, and the two key frames' extra would otherwise come out of the
        # frames after them: the aim grows by that extra.
        aim = round(aim * (frames + 2 * (KEY_FRAME_BUDGET - 1)) / frames)
        per_frame = f"vbv-bufsize={bits // 1000},vbv-maxrate={cap // 1000}"
        x264 += ["vbv-init=1", f"zones={rate_dither(frames, seed, per_frame, key_qp)}"]
    rate = ["-b:v", str(aim), "-maxrate", str(top), "-bufsize", str(buffer), "-bsf:v", "filter_units=remove_types=6"]
    return rate, x264


def ffmpeg_writer(
    out_mp4,
    size,
    fps,
    preset="ultrafast",
    qp=None,
    crf=None,
    threads=None,
    frames=None,
    seed=None,
    width=None,
    bits_per_row=None,
    bits=None,
    key_qp=None,
):
    """An ffmpeg process reading raw yuv420p frames on stdin and writing H.264 yuv420p +faststart MP4, no audio.
    The frames are `size` pixels high and `width` wide (None: square).

    Rate control: by default every frame is `frame_bits(size, fps, bits_per_row)` bits, filler data included (given
    `frames`, the key frame KEY_FRAME_BUDGET times that and the next nearly as much), so every video of one size,
    frame rate and rate has the same frame sizes and byte size: what a blinded stimulus set needs
    (rendering.blinding, CONTRACTS §4). With `qp` (a constant quantiser) or `crf` (x264's rate factor) the
    sizes follow the content instead. ultrafast at qp 17 was the default before; the default now is as close to
    the frames (PSNR +0.8 dB on average, SSIM higher for every clip measured; bench/notes/2026-11-25-history.md).
    frames, seed: the number of frames that will come, for the default's random share of the rate per frame
    (`rate_dither`; no dither without `frames`), and its seed (None: fresh randomness).
    bits_per_row: the default's rate (None: RATE_BITS_PER_ROW; MESH_RATE_BITS_PER_ROW for a set with a mesh body).
    bits: each frame's budget in bits, as another video of the set has it (rendering.reencode), in place of the one
    `bits_per_row` gives; a whole number of bytes.
    key_qp: the key frame's quantiser (0-51; KEY_QP for a video encoded again because it came out a few bytes short),
    None for the rate control's own; the budget still caps the frame (x264's buffer overrides a zone's quantiser).
    """
    import imageio_ffmpeg  # here, not at the top: loading and sampling the models must not need an encoder

    width = width or size
    # A wide frame holds more side by side at the same scale (two people): its rate is a square frame's of the
    # same area, so that a set's frame sizes still follow from its pixel size alone.
    side = round((width * size) ** 0.5)
    if bits is None:
        bits = frame_bits(side, fps, bits_per_row)
    elif bits <= 0 or bits % 8:
        raise ValueError(f"a frame budget is a positive whole number of bytes, got {bits} bits")
    if key_qp is not None and not 0 <= key_qp <= 51:
        raise ValueError(f"key_qp is an H.264 quantiser, 0-51, got {key_qp}")
    rate, x264 = _rate_control(side, fps, qp, crf, frames, seed, bits, key_qp)

    cmd = [
        imageio_ffmpeg.get_ffmpeg_exe(),
        "-y",
        "-loglevel",
        "error",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "yuv420p",
        "-s",
        f"{width}x{size}",
        "-r",
        str(video_rate(fps)),
        "-i",
        "-",
        "-an",
        "-c:v",
        "libx264",
        "-preset",
        preset,
        *rate,
        "-pix_fmt",
        "yuv420p",
        "-movflags",
        "+faststart",
    ]
    if threads is not None:
        cmd += ["-threads", str(threads)]
        x264 += [f"threads={threads}", "lookahead-threads=1"]
    if x264:
        cmd += ["-x264-params", ":".join(x264)]
    return subprocess.Popen(cmd + [str(out_mp4)], stdin=subprocess.PIPE, stderr=subprocess.PIPE)
