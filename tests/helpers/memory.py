"""The peak of traced memory while a reader refuses (or takes) a hostile file."""

import tracemalloc


def peak(fn, *args, **kw):
    """(the exception fn raised or None, the peak of traced memory while it ran)."""
    tracemalloc.start()
    try:
        fn(*args, **kw)
    except Exception as e:  # noqa: BLE001 - the caller checks what was raised
        raised = e
    else:
        raised = None
    peak_bytes = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return raised, peak_bytes
