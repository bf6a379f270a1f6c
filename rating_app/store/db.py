"""The store: SQLAlchemy models and engine set-up (SQLite file with WAL by default, PostgreSQL by URL).

One row per rater session (`Rater`), one per planned trial (`Trial`), one per stored rating (`Rating`, unique per
trial so a repeated submission can never be counted twice), plus playback events and the clip table copied from the
manifest (so an export needs only the database). Pairwise and parallel trials show several clips (`TrialClip`) and
store a `Preference` or one `PageRating` per clip; the study's design is a `StudySetting` row, so a restart can never
mix designs in one database. The admin's logins and failed token guesses are rows too, so that every gunicorn worker
sees a logout and a lockout at once. Every table is here, a growing study's too (rounds.py), so that the schema
`init_db` creates never depends on which modules were imported.

At about 500 lines it is longer than the house's 400: the models, their additions for databases made by earlier
versions and the engine set-up are one concept (what the database is), kept together so that a table and its
migration change side by side.
"""

from __future__ import annotations

import datetime as dt
import os
import secrets

from flask import current_app
from sqlalchemy import (
    Boolean,
    CheckConstraint,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    Text,
    UniqueConstraint,
    and_,
    case,
    create_engine,
    event,
    func,
    or_,
    select,
)
from sqlalchemy.engine import Engine, make_url
from sqlalchemy.exc import ArgumentError
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from moglow_eval.core import study

from .manifest import AppError
from .schema import add_missing_columns, init_lock
from .settings import SETTINGS

DEFAULT_DB = "sqlite:///ratings.sqlite"


def utcnow() -> dt.datetime:
    """Naive UTC timestamps everywhere (SQLite keeps no zone); exported with a 'Z'."""
    return dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)


class Base(DeclarativeBase):
    pass


class Clip(Base):
    __tablename__ = "clips"
    clip_id: Mapped[str] = mapped_column(String(64), primary_key=True)
    condition: Mapped[str] = mapped_column(String(64))
    role: Mapped[str] = mapped_column(String(16), index=True)
    item: Mapped[str] = mapped_column(String(128), default="")
    frames: Mapped[int | None] = mapped_column(Integer, nullable=True)
    fps: Mapped[float | None] = mapped_column(Float, nullable=True)
    # appropriateness: the other item whose motion a mismatched clip shows (CONTRACTS §10); "" for the others
    motion_item: Mapped[str | None] = mapped_column(String(128), nullable=True, default="")
    # how the body is drawn (manifest `style`, CONTRACTS §4); "" or NULL when the manifest has no style column
    style: Mapped[str | None] = mapped_column(String(16), nullable=True, default="")
    # a stochastic system's sample (manifest `sample`), and the clip that stands for its samples in the balancing
    # (pairing/samples.py): "" or NULL without samples
    sample: Mapped[str | None] = mapped_column(String(64), nullable=True, default="")
    sample_of: Mapped[str | None] = mapped_column(String(64), nullable=True, default="")


class Rater(Base):
    """One rater session. `token` is the secret capability used in API URLs; `rater_id` is exported."""

    __tablename__ = "raters"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    token: Mapped[str] = mapped_column(String(64), unique=True)
    rater_id: Mapped[str] = mapped_column(String(32), unique=True)
    external_id: Mapped[str | None] = mapped_column(String(128), unique=True, nullable=True)
    study_id: Mapped[str | None] = mapped_column(String(128), nullable=True)
    external_session: Mapped[str | None] = mapped_column(String(128), nullable=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime)
    last_seen: Mapped[dt.datetime] = mapped_column(DateTime, index=True)
    # Creation or the last accepted answer: polling GET next is no progress, so it cannot keep a session alive.
    last_progress: Mapped[dt.datetime] = mapped_column(DateTime, index=True)
    completed_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    expired_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    completion_code: Mapped[str] = mapped_column(String(64))
    n_training: Mapped[int] = mapped_column(Integer, default=0)
    n_rating: Mapped[int] = mapped_column(Integer, default=0)
    client: Mapped[str] = mapped_column(String(32), index=True, default="")  # keyed hash of the address
    resume_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)  # sha256 of the resume cookie
    n_early: Mapped[int] = mapped_column(Integer, default=0)  # answers refused as too early
    # The audio check of a study with sound (media/audio_check.py): the sample being played, failed tries, passed when.
    audio_sample: Mapped[str | None] = mapped_column(String(64), nullable=True)
    audio_tries: Mapped[int | None] = mapped_column(Integer, nullable=True, default=0)
    audio_passed_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)


class Trial(Base):
    """A slot in a rater's own random order (`position`). Training slots get their clip at creation; a test or
    catch slot gets it only when it is first served, so a session holds a clip's slot only while it is on the
    rater's screen (a session that never progresses holds nothing), and test and catch slots take the same path."""

    __tablename__ = "trials"
    __table_args__ = (UniqueConstraint("rater_pk", "clip_id"), UniqueConstraint("rater_pk", "position"))
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rater_pk: Mapped[int] = mapped_column(ForeignKey("raters.id"), index=True)
    clip_id: Mapped[str | None] = mapped_column(ForeignKey("clips.clip_id"), index=True, nullable=True)
    kind: Mapped[str] = mapped_column(String(16), default="test")  # training | test | catch (never sent)
    phase: Mapped[str] = mapped_column(String(16))  # training | rating
    position: Mapped[int] = mapped_column(Integer)  # 0.. over the whole session
    index: Mapped[int] = mapped_column(Integer)  # 1.. within the phase
    served_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)  # first GET next
    video_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)  # first bytes of the video sent
    video_ranges: Mapped[str | None] = mapped_column(String(400), nullable=True)  # bytes sent (media/fetched.py)
    answered_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    # An expired session's unanswered slots, and a slot no clip was left for, are released: never served
    # and never answerable again.
    released: Mapped[bool] = mapped_column(Boolean, default=False)
    # pairwise / parallel: the unit (designs.Unit.key) the slot got when served; its clips are TrialClip rows.
    unit: Mapped[str | None] = mapped_column(String(400), nullable=True, index=True)
    # acr, a stochastic system's clip: the sample drawn for this rater (pairing/samples.py), which the trial shows
    # and its rating names; NULL where the clip has no other samples. (A unit's clips are the drawn samples.)
    sample_clip: Mapped[str | None] = mapped_column(String(64), nullable=True)


class TrialClip(Base):
    """One clip of a pairwise or parallel trial, in the order and under the label the rater sees (A, B, ...)."""

    __tablename__ = "trial_clips"
    __table_args__ = (UniqueConstraint("trial_pk", "position"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    trial_pk: Mapped[int] = mapped_column(ForeignKey("trials.id"), index=True)
    position: Mapped[int] = mapped_column(Integer)
    label: Mapped[str] = mapped_column(String(4))
    clip_id: Mapped[str] = mapped_column(ForeignKey("clips.clip_id"))
    video_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)  # first bytes of the video sent
    video_ranges: Mapped[str | None] = mapped_column(String(400), nullable=True)  # bytes sent (media/fetched.py)


class Rating(Base):
    __tablename__ = "ratings"
    __table_args__ = (CheckConstraint("rating BETWEEN 1 AND 5", name="rating_range"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    trial_pk: Mapped[int] = mapped_column(ForeignKey("trials.id"), unique=True)  # stored once per trial
    rater_pk: Mapped[int] = mapped_column(ForeignKey("raters.id"), index=True)
    clip_id: Mapped[str] = mapped_column(ForeignKey("clips.clip_id"), index=True)
    rating: Mapped[int] = mapped_column(Integer)
    watched_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    submitted_at: Mapped[dt.datetime] = mapped_column(DateTime)
    flags: Mapped[str] = mapped_column(String(64), default="")  # e.g. no_video, partial_video (see export.FLAGS)


class Preference(Base):
    """A pairwise answer: 2 = A clearly more natural .. -2 = B clearly (A = the clip shown as A)."""

    __tablename__ = "preferences"
    __table_args__ = (CheckConstraint("preference BETWEEN -2 AND 2", name="preference_range"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    trial_pk: Mapped[int] = mapped_column(ForeignKey("trials.id"), unique=True)  # stored once per trial
    rater_pk: Mapped[int] = mapped_column(ForeignKey("raters.id"), index=True)
    clip_a: Mapped[str] = mapped_column(ForeignKey("clips.clip_id"))
    clip_b: Mapped[str] = mapped_column(ForeignKey("clips.clip_id"))
    preference: Mapped[int] = mapped_column(Integer)
    watched_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    submitted_at: Mapped[dt.datetime] = mapped_column(DateTime)
    flags: Mapped[str] = mapped_column(String(64), default="")
    # The study's round when the vote was stored (rounds.py; NULL: stored before rounds, i.e. round 1), the reasons
    # ticked (ids joined by ';') and the free text exactly as typed (reasons.py).
    round: Mapped[int | None] = mapped_column(Integer, nullable=True)
    reasons: Mapped[str | None] = mapped_column(String(500), nullable=True, default="")
    reason_text: Mapped[str | None] = mapped_column(Text, nullable=True, default="")


class PageRating(Base):
    """One clip's 0..100 rating on a parallel page; a page's rows are written in one transaction."""

    __tablename__ = "page_ratings"
    __table_args__ = (
        UniqueConstraint("trial_pk", "clip_id"),
        CheckConstraint("rating BETWEEN 0 AND 100", name="page_rating_range"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    trial_pk: Mapped[int] = mapped_column(ForeignKey("trials.id"), index=True)
    rater_pk: Mapped[int] = mapped_column(ForeignKey("raters.id"), index=True)
    clip_id: Mapped[str] = mapped_column(ForeignKey("clips.clip_id"), index=True)
    rating: Mapped[int] = mapped_column(Integer)
    watched_ms: Mapped[int | None] = mapped_column(Integer, nullable=True)
    submitted_at: Mapped[dt.datetime] = mapped_column(DateTime)
    flags: Mapped[str] = mapped_column(String(64), default="")


# The StudySetting (and export column) holding how many raters fill the study as the app was last started
# (create_app's target_raters): analysis.report notes an export from fewer raters than that (CONTRACTS §6).
TARGET_RATERS = "target_raters"
# The secret that seeds each rater's draw of a stochastic system's sample (pairing/samples.py): written by the
# first start and kept, so that a restart draws as before.
SAMPLE_SEED = "sample_seed"


class StudySetting(Base):
    """Settings fixed for the life of a study's database; `design` is written by the first start."""

    __tablename__ = "study_settings"
    name: Mapped[str] = mapped_column(String(32), primary_key=True)
    value: Mapped[str] = mapped_column(String(200))


class StudyCondition(Base):
    """A test condition of a growing study (rounds.py): the round it joined in, when it was withdrawn (NULL: served)."""

    __tablename__ = "study_conditions"
    name: Mapped[str] = mapped_column(String(64), primary_key=True)
    round: Mapped[int] = mapped_column(Integer)
    added_at: Mapped[dt.datetime] = mapped_column(DateTime)
    withdrawn_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)


class StudyManifest(Base):
    """Where the study's manifest lies, as the app was last started: add-condition appends to it (rounds.py)."""

    __tablename__ = "study_manifest"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)  # always 1
    path: Mapped[str] = mapped_column(Text)


class Event(Base):
    """Client-reported problems (failed playback, ...), also written to the server log."""

    __tablename__ = "events"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rater_pk: Mapped[int | None] = mapped_column(ForeignKey("raters.id"), nullable=True)
    trial_pk: Mapped[int | None] = mapped_column(Integer, nullable=True)
    kind: Mapped[str] = mapped_column(String(32))
    detail: Mapped[str] = mapped_column(String(500), default="")
    created_at: Mapped[dt.datetime] = mapped_column(DateTime)


class AdminLogin(Base):
    """A browser login to the dashboard; logout deletes the row, so a copied cookie stops working."""

    __tablename__ = "admin_logins"
    key_hash: Mapped[str] = mapped_column(String(64), primary_key=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime)


class LoginFailure(Base):
    """A wrong admin token, per client: enough of them lock that client out for a while."""

    __tablename__ = "login_failures"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    client: Mapped[str] = mapped_column(String(32), index=True)
    at: Mapped[dt.datetime] = mapped_column(DateTime)


class Cover(Base):
    """How far each test or catch clip (acr) or unit (pairwise, parallel) is covered: its answered trials and the
    slots held for it now (served, unanswered, not released). The transactions that assign, answer and release
    a slot update its row, so assignment reads one small row per clip or unit instead of counting every trial
    under the assignment lock; `trial_cover` is the count from the trials that these rows always equal."""

    __tablename__ = "cover"
    key: Mapped[str] = mapped_column(String(400), primary_key=True)  # clip_id (acr) or designs.Unit.key
    answered: Mapped[int] = mapped_column(Integer, default=0)
    held: Mapped[int] = mapped_column(Integer, default=0)


# A trial's Cover key: its clip (acr) or its unit (pairwise, parallel); a served test or catch trial has exactly one.
COVER_KEY = func.coalesce(Trial.clip_id, Trial.unit)
# A clip the balancing counts: every clip but the other samples of a stochastic system's clip (store/samples.py).
STANDING_CLIP = or_(Clip.sample_of.is_(None), Clip.sample_of == "", Clip.sample_of == Clip.clip_id)
COVERED_KINDS = ("test", "catch")  # trials counted in Cover (training trials are shown to everyone)


def trial_cover(conn):
    """{Cover key: (answered trials, held slots)} over test and catch trials, counted from the trials in ONE statement
    (two statements would each see the data as of their own start under PostgreSQL's read committed, and an
    answer committed between them would be in neither count)."""
    held = case((and_(Trial.answered_at.is_(None), Trial.released.is_(False)), 1), else_=0)
    rows = conn.execute(
        select(COVER_KEY, func.count(Trial.answered_at), func.sum(held))
        .where(Trial.kind.in_(COVERED_KINDS), COVER_KEY.is_not(None))
        .group_by(COVER_KEY)
    ).all()
    return {k: (int(done), int(h or 0)) for k, done, h in rows}


class Lock(Base):
    """A single row taken FOR UPDATE while assigning clips, so concurrent sessions see each other's slots."""

    __tablename__ = "locks"
    name: Mapped[str] = mapped_column(String(32), primary_key=True)


def normalise_url(url: str | None) -> str:
    url = url or DEFAULT_DB
    if url.startswith("postgres://"):
        url = "postgresql://" + url[len("postgres://") :]
    if url.startswith("postgresql://"):
        url = "postgresql+psycopg://" + url[len("postgresql://") :]
    return url


def check_url(url: str | None) -> str:
    """The normalised URL, or an AppError naming what is wrong: not a URL, a database other than SQLite or
    PostgreSQL, or an SQLite path that is an existing file but no SQLite database."""
    url = normalise_url(url)
    try:
        parsed = make_url(url)
    except ArgumentError:
        raise AppError(f"--db {url!r} is not a database URL (sqlite:///FILE or postgresql://HOST/DB)") from None
    family = parsed.get_backend_name()
    if family not in ("sqlite", "postgresql"):
        raise AppError(
            f"--db {parsed.render_as_string(hide_password=True)}: unsupported database {family!r} "
            "(sqlite or postgresql)"
        )
    db = parsed.database or ""
    if family == "sqlite" and db and db != ":memory:" and os.path.exists(db):
        if not os.path.isfile(db):
            raise AppError(f"{db}: not a file")
        with open(db, "rb") as fh:
            head = fh.read(16)
        if head and head != b"SQLite format 3\0":
            raise AppError(f"{db}: not an SQLite database")
    return url


def require_sqlite_file(path: str) -> None:
    """AppError unless `path` is a file with something in it: a command that reads a study (export, backup, adding
    a condition) would otherwise open a missing or empty file as a new database and write SQLite's header into
    the user's file."""
    if not path or path == ":memory:":  # sqlite:// is a database in memory, with no study in it
        raise AppError("--db: an SQLite database in a file is needed (sqlite:///FILE), not one in memory")
    if not os.path.isfile(path):
        raise AppError(f"{path}: no such database file")
    if os.path.getsize(path) == 0:
        raise AppError(f"{path}: an empty file, not a rating app database")


def is_sqlite(engine: Engine) -> bool:
    return engine.dialect.name == "sqlite"


def app_engine(app=None) -> Engine:
    """The database engine of `app` (default: the app handling the current request), which create_app made."""
    return (app or current_app).extensions["rating_app"]["engine"]


def read_engine(app=None) -> Engine:
    """The engine for a request's single reads (the current trial, a video's trial), made by make_read_engine."""
    return (app or current_app).extensions["rating_app"]["read_engine"]


def make_read_engine(engine: Engine) -> Engine:
    """`engine` for single reads: PostgreSQL runs them in autocommit, without the BEGIN and COMMIT round trips of
    a transaction; SQLite in a read-only transaction, which takes no write lock (make_engine). It shares
    `engine`'s pool."""
    if is_sqlite(engine):
        return engine.execution_options(read_only=True)
    return engine.execution_options(isolation_level="AUTOCOMMIT")


def make_engine(url: str | None = None, pool_size: int = SETTINGS["DB_POOL_SIZE"].default) -> Engine:
    """The engine of `url` (check_url); PostgreSQL's pool `pool_size` a process, within the bounds of DB_POOL_SIZE."""
    pool = SETTINGS["DB_POOL_SIZE"].parse(pool_size, "pool_size")  # create_app's: RATING_DB_POOL_SIZE, read once
    url = check_url(url)
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"timeout": 30, "check_same_thread": False})

        @event.listens_for(engine, "connect")
        def _sqlite_connect(dbapi_conn, _record):
            dbapi_conn.isolation_level = None  # we issue BEGIN ourselves
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=FULL")  # a commit survives a crash of the machine too
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA busy_timeout=30000")
            cur.close()

        @event.listens_for(engine, "begin")
        def _sqlite_begin(conn):
            # Take the write lock up front: a read-then-write transaction can then never fail on a
            # stale snapshot when several worker processes share the file. Pure reads (marked
            # read_only) take no lock, so with WAL they never wait for a writer.
            read_only = conn.get_execution_options().get("read_only", False)
            conn.exec_driver_sql("BEGIN" if read_only else "BEGIN IMMEDIATE")

        return engine
    # Per process; keep workers x (pool_size + max_overflow) under the server's max_connections (100 by default).
    return create_engine(url, pool_size=pool, max_overflow=pool, pool_recycle=1800)


def study_setting(conn, name: str) -> str | None:
    """A StudySetting's value, or None when the database has none of that name."""
    return conn.execute(select(StudySetting.value).where(StudySetting.name == name)).scalar()


def study_design(conn) -> str | None:
    """The design stored with the study, or None for a database that has none yet."""
    return conn.execute(select(StudySetting.value).where(StudySetting.name == "design")).scalar()


def _add_cover_rows(session, keys) -> None:
    """Cover rows for keys that have none: zero in a new study, counted from the trials in a database made
    before the rows existed. Under the assignment lock, so no slot is assigned meanwhile."""
    have = set(session.scalars(select(Cover.key)))
    missing = [k for k in keys if k not in have]
    if missing:
        if session.bind.dialect.name != "sqlite":  # SQLite: BEGIN IMMEDIATE already holds the write lock
            session.execute(select(Lock).where(Lock.name == "assign").with_for_update())
        counts = trial_cover(session.connection())
        session.add_all(Cover(key=k, answered=counts.get(k, (0, 0))[0], held=counts.get(k, (0, 0))[1]) for k in missing)


# from the manifest (and pairing/samples.py's sample_of)
CLIP_COLUMNS = ("clip_id", "condition", "role", "item", "frames", "fps", "motion_item", "style", "sample", "sample_of")


def clip_row(c) -> Clip:
    """The Clip row of a manifest clip (manifest.ManifestClip)."""
    return Clip(**{k: getattr(c, k) for k in CLIP_COLUMNS})


def _upsert_clips(s, clips) -> None:
    """The manifest's clips as Clip rows: new ones added, known ones updated."""
    have = {c.clip_id: c for c in s.scalars(select(Clip))}
    for c in clips:
        row = have.get(c.clip_id)
        if row is None:
            s.add(clip_row(c))
        else:
            for k in CLIP_COLUMNS[1:]:
                setattr(row, k, getattr(c, k))


def init_db(engine: Engine, clips=None, design: str | None = None, cover_keys=None, settings=None) -> None:
    """Create the schema (idempotent), upsert the manifest's clips, store the study's design and give every key
    in `cover_keys` (test clips or units) its Cover row; AppError when the database already holds a study of
    another design (a database that predates designs holds an acr one). `settings` {name: value}: StudySetting
    rows that follow the app's configuration, written at every start (the design is written once)."""
    from sqlalchemy.orm import Session

    with init_lock(engine):
        Base.metadata.create_all(engine)
        add_missing_columns(engine)
        with Session(engine) as s, s.begin():
            if s.get(Lock, "assign") is None:
                s.add(Lock(name="assign"))
            if design is not None:
                have = study_design(s)
                if have is None and s.scalar(select(Rater.id).limit(1)) is not None:
                    have = study.DEFAULT_DESIGN  # sessions from before designs were stored (acr)
                if have is not None and have != design:
                    where = make_url(str(engine.url)).render_as_string(hide_password=True)
                    raise AppError(
                        f"the database {where} holds a {have} study; it cannot be served as {design} "
                        "(use another database, or --design " + have + ")"
                    )
                if s.get(StudySetting, "design") is None:
                    s.add(StudySetting(name="design", value=design))
            if s.get(StudySetting, SAMPLE_SEED) is None:
                s.add(StudySetting(name=SAMPLE_SEED, value=secrets.token_hex(16)))
            if clips:
                _upsert_clips(s, clips)
            if cover_keys:
                _add_cover_rows(s, cover_keys)
            for name, value in (settings or {}).items():
                s.merge(StudySetting(name=name, value=str(value)))
