"""Videos through the proxy (issue 33 item 4): with VIDEO_ACCEL the app maps a trial's URL to its clip and answers
with an internal redirect, and the reverse proxy (Debian's nginx, or Caddy) sends the bytes. Checked on what the
client receives: the file's exact bytes and ranges, no redirect header, no date, no path naming a clip; and the
viewing rule of issue 37 still flags a 1-byte fetch. No video is read into a worker's memory."""

import contextlib
import csv
import io
import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest
import requests
from helpers.fake_stimuli import write_fake_stimuli
from helpers.flags import video_flags
from helpers.proxies import caddy_accel, nginx_accel, nginx_head, nginx_temp_paths
from helpers.servers import start_gunicorn, wait_for

from moglow_eval.core.ports import free_port

pytestmark = pytest.mark.full  # the full tier: real proxies (nginx, caddy)

NGINX_ACCEL = """{head}
http {{
  access_log off;
  {temp}
  server {{
    listen 127.0.0.1:{port};
    {accel}
    location / {{
      proxy_pass http://127.0.0.1:{upstream};
      proxy_set_header Host $http_host;
      proxy_set_header X-Forwarded-For $proxy_add_x_forwarded_for;
    }}
  }}
}}
"""
CADDY_ACCEL = """
{{
  admin off
  auto_https off
}}
http://127.0.0.1:{port} {{
  reverse_proxy 127.0.0.1:{upstream} {{
    {accel}
  }}
}}
"""


@contextlib.contextmanager
def behind(proxy, tmp_path, stimuli):
    """(proxy URL, app URL) of gunicorn with VIDEO_ACCEL=proxy behind that proxy, on SQLite."""
    exe = shutil.which(proxy) or f"/usr/sbin/{proxy}"
    if not os.path.exists(exe):
        pytest.fail(f"Debian's {proxy} is needed (scripts/install-system-deps.sh installs it)")
    app_port, port = free_port(), free_port()
    env = dict(
        os.environ,
        RATING_MANIFEST=str(stimuli),
        RATING_DATABASE_URL=f"sqlite:///{tmp_path / 'r.sqlite'}",
        RATING_ADMIN_TOKEN="accel-token",
        RATING_VIDEO_ACCEL=proxy,
        RATING_PROXY_COUNT="1",
        RATING_MIN_VIEW="0",
        RATING_SESSIONS_PER_CLIENT="0",
    )
    conf = tmp_path / f"{proxy}.conf"
    text = NGINX_ACCEL if proxy == "nginx" else CADDY_ACCEL
    folder = Path(stimuli).parent
    accel = nginx_accel(folder) if proxy == "nginx" else caddy_accel(folder)
    head, temp = nginx_head(tmp_path), nginx_temp_paths(tmp_path)
    conf.write_text(text.format(head=head, temp=temp, port=port, upstream=app_port, accel=accel))
    cmd = [exe, "-p", str(tmp_path), "-c", str(conf)] if proxy == "nginx" else [exe, "run", "--config", str(conf)]
    if proxy == "caddy":
        cmd += ["--adapter", "caddyfile"]
    procs = []
    with open(tmp_path / "log", "w") as log:
        try:
            procs.append(start_gunicorn(app_port, env, log, workers=2, threads=4))
            procs.append(
                subprocess.Popen(
                    cmd,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                    env=dict(os.environ, HOME=str(tmp_path), XDG_DATA_HOME=str(tmp_path)),
                )
            )
            wait_for(f"http://127.0.0.1:{port}/healthz", procs[-1], proxy)
            yield f"http://127.0.0.1:{port}", f"http://127.0.0.1:{app_port}"
        finally:
            for p in reversed(procs):
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.pid, signal.SIGTERM)
                p.wait(15)


@pytest.mark.parametrize("proxy", ["nginx", "caddy"])
def test_the_proxy_sends_the_bytes_blind(proxy, tmp_path):
    stimuli = write_fake_stimuli(tmp_path / "stimuli", n_items=2, n_catch=1, n_training=0, n_frames=40)
    files = {r["clip_id"]: (stimuli.parent / r["video"]).read_bytes() for r in csv.DictReader(open(stimuli))}
    with behind(proxy, tmp_path, stimuli) as (url, app_url):
        http = requests.Session()
        token = http.post(url + "/api/sessions", json={}).json()["session"]
        trial = http.get(f"{url}/api/sessions/{token}/next").json()["trial"]
        video = url + trial["video_url"]
        r = http.get(video)
        assert r.status_code == 200 and r.content == files[trial["clip_id"]]
        leaked = {k.lower() for k in r.headers} & {"x-accel-redirect", "last-modified", "etag", "content-location"}
        assert not leaked, r.headers
        assert not any(cid in v for cid in files for v in r.headers.values())  # no header names a clip
        part = http.get(video, headers={"Range": "bytes=10-109"})
        assert part.status_code == 206 and part.content == files[trial["clip_id"]][10:110]
        direct = requests.get(app_url + trial["video_url"])  # the app alone sends no bytes, only the redirect
        assert direct.content == b"" and direct.headers["X-Accel-Redirect"].startswith("/_stimuli/videos/")
        assert (
            http.post(
                f"{url}/api/sessions/{token}/ratings", json={"trial_id": trial["trial_id"], "rating": 4}
            ).status_code
            == 201
        )

        # A 1-byte fetch through the proxy is still only one byte: the answer is flagged (issue 37 item 3).
        token = http.post(url + "/api/sessions", json={}).json()["session"]
        trial = http.get(f"{url}/api/sessions/{token}/next").json()["trial"]
        assert http.get(url + trial["video_url"], headers={"Range": "bytes=0-0"}).status_code == 206
        http.post(f"{url}/api/sessions/{token}/ratings", json={"trial_id": trial["trial_id"], "rating": 2})
        export = http.get(url + "/admin/export.csv", headers={"Authorization": "Bearer accel-token"}).text
    flags = {row["rating"]: video_flags(row["flags"]) for row in csv.DictReader(io.StringIO(export))}
    assert flags["4"] == "" and "partial_video" in flags["2"]


def test_no_video_in_a_workers_memory(tmp_path, monkeypatch):
    from rating_app import create_app

    stimuli = write_fake_stimuli(tmp_path / "stimuli", n_items=2, n_catch=1)
    monkeypatch.setenv("RATING_VIDEO_ACCEL", "nginx")
    app = create_app(manifest=stimuli, db_url=f"sqlite:///{tmp_path / 'r.sqlite'}", admin_token="t")
    assert app.extensions["rating_app"]["videos"].videos == {}  # nothing read at start-up
    monkeypatch.setenv("RATING_VIDEO_ACCEL", "squid")
    with pytest.raises(Exception, match="RATING_VIDEO_ACCEL: 'squid' must be one of off, nginx, caddy"):
        create_app(manifest=stimuli, db_url=f"sqlite:///{tmp_path / 'r2.sqlite'}", admin_token="t")


# Range headers that are not one satisfiable byte range (issue 55, failure 10): Caddy and nginx would send 1 byte, a
# multipart body or a 416 for them; the app answers 416 itself, before any proxy sends a byte, and records nothing.
NOT_ONE_RANGE = (
    "bytes=0-0,",
    "bytes=,0-0",
    "bytes=+0-0",
    "bytes=0-0,0-0",
    "bytes=0-0;",
    "bytes=0-0,5-9",
    "bytes=99999999-",
    "bytes=5-1",
    "items=0-9",
    "bytes=",
    "",
)


@pytest.mark.parametrize("proxy", ["nginx", "caddy"])
def test_a_range_that_is_not_one_satisfiable_range_is_refused_and_records_nothing(proxy, tmp_path):
    stimuli = write_fake_stimuli(tmp_path / "stimuli", n_items=2, n_catch=1, n_training=0, n_frames=40)
    with behind(proxy, tmp_path, stimuli) as (url, _):
        http = requests.Session()
        token = http.post(url + "/api/sessions", json={}).json()["session"]
        trial = http.get(f"{url}/api/sessions/{token}/next").json()["trial"]
        for header in NOT_ONE_RANGE:
            r = http.get(url + trial["video_url"], headers={"Range": header})
            assert r.status_code == 416 and len(r.content) < 200, (header, r.status_code, len(r.content))
            assert r.headers["Content-Range"].startswith("bytes */"), header
        answer = {"trial_id": trial["trial_id"], "rating": 3}
        assert http.post(f"{url}/api/sessions/{token}/ratings", json=answer).status_code == 201
        admin = {"Authorization": "Bearer accel-token"}
        export = http.get(url + "/admin/export.csv", headers=admin).text
        sent = http.get(url + "/admin/progress.json", headers=admin).json()["raters"][0]["bytes_sent"]
    (row,) = csv.DictReader(io.StringIO(export))
    assert video_flags(row["flags"]) == "no_video" and sent == 0
