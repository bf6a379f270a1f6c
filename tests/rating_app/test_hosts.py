"""Several app hosts, one database (issue 33 items 4-5): two gunicorn processes on their own ports behind one
reverse proxy over HTTPS (Debian's nginx with a certificate made here, Caddy with its own CA), sharing one
PostgreSQL database (one started with gunicorn's --preload, one without), the proxy sending the videos' bytes
(VIDEO_ACCEL). A simulated crowd answers through the
proxy; one host is killed with SIGKILL a third of the way through, the proxy sends the rest to the other. Every
acknowledged answer is stored once, the running counts agree with the trials, the test units stay balanced, every
rater completes, and what the client receives of a video is blind (its bytes; no date, no redirect, no path)."""

import collections
import contextlib
import os
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest
import requests
from helpers.concurrent_raters import cover_mismatches
from helpers.fake_stimuli import write_fake_stimuli
from helpers.proxies import caddy_accel, nginx_accel, nginx_head, nginx_temp_paths
from helpers.servers import crowd_env, kill9, start_gunicorn, stop

from moglow_eval.core.ports import free_port
from rating_app.designs.acr import iter_rows
from rating_app.simulate import run_simulation
from rating_app.store.db import make_engine

pytestmark = pytest.mark.full  # the full tier: two hosts, proxies and PostgreSQL

NGINX = """{head}
http {{
  access_log off;
  {temp}
  upstream app {{ server 127.0.0.1:{a} max_fails=1 fail_timeout=30s; server 127.0.0.1:{b}; }}
  server {{
    listen 127.0.0.1:{port} ssl;
    ssl_certificate {tmp}/cert.pem;
    ssl_certificate_key {tmp}/key.pem;
    {accel}
    location / {{
      proxy_pass http://app;
      proxy_next_upstream error timeout http_502;
      proxy_set_header Host $http_host;
      proxy_set_header X-Forwarded-For $proxy_add_x_forwarded_for;
    }}
  }}
}}
"""
CADDY = """
{{
  admin off
}}
https://127.0.0.1:{port} {{
  tls internal
  reverse_proxy 127.0.0.1:{a} 127.0.0.1:{b} {{
    lb_policy round_robin
    lb_try_duration 5s
    fail_duration 30s
    {accel}
  }}
}}
"""


@contextlib.contextmanager
def proxy(kind, tmp_path, a, b, stimuli):
    """(the proxy's HTTPS URL, the CA bundle that trusts it) in front of app ports a and b."""
    exe = shutil.which(kind) or f"/usr/sbin/{kind}"
    if not os.path.exists(exe):
        pytest.fail(f"Debian's {kind} is needed (scripts/install-system-deps.sh installs it)")
    port = free_port()
    conf = tmp_path / f"{kind}.conf"
    text = NGINX if kind == "nginx" else CADDY
    accel = nginx_accel(stimuli) if kind == "nginx" else caddy_accel(stimuli)
    head, temp = nginx_head(tmp_path), nginx_temp_paths(tmp_path)
    conf.write_text(text.format(head=head, temp=temp, tmp=tmp_path, port=port, a=a, b=b, accel=accel))
    if kind == "nginx":  # a certificate for 127.0.0.1, made here; the crowd trusts it and nothing else
        subprocess.run(
            [
                "openssl",
                "req",
                "-x509",
                "-newkey",
                "rsa:2048",
                "-nodes",
                "-days",
                "1",
                "-subj",
                "/CN=127.0.0.1",
                "-addext",
                "subjectAltName=IP:127.0.0.1",
                "-keyout",
                str(tmp_path / "key.pem"),
                "-out",
                str(tmp_path / "cert.pem"),
            ],
            check=True,
            capture_output=True,
        )
    env = dict(os.environ, HOME=str(tmp_path), XDG_DATA_HOME=str(tmp_path / "data"))
    cmd = [exe, "-p", str(tmp_path), "-c", str(conf)] if kind == "nginx" else [exe, "run", "--config", str(conf)]
    cmd += [] if kind == "nginx" else ["--adapter", "caddyfile"]
    with open(tmp_path / f"{kind}.log", "w") as log:
        p = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    url = f"https://127.0.0.1:{port}"
    ca = tmp_path / ("cert.pem" if kind == "nginx" else "data/caddy/pki/authorities/local/root.crt")
    try:
        deadline = time.monotonic() + 120  # a deadline, not a wait: Caddy makes its local CA first
        while True:
            if p.poll() is not None:
                raise AssertionError(f"{kind} exited with {p.returncode}")
            with contextlib.suppress(requests.RequestException, OSError):  # OSError: Caddy's CA not written yet
                if requests.get(url + "/healthz", timeout=1, verify=str(ca)).ok:
                    break
            if time.monotonic() > deadline:
                raise AssertionError(f"{kind} did not come up (see {kind}.log)")
            time.sleep(0.1)
        yield url, str(ca)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGTERM)
        p.wait(15)


@pytest.mark.parametrize("kind", ["nginx", "caddy"])
def test_two_hosts_one_database_and_a_kill(kind, tmp_path, pg_database, monkeypatch):
    raters = 40
    db = pg_database.replace("postgresql://", "postgresql+psycopg://", 1)
    stimuli = write_fake_stimuli(tmp_path / "stimuli", n_items=10, n_catch=2)
    env = crowd_env(stimuli, db, "hosts-token", PROXY_COUNT="1", VIDEO_ACCEL=kind)
    a, b = free_port(), free_port()
    log = open(tmp_path / "gunicorn.log", "w")
    # one host as docs/hosting.md starts it (--preload), the other with every worker building its own app
    hosts = [start_gunicorn(a, env, log), start_gunicorn(b, env, log, preload=False)]
    acks, summary = [0], {}
    try:
        with proxy(kind, tmp_path, a, b, stimuli.parent) as (url, ca):
            monkeypatch.setenv("REQUESTS_CA_BUNDLE", ca)  # the crowd trusts the proxy's certificate, nothing else
            blind_videos(url, ca, stimuli)
            sim = threading.Thread(
                target=lambda: summary.update(
                    run_simulation(
                        url,
                        raters,
                        seed=5,
                        careless=0.1,
                        manifest=stimuli,
                        concurrency=raters,
                        timeout_s=150,
                        progress=False,
                        on_ack=lambda rec: acks.__setitem__(0, acks[0] + 1),
                    )
                )
            )
            sim.start()
            while acks[0] < raters and sim.is_alive():  # a third of the way (about 3 answers per rater)
                time.sleep(0.01)
            acked_before = acks[0]
            kill9(hosts[0])
            sim.join(180)
            assert not sim.is_alive(), "the crowd did not finish"
    finally:
        stop(hosts)
        log.close()
    assert 0 < acked_before < summary["n_ratings"]
    assert summary["errors"] == [], summary["errors"][:3]
    assert summary["n_raters_completed"] == raters
    key = ("rater_id", "clip_id", "rating")
    acked = collections.Counter(tuple(r[k] for k in key) for r in summary["ratings"])
    engine = make_engine(db)
    try:
        from sqlalchemy.orm import Session

        with Session(engine) as s:
            rows = list(iter_rows(s))
        assert cover_mismatches(engine) == {}
    finally:
        engine.dispose()
    stored = collections.Counter(tuple(r[k] for k in key) for r in rows)
    assert max(stored.values()) == 1 and stored == acked  # each acknowledged answer committed once, none lost
    per_clip = collections.Counter(r["clip_id"] for r in rows if r["role"] == "test")
    assert max(per_clip.values()) - min(per_clip.values()) <= 3  # balance across the hosts


def blind_videos(url, ca, stimuli):
    """What a client receives of two sessions' first videos through the proxy: the files' bytes and sizes (one size
    for a whole stimulus set is make_stimuli's, rendering.blinding), and no date, ETag, redirect header or path
    naming a clip."""
    import csv

    ids = [r["clip_id"] for r in csv.DictReader(open(stimuli))]
    for _ in range(2):
        http = requests.Session()
        http.verify = ca
        token = http.post(url + "/api/sessions", json={}).json()["session"]
        trial = http.get(f"{url}/api/sessions/{token}/next").json()["trial"]
        r = http.get(url + trial["video_url"])
        video = Path(stimuli).parent / "videos" / f"{trial['clip_id']}.mp4"
        assert r.status_code == 200 and r.content == video.read_bytes()
        assert not {k.lower() for k in r.headers} & {"x-accel-redirect", "last-modified", "etag"}, r.headers
        assert not any(cid in v for cid in ids for v in r.headers.values())
        assert int(r.headers["Content-Length"]) == video.stat().st_size  # the file's size, nothing added
