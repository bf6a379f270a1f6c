"""Rendering many clips at once: one process per worker, each rendering whole clips with one encoder thread.

The workers are not forked from the parent: it has loaded torch (sampling, training), whose thread pools make
forked children hang. They are forked from multiprocessing's fork server, a fresh process that has imported this
module and nothing else (`_workers_context`), so a worker starts with rendering loaded instead of importing it
again, and a process that builds again (a notebook, the tests) starts its next workers from the same server; where
there is no fork server, they are spawned and import this module themselves. Either way this
module imports rendering and nothing that loads torch; keep it so (seconds and hundreds of MB per worker otherwise;
tests/generation/test_stimuli.py checks the workers' imports). Nor does a worker run the command's main module
again, as spawned children do by default (`_main_left_out`).
"""

import contextlib
import logging
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import fields
from multiprocessing import get_all_start_methods, get_context
from pathlib import Path

import numpy as np
from tqdm import tqdm

from rendering.audio import mux_audio
from rendering.blinding import check_one_size, odd_ones, same_mtime
from rendering.encode import KEY_QP
from rendering.mesh import set_gl_environment
from rendering.render import RenderOptions, frame_width, render_clip

from .build_index import job_key

log = logging.getLogger(__name__)
SETTINGS = frozenset(f.name for f in fields(RenderOptions))  # a job's keywords that are RenderOptions'
PART = ".part"  # a file being written: VIDEO.part.mp4, SHEET.part.png, renamed when whole
# A video that came out a size off is encoded again, each time with a fresh random rate dither and its key frame at
# the next of the encoder's KEY_QP (a key frame x264 codes to within a filler unit of its budget comes out short,
# which the dither of the frames after it cannot mend).
RETRIES = len(KEY_QP)


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
    # Written under other names and renamed when whole: a build killed at any moment leaves no broken video.
    video, sheet = Path(video), Path(sheet) if sheet else None
    part_video = video.with_name(video.stem + PART + video.suffix)
    part_sheet = sheet.with_name(sheet.stem + PART + sheet.suffix) if sheet else None
    n = render_clip(motion, part_video, options, sheet=part_sheet, **keywords)
    if audio is not None:
        samples, start, duration = audio
        mux_audio(part_video, np.load(samples), start, duration)
    if sheet:
        os.replace(part_sheet, sheet)
    os.replace(part_video, video)
    return n


def render_all(jobs, workers, progress=True, done=None, scheduler=None):
    """Render (motion, video, sheet, size, preset[, keywords: _render_job's]) jobs on `workers` processes, or on the
    Dask cluster at `scheduler`, with a progress bar; `done(k)` is called as job k's files take their names."""
    with tqdm(total=len(jobs), desc="render", unit="clip", file=sys.stderr, disable=not progress) as bar:
        if scheduler is not None:
            from .cluster import render_on_cluster

            return render_on_cluster(jobs, scheduler, _render_job, lambda k: (done and done(k), bar.update()))
        if workers <= 1:
            for k, job in enumerate(jobs):
                _render_job(job)
                if done:
                    done(k)
                bar.update()
            return
        # A worker is a process of its own: its initialiser sets what its GL drawing wants, as a command's main does.
        pool = ProcessPoolExecutor(workers, mp_context=_workers_context(), initializer=set_gl_environment)
        try:
            with _main_left_out():  # the workers start as the first jobs are submitted
                futures = {pool.submit(_render_job, job): k for k, job in enumerate(jobs)}
            for fut in as_completed(futures):
                fut.result()  # a worker's RenderError is raised here
                if done:
                    done(futures[fut])
                bar.update()
        finally:
            pool.shutdown(cancel_futures=True)


def _workers_context():
    """The render workers' multiprocessing context: the fork server with this module loaded before it forks, or
    spawn where the platform has no fork server. The server lives as long as this process and keeps the environment
    it started with, so the GL settings a worker draws with are set by each worker's initialiser."""
    if "forkserver" not in get_all_start_methods():
        return get_context("spawn")
    context = get_context("forkserver")
    context.set_forkserver_preload([__name__])
    return context


@contextlib.contextmanager
def _main_left_out():
    """Workers started inside this block do not import the parent's main module. A spawned child, or one forked
    from the fork server, runs it again (multiprocessing's "safe importing of the main module") when `__main__` has
    a spec or a file: for `python -m generation.make_stimuli` that is all of make_stimuli, which a worker does not
    need. A job holds data and `_render_job`, nothing defined in a main module, so the workers lose nothing."""
    main = sys.modules["__main__"]
    saved = {k: main.__dict__[k] for k in ("__spec__", "__file__") if k in main.__dict__}
    main.__spec__ = None
    main.__dict__.pop("__file__", None)
    try:
        yield
    finally:
        main.__dict__.pop("__spec__", None)
        main.__dict__.update(saved)


def render_stimuli(jobs, workers, progress=True, groups=None, index=None, scheduler=None):
    """Render every job of a stimulus set, check that the videos are one size (rendering.blinding: by
    construction, every frame one size) and give every file one time. `groups`: a key per job whose videos must
    agree (a study of your own motion: the item, whose clips share a length and a sound); None: all of them.

    `index` (build_index.BuildIndex of the folder): every job is keyed (build_index.job_key) and its encoder's
    random rate share seeded from its key, so one study with one seed gives the same bytes in every build; a job
    whose key the index lists, with its files there, is not rendered again (renamed, where its clip's id
    changed), each finished job is listed as it finishes, and files of clips no job names any more are removed.
    `scheduler`: render on that Dask cluster (cluster.py) instead of local processes."""
    workers = min(workers, len(jobs))
    size = jobs[0][3] if jobs else 0
    width = frame_width(size, jobs[0][5].get("aspect", 1.0)) if jobs and len(jobs[0]) > 5 else size
    todo = list(range(len(jobs)))
    if index is not None:
        keys = [job_key(job) for job in jobs]
        for k, key in enumerate(keys):
            jobs[k][5]["rate_seed"] = int(key[:12], 16)  # the same bytes for the same inputs, build after build
        todo = _reuse(jobs, keys, index)
    log.info(
        f"render: {len(todo)} of {len(jobs)} clips at {width}x{size} on {min(workers, max(1, len(todo)))} processes"
    )

    def finished(k):
        if index is not None:
            index.add(keys[todo[k]], Path(jobs[todo[k]][1]).stem)

    render_all([jobs[k] for k in todo], workers, progress=progress, done=finished, scheduler=scheduler)
    by_group = {}
    for k, job in enumerate(jobs):
        by_group.setdefault(None if groups is None else groups[k], []).append(k)
    for attempt in range(1, RETRIES + 1):
        odd = [ks[i] for ks in by_group.values() if len(ks) > 2 for i in odd_ones([jobs[k][1] for k in ks])]
        if not odd:
            break
        # x264 can overshoot one frame's budget by a byte on a frame dense with edges (captions at a small size), or
        # code a key frame to within a filler unit of its budget: another random share of the rate per frame puts
        # the frames elsewhere, a quantiser of its own leaves the key frame room, and the video comes out one size.
        log.info(f"render: {len(odd)} video(s) came out a frame size off the others of their item; encoding again")
        again = [_again(jobs[k], attempt, seeded=index is not None) for k in odd]
        render_all(again, max(1, min(workers, len(odd))), progress=False, scheduler=scheduler)
    if index is not None:
        index.keep_only({keys[k]: Path(job[1]).stem for k, job in enumerate(jobs)})
        _remove_stale(jobs)
    by_group = {g: [jobs[k][1] for k in ks] for g, ks in by_group.items()}
    sizes = {check_one_size(videos) for videos in by_group.values()}
    same_mtime([p for job in jobs for p in job[:3]], time.time())
    what = f"{sizes.pop()} bytes" if len(sizes) == 1 else f"one size per item ({len(sizes)} sizes)"
    log.info(f"render: done; every video is {what}, in frames of one size, stamped with the same time")


def _again(job, attempt, seeded):
    """The job encoded again the `attempt`th time (from 1): its key frame at the quantiser KEY_QP gives that attempt,
    and a seeded job's rate seed moved on by `attempt` (the same in every build); an unseeded one draws afresh."""
    settings = {**(job[5] if len(job) > 5 else {}), "key_qp": KEY_QP[attempt - 1]}
    if seeded:
        settings["rate_seed"] += attempt
    return (*job[:5], settings)


def _reuse(jobs, keys, index) -> list[int]:
    """The jobs still to render; every other job's files, listed by the index under its key, are moved to its
    clip's names (through names of their own first, so that two clips whose ids swapped never overwrite)."""
    moves, todo = [], []
    ids = {Path(job[1]).stem for job in jobs}
    for k, (key, job) in enumerate(zip(keys, jobs)):
        old = index.done.get(key)
        video, sheet = Path(job[1]), Path(job[2])
        was = (video.with_name(f"{old}{video.suffix}"), sheet.with_name(f"{old}{sheet.suffix}")) if old else None
        if was is None or not all(p.is_file() for p in was) or (old != video.stem and old in ids):
            todo.append(k)  # not finished, or finished as another clip of this build (two clips of the same bytes)
        elif was[0] != video:
            moves.append((was, (video, sheet)))
    staged = []
    for (src_v, src_s), dst in moves:
        tmp = (src_v.with_name(src_v.name + ".moving"), src_s.with_name(src_s.name + ".moving"))
        os.replace(src_v, tmp[0])
        os.replace(src_s, tmp[1])
        staged.append((tmp, dst))
    for (tmp_v, tmp_s), (video, sheet) in staged:
        os.replace(tmp_s, sheet)
        os.replace(tmp_v, video)
    if moves:
        log.info(f"render: {len(moves)} finished clip(s) renamed to their new ids")
    return todo


def _remove_stale(jobs) -> None:
    """Remove the videos and sheets (and parts of either) that no job names: clips of an earlier build that this
    one has no more."""
    keep = {Path(p).resolve() for job in jobs for p in job[1:3]}
    folders = {Path(p).resolve().parent for job in jobs for p in job[1:3]}
    for folder in folders:
        for path in folder.iterdir():
            if path.is_file() and path.resolve() not in keep:
                path.unlink()
