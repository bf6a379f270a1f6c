"""What the report says of the stimuli's objective measures beside the human result (analysis.stats.metric_agreement):
a section, a sentence for the methods paragraph and lines for the console."""

from __future__ import annotations

import html

import numpy as np
import pandas as pd

from .report_html import table

BETTER = {"lower": "lower", "higher": "higher", "reference": "nearer the reference"}


def _span(value, low, high, digits=3) -> str:
    if not np.isfinite(value):
        return ""
    inner = f" [{low:.{digits}g}, {high:.{digits}g}]" if np.isfinite(low) and np.isfinite(high) else ""
    return f"{value:.{digits}g}{inner}"


def measures_table(values, agreement) -> pd.DataFrame:
    """One row per measure: each system's value [95% interval], which way is better, tau [interval], systems."""
    systems = list(dict.fromkeys(values["system"]))
    rows = []
    for m in dict.fromkeys(values["measure"]):
        mine = values[values["measure"] == m].set_index("system")
        row = {"measure": m}
        for s in systems:
            row[s] = _span(*mine.loc[s, ["value", "low", "high"]]) if s in mine.index else ""
        a = agreement[agreement["measure"] == m]
        if len(a):
            a = a.iloc[0]
            row["better"] = BETTER.get(a["direction"], a["direction"])
            row["Kendall tau [95%]"] = _span(a["tau"], a["low"], a["high"], 2) or "n/a"
            row["systems"] = int(a["n_systems"])
        rows.append(row)
    return pd.DataFrame(rows).set_index("measure")


def measures_html(values, agreement, score, notes, n_boot) -> str:
    """The report's section; `score` the human score's name (the design's), `notes` measures.csv's rows."""
    if values.empty:
        return ""
    intro = (
        f"Each system's value is its mean over items of its matched test clips, with a 95% bootstrap interval over "
        f"items ({n_boot} resamples). Kendall tau is the rank agreement of the measure with the {html.escape(score)} "
        "across systems: +1 orders the systems as people did, -1 the reverse, the measure read the way it is "
        "better (lower, higher, or nearer the reference's value); its interval resamples the items and draws each "
        "system's human score from its 95% interval. Definitions and settings: docs/metrics.md and measures.csv."
    )
    skipped = notes[notes["status"] == "skipped"] if len(notes) else notes
    why = ""
    if len(skipped):
        items = "".join(f"<li>{html.escape(r.measure)}: {html.escape(r.reason)}</li>" for r in skipped.itertuples())
        why = f"<p>Not measured for this study:</p><ul>{items}</ul>"
    return (
        "<h2>Objective measures and how far each agrees with people</h2>"
        f"<p>{intro}</p>{table(measures_table(values, agreement))}{why}"
    )


def measures_sentence(notes, agreement, score, n_boot, seed) -> str:
    """The methods paragraph's sentence on the measures; "" without any."""
    if agreement.empty:
        return ""
    measured = notes[notes["status"] != "skipped"] if len(notes) else pd.DataFrame(columns=["measure", "settings"])
    by_settings = {}  # measures that share their settings (the Hellinger distances) are named together
    for r in measured.itertuples():
        if r.measure in set(agreement["measure"]):
            by_settings.setdefault(r.settings, []).append(r.measure)
    named = [f"{', '.join(ms)} ({s})" if s else ", ".join(ms) for s, ms in by_settings.items()]
    named = named or list(agreement["measure"])
    return (
        f"Objective measures of the stimuli were {'; '.join(named)}; each system's value is its mean over items with "
        f"a 95% bootstrap interval over items ({n_boot} resamples, seed {seed}), and its rank agreement with the "
        f"{score} is Kendall's tau-b with an interval from the same resamples, each system's score drawn from a "
        "normal distribution fitted to its 95% interval."
    )


def measures_console(agreement, score) -> str:
    if agreement.empty:
        return ""
    lines = [f"Objective measures against the {score} (Kendall tau, 95% interval; systems):"]
    for r in agreement.itertuples():
        tau = _span(r.tau, r.low, r.high, 2) or "n/a"
        lines.append(f"  {r.measure:<24} {tau:<24} {r.n_systems}")
    return "\n".join(lines)
