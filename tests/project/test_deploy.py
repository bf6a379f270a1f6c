"""The container recipe in deploy/ (issue 33): the compose file's services, ports, volumes and health checks, the
Caddyfile (validated by Debian's caddy) and the study file the app container reads. Building the image itself takes
minutes and tools the suite's machine lacks (podman, runc, debootstrap): `python deploy/check_image.py` does it."""

import json
import re
import shutil
import subprocess

import pytest
import yaml
from helpers.paths import ROOT

from rating_app import SETTINGS
from rating_app.store.config import load_study_file

pytestmark = pytest.mark.full  # the full tier: containers and system services

DEPLOY = ROOT / "deploy"


@pytest.fixture(scope="module")
def compose():
    return yaml.safe_load((DEPLOY / "compose.yaml").read_text())


def test_compose_has_the_app_postgres_and_caddy(compose):
    services = compose["services"]
    assert set(services) == {"db", "app", "proxy"}
    db, app, proxy = services["db"], services["app"], services["proxy"]
    assert "ratings-db:/var/lib/postgresql/data" in db["volumes"] and "ratings-db" in compose["volumes"]
    assert "pg_isready" in db["healthcheck"]["test"]
    assert any(v.endswith(":/srv/stimuli:ro") for v in app["volumes"])  # the stimuli, read-only
    assert (
        "/healthz" in " ".join(app["healthcheck"]["test"]) and app["depends_on"]["db"]["condition"] == "service_healthy"
    )
    env = app["environment"]
    assert env["RATING_PROXY_COUNT"] == "1" and env["RATING_COOKIE_SECURE"] == "1"  # one trusted proxy, HTTPS only
    assert env["RATING_VIDEO_ACCEL"] == "caddy" and "../stimuli:/srv/stimuli:ro" in proxy["volumes"]  # Caddy's videos
    assert "RATING_ADMIN_TOKEN" in env and "password" not in env["RATING_DATABASE_URL"].lower()
    # Only the settings' variables (and libpq's password): a name the app does not read would be dropped unseen.
    assert set(env) - {s.env for s in SETTINGS.values()} == {"PGPASSWORD"}
    assert "app" not in {p.split(":")[0] for p in app.get("ports", [])}  # only the proxy is published
    assert {"80:80", "443:443"} <= set(proxy["ports"]) and "./Caddyfile:/etc/caddy/Caddyfile:ro" in proxy["volumes"]
    assert (DEPLOY / app["build"]["dockerfile"].removeprefix("deploy/")).is_file()


def test_containerfile_has_no_torch_and_a_health_check():
    text = (DEPLOY / "Containerfile").read_text()
    assert "torch" not in text.replace("without torch", "").replace("no torch", "")
    assert "HEALTHCHECK" in text and "rating_app.wsgi:app" in text and "USER rater" in text


def test_the_container_starts_gunicorn_as_the_hosting_page_does():
    """The image's gunicorn command is docs/hosting.md's production command, less the address it binds (all of the
    container's, where the page binds loopback behind its proxy)."""
    cmd = re.search(r"^CMD (\[.*?\])$", (DEPLOY / "Containerfile").read_text(), re.M | re.S).group(1)
    image = json.loads(cmd.replace("\\\n", ""))
    page = next(
        line.split()
        for line in (ROOT / "docs" / "hosting.md").read_text().splitlines()
        if line.startswith("gunicorn ") and "rating_app.wsgi:app" in line
    )
    bind = image.index("-b")
    assert image[bind + 1] == "0.0.0.0:8000" and page[page.index("-b") + 1] == "127.0.0.1:8000"
    assert image[:bind] + image[bind + 2 :] == page[: page.index("-b")] + page[page.index("-b") + 2 :]
    assert "--preload" in image  # one copy of the videos for all the workers


def test_caddyfile_is_valid():
    if not shutil.which("caddy"):
        pytest.fail("Debian's caddy is needed (scripts/install-system-deps.sh installs it)")
    r = subprocess.run(
        ["caddy", "validate", "--config", str(DEPLOY / "Caddyfile"), "--adapter", "caddyfile"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0 and "Valid configuration" in r.stdout + r.stderr, r.stderr[-500:]


def test_the_study_file_is_one_the_app_reads():
    values = load_study_file(DEPLOY / "study.toml", SETTINGS)
    assert values["RATINGS_PER_CLIP"] == "20" and values["CATCH_PER_RATER"] == "4"
