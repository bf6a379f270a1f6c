"""A running study's folders and stored state, for the tests of a condition joining it (add-condition): stimulus
folders that keep CONTRACTS §4's one-size rule, and every row and file as it is, to compare before and after."""

import csv
import os
import shutil
from pathlib import Path

from sqlalchemy import MetaData, select

N_ITEMS = 3


def one_size(folder: Path, ref: Path) -> None:
    """Every video of a stimulus folder the same bytes as `ref` (made by the stimulus encoder), and every motion
    file the manifest names present: a set that keeps CONTRACTS §4's one-size rule, as make_stimuli writes one."""
    for v in (folder / "videos").glob("*.mp4"):
        shutil.copyfile(ref, v)
        os.utime(v, (1.7e9, 1.7e9))  # and one file time (make_stimuli's same_mtime)
    for row in csv.DictReader(open(folder / "manifest.csv")):
        (folder / row["motion"]).parent.mkdir(exist_ok=True)
        (folder / row["motion"]).write_bytes(b"motion of " + row["clip_id"].encode())


def dump(engine) -> dict:
    """{table: {primary key: row}} of every row of every table."""
    meta = MetaData()
    meta.reflect(engine)
    out = {}
    with engine.connect() as conn:
        for t in meta.sorted_tables:
            pk = [c.name for c in t.primary_key.columns]
            out[t.name] = {tuple(r._mapping[k] for k in pk): tuple(r) for r in conn.execute(select(t))}
    return out


def folder_state(manifest: Path) -> dict:
    """{relative path: bytes} of a stimulus folder's files (the videos by name and size only)."""
    root = manifest.parent
    return {
        str(p.relative_to(root)): (p.stat().st_size if p.suffix == ".mp4" else p.read_bytes())
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }
