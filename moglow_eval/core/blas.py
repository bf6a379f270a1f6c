"""One BLAS thread around small, repeated linear algebra: the model fits of the report, the classifier fits of the
two-sample tests, the mesh's skinning while a clip is drawn (rendering.render). There, each product is too small for
threads to gain, and their hand-offs cost CPU, most of all on a busy 2-core machine (a stimulus build's metrics took
up to twice the CPU beside other work), while the rounding stays the same from run to run.

threadpoolctl's `threadpool_limits` looks up the loaded BLAS libraries afresh on every call: 1-3 ms in a process
that has imported the report's libraries, paid once per fit, and a bootstrap of the ICC fits up to a thousand times.
One controller, made at the first use, is looked up once; numpy's and scipy's BLAS are loaded before it is made,
so that both are held.
"""

from functools import cache


@cache
def _controller():
    import scipy.linalg  # noqa: F401  (loads scipy's own BLAS, which the controller must see)
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def one_blas_thread():
    """A context manager: numpy's and scipy's BLAS held to one thread inside it, as they were after it."""
    return _controller().limit(limits=1, user_api="blas")
