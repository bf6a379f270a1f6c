"""Speech made for a known answer: a syllable-like burst (a harmonic tone at a voice's pitch, rising fast and dying
away) starting at each given time, silence between. Its onsets are the times given, so a test knows where a voice's
beats are; and a burst train over a span stands for a person speaking then."""

import numpy as np

RATE = 16_000


def syllables(times, seconds, rate=RATE, f0=160.0, length=0.12):
    """Mono float samples, `seconds` long, with a burst starting at each of `times` (s)."""
    out = np.zeros(int(round(seconds * rate)))
    n = int(length * rate)
    t = np.arange(n) / rate
    envelope = np.minimum(t / 0.005, 1.0) * np.exp(-t / 0.03) * np.cos(0.5 * np.pi * t / length) ** 2  # dies away
    burst = 0.4 * envelope * sum(np.sin(2 * np.pi * k * f0 * t) / k for k in (1, 2, 3))
    for start in times:
        i = int(round(start * rate))
        if 0 <= i < len(out):
            out[i : i + n] += burst[: len(out) - i]
    return out


def speech_over(span, seconds, rate=RATE, f0=160.0, every=0.2):
    """A person speaking over `span` (start, end in s): a syllable every `every` seconds."""
    return syllables(np.arange(span[0], span[1] - 0.1, every), seconds, rate, f0)
