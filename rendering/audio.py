"""Sound for stimulus videos: read an item's audio, check it, normalise its loudness, and mux it into a video.

- `read_audio`: a WAV or FLAC file (any sample rate, mono or stereo) as float32 samples at RATE, decoded by
  ffmpeg after its header has been checked here (a sample rate of 0, or no audio at all, is one clear error).
- `integrated_loudness`: ITU-R BS.1770-4 integrated loudness in LUFS (K-weighting, 400 ms blocks overlapping by
  75%, the absolute gate at -70 LUFS and the relative gate 10 LU below), in numpy; `normalise` scales a signal
  to a target (EBU R128: -23 LUFS). The tests check the result with ffmpeg's own ebur128 meter.
- `mux_audio`: the span [start, start + duration) of a normalised signal as AAC in an existing MP4, the video
  stream copied, audio and video starting together (ffmpeg writes the AAC encoder's priming as an edit list,
  which players honour), so sound and motion stay in sync to well within a frame.
"""

import os
import struct
import subprocess
from pathlib import Path

import numpy as np

from .errors import RenderError

RATE = 48_000  # samples per second of every stimulus's audio
AAC_BITRATE = "128k"
SILENCE_DBFS = -60.0  # an RMS below this over a clip's span is silence
MAX_SECONDS = 3600.0  # the most of one file ever decoded
MAX_RATE = 768_000  # samples per second in a header beyond any real recording


def _ffmpeg():
    import imageio_ffmpeg  # here, as in encode: sampling the models needs no encoder

    return imageio_ffmpeg.get_ffmpeg_exe()


def _head(path):
    """The first 64 KB of an audio file, where its header is; RenderError naming the file when it cannot be read."""
    try:
        with open(path, "rb") as f:
            return f.read(1 << 16)
    except OSError as e:
        raise RenderError(f"{path}: cannot read the audio file ({e.strerror or e})") from None


def _wav_chunks(head):
    """(id, offset of its body, declared size) of each RIFF chunk whose 8-byte header lies in `head`, in order: the
    one walk of a WAV's chunks (each padded to an even length)."""
    pos = 12
    while pos + 8 <= len(head):
        size = struct.unpack("<I", head[pos + 4 : pos + 8])[0]
        yield head[pos : pos + 4], pos + 8, size
        pos += 8 + size + (size & 1)


def _header(path, head=None):
    """(channels, sample rate) from a WAV or FLAC header; RenderError naming the file otherwise."""
    head = _head(path) if head is None else head
    if head[:4] == b"RIFF" and head[8:12] == b"WAVE":
        for cid, at, _ in _wav_chunks(head):
            if cid == b"fmt " and at + 8 <= len(head):
                channels, rate = struct.unpack("<HI", head[at + 2 : at + 8])
                return channels, rate
        raise RenderError(f"{path}: a WAV file without a 'fmt ' chunk")
    if head[:4] == b"fLaC" and len(head) >= 8 + 18:
        info = int.from_bytes(head[18:21], "big")  # STREAMINFO: 20 bits of rate, 3 of channels - 1, ...
        return ((info >> 1) & 0x7) + 1, info >> 4
    raise RenderError(f"{path}: not a WAV or FLAC file")


def audio_seconds(path):
    """The length of a WAV or FLAC file in seconds, from its header and, for a WAV, its size (None where they do not
    say: a FLAC without its sample count, a WAV whose data chunk lies beyond the first 64 KB); RenderError naming
    the file for anything else."""
    head = _head(path)
    _header(path, head)
    if head[:4] == b"fLaC":
        total = int.from_bytes(head[18:26], "big") & ((1 << 36) - 1)
        rate = int.from_bytes(head[18:21], "big") >> 4
        return total / rate if total and rate else None
    byte_rate = 0
    for cid, at, size in _wav_chunks(head):
        if cid == b"fmt " and at + 12 <= len(head):
            byte_rate = struct.unpack("<I", head[at + 8 : at + 12])[0]
        if cid == b"data":
            if not byte_rate:
                raise RenderError(f"{path}: the WAV header's byte rate is 0: write the file again")
            # What plays is the data the file holds: a streamed WAV declares 0xFFFFFFFF bytes, a cut file more
            # than it has. A header alone could make a short file hours long, or turn a length check off.
            held = max(os.path.getsize(path) - at, 0)
            return (held if size == 0xFFFFFFFF else min(size, held)) / byte_rate
    return None


def read_audio(path, max_seconds=MAX_SECONDS, start_s=0.0):
    """Samples [N, channels] float32 at RATE Hz (mono or stereo kept as it is), at most `max_seconds` of them from
    `start_s` seconds into the file.

    ffmpeg decodes only the first `max_seconds` (at most MAX_SECONDS) from there, so a small FLAC or a WAV whose
    header claims hours holds at most that much in memory; the caller asks for what it will play."""
    channels, rate = _header(path)
    if rate <= 0:
        raise RenderError(f"{path}: the sample rate is {rate}; an audio file needs a positive one")
    if rate > MAX_RATE:
        raise RenderError(f"{path}: the sample rate is {rate} Hz, more than the limit of {MAX_RATE} Hz")
    if channels not in (1, 2):
        raise RenderError(f"{path}: {channels} channels; give mono or stereo audio")
    seconds = f"{min(float(max_seconds), MAX_SECONDS):.3f}"
    # -ss before -i seeks in the input: sample-exact for PCM and FLAC, and nothing before the span is decoded.
    cmd = [_ffmpeg(), "-v", "error", "-ss", f"{max(float(start_s), 0.0):.6f}", "-i", str(path), "-t", seconds]
    cmd += ["-f", "f32le", "-ac", str(channels)]
    out = subprocess.run([*cmd, "-ar", str(RATE), "-"], capture_output=True)
    if out.returncode != 0:
        msg = out.stderr.decode(errors="replace").strip().splitlines()
        raise RenderError(f"{path}: unreadable audio ({msg[-1] if msg else 'ffmpeg failed'})")
    samples = np.frombuffer(out.stdout, dtype="<f4").reshape(-1, channels)
    if not len(samples):
        raise RenderError(f"{path}: no audio samples")
    return samples


def _biquad(x, b, a):
    from scipy.signal import lfilter

    return lfilter(b, a, x, axis=0)


def _k_weighting_48k(x):
    """BS.1770's pre-filter (a high shelf) and RLB high-pass, with the standard's coefficients at 48 kHz."""
    shelf_b = [1.53512485958697, -2.69169618940638, 1.19839281085285]
    shelf_a = [1.0, -1.69065929318241, 0.73248077421585]
    hp_b = [1.0, -2.0, 1.0]
    hp_a = [1.0, -1.99004745483398, 0.99007225036621]
    return _biquad(_biquad(x, shelf_b, shelf_a), hp_b, hp_a)


def integrated_loudness(samples, rate=RATE):
    """BS.1770-4 integrated loudness (LUFS) of float samples [N, channels] at 48 kHz; -inf for silence."""
    if rate != RATE:
        raise ValueError(f"integrated_loudness: the K-weighting here is for {RATE} Hz, got {rate}")
    y = _k_weighting_48k(np.asarray(samples, dtype=np.float64))
    block, hop = int(0.4 * rate), int(0.1 * rate)
    if len(y) < block:
        return float("-inf")
    power = np.cumsum(np.concatenate([np.zeros((1, y.shape[1])), y**2]), axis=0)
    starts = np.arange(0, len(y) - block + 1, hop)
    z = (power[starts + block] - power[starts]) / block  # mean square per block and channel
    z = z.sum(axis=1)  # channel weights are 1 for left, right and mono
    with np.errstate(divide="ignore"):
        lk = -0.691 + 10 * np.log10(z)
    z = z[lk > -70.0]
    if not len(z):
        return float("-inf")
    relative = -0.691 + 10 * np.log10(z.mean()) - 10.0
    with np.errstate(divide="ignore"):
        z = z[-0.691 + 10 * np.log10(z) > relative]
    return float(-0.691 + 10 * np.log10(z.mean()))


def normalise(samples, target_lufs):
    """Samples scaled to `target_lufs` integrated loudness (peaks limited to full scale)."""
    level = integrated_loudness(samples)
    if not np.isfinite(level):
        return samples
    gain = 10 ** ((target_lufs - level) / 20)
    return np.clip(samples * gain, -1.0, 1.0).astype(np.float32)


SPEECH_FLOOR_LUFS = -50.0  # a voice quieter than this over an item says nothing there: it is never raised
PAN = 0.6  # how far to its side each voice of a stereo mix is panned (1: hard left or right)


def mix_voices(tracks, target_lufs, pans=None):
    """One item's sound from each person's voice: the tracks [N, channels] float32 at RATE (of one length) each
    made mono and normalised to `target_lufs` where it holds speech (a listener's near-silence, quieter than
    SPEECH_FLOOR_LUFS, is kept as it is, never raised to speech level), then summed, and the sum normalised to
    `target_lufs`. Mono [N, 1] with `pans` None; else stereo [N, 2], voice k panned to pans[k] (-1 left .. 1
    right) at constant power."""
    voices = []
    for track in tracks:
        mono = np.asarray(track, np.float32).mean(axis=1, keepdims=True)
        if integrated_loudness(mono) > SPEECH_FLOOR_LUFS:
            mono = normalise(mono, target_lufs)
        voices.append(mono[:, 0])
    if pans is None:
        mixed = np.sum(voices, axis=0)[:, None]
    else:
        angle = (np.clip(np.asarray(pans, np.float64), -1, 1) + 1) * np.pi / 4
        gains = np.stack([np.cos(angle), np.sin(angle)], 1) * np.sqrt(2)  # centred: each channel at unity
        mixed = sum(v[:, None] * g[None].astype(np.float32) for v, g in zip(voices, gains))
    return normalise(mixed.astype(np.float32), target_lufs)


def write_wav(path, samples, rate=RATE):
    """Float samples [N] or [N, channels] in [-1, 1] as a 16-bit PCM WAV file."""
    import wave

    samples = np.asarray(samples, np.float32)
    samples = samples[:, None] if samples.ndim == 1 else samples
    with wave.open(str(path), "wb") as w:
        w.setnchannels(samples.shape[1])
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes((np.clip(samples, -1, 1) * 32767).round().astype("<i2").tobytes())


def rms_dbfs(samples):
    with np.errstate(divide="ignore"):
        return float(10 * np.log10(np.mean(np.asarray(samples, np.float64) ** 2) + 1e-20))


def mux_audio(video, samples, start_s, duration_s):
    """Put samples[start, start + duration) (float32 [N, channels] at RATE) into the MP4 `video` as AAC, in
    place; a span past the end of the samples is an error (check lengths before rendering)."""
    a, n = int(round(start_s * RATE)), int(round(duration_s * RATE))
    if a + n > len(samples):
        raise RenderError(f"{video}: the audio is {len(samples) / RATE:.2f} s, shorter than the clip's span")
    span = np.ascontiguousarray(samples[a : a + n], dtype="<f4")
    video = Path(video)
    tmp = video.with_name(video.stem + ".sound.mp4")
    cmd = [_ffmpeg(), "-y", "-v", "error", "-i", str(video), "-f", "f32le", "-ar", str(RATE)]
    cmd += ["-ac", str(span.shape[1]), "-i", "-", "-map", "0:v", "-map", "1:a", "-c:v", "copy", "-c:a", "aac"]
    cmd += ["-b:a", AAC_BITRATE, "-map_metadata", "-1", "-fflags", "+bitexact", "-flags:a", "+bitexact"]
    cmd += ["-movflags", "+faststart", str(tmp)]
    out = subprocess.run(cmd, input=span.tobytes(), capture_output=True)
    if out.returncode != 0:
        msg = out.stderr.decode(errors="replace").strip().splitlines()
        raise RenderError(f"{video}: muxing the audio failed ({msg[-1] if msg else 'no message'})")
    tmp.replace(video)
