"""Sound checks on a stimulus video: its audio decoded by ffmpeg, its loudness by ffmpeg's own EBU R128 meter, and
how much of a voice (tests/helpers/seamless_fixtures.VOICE_HZ: a harmonic tone at its pitch) is in it."""

import re
import subprocess

import imageio_ffmpeg
import numpy as np

from rendering.audio import RATE

FFMPEG = imageio_ffmpeg.get_ffmpeg_exe()


def decoded_audio(mp4, channels=1):
    """The video's audio as decoded by ffmpeg: float32 [N, channels] at RATE, from the file's time 0."""
    out = subprocess.run(
        [FFMPEG, "-v", "error", "-i", str(mp4), "-map", "0:a", "-ac", str(channels), "-ar", str(RATE),
         "-f", "f32le", "-"],
        capture_output=True, check=True,
    )  # fmt: skip
    return np.frombuffer(out.stdout, "<f4").reshape(-1, channels)


def ffmpeg_loudness(mp4):
    """The video's integrated loudness in LUFS, by ffmpeg's ebur128 filter."""
    err = subprocess.run(
        [FFMPEG, "-nostats", "-i", str(mp4), "-map", "0:a", "-af", "ebur128", "-f", "null", "-"],
        capture_output=True, text=True,
    ).stderr  # fmt: skip
    return float(re.findall(r"I:\s+(-?[\d.]+) LUFS", err)[-1])


def voice_energy(x, f0):
    """The energy of samples x [N] around the first three harmonics of a voice's pitch f0."""
    spec = np.abs(np.fft.rfft(x)) ** 2
    freqs = np.fft.rfftfreq(len(x), 1 / RATE)
    return sum(spec[(freqs > k * f0 - 6) & (freqs < k * f0 + 6)].sum() for k in (1, 2, 3))
