"""Running a simulated crowd: raters in a thread pool, each through its own session, until the study is full,
every rater has been, or the time limit; then a summary of everything submitted and acknowledged.

A server that dies and comes back meanwhile (the crash test kills and restarts it) is waited out by the client's
retries; any other failure of one rater is reported in the summary, never fatal to the crowd.
"""

from __future__ import annotations

import json
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from moglow_eval.core import whole_files

from ..store.manifest import AppError
from .client import Client, Refused, Visit, check_design, probe
from .raters import ClipInfo, Rater, duration_ms, load_audio_answers, load_clips, make_raters, set_qualities

MAX_RATERS = 100_000


def run_simulation(
    url: str,
    n_raters: int,
    *,
    manifest,
    seed: int = 0,
    careless: float = 0.1,
    quality: dict[str, float] | None = None,
    concurrency: int = 8,
    timeout_s: float = 600.0,
    think_s: float = 0.0,
    prefix: str | None = None,
    progress: bool = True,
    on_ack=None,
    design: str | None = None,
) -> dict:
    """Run the crowd against the app at `url` serving `manifest` (metrics.csv beside it gives the clips'
    quality); return a summary of everything submitted and acknowledged (JSON-serialisable).

    `on_ack(record)` is called after each acknowledged rating (used by the crash test). `design`: the design the
    server must run (checked at /healthz before any session); None answers whichever it runs."""
    _check_arguments(n_raters, careless, concurrency, timeout_s)
    started = time.monotonic()
    clips = load_clips(manifest)  # the user's files first: a bad one is named even with no server up
    by_condition = set_qualities(clips, quality)
    # no server, or another design: say so now, not at the time limit
    health = check_design(url, design) if design is not None else probe(url)
    raters = make_raters(n_raters, seed, careless, prefix or f"sim{seed}")
    crowd = _Crowd(url, clips, started + timeout_s, think_s, on_ack)
    view = health.get("min_view")  # the time limit's line names it even if no session began
    crowd.min_view = float(view) if isinstance(view, (int, float)) and not isinstance(view, bool) else None
    crowd.heard = load_audio_answers(manifest)
    if progress:
        from tqdm import tqdm

        crowd.bar = tqdm(total=n_raters, desc="simulated raters", unit="rater")
    try:
        with ThreadPoolExecutor(max_workers=min(concurrency, n_raters)) as pool:
            list(pool.map(crowd.take_part, raters))
    finally:
        if crowd.bar is not None:
            crowd.bar.close()
    return {
        "url": url,
        "seed": seed,
        "careless_share": careless,
        "quality": {k: round(v, 3) for k, v in by_condition.items()},
        "n_raters_requested": n_raters,
        **crowd.summary(),
        "elapsed_s": round(time.monotonic() - started, 2),
        "timeout_s": timeout_s,
    }


def shortfall(summary: dict) -> str | None:
    """Why the crowd fell short of what was asked, in one line that says what to change; None when it did not:
    raters were refused, the time limit passed, a rater failed, or every rater took part and none found the study
    full (a crowd exactly as large as the study needs is told so too: only a rater turned away sees it full)."""
    n, started = summary["n_raters_requested"], summary["n_raters_started"]
    refused = summary["n_raters_refused"]
    if refused:
        return (
            f"{refused} of {n} raters refused with 429 after {started} started: the app allows only so many new "
            "sessions per address an hour, and the simulated crowd is one address (serve --sessions-per-client; "
            "0 lifts the limit for a local trial)"
        )
    if summary["timed_out"]:
        view = summary.get("min_view")
        waits = "" if view is None else f"; the app's is {view:g}, and the crowd waits that share of every clip"
        return (
            f"the time limit passed (--timeout {summary['timeout_s']:g} s) with {summary['n_raters_completed']} of "
            f"{n} raters done: raise --timeout, or serve a local trial with a small --min-view{waits}"
        )
    if summary["errors"]:
        return f"{len(summary['errors'])} of {n} raters failed; the first: {summary['errors'][0]}"
    if not summary["study_full"]:
        return (
            f"the study did not fill: all {n} raters took part ({summary['n_ratings']} answers) and none found it "
            "full; raise --raters"
        )
    return None


def _check_arguments(n_raters, careless, concurrency, timeout_s):
    if not 1 <= n_raters <= MAX_RATERS:
        raise AppError(f"--raters must be between 1 and {MAX_RATERS}, got {n_raters}")
    if not 0.0 <= careless <= 1.0:
        raise AppError(f"--careless must be a share between 0 and 1, got {careless}")
    if not 1 <= concurrency <= 1000:
        raise AppError(f"--concurrency must be between 1 and 1000, got {concurrency}")
    if not timeout_s > 0:
        raise AppError(f"--timeout must be positive, got {timeout_s}")


def write_summary(summary: dict, path) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    whole_files.write_whole(path, json.dumps(summary, indent=1))


class _Crowd:
    """What the raters' threads share: the clips, the time limit, whether the study is full, and what they did."""

    def __init__(self, url, clips: dict[str, ClipInfo], deadline: float, think_s: float, on_ack):
        self.url, self.clips, self.deadline, self.think_s, self.on_ack = url, clips, deadline, think_s, on_ack
        self.full = threading.Event()
        self.lock = threading.Lock()
        self.results: dict[int, dict] = {}
        self.ratings: list[dict] = []
        self.errors: list[str] = []
        self.local = threading.local()  # one HTTP client (keep-alive connection) per thread
        self.bar = None  # a progress bar, counting raters as they finish
        self.heard = {}  # a study with sound: the sound-check samples' digits by their bytes' hash
        self.timed_out = False  # a rater gave up, or never began, at the time limit
        self.min_view = None  # the app's, from /healthz, then from the session replies

    def take_part(self, rater: Rater) -> None:
        res = self.results[rater.index] = _new_result(rater)
        try:
            self._visit(rater, res)
        except Refused:  # counted apart: the summary's one line says why and what to change
            res["refused"] = True
        except TimeoutError as e:
            self.timed_out = True
            with self.lock:
                self.errors.append(f"{rater.external_id}: {e}")
            res["error"] = str(e)
        except Exception as e:  # any failure of one rater is reported, never fatal to the crowd
            with self.lock:
                self.errors.append(f"{rater.external_id}: {e}")
            res["error"] = str(e)
        finally:
            if self.bar is not None:
                self.bar.update(1)

    def _visit(self, rater: Rater, res: dict) -> None:
        if self.full.is_set() or time.monotonic() > self.deadline:
            res["skipped"] = "study full" if self.full.is_set() else "time limit"
            self.timed_out = self.timed_out or not self.full.is_set()
            return
        if not hasattr(self.local, "client"):
            self.local.client = Client(self.url, self.deadline)
        visit = Visit(self.local.client, rater, self.clips, self.think_s, self.heard)
        if not visit.start():
            self.full.set()
            res["skipped"] = "study full"
            return
        res["rater_id"], res["started"] = visit.rater_id, True
        self.min_view = visit.min_view
        for _ in range(visit.n_trials + 3):
            if time.monotonic() > self.deadline:
                raise TimeoutError(f"rater {rater.external_id}: the time limit passed mid-session")
            kind, got = visit.next()
            if kind == "full":
                res["skipped"] = "study full"
                return
            if kind == "done":
                res["completed"], res["completion_code"] = True, got
                return
            self._answer(visit, rater, res, got)
        raise AppError(f"rater {rater.external_id}: the server kept serving trials beyond n_trials")

    def _answer(self, visit: Visit, rater: Rater, res: dict, trial: dict) -> None:
        ids, shown = visit.shown(trial)
        if trial["phase"] == "training":
            visit.submit(trial, shown, None, sum(map(duration_ms, shown)), "training ack")
            res["n_training"] += 1
            return
        design = visit.design
        value, watched = design.simulated_answer(rater, ids, shown)
        value = visit.submit(trial, shown, value, watched, design.answer_noun)
        catch = any(c is not None and c.role == "catch" for c in shown)
        conditions = [c.condition if c else None for c in shown]
        res["n_ratings"] += 1
        res["n_catch"] += catch
        res["failed_catch"] = res["failed_catch"] or (catch and design.catch_failed(ids, conditions, value))
        head = {
            "rater_id": res["rater_id"],
            "external_id": rater.external_id,
            "trial_id": trial["trial_id"],
            "careless": rater.careless,
        }
        records = design.records(head, ids, shown, value, "catch" if catch else "test")
        with self.lock:
            self.ratings.extend(records)
        if self.on_ack:
            for rec in records:
                self.on_ack(rec)

    def summary(self) -> dict:
        raters = [self.results[i] for i in sorted(self.results)]
        by_condition: dict[str, int] = {}
        for r in self.ratings:
            by_condition[str(r["condition"])] = by_condition.get(str(r["condition"]), 0) + 1
        started = [r for r in raters if r["started"]]
        return {
            "n_raters_started": len(started),
            "n_raters_completed": sum(r["completed"] for r in raters),
            "n_raters_refused": sum(r["refused"] for r in raters),
            "study_full": self.full.is_set(),
            "timed_out": self.timed_out,
            "min_view": self.min_view,
            "n_ratings": len(self.ratings),
            "n_ratings_by_condition": by_condition,
            "careless_raters": [r["rater_id"] for r in started if r["careless"]],
            "failed_catch_raters": [r["rater_id"] for r in started if r["failed_catch"]],
            "raters": raters,
            "ratings": self.ratings,
            "errors": self.errors,
        }


def _new_result(rater: Rater) -> dict:
    return {
        "external_id": rater.external_id,
        "careless": rater.careless,
        "rater_id": None,
        "started": False,
        "refused": False,
        "completed": False,
        "completion_code": None,
        "n_ratings": 0,
        "n_catch": 0,
        "n_training": 0,
        "failed_catch": False,
        "bias": round(rater.bias, 3),
        "noise_sd": round(rater.noise_sd, 3),
    }
