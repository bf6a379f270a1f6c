"""What every test design (CONTRACTS §8) is to the analysis: one small interface, which each design implements.

`python -m analysis.report FILE` (report.py) knows no design: it asks each one in the registry whether the file's
columns are its own, then has that design prepare the rows, analyse them with and without the catch-trial exclusion,
draw its figures, and write its stats.json keys, its report.html parts and its console summary. The statistics
themselves are pure functions on the exported DataFrame (stats/anova.py, designs/pairwise/preference.py,
designs/parallel/mushra.py, designs/appropriateness/mas.py); a design module adapts them to this interface."""

import html
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ..data.filtering import DEFAULT_THRESHOLD
from ..data.load import AnalysisError
from ..page import report_html
from ..page.study_text import rename_reference

MIXED_MAX_LEVELS = 2000  # the mixed models are skipped when the raters and the clips both outnumber this
# The ordinal fit works on every rating (no sufficient statistics exist for it): ~4 s for 50,000 ratings on a
# busy 2-core machine, twice per report, so beyond this many test ratings it is skipped unless asked for.
ORDINAL_MAX_RATINGS = 50_000


@dataclass(frozen=True)
class Options:
    """The report's settings (analysis.report's flags, plain data); each design reads those it uses.

    metrics_path: the stimuli's metrics.csv (and the c2st.csv beside it), each metric correlated with the clips'
    mean ratings; None: none. threshold: the catch rating at or above which an acr rater is excluded. mixed, ordinal:
    fit the linear and the ordinal mixed model. seed, n_boot: the bootstraps'. alpha: the family-wise error rate.
    mixed_max_levels: the mixed models are skipped when the raters and the clips both outnumber it;
    ordinal_max_ratings: the ordinal model above this many test ratings. reference_name: the reference's own name
    for NAT (analysis.page.study_text). reference: pairwise, the condition at strength 0 and Elo 1000 (None: NAT, else
    the first by name). indifference: pairwise, the Elo margin within which neighbours share a group
    (elo_ranks.rank_table; the app's PAIRING_INDIFFERENCE; 0: groups by rank intervals alone)."""

    metrics_path: str | None = None
    threshold: int = DEFAULT_THRESHOLD
    mixed: bool = True
    seed: int = 0
    n_boot: int = 2000
    alpha: float = 0.05
    mixed_max_levels: int = MIXED_MAX_LEVELS
    ordinal: bool = True
    ordinal_max_ratings: int = ORDINAL_MAX_RATINGS
    reference_name: str | None = None
    reference: str | None = None
    indifference: float = 0.0


@dataclass
class Prepared:
    """A file's rows, ready to analyse: all of them, those kept by the catch-trial exclusion, and the counts."""

    rows: pd.DataFrame
    kept: pd.DataFrame
    counts: dict
    extra: dict  # what else a design read beside the file (acr: metrics, the C2ST table)


@dataclass(frozen=True)
class Standings:
    """A task's results as a board publishes them: what the score is, and one row per system, best first.

    score: the score's short name, a table's heading ("MOS", "Elo"). about: one sentence for the reader: the scale,
    the interval, and what decides the ranks. count: what `n` counts ("ratings" or "votes"). rows: {"system",
    "score", "low", "high" (the interval), "n", "rank_low", "rank_high" (the rank interval), "group" (1 = best)}."""

    score: str
    about: str
    count: str
    rows: list


def ranked(rows, better) -> list[dict]:
    """`rows` ({"system", "score", "low", "high", "n"}) best score first, with rank intervals and groups where the
    design's tests order systems: `better` holds (a, b) for each pair its test says a beats b. A system ranks at
    best 1 + the systems decided above it and at worst K - those decided below it; groups join neighbours in score
    order while their rank intervals overlap, as the pairwise ranking's groups do."""
    order = sorted(rows, key=lambda r: (r["score"] is None, -(r["score"] or 0.0), r["system"]))
    names = [r["system"] for r in order]
    out, group, reach = [], 0, 0
    for r in order:
        me = r["system"]
        low = 1 + sum((other, me) in better for other in names)
        high = len(names) - sum((me, other) in better for other in names)
        group += low > reach  # disjoint from every rank interval above: a new group starts
        reach = max(reach, high)
        out.append({**r, "rank_low": low, "rank_high": high, "group": group})
    return out


# The Options fields only some designs read, and their flags: a design that does not read one refuses it where it
# is given (unchanged from its default, it is not given), as a flag without effect would otherwise pass unsaid.
DESIGN_OPTIONS = {"reference": "--reference", "indifference": "--indifference"}


class Design:
    name = ""  # as moglow_eval.core.study.DESIGNS spells it
    steps = 0  # progress-bar steps of one report (0: no bar)
    reads = frozenset()  # which of DESIGN_OPTIONS this design reads
    # The methods paragraph's words for this design (analysis.page.methods): what a rater did ("Raters ..."), what
    # failing a catch trial means ("excluded because they ..."; {threshold}: the report's), and the statistics.
    methods_task = ""
    methods_catch = "preferred a deliberately broken clip (BAD) to the real motion"
    methods_stats = ""
    methods_resamples = True  # whether those statistics resample (Options.n_boot, seed): counted and seeded then
    methods_mixed = ""  # the clause of methods_stats naming its mixed model: said only where one was fitted

    def statistics_text(self, result) -> str:
        """methods_stats as the report computed them: without the mixed model's clause where the primary analysis
        `result` holds no fitted model (--no-mixed, more levels than --mixed-max-levels, a model undefined)."""
        fitted = bool((result.get("mixed") or {}).get("fixed_effects"))
        return self.methods_stats if fitted else self.methods_stats.replace(self.methods_mixed, "")

    def answers_per_unit(self, test) -> tuple[str, pd.Series]:
        """(what a unit of the methods paragraph's count is, the kept test answers per unit): ratings per clip
        unless the design counts otherwise."""
        return "ratings per clip", test.groupby("clip_id").size()

    def detects(self, columns: set[str]) -> bool:
        """Whether a CSV file with these header columns is this design's export (exactly one design says so)."""
        raise NotImplementedError

    def prepare(self, path, options: Options) -> Prepared:
        """Read and check the file, and apply the catch-trial exclusion; AnalysisError, one line, for bad input."""
        raise NotImplementedError

    def analyse(self, data: Prepared, options: Options, progress) -> tuple[dict, dict]:
        """(the analysis of the kept rows, that of every row): the design's statistics, DataFrames in, dicts out."""
        raise NotImplementedError

    def figures(self, data: Prepared, kept: dict, everyone: dict, folder: Path) -> dict[str, Path]:
        """{name: path} of the PNG figures drawn into `folder`."""
        raise NotImplementedError

    def stats_head(self) -> dict:
        """stats.json's first keys: the design's name (acr: none, CONTRACTS §7)."""
        return {"design": self.name}

    def stats_json(self, kept: dict, everyone: dict) -> dict:
        """stats.json's keys after the counts: the design's results, with "without_exclusion"."""
        raise NotImplementedError

    def html(self, meta: dict, counts: dict, kept: dict, everyone: dict, figs: dict) -> list[str]:
        """report.html's parts (html.page wraps them)."""
        raise NotImplementedError

    def console(self, counts: dict, kept: dict, everyone: dict) -> str:
        """The summary printed on stdout."""
        raise NotImplementedError

    def standings(self, doc: dict) -> Standings:
        """The results a board publishes (analysis.board), read from the report's stats.json `doc` (its primary
        analysis, with the rater exclusion). KeyError, TypeError or ValueError where `doc` is not this design's."""
        raise NotImplementedError


def exclude(df, failed) -> tuple[pd.DataFrame, dict]:
    """(the rows of raters not in `failed`, the exclusion's counts) for a design whose raters are excluded when
    they fail any catch trial."""
    drop = df["rater_id"].isin(failed)
    kept = df[~drop]
    counts = {
        "n_ratings_total": int(len(df)),
        "n_ratings_removed": int(drop.sum()),
        "n_ratings_kept": int(len(kept)),
        "n_raters_total": int(df["rater_id"].nunique()),
        "n_raters_excluded": len(failed),
        "n_raters_kept": int(kept["rater_id"].nunique()),
        "excluded_raters": failed,
        "n_catch_ratings": int((df["role"] == "catch").sum()),
    }
    return kept, counts


class FailedCatchDesign(Design):
    """A design whose raters are excluded when they fail any catch trial (every design but acr); its statistics
    are one `analyse(df, ...)` function, run on the kept rows and on every row."""

    def load(self, path) -> pd.DataFrame:
        """The file's rows, checked (AnalysisError names the file and line)."""
        raise NotImplementedError

    def failed_raters(self, df) -> list[str]:
        raise NotImplementedError

    def analyse_rows(self, df, options: Options) -> dict:
        raise NotImplementedError

    def section_json(self, res) -> dict:
        raise NotImplementedError

    def section_html(self, res) -> list[str]:
        raise NotImplementedError

    def console_lines(self, kept) -> list[str]:
        raise NotImplementedError

    def prepare(self, path, options):
        df = self.load(path)
        kept, counts = exclude(df, self.failed_raters(df))  # the catch rules key on NAT: before any renaming
        if not (kept["role"] == "test").any():
            raise AnalysisError(f"{path}: every rater failed the catch trials; no test answers are left")
        name = options.reference_name
        for col in ("condition", "condition_a", "condition_b"):
            if name and col in df.columns:
                df, kept = rename_reference(df, name, col), rename_reference(kept, name, col)
        return Prepared(df, kept, counts, {})

    def analyse(self, data, options, progress):
        return self.analyse_rows(data.kept, options), self.analyse_rows(data.rows, options)

    def stats_json(self, kept, everyone):
        return {**self.section_json(kept), "without_exclusion": self.section_json(everyone)}

    def html(self, meta, counts, kept, everyone, figs):
        def section(res, title):
            return "\n".join([f"<h2>{html.escape(title)}</h2>", *self.section_html(res)])

        return [
            f"<h1>Perceptual test report ({self.name})</h1><p class=note>{html.escape(meta['input'])} · generated "
            f"{html.escape(meta['generated_at'])} · bootstrap seed {meta['seed']}</p>",
            f"<h2>Summary</h2><p>{counts['n_ratings_total']} rows from "
            f"{report_html.count(counts['n_raters_total'], 'rater')}. "
            f"{report_html.excluded_text(counts, 'failed a catch trial')}, removing "
            f"{counts['n_ratings_removed']} rows; {counts['n_ratings_kept']} were kept.</p>",
            *[f"<p>{report_html.img(f)}</p>" for f in figs.values()],
            section(kept, "With the rater exclusion (primary analysis)"),
            section(everyone, "Without the exclusion (all raters)"),
            "<h2>Excluded raters</h2><p>" + (html.escape(", ".join(counts["excluded_raters"])) or "none") + "</p>",
        ]

    def console(self, counts, kept, everyone):
        lines = [
            f"Design {self.name}: {counts['n_ratings_total']} rows, {counts['n_ratings_removed']} removed, "
            f"{counts['n_ratings_kept']} kept (raters: {counts['n_raters_total']} total, "
            f"{counts['n_raters_excluded']} excluded for a failed catch trial)",
            "",
        ]
        return "\n".join(lines + self.console_lines(kept))
