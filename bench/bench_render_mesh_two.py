"""The mesh against the stick figure, one person and two, as a study builds them (targets: a two-person mesh clip
within 3 times the same two-person stick clip on 2 cores, one person within 2.5 times).

A dyadic study of a conversation in Seamless Interaction's layout (tests/helpers/seamless_fixtures.py: two people,
SMPL-H, captions, both voices) with `[render] style = ["stick", "mesh"]`, its body model swapped for the synthetic
SMPL-H body of about the real one's 6890 vertices (smpl_fixtures.body_model_arrays), is built by make_stimuli's own
builder, which hands its render jobs here instead of to its pool. Each mesh job is paired with the stick job of the
same clip (the same motion, camera, size, captions and sound), and each pair is rendered by render_pool's own job
function, stick then mesh, clip after clip, for --repeats rounds:

- `two`: the clip as the study builds it (the agent and the interlocutor, through the item's camera and frame);
- `one`: the same clip without the interlocutor, through the agent's own front, upper-body camera, in a square
  frame (as a one-person study of speech frames it).

The jobs run in this process one at a time, so each clip has the machine's cores to itself. Prints, per round and
over the rounds, the seconds of the clips and their CPU seconds (this process's and ffmpeg's), the mesh's over the
stick's, with the load average beside them. With --build N, also N rounds of whole builds (`make_stimuli --study`,
a fresh process each, --workers 2) in stick and in mesh, in turns; with --estimate K, a whole mesh build of the study
with K made-up systems (a dyadic study's clips: each system's matched and mismatched clip of each item), and the
time 1,200 such clips take at its pace.

    PYTHONPATH=$PWD python bench/bench_render_mesh_two.py [--size 640] [--seconds 6] [--clips 6] [--repeats 3]
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from helpers import seamless_fixtures, smpl_fixtures  # noqa: E402

import generation.own_study.builder as builder  # noqa: E402
from generation.make_stimuli import main as make_stimuli  # noqa: E402
from generation.stimuli.render_pool import _render_job  # noqa: E402
from moglow_eval.core.clip import load_clip  # noqa: E402
from rendering.framing import item_camera  # noqa: E402
from rendering.mesh import set_gl_environment  # noqa: E402

BODY = dict(rings=7, segments=18, head_rings=22)  # 6850 vertices, 13392 faces: about the real SMPL-H's
TWO_PEOPLE = ("partner", "partner_mesh", "partner_style", "target", "aspect")  # what `one` leaves out


def write_study(root, seconds, styles, systems=None):
    """A dyadic study of the test conversations, items of `seconds`, drawn in `styles` (a TOML value), through the
    synthetic SMPL-H body, with the fixture's two made-up systems or `systems` of them; returns its study file."""
    made_up = seamless_fixtures.SYSTEMS
    if systems:
        seamless_fixtures.SYSTEMS = {f"SYS{k}": 0.02 + 0.01 * k for k in range(systems)}
    try:
        study = seamless_fixtures.write_study(root, "dyadic", length_s=seconds)
    finally:
        seamless_fixtures.SYSTEMS = made_up
    smpl_fixtures.write_body_model(root / "raw" / "models" / "SMPLH_NEUTRAL.npz", "smplh", **BODY)
    study.write_text(study.read_text().replace('style = "stick"', f"style = {styles}"))
    return study


class _Captured(Exception):
    """Raised in place of the build's rendering once the jobs are timed: the build stops there."""


def study_jobs(study, out, size, use):
    """Build the study up to its rendering and call `use(jobs)` with its render jobs, while the build's temporary
    files (the sound, the placed interlocutor) exist."""

    def instead(jobs, *args, **kwargs):
        for job in jobs:
            job[5]["rate_seed"] = 0  # (as a build keys them: the same bytes each round)
        use(jobs)
        raise _Captured

    rendering = builder.render_stimuli
    builder.render_stimuli = instead
    try:
        make_stimuli(["--study", str(study), "--out", str(out), "--size", str(size), "--quiet", "--workers", "1"])
    except _Captured:
        pass
    finally:
        builder.render_stimuli = rendering


def pairs_of(jobs, clips):
    """[(stick job, mesh job)] of the same clip, at most `clips` of them: a job's motion file holds its joints."""
    by_joints = {}
    for job in jobs:
        key = load_clip(job[0])["joints"].tobytes()
        by_joints.setdefault(key, {})[job[5]["style"].body] = job
    return [(d["stick"], d["mesh"]) for d in by_joints.values() if {"stick", "mesh"} <= d.keys()][:clips]


def alone(job):
    """The job with the interlocutor left out, through the agent's own front, upper-body camera, in a square frame."""
    clip = load_clip(job[0])
    camera = item_camera([clip["joints"]], clip["joint_names"], clip["parents"], clip["fps"], "front", "upper")
    keywords = {k: v for k, v in job[5].items() if k not in TWO_PEOPLE}
    return (*job[:5], {**keywords, "camera": camera})


def cpu_seconds():
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def time_pairs(pairs, repeats, folder):
    """{(people, style): [[wall s, cpu s] per round, the round's clips summed]}: each clip stick, then mesh."""
    times = {}
    for r in range(repeats):
        for people in ("two", "one"):
            for stick, mesh in pairs:
                for style, job in (("stick", stick), ("mesh", mesh)):
                    job = job if people == "two" else alone(job)
                    name = folder / f"{people}-{style}"
                    job = (job[0], f"{name}.mp4", f"{name}.png", *job[3:])
                    wall, cpu = time.perf_counter(), cpu_seconds()
                    _render_job(job)
                    spent = times.setdefault((people, style), np.zeros((repeats, 2)))
                    spent[r] += (time.perf_counter() - wall, cpu_seconds() - cpu)
        print(f"round {r + 1}: " + round_line(times, r), flush=True)
    return times


def round_line(times, r):
    parts = []
    for people in ("two", "one"):
        stick, mesh = times[(people, "stick")][r], times[(people, "mesh")][r]
        parts.append(f"{people} {mesh[0] / stick[0]:.2f} (cpu {mesh[1] / stick[1]:.2f})")
    return ", ".join(parts) + f"; load {os.getloadavg()[0]:.1f}"


def report(times, n_clips, seconds):
    for people in ("two", "one"):
        stick, mesh = times[(people, "stick")], times[(people, "mesh")]
        ratios = mesh / stick
        s, m = np.median(stick, 0), np.median(mesh, 0)
        print(
            f"{people}: a {seconds:g}-s clip stick {s[0] / n_clips:.2f} s (cpu {s[1] / n_clips:.2f}), mesh "
            f"{m[0] / n_clips:.2f} s (cpu {m[1] / n_clips:.2f}); mesh / stick {m[0] / s[0]:.2f} "
            f"(rounds {ratios[:, 0].min():.2f}-{ratios[:, 0].max():.2f}), cpu {m[1] / s[1]:.2f}"
        )


def build_seconds(study, out, size, workers):
    """Seconds of a whole `make_stimuli --study` in a fresh process, into a new folder (a folder already built would
    have its finished clips reused)."""
    shutil.rmtree(out, ignore_errors=True)
    argv = [sys.executable, "-m", "generation.make_stimuli", "--study", str(study), "--out", str(out)]
    argv += ["--size", str(size), "--quiet", "--workers", str(workers)]
    t0 = time.perf_counter()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    subprocess.run(argv, check=True, cwd=ROOT, env=env, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def estimate(root, seconds, size, systems, clips=1200):
    """A two-person mesh study of `systems` made-up systems built whole (--workers 2): its clips and seconds, and the
    seconds of `clips` such clips at its pace."""
    study = write_study(root / "estimate", seconds, '"mesh"', systems)
    spent = build_seconds(study, root / "estimate" / "out", size, 2)
    with open(root / "estimate" / "out" / "manifest.csv") as f:
        n = sum(1 for _ in f) - 1
    print(f"a two-person mesh study of {n} clips of {seconds:g} s at {size} px high, built whole on 2 processes: "
          f"{spent:.0f} s, {spent / n:.2f} s a clip; {clips} such clips: {spent / n * clips / 3600:.2f} h; load "
          f"{os.getloadavg()[0]:.1f}")  # fmt: skip


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=640, help="the frame's height in pixels")
    ap.add_argument("--seconds", type=float, default=6.0, help="the items' length")
    ap.add_argument("--clips", type=int, default=6, help="clips per round, each in stick and in mesh (0: none)")
    ap.add_argument("--repeats", type=int, default=3, help="rounds")
    ap.add_argument("--build", type=int, default=0, help="also this many rounds of whole builds, stick and mesh")
    ap.add_argument("--estimate", type=int, default=0, help="also a whole mesh build with this many systems, scaled")
    args = ap.parse_args()
    set_gl_environment()  # as make_stimuli's main does
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        found = {}

        def use(jobs):
            pairs = pairs_of(jobs, args.clips)
            print(f"{len(pairs)} clips of {args.seconds:g} s, each in stick and in mesh, {args.size} px high")
            found["times"] = time_pairs(pairs, args.repeats, root)
            found["n"] = len(pairs)

        if args.clips:
            study = write_study(root / "both", args.seconds, '["stick", "mesh"]')
            study_jobs(study, root / "out", args.size, use)
            report(found["times"], found["n"], args.seconds)
        if args.build:
            studies = {s: write_study(root / s, args.seconds, f'"{s}"') for s in ("stick", "mesh")}
            builds = {}
            for _ in range(args.build):
                for style in ("stick", "mesh"):
                    spent = build_seconds(studies[style], root / style / "out", args.size, 2)
                    builds.setdefault(style, []).append(spent)
                print(f"builds: stick {builds['stick'][-1]:.1f} s, mesh {builds['mesh'][-1]:.1f} s; load "
                      f"{os.getloadavg()[0]:.1f}", flush=True)  # fmt: skip
            stick, mesh = np.median(builds["stick"]), np.median(builds["mesh"])
            print(f"whole builds, --workers 2: stick {stick:.1f} s, mesh {mesh:.1f} s, mesh / stick {mesh / stick:.2f}")
        if args.estimate:
            estimate(root, args.seconds, args.size, args.estimate)


if __name__ == "__main__":
    main()
