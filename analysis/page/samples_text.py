"""What the report says of a stochastic system's samples (analysis.stats.samples): a section, a sentence for the
methods paragraph and a line for the console."""

from __future__ import annotations

import html

import numpy as np

from .report_html import p_equals, table

NOTE = (
    "sigma_sample: the standard deviation of a sample's true score around its item's (a random-effects ANOVA of "
    "samples nested in items, per condition), in the design's score: a rating, or a preference from -2 to 2 "
    "seen from the sample's side. sample_range: the highest sample mean less the lowest, averaged over items. "
    "The intervals above resample clips, and each sample is a clip of its own, so they include this spread."
)


def _varied(spread) -> bool:
    return bool((spread["df_samples"] > 0).any())


def samples_html(spread) -> str:
    """The report's section on the samples; "" where no condition has samples."""
    if spread.empty:
        return ""
    if not _varied(spread):
        words = (
            "One sample was drawn per item (the study file's <code>[samples] draw = \"item\"</code>): each system's "
            "spread between samples is part of its spread between items, in every interval, and cannot be told apart."
        )
    else:
        words = 'Each rater saw a sample drawn for them (<code>[samples] draw = "rater"</code>).'
    return f"<h2>Samples of stochastic systems</h2><p>{words}</p>{table(spread.set_index('condition'), ('p',))}" + (
        f"<p class=note>{html.escape(NOTE)}</p>"
    )


def samples_sentence(spread) -> str:
    """The methods paragraph's sentence on the samples; "" where no condition has samples."""
    if spread.empty:
        return ""
    names = ", ".join(spread["condition"])
    k = int(spread["samples_per_item"].max())
    if not _varied(spread):
        return (
            f"{names} gave several samples per item; one was drawn per item with a fixed seed, so the spread between "
            "samples is part of the spread between items in every interval."
        )
    parts = []
    for r in spread.itertuples():
        sigma = "n/a" if not np.isfinite(r.sigma_sample) else f"{r.sigma_sample:.2f}"
        parts.append(f"{r.condition}: sigma_sample = {sigma}, {p_equals(r.p)}")
    return (
        f"{names} gave up to {k} samples per item, and each rater was shown one drawn per rater and unit with a "
        "seeded hash; the spread between samples was estimated by a random-effects ANOVA of samples nested in "
        f"items ({'; '.join(parts)}), and the intervals, which resample clips, include it."
    )


def samples_console(spread) -> str:
    if spread.empty:
        return ""
    lines = ["Samples of stochastic systems (spread between a system's samples of one item):"]
    for r in spread.itertuples():
        sigma = "n/a" if not np.isfinite(r.sigma_sample) else f"{r.sigma_sample:.3f}"
        lines.append(
            f"  {r.condition:<14} {r.samples_per_item} per item, {r.answers} answers, sigma_sample {sigma}, "
            f"{p_equals(r.p)}"
        )
    return "\n".join(lines)
