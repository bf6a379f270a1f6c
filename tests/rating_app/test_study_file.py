"""The study file (issue 33, item 1): `serve --config study.toml` / gunicorn RATING_CONFIG give the app the same
settings as the environment variables, environment variables override the file, and a bad file is one line."""

import os
import subprocess
import sys

import pytest
from helpers.fake_stimuli import write_fake_stimuli
from helpers.paths import ROOT

from rating_app import SETTINGS, AppError, create_app
from rating_app.store.config import known_keys
from rating_app.store.db import app_engine

STUDY = {  # every key a study file may hold, with a value other than its default
    "rating_manifest": "stimuli/manifest.csv",
    "database_url": "sqlite:///db/ratings.sqlite",
    "study_design": "pairwise",
    "study_question": "Which one moves like a person?",
    "vote_reasons": "Jerky=Jerky motion,Feet=Feet slide",
    "reason_text": 120,
    "pairing": "active",
    "pairing_random": 0.3,
    "pairing_indifference": 40.0,
    "stop_when": "settled",
    "stop_level": 0.9,
    "stop_width": 80.0,
    "stop_max_votes": 5000,
    "completion_code": "C0DE42",
    "completion_url": "https://app.prolific.com/submissions/complete?cc={code}",
    "ratings_per_clip": 7,
    "clips_per_rater": 5,
    "catch_per_rater": 2,
    "slot_timeout": 900.5,
    "min_view": 0.25,
    "sessions_per_client": 3,
    "proxy_count": 1,
    "db_pool_size": 4,
    "cookie_secure": True,
    "video_accel": "nginx",
    "upload_root": "uploads",
    "video_cache_mb": 64,
}


def toml(values):
    def v(x):
        return ("true" if x else "false") if isinstance(x, bool) else repr(x) if not isinstance(x, str) else f'"{x}"'

    return "".join(f"{k} = {v(x)}\n" for k, x in values.items())


@pytest.fixture
def study_dir(tmp_path, monkeypatch):
    """A study folder: study.toml beside a copy of the stimuli; no setting in the environment but the token."""
    for s in SETTINGS.values():
        monkeypatch.delenv(s.env, raising=False)
    monkeypatch.setenv("RATING_ADMIN_TOKEN", "study-file-token")
    write_fake_stimuli(tmp_path / "stimuli", catch_nat=True)  # pairwise: each catch item has its NAT clip
    (tmp_path / "db").mkdir()
    (tmp_path / "study.toml").write_text(toml(STUDY))
    return tmp_path


def made(**kw):
    app = create_app(**kw)
    app_engine(app).dispose()
    return app


def test_every_settable_key_is_in_the_test():
    assert set(STUDY) == set(known_keys(SETTINGS))


def test_the_file_and_the_environment_give_the_same_app(study_dir, monkeypatch):
    from_file = made(config=study_dir / "study.toml")
    for key, value in STUDY.items():
        value = {
            "cookie_secure": "1",
            "rating_manifest": study_dir / "stimuli/manifest.csv",
            "upload_root": study_dir / "uploads",  # relative to the file, as the manifest is
        }.get(key, value)
        value = f"sqlite:///{study_dir}/db/ratings.sqlite" if key == "database_url" else value
        monkeypatch.setenv(SETTINGS[key.upper()].env, str(value))
    from_env = made()
    assert dict(from_file.config) == dict(from_env.config)
    assert str(app_engine(from_file).url) == str(app_engine(from_env).url) == f"sqlite:///{study_dir}/db/ratings.sqlite"
    assert from_file.config["RATINGS_PER_CLIP"] == 7 and from_file.config["STUDY_DESIGN"] == "pairwise"
    assert from_file.config["SESSION_COOKIE_SECURE"] is True and from_file.config["SLOT_TIMEOUT_S"] == 900.5


def test_the_environment_overrides_the_file_and_flags_override_both(study_dir, monkeypatch):
    monkeypatch.setenv("RATING_RATINGS_PER_CLIP", "11")
    monkeypatch.setenv("RATING_CONFIG", str(study_dir / "study.toml"))  # as gunicorn is given it
    app = made()
    assert (app.config["RATINGS_PER_CLIP"], app.config["CLIPS_PER_RATER"]) == (11, 5)
    assert made(ratings_per_clip=13).config["RATINGS_PER_CLIP"] == 13


def test_a_stale_variable_does_not_change_the_study(study_dir, monkeypatch):
    """A shell's variable under a setting's name from before the prefix is refused with one line naming the new
    variable: obeyed, it would change a study from outside its file; dropped, a deployment would lose its database."""
    config = study_dir / "study.toml"
    assert made(config=config).config["PAIRING"] == "active"
    for name, value in (("PAIRING", "balanced"), ("DATABASE_URL", f"sqlite:///{study_dir}/other.sqlite")):
        monkeypatch.setenv(name, value)
        with pytest.raises(AppError) as refused:
            made(config=config)
        assert (
            str(refused.value)
            == f"{name} is set, but the app reads RATING_{name} now: rename the variable (or unset it)"
        )
        monkeypatch.delenv(name)
    assert not (study_dir / "other.sqlite").exists()
    monkeypatch.setenv("RATING_PAIRING_RANDOMNESS", "0.9")  # under the prefix but no setting's: read by nothing
    assert made(config=config).config["PAIRING_RANDOM"] == 0.3


def test_gunicorns_entry_point_reads_rating_config(study_dir):
    env = {**os.environ, "RATING_CONFIG": str(study_dir / "study.toml")}
    code = (
        "import gc, rating_app.wsgi as w;"
        "print(w.app.config['RATINGS_PER_CLIP'], w.app.config['STUDY_DESIGN'], gc.get_freeze_count() > 0)"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    # the app built and frozen (cli.imports_done), so gunicorn's forked workers neither walk it nor write to it
    assert (r.returncode, r.stdout.strip()) == (0, "7 pairwise True"), r.stderr


BAD = [
    ("ratings_per_clip = 0\n", "ratings_per_clip: must be >= 1 and <= 1000000, got '0'"),
    ("ratings_per_clip = 2.5\n", "ratings_per_clip: expected an integer, got 2.5"),
    ('min_view = "half"\n', "min_view: expected a number, got 'half'"),
    ("min_view = nan\n", "min_view: must be finite, got 'nan'"),
    ("study_design = 3\n", "study_design: expected a string, got 3"),
    ("ratings_per_klip = 20\n", "ratings_per_klip: unknown key (known: rating_manifest, database_url"),
    ("RATINGS_PER_CLIP = 20\n", "RATINGS_PER_CLIP: unknown key"),
    ("[design]\nname = 1\n", "design: unknown key"),
    ('admin_token = "s3cret"\n', "admin_token: a secret stays out of the study file; set RATING_ADMIN_TOKEN in the"),
    ('secret_key = "k"\n', "secret_key: a secret stays out of the study file; set RATING_SECRET_KEY"),
    ('database_url = "postgresql://u:pw@127.0.0.1/x"\n', "database_url: holds a password; a secret stays out"),
    ('database_url = "nonsense"\n', "database_url: not a database URL"),
    ("cookie_secure = 1\n", "cookie_secure: expected true or false, got 1"),
    ("ratings_per_clip = = 3\n", "not a TOML file: Invalid value (at line 2, column 20)"),
]


@pytest.mark.parametrize("text, message", BAD, ids=[m.split(":")[0] for _, m in BAD])
def test_a_bad_study_file_is_one_line_naming_the_key(study_dir, text, message, command_fails):
    """`serve --config` per bad file, in-process (a process each was the full tier's; the conftest's command_fails)."""
    bad = study_dir / "bad.toml"
    bad.write_text('rating_manifest = "stimuli/manifest.csv"\n' + text)
    assert command_fails("serve", "--config", bad, needle="").startswith(f"error: {bad}: {message}")


def test_a_missing_study_file_is_one_line(study_dir):
    with pytest.raises(Exception, match=r"nowhere\.toml: no such study file"):
        create_app(config=study_dir / "nowhere.toml")
