"""The precision MG's streaming sampler runs in on this CPU, picked once and remembered.

bfloat16 (generation.models.mg_stream.MGStream) reads the big products' weights in half the bytes: on some CPUs
(an AMD Zen 4; an Intel Xeon with AMX) it samples many streams about twice as fast, on others (an Intel Xeon with
AVX512-BF16 but no AMX) it is slower (bench/RESULTS.md "sampling-bfloat16"). A CPU's flags do not tell which, so
the first sampling on a CPU measures both on the shipped MG, 30 streams as make_stimuli samples them, and picks
bfloat16 only where it is clearly faster (MIN_GAIN) and the shipped models' quality guard
(pretrained.quality_failures) holds with MG sampled in it. The pick and its figures are cached per CPU model, CPU
flags and torch version in CACHE_NAME under the user's cache folder, so that every later run on that CPU samples
the same bits without measuring.

MOGLOW_SAMPLER_PRECISION=float32|bfloat16 (or make_stimuli's --sample-precision) overrides the pick; =auto (the
default) picks as above. A GPU samples in float32. generation.sampling.sample (a checkpoint's windows, for
benchmarks and tools) keeps its explicit --precision, float32 by default.
"""

from __future__ import annotations

import json
import logging
import os
import platform
import time
from pathlib import Path

from moglow_eval.core.cli import UserError

log = logging.getLogger(__name__)

ENV = "MOGLOW_SAMPLER_PRECISION"
CHOICES = ("auto", "float32", "bfloat16")
CACHE_NAME = "sampler_precision.json"
# bfloat16 must be this much faster: two timings of one thing on a shared 2-core host differ by up to ~10%, and a
# pick that only breaks even is not worth samples that differ from float32's in their last bits.
MIN_GAIN = 1.15
STREAMS = 30  # the default job samples its 30 test items (and the catch and training items) in one batch
FLAGS = ("amx_bf16", "amx_tile", "avx512_bf16", "avx512f", "avx2")  # what decides the speed of bfloat16 products


class PrecisionError(UserError):
    """A bad precision setting: one line naming the variable or flag."""


def cache_file(env=None) -> Path:
    """CACHE_NAME under $XDG_CACHE_HOME/moglow-eval, else ~/.cache/moglow-eval."""
    env = os.environ if env is None else env
    base = env.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "moglow-eval" / CACHE_NAME


def cpu_key(cpuinfo: str | None = None, torch_version: str | None = None) -> str:
    """'MODEL | FLAGS | torch VERSION' of this CPU (or of the /proc/cpuinfo text given): what the pick is kept by."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text(errors="replace")
        except OSError:
            cpuinfo = ""
    fields = {}
    for line in cpuinfo.splitlines():
        name, _, value = line.partition(":")
        fields.setdefault(name.strip(), value.strip())
    model = fields.get("model name") or platform.processor() or platform.machine()
    flags = set(fields.get("flags", "").split())
    if torch_version is None:
        import torch  # lazy, as above; only its version: the key changes with the library that runs the products

        torch_version = torch.__version__
    return f"{model} | {','.join(f for f in FLAGS if f in flags) or '-'} | torch {torch_version}"


def decide(times_ms: dict, guard_failures: list[str] | None) -> tuple[str, str]:
    """(precision, why) from the sampler's ms per frame in each precision (and, where measured, their paired
    "ratio") and, where bfloat16 is faster, the quality guard's failures in it (None when the guard was not run)."""
    f32, bf16 = times_ms["float32"], times_ms["bfloat16"]
    gain = speed_gain(times_ms)
    if gain < MIN_GAIN:
        return "float32", f"bfloat16 {gain:.2f}x as fast ({bf16:.1f} against {f32:.1f} ms per frame): not {MIN_GAIN}x"
    if guard_failures is None:
        raise ValueError("decide: bfloat16 is faster, so the quality guard must have run")
    if guard_failures:
        return "float32", f"bfloat16 is {gain:.2f}x faster, but the quality guard fails: {guard_failures[0]}"
    return "bfloat16", f"{gain:.2f}x faster ({bf16:.1f} against {f32:.1f} ms per frame), quality guard holds"


def speed_gain(times_ms: dict) -> float:
    """How much faster bfloat16 is: the measurement's own "ratio" (float32's time over bfloat16's, paired frame by
    frame) where it gives one, else the ratio of the two times."""
    return float(times_ms.get("ratio") or times_ms["float32"] / times_ms["bfloat16"])


def pick(device, override, measure, guard, *, cache=None, env=None, key=None) -> str:
    """The precision to sample MG in: `override` (a flag), else $MOGLOW_SAMPLER_PRECISION, else auto: float32 on a
    GPU, on a CPU the cached pick for this CPU, measured now when there is none (`measure()` -> {precision: ms per
    frame}; `guard()` -> the quality guard's failures in bfloat16, asked only where bfloat16 is faster) and
    cached. A cache that cannot be read or written is measured past, not fatal. pretrained.sampler_precision
    passes the shipped MG's measurements; this module imports nothing of the models, so the sampler may import
    it."""
    env = os.environ if env is None else env
    choice = override or env.get(ENV) or "auto"
    if choice not in CHOICES:
        where = "--sample-precision" if override else ENV
        raise PrecisionError(f"{where}: {choice!r} must be one of {', '.join(CHOICES)}")
    if choice != "auto":
        return choice
    if str(device or "cpu").split(":")[0] != "cpu":
        return "float32"
    path, key = Path(cache or cache_file(env)), key or cpu_key()
    entries = _read(path)
    if key in entries and entries[key].get("precision") in CHOICES[1:]:
        return entries[key]["precision"]
    log.info("sampler precision: measuring float32 and bfloat16 once on this CPU (cached in %s)", path)
    times = measure()
    failures = None if speed_gain(times) < MIN_GAIN else guard()
    precision, why = decide(times, failures)
    entries[key] = {
        "precision": precision,
        "why": why,
        "ms_per_frame": {k: round(v, 2) for k, v in times.items() if k != "ratio"},
        "speed_gain": round(speed_gain(times), 3),
        "guard_failures": failures,
        "measured": time.strftime("%Y-%m-%d"),
    }
    _write(path, entries)
    log.info("sampler precision: %s (%s)", precision, why)
    return precision


def _read(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _write(path: Path, entries: dict) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}")
        tmp.write_text(json.dumps(entries, indent=1) + "\n", encoding="utf-8")
        tmp.replace(path)  # whole or not at all, should two runs measure at once
    except OSError as e:
        log.warning("note: cannot cache the sampler precision in %s (%s); it is measured again next time", path, e)
