"""The files of a stimulus folder (CONTRACTS.md §4): the folder itself, manifest.csv, metrics.csv, fmd.csv,
items.csv and items/ITEM.npz. What goes into them is decided by make_stimuli; their layout is decided here."""

import contextlib
import csv
import io
import logging
import shutil
from pathlib import Path

import numpy as np

from moglow_eval.core import cli, study, whole_files
from moglow_eval.core.cli import UserError

from ..data.systems import canonical_placement
from ..motion import skeleton
from ..motion.features import to_world
from .build_index import INDEX
from .items import CATCH, TRAINING

log = logging.getLogger(__name__)

MANIFEST_COLUMNS = [
    "clip_id",
    "condition",
    "role",
    "item",
    "video",
    "motion",
    "seed",
    "frames",
    "fps",
    "width",
    "height",
]
METRICS_COLUMNS = [*study.METRIC_KEYS, *study.METRIC_NAMES]
ITEMS_COLUMNS = ["item", "role", "category", "take", "start_frame", "frames", "fps", "control"]
FMD_COLUMNS = ["condition", "n_windows", "fmd"]
SUBFOLDERS = ("videos", "motion", "sheets")  # one file per clip in each, named by its clip id
# Made before a build's first folder and removed once its tables are written: the folders a killed build leaves
# (no manifest, and no build index before a study's render) are its own, for the next build to replace.
BUILDING = ".stimuli-building"
# What a stimulus set holds at its top, which a new build replaces: its folders, then its tables.
SET_ENTRIES = (*SUBFOLDERS, "items", "audio_check", "manifest.csv", "metrics.csv", "items.csv", "c2st.csv",
               "c2st_features.csv", "audio_check.csv", study.MEASURES_FILE, study.GESTURE_FILE)  # fmt: skip


class StimuliError(UserError):
    """Bad input to make_stimuli; one line naming the file or option."""


def refuse_existing(out, force):
    """StimuliError when `out` holds a stimulus set and `force` is not given; a UserError when it is empty, or it
    or the nearest of its folders that exists is a file (cli.folder_to_write: else the set's first file would be
    refused only after the work)."""
    out = cli.folder_to_write(out, "the stimulus folder")
    if (out / "manifest.csv").exists() and not force:
        raise StimuliError(f"{out}: already holds a stimulus set (manifest.csv); pass --force to replace it")
    # A folder of the user's own (their study's items/ or motion/, beside --out .) with the name of one a set
    # holds is not a set's to replace, --force or not (--force replaces a set). A killed build's are marked.
    theirs = next((n for n in SET_ENTRIES if (out / n).exists()), None)
    if theirs and not any((out / n).exists() for n in ("manifest.csv", INDEX, BUILDING)):
        shown = f"{theirs}/" if (out / theirs).is_dir() else theirs
        raise StimuliError(
            f"--out {out}: holds {shown}, which is no stimulus set's (there is no manifest.csv) and a build would "
            "replace: give another folder"
        )


def prepare_out(out, force, keep_videos=False):
    """An empty stimulus folder at `out` with its clip subfolders; an existing set is replaced only with `force`.
    `keep_videos`: the videos and sheets stay, for the build's index to reuse (build_index; the render removes
    those no clip names any more)."""
    out = Path(out)
    refuse_existing(out, force)
    out.mkdir(parents=True, exist_ok=True)
    (out / BUILDING).touch()
    kept = ("videos", "sheets") if keep_videos else ()
    for name in SET_ENTRIES:
        if (out / name).is_dir() and name not in kept:
            shutil.rmtree(out / name)
        elif name.endswith(".csv"):
            (out / name).unlink(missing_ok=True)
    for sub in SUBFOLDERS:
        (out / sub).mkdir(parents=True, exist_ok=True)
    return out


@contextlib.contextmanager
def nothing_left_on_failure(out):
    """Within the block, build a stimulus set at `out`; if the block fails (any exception, Ctrl-C included), remove
    what it left there: `out` itself and any parent folder it made, else every entry of `out` that was not there
    before and the set's clip folders it left empty (CONTRACTS §4: a failed build leaves nothing behind). What was
    there before is kept, so a refusal to replace an existing set touches nothing."""
    out = Path(out).absolute()
    top = None  # the outermost folder the build creates, when it creates `out`
    for folder in (out, *out.parents):
        if folder.exists():
            break
        top = folder
    before = {p.name for p in out.iterdir()} if out.is_dir() else set()
    try:
        yield
    except BaseException:
        if (out / INDEX).is_file():
            # A study's build had begun to render: its finished clips stay for the same command to resume with,
            # and the folder holds no manifest, so it is no stimulus set meanwhile.
            for part in [*out.glob("videos/*.part.*"), *out.glob("sheets/*.part.*")]:
                part.unlink(missing_ok=True)
            (out / "manifest.csv").unlink(missing_ok=True)
            log.warning(f"{out}: the build stopped; its finished clips are kept: run the same command to go on")
            raise
        if top is not None:
            shutil.rmtree(top, ignore_errors=True)
        elif out.is_dir():
            for p in out.iterdir():
                if p.name not in before:
                    shutil.rmtree(p, ignore_errors=True) if p.is_dir() and not p.is_symlink() else p.unlink()
                elif p.name in SUBFOLDERS and p.is_dir() and not any(p.iterdir()):
                    p.rmdir()  # emptied and remade by prepare_out (--force), nothing in it
        raise


def clip_files(out, cid):
    """(motion .npz, video .mp4, contact sheet .png) paths of clip `cid` in stimulus folder `out`."""
    out = Path(out)
    return out / "motion" / f"{cid}.npz", out / "videos" / f"{cid}.mp4", out / "sheets" / f"{cid}.png"


def manifest_row(cid, condition, item, seed, frames, fps, size):
    """One manifest.csv row (paths relative to the stimulus folder)."""
    return dict(
        clip_id=cid,
        condition=condition,
        role=item["role"],
        item=item["id"],
        video=f"videos/{cid}.mp4",
        motion=f"motion/{cid}.npz",
        seed=seed,
        frames=frames,
        fps=f"{fps:g}",
        width=size,
        height=size,
    )


def write_csv(path, columns, rows, *, line_end="\r\n"):
    """A table written whole or not at all: a build killed while writing its manifest leaves the earlier one, not
    half of a new one. The stimulus folder's tables keep the csv module's dialect (CRLF line ends), so a rebuild's
    files stay byte-identical to earlier builds'; newer tables (the intake's) take the project's LF."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator=line_end)
    w.writeheader()
    w.writerows(rows)
    whole_files.write_whole(path, buf.getvalue())


def write_tables(out, manifest, metrics_rows, fmd, extra_metrics=()):
    """manifest.csv (rows in the given order), metrics.csv (6 significant digits, nan for undefined; `extra_metrics`
    columns after study.METRIC_NAMES: a gesture study's measures) and, when there are FMD rows, fmd.csv."""
    out = Path(out)
    # A study of your own motion may also say which item's motion each clip shows (appropriateness) and that its
    # videos carry sound (CONTRACTS §10).
    # The built-in study says which clips' bones were set to the actor's (generation.motion.rigid). A study drawn in
    # more than one style says each clip's ([render] style), and one with a stochastic system each clip's sample.
    extra = [c for c in ("motion_item", "audio", "postprocess", "style", "sample") if any(c in row for row in manifest)]
    write_csv(out / "manifest.csv", MANIFEST_COLUMNS + extra, manifest)
    write_csv(
        out / "metrics.csv",
        [*METRICS_COLUMNS, *extra_metrics],
        [{k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()} for row in metrics_rows],
    )
    if fmd:
        write_csv(out / "fmd.csv", FMD_COLUMNS, fmd)
    (out / BUILDING).unlink(missing_ok=True)  # a stimulus set now: its manifest says so


def summary_text(metrics_rows):
    """Per-condition means (sd) of every metric over test and catch clips, as a printable table."""
    import pandas as pd  # here: the render workers import this module's neighbours, not pandas

    df = pd.DataFrame(metrics_rows)
    df = df[df.role != TRAINING]
    g = df.groupby(["role", "condition"])
    names = [m for m in study.METRIC_NAMES if df[m].notna().any()]  # a study without control has no control metrics
    mean, sd = g[names].mean(), g[names].std()
    table = mean.map(lambda v: f"{v:.3g}") + " (" + sd.map(lambda v: f"{v:.2g}") + ")"
    table.insert(0, "n", g.size())
    return table.to_string()


def write_items(folder, items, arrays, fps):
    """items.csv plus items/ITEM.npz (control, real history) for the items another system must generate."""
    folder = Path(folder)
    (folder / "items").mkdir(parents=True, exist_ok=True)
    with open(folder / "items.csv", "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(ITEMS_COLUMNS)
        for k, it in enumerate(items):
            if it["role"] == CATCH:
                continue
            rel = f"items/{it['id']}.npz"
            _write_item(folder / rel, arrays, k, fps)
            frames = arrays["c"][k].shape[0]
            w.writerow([it["id"], it["role"], it["category"], it["take"], it["start"], frames, f"{fps:g}", rel])


def _write_item(path, arrays, k, fps):
    # The real frames just before the window, placed so that the window starts at the origin
    # facing +Z: a system can continue them, as MG does.
    hist_x = np.concatenate([arrays["hist"][k], arrays["x"][k][:1]])
    hist_c = np.concatenate([arrays["hist_c"][k], arrays["c"][k][:1]])
    hist = canonical_placement(to_world(hist_x, hist_c), fps, frame=-1)[:-1]
    np.savez_compressed(
        path,
        control=arrays["c"][k],
        history=arrays["hist"][k],
        history_control=arrays["hist_c"][k],
        history_joints=hist,
        fps=np.float64(fps),
        frames=np.int64(arrays["c"][k].shape[0]),
        joint_names=np.array(skeleton.JOINT_NAMES),
        parents=skeleton.PARENTS,
    )
