"""Rendering many clips at once: one process per worker, each rendering whole clips with one encoder thread.

The workers are spawned, not forked: the parent has loaded torch (sampling, training), whose thread pools make
forked children hang. A spawned worker imports only this module to find `_render_job`, so this module imports
rendering and nothing that loads torch; keep it so (seconds and hundreds of MB per worker otherwise;
tests/generation/test_stimuli.py checks the workers' imports).
"""

import logging
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import fields
from multiprocessing import get_context

import numpy as np
from tqdm import tqdm

from rendering.audio import mux_audio
from rendering.blinding import check_one_size, odd_ones, same_mtime
from rendering.mesh import set_gl_environment
from rendering.render import RenderOptions, render_clip

log = logging.getLogger(__name__)
SETTINGS = frozenset(f.name for f in fields(RenderOptions))  # a job's keywords that are RenderOptions'
RETRIES = 3  # times a video that came out a size off is encoded again (each time with a fresh random rate dither)


def _render_job(job):
    """Render one clip; its keywords: RenderOptions' fields (camera, style, hide, thin, ...), render_clip's own
    (partner, captions, and a MeshSpec for mesh and partner_mesh), and `audio`: (normalised samples .npy, start s,
    duration s) to mux into the video."""
    motion, video, sheet, size, preset, *keywords = job
    keywords = dict(keywords[0]) if keywords else {}
    audio = keywords.pop("audio", None)
    settings = {k: keywords.pop(k) for k in SETTINGS & set(keywords)}
    options = RenderOptions(size=size, preset=preset, threads=1, **settings)
    for key in ("mesh", "partner_mesh"):  # a mesh style's spec: the worker skins the file itself (torch, smplx)
        if keywords.get(key) is not None:
            from .mesh_track import track

            keywords[key] = track(keywords[key])
    n = render_clip(motion, video, options, sheet=sheet, **keywords)
    if audio is not None:
        samples, start, duration = audio
        mux_audio(video, np.load(samples), start, duration)
    return n


def render_all(jobs, workers, progress=True):
    """Render (motion, video, sheet, size, preset[, keywords: _render_job's]) jobs on `workers` processes, with a
    progress bar."""
    with tqdm(total=len(jobs), desc="render", unit="clip", file=sys.stderr, disable=not progress) as bar:
        if workers <= 1:
            for job in jobs:
                _render_job(job)
                bar.update()
            return
        # A worker is a process of its own: its initialiser sets what its GL drawing wants, as a command's main does.
        pool = ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=set_gl_environment)
        try:
            for fut in as_completed([pool.submit(_render_job, job) for job in jobs]):
                fut.result()  # a worker's RenderError is raised here
                bar.update()
        finally:
            pool.shutdown(cancel_futures=True)


def render_stimuli(jobs, workers, progress=True, groups=None):
    """Render every job of a stimulus set, check that the videos are one size (rendering.blinding: by
    construction, every frame one size) and give every file one time. `groups`: a key per job whose videos must
    agree (a study of your own motion: the item, whose clips share a length and a sound); None: all of them."""
    workers = min(workers, len(jobs))
    size = jobs[0][3] if jobs else 0
    log.info(f"render: {len(jobs)} clips at {size}x{size} on {workers} processes")
    render_all(jobs, workers, progress=progress)
    by_group = {}
    for k, job in enumerate(jobs):
        by_group.setdefault(None if groups is None else groups[k], []).append(k)
    for _ in range(RETRIES):
        odd = [ks[i] for ks in by_group.values() if len(ks) > 2 for i in odd_ones([jobs[k][1] for k in ks])]
        if not odd:
            break
        # x264 can overshoot one frame's budget by a byte on a frame dense with edges (captions at a small size):
        # a fresh random share of the rate per frame puts the frames elsewhere, and the video comes out one size.
        log.info(f"render: {len(odd)} video(s) came out a frame size off the others of their item; encoding again")
        render_all([jobs[k] for k in odd], min(workers, len(odd)), progress=False)
    by_group = {g: [jobs[k][1] for k in ks] for g, ks in by_group.items()}
    sizes = {check_one_size(videos) for videos in by_group.values()}
    same_mtime([p for job in jobs for p in job[:3]], time.time())
    what = f"{sizes.pop()} bytes" if len(sizes) == 1 else f"one size per item ({len(sizes)} sizes)"
    log.info(f"render: done; every video is {what}, in frames of one size, stamped with the same time")
