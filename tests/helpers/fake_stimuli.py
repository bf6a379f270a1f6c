"""Helpers for the rating app's tests and bench/bench_app.py: a small stimulus folder of real MP4s and throw-away
PostgreSQL schemas (free ports: moglow_eval.core.ports). They live beside the tests, not in rating_app, so that the
product ships no fake stimuli under the name of the real `generation.make_stimuli`."""

from __future__ import annotations

import contextlib
import csv
import os
import secrets
from pathlib import Path

import numpy as np

from moglow_eval.core import study


def pg_base() -> str:
    """The SQLAlchemy URL of the tests' PostgreSQL database `test`, read when asked: the `pg_server` fixture sets
    RATING_TEST_PG when it starts a server of the tests' own."""
    return os.environ.get("RATING_TEST_PG", "postgresql+psycopg://postgres@127.0.0.1:5432/test")


_ENCODED = {}  # (n_frames, size, fps, shade) -> the MP4's bytes: an ffmpeg process per clip was most of a folder's time


def write_mp4(path, n_frames=6, size=64, fps=20, shade=0):
    """A few frames of real H.264 yuv420p video (+faststart), as the stimuli contract asks; encoded once per
    process for each set of arguments, and copied after that. The bar's place repeats every `size - 8` shades, and
    so does the video: a set of more clips than that (the design tests' 30 items) encodes that many, not one a clip."""
    key = (n_frames, size, fps, shade % (size - 8))
    if key not in _ENCODED:
        _encode(path, *key)
        _ENCODED[key] = Path(path).read_bytes()
    else:
        Path(path).write_bytes(_ENCODED[key])


def _encode(path, n_frames, size, fps, shade):
    import imageio_ffmpeg

    w = imageio_ffmpeg.write_frames(
        str(path),
        (size, size),
        fps=fps,
        codec="libx264",
        pix_fmt_out="yuv420p",
        macro_block_size=16,
        ffmpeg_log_level="error",
        output_params=["-movflags", "+faststart", "-an"],
    )
    w.send(None)
    for t in range(n_frames):
        frame = np.full((size, size, 3), 255, np.uint8)
        x = (t * 7 + shade * 5) % (size - 8)
        frame[size // 2 - 10 : size // 2 + 10, x : x + 8] = (20, 20, 20)
        w.send(frame)
    w.close()


def write_stimulus_mp4(path, n_frames=16, size=64, fps=20, seed=0):
    """A video as the stimulus encoder makes them (rendering.encode's one-size rate control): every such video of
    the same size, rate and length has the same byte size, whatever it shows, as a study's videos have."""
    from rendering.encode import ffmpeg_writer

    proc = ffmpeg_writer(path, size, fps, frames=n_frames, seed=seed)
    chroma = np.full(size * size // 2, 128, np.uint8).tobytes()
    for t in range(n_frames):
        luma = np.full((size, size), 235, np.uint8)
        x = (t * 7 + seed * 5) % (size - 8)
        luma[size // 2 - 10 : size // 2 + 10, x : x + 8] = 20
        proc.stdin.write(luma.tobytes() + chroma)
    proc.stdin.close()
    assert proc.wait() == 0, proc.stderr.read()
    return Path(path)


def write_fake_stimuli(
    folder,
    n_items=4,
    conditions=study.BUILTIN,
    n_catch=2,
    n_training=3,
    n_frames=16,
    fps=20,
    metrics=True,
    seed=0,
    catch_nat=False,
    mismatched=False,
    styles=(),
) -> Path:
    """Write manifest.csv (+ metrics.csv) with one short MP4 per clip; return the manifest path.

    NAT/MG/FL share items; BAD clips are catch trials; training clips cover every condition. `catch_nat`: also a
    clip of every condition of each catch item (role catch), as make_stimuli writes them for pairwise and parallel
    catch trials (NAT is the reference, the others fill a parallel catch page to a test page's size). `mismatched`:
    also each condition's mismatched clip of every test item (the next item's motion, CONTRACTS §10), for the
    appropriateness design; the other designs leave those out. `styles` (e.g. ("stick", "solid")): every clip once
    in each style, each its own stimulus, and a manifest `style` column, as a study with `[render] style` makes."""
    folder = Path(folder)
    (folder / "videos").mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    rows, taken = [], set()

    def add(condition, role, item, motion_item=""):
        for style in styles or (None,):
            add_one(condition, role, item, motion_item, style)

    def add_one(condition, role, item, motion_item, style):
        cid = study.new_clip_id(taken)  # as make_stimuli names clips: no id spells a condition
        video = f"videos/{cid}.mp4"
        write_mp4(folder / video, n_frames=n_frames, fps=fps, shade=len(rows))
        rows.append(
            {
                "clip_id": cid,
                "condition": condition,
                "role": role,
                "item": item,
                "video": video,
                "motion": f"clips/{cid}.npz",
                "seed": "" if condition == study.NATURAL else str(len(rows)),
                "frames": n_frames,
                "fps": fps,
                "motion_item": motion_item,
                **({"style": style} if style else {}),
            }
        )

    for i in range(n_items):
        for cond in conditions:
            add(cond, "test", f"item{i:02d}")
            if mismatched:
                add(cond, "test", f"item{i:02d}", motion_item=f"item{(i + 1) % n_items:02d}")
    for i in range(n_catch):
        add(study.CATCH, "catch", f"bad{i:02d}")
        if catch_nat:
            for cond in conditions:
                add(cond, "catch", f"bad{i:02d}")
    for i in range(n_training):
        add((*conditions, study.CATCH)[i % (len(conditions) + 1)], "training", f"train{i:02d}")
    manifest = folder / "manifest.csv"
    with open(manifest, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    if metrics:
        _write_fake_metrics(folder / "metrics.csv", rows, rng)
    return manifest


def _write_fake_metrics(path, rows, rng):
    """metrics.csv for the clips `rows`: NAT best and BAD worst by every metric (MG, then FL, between), so that
    the simulated crowd's quality, which follows the metrics, has the paper's order. Only the first four metrics:
    metrics.csv need not have every one (CONTRACTS §4), and the reader must cope."""
    badness = {study.NATURAL: 0.0, **dict(zip(study.GENERATED, (1.0, 2.0))), study.CATCH: 6.0}
    scale = {
        "foot_skating": (0.05, 0.1),
        "bone_length_std": (0.001, 0.01),
        "jerk": (20, 30),
        "control_error": (0.02, 0.1),
    }
    assert tuple(scale) == study.METRIC_NAMES[:4]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow([*study.METRIC_KEYS, *scale])
        for r in rows:
            b = badness.get(r["condition"], 1.5) + rng.normal(0, 0.1)
            w.writerow([*(r[k] for k in study.METRIC_KEYS), *(lo + step * b for lo, step in scale.values())])


@contextlib.contextmanager
def pg_schema(base_url: str | None = None):
    """A fresh PostgreSQL schema for one test (run), dropped afterwards; yields a URL that uses it."""
    import psycopg

    name = "ra_" + secrets.token_hex(6)
    base_url = base_url or pg_base()
    plain = base_url.replace("postgresql+psycopg://", "postgresql://")
    with psycopg.connect(plain, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{name}"')
    sep = "&" if "?" in base_url else "?"
    try:
        yield f"{base_url}{sep}options=-csearch_path%3D{name}"
    finally:
        with psycopg.connect(plain, autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA IF EXISTS "{name}" CASCADE')
