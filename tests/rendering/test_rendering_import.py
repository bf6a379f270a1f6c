"""Library code holds no process-global state (CONTRIBUTING, issue 63): importing rendering starts no thread,
registers no fork hook and writes no environment variable, and making a GL context writes none either; the
commands and the render workers' initialiser set what the drawing wants (rendering.mesh.GL_ENVIRONMENT)."""

import json
import os
import subprocess
import sys

from helpers.paths import ROOT

# Run in a fresh interpreter: pytest's own process has imported rendering long before, and started threads.
# The spy records which module registers each fork hook, so the standard library's own (logging, random) pass.
PROBE = """
import importlib, json, os, pkgutil, sys, threading
hooks, real = [], os.register_at_fork
def spy(**callbacks):
    hooks.append(sys._getframe(1).f_globals.get("__name__", "?"))
    real(**callbacks)
os.register_at_fork = spy
before = dict(os.environ)
import rendering
for module in pkgutil.iter_modules(rendering.__path__, "rendering."):
    importlib.import_module(module.name)
if sys.argv[1:] == ["gl"]:
    from rendering.mesh import gl_context
    gl_context()
changed = sorted(k for k in {*before, *os.environ} if before.get(k) != os.environ.get(k))
ours = [h for h in hooks if h.split(".")[0] == "rendering"]
print(json.dumps(dict(hooks=ours, threads=threading.active_count(), changed=changed)))
"""


def probe(*args):
    env = {k: v for k, v in os.environ.items() if k not in ("LP_NUM_THREADS",)}
    env["PYTHONPATH"] = str(ROOT)
    out = subprocess.run(
        [sys.executable, "-c", PROBE, *args], capture_output=True, text=True, env=env, cwd=ROOT, timeout=120
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.splitlines()[-1])


def test_importing_every_rendering_module_starts_nothing():
    assert probe() == dict(hooks=[], threads=1, changed=[])


def test_a_gl_context_leaves_the_environment_as_it_found_it():
    assert probe("gl")["changed"] == []
