"""The encoder: raw yuv420p frames piped into ffmpeg's libx264, out as an H.264 MP4 for browsers."""

import subprocess


def ffmpeg_writer(out_mp4, size, fps, preset="ultrafast", qp=17, crf=None, threads=None):
    """An ffmpeg process reading raw yuv420p frames on stdin and writing H.264 yuv420p +faststart MP4, no audio.

    Quality: a constant quantiser `qp`, or x264's rate factor `crf` where given. A constant quantiser spares
    x264 the per-frame complexity estimate that crf needs (~10% of the encoder's time with ultrafast); for our
    line drawings ultrafast at qp 17 is as close to the frames as superfast at crf 20 (PSNR ~53 dB).
    """
    import imageio_ffmpeg  # here, not at the top: loading and sampling the models must not need an encoder

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
        f"{size}x{size}",
        "-r",
        f"{fps:g}",
        "-i",
        "-",
        "-an",
        "-c:v",
        "libx264",
        "-preset",
        preset,
        *(["-crf", str(crf)] if crf is not None else ["-qp", str(qp)]),
        "-pix_fmt",
        "yuv420p",
        "-movflags",
        "+faststart",
    ]
    if threads is not None:
        cmd += ["-threads", str(threads), "-x264-params", f"threads={threads}:lookahead-threads=1"]
    return subprocess.Popen(cmd + [str(out_mp4)], stdin=subprocess.PIPE, stderr=subprocess.PIPE)
