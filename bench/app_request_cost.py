"""What one rater's request costs the app: SQL statements and CPU milliseconds per call, by design.

    python bench/app_request_cost.py [--design acr|pairwise|parallel] [--db postgres|sqlite] [--answers 600]
        [--pairing balanced|active] [--stop-when never|settled] [--refresh S]

Raters go through a paper-sized study (30 items x NAT/MG/FL, 4 catch, 4 training clips) in one process, one
call at a time, through Flask's test client: create a session, then GET next, GET every video of the trial and
POST the answer, as the page does, until --answers answers are in. For each kind of call it prints the median
and mean CPU time of this process (time.process_time: the app's Python, the driver and SQLAlchemy; the
database server's own work is not in it) and the median number of SQL statements sent. Under 200 concurrent
raters (bench_app.py) the two cores run out of CPU, so this is the cost that sets the tail latency there.
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))  # bench_app: the page's answers, as the load benchmark sends them
sys.path.insert(0, str(ROOT / "tests"))  # the fake stimulus folder the app's tests use (tests/fake_stimuli.py)

from bench_app import answer, trial_clips  # noqa: E402
from helpers.fake_stimuli import pg_schema, write_fake_stimuli  # noqa: E402
from sqlalchemy import event  # noqa: E402

from moglow_eval.core import cli  # noqa: E402
from moglow_eval.core.study import DESIGNS  # noqa: E402
from rating_app import create_app  # noqa: E402
from rating_app.store.db import app_engine  # noqa: E402

SAME_SITE = {"Sec-Fetch-Site": "same-origin"}


def run(app, design, n_answers):
    """{call kind: ([cpu seconds], [statements])} over raters until `n_answers` answers."""
    sent = []
    event.listen(app_engine(app), "before_cursor_execute", lambda *a: sent.append(1))
    client = app.test_client()
    rng = random.Random(0)
    cost = defaultdict(lambda: ([], []))

    def call(kind, fn):
        sent.clear()
        t0 = time.process_time()
        resp = fn()
        cost[kind][0].append(time.process_time() - t0)
        cost[kind][1].append(len(sent))
        return resp

    while len(cost["answer POST"][0]) < n_answers:
        token = call("session POST", lambda: client.post("/api/sessions", json={}, headers=SAME_SITE)).get_json()
        token = token["session"]
        while len(cost["answer POST"][0]) < n_answers:
            body = call("next GET", lambda: client.get(f"/api/sessions/{token}/next")).get_json()
            if "trial" not in body:
                break
            trial = body["trial"]
            for clip in trial_clips(trial):
                call("video GET", lambda: client.get(clip["video_url"]))
            payload = {"trial_id": trial["trial_id"], "watched_ms": 4000, **answer(design, trial, rng)}
            resp = call("answer POST", lambda: client.post(f"/api/sessions/{token}/ratings", json=payload))
            if resp.status_code != 201:
                raise SystemExit(f"app_request_cost: answer refused: {resp.status_code} {resp.get_data(as_text=True)}")
    return cost


def main():
    p = cli.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--design", choices=DESIGNS, default="pairwise")
    p.add_argument("--db", choices=("postgres", "sqlite"), default="postgres")
    p.add_argument("--answers", type=int, default=600)
    p.add_argument("--stimuli", default=None, help="reuse (or create) the stimulus folder here")
    p.add_argument("--pairing", choices=("balanced", "active"), default="balanced", help="pairwise: PAIRING")
    p.add_argument("--stop-when", choices=("never", "settled"), default="never", help="pairwise: STOP_WHEN")
    p.add_argument(
        "--refresh",
        type=float,
        default=None,
        help="active: seconds between refits (rating_app.pairing.active.REFRESH_S)",
    )
    a = p.parse_args()
    if a.refresh is not None:
        from rating_app.pairing import active

        active.REFRESH_S = a.refresh
    tmp = Path(tempfile.mkdtemp(prefix="app_cost_"))
    stim = Path(a.stimuli) if a.stimuli else tmp / "stimuli"
    manifest = stim / "manifest.csv"
    if not manifest.is_file():
        manifest = write_fake_stimuli(stim, n_items=30, n_catch=4, n_training=4, n_frames=80, catch_nat=True)
    ctx = pg_schema() if a.db == "postgres" else None
    url = ctx.__enter__() if ctx else f"sqlite:///{tmp}/ratings.sqlite"
    try:
        app = create_app(
            manifest=manifest,
            db_url=url,
            ratings_per_clip=100000,
            min_view=0,
            design=a.design,
            admin_token="bench",
            sessions_per_client=0,
            **({"pairing": a.pairing, "stop_when": a.stop_when} if a.design == "pairwise" else {}),
        )
        cost = run(app, a.design, a.answers)
    finally:
        if ctx:
            ctx.__exit__(None, None, None)
    setting = f", {a.pairing}, stop {a.stop_when}" if a.design == "pairwise" else ""
    print(f"| call | n | CPU ms, median / mean / p99 | statements (median / max) |  ({a.design}, {a.db}{setting})")
    for kind, (cpu, stmts) in cost.items():
        ms = [1000 * x for x in cpu]
        print(
            f"| {kind} | {len(ms)} | {statistics.median(ms):.2f} / {statistics.mean(ms):.2f} / "
            f"{np.percentile(ms, 99):.2f} | {statistics.median(stmts):g} / {max(stmts)} |"
        )


if __name__ == "__main__":
    main()
