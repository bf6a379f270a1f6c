"""The study file: the app's settings in one TOML file (`serve --config study.toml`, gunicorn `RATING_CONFIG`).

Its keys are the environment variables of the settings in lower case (`ratings_per_clip = 20` is
`RATINGS_PER_CLIP=20`), and an environment variable that is set overrides its key. Secrets stay out of the file:
the admin token and the cookie key are given in the environment, the database password in `PGPASSWORD` or
`~/.pgpass` (libpq reads both), so the file can be kept with the study and shared. Relative paths in the file
(`rating_manifest`, an SQLite `database_url`) are relative to the file.

    rating_manifest = "stimuli/manifest.csv"
    database_url = "postgresql://rater@127.0.0.1:5432/study"
    study_design = "pairwise"
    ratings_per_clip = 20
"""

from __future__ import annotations

import argparse
import os
import tomllib
from pathlib import Path

from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError

from moglow_eval.core.cli import number

from .manifest import AppError

# The numbers' bounds are rating_app.SETTINGS'; these are the other keys, as the environment variables they stand for.
TEXT_KEYS = (
    "RATING_MANIFEST",
    "DATABASE_URL",
    "STUDY_DESIGN",
    "STUDY_QUESTION",
    "COMPLETION_CODE",
    "COMPLETION_URL",
    "VIDEO_ACCEL",
)
FLAG_KEYS = ("COOKIE_SECURE",)
EXTRA_NUMBERS = {"DB_POOL_SIZE": (int, 10, 1, 1000, False)}
SECRETS = ("ADMIN_TOKEN", "SECRET_KEY", "PGPASSWORD", "DATABASE_PASSWORD")


def known_keys(settings) -> list[str]:
    """Every key a study file may hold, lower case, in the order of the settings in docs/hosting.md."""
    return [k.lower() for k in (*TEXT_KEYS, *settings, *EXTRA_NUMBERS, *FLAG_KEYS)]


def load_study_file(path, settings) -> dict[str, str]:
    """{ENVIRONMENT_NAME: value as the environment would hold it} from the study file at `path`; AppError, one line
    naming the file and the key, for anything wrong in it. `settings`: rating_app.SETTINGS (the numbers' bounds)."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            table = tomllib.load(fh)
    except FileNotFoundError:
        raise AppError(f"{path}: no such study file") from None
    except IsADirectoryError:
        raise AppError(f"{path}: is a folder, not a study file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise AppError(f"{path}: not a TOML file: {e}") from None
    numbers = {**settings, **EXTRA_NUMBERS}
    values = {}
    for key, value in table.items():
        name = key.upper()
        where = f"{path}: {key}"
        if name in SECRETS:
            raise AppError(f"{where}: a secret stays out of the study file; set {name} in the environment instead")
        if key != key.lower() or name not in (*TEXT_KEYS, *numbers, *FLAG_KEYS):
            raise AppError(f"{where}: unknown key (known: {', '.join(known_keys(settings))})")
        if name in FLAG_KEYS:
            if not isinstance(value, bool):
                raise AppError(f"{where}: expected true or false, got {value!r}")
            values[name] = "1" if value else "0"
        elif name in numbers:
            values[name] = _number(where, value, numbers[name])
        elif not isinstance(value, str):
            raise AppError(f"{where}: expected a string, got {value!r}")
        else:
            values[name] = value
    return _resolve_paths(path, values)


def _number(where, value, bounds) -> str:
    kind, _default, lo, hi, lo_open = bounds
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind is int and isinstance(value, float)):
        raise AppError(f"{where}: expected {'an integer' if kind is int else 'a number'}, got {value!r}")
    try:
        number(kind, lo, hi, lo_open)(str(value))
    except argparse.ArgumentTypeError as e:
        raise AppError(f"{where}: {e}") from None
    return str(value)


def _resolve_paths(path: Path, values: dict) -> dict:
    home = path.resolve().parent
    if "RATING_MANIFEST" in values:
        values["RATING_MANIFEST"] = str(home / Path(values["RATING_MANIFEST"]).expanduser())
    if "DATABASE_URL" in values:
        try:
            url = make_url(values["DATABASE_URL"])
        except ArgumentError:
            raise AppError(
                f"{path}: database_url: not a database URL (sqlite:///FILE or postgresql://HOST/DB)"
            ) from None
        if url.password is not None:
            raise AppError(
                f"{path}: database_url: holds a password; a secret stays out of the study file: give it in "
                "PGPASSWORD or ~/.pgpass (or the whole URL in DATABASE_URL)"
            )
        if url.get_backend_name() == "sqlite" and url.database and url.database != ":memory:":
            values["DATABASE_URL"] = url.set(database=str(home / url.database)).render_as_string(hide_password=False)
    return values


def study_environment(config_path, settings) -> dict[str, str]:
    """The settings as the app reads them: the study file's (if any), overridden by the environment variables that
    are set (an empty variable counts as unset, as everywhere in the app)."""
    values = load_study_file(config_path, settings) if config_path else {}
    return {**values, **{k: v for k, v in os.environ.items() if v}}
