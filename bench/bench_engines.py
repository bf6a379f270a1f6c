"""Which distributed engine renders a study's clips: Dask distributed, Celery with Redis (what GENEA's visualiser
server ran), or Ray, each against the local process pool `make_stimuli` uses by default, on this machine.

One study's render jobs (own_study.demo_study: real actions, two made-up systems, speech; the very jobs
`make_stimuli --study` hands its renderer) are rendered by each engine in turn, two workers of one thread each,
the engines started beforehand and kept warm, as a cluster is. Each round runs every engine once, the order turning
from round to round; the figure is each engine's time for the whole set against the local pool's in the same round
(the median of the rounds), with each engine's start-up time beside it. Every engine's videos are checked to be
the local pool's bytes, file for file.

    PY bench/bench_engines.py [--items 8] [--size 160] [--rounds 3]

PY: a Python that has the project and celery, redis (the client) and ray, none of them the project's dependencies,
e.g. `python -m venv --system-site-packages V && V/bin/pip install celery redis ray`. Celery needs a Redis server at
127.0.0.1:6379 (`--redis`).
"""

import argparse
import filecmp
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from generation.stimuli import render_pool  # noqa: E402
from moglow_eval.core.ports import free_port  # noqa: E402

WORKERS = 2


class _Captured(Exception):
    pass


def study_jobs(folder, items, size):
    """The render jobs of demo_study's study, as make_stimuli builds them (its motion and sound files written)."""
    from generation import make_stimuli
    from generation.own_study import demo_study

    study = demo_study.build(folder / "in", items)
    got = {}

    def capture(jobs, workers, **_):
        # The build removes its half-made folders (the stimulus folder, the sound's scratch folder) when stopped
        # here: keep every folder the jobs read from, at a path of its own.
        jobs = list(jobs)
        folders = sorted({str(Path(v).parent) for v in _strings(jobs) if Path(v).is_file()})
        for k, source in enumerate(folders):
            shutil.copytree(source, folder / "inputs" / str(k))
            jobs = [_moved(job, source + "/", f"{folder / 'inputs' / str(k)}/") for job in jobs]
        got["jobs"] = jobs
        raise _Captured

    real, render_pool.render_all = render_pool.render_all, capture
    try:
        make_stimuli.main(["--study", str(study), "--out", str(folder / "stimuli"), "--size", str(size), "--quiet"])
    except _Captured:
        pass
    finally:
        render_pool.render_all = real
    return got["jobs"]


def _strings(value):
    if isinstance(value, (str, Path)):
        yield str(value)
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _strings(v)
    elif isinstance(value, dict):
        for v in value.values():
            yield from _strings(v)


def _moved(value, old, new):
    """`value` (a job, or any part of it) with every path under `old` put under `new`."""
    if isinstance(value, (str, Path)) and str(value).startswith(old):
        return type(value)(new + str(value)[len(old) :])
    if isinstance(value, (list, tuple)):
        return type(value)(_moved(v, old, new) for v in value)
    if isinstance(value, dict):
        return {k: _moved(v, old, new) for k, v in value.items()}
    return value


def retarget(jobs, out):
    """The jobs with their videos and sheets written into `out` (emptied first)."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    moved = []
    for motion, video, sheet, *rest in jobs:
        moved.append((motion, str(out / Path(video).name), str(out / Path(sheet).name) if sheet else None, *rest))
    return moved


# ---------------------------------------------------------------- the engines
QUIET = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)


class Local:
    name = "local processes (the default)"

    def start(self):
        pass

    def run(self, jobs):
        render_pool.render_all(jobs, WORKERS, progress=False)

    def stop(self):
        pass


class Dask:
    name = "Dask distributed"

    def start(self):
        from distributed import Client

        port = free_port()
        address = f"tcp://127.0.0.1:{port}"
        self.procs = [subprocess.Popen(["dask", "scheduler", "--port", str(port), "--no-dashboard"], **QUIET)]
        worker = ["dask", "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard"]
        self.procs += [subprocess.Popen(worker, **QUIET) for _ in range(WORKERS)]
        self.client = Client(address, timeout="30s")
        self.client.wait_for_workers(WORKERS)
        self.address = address

    def run(self, jobs):
        from generation.stimuli.cluster import render_on_cluster

        render_on_cluster(jobs, self.address, render_pool._render_job, lambda k: None)

    def stop(self):
        self.client.close()
        for p in self.procs:
            os.killpg(p.pid, signal.SIGKILL)


class Celery:
    name = "Celery, Redis broker"

    def __init__(self, redis):
        self.redis = redis

    def start(self):
        import celery_engine

        env = dict(os.environ, PYTHONPATH=f"{ROOT}:{ROOT / 'bench'}", ENGINE_REDIS=self.redis)
        if os.geteuid() == 0:  # Celery refuses pickle under root unless told; a container's bench runs as root
            env["C_FORCE_ROOT"] = "1"
        worker = ["-m", "celery", "-A", "celery_engine", "worker", "--pool", "solo", "--without-gossip"]
        self.procs = [
            subprocess.Popen(
                [sys.executable, *worker, "-n", f"w{k}@%h", "--prefetch-multiplier", "1"], env=env, **QUIET
            )
            for k in range(WORKERS)
        ]
        self.app = celery_engine.make_app(self.redis)
        deadline = time.time() + 60
        while len(self.app.control.ping(timeout=1.0) or []) < WORKERS:
            if time.time() > deadline:
                raise RuntimeError("the Celery workers did not answer")

    def run(self, jobs):
        import celery_engine

        results = [celery_engine.render.apply_async((job,)) for job in jobs]
        for r in results:
            r.get(timeout=600)

    def stop(self):
        for p in self.procs:
            os.killpg(p.pid, signal.SIGKILL)


class Ray:
    name = "Ray"

    def start(self):
        import ray

        ray.init(num_cpus=WORKERS, include_dashboard=False, log_to_driver=False)
        self.task = ray.remote(num_cpus=1, max_retries=2)(_ray_render)
        ray.get([self.task.remote(None) for _ in range(WORKERS)])  # the workers up

    def run(self, jobs):
        import ray

        ray.get([self.task.remote(job) for job in jobs])

    def stop(self):
        import ray

        ray.shutdown()


def _ray_render(job):
    if job is None:
        return 0
    from rendering.mesh import set_gl_environment

    set_gl_environment()
    return render_pool._render_job(job)


# ---------------------------------------------------------------- the measure
def same_bytes(a, b):
    names = sorted(p.name for p in a.iterdir())
    assert names == sorted(p.name for p in b.iterdir()), (a, b)
    _, mismatch, errors = filecmp.cmpfiles(a, b, names, shallow=False)
    return not mismatch and not errors


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--items", type=int, default=8)
    ap.add_argument("--size", type=int, default=160)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--redis", default="redis://127.0.0.1:6379/15")
    args = ap.parse_args()
    engines = [Local(), Dask(), Celery(args.redis), Ray()]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        jobs = study_jobs(tmp, args.items, args.size)
        print(f"{len(jobs)} clips at {args.size} px, {WORKERS} workers; load {os.getloadavg()[0]:.1f}", flush=True)
        startup = {}
        for e in engines:
            t0 = time.perf_counter()
            e.start()
            startup[e.name] = time.perf_counter() - t0
        times = {e.name: [] for e in engines}
        ratios = {e.name: [] for e in engines}
        try:
            for r in range(args.rounds):
                order = engines[r % len(engines) :] + engines[: r % len(engines)]
                this = {}
                for e in order:
                    out = tmp / "out" / e.name.split()[0]
                    moved = retarget(jobs, out)
                    t0 = time.perf_counter()
                    e.run(moved)
                    this[e.name] = time.perf_counter() - t0
                    if e is not engines[0] and not same_bytes(out, tmp / "out" / engines[0].name.split()[0]):
                        print(f"  {e.name}: videos differ from the local pool's")
                for name, t in this.items():
                    times[name].append(t)
                    ratios[name].append(t / this[engines[0].name])
                print(f"round {r + 1}: " + ", ".join(f"{n.split()[0]} {t:.1f} s" for n, t in this.items()), flush=True)
        finally:
            for e in engines:
                e.stop()
        print(f"\nload {os.getloadavg()[0]:.1f}")
        print(f"{'engine':<32}{'start-up s':>12}{'render s (median)':>20}{'x local (median, range)':>28}")
        for e in engines:
            rs = ratios[e.name]
            print(
                f"{e.name:<32}{startup[e.name]:>12.1f}{statistics.median(times[e.name]):>20.1f}"
                f"{statistics.median(rs):>14.3f} ({min(rs):.3f}-{max(rs):.3f})"
            )


if __name__ == "__main__":
    main()
