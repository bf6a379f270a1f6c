"""gunicorn with and without `--preload`: the memory of a whole server and what its start costs, on one stimulus set.

    python bench/bench_preload.py [--stimuli DIR] [--workers 4] [--threads 16] [--repeats 3]

Without `--preload` every worker imports the app and builds it: it reads the manifest, checks the files and reads
the videos into its own cache (up to RATING_VIDEO_CACHE_MB each), so a server of four workers holds four copies of
the set. With it, the master builds the app once and forks the workers, which share the master's pages until they
write to them: the videos' bytes are never written.

The set is the one in --stimuli (default: the README's study, `python -m generation.make_stimuli` with its defaults,
made once into a temporary folder: 141 clips at 640 px). Each server has a fresh SQLite database and is started as
docs/hosting.md starts it; once every worker answers, `python -m rating_app simulate` fills the study (--ratings per
test clip, --clients raters at once, no pause: every worker serves videos from its cache). Measured, the two ways
alternating --repeats times: the seconds until every worker answers and the CPU seconds the master and its workers
took to get there (/proc/PID/stat); after the crowd, the memory of the master and its workers as the kernel counts
it (/proc/PID/smaps_rollup): their proportional set sizes added up (PSS: a page shared by n processes counts 1/n in
each), and the largest private memory of one worker.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from helpers.servers import wait_for, warm_up  # noqa: E402

from moglow_eval.core import cli  # noqa: E402
from moglow_eval.core.ports import free_port  # noqa: E402
from rating_app.store.manifest import load_manifest  # noqa: E402


def the_set(stimuli: str | None, tmp: Path) -> Path:
    """The manifest of --stimuli, or of the README's study made once into `tmp`."""
    if stimuli:
        return Path(stimuli) / "manifest.csv"
    out = tmp / "stimuli"
    print("making the README's study (python -m generation.make_stimuli, its defaults) ...", flush=True)
    cmd = [sys.executable, "-m", "generation.make_stimuli", "--out", str(out), "--quiet"]
    subprocess.run(cmd, cwd=ROOT, check=True)
    return out / "manifest.csv"


def memory_mb(master: int) -> tuple[float, float]:
    """(PSS of the master and its workers added up, the largest private memory of one worker), in MiB."""
    workers = [int(p) for p in Path(f"/proc/{master}/task/{master}/children").read_text().split()]
    pss, private = 0, 0
    for pid in [master, *workers]:
        fields = dict(
            (line.split(":")[0], int(line.split()[1]))
            for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines()[1:]
        )
        pss += fields["Pss"]
        if pid != master:
            private = max(private, fields["Private_Clean"] + fields["Private_Dirty"])
    return pss / 1024, private / 1024


def server_cpu(master: int) -> float:
    """CPU seconds the master and its live workers have used so far (/proc/PID/stat: utime, stime)."""
    workers = Path(f"/proc/{master}/task/{master}/children").read_text().split()
    ticks = 0
    for pid in [master, *map(int, workers)]:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        ticks += int(fields[11]) + int(fields[12])
    return ticks / os.sysconf("SC_CLK_TCK")


def one_server(manifest: Path, preload: bool, a, tmp: Path) -> dict:
    port = free_port()
    env = dict(
        os.environ,
        RATING_MANIFEST=str(manifest),
        RATING_DATABASE_URL=f"sqlite:///{tmp}/r{time.monotonic_ns()}.sqlite",
        RATING_ADMIN_TOKEN="bench",
        RATING_RATINGS_PER_CLIP=str(a.ratings),
        RATING_MIN_VIEW="0",
        RATING_SESSIONS_PER_CLIENT="0",  # every rater is on loopback
        PYTHONPATH=str(ROOT),
    )
    cmd = [sys.executable, "-m", "gunicorn", "-w", str(a.workers), "-k", "gthread", "--threads", str(a.threads)]
    cmd += ["--preload"] if preload else []
    cmd += ["-b", f"127.0.0.1:{port}", "rating_app.wsgi:app"]
    t0 = time.monotonic()
    with open(tmp / "gunicorn.log", "a") as log:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
        try:
            url = f"http://127.0.0.1:{port}"
            wait_for(f"{url}/healthz", proc, "gunicorn")
            warm_up(url, a.workers * a.threads)
            up, cpu = time.monotonic() - t0, server_cpu(proc.pid)
            crowd = [sys.executable, "-m", "rating_app", "simulate", "--url", url, "--manifest", str(manifest)]
            crowd += ["--raters", "1000", "--concurrency", str(a.clients), "--think", "0", "--quiet"]
            subprocess.run(crowd, cwd=ROOT, env=env, check=True, stdout=subprocess.DEVNULL)
            pss, private = memory_mb(proc.pid)
        finally:
            proc.terminate()
            proc.wait(60)
    return {"up": up, "cpu": cpu, "pss": pss, "private": private}


def main():
    p = cli.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--stimuli", default=None, help="a stimulus folder (default: the README's study, made here)")
    p.add_argument("--workers", type=int, default=4, help="gunicorn workers (4, as docs/hosting.md)")
    p.add_argument("--threads", type=int, default=16, help="threads a worker (16, as docs/hosting.md)")
    p.add_argument("--ratings", type=int, default=10, help="ratings per test clip the crowd gives (10)")
    p.add_argument("--clients", type=int, default=16, help="raters at once (16)")
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_preload_"))
    manifest = the_set(a.stimuli, tmp)
    clips = load_manifest(manifest)
    size = sum(Path(c.video).stat().st_size for c in clips) / 2**20
    print(f"{len(clips)} clips, {size:.0f} MiB of video; {a.workers} workers x {a.threads} threads")
    runs = {False: [], True: []}
    for _ in range(a.repeats):
        for preload in (False, True):
            runs[preload].append(one_server(manifest, preload, a, tmp))
    best = {k: {m: min(r[m] for r in v) for m in v[0]} for k, v in runs.items()}
    print(f"{'':14s}{'up s':>8s}{'CPU s':>8s}{'PSS MiB':>10s}{'worker private MiB':>20s}")
    for preload in (False, True):
        b = best[preload]
        name = "--preload" if preload else "no preload"
        print(f"{name:14s}{b['up']:8.2f}{b['cpu']:8.2f}{b['pss']:10.0f}{b['private']:20.0f}")
    ratio = {m: best[True][m] / best[False][m] for m in ("up", "cpu", "pss")}
    print("--preload / none (best of each): " + ", ".join(f"{m} {r:.2f}x" for m, r in ratio.items()))


if __name__ == "__main__":
    main()
