"""The cells every design's export row shares (CONTRACTS §6, §8), and the flags that mark a row or a rater.

The `flags` column marks answers to look at before trusting them (FLAGS). A design's own cells are its own
(designs/); these come after them in every file.
"""

from __future__ import annotations

from sqlalchemy import select

from ..store.db import Clip, Rater

# The columns after a design's own, in every export (CONTRACTS §6, §8).
TAIL = ("trial_index", "watched_ms", "submitted_at", "external_id", "study_id", "rater_completed", "flags")
FLAGS = {
    "no_video": "the server never sent this trial's video before the answer",
    "partial_video": "the server had sent only part of this trial's video before the answer (e.g. one byte)",
    "too_fast": "the session had answers refused as arriving before the clip could have played to the end",
    # Every row of a rater whom moglow_eval.core.study.excluded_raters excludes: kept, and left out of every ranking.
    "failed_catch": "the rater failed a catch trial: the report's primary analysis and the app's ranking leave out "
    "every answer of theirs",
}
EXCLUDED = "failed_catch"
RATER_EXTRA = (Rater.external_id, Rater.study_id, Rater.completed_at)  # selected beside an answer's own columns


def row_flags(answer_flags: str, n_early: int) -> str:
    flags = set(filter(None, (answer_flags or "").split(";")))
    if n_early:
        flags.add("too_fast")
    return ";".join(sorted(flags))


def with_flag(flags: str, flag: str) -> str:
    """A row's `flags` cell with `flag` added."""
    return ";".join(sorted({*filter(None, flags.split(";")), flag}))


def rater_flags(n_early, n_no_video, n_partial) -> list[str]:
    """What makes a rater suspicious on the dashboard: answers refused as too early, answers without the video
    or with only part of it."""
    return [f for f, bad in (("too_fast", n_early), ("no_video", n_no_video), ("partial_video", n_partial)) if bad]


def common(rater_id, idx, watched, at, ext, study, completed, flags, n_early) -> dict:
    """rater_id and the TAIL cells of one row."""
    return {
        "rater_id": rater_id,
        "trial_index": idx,
        "watched_ms": "" if watched is None else watched,
        "submitted_at": at.strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
        "external_id": ext or "",
        "study_id": study or "",
        "rater_completed": int(completed is not None),
        "flags": row_flags(flags, n_early),
    }


# The columns of a row that name a clip: acr and parallel rows have one, pairwise and appropriateness rows two.
CLIP_COLUMNS = ("clip_id", "clip_a", "clip_b")


def clip_styles(s) -> dict[str, str]:
    """{clip_id: style} of the study's clips (manifest `style`, CONTRACTS §4); empty when no clip has a style,
    and the export then has no style column."""
    styles = {c: st for c, st in s.execute(select(Clip.clip_id, Clip.style)) if st}
    return styles


# A stochastic system's samples (CONTRACTS §4, §6): the sample each clip column's clip shows.
SAMPLE_COLUMNS = {"clip_id": "sample", "clip_a": "sample_a", "clip_b": "sample_b"}


def clip_samples(s) -> dict[str, str]:
    """{clip_id: sample} of the study's clips that name a sample; empty when none does, and the export then has no
    sample column."""
    return {c: name for c, name in s.execute(select(Clip.clip_id, Clip.sample)) if name}


def sample_columns(columns) -> list[str]:
    """The sample columns of an export with these columns: one per column that names a clip."""
    return [SAMPLE_COLUMNS[c] for c in CLIP_COLUMNS if c in columns]


def row_samples(row: dict, samples: dict[str, str]) -> dict[str, str]:
    """The sample cells of a row: the sample its clip, or each of its clips, shows ("" for a clip without one)."""
    return {SAMPLE_COLUMNS[c]: samples.get(row.get(c) or "", "") for c in CLIP_COLUMNS if c in row}


def row_style(row: dict, styles: dict[str, str]) -> str:
    """The style of the clips a row names: one style, or the distinct ones joined by `/` in the row's clip order
    (a pair of clips drawn in different styles)."""
    seen = []
    for col in CLIP_COLUMNS:
        st = styles.get(row.get(col) or "", "")
        if st and st not in seen:
            seen.append(st)
    return "/".join(seen)
