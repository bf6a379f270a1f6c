"""Training threads that follow the free cores, so that training slows gracefully on a shared machine.

With 2 threads on 2 cores, each parallel region of a step waits for the thread whose core another process also
wants: beside one busy process, mg_cpu training fell from 5.7 to 0.8-1.1 steps/s, whatever OpenMP's spin
settings, while 1 thread kept 3.5 (bench/bench_train_load.py, bench/RESULTS.md). So, unless the user fixes
`--threads`, training measures every 2 s how many cores other processes used (all busy time in /proc/stat
minus this process's own CPU time) and runs on the cores left, at least one.

A thread count changes the float rounding of the products, so an adaptive run is reproducible only as long as
the machine's load is; `--threads N` fixes it (the shipped models were trained with --threads 1).
"""

import contextlib
import os
import time

import torch


@contextlib.contextmanager
def torch_threads(threads):
    """torch's CPU thread count set to `threads` (None: left as it is) inside the block, and whatever it was
    (CoreShare may change it too) restored on leaving: library code never leaves process-wide state changed."""
    before = torch.get_num_threads()
    if threads is not None:
        torch.set_num_threads(int(threads))
    try:
        yield
    finally:
        if torch.get_num_threads() != before:
            torch.set_num_threads(before)


def _busy_seconds():
    """CPU seconds spent busy by the whole machine so far (all cores), from /proc/stat; None where unreadable."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            fields = [int(v) for v in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


class CoreShare:
    """Call `step()` once per training step; every `interval` seconds it sets torch's thread count to the cores
    other processes left free over that time."""

    def __init__(self, interval=2.0, cores=None):
        self.interval, self.cores = interval, cores or os.cpu_count() or 1
        self._mark()

    def _mark(self):
        self.t, self.busy, self.own = time.monotonic(), _busy_seconds(), time.process_time()

    def others(self):
        """Cores used by other processes since the last mark (0 where /proc/stat cannot be read)."""
        t, busy, own = time.monotonic(), _busy_seconds(), time.process_time()
        if busy is None or self.busy is None or t - self.t <= 0:
            return 0.0
        return max(0.0, (busy - self.busy) - (own - self.own)) / (t - self.t)

    def step(self):
        if time.monotonic() - self.t < self.interval:
            return
        free = max(1, min(self.cores, round(self.cores - self.others())))
        if free != torch.get_num_threads():
            torch.set_num_threads(free)
        self._mark()
