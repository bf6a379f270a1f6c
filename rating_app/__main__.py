"""python -m rating_app serve | export | backup | restore | add-condition | withdraw-condition | simulate  (see --help
of each)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from moglow_eval.core import cli, whole_files
from moglow_eval.core.study import DESIGNS

from .store.config import environment
from .store.manifest import AppError
from .store.settings import add_flags

# Diagnostics (where the app runs, how many rows were exported) go to the log, on stderr; results to stdout.
log = logging.getLogger("rating_app")


def _serve(a):
    from . import create_app

    app = create_app(**a.given)  # the settings given as flags; the rest from the environment and study file
    from .store.db import app_engine

    db = app_engine(app).url.render_as_string(hide_password=True)
    log.info(
        "rating app on http://%s:%s/  (%s design; database %s; admin at /admin%s)",
        a.host,
        a.port,
        app.config["STUDY_DESIGN"],
        db,
        "" if app.config["ADMIN_TOKEN"] else " disabled: set RATING_ADMIN_TOKEN",
    )
    if app.config["MIN_VIEW"] < 1:
        log.warning(
            "warning: minimum viewing time lowered to %g of each clip (tests and simulations only)",
            app.config["MIN_VIEW"],
        )
    if app.config["SESSIONS_PER_CLIENT"] == 0:
        log.warning("warning: no limit on new sessions per address (local trials and simulated crowds only)")
    app.run(host=a.host, port=a.port, threaded=True, debug=False, use_reloader=False)
    return 0


def _export(a):
    from sqlalchemy import inspect
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import SQLAlchemyError

    from .designs import get
    from .operations.battles import export_battles
    from .operations.export import export_csv
    from .store.db import check_url, make_engine, require_sqlite_file, study_design

    url = check_url(a.db)
    parsed = make_url(url)
    sqlite = parsed.drivername.startswith("sqlite")
    if a.out != "-":  # the study's own SQLite file as --out would be replaced by its export
        db_file = (parsed.database or None) if sqlite else None
        cli.file_to_write(a.out, "the file to write, or - for the standard output", reads=[("--db", db_file)])
    if sqlite:
        require_sqlite_file(parsed.database or "")
    engine = make_engine(url)
    try:
        if "ratings" not in inspect(engine).get_table_names():
            raise AppError(
                f"{parsed.render_as_string(hide_password=True)}: no ratings table (not a rating app database)"
            )
        with engine.connect() as conn:
            design = study_design(conn)
        write = export_csv if a.format == "csv" else export_battles
        if a.out == "-":
            n = write(engine, sys.stdout)
        else:
            # Written whole or not at all: a refusal half-way leaves no half-written file.
            try:
                with whole_files.writing(a.out) as tmp, open(tmp, "x", newline="", encoding="utf-8") as fh:
                    n = write(engine, fh)
            except OSError as e:
                raise AppError(f"{a.out}: {e.strerror}") from None
    except SQLAlchemyError as e:
        first = str(getattr(e, "orig", None) or e).strip().splitlines()
        raise AppError(f"cannot read the database: {first[0] if first else e.__class__.__name__}") from None
    finally:
        engine.dispose()
    log.info("%s %s -> %s", n, get(design).export_noun if a.format == "csv" else "battles", a.out)
    return 0


def _backup(a):
    from .operations.backup import backup

    kind = backup(a.db, a.out)
    log.info("%s backup -> %s", kind, a.out)
    print(a.out)
    return 0


def _restore(a):
    from .operations.backup import restore

    kind = restore(a.backup, a.db)
    log.info("%s backup %s restored", kind, a.backup)
    return 0


def _simulate(a):
    from .simulate import parse_quality, run_simulation, shortfall, write_summary

    if a.summary and (Path(a.summary).is_dir() or not Path(a.summary).parent.is_dir()):  # before any rater answers
        raise AppError(f"--summary {a.summary}: not a file in an existing folder")
    summary = run_simulation(
        a.url,
        a.raters,
        manifest=a.manifest,
        seed=a.seed,
        careless=a.careless,
        quality=parse_quality(a.quality),
        concurrency=a.concurrency,
        timeout_s=a.timeout,
        think_s=a.think,
        prefix=a.prefix,
        progress=not a.quiet,
        design=a.design,
    )
    if a.summary:
        write_summary(summary, a.summary)
    short = {
        k: summary[k]
        for k in (
            "n_raters_started",
            "n_raters_completed",
            "n_raters_refused",
            "study_full",
            "timed_out",
            "n_ratings",
            "n_ratings_by_condition",
            "quality",
            "elapsed_s",
        )
    }
    short["careless_raters"] = len(summary["careless_raters"])
    short["failed_catch_raters"] = len(summary["failed_catch_raters"])
    short["errors"] = summary["errors"][:5]
    print(json.dumps(short))
    why = shortfall(summary)
    if why:  # the summary above is still the record; the exit and this one line say the crowd fell short
        raise AppError(why)
    return 0


def _open_db(db_url):
    """The engine of an existing rating app database; AppError, one line, otherwise."""
    from sqlalchemy import inspect
    from sqlalchemy.engine import make_url

    from .store.db import check_url, make_engine, require_sqlite_file

    url = check_url(db_url)
    parsed = make_url(url)
    if parsed.drivername.startswith("sqlite"):
        require_sqlite_file(parsed.database or "")
    engine = make_engine(url)
    if "study_conditions" not in inspect(engine).get_table_names():
        engine.dispose()
        raise AppError(f"{parsed.render_as_string(hide_password=True)}: not a study started by this version of the app")
    return engine


def _add_condition(a):
    from .operations.conditions import add_condition

    engine = _open_db(a.db)
    try:
        out = add_condition(engine, a.manifest, a.condition or (), a.study_manifest)
    finally:
        engine.dispose()
    log.info(
        "round %s: %s joined the study (%s clips, %s new pairs)",
        out["round"],
        ", ".join(out["conditions"]),
        out["clips"],
        out["pairs"],
    )
    print(json.dumps(out))
    return 0


def _withdraw_condition(a):
    from .operations.conditions import withdraw_condition

    engine = _open_db(a.db)
    try:
        out = withdraw_condition(engine, a.condition)
    finally:
        engine.dispose()
    log.info("%s withdrawn: its pairs are no longer served; its votes stay in the export", a.condition)
    print(json.dumps(out))
    return 0


def _rounds_parsers(sub, db):
    """add-condition and withdraw-condition (operations/conditions.py)."""
    c = sub.add_parser("add-condition", help="add a condition's clips to a running pairwise study (a new round)")
    c.add_argument("--db", default=None, help=db)
    c.add_argument("--manifest", required=True, help="the new condition's stimulus folder's manifest.csv")
    c.add_argument(
        "--condition", action="append", help="the condition to add (repeatable; default: every one the study lacks)"
    )
    c.add_argument(
        "--study-manifest", default=None, help="the study's manifest (default: the one the app was last started with)"
    )
    c.set_defaults(fn=_add_condition)
    w = sub.add_parser("withdraw-condition", help="stop serving a condition's pairs (its votes stay in the export)")
    w.add_argument("--db", default=None, help=db)
    w.add_argument("--condition", required=True, help="the condition to withdraw")
    w.set_defaults(fn=_withdraw_condition)


def build_parser():
    """The command's parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    p = cli.ArgumentParser(prog="python -m rating_app", description=__doc__)
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=cli.ArgumentParser)
    _serve_parser(sub)
    db = "database URL (default $RATING_DATABASE_URL or sqlite:///ratings.sqlite)"
    e = sub.add_parser("export", help="write ratings.csv from the database")
    e.add_argument("--db", default=None, help=db)
    e.add_argument("--out", default="ratings.csv", help="output file, '-' for stdout")
    e.add_argument(
        "--format",
        choices=("csv", "battles"),
        default="csv",
        help="csv: the design's file (ratings.csv, pairs.csv, ...); battles: a pairwise study's test votes in the "
        "GENEA leaderboard's battle format",
    )
    e.set_defaults(fn=_export)
    b = sub.add_parser("backup", help="a consistent copy of a running study's database (SQLite backup API / pg_dump)")
    b.add_argument("--db", default=None, help=db)
    b.add_argument("--out", required=True, help="the backup file (SQLite: a database file; PostgreSQL: pg_dump -Fc)")
    b.set_defaults(fn=_backup)
    r = sub.add_parser("restore", help="restore a backup into a new SQLite file or an empty PostgreSQL database")
    r.add_argument("backup", help="the file `backup` wrote")
    r.add_argument("--db", required=True, help="the new SQLite file or empty PostgreSQL database to restore into")
    r.set_defaults(fn=_restore)
    _rounds_parsers(sub, db)
    _simulate_parser(sub)
    return p


def _serve_parser(sub):
    """serve: a flag per setting of the settings table (settings.TABLE), and where to listen."""
    s = sub.add_parser("serve", help="run the app (local use; production: gunicorn --preload, docs/hosting.md)")
    add_flags(s)
    s.add_argument("--host", default="127.0.0.1")
    s.add_argument("--port", type=cli.number(int, 1, 65535), default=5000)
    s.set_defaults(fn=_serve)


def _app_url(text):
    """--url: the app's http(s) address (any other would be tried for seconds before a bare connection error)."""
    from urllib.parse import urlsplit

    parts = urlsplit(text)
    if parts.scheme not in ("http", "https") or not parts.netloc:
        raise argparse.ArgumentTypeError(f"expected the app's address, http://HOST:PORT or https://HOST, got {text!r}")
    return text


def _rater_prefix(text):
    """--prefix: what the app takes as the start of an id (guard.bodies.EXTERNAL), room left for -NNNNNN."""
    from .guard.bodies import EXTERNAL

    if len(text) > 120 or not EXTERNAL.fullmatch(text):
        raise argparse.ArgumentTypeError(
            f"expected 1-120 letters, digits and _.:@- (each rater's id is PREFIX-NNNNN), got {text[:40]!r}"
        )
    return text


def _simulate_parser(sub):
    m = sub.add_parser("simulate", help="a simulated crowd rating through the public API")
    m.add_argument("--url", required=True, type=_app_url, help="base URL of the running app")
    m.add_argument(
        "--raters",
        type=cli.number(int, 1, 1_000_000),
        required=True,
        help="number of raters (stops early when the study is full)",
    )
    m.add_argument("--seed", type=cli.number(int, 0, 2**31 - 1), default=0)
    m.add_argument(
        "--careless", type=cli.number(float, 0, 1), default=0.1, help="share of careless raters answering at random"
    )
    m.add_argument(
        "--manifest",
        required=True,
        help="the manifest.csv the app serves: the clips' conditions and durations (+ metrics.csv beside it: "
        "their quality)",
    )
    m.add_argument("--quality", default=None, help="per-condition mean rating, e.g. NAT=4.3,MG=3.8,FL=2.5,BAD=1.3")
    m.add_argument(
        "--design",
        choices=DESIGNS,
        default=None,
        help="the design the server must run (checked first); default: answer whichever it runs",
    )
    m.add_argument("--concurrency", type=cli.number(int, 1, 1000), default=8, help="raters at once")
    m.add_argument(
        "--timeout", type=cli.number(float, 0, 1e6, lo_open=True), default=600.0, help="overall time limit in seconds"
    )
    m.add_argument(
        "--think", type=cli.number(float, 0, 3600), default=0.0, help="mean pause before each answer, seconds"
    )
    m.add_argument("--prefix", default=None, type=_rater_prefix, help="external id prefix (default sim{seed})")
    m.add_argument("--summary", default=None, help="write the full summary (raters, ratings) as JSON here")
    m.add_argument("--quiet", action="store_true", help="no progress bar")
    m.set_defaults(fn=_simulate)


def _main(argv):
    a = build_parser().parse_args(argv)
    if getattr(a, "db", "") is None:  # export, backup and the rounds' commands without --db: the study's variable
        a.db = environment().get("DATABASE_URL")
    return a.fn(a)


def main(argv=None) -> int:
    # The one place that configures logging: library code (create_app, the crowd) only logs.
    cli.log_to_stderr()
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
