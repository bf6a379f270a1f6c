"""The container recipe in deploy/ (issue 33): the compose file's services, ports, volumes and health checks, the
Caddyfile (validated by Debian's caddy) and the study file the app container reads; with --run-slow, the image is
built with Debian's podman from a base made by debootstrap (no image registry is reachable here) and its app
serves /healthz without torch."""

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


@pytest.mark.slow
def test_image_builds_and_serves(tmp_path):
    """podman (runc, cgroupfs, no default ulimits: ../shared/notes/containers-here.md) builds deploy/Containerfile on
    a debootstrap base and runs the app on SQLite with a stimulus set mounted read-only."""
    import os
    import time

    import requests
    from helpers.fake_stimuli import free_port, write_fake_stimuli

    for tool in ("podman", "debootstrap", "runc"):
        if not shutil.which(tool):
            pytest.fail(f"{tool} is needed: apt-get install podman runc debootstrap")
    conf = tmp_path / "containers.conf"
    conf.write_text("[containers]\ndefault_ulimits = []\n")
    env = dict(os.environ, CONTAINERS_CONF=str(conf))
    pod = ["podman", "--runtime", "runc", "--cgroup-manager", "cgroupfs"]

    def run(*cmd, **kw):
        return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900, **kw)

    if run(*pod, "image", "exists", "local/debian:bookworm").returncode != 0:
        root = tmp_path / "rootfs"
        assert run("debootstrap", "--variant=minbase", "bookworm", str(root)).returncode == 0
        tar = subprocess.Popen(["tar", "-C", str(root), "-c", "."], stdout=subprocess.PIPE)
        assert run(*pod, "import", "-", "local/debian:bookworm", stdin=tar.stdout).returncode == 0
    ca = "/etc/ssl/certs/ca-certificates.crt"  # the host's CA bundle (a TLS-inspecting proxy's CA included)
    build = run(
        *pod,
        "build",
        "--network",
        "host",
        "-v",
        f"{ca}:/ca.crt:ro",
        "--build-arg",
        "PIP_CERT=/ca.crt",
        "-f",
        str(DEPLOY / "Containerfile"),
        "-t",
        "moglow-eval-app",
        str(DEPLOY.parent),
    )
    assert build.returncode == 0, build.stderr[-2000:]
    stimuli = write_fake_stimuli(tmp_path / "stimuli", n_items=2, n_catch=1)
    data = tmp_path / "data"
    data.mkdir(mode=0o777)
    data.chmod(0o777)
    port = free_port()
    name = f"mgapp{port}"
    started = run(
        *pod,
        "run",
        "-d",
        "--rm",
        "--name",
        name,
        "--network",
        "host",
        "-v",
        f"{stimuli.parent}:/srv/stimuli:ro",
        "-v",
        f"{data}:/data",
        "-e",
        "RATING_MANIFEST=/srv/stimuli/manifest.csv",
        "-e",
        "RATING_DATABASE_URL=sqlite:////data/r.sqlite",
        "-e",
        "RATING_ADMIN_TOKEN=x",
        "moglow-eval-app",
        "gunicorn",
        "-w",
        "1",
        "-b",
        f"127.0.0.1:{port}",
        "rating_app.wsgi:app",
    )
    assert started.returncode == 0, started.stderr[-2000:]
    try:
        for _ in range(100):
            try:
                r = requests.get(f"http://127.0.0.1:{port}/healthz", timeout=1)
                if r.ok:
                    break
            except requests.RequestException:
                time.sleep(0.3)
        assert r.json()["ok"]
        no_torch = run(*pod, "exec", name, "python3", "-c", "import torch")
        assert no_torch.returncode != 0 and "No module named 'torch'" in no_torch.stderr
    finally:
        run(*pod, "stop", name)
