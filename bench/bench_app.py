"""Latency of the rating POST and the next-trial GET with 200 concurrent raters, gunicorn on this machine.

    python bench/bench_app.py [--behind caddy --hosts 2] [--design acr|pairwise|parallel|appropriateness]
        [--pace app|stress] [--raters 200]
        [--duration 30] [--think S] [--db sqlite|postgres|URL] [--workers 4] [--threads 16] [--no-preload]
        [--json out.json]
        [--pairing balanced|active] [--stop-when never|settled]

A real gunicorn process (gthread workers) serves a paper-sized study (30 items x NAT/MG/FL + 4 catch + 4
training clips, real MP4s of --clip-frames frames at 20 fps, 4 s like the paper's) from a fresh PostgreSQL schema
(or SQLite file). Each simulated rater keeps one keep-alive connection and loops, as the page does:

- `--pace app` (default): GET next -> GET every video of the trial -> wait until the clips can have played to the
  end (the app's own rule, RATING_MIN_VIEW=1, its default: the clip in acr, the longer clip in pairwise, the sum of a
  parallel page's clips) -> a decision pause (exponential, mean --think, default 1 s) -> POST the answer. This is
  the fastest a rater can go: the app refuses an earlier answer.
- `--pace stress`: the app's viewing rule off (RATING_MIN_VIEW=0), no video fetches, and a pause of mean --think
  (default 2 s) between GET and POST: more answers per second than raters could give (the earlier benchmark).

--behind caddy (issue 33): the raters reach --hosts gunicorn hosts (each --workers x --threads) sharing the database
through Caddy over HTTPS with its own CA, and Caddy sends the videos (RATING_VIDEO_ACCEL=caddy); the target is then
p99 <= 150 ms, and the largest worker's resident memory is reported (it holds no video).

Latencies are client-side wall times (http.client, no retries); the first --warmup seconds are discarded.
Target: p99 <= 100 ms for the answer POST and the next-trial GET, 0 errors.

--design pairwise / parallel / appropriateness runs that test design (CONTRACTS §8): each answer is a preference for
the trial's two clips, or a 0-100 rating of every clip of its page (one POST per page); the stimuli then include the
NAT clip of each catch item (and, for appropriateness, each condition's mismatched clip of every item, whose two
clips play one after the other). The answer POST is reported as "rating" in every design. --pairing active and
--stop-when settled (pairwise) turn on the app's active pairing and its stopping rule (the answers are random, so
the ranking never settles: every new session checks it).
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # the fake stimulus folder the app's tests use (tests/fake_stimuli.py)

from helpers.fake_stimuli import pg_schema, write_fake_stimuli  # noqa: E402
from helpers.proxies import caddy_accel  # noqa: E402

from moglow_eval.core import cli  # noqa: E402
from moglow_eval.core.ports import free_port  # noqa: E402
from moglow_eval.core.study import DESIGNS  # noqa: E402


def start_server(port, env, workers, threads, log, preload=True):
    cmd = [
        sys.executable,
        "-m",
        "gunicorn",
        "-w",
        str(workers),
        "-k",
        "gthread",
        "--threads",
        str(threads),
        "--backlog",
        "2048",
        "--keep-alive",
        "75",
        *(["--preload"] if preload else []),  # as docs/hosting.md starts it
        "-b",
        f"127.0.0.1:{port}",
        "rating_app.wsgi:app",
    ]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    for _ in range(300):
        try:
            c = http.client.HTTPConnection("127.0.0.1", port, timeout=1)
            c.request("GET", "/healthz")
            if c.getresponse().status == 200:
                return proc
        except OSError:
            time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGKILL)
    raise SystemExit("gunicorn did not start")


def trial_clips(t):
    """The clips of a trial as the API sends it: its one clip (acr), A and B (pairwise) or its page (parallel)."""
    return t.get("clips") or [t[k] for k in ("a", "b") if k in t] or [t]


def answer(design, t, rng):
    """The answer field of `design` for trial `t`, null for a familiarisation trial; values drawn from `rng`."""
    training = t["phase"] == "training"
    if design in ("pairwise", "appropriateness"):
        return {"preference": None if training else rng.randint(-2, 2)}
    if design == "parallel":
        return {"ratings": None if training else {c["clip_id"]: rng.randint(0, 100) for c in t["clips"]}}
    return {"rating": None if training else rng.randint(1, 5)}


class Rater(threading.Thread):
    def __init__(self, port, i, stop_at, warm_at, think, rec, lock, errors, design="acr", clip_s=None, tls=None):
        super().__init__(daemon=True)
        self.tls = tls  # an ssl context: HTTPS to a proxy (--behind caddy); None: HTTP to gunicorn
        self.design, self.clip_s = design, clip_s  # clip_s: None = stress pace (no videos, no viewing time)
        self.port, self.i, self.stop_at, self.warm_at, self.think = port, i, stop_at, warm_at, think
        self.rec, self.lock, self.errors = rec, lock, errors
        self.rng = random.Random(i)
        self.conn = None

    def call(self, method, path, body=None):
        data = None if body is None else json.dumps(body).encode()
        headers = {"Content-Type": "application/json"} if body is not None else {}
        t0 = time.perf_counter()
        try:
            for attempt in (0, 1):
                fresh = self.conn is None
                if fresh:
                    self.conn = (
                        http.client.HTTPSConnection("127.0.0.1", self.port, timeout=30, context=self.tls)
                        if self.tls
                        else http.client.HTTPConnection("127.0.0.1", self.port, timeout=30)
                    )
                try:
                    self.conn.request(method, path, body=data, headers=headers)
                    resp = self.conn.getresponse()
                    payload = resp.read()
                    break
                except (BrokenPipeError, ConnectionResetError, http.client.RemoteDisconnected):
                    # A kept-alive connection the server had closed: reconnect once, as browsers do.
                    self.conn.close()
                    self.conn = None
                    if fresh or attempt:
                        raise
        except OSError as e:
            self.conn.close()
            self.conn = None
            with self.lock:
                self.errors.append(f"{method} {path}: {e.__class__.__name__}")
            return None, None, time.perf_counter() - t0
        if resp.getheader("Content-Type", "").startswith("video/"):
            return resp.status, len(payload), time.perf_counter() - t0
        return resp.status, json.loads(payload), time.perf_counter() - t0

    def record(self, kind, status, ok, dt):
        if time.monotonic() < self.warm_at:
            return
        with self.lock:
            self.rec[kind].append(dt)
            if status not in ok:
                self.errors.append(f"{kind}: HTTP {status}")

    def run(self):
        try:
            self.loop()
        except Exception as e:  # a rater that dies must count, not vanish from the figures
            with self.lock:
                self.errors.append(f"rater {self.i}: {e!r}")

    def loop(self):
        status, body, dt = self.call("POST", "/api/sessions", {"external_id": f"bench-{os.getpid()}-{self.i}"})
        self.record("session", status, (201, 200), dt)
        if status not in (200, 201):
            return
        token = body["session"]
        while time.monotonic() < self.stop_at:
            status, body, dt = self.call("GET", f"/api/sessions/{token}/next")
            self.record("next", status, (200,), dt)
            if status != 200 or body.get("done"):
                return
            t = body["trial"]
            shown = time.monotonic()
            pause = min(self.rng.expovariate(1.0 / self.think), 10 * self.think) if self.think else 0
            if self.clip_s is not None:
                urls = [c["video_url"] for c in trial_clips(t)]
                for url in urls:
                    status, _, dt = self.call("GET", url)
                    self.record("video", status, (200,), dt)
                # The page enables the answer once every clip has played: at once side by side (pairwise), one
                # after the other (parallel).
                n = len(urls) if self.design in ("parallel", "appropriateness") else 1
                pause += max(0.0, shown + n * self.clip_s + 0.05 - time.monotonic())
            time.sleep(pause)
            if time.monotonic() >= self.stop_at:
                return
            status, body, dt = self.call(
                "POST",
                f"/api/sessions/{token}/ratings",
                {"trial_id": t["trial_id"], "watched_ms": 4000, **answer(self.design, t, self.rng)},
            )
            self.record("training_ack" if t["phase"] == "training" else "rating", status, (201,), dt)


def stats(xs):
    a = np.array(xs) * 1000
    if not len(a):
        return {"n": 0}
    return {
        "n": int(len(a)),
        "p50_ms": round(float(np.percentile(a, 50)), 2),
        "p90_ms": round(float(np.percentile(a, 90)), 2),
        "p99_ms": round(float(np.percentile(a, 99)), 2),
        "max_ms": round(float(a.max()), 2),
    }


CADDYFILE = """
{{
  admin off
}}
https://127.0.0.1:{port} {{
  tls internal
  reverse_proxy {upstreams} {{
    lb_policy round_robin
    {accel}
  }}
}}
"""


def start_caddy(port, upstreams, stimuli, tmp, log):
    """(Caddy over HTTPS with its own CA in front of the app hosts, an ssl context trusting that CA)."""
    import ssl

    conf = tmp / "Caddyfile"
    hosts = " ".join(f"127.0.0.1:{q}" for q in upstreams)
    conf.write_text(CADDYFILE.format(port=port, upstreams=hosts, accel=caddy_accel(stimuli)))
    env = dict(os.environ, HOME=str(tmp), XDG_DATA_HOME=str(tmp / "data"))
    cmd = ["caddy", "run", "--config", str(conf), "--adapter", "caddyfile"]
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    ca = tmp / "data" / "caddy" / "pki" / "authorities" / "local" / "root.crt"
    for _ in range(300):
        if ca.is_file():
            ctx = ssl.create_default_context(cafile=str(ca))
            try:
                c = http.client.HTTPSConnection("127.0.0.1", port, timeout=1, context=ctx)
                c.request("GET", "/healthz")
                if c.getresponse().status == 200:
                    return proc, ctx
            except OSError:
                pass
        time.sleep(0.1)
    raise SystemExit("bench_app: caddy did not come up")


def worker_rss_mb(masters):
    """The largest resident memory (MB) of any gunicorn worker (a child of the masters), from /proc."""
    best = 0.0
    for m in masters:
        try:
            children = Path(f"/proc/{m.pid}/task/{m.pid}/children").read_text().split()
        except OSError:
            continue
        for pid in children:
            try:
                status = Path(f"/proc/{pid}/status").read_text()
            except OSError:
                continue
            kb = int(next(line.split()[1] for line in status.splitlines() if line.startswith("VmRSS:")))
            best = max(best, kb / 1024)
    return round(best, 1)


def main():
    p = cli.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--design", choices=DESIGNS, default="acr", help="test design to serve and answer (acr)")
    p.add_argument("--raters", type=int, default=200)
    p.add_argument("--duration", type=float, default=30.0, help="seconds of measurement after the warm-up")
    p.add_argument("--warmup", type=float, default=10.0, help="seconds discarded (raters arrive over --ramp)")
    p.add_argument("--ramp", type=float, default=5.0, help="seconds over which the raters arrive")
    p.add_argument(
        "--pace",
        choices=("app", "stress"),
        default="app",
        help="raters as fast as the app lets them (app) or faster (stress)",
    )
    p.add_argument(
        "--think", type=float, default=None, help="mean decision pause, seconds (app: 1, after viewing; stress: 2)"
    )
    p.add_argument("--clip-frames", type=int, default=80, help="frames per clip at 20 fps (80: 4 s, the paper's)")
    p.add_argument("--db", default="postgres", help="postgres (fresh schema at 127.0.0.1), sqlite, or a URL")
    p.add_argument("--workers", type=int, default=4)
    p.add_argument("--threads", type=int, default=16)
    p.add_argument(
        "--preload", action=argparse.BooleanOptionalAction, default=True, help="gunicorn --preload (docs/hosting.md)"
    )
    p.add_argument("--json", default=None)
    p.add_argument("--stimuli", default=None, help="reuse (or create) the benchmark's stimulus folder here")
    p.add_argument(
        "--behind",
        choices=("none", "caddy"),
        default="none",
        help="caddy: the raters reach --hosts app hosts through Caddy over HTTPS (its own CA), Caddy sending the "
        "videos (RATING_VIDEO_ACCEL=caddy); target p99 <= 150 ms",
    )
    p.add_argument("--hosts", type=int, default=2, help="app hosts (gunicorn processes) behind the proxy (2)")
    p.add_argument("--pairing", choices=("balanced", "active"), default="balanced", help="pairwise: RATING_PAIRING")
    p.add_argument("--stop-when", choices=("never", "settled"), default="never", help="pairwise: RATING_STOP_WHEN")
    a = p.parse_args()
    if a.think is None:
        a.think = 1.0 if a.pace == "app" else 2.0

    tmp = Path(tempfile.mkdtemp(prefix="bench_app_"))
    stim = Path(a.stimuli) if a.stimuli else tmp / "stimuli"
    manifest = stim / "manifest.csv"
    if not manifest.is_file():
        manifest = write_fake_stimuli(
            stim,
            n_items=30,
            n_catch=4,
            n_training=4,
            n_frames=a.clip_frames,
            catch_nat=True,
            mismatched=a.design == "appropriateness",
        )
    ctx = pg_schema() if a.db == "postgres" else None
    url = ctx.__enter__() if ctx else (f"sqlite:///{tmp}/ratings.sqlite" if a.db == "sqlite" else a.db)
    port = free_port()
    env = dict(
        os.environ,
        RATING_MANIFEST=str(manifest),
        RATING_DATABASE_URL=url,
        RATING_ADMIN_TOKEN="bench",
        RATING_RATINGS_PER_CLIP="100000",
        RATING_MIN_VIEW="1" if a.pace == "app" else "0",
        RATING_SESSIONS_PER_CLIENT="0",  # every rater is on loopback
        RATING_STUDY_DESIGN=a.design,
        RATING_PAIRING=a.pairing,
        RATING_STOP_WHEN=a.stop_when,
    )
    log = open(tmp / "gunicorn.log", "w")
    tls, procs = None, []
    if a.behind == "caddy":
        env["RATING_VIDEO_ACCEL"], env["RATING_PROXY_COUNT"] = "caddy", "1"
        ports = [free_port() for _ in range(a.hosts)]
        procs = [start_server(q, env, a.workers, a.threads, log, a.preload) for q in ports]
        caddy, tls = start_caddy(port, ports, stim, tmp, log)
        procs.append(caddy)
    else:
        procs = [start_server(port, env, a.workers, a.threads, log, a.preload)]
    rec = {"session": [], "next": [], "rating": [], "training_ack": [], "video": []}
    clip_s = a.clip_frames / 20 if a.pace == "app" else None
    errors, lock = [], threading.Lock()
    try:
        t0 = time.monotonic()
        warm_at, stop_at = t0 + a.warmup, t0 + a.warmup + a.duration
        raters = [
            Rater(port, i, stop_at, warm_at, a.think, rec, lock, errors, a.design, clip_s, tls) for i in range(a.raters)
        ]
        for r in raters:  # participants arrive over --ramp seconds
            r.start()
            time.sleep(a.ramp / a.raters)
        for r in raters:
            r.join(a.warmup + a.duration + 60)
        wall = time.monotonic() - warm_at
        rss = worker_rss_mb([p for p in procs if "gunicorn" in " ".join(p.args)])
    finally:
        for proc in procs:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(20)
        log.close()
        if ctx:
            ctx.__exit__(None, None, None)
    measured = sum(len(v) for k, v in rec.items() if k != "session")
    out = {
        "design": a.design,
        "pairing": a.pairing,
        "stop_when": a.stop_when,
        "raters": a.raters,
        "pace": a.pace,
        "think_s": a.think,
        "clip_s": a.clip_frames / 20,
        "db": a.db if a.db in ("sqlite", "postgres") else "url",
        "workers": a.workers,
        "behind": a.behind,
        "hosts": a.hosts if a.behind != "none" else 1,
        "worker_rss_mb_max": rss,
        "threads": a.threads,
        "duration_s": a.duration,
        "throughput_rps": round(measured / max(wall, 1e-9), 1),
        "errors": len(errors),
        "error_examples": errors[:5],
        "load_avg_1min": round(os.getloadavg()[0], 2),
        "cpus": os.cpu_count(),
        "next": stats(rec["next"]),
        "rating": stats(rec["rating"]),
        "training_ack": stats(rec["training_ack"]),
        "video": stats(rec["video"]),
        "session": stats(rec["session"]),
    }
    print(json.dumps(out, indent=1))
    if not out["next"]["n"] or not out["rating"]["n"]:
        raise SystemExit("bench_app: no trial was answered; see the server log " + str(tmp / "gunicorn.log"))
    target = 150 if a.behind != "none" else 100
    ok = out["errors"] == 0 and out["next"].get("p99_ms", 1e9) <= target and out["rating"].get("p99_ms", 1e9) <= target
    db = (
        f"{a.db} {a.design} {a.pace}"
        + (f" {a.pairing}" if a.design == "pairwise" else "")
        + (f" via {a.behind}, {a.hosts} hosts, worker RSS {rss} MB" if a.behind != "none" else "")
    )
    print(
        f"| {db} | {a.raters} | {a.think} | {a.workers}x{a.threads} | {out['throughput_rps']} | "
        f"{out['rating']['p50_ms']} / {out['rating']['p99_ms']} | {out['next']['p50_ms']} / {out['next']['p99_ms']} | "
        f"{out['errors']} | {out['load_avg_1min']} | {'PASS' if ok else 'FAIL'} |"
    )
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
