"""Rendering on other machines: a study's clips as tasks of a Dask distributed cluster (`make_stimuli --scheduler`).

Dask fits the work: each clip is one task of seconds that needs no other, its workers are plain Python processes
started with one command on any machine (`dask worker tcp://host:8786`), and its scheduler runs a task again on
another worker when the one running it is lost (a crash, a killed process, a machine gone), which the build's index
(build_index) then lists once. The workers see the study's files at the same paths as the machine that builds (a
shared file system): the motion files, the sound and the other person (written inside the stimulus folder), the
body model, and the stimulus folder they write the videos to. A worker with a GPU draws the mesh on it, as a local
process does (EGL). The render of a clip is the same function as a local process runs, with the same seed from the
clip's key, so a cluster's build is the same bytes as a local one.

Dask is optional (`pip install 'moglow-eval[cluster]'`); without --scheduler nothing of it is imported.
"""

from __future__ import annotations

import uuid
from pathlib import Path

from moglow_eval.core.cli import UserError

RETRIES = 2  # a clip whose task fails is tried again this often (a lost worker is rescheduled by Dask itself)


def render_on_cluster(jobs, scheduler: str, render, done) -> None:
    """Render every job with `render` (render_pool._render_job) as a task of the cluster at `scheduler`; `done(k)`
    as job k finishes. UserError, one line, when the cluster cannot be reached or a clip fails there."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise UserError("--scheduler needs Dask: pip install 'moglow-eval[cluster]'") from None
    _refuse_a_closed_port(scheduler)
    try:
        client = Client(scheduler, timeout="20s")
    except OSError as e:
        raise UserError(f"--scheduler {scheduler}: no Dask scheduler answers there ({e})") from None
    with client:
        from rendering.mesh import set_gl_environment

        client.run(set_gl_environment)  # each worker's GL set-up, as a local worker's initialiser does
        # pure=False: every job is run, even two of equal arguments; the key names the clip in the dashboard.
        futures = {
            client.submit(
                render, job, pure=False, retries=RETRIES, key=f"render-{_name(job)}-{uuid.uuid4().hex[:8]}"
            ): k
            for k, job in enumerate(jobs)
        }
        for fut in as_completed(futures):
            try:
                fut.result()
            except Exception as e:  # the worker's RenderError, or Dask's KilledWorker after repeated losses
                raise UserError(f"{jobs[futures[fut]][1]}: rendering on the cluster failed: {e}") from None
            done(futures[fut])


def _refuse_a_closed_port(scheduler: str) -> None:
    """UserError at once when nothing listens at a tcp:// scheduler's port. Dask's Client tries a refused address
    again until its timeout, which suits a scheduler still starting on a slow network; a machine that answers
    "refused" now has no scheduler there, and the organiser should hear so in a moment, not in twenty seconds.
    Other schemes, and an address that does not answer at all, are left to Dask's own timeout."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(scheduler)
    try:
        host, port = parts.hostname, parts.port
    except ValueError:  # a port that is not a number: Dask names the fault
        return
    if parts.scheme != "tcp" or not host or not port:
        return
    try:
        socket.create_connection((host, port), timeout=5).close()
    except ConnectionRefusedError:
        raise UserError(
            f"--scheduler {scheduler}: no Dask scheduler answers there (the connection was refused)"
        ) from None
    except OSError:
        return


def _name(job) -> str:
    return Path(job[1]).stem
