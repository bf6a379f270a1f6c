"""Build the app's container image from deploy/Containerfile and check that it serves, as an operator would.

    python deploy/check_image.py

podman (runc, cgroupfs, no default ulimits: ../shared/notes/containers-here.md) builds the image on a Debian base
made by debootstrap (no image registry is needed), then runs the app on SQLite with a small stimulus set mounted
read-only: /healthz must answer, and the image must hold no torch. Minutes of work and tools the test suite's
machine lacks, so it is a command of its own (tests/project/test_deploy.py checks the recipe's files). Exits 0 when
the image builds and serves; an AssertionError says which step failed.
"""

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

DEPLOY = Path(__file__).resolve().parent
sys.path.insert(0, str(DEPLOY.parent / "tests"))  # the tests' writer of a small stimulus set
sys.path.insert(0, str(DEPLOY.parent))
from helpers.fake_stimuli import write_fake_stimuli  # noqa: E402

from moglow_eval.core.ports import free_port  # noqa: E402


def check_image(tmp_path):
    """podman (runc, cgroupfs, no default ulimits: ../shared/notes/containers-here.md) builds deploy/Containerfile on
    a debootstrap base and runs the app on SQLite with a stimulus set mounted read-only."""
    import os
    import time

    import requests

    for tool in ("podman", "debootstrap", "runc"):
        if not shutil.which(tool):
            raise SystemExit(f"{tool} is needed: apt-get install podman runc debootstrap")
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


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        check_image(Path(tmp))
    print("the image builds, serves /healthz and holds no torch")
