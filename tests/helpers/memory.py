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


def run_under_address_cap(imports: str, work: str, headroom: int, *args):
    """`imports`, then `work`, as a Python process of its own whose address space is capped `headroom` bytes above
    what its imports took: a host that does not overcommit memory refuses a large allocation so, even one never
    touched. Returns the CompletedProcess (text); `args` are its sys.argv[1:]."""
    import subprocess
    import sys

    from .paths import ROOT

    cap = (
        "import re, resource\n"
        'size = int(re.search(r"VmSize:\\s*(\\d+) kB", open("/proc/self/status").read()).group(1)) * 1024\n'
        f"resource.setrlimit(resource.RLIMIT_AS, (size + {int(headroom)}, resource.RLIM_INFINITY))\n"
    )
    code = f"{imports}\n{cap}{work}\n"
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, cwd=ROOT)
