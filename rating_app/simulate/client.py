"""The simulated crowd's side of the HTTP API (CONTRACTS §5, §8): it answers exactly as the rater's page does.

A rater creates a session (with a platform session id, as Prolific's link gives one, which is also its proof for
resuming after a lost reply), and for every trial fetches every video and waits until the server would accept
an answer: the clips' duration (the longest of a pair, the sum of a page) times the server's `min_view` (from the
session reply; 1 = the whole clip). Familiarisation trials are acknowledged with a null answer.
"""

from __future__ import annotations

import time

import requests

from moglow_eval.core import study

from ..designs import get
from ..store.manifest import AppError
from .raters import ClipInfo, Rater, duration_ms

REACH_S = 5.0  # how long a server that is still starting may take to answer before the crowd gives up


def probe(url: str, wait_s: float = REACH_S) -> dict:
    """The app's /healthz reply; AppError within about `wait_s` seconds when nothing answers at `url` (connection
    refused is retried meanwhile: the app may have been started a moment ago) or what answers is not the app."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            r = requests.get(url.rstrip("/") + "/healthz", timeout=max(1.0, wait_s))
            break
        except requests.RequestException as e:
            if time.monotonic() + 0.25 > deadline:
                raise AppError(
                    f"{url}: no rating app answers ({e.__class__.__name__} for {wait_s:g} s); start it first "
                    "(python -m rating_app serve) or correct --url"
                ) from None
            time.sleep(0.25)
    try:
        body = r.json()
    except ValueError:
        body = None
    if r.status_code != 200 or not isinstance(body, dict) or "ok" not in body:
        raise AppError(f"{url}: HTTP {r.status_code} at /healthz: not the rating app; correct --url")
    return body


def check_design(url: str, design: str) -> dict:
    """The app's /healthz reply; AppError unless the server at `url` runs `design` (the reply names it)."""
    body = probe(url)
    running = body.get("design", study.DEFAULT_DESIGN)
    if running != design:
        raise AppError(f"--design {design}: the server at {url} runs a {running} study")
    return body


class Refused(AppError):
    """The app turned a new session away (429): too many sessions from this address."""


class Client:
    """HTTP with retries: a server restart or a dropped connection is waited out until the deadline.
    Every call the crowd makes is idempotent (session by external id, GET next, rating per trial), so a retry
    of a call whose reply was lost stores nothing twice."""

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


def trial_parts(trial: dict) -> list[dict]:
    """The clips a trial shows, each with its clip_id and video_url: one (acr), A and B (pairwise) or a page."""
    if "a" in trial:
        return [trial["a"], trial["b"]]
    return trial.get("clips") or [trial]


class Visit:
    """One rater's session on the server, driven as the page drives it."""

    def __init__(self, client: Client, rater: Rater, clips: dict[str, ClipInfo], think_s: float = 0.0, heard=None):
        self.client, self.rater, self.clips, self.think_s = client, rater, clips, think_s
        self.heard = heard or {}  # a study with sound: {sha256 of a sound-check sample: its digits}
        self.token = self.rater_id = None
        self.design, self.min_view, self.n_trials = get(None), 1.0, 0

    def start(self) -> bool:
        """Open (or resume) the session; False when the study is full."""
        status, body = self.client.call(
            "POST", "/api/sessions", {"external_id": self.rater.external_id, "session_id": self.rater.session_id}
        )
        if status == 409 and body.get("full"):
            return False
        if status == 429:
            raise Refused(f"POST /api/sessions: HTTP 429: {body.get('error')}")
        if status not in (200, 201):
            raise AppError(f"POST /api/sessions: HTTP {status}: {body.get('error')}")
        self.token, self.rater_id = body["session"], body["rater_id"]
        self.min_view = float(body.get("min_view", 1.0))
        self.design = get(body.get("design"))  # the design the server runs (designs/)
        self.n_trials = int(body["n_trials"])
        return True

    def next(self) -> tuple[str, object]:
        """("trial", the trial), ("done", the completion code) or ("full", None): every slot was dropped."""
        status, body = self.client.call("GET", f"/api/sessions/{self.token}/next")
        if status == 403 and body.get("audio_check"):
            self.sound_check()
            status, body = self.client.call("GET", f"/api/sessions/{self.token}/next")
        if status == 409 and body.get("full"):
            return "full", None
        if status != 200:
            raise AppError(f"GET next: HTTP {status}: {body.get('error')}")
        if body.get("done"):
            return "done", body["completion_code"]
        return "trial", body["trial"]

    def sound_check(self) -> None:
        """Pass the sound check as a rater who hears does: fetch the sample, type its digits."""
        import hashlib

        status, wav = self.client.call("GET", f"/api/sessions/{self.token}/audio-check.wav", raw=True)
        if status != 200:
            raise AppError(f"sound check sample: HTTP {status}")
        digits = self.heard.get(hashlib.sha256(wav).hexdigest(), "")
        status, body = self.client.call("POST", f"/api/sessions/{self.token}/audio-check", {"answer": digits})
        if status != 200 or not body.get("passed"):
            raise AppError(f"sound check: HTTP {status}: not passed")

    def shown(self, trial: dict) -> tuple[list[str], list[ClipInfo | None]]:
        """The clip ids of a trial and what the crowd knows of them (None: a clip not in its manifest)."""
        ids = [part["clip_id"] for part in trial_parts(trial)]
        return ids, [self.clips.get(i) for i in ids]

    def submit(self, trial: dict, shown: list[ClipInfo | None], value, watched: int, what: str):
        """Watch the trial and post `value`; the answer the server holds (a retry's is the first one's)."""
        status, ans = self._post_when_watched(trial, shown, value, watched)
        if status not in (200, 201):
            raise AppError(f"{what}: HTTP {status}: {ans.get('error')}")
        stored = ans.get(self.design.answer_field) if status == 200 else None
        return value if stored is None else stored

    def _post_when_watched(self, trial, shown, value, watched):
        """Fetch every video of the trial, wait as the server requires, post; wait again if the server says
        too early."""
        started = time.monotonic()
        for part in trial_parts(trial):
            status, _ = self.client.call("GET", part["video_url"], raw=True)
            if status != 200:
                raise AppError(f"video of trial {trial['trial_id']}: HTTP {status}")
        need = self.design.required_ms([duration_ms(c) for c in shown])
        wait = self.min_view * need / 1000.0 + self.rater.think(self.think_s)
        if started + wait > self.client.deadline:  # stop at the time limit, not a whole viewing later
            time.sleep(max(0.0, self.client.deadline - time.monotonic()))
            raise TimeoutError(f"trial {trial['trial_id']}: the time limit passed while watching")
        time.sleep(max(0.0, started + wait - time.monotonic()))
        body = {"trial_id": trial["trial_id"], self.design.answer_field: value, "watched_ms": watched}
        for _ in range(5):
            status, ans = self.client.call("POST", f"/api/sessions/{self.token}/ratings", body)
            if status != 425:
                break
            time.sleep(ans.get("retry_after_ms", 100) / 1000.0)
        return status, ans
