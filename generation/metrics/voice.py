"""When a voice starts a sound and when it speaks: the audio side of the gesture measures, from samples alone.

- Onsets (`onsets`), the audio beats of BeatAlign: a spectral-flux onset detector after librosa's defaults, the
  detector BEAT's BeatAlign calls. The mono samples are cut into HOP_S frames (a Hann window of WINDOW_S); each frame's
  spectrum is pooled into N_BANDS log-spaced bands from 60 Hz to 8 kHz, in dB, floored 80 dB below the loudest;
  the onset strength of a frame is the mean rise of its bands over the frame before, scaled to 0..1. A frame is an
  onset where its strength is the greatest within PRE_MAX_S before it, stands DELTA above its mean over AVG_S either
  side, comes WAIT_S or more after the last onset, and the frame is not silent (within GATE_DB of the voice's
  loudest frames). Each onset is then moved back to the quietest frame before it (BEAT backtracks its onsets to the
  RMS energy's minimum), where the sound begins.
- Speech activity (`speaking`): a frame speaks where its RMS level is within GATE_DB of the voice's loud frames (its
  95th percentile) and above SILENCE_DBFS; pauses shorter than BRIDGE_S are bridged and bursts shorter than
  MIN_BURST_S dropped.
Samples are float in -1..1 at any rate; times are seconds from the first sample.
"""

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

HOP_S = 0.010  # between frames
WINDOW_S = 0.046  # a frame's window
N_BANDS = 40
BAND_HZ = (60.0, 8000.0)
FLOOR_DB = 80.0  # bands below the loudest by more than this count as the floor
PRE_MAX_S, AVG_S, WAIT_S, DELTA = 0.03, 0.10, 0.03, 0.07  # peak picking, as librosa's onset_detect
GATE_DB = 35.0  # a frame quieter than the voice's loud frames by more than this is silence
SILENCE_DBFS = -55.0  # and any frame below this
BRIDGE_S, MIN_BURST_S = 0.3, 0.1  # speech activity: pauses bridged, bursts dropped


def _frames(samples, rate):
    """Windowed frames [F, W] of mono samples, one every HOP_S, centred on each frame's time."""
    x = np.asarray(samples, dtype=np.float64).reshape(len(samples), -1).mean(axis=1)
    hop, width = max(1, int(round(HOP_S * rate))), max(8, int(round(WINDOW_S * rate)))
    x = np.pad(x, (width // 2, width // 2))
    n = max(0, (len(x) - width) // hop + 1)
    idx = np.arange(width)[None, :] + hop * np.arange(n)[:, None]
    return x[idx], width


def levels_db(samples, rate):
    """Each frame's RMS level in dBFS [F] (frames every HOP_S)."""
    frames, _ = _frames(samples, rate)
    return 10 * np.log10(np.mean(frames**2, axis=1) + 1e-12)


def _loud_gate(level):
    """The level (dB) below which a frame is silence: GATE_DB under the loud frames, and never below SILENCE_DBFS."""
    return max(SILENCE_DBFS, np.percentile(level, 95) - GATE_DB) if len(level) else SILENCE_DBFS


def onset_strength(samples, rate):
    """The onset strength of each frame [F], 0..1 (see the module's docstring)."""
    frames, width = _frames(samples, rate)
    if len(frames) < 2:
        return np.zeros(len(frames))
    spec = np.abs(np.fft.rfft(frames * np.hanning(width), axis=1)) ** 2
    freqs = np.fft.rfftfreq(width, 1 / rate)
    edges = np.geomspace(BAND_HZ[0], min(BAND_HZ[1], rate / 2), N_BANDS + 1)
    band = np.digitize(freqs, edges) - 1
    energy = np.stack([spec[:, band == b].sum(axis=1) for b in range(N_BANDS)], axis=1)
    db = 10 * np.log10(energy + 1e-12)
    db = np.maximum(db, db.max() - FLOOR_DB)
    flux = np.concatenate([[0.0], np.maximum(np.diff(db, axis=0), 0).mean(axis=1)])
    span = flux.max() - flux.min()
    return (flux - flux.min()) / span if span > 0 else np.zeros_like(flux)


def onsets(samples, rate):
    """The voice's onset times (s), backtracked to where each sound begins; empty for silence."""
    strength = onset_strength(samples, rate)
    level = levels_db(samples, rate)[: len(strength)]
    if len(strength) < 2:
        return np.zeros(0)
    pre, avg, wait = (max(1, int(round(s / HOP_S))) for s in (PRE_MAX_S, AVG_S, WAIT_S))
    padded = np.pad(strength, (pre, 0), constant_values=-np.inf)
    peak = strength >= sliding_window_view(padded, pre + 1).max(axis=1)  # the greatest within PRE_MAX_S before it
    window = np.pad(strength, avg, mode="constant", constant_values=np.nan)
    mean = np.nanmean(sliding_window_view(window, 2 * avg + 1), axis=1)  # its mean over AVG_S either side
    candidates = np.flatnonzero(peak & (strength >= mean + DELTA) & (level >= _loud_gate(level)))
    found, last = [], -(10**9)
    for t in candidates[candidates > 0]:
        if t - last >= wait:
            found.append(t)
            last = t
    # Two onsets within one sound can backtrack to the same start: it is one onset.
    return np.unique([_backtrack(level, t) for t in found]).astype(np.float64) * HOP_S


def _backtrack(level, t):
    """The frame of the quietest point before frame t, walking back while the level falls."""
    while t > 0 and level[t - 1] < level[t]:
        t -= 1
    return t


def speaking(samples, rate):
    """Whether the voice speaks in each frame [F] bool (frames every HOP_S; see the module's docstring)."""
    level = levels_db(samples, rate)
    on = level >= _loud_gate(level) if len(level) and level.max() > SILENCE_DBFS else np.zeros(len(level), bool)
    on = _fill_runs(on, False, int(round(BRIDGE_S / HOP_S)))  # short pauses inside speech
    return _fill_runs(on, True, int(round(MIN_BURST_S / HOP_S)))  # short bursts of noise


def _fill_runs(mask, value, shorter_than):
    """`mask` with each inner run of `value` shorter than `shorter_than` frames flipped (a run at either end is kept
    when it is of pauses, so that a voice that starts late still starts late)."""
    mask = mask.copy()
    edges = np.flatnonzero(np.diff(np.concatenate([[not value], mask == value, [not value]]).astype(np.int8)))
    for start, end in zip(edges[::2], edges[1::2]):
        inner = start > 0 and end < len(mask)
        if end - start < shorter_than and (inner or value):
            mask[start:end] = not value
    return mask


def at_frames(activity, n_frames, fps):
    """Speech activity [F] on the audio's HOP_S grid, read at each of n_frames motion frames [n_frames] bool."""
    idx = np.minimum(np.round(np.arange(n_frames) / fps / HOP_S).astype(int), len(activity) - 1)
    return activity[idx] if len(activity) else np.zeros(n_frames, bool)
