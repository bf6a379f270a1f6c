"""The app's settings, in one typed table: from it come `create_app`'s keyword arguments, the environment variables
(gunicorn), the study file's keys (store/config.py), `serve`'s flags and their help.

Each setting has a name (`DATABASE_URL`); its study-file key is the name in lower case (`database_url`) and its
environment variable the name under the one prefix `RATING_` (`RATING_DATABASE_URL`; a name that has the prefix
already, `RATING_MANIFEST`, keeps it once). The app reads no other variable of the environment, so a shell's
unrelated `DATABASE_URL` or `SECRET_KEY` cannot change a study (store/config.py refuses the names from before the
prefix).

A setting given to `create_app` (or as a flag) wins over its environment variable, which wins over the study file,
which wins over the default. Every value is checked where it is read, so a bad one stops the start with one line
naming the flag, the variable or the key.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

from moglow_eval.core import pair_posterior, study, votes
from moglow_eval.core.cli import number

from .manifest import AppError

PREFIX = "RATING_"  # of every environment variable the app reads as a setting
# VIDEO_ACCEL: the reverse proxy that sends the bytes itself (an internal redirect); off: the app sends them.
ACCEL = ("off", "nginx", "caddy")


@dataclass(frozen=True)
class Setting:
    """One setting. `name`: what the code calls it (create_app's values, the study file's key in lower case);
    `kind`: str, int, float or bool (bool: "1" in the environment, true or false in the study file). `arg`:
    create_app's keyword argument (None: the environment and the study file only); `flag`: serve's flag (None:
    none); `bounds`: a number's (lo, hi, lo_open), as cli.number takes them; `secret`: given in the environment
    only, refused in the study file; `in_file`: a key of the study file."""

    name: str
    kind: type = str
    default: object = None
    help: str = ""
    arg: str | None = None
    flag: str | None = None
    bounds: tuple = ()
    choices: tuple = ()
    secret: bool = False
    in_file: bool = True

    @property
    def env(self) -> str:
        """Its environment variable: the name under PREFIX."""
        return self.name if self.name.startswith(PREFIX) else PREFIX + self.name

    @property
    def key(self) -> str:
        """Its key in the study file."""
        return self.name.lower()

    def parse(self, raw, where):
        """`raw` (a string from the environment or the study file, or a value given to create_app) as this
        setting's value; AppError naming `where` when it is not one."""
        if self.kind in (int, float):
            try:
                return number(self.kind, *self.bounds)(str(raw))
            except argparse.ArgumentTypeError as e:
                raise AppError(f"{where}: {e}") from None
        if self.kind is bool:
            return raw is True or raw == "1"
        value = str(raw)
        if self.choices:
            value = value.strip().lower()
            if value not in self.choices:
                raise AppError(f"{where}: {value!r} must be one of {', '.join(self.choices)}")
        return value

    def flag_type(self):
        """The flag's argparse type: the same bounds as the environment variable."""
        return number(self.kind, *self.bounds) if self.kind in (int, float) else str


_COUNT = (1, 1_000_000)
_ZERO_UP = (0, 1_000_000)
# In the order docs/hosting.md gives them: what the study is and where it lives, then its numbers, then the server's.
TABLE = (
    Setting(
        "RATING_CONFIG",
        arg="config",
        flag="--config",
        in_file=False,
        help="study file (TOML): a key per setting below, its variable in lower case less RATING_ (rating_manifest "
        "keeps it), e.g. ratings_per_clip = 20; flags and set environment variables override it",
    ),
    Setting("RATING_MANIFEST", arg="manifest", flag="--manifest", help="stimuli/manifest.csv"),
    Setting(
        "DATABASE_URL", arg="db_url", flag="--db", help="database URL (unset: sqlite:///ratings.sqlite in this folder)"
    ),
    Setting(
        "STUDY_DESIGN",
        default=study.DEFAULT_DESIGN,
        arg="design",
        flag="--design",
        choices=tuple(study.DESIGNS),
        help="acr (one clip, 1-5), pairwise (two clips, a preference), parallel (every condition of an item on one "
        "page, 0-100), appropriateness (motion for the speech heard against another item's), dyadic (the agent "
        "beside its interlocutor against another interlocutor's) or semantic (motion for the words said against "
        "another utterance's); stored with the study: a database holds one design",
    ),
    Setting(
        "STUDY_QUESTION",
        arg="question",
        flag="--question",
        help="the question on the rating page (unset: the design's, e.g. 'Which motion looks more natural?' for "
        "pairwise)",
    ),
    Setting(
        "VOTE_REASONS",
        arg="reasons",
        flag="--reasons",
        help="tick boxes shown with each pairwise vote: ID=Label entries joined by commas, or none (unset: GENEA's "
        "four realism reasons for pairwise, none for the other designs)",
    ),
    Setting(
        "REASON_TEXT",
        int,
        arg="reason_text",
        flag="--reason-text",
        bounds=(0, votes.FREE_TEXT_MAX),
        help=f"most characters of the optional free text with each pairwise vote, 0: no text box (unset: "
        f"{votes.FREE_TEXT_MAX} for pairwise, 0 for the other designs)",
    ),
    Setting(
        "COMPLETION_CODE",
        arg="completion_code",
        flag="--completion-code",
        help="one code for everybody (e.g. Prolific's); unset: random per rater",
    ),
    Setting(
        "COMPLETION_URL",
        arg="completion_url",
        flag="--completion-url",
        help="redirect after the last trial; {code} is replaced, e.g. "
        "https://app.prolific.com/submissions/complete?cc={code}",
    ),
    Setting(
        "UPLOAD_ROOT",
        arg="upload_root",
        flag="--upload-root",
        help="the folder under which the dashboard's add-condition form may read a new system's stimulus folder "
        "(unset: the form is off; python -m rating_app add-condition reads any path its user can)",
    ),
    Setting(
        "VIDEO_ACCEL",
        default="off",
        choices=ACCEL,
        help="the reverse proxy that sends the videos' bytes (nginx or caddy: an internal redirect, media/videos.py)",
    ),
    Setting(
        "RATINGS_PER_CLIP",
        int,
        20,
        arg="ratings_per_clip",
        flag="--ratings-per-clip",
        bounds=_COUNT,
        help="target answers per test unit: clip (acr), item and pair of conditions (pairwise), item page (parallel)",
    ),
    Setting(
        "CLIPS_PER_RATER",
        int,
        0,
        arg="clips_per_rater",
        flag="--clips-per-rater",
        bounds=_ZERO_UP,
        help="test units (clips, pairs or pages) per rater (0: all that still need answers)",
    ),
    Setting(
        "CATCH_PER_RATER",
        int,
        4,
        arg="catch_per_rater",
        flag="--catch-per-rater",
        bounds=_ZERO_UP,
        help="catch units per rater, drawn least-covered first from the pool (0: every one); size the pool so that "
        "catch-per-rater / pool matches clips-per-rater / test units",
    ),
    Setting(
        "PAIRING",
        default="balanced",
        arg="pairing",
        flag="--pairing",
        choices=("balanced", "active"),
        help="pairwise: how a slot's pair of conditions is chosen: balanced (least-covered unit) or active (the pair "
        "whose order the votes so far back least, under the Bradley-Terry posterior of the votes so far)",
    ),
    Setting(
        "PAIRING_RANDOM",
        float,
        pair_posterior.RANDOM_SHARE,
        arg="pairing_random",
        flag="--pairing-random",
        bounds=(0.0, 1.0),
        help="active pairing: the share of slots that keep the balanced rule, so that a wrong model cannot starve a "
        "pair",
    ),
    Setting(
        "PAIRING_INDIFFERENCE",
        float,
        pair_posterior.INDIFFERENCE_ELO,
        arg="pairing_indifference",
        flag="--pairing-indifference",
        bounds=(0.0, 1000.0),
        help="active pairing and the stopping rule: two conditions confidently closer than this many Elo points "
        "are tied, get no more active votes and count as settled (0: off)",
    ),
    Setting(
        "STOP_WHEN",
        default="never",
        arg="stop_when",
        flag="--stop-when",
        choices=("never", "settled"),
        help="pairwise: settled closes the study to new raters once the ranking is settled (every adjacent pair "
        "separated at --stop-level, or every Elo interval narrower than --stop-width) or at --stop-max-votes; "
        "sessions already started finish",
    ),
    Setting(
        "STOP_LEVEL",
        float,
        0.95,
        arg="stop_level",
        flag="--stop-level",
        bounds=(0.5, 0.9999),
        help="the stopping rule's level: the chance that the whole order is right (split over the adjacent pairs)",
    ),
    Setting(
        "STOP_WIDTH",
        float,
        0.0,
        arg="stop_width",
        flag="--stop-width",
        bounds=(0.0, 10_000.0),
        help="the stopping rule's Elo width: settled too when every condition's interval at --stop-level is "
        "narrower (Elo points; 0: not used)",
    ),
    Setting(
        "STOP_MAX_VOTES",
        int,
        0,
        arg="stop_max_votes",
        flag="--stop-max-votes",
        bounds=_ZERO_UP,
        help="the stopping rule's cap: closed once the test votes reach it (0: no cap)",
    ),
    Setting(
        "SLOT_TIMEOUT",
        float,
        3600.0,
        arg="slot_timeout_s",
        flag="--slot-timeout",
        bounds=(0.0, 1e7, True),
        help="seconds without an answer before a session expires and its slot is freed",
    ),
    Setting(
        "MIN_VIEW",
        float,
        1.0,
        arg="min_view",
        flag="--min-view",
        bounds=(0.0, 1.0),
        help="share of each clip that must have played before an answer is accepted (1: the whole clip; lower only "
        "for tests and simulated crowds)",
    ),
    Setting(
        "SESSIONS_PER_CLIENT",
        int,
        10,
        arg="sessions_per_client",
        flag="--sessions-per-client",
        bounds=_ZERO_UP,
        help="new sessions per client address and hour (0: no limit)",
    ),
    Setting(
        "PROXY_COUNT",
        int,
        0,
        bounds=(0, 10),
        help="trusted reverse proxies in front, whose X-Forwarded-For names the client",
    ),
    Setting("DB_POOL_SIZE", int, 10, bounds=(1, 1000), help="database connections per worker (and as many overflow)"),
    Setting(
        "VIDEO_CACHE_MB",
        int,
        512,
        bounds=(0, 1_000_000),
        help="megabytes of videos each worker keeps in memory, read at the start; the others are read per request "
        "(0: none kept)",
    ),
    Setting("COOKIE_SECURE", bool, False, help="1: the admin cookie over HTTPS only"),
    Setting("ADMIN_TOKEN", arg="admin_token", secret=True, help="opens /admin; unset: no admin"),
    Setting("SECRET_KEY", arg="secret_key", secret=True, help="the cookie key; unset: derived from RATING_ADMIN_TOKEN"),
)
SETTINGS = {s.name: s for s in TABLE}
ARGS = {s.arg: s for s in TABLE if s.arg}


def resolve(given: dict, env: dict) -> dict:
    """{NAME: value} of every setting but RATING_CONFIG: the value `given` for its argument, else its (non-empty)
    value in `env` ({NAME: raw}, store/config.study_environment), else its default; each checked (AppError naming
    the argument or the variable)."""
    values = {}
    for s in TABLE:
        if s.name == "RATING_CONFIG":
            continue
        raw, where = given.get(s.arg) if s.arg else None, s.key
        if raw is None:
            raw, where = env.get(s.name) or None, s.env
        values[s.name] = s.default if raw is None else s.parse(raw, where)
    return values


class _Given(argparse.Action):
    """Stores a setting's flag and notes it in `given`: only a flag that was given overrides the variable and the
    study file, though the parser's default (the setting's, shown in the help) fills every other."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.given = {**namespace.given, self.dest: values}


def add_flags(parser: argparse.ArgumentParser) -> None:
    """serve's flag of each setting that has one, with its help, its default and its variable; the settings given
    as flags are then the parsed namespace's `given` ({create_app argument: value})."""
    parser.set_defaults(given={})
    for s in TABLE:
        if s.flag:
            shown = "" if s.default is None else "default %(default)s; "
            parser.add_argument(
                s.flag,
                dest=s.arg,
                metavar=s.flag.removeprefix("--").replace("-", "_").upper(),
                action=_Given,
                type=s.flag_type(),
                choices=s.choices or None,
                default=s.default,
                help=f"{s.help.replace('%', '%%')} ({shown}${s.env})",
            )
