"""A pairwise ranking study run end to end through the app: the simulated crowd against a served app on
PostgreSQL, with the 8 GENEA leaderboard systems as conditions, balanced pairing against active pairing, the
stopping rule on in both.

    nice python bench/pairwise_active_app.py [--items 20] [--level 0.95] [--width 60] [--cap 12000] [--seed 0]

The conditions' qualities (`simulate --quality`) are the Bradley-Terry strengths fitted on the released realism
votes (bench/pairwise_active.py's truth, read from ../shared, never copied) as quality = 3 + theta / BT_SCALE, so
the crowd's choices follow those strengths (rating_app/simulate/raters.py). For each pairing a fresh schema and
app (werkzeug, threaded, in this process) with `--stop-when settled`: the crowd (8 at once, no careless raters,
no viewing wait) takes part until the app closes the study to new raters; then the votes it holds, the ranking
the app's dashboard gives, and its Kendall tau against the truth's order.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np
from scipy.stats import kendalltau

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "bench"))

from helpers.fake_stimuli import pg_schema, write_fake_stimuli  # noqa: E402
from helpers.pg_server import suite_server  # noqa: E402
from pairwise_active import leaderboard_truth  # noqa: E402

from rating_app import create_app  # noqa: E402
from rating_app.simulate import run_simulation  # noqa: E402
from rating_app.simulate.raters import BT_SCALE  # noqa: E402
from rating_app.store.db import app_engine  # noqa: E402


def one_study(manifest, quality, pairing, a):
    """(votes held, the dashboard's ranking block, seconds) of one study run until the app closes it."""
    from werkzeug.serving import make_server

    logging.getLogger("werkzeug").setLevel(logging.ERROR)  # not a line per request
    with pg_schema() as url:
        app = create_app(
            manifest=manifest,
            db_url=url,
            design="pairwise",
            admin_token="bench",
            ratings_per_clip=1000,
            clips_per_rater=30,
            min_view=0,
            sessions_per_client=0,
            pairing=pairing,
            stop_when="settled",
            stop_level=a.level,
            stop_width=a.width,
            stop_max_votes=a.cap,
        )
        server = make_server("127.0.0.1", 0, app, threaded=True)
        th = threading.Thread(target=server.serve_forever, daemon=True)
        th.start()
        t0 = time.monotonic()
        try:
            summary = run_simulation(
                f"http://127.0.0.1:{server.server_port}",
                a.raters,
                manifest=manifest,
                seed=a.seed,
                careless=0.0,
                quality=quality,
                concurrency=8,
                timeout_s=3000,
                progress=False,
                design="pairwise",
            )
            ranking = app.test_client().get("/admin/progress.json", headers={"Authorization": "Bearer bench"})
            ranking = ranking.get_json()["ranking"]
        finally:
            server.shutdown()
            th.join(5)
            app_engine(app).dispose()
        return summary, ranking, time.monotonic() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--items", type=int, default=20)
    ap.add_argument("--raters", type=int, default=2000, help="at most this many simulated raters")
    ap.add_argument("--level", type=float, default=0.95)
    ap.add_argument("--width", type=float, default=60.0)
    ap.add_argument("--cap", type=int, default=12000)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    names, theta = leaderboard_truth()
    quality = {n: round(float(3.0 + (t - theta.mean()) / BT_SCALE), 4) for n, t in zip(names, theta)}
    cluster, _ = suite_server()
    tmp = Path(os.environ.get("TMPDIR", "/tmp")) / f"pairwise_active_app_{os.getpid()}"
    try:
        manifest = write_fake_stimuli(tmp, n_items=a.items, conditions=tuple(names), n_catch=0, n_frames=4)
        print(f"load average {os.getloadavg()[0]:.2f}; qualities {quality}")
        for pairing in ("balanced", "active"):
            summary, r, wall = one_study(manifest, quality, pairing, a)
            order = r["order"]
            tau = kendalltau([r["elo"][n] for n in names], theta).statistic
            truth_order = [names[i] for i in np.argsort(-theta)]
            print(
                f"| {pairing} | {r['votes']} | {'settled' if r['settled'] else 'cap'} | {tau:.3f} | "
                f"{'yes' if order == truth_order else 'no'} | {r['weakest_separation']} | {r['widest_interval']} | "
                f"{summary['n_raters_started']} | {wall:.0f} s | {os.getloadavg()[0]:.2f} |",
                flush=True,
            )
    finally:
        if cluster is not None:
            cluster.remove()


if __name__ == "__main__":
    main()
