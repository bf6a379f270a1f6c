"""Rendering many clips at once: one process per worker, each rendering whole clips with one encoder thread.

The workers are spawned, not forked: the parent has loaded torch (sampling, training), whose thread pools make
forked children hang. A spawned worker imports only this module to find `_render_job`, so this module imports
rendering and nothing that loads torch; keep it so (seconds and hundreds of MB per worker otherwise;
tests/test_stimuli.py checks the workers' imports).
"""

import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context

from tqdm import tqdm

from rendering.render import render_clip


def _render_job(job):
    motion, video, sheet, size, preset = job
    return render_clip(motion, video, size=size, sheet=sheet, preset=preset, threads=1)


def render_all(jobs, workers, progress=True):
    """Render (motion, video, sheet, size, preset) jobs on `workers` processes, with a progress bar."""
    with tqdm(total=len(jobs), desc="render", unit="clip", file=sys.stderr, disable=not progress) as bar:
        if workers <= 1:
            for job in jobs:
                _render_job(job)
                bar.update()
            return
        pool = ProcessPoolExecutor(workers, mp_context=get_context("spawn"))
        try:
            for fut in as_completed([pool.submit(_render_job, job) for job in jobs]):
                fut.result()  # a worker's RenderError is raised here
                bar.update()
        finally:
            pool.shutdown(cancel_futures=True)
