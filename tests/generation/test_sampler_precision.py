"""Issue 46, item 7: MG's sampler picks its precision once per CPU: measured at first use, cached, overridable, and
bfloat16 only where it is faster and the quality guard holds in it (generation.sampling.precision).

The decision and the cache are tested with measurements given to them (a test never times anything); what the
measurements are on this host is bench/bench_sampler_precision.py's business (bench/RESULTS.md)."""

import json

import pytest

from generation.sampling import precision
from generation.sampling.precision import MIN_GAIN, PrecisionError, decide, pick

CPUINFO = """processor\t: 0
model name\t: Intel(R) Xeon(R) Platinum 8480+
flags\t\t: fpu sse avx2 avx512f avx512_bf16 amx_bf16 amx_tile amx_int8
processor\t: 1
model name\t: Intel(R) Xeon(R) Platinum 8480+
"""


class Calls:
    """A measurement or guard that returns what it is given and counts its calls."""

    def __init__(self, result):
        self.result, self.n = result, 0

    def __call__(self):
        self.n += 1
        return self.result


def never():
    raise AssertionError("called where the pick needed no measurement")


def test_decide_takes_bfloat16_only_when_faster_and_the_guard_holds():
    fast = {"float32": 32.0, "bfloat16": 12.0}
    assert decide(fast, [])[0] == "bfloat16"
    assert decide(fast, ["MG jerk 1.4 against max 1.27"]) == (
        "float32",
        "bfloat16 is 2.67x faster, but the quality guard fails: MG jerk 1.4 against max 1.27",
    )
    assert decide({"float32": 27.0, "bfloat16": 36.0}, None)[0] == "float32"  # slower (Xeon without AMX)
    # faster, but by less than MIN_GAIN: timing noise, not a reason to change the samples' bits
    assert decide({"float32": 10.0, "bfloat16": 10.0 / (MIN_GAIN - 0.05)}, None)[0] == "float32"
    with pytest.raises(ValueError):
        decide(fast, None)  # faster but never guarded: a bug in the caller


def test_first_use_measures_then_the_cache_answers(tmp_path):
    cache = tmp_path / "cache" / "sampler_precision.json"
    measure, guard = Calls({"float32": 32.0, "bfloat16": 12.0}), Calls([])
    assert pick("cpu", None, measure, guard, cache=cache, env={}, key="cpu A") == "bfloat16"
    assert (measure.n, guard.n) == (1, 1)
    entry = json.loads(cache.read_text())["cpu A"]
    assert entry["precision"] == "bfloat16" and entry["ms_per_frame"] == {"float32": 32.0, "bfloat16": 12.0}
    assert entry["guard_failures"] == [] and "2.67x faster" in entry["why"]
    # later runs on this CPU: the cached pick, nothing measured
    assert pick("cpu", None, never, never, cache=cache, env={}, key="cpu A") == "bfloat16"
    # another CPU (or torch version) in the same cache: measured for itself, the first entry kept
    slow = Calls({"float32": 27.0, "bfloat16": 36.0})
    assert pick("cpu", None, slow, never, cache=cache, env={}, key="cpu B") == "float32"
    assert slow.n == 1 and set(json.loads(cache.read_text())) == {"cpu A", "cpu B"}


def test_a_failing_guard_keeps_float32_and_is_recorded(tmp_path):
    cache = tmp_path / "p.json"
    guard = Calls(["MG fmd_over_floor 1.2 against max 1.002"])
    assert pick("cpu", None, Calls({"float32": 30.0, "bfloat16": 10.0}), guard, cache=cache, env={}, key="k") == (
        "float32"
    )
    entry = json.loads(cache.read_text())["k"]
    assert entry["guard_failures"] == guard.result and "quality guard fails" in entry["why"]


def test_overrides_and_devices_need_no_measurement(tmp_path):
    cache = tmp_path / "p.json"
    assert pick("cpu", "float32", never, never, cache=cache, env={}) == "float32"
    assert pick("cpu", None, never, never, cache=cache, env={precision.ENV: "bfloat16"}) == "bfloat16"
    assert pick("cpu", "float32", never, never, cache=cache, env={precision.ENV: "bfloat16"}) == "float32"  # flag wins
    assert pick("cuda:0", None, never, never, cache=cache, env={}) == "float32"
    assert not cache.exists()
    with pytest.raises(PrecisionError, match=f"{precision.ENV}: 'half' must be one of auto, float32, bfloat16"):
        pick("cpu", None, never, never, cache=cache, env={precision.ENV: "half"})


def test_a_broken_or_unwritable_cache_is_measured_past(tmp_path, caplog):
    broken = tmp_path / "p.json"
    broken.write_text("{not json")
    measure = Calls({"float32": 30.0, "bfloat16": 40.0})
    assert pick("cpu", None, measure, never, cache=broken, env={}, key="k") == "float32" and measure.n == 1
    assert json.loads(broken.read_text())["k"]["precision"] == "float32"  # rewritten whole
    blocked = tmp_path / "file"
    blocked.write_text("")
    assert pick("cpu", None, measure, never, cache=blocked / "p.json", env={}, key="k") == "float32"
    assert "cannot cache the sampler precision" in caplog.text


def test_the_cache_is_kept_per_cpu_model_flags_and_torch_version(tmp_path):
    key = precision.cpu_key(CPUINFO, "2.13.0")
    assert key == "Intel(R) Xeon(R) Platinum 8480+ | amx_bf16,amx_tile,avx512_bf16,avx512f,avx2 | torch 2.13.0"
    assert precision.cpu_key(CPUINFO, "2.14.0") != key
    assert precision.cpu_key(CPUINFO.replace(" amx_bf16 amx_tile", ""), "2.13.0") != key
    assert (
        precision.cache_file({"XDG_CACHE_HOME": str(tmp_path)}) == tmp_path / "moglow-eval" / "sampler_precision.json"
    )


@pytest.mark.full  # the full tier: the shipped MG timed and its quality guard run
def test_the_shipped_mgs_measurement_and_guard_run_as_the_pick_calls_them():
    """What pretrained.sampler_precision hands the pick, on the shipped MG: both precisions timed (their values are
    bench/'s business), and the quality guard's figures in bfloat16 holding, as bench/RESULTS.md records."""
    from generation.sampling import pretrained

    times = pretrained.measure_speed(frames=3, warmup=1, streams=4)
    assert set(times) == {"float32", "bfloat16", "ratio"} and all(v > 0 for v in times.values())
    assert pretrained.bfloat16_guard_failures() == []


@pytest.mark.parametrize("early", [True, False])
def test_the_measurement_stops_early_only_where_bfloat16_is_hopeless(monkeypatch, early):
    """measure_speed stops after EARLY_FRAMES frames when bfloat16 is under EARLY_RATIO of float32's speed: here
    with the ratio's bar set so high that any CPU is under it, counted by the frames the streams were asked for."""
    from generation.models.mg_stream import MGStream
    from generation.sampling import pretrained

    steps = []
    step = MGStream.step
    monkeypatch.setattr(MGStream, "step", lambda self, c: steps.append(1) or step(self, c))
    monkeypatch.setattr(pretrained, "EARLY_FRAMES", 2)
    monkeypatch.setattr(pretrained, "EARLY_RATIO", 1e9)
    times = pretrained.measure_speed(frames=6, warmup=1, streams=2, early=early)
    assert len(steps) == 2 * (1 + (2 if early else 6)) and times["ratio"] > 0
