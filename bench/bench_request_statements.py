"""What a rater's requests cost in SQLAlchemy: giving a slot, storing an answer and recording a video's bytes, their
statements built at every call, as the app did before they were built once, against the app's own
(rating_app.pairing.assign's `claim`, `hold` and `answer`, rating_app.trials.answers' and trial_videos' writes).

    python bench/bench_request_statements.py [--rounds 30] [--calls 100]

One acr study on SQLite (30 items x NAT/MG/FL, 4 catch, 4 training clips, the fake stimuli of the app's tests), one
connection; a slot claims a test clip for a rater and holds it, an answer runs the three writes of an answer (the
rater's progress, the trial, the clip's cover) and a video's the write of its byte ranges, on rows that are not
there, each in a transaction rolled back after it, so every call sees the same rows. The two ways alternate round by
round in one process (the first of each pair switching), so the host's drift falls on both alike; it prints the
median CPU milliseconds a call of each over the rounds. The database's own work is the same in both: the difference
is the statements' building and their cache keys.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # the fake stimulus folder the app's tests use

from helpers.fake_stimuli import write_fake_stimuli  # noqa: E402
from sqlalchemy import func, select, update  # noqa: E402

from moglow_eval.core import cli  # noqa: E402
from rating_app import create_app  # noqa: E402
from rating_app.designs.acr import _ROLE_CLIPS  # noqa: E402
from rating_app.pairing import assign  # noqa: E402
from rating_app.store.db import Cover, Rater, Trial, app_engine, utcnow  # noqa: E402
from rating_app.trials import answers, trial_videos  # noqa: E402
from rating_app.trials.sessions import is_open  # noqa: E402

RATER, TARGET = 1, 20


def built_per_call(conn):
    """The claim and the hold as the app built them before: every statement made anew."""
    had = select(Trial.clip_id).where(Trial.rater_pk == RATER, Trial.clip_id.is_not(None))
    covered = Cover.answered + Cover.held
    q = (
        select(Cover.key)
        .where(Cover.key.in_(_ROLE_CLIPS.params(role="test")), covered < TARGET, Cover.key.not_in(had))
        .order_by(covered, func.random())
        .limit(1)
    )
    key = conn.execute(q.with_for_update(skip_locked=True)).scalar()
    conn.execute(update(Cover).where(Cover.key == key).values(held=Cover.held + 1))
    return key


def built_once(conn):
    """The app's claim and hold."""
    key = assign.claim(conn, _ROLE_CLIPS, "clip_id", RATER, TARGET, False, params={"role": "test"})
    assign.hold(conn, key)
    return key


def answer_built_per_call(conn):
    """An answer's writes as the app built them before."""
    now = utcnow()
    rows = conn.execute(
        update(Rater)
        .where(Rater.id == 0, Rater.expired_at.is_(None), Rater.last_progress >= now)
        .values(last_progress=now, last_seen=now)
    ).rowcount
    rows += conn.execute(update(Trial).where(Trial.id == 0, is_open()).values(answered_at=now)).rowcount
    conn.execute(update(Cover).where(Cover.key == "none").values(held=Cover.held - 1, answered=Cover.answered + 1))
    return rows == 0


def answer_built_once(conn):
    """The app's."""
    now = utcnow()
    rows = conn.execute(answers._PROGRESS, {"rater_pk": 0, "cutoff": now, "now": now}).rowcount
    rows += conn.execute(answers._ANSWERED, {"trial_pk": 0, "now": now}).rowcount
    assign.answer(conn, "none")
    return rows == 0


def video_built_per_call(conn):
    """A video's ranges write as the app built it before."""
    write = (
        update(Trial)
        .where(Trial.id == 0, Trial.video_ranges.is_not_distinct_from("0-99"))
        .values(video_ranges="0-199", video_at=func.coalesce(Trial.video_at, utcnow()))
    )
    return conn.execute(write).rowcount == 0


def video_built_once(conn):
    """The app's."""
    values = {"row_pk": 0, "have": "0-99", "merged": "0-199", "now": utcnow()}
    return conn.execute(trial_videos._ranges_write(Trial), values).rowcount == 0


def main():
    p = cli.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=30)
    p.add_argument("--calls", type=int, default=100, help="calls of each way a round")
    a = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="slot_statements_"))
    manifest = write_fake_stimuli(tmp / "stimuli", n_items=30, n_catch=4, n_training=4, n_frames=20, catch_nat=True)
    app = create_app(manifest=manifest, db_url=f"sqlite:///{tmp}/r.sqlite", design="acr", admin_token="bench")
    ops = {
        "claim and hold of one slot": {"built per call": built_per_call, "built once": built_once},
        "an answer's writes": {"built per call": answer_built_per_call, "built once": answer_built_once},
        "a video's ranges write": {"built per call": video_built_per_call, "built once": video_built_once},
    }
    with app_engine(app).connect() as conn:

        def calls(fn, n):
            for _ in range(n):
                with conn.begin() as tr:
                    if not fn(conn):
                        raise SystemExit(f"bench_request_statements: {fn.__name__} did not do its work")
                    tr.rollback()

        for op, ways in ops.items():
            ms = {name: [] for name in ways}
            for fn in ways.values():  # warm: SQLAlchemy's compiled cache, SQLite's pages
                calls(fn, 5)
            for r in range(a.rounds):
                for name in ways if r % 2 else reversed(ways):
                    t0 = time.process_time()
                    calls(ways[name], a.calls)
                    ms[name].append((time.process_time() - t0) / a.calls * 1000)
            before, after = (statistics.median(ms[n]) for n in ways)
            print(f"{op}, CPU ms (median of {a.rounds} rounds of {a.calls}): built per call {before:.3f}, built once")
            print(f"  {after:.3f}: {after / before:.2f}x, {before - after:.3f} ms less")


if __name__ == "__main__":
    main()
