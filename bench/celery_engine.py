"""The Celery app of bench/bench_engines.py: one task, a clip's render, as GENEA's visualiser server ran its renders
(Celery workers behind a Redis queue). Started by the bench as `celery -A celery_engine worker` with bench/ on the
path; the broker's address comes from ENGINE_REDIS."""

import os

from celery import Celery


def make_app(redis):
    app = Celery("celery_engine", broker=redis, backend=redis)
    # The jobs are tuples of paths, options and dataclasses (a camera, a style): pickle carries them as the local
    # pool's processes and Dask do. acks_late: a worker lost mid-clip leaves its task to another.
    app.conf.update(
        task_serializer="pickle",
        result_serializer="pickle",
        accept_content=["pickle"],
        task_acks_late=True,
        worker_prefetch_multiplier=1,
        broker_connection_retry_on_startup=True,
    )
    return app


app = make_app(os.environ.get("ENGINE_REDIS", "redis://127.0.0.1:6379/15"))


@app.task(name="render")
def render(job):
    from generation.stimuli import render_pool
    from rendering.mesh import set_gl_environment

    set_gl_environment()
    return render_pool._render_job(job)
