"""The study file and the environment: the app's settings in one TOML file (`serve --config study.toml`, gunicorn
`RATING_CONFIG`), overridden by the settings' environment variables.

The file's keys are the settings' names in lower case (`ratings_per_clip = 20` is `RATING_RATINGS_PER_CLIP=20`,
`rating_manifest` is `RATING_MANIFEST`), and an environment variable that is set overrides its key. Of the
environment the app reads only the variables of the settings table, each under the prefix `RATING_`; a variable
named as before the prefix (`DATABASE_URL`) stops the start with one line naming its new name. Secrets stay out of
the file: the admin token and the cookie key are given in the environment, the database password in `PGPASSWORD`
or `~/.pgpass` (libpq reads both), so the file can be kept with the study and shared. Relative paths in the file
(`rating_manifest`, `upload_root`, an SQLite `database_url`) are relative to the file.

    rating_manifest = "stimuli/manifest.csv"
    database_url = "postgresql://rater@127.0.0.1:5432/study"
    study_design = "pairwise"
    ratings_per_clip = 20
"""

from __future__ import annotations

import os
from pathlib import Path

from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError

from moglow_eval.core import user_files

from .manifest import AppError
from .settings import SETTINGS

# The study file's keys, by kind, as the settings' names (settings.TABLE holds them all).
TEXT_KEYS = tuple(s.name for s in SETTINGS.values() if s.kind is str and s.in_file and not s.secret)
FLAG_KEYS = tuple(s.name for s in SETTINGS.values() if s.kind is bool)
# Never in the file: the app's secrets, and the database password libpq would read (PGPASSWORD or ~/.pgpass).
SECRETS = (*(s.name for s in SETTINGS.values() if s.secret), "PGPASSWORD", "DATABASE_PASSWORD")
MAX_BYTES = 1 << 20  # a study file is a few dozen keys


def known_keys(settings=SETTINGS) -> list[str]:
    """Every key a study file may hold, lower case, in the order of the settings in docs/hosting.md."""
    return [s.key for s in settings.values() if s.in_file and not s.secret]


def load_study_file(path, settings=SETTINGS) -> dict[str, str]:
    """{ENVIRONMENT_NAME: value as the environment would hold it} from the study file at `path`; AppError, one line
    naming the file and the key, for anything wrong in it. `settings`: rating_app.SETTINGS (the settings table)."""
    path = Path(path)
    table = user_files.read_toml(path, MAX_BYTES, AppError, "study file")
    values = {}
    for key, value in table.items():
        name = key.upper()
        where = f"{path}: {key}"
        if name in SECRETS:
            variable = settings[name].env if name in settings else name
            raise AppError(f"{where}: a secret stays out of the study file; set {variable} in the environment instead")
        if key != key.lower() or key not in known_keys(settings):
            raise AppError(f"{where}: unknown key (known: {', '.join(known_keys(settings))})")
        values[name] = _as_environment(where, value, settings[name])
    return _resolve_paths(path, values)


def _as_environment(where, value, setting) -> str:
    """A study file's value as its environment variable would hold it, once it is of the setting's type and
    within its bounds."""
    if setting.kind is bool:
        if not isinstance(value, bool):
            raise AppError(f"{where}: expected true or false, got {value!r}")
        return "1" if value else "0"
    if setting.kind in (int, float):
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not number or (setting.kind is int and isinstance(value, float)):
            raise AppError(f"{where}: expected {'an integer' if setting.kind is int else 'a number'}, got {value!r}")
        setting.parse(str(value), where)
        return str(value)
    if not isinstance(value, str):
        raise AppError(f"{where}: expected a string, got {value!r}")
    return value


def _resolve_paths(path: Path, values: dict) -> dict:
    home = path.resolve().parent
    for name in ("RATING_MANIFEST", "UPLOAD_ROOT"):
        if values.get(name):
            values[name] = str(home / Path(values[name]).expanduser())
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
                "PGPASSWORD or ~/.pgpass (or the whole URL in RATING_DATABASE_URL)"
            )
        if url.get_backend_name() == "sqlite" and url.database and url.database != ":memory:":
            values["DATABASE_URL"] = url.set(database=str(home / url.database)).render_as_string(hide_password=False)
    return values


def stale_variables(settings=SETTINGS, environ=None) -> None:
    """AppError, one line, when a variable is set under a setting's name from before the RATING_ prefix
    (`DATABASE_URL`): ignored, it would drop a deployment's database or token without a word, so it stops the
    start instead, naming the new variable."""
    environ = os.environ if environ is None else environ
    stale = [(s.name, s.env) for s in settings.values() if s.env != s.name and environ.get(s.name)]
    if not stale:
        return
    old, new = (", ".join(names) for names in zip(*stale))
    if len(stale) == 1:
        raise AppError(f"{old} is set, but the app reads {new} now: rename the variable (or unset it)")
    raise AppError(f"{old} are set, but the app reads {new} now: rename the variables (or unset them)")


def environment(settings=SETTINGS, environ=None) -> dict[str, str]:
    """{NAME: value} of the settings whose variable (NAME under the RATING_ prefix) is set, and nothing else of the
    environment (an empty variable counts as unset, as everywhere in the app); AppError, one line, for a variable
    named as before the prefix (stale_variables)."""
    environ = os.environ if environ is None else environ
    stale_variables(settings, environ)
    return {s.name: environ[s.env] for s in settings.values() if environ.get(s.env)}


def study_environment(config_path=None, settings=SETTINGS) -> dict[str, str]:
    """{NAME: value} of the settings as the app reads them: the study file's (`config_path`, else RATING_CONFIG's,
    if any), overridden by the settings' variables that are set (environment)."""
    env = environment(settings)
    config_path = config_path or env.get("RATING_CONFIG")
    values = load_study_file(config_path, settings) if config_path else {}
    return {**values, **env}
