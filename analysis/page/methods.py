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

DESIGN_TEXT = {
    "acr": "rated each clip on its own on a five-point scale (1 = bad, 5 = excellent)",
    "pairwise": (
        "watched two clips of the same item from two conditions and chose the one that looked more natural on a "
        "five-level scale (clearly, slightly, no preference)"
    ),
    "parallel": "rated every condition of an item on one page, side by side, on a 0-100 scale (MUSHRA-like)",
    "appropriateness": (
        "watched a system's motion for the speech they heard and its motion for other speech, with the same "
        "audio, and chose the one that fitted the speech better on a five-level scale"
    ),
    "dyadic": (
        "watched two people in conversation, the same real interlocutor and the same audio in both videos, one with a "
        "system's agent motion made for that interlocutor and one with the same system's motion made for another, "
        "and chose the agent that responded more appropriately on a five-level scale"
    ),
    "semantic": (
        "watched a system's motion for an utterance and its motion for another utterance, both with the utterance's "
        "speech and captions and one word highlighted, and chose the motion that better showed the meaning of that "
        "word on a five-level scale"
    ),
}
CATCH_TEXT = {
    "acr": "rated a deliberately broken clip (BAD) at {threshold} or above",
    "parallel": "rated a deliberately broken clip (BAD) at or above the real motion on the same page",
}
CATCH_PAIR = "preferred a deliberately broken clip (BAD) to the real motion"
STATS_TEXT = {
    "acr": (
        "a one-way ANOVA with Tukey's HSD, a linear mixed model with crossed random intercepts for raters and "
        "clips, and cluster-bootstrap intervals resampling raters and clips"
    ),
    "pairwise": (
        "two-sided sign tests per pair (Holm-adjusted) and a Bradley-Terry model with Davidson's tie parameter, "
        "reported on an Elo scale (400 points per factor of ten in the odds), with intervals and rank intervals "
        "from a bootstrap over raters"
    ),
    "parallel": "Wilcoxon signed-rank tests on page-paired ratings, Holm-adjusted",
    "appropriateness": (
        "the mean appropriateness score with Student-t intervals and sign tests against chance, Holm-adjusted"
    ),
    "dyadic": (
        "the mean interlocutor appropriateness score with Student-t intervals and sign tests against no preference, "
        "Holm-adjusted"
    ),
    "semantic": (
        "the mean semantic alignment score with Student-t intervals and sign tests against chance, Holm-adjusted"
    ),
}


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
    """(what a unit is, fewest, most, median answers per unit) over the kept test rows `test`."""
    if design == "pairwise":
        lo = np.minimum(test["condition_a"], test["condition_b"])
        hi = np.maximum(test["condition_a"], test["condition_b"])
        n, unit = test.groupby([lo, hi]).size(), "votes per pair of conditions"
    elif design in study.MISMATCH_COLUMN:
        n, unit = test.groupby("condition_a").size(), "votes per system"
    else:
        n, unit = test.groupby("clip_id").size(), "ratings per clip"
    return unit, int(n.min()), int(n.max()), float(n.median())


def conditions_of(rows) -> list[str]:
    """The conditions of the rows' test answers, in the study's order."""
    test = only_test_rows(rows)
    cols = [c for c in ("condition", "condition_a", "condition_b") if c in test.columns]
    return study.condition_order(np.concatenate([test[c].astype(str).to_numpy() for c in cols]))


def methods_paragraph(design, rows, kept, counts, options) -> str:
    """The paragraph (see the module's docstring): `rows` every answer, `kept` those of the raters kept,
    `counts` the exclusion's counts, `options` the report's settings (analysis.designs.Options)."""
    conditions = conditions_of(rows)
    n_total, n_excl = counts["n_raters_total"], counts["n_raters_excluded"]
    catch = CATCH_TEXT.get(design, CATCH_PAIR).format(threshold=options.threshold)
    test = only_test_rows(kept)
    unit, lo, hi, med = answers_per_unit(design, test)
    n_items = test["item"].nunique() if "item" in test.columns else 0
    conds = [c for c in conditions if c != study.CATCH]
    if counts.get("n_catch_ratings", 1):
        excluded = (
            f"{n_excl} {'was' if n_excl == 1 else 'were'} excluded because they {catch} in at least one catch "
            f"trial, leaving {counts['n_raters_kept']} raters and {len(test)} test answers."
        )
    else:  # e.g. votes imported from another tool
        excluded = f"The answers hold no catch trials, so no rater was excluded; {len(test)} test answers."
    parts = [
        f"{n_total} raters took part. {excluded}",
        f"Raters {DESIGN_TEXT[design]}.",
        f"The study compared {len(conds)} conditions ({', '.join(conds)}) on {n_items} items; "
        f"there were {lo}-{hi} {unit} (median {med:g})."
        if lo != hi
        else f"The study compared {len(conds)} conditions ({', '.join(conds)}) on {n_items} items, {lo} {unit}.",
        f"The statistics are {STATS_TEXT[design]} ({options.n_boot} resamples, seed {options.seed}; "
        f"family-wise error rate {options.alpha:g}).",
        f"Stimuli: SHA-256 of the clip ids {clip_set_hash(rows)[:16]}",
    ]
    mh = manifest_hash(options.metrics_path)
    parts[-1] += f", of the stimulus manifest {mh[:16]}." if mh else "."
    parts.append(f"Analysed with moglow-eval {tool_version()}.")
    return " ".join(parts)
