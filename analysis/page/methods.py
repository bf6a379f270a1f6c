"""A methods paragraph written from the data, for a user to paste into a paper (stats.json "methods", methods.txt).

It states what a reviewer asks of a perceptual study and what the export alone can show: how many raters took
part and how many were excluded and why, the design and the scale, how many answers each comparison or clip got,
which stimuli were shown (a SHA-256 over the clip ids answered, and over the stimulus folder's manifest when the
report is given it), the statistics with their seed, and the tool's version. Every number comes from the rows; the
prose only joins them.
"""

import hashlib
import importlib.metadata
from pathlib import Path

import numpy as np

from moglow_eval.core import study

from ..data.filtering import only_test_rows
from .report_html import was


def tool_version() -> str:
    try:
        return importlib.metadata.version("moglow-eval")
    except importlib.metadata.PackageNotFoundError:  # run from a checkout that was never installed
        return "unknown"


def clip_set_hash(rows) -> str:
    """SHA-256 of the sorted ids of every clip in the rows: the same stimuli give the same hash."""
    cols = [c for c in ("clip_id", "clip_a", "clip_b") if c in rows.columns]
    ids = sorted(set(np.concatenate([rows[c].astype(str).to_numpy() for c in cols]))) if cols else []
    return hashlib.sha256("\n".join(ids).encode()).hexdigest()


def manifest_hash(metrics_path) -> str | None:
    """SHA-256 of manifest.csv beside the stimuli's metrics.csv (it names every clip, its video and its seed)."""
    if not metrics_path:
        return None
    manifest = Path(metrics_path).resolve().parent / "manifest.csv"
    try:
        return hashlib.sha256(manifest.read_bytes()).hexdigest()
    except OSError:
        return None


def answers_per_unit(design, test) -> tuple[str, int, int, float]:
    """(what a unit is, fewest, most, median answers per unit) over the kept test rows `test`, units as the design
    (analysis.designs.base.Design) counts them."""
    unit, n = design.answers_per_unit(test)
    return unit, int(n.min()), int(n.max()), float(n.median())


def conditions_of(rows) -> list[str]:
    """The conditions of the rows' test answers, in the study's order."""
    test = only_test_rows(rows)
    cols = [c for c in ("condition", "condition_a", "condition_b") if c in test.columns]
    return study.condition_order(np.concatenate([test[c].astype(str).to_numpy() for c in cols]))


def methods_paragraph(design, rows, kept, counts, options, statistics=None) -> str:
    """The paragraph (see the module's docstring): `rows` every answer, `kept` those of the raters kept,
    `counts` the exclusion's counts, `options` the report's settings (analysis.designs.Options), `design` the
    study's analysis design (analysis.designs.base.Design), whose words for its task, catch rule and statistics the
    paragraph joins: it names no design itself. `statistics`: the design's statistics as the report computed them
    (Design.statistics_text of its primary analysis); the design's full list where None."""
    conditions = conditions_of(rows)
    n_total, n_excl = counts["n_raters_total"], counts["n_raters_excluded"]
    catch = design.methods_catch.format(threshold=options.threshold)
    test = only_test_rows(kept)
    unit, lo, hi, med = answers_per_unit(design, test)
    n_items = test["item"].nunique() if "item" in test.columns else 0
    conds = [c for c in conditions if c != study.CATCH]
    n_kept = counts["n_raters_kept"]
    # A rater whose session came when every unit had its answers saw only catch trials: kept, but in no test
    # answer, so the sections' rater counts are smaller than this one. Said here, where a reader compares the two.
    idle = n_kept - test["rater_id"].nunique() if "rater_id" in test.columns else 0
    resamples = f"{options.n_boot} resamples, seed {options.seed}; " if design.methods_resamples else ""
    kept = f"{n_kept} raters" + (f" ({idle} of them answered no test trial)" if idle > 0 else "")
    if counts.get("n_catch_ratings", 1) and n_excl == 0:
        excluded = f"None {catch} in a catch trial, so none was excluded: {kept} and {len(test)} test answers."
    elif counts.get("n_catch_ratings", 1):
        excluded = (
            f"{n_excl} {was(n_excl)} excluded because they {catch} in at least one catch "
            f"trial, leaving {kept} and {len(test)} test answers."
        )
    else:  # e.g. votes imported from another tool
        excluded = f"The answers hold no catch trials, so no rater was excluded; {len(test)} test answers."
    parts = [
        f"{n_total} raters took part. {excluded}",
        f"Raters {design.methods_task}.",
        f"The study compared {len(conds)} conditions ({', '.join(conds)}) on {n_items} items; "
        f"there were {lo}-{hi} {unit} (median {med:g})."
        if lo != hi
        else f"The study compared {len(conds)} conditions ({', '.join(conds)}) on {n_items} items, {lo} {unit}.",
        f"The statistics are {statistics or design.methods_stats} ({resamples}family-wise error rate "
        f"{options.alpha:g}).",
        f"Stimuli: SHA-256 of the clip ids {clip_set_hash(rows)[:16]}",
    ]
    mh = manifest_hash(options.metrics_path)
    parts[-1] += f", of the stimulus manifest {mh[:16]}." if mh else "."
    parts.append(f"Analysed with moglow-eval {tool_version()}.")
    return " ".join(parts)


def methods_outline(design) -> str:
    """What a study of `design` asks and how it is analysed, in the paragraph's words, from the design alone: no
    number and no condition of the data, for a page that may not show results yet (a challenge's board before it
    publishes)."""
    return f"Raters {design.methods_task}. The statistics are {design.methods_stats}."
