"""Behind a real reverse proxy (Debian's nginx) in front of gunicorn (issue 37, item 4): the docs' production
recipe trusts the proxy, so 50 raters from 50 addresses all get sessions and one client's wrong admin tokens do not
lock the admin out; a proxy the app does not trust (PROXY_COUNT 0) is noticed: one warning in the log, on the
dashboard and in /healthz, and no error."""

import contextlib
import http.client
import json
import os
import re
import shlex
import shutil
import signal
import subprocess

import pytest
import requests
from helpers.paths import ROOT
from helpers.servers import start_gunicorn, wait_for

from moglow_eval.core.ports import free_port

NGINX = shutil.which("nginx") or "/usr/sbin/nginx"
TOKEN = "proxy-admin-token"

NGINX_CONF = """
worker_processes 1;
daemon off;
pid {tmp}/nginx.pid;
error_log {tmp}/nginx-error.log;
events {{ worker_connections 512; }}
http {{
  access_log off;
  client_body_temp_path {tmp}/body; proxy_temp_path {tmp}/proxy; fastcgi_temp_path {tmp}/fastcgi;
  uwsgi_temp_path {tmp}/uwsgi; scgi_temp_path {tmp}/scgi;
  server {{
    listen 127.0.0.1:{port};
    location / {{
      proxy_pass http://127.0.0.1:{upstream};
      proxy_set_header Host $http_host;
      proxy_set_header X-Forwarded-For $proxy_add_x_forwarded_for;
      proxy_set_header X-Forwarded-Proto $scheme;
      proxy_set_header X-Forwarded-Host $http_host;
    }}
  }}
}}
"""


@contextlib.contextmanager
def gunicorn_behind_nginx(tmp_path, env, workers=2):
    """(the proxy's URL, the app's own URL, the gunicorn log path, /healthz before nginx started) for gunicorn
    behind nginx."""
    if not os.path.exists(NGINX):
        pytest.fail("Debian's nginx is needed (apt-get install nginx)")
    app_port, proxy_port = free_port(), free_port()
    log_path = tmp_path / "gunicorn.log"
    conf = tmp_path / "nginx.conf"
    conf.write_text(NGINX_CONF.format(tmp=tmp_path, port=proxy_port, upstream=app_port))
    procs = []
    with open(log_path, "w") as log:
        try:
            procs.append(start_gunicorn(app_port, env, log, workers=workers, threads=4))
            before = requests.get(f"http://127.0.0.1:{app_port}/healthz", timeout=10).json()
            procs.append(
                subprocess.Popen(
                    [NGINX, "-p", str(tmp_path), "-c", str(conf)],
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
            )
            wait_for(f"http://127.0.0.1:{proxy_port}/healthz", procs[-1], "nginx")
            yield f"http://127.0.0.1:{proxy_port}", f"http://127.0.0.1:{app_port}", log_path, before
        finally:
            for p in reversed(procs):
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.pid, signal.SIGTERM)
                p.wait(15)


def call(proxy_url, method, path, source, body=None, headers=None):
    """(status, JSON) of a request to the proxy from the loopback address `source` (127.0.0.0/8 is all ours)."""
    host, port = proxy_url.split("//")[1].split(":")
    conn = http.client.HTTPConnection(host, int(port), timeout=30, source_address=(source, 0))
    try:
        hdrs = dict(headers or {})
        if body is not None:
            hdrs["Content-Type"] = "application/json"
        conn.request(method, path, body=None if body is None else json.dumps(body), headers=hdrs)
        r = conn.getresponse()
        data = r.read()
        return r.status, data
    finally:
        conn.close()


def readme_recipe() -> dict[str, str]:
    """The settings the production recipe of docs/hosting.md (once the README's) exports (those not computed by
    the shell)."""
    text = (ROOT / "docs" / "hosting.md").read_text(encoding="utf-8")
    block = text[text.index("# production:") :]
    block = block[: block.index("```")]
    out = {}
    for line in block.splitlines():
        if line.startswith("export "):
            for word in shlex.split(line[len("export ") :]):
                key, _, value = word.partition("=")
                if "$" not in value:
                    out[key] = value
    return out


@pytest.mark.parametrize("app_db_url", ["postgres", "sqlite"], indirect=True)
def test_readme_recipe_behind_nginx_admits_50_raters_and_keeps_the_admin_in(app_stimuli, app_db_url, tmp_path):
    recipe = readme_recipe()
    assert recipe["RATING_CLIPS_PER_RATER"] == "30"  # the parser found the recipe
    env = {**os.environ, **recipe, "RATING_MANIFEST": str(app_stimuli), "RATING_DATABASE_URL": app_db_url}
    env["RATING_ADMIN_TOKEN"] = TOKEN
    env.pop("RATING_SESSIONS_PER_CLIENT", None)  # the default, 10 an hour
    with gunicorn_behind_nginx(tmp_path, env) as (proxy, _, log_path, _):
        statuses = [call(proxy, "POST", "/api/sessions", f"127.0.0.{2 + i}", {})[0] for i in range(50)]
        assert statuses == [201] * 50, statuses
        # one client guesses admin tokens until it is locked out; the admin, elsewhere, is not
        wrong = [call(proxy, "GET", "/admin/export.csv", "127.0.1.1", headers={"Authorization": "Bearer no"})[0]]
        wrong += [
            call(proxy, "GET", "/admin/export.csv", "127.0.1.1", headers={"Authorization": "Bearer no"})[0]
            for _ in range(10)
        ]
        assert wrong == [401] * 10 + [429], wrong
        status, body = call(
            proxy, "GET", "/admin/progress.json", "127.0.1.2", headers={"Authorization": f"Bearer {TOKEN}"}
        )
        assert status == 200 and len(json.loads(body)["raters"]) == 50
        assert json.loads(body)["warnings"] == []  # the proxy is trusted
    assert "Traceback" not in log_path.read_text()


@pytest.mark.parametrize("app_db_url", ["sqlite"], indirect=True)
def test_an_untrusted_proxy_is_one_warning_and_no_error(app_stimuli, app_db_url, tmp_path):
    env = dict(os.environ, RATING_MANIFEST=str(app_stimuli), RATING_DATABASE_URL=app_db_url, RATING_ADMIN_TOKEN=TOKEN)
    env.pop("RATING_PROXY_COUNT", None)
    with gunicorn_behind_nginx(tmp_path, env, workers=1) as (proxy, direct, log_path, before):
        assert before["warnings"] == []  # no proxy yet
        assert requests.post(direct + "/api/sessions", json={}, timeout=10).status_code == 201
        statuses = [call(proxy, "POST", "/api/sessions", f"127.0.0.{2 + i}", {})[0] for i in range(3)]
        assert statuses == [201] * 3  # noticed, and served as before
        health = requests.get(proxy + "/healthz", timeout=10)
        assert health.status_code == 200
        (warning,) = health.json()["warnings"]
        assert "RATING_PROXY_COUNT" in warning and "X-Forwarded-For" in warning
        assert requests.get(direct + "/healthz", timeout=10).json()["warnings"] == [warning]
        page = requests.get(proxy + "/admin", headers={"Authorization": f"Bearer {TOKEN}"}, timeout=10).text
        assert 'id="warnings"' in page and "RATING_PROXY_COUNT is 0" in page
    log = log_path.read_text()
    assert len(re.findall(r"warning: requests come through a reverse proxy", log)) == 1, log[-2000:]
    assert "Traceback" not in log and "ERROR" not in log


def test_only_a_local_peer_with_forwarded_for_is_taken_for_a_proxy(make_app):
    """A public peer that sends X-Forwarded-For is a client, not our proxy; a private one is a proxy; with
    PROXY_COUNT set, nothing is said."""
    app = make_app()
    c = app.test_client()
    fwd = {"X-Forwarded-For": "93.184.216.35"}
    assert c.get("/healthz", headers=fwd, environ_base={"REMOTE_ADDR": "93.184.216.34"}).json["warnings"] == []
    assert c.get("/healthz", environ_base={"REMOTE_ADDR": "10.1.2.3"}).json["warnings"] == []
    (w,) = c.get("/healthz", headers=fwd, environ_base={"REMOTE_ADDR": "10.1.2.3"}).json["warnings"]
    assert "from 10.1.2.3" in w
    os.environ["RATING_PROXY_COUNT"] = "1"
    try:
        trusted = make_app().test_client()
    finally:
        del os.environ["RATING_PROXY_COUNT"]
    assert trusted.get("/healthz", headers=fwd, environ_base={"REMOTE_ADDR": "127.0.0.1"}).json["warnings"] == []
