"""What giving a rater a slot costs in SQLAlchemy: the claim and hold statements built at every call, as the app
did before a slot's statements were built once, against the app's own `claim` and `hold` (rating_app.pairing.assign).

    python bench/bench_slot_statements.py [--rounds 30] [--calls 100]

One acr study on SQLite (30 items x NAT/MG/FL, 4 catch, 4 training clips, the fake stimuli of the app's tests), one
connection; each call claims a test clip for a rater and holds it, in a transaction rolled back after it, so every
call sees the same rows. The two ways alternate round by round in one process (the first of each pair switching), so
the host's drift falls on both alike; it prints the median CPU milliseconds a call of each over the rounds. The
database's own work is the same in both: the difference is the statements' building and their cache keys.
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
from rating_app.store.db import Cover, Trial, app_engine  # noqa: E402

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


def main():
    p = cli.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=30)
    p.add_argument("--calls", type=int, default=100, help="calls of each way a round")
    a = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="slot_statements_"))
    manifest = write_fake_stimuli(tmp / "stimuli", n_items=30, n_catch=4, n_training=4, n_frames=20, catch_nat=True)
    app = create_app(manifest=manifest, db_url=f"sqlite:///{tmp}/r.sqlite", design="acr", admin_token="bench")
    ways = {"built per call": built_per_call, "built once": built_once}
    ms = {name: [] for name in ways}
    with app_engine(app).connect() as conn:

        def calls(fn, n):
            for _ in range(n):
                with conn.begin() as tr:
                    if fn(conn) is None:
                        raise SystemExit("bench_slot_statements: no clip was claimed")
                    tr.rollback()

        for fn in ways.values():  # warm: SQLAlchemy's compiled cache, SQLite's pages
            calls(fn, 5)
        for r in range(a.rounds):
            for name in ways if r % 2 else reversed(ways):
                t0 = time.process_time()
                calls(ways[name], a.calls)
                ms[name].append((time.process_time() - t0) / a.calls * 1000)
    before, after = (statistics.median(ms[n]) for n in ways)
    print(f"claim and hold of one slot, CPU ms (median of {a.rounds} rounds of {a.calls}):")
    print(f"  built per call {before:.3f}, built once {after:.3f}: {after / before:.2f}x, {before - after:.3f} ms less")


if __name__ == "__main__":
    main()
