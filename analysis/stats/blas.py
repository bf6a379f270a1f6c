"""One BLAS thread around the model fits, which are chains of small factorisations: thread hand-offs cost more than
they save there (far more on a busy 2-core machine), and the rounding is then the same from run to run.

threadpoolctl's `threadpool_limits` looks up the loaded BLAS libraries afresh on every call: 1-3 ms in a process
that has imported the report's libraries, paid once per fit, and a bootstrap of the ICC fits up to a thousand times.
One controller, made at the first fit (when numpy's and scipy's BLAS are loaded), is looked up once.
"""

from functools import cache

from threadpoolctl import ThreadpoolController


@cache
def _controller() -> ThreadpoolController:
    return ThreadpoolController()


def one_blas_thread():
    """A context manager: the BLAS libraries held to one thread inside it, as they were after it."""
    return _controller().limit(limits=1, user_api="blas")
