"""A simulated crowd: raters that use the public API exactly as the page does.

Each rater creates a session (with a platform session id, as Prolific's link gives one, which is also its proof
for resuming after a lost reply), and for every trial fetches the video and waits until the server would accept
an answer: the clip's duration times the server's `min_view` (from the session reply; 1 = the whole clip). It
acknowledges the familiarisation clips (rating null), then rates every clip it is served. An attentive rater
answers round(quality(clip) + bias + noise), clipped to 1..5, with a personal bias
and noise level, and recognises the bad examples (catch clips) as such. A careless rater answers uniformly
at random, and so fails catch trials. The per-clip quality comes by default from metrics.csv (worse objective
metrics -> lower quality; the best condition by the metrics gets QUALITY_HIGH, the worst QUALITY_LOW), else
from DEFAULT_QUALITY, and can be set per condition.

Only the server's API is used; to know which condition a clip belongs to, the crowd reads the manifest (and
metrics.csv beside it) or, without a manifest, the admin clip table (/admin/clips.json, needs ADMIN_TOKEN).

The crowd answers whatever design the server runs (the session reply names it, CONTRACTS §8), fetching every clip
of a trial and waiting as long as the server requires for all of them: in a pairwise study an attentive rater
prefers the clip of higher quality (its own noise and a tie band; the margin picks "slightly" or "clearly") and
never the bad example; in a parallel study it rates every clip of the page on 0..100 (the 1..5 quality scaled)
and the bad example below the page's NAT clip. Careless raters answer at random in every design.
"""

from __future__ import annotations

import json
import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import requests

from .manifest import METRIC_COLUMNS, AppError, load_manifest, load_metrics

DEFAULT_QUALITY = {"NAT": 4.2, "MG": 3.6, "FL": 2.6, "BAD": 1.3}
OTHER_QUALITY = 3.0
QUALITY_HIGH, QUALITY_LOW = 4.3, 1.3
BIAS_SD = 0.3
PREFERENCE_TIE, PREFERENCE_CLEAR = 0.3, 1.0  # quality margins: below the first no preference, above the second clear
NOISE_SD = (0.35, 0.7)  # each rater's own noise level is drawn from this range
MAX_RATERS = 100_000


@dataclass
class ClipInfo:
    clip_id: str
    condition: str
    role: str
    duration_ms: int = 2000
    quality: float | None = None
    metrics: dict = field(default_factory=dict)


def parse_quality(text: str | None) -> dict[str, float]:
    out = {}
    for part in (text or "").split(","):
        if not part.strip():
            continue
        name, sep, value = part.partition("=")
        try:
            q = float(value)
        except ValueError:
            q = math.nan
        if not sep or not name.strip() or not 1.0 <= q <= 5.0:
            raise AppError(f"--quality: {part.strip()!r} must be CONDITION=NUMBER with 1 <= NUMBER <= 5")
        out[name.strip()] = q
    return out


def quality_from_metrics(clips: dict[str, ClipInfo]) -> dict[str, float]:
    """Per-condition quality from the clips' objective metrics; also sets a small per-clip offset.

    Each metric is turned into a percentile rank over all clips (0 = best, 1 = worst; ranks, so one extreme
    condition such as NAT with zero bone-length error does not squash the others together); a clip's badness is
    its mean rank. Conditions are placed linearly between QUALITY_HIGH (least bad) and QUALITY_LOW (most bad)
    by mean badness, so the order of the conditions is the order the metrics give (NAT best and BAD worst
    whenever the metrics say so)."""
    from scipy.stats import rankdata

    have = [c for c in clips.values() if any(c.metrics.get(m) is not None for m in METRIC_COLUMNS)]
    if not have:
        return {}
    total = np.zeros(len(have))
    n = np.zeros(len(have))
    for m in METRIC_COLUMNS:
        vals = np.array([np.nan if c.metrics.get(m) is None else c.metrics[m] for c in have], float)
        ok = np.isfinite(vals)
        if ok.sum() < 2 or np.ptp(vals[ok]) == 0:
            continue
        total[ok] += (rankdata(vals[ok], method="average") - 1) / (ok.sum() - 1)
        n[ok] += 1
    badness = np.where(n > 0, total / np.maximum(n, 1), 0.5)
    by_cond: dict[str, list[float]] = {}
    for c, b in zip(have, badness):
        by_cond.setdefault(c.condition, []).append(float(b))
    mean = {k: float(np.mean(v)) for k, v in by_cond.items()}
    lo, hi = min(mean.values()), max(mean.values())
    quality = {
        k: (QUALITY_HIGH + QUALITY_LOW) / 2
        if hi - lo < 1e-9
        else QUALITY_HIGH - (QUALITY_HIGH - QUALITY_LOW) * (b - lo) / (hi - lo)
        for k, b in mean.items()
    }
    for c, b in zip(have, badness):
        # Within a condition, worse clips are rated a little lower (at most 0.4 of a point).
        c.quality = quality[c.condition] - float(np.clip(1.5 * (b - mean[c.condition]), -0.4, 0.4))
    return quality


def load_clips(url: str, manifest=None, admin_token=None, timeout=30.0) -> dict[str, ClipInfo]:
    clips = {}
    if manifest:
        for c in load_manifest(manifest, check_files=False):
            clips[c.clip_id] = ClipInfo(c.clip_id, c.condition, c.role, c.duration_ms or 2000)
        mpath = Path(manifest).resolve().parent / "metrics.csv"
        if mpath.is_file():
            for cid, rec in load_metrics(mpath).items():
                if cid in clips:
                    clips[cid].metrics = {m: rec.get(m) for m in METRIC_COLUMNS}
        return clips
    if not admin_token:
        raise AppError("simulate needs --manifest, or ADMIN_TOKEN to read the clip table from the server")
    try:
        r = requests.get(
            url.rstrip("/") + "/admin/clips.json", timeout=timeout, headers={"Authorization": f"Bearer {admin_token}"}
        )
    except requests.RequestException as e:
        raise AppError(f"{url}: server not reachable ({e.__class__.__name__})") from None
    if r.status_code != 200:
        raise AppError(f"{url}/admin/clips.json: HTTP {r.status_code} ({r.text[:200].strip()})")
    for c in r.json()["clips"]:
        dur = int(1000 * c["frames"] / c["fps"]) if c.get("frames") and c.get("fps") else 2000
        clips[c["clip_id"]] = ClipInfo(
            c["clip_id"], c["condition"], c["role"], dur, metrics={m: c.get(m) for m in METRIC_COLUMNS}
        )
    return clips


def check_design(url: str, design: str, timeout=30.0) -> None:
    """AppError unless the server at `url` runs `design` (its /healthz names it)."""
    try:
        r = requests.get(url.rstrip("/") + "/healthz", timeout=timeout)
        running = r.json().get("design", "acr")
    except (requests.RequestException, ValueError) as e:
        raise AppError(f"{url}: server not reachable ({e.__class__.__name__})") from None
    if running != design:
        raise AppError(f"--design {design}: the server at {url} runs a {running} study")


class _Client:
    """HTTP with retries: a server restart or a dropped connection is waited out until the deadline.
    Every call the crowd makes is idempotent (session by external id, GET next, rating per trial)."""

    def __init__(self, base: str, deadline: float, request_timeout: float = 30.0):
        self.base, self.deadline, self.request_timeout = base.rstrip("/"), deadline, request_timeout
        self.http = requests.Session()
        self.retries = 0

    def call(self, method: str, path: str, body=None, raw=False):
        """(status, JSON body), or (status, bytes) with `raw` (a video)."""
        delay = 0.05
        while True:
            try:
                r = self.http.request(method, self.base + path, json=body, timeout=self.request_timeout)
                if r.status_code < 500:
                    return r.status_code, (r.content if raw and r.status_code == 200 else r.json())
                err = f"HTTP {r.status_code}"
            except (requests.RequestException, ValueError) as e:  # dropped connection, restart, bad JSON
                err = e.__class__.__name__
            if time.monotonic() + delay > self.deadline:
                raise TimeoutError(f"{method} {path}: gave up at the time limit ({err})")
            self.retries += 1
            time.sleep(delay)
            delay = min(delay * 2, 1.0)


def run_simulation(
    url: str,
    n_raters: int,
    seed: int = 0,
    careless: float = 0.1,
    manifest=None,
    quality: dict[str, float] | None = None,
    concurrency: int = 8,
    timeout_s: float = 600.0,
    admin_token: str | None = None,
    think_s: float = 0.0,
    prefix: str | None = None,
    progress: bool = True,
    on_ack=None,
    design: str | None = None,
) -> dict:
    """Run the crowd; return a summary of everything submitted and acknowledged (JSON-serialisable).

    `on_ack(record)` is called after each acknowledged rating (used by the crash test). `design`: the design the
    server must run (checked at /healthz before any session); None answers whichever it runs."""
    if not 1 <= n_raters <= MAX_RATERS:
        raise AppError(f"--raters must be between 1 and {MAX_RATERS}, got {n_raters}")
    if not 0.0 <= careless <= 1.0:
        raise AppError(f"--careless must be a share between 0 and 1, got {careless}")
    if not 1 <= concurrency <= 1000:
        raise AppError(f"--concurrency must be between 1 and 1000, got {concurrency}")
    if not timeout_s > 0:
        raise AppError(f"--timeout must be positive, got {timeout_s}")
    started = time.monotonic()
    deadline = started + timeout_s
    if design is not None:
        check_design(url, design)
    clips = load_clips(url, manifest, admin_token)
    q_cond = dict(DEFAULT_QUALITY)
    q_cond.update(quality_from_metrics(clips))
    if quality:
        q_cond.update(quality)
    for c in clips.values():
        if c.quality is None or (quality and c.condition in quality):
            c.quality = q_cond.get(c.condition, OTHER_QUALITY)

    rng = np.random.default_rng(seed)
    n_careless = int(round(careless * n_raters))
    careless_set = set(rng.choice(n_raters, size=n_careless, replace=False).tolist()) if n_careless else set()
    prefix = prefix or f"sim{seed}"
    specs = [
        {
            "index": i,
            "external_id": f"{prefix}-{i:05d}",
            "careless": i in careless_set,
            "session_id": f"{prefix}-{i:05d}-{int(rng.integers(2**62)):x}",
            "bias": float(rng.normal(0, BIAS_SD)),
            "noise_sd": float(rng.uniform(*NOISE_SD)),
            "seed": int(rng.integers(2**31)),
        }
        for i in range(n_raters)
    ]
    full = threading.Event()
    lock = threading.Lock()
    ratings: list[dict] = []
    results: list[dict | None] = [None] * n_raters
    errors: list[str] = []
    local = threading.local()

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_raters, desc="simulated raters", unit="rater")

    def rate(spec, r_rng, clip: ClipInfo | None) -> tuple[int, int]:
        dur = clip.duration_ms if clip else 2000
        if spec["careless"]:
            return int(r_rng.integers(1, 6)), int(dur * r_rng.uniform(0.2, 1.0))
        q = clip.quality if clip and clip.quality is not None else OTHER_QUALITY
        x = int(np.clip(round(q + spec["bias"] + r_rng.normal(0, spec["noise_sd"])), 1, 5))
        if clip is not None and clip.role == "catch":
            x = min(x, 2)  # an attentive rater recognises a bad example
        return x, int(dur + r_rng.uniform(0, 300))

    def prefer(spec, r_rng, a: ClipInfo | None, b: ClipInfo | None) -> int:
        """A pairwise answer: 2 = A clearly .. -2 = B clearly."""
        if spec["careless"]:
            return int(r_rng.integers(-2, 3))
        qa = a.quality if a and a.quality is not None else OTHER_QUALITY
        qb = b.quality if b and b.quality is not None else OTHER_QUALITY
        d = qa - qb + r_rng.normal(0, spec["noise_sd"])
        level = 0 if abs(d) < PREFERENCE_TIE else 1 if abs(d) < PREFERENCE_CLEAR else 2
        pref = level if d > 0 else -level
        if a is not None and b is not None and "BAD" in (a.condition, b.condition):
            strength = abs(pref) or 1  # never the bad example, never a tie with it
            pref = strength if b.condition == "BAD" else -strength
        return pref

    def page(spec, r_rng, shown: list[ClipInfo | None]) -> list[int]:
        """Parallel ratings 0..100 of the clips of one page, in order."""
        if spec["careless"]:
            return [int(r_rng.integers(0, 101)) for _ in shown]
        out = []
        for c in shown:
            q = c.quality if c and c.quality is not None else OTHER_QUALITY
            x = 25.0 * (q + spec["bias"] + r_rng.normal(0, spec["noise_sd"]) - 1.0)
            out.append(int(np.clip(round(x), 0, 100)))
        conds = [c.condition if c else None for c in shown]
        if "BAD" in conds and "NAT" in conds:  # an attentive rater puts the bad example below natural
            nat = out[conds.index("NAT")]
            for i, cond in enumerate(conds):
                if cond == "BAD" and out[i] >= nat:
                    out[i] = max(0, nat - 10) if nat > 0 else 0
                    if nat == 0:
                        out[conds.index("NAT")] = 10
        return out

    def one_rater(spec):
        res = {
            "external_id": spec["external_id"],
            "careless": spec["careless"],
            "rater_id": None,
            "started": False,
            "completed": False,
            "completion_code": None,
            "n_ratings": 0,
            "n_catch": 0,
            "n_training": 0,
            "failed_catch": False,
            "bias": round(spec["bias"], 3),
            "noise_sd": round(spec["noise_sd"], 3),
        }
        results[spec["index"]] = res
        if full.is_set() or time.monotonic() > deadline:
            res["skipped"] = "study full" if full.is_set() else "time limit"
            return
        if not hasattr(local, "client"):
            local.client = _Client(url, deadline)
        cl = local.client
        r_rng = np.random.default_rng(spec["seed"])
        status, body = cl.call(
            "POST", "/api/sessions", {"external_id": spec["external_id"], "session_id": spec["session_id"]}
        )
        if status == 409 and body.get("full"):
            full.set()
            res["skipped"] = "study full"
            return
        if status not in (200, 201):
            raise AppError(f"POST /api/sessions: HTTP {status}: {body.get('error')}")
        token, res["rater_id"], res["started"] = body["session"], body["rater_id"], True
        min_view = float(body.get("min_view", 1.0))
        design = body.get("design", "acr")
        field_name = {"acr": "rating", "pairwise": "preference", "parallel": "ratings"}[design]

        def answer(t, trial_clips, value, watched):
            """Fetch every video of the trial, wait as the server requires, post; wait again if the server says
            too early."""
            shown = time.monotonic()
            parts = [t] if design == "acr" else [t["a"], t["b"]] if "a" in t else t["clips"]
            urls = [x["video_url"] for x in parts]
            for u in urls:
                status, data = cl.call("GET", u, raw=True)
                if status != 200:
                    raise AppError(f"video of trial {t['trial_id']}: HTTP {status}")
            durations = [c.duration_ms if c else 2000 for c in trial_clips]
            need = sum(durations) if design == "parallel" else max(durations)
            wait = min_view * need / 1000.0
            if think_s:
                wait += float(r_rng.exponential(think_s))
            time.sleep(max(0.0, shown + wait - time.monotonic()))
            for _ in range(5):
                status, ans = cl.call(
                    "POST",
                    f"/api/sessions/{token}/ratings",
                    {"trial_id": t["trial_id"], field_name: value, "watched_ms": watched},
                )
                if status != 425:
                    return status, ans
                time.sleep(ans.get("retry_after_ms", 100) / 1000.0)
            return status, ans

        for _ in range(int(body["n_trials"]) + 3):
            status, body = cl.call("GET", f"/api/sessions/{token}/next")
            if status == 409 and body.get("full"):
                res["skipped"] = "study full"
                return
            if status != 200:
                raise AppError(f"GET next: HTTP {status}: {body.get('error')}")
            if body.get("done"):
                res["completed"], res["completion_code"] = True, body["completion_code"]
                return
            t = body["trial"]
            if design != "acr":
                ids = [t["a"]["clip_id"], t["b"]["clip_id"]] if "a" in t else [x["clip_id"] for x in t["clips"]]
                shown = [clips.get(i) for i in ids]
                if t["phase"] == "training":
                    status, ans = answer(t, shown, None, sum(c.duration_ms if c else 2000 for c in shown))
                    if status not in (200, 201):
                        raise AppError(f"training ack: HTTP {status}: {ans.get('error')}")
                    res["n_training"] += 1
                    continue
                recs = multi_answer(spec, r_rng, res, t, ids, shown, answer)
                with lock:
                    ratings.extend(recs)
                if on_ack:
                    for rec in recs:
                        on_ack(rec)
                continue
            clip = clips.get(t["clip_id"])
            if t["phase"] == "training":
                status, ans = answer(t, [clip], None, clip.duration_ms if clip else 2000)
                if status not in (200, 201):
                    raise AppError(f"training ack: HTTP {status}: {ans.get('error')}")
                res["n_training"] += 1
                continue
            value, watched = rate(spec, r_rng, clip)
            status, ans = answer(t, [clip], value, watched)
            if status not in (200, 201):
                raise AppError(f"rating: HTTP {status}: {ans.get('error')}")
            if status == 200 and ans.get("rating") is not None:
                value = ans["rating"]  # a retry of a rating the server had already stored
            rec = {
                "rater_id": res["rater_id"],
                "external_id": spec["external_id"],
                "trial_id": t["trial_id"],
                "clip_id": t["clip_id"],
                "condition": clip.condition if clip else None,
                "role": clip.role if clip else None,
                "rating": value,
                "careless": spec["careless"],
            }
            res["n_ratings"] += 1
            if clip is not None and clip.role == "catch":
                res["n_catch"] += 1
                res["failed_catch"] = res["failed_catch"] or value >= 3
            with lock:
                ratings.append(rec)
            if on_ack:
                on_ack(rec)
        raise AppError(f"rater {spec['external_id']}: the server kept serving trials beyond n_trials")

    def multi_answer(spec, r_rng, res, t, ids, shown, answer):
        """Answer a pairwise or parallel trial; the acknowledged records (one per pair, one per clip of a page)."""
        watched = int(sum(c.duration_ms if c else 2000 for c in shown) + r_rng.uniform(0, 300))
        catch = any(c is not None and c.role == "catch" for c in shown)
        base = {
            "rater_id": res["rater_id"],
            "external_id": spec["external_id"],
            "trial_id": t["trial_id"],
            "role": "catch" if catch else "test",
            "careless": spec["careless"],
        }
        cond = [c.condition if c else None for c in shown]
        if "a" in t:
            value = prefer(spec, r_rng, shown[0], shown[1])
        else:
            value = dict(zip(ids, page(spec, r_rng, shown)))
        status, ans = answer(t, shown, value, watched)
        if status not in (200, 201):
            raise AppError(f"answer: HTTP {status}: {ans.get('error')}")
        stored = ans.get("preference" if "a" in t else "ratings") if status == 200 else None
        if stored is not None:
            value = stored  # a retry of an answer the server had already stored
        res["n_ratings"] += 1
        res["n_catch"] += catch
        if "a" in t:
            failed = catch and ((cond[0] == "BAD" and value > 0) or (cond[1] == "BAD" and value < 0))
            recs = [
                {
                    **base,
                    "clip_a": ids[0],
                    "clip_b": ids[1],
                    "condition_a": cond[0],
                    "condition_b": cond[1],
                    "condition": " vs ".join(sorted(map(str, cond))),
                    "preference": value,
                }
            ]
        else:
            by = {c: value[i] for i, c in zip(ids, cond)}
            failed = catch and "BAD" in by and "NAT" in by and by["BAD"] >= by["NAT"]
            recs = [
                {**base, "page_id": f"p{t['trial_id']}", "clip_id": i, "condition": c, "rating": value[i]}
                for i, c in zip(ids, cond)
            ]
        res["failed_catch"] = res["failed_catch"] or bool(failed)
        return recs

    def job(spec):
        try:
            one_rater(spec)
        except Exception as e:  # any failure of one rater is reported, never fatal to the crowd
            with lock:
                errors.append(f"{spec['external_id']}: {e}")
            if results[spec["index"]] is not None:
                results[spec["index"]]["error"] = str(e)
        finally:
            if bar is not None:
                bar.update(1)

    with ThreadPoolExecutor(max_workers=min(concurrency, n_raters)) as pool:
        list(pool.map(job, specs))
    if bar is not None:
        bar.close()

    raters = [r for r in results if r is not None]
    by_cond: dict[str, int] = {}
    for r in ratings:
        by_cond[str(r["condition"])] = by_cond.get(str(r["condition"]), 0) + 1
    started_raters = [r for r in raters if r["started"]]
    return {
        "url": url,
        "seed": seed,
        "careless_share": careless,
        "quality": {k: round(v, 3) for k, v in q_cond.items()},
        "n_raters_requested": n_raters,
        "n_raters_started": len(started_raters),
        "n_raters_completed": sum(r["completed"] for r in raters),
        "study_full": full.is_set(),
        "n_ratings": len(ratings),
        "n_ratings_by_condition": by_cond,
        "careless_raters": [r["rater_id"] for r in started_raters if r["careless"]],
        "failed_catch_raters": [r["rater_id"] for r in started_raters if r["failed_catch"]],
        "raters": raters,
        "ratings": ratings,
        "errors": errors,
        "elapsed_s": round(time.monotonic() - started, 2),
    }


def write_summary(summary: dict, path) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(summary, fh, indent=1)
