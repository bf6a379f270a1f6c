"""`python -m analysis.report ratings.csv [--out report/]`: the report of a perceptual test, whatever its design.

Writes OUT/stats.json (CONTRACTS.md §7, §8), OUT/figures/*.png and OUT/report.html (figures embedded, opens
offline), and prints a summary. The file's design is told by its columns (designs/); that design prepares,
analyses and reports the rows, with the catch-trial rater exclusion and without it ("without_exclusion").
"""

import html
import json
import os
import sys
import time
from pathlib import Path

import pandas as pd
from tqdm import tqdm

from moglow_eval.core import cli, study, tables, user_files, whole_files

from .data.filtering import DEFAULT_THRESHOLD
from .data.load import AnalysisError, load_measure_clips, load_measure_notes
from .designs import Options, check_design_options, design_of
from .designs.base import MIXED_MAX_LEVELS, ORDINAL_MAX_RATINGS
from .page import report_html
from .page.measures_text import measures_console, measures_html, measures_sentence
from .page.methods import methods_paragraph
from .page.samples_text import samples_console, samples_html, samples_sentence
from .page.study_text import reference_from_study_file
from .stats.metric_agreement import item_table, rank_agreement, system_values
from .stats.samples import sample_scores, sample_spread


def _prepare_out(out):
    """The report folder, created; a file in the way or a place we cannot write is the --out flag's problem."""
    try:
        (out / "figures").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AnalysisError(f"--out {out}: cannot create the report folder ({exc.strerror or exc})") from None
    if not os.access(out, os.W_OK | os.X_OK) or not os.access(out / "figures", os.W_OK | os.X_OK):
        raise AnalysisError(f"--out {out}: folder is not writable")


TARGET_COLUMN = "target_raters"  # the app's export: how many raters fill the study (CONTRACTS §6)


def _study_column(path, column) -> str | None:
    """A column the app's export repeats on every row (a study's setting), read from the first row; None where
    the export has no such column or it is empty."""
    # Read after the design's own reader accepted the file; a cell it could not decode only spoils this one column.
    try:
        with user_files.csv_rows(path, tables.MAX_BYTES, AnalysisError) as (_, rows):
            row = next((r for _, r in rows), None)
    except AnalysisError:  # a bad cell (the design's reader names what it reads); a missing file, named there too
        return None
    raw = (row or {}).get(column)
    return None if raw is None or raw.strip() == "" else raw


def study_reference(path) -> str | None:
    """The reference's own name the export carries (a study of your own motion, CONTRACTS §6), None without it."""
    raw = _study_column(path, study.REFERENCE_NAME)
    if raw is None or raw.strip() == study.NATURAL:
        return None
    if not study.CONDITION_NAME.fullmatch(raw.strip()):
        raise AnalysisError(f"{path}:2: {study.REFERENCE_NAME} {raw[:40]!r} is not a condition name")
    return raw.strip()


def study_target(path) -> int | None:
    """The export's target_raters (every row holds the same), None in an export without the column."""
    raw = _study_column(path, TARGET_COLUMN)
    if raw is None:
        return None
    if not (raw.strip().isascii() and raw.strip().isdigit() and len(raw.strip()) <= 9):
        raise AnalysisError(f"{path}:2: {TARGET_COLUMN} {raw[:20]!r} is not a whole number")
    return int(raw)


def shortfall_note(n_raters: int, target: int | None) -> str | None:
    """A sentence for the summary and the report when the ratings come from fewer raters than the study needs."""
    if target is None or n_raters >= target:
        return None
    return (
        f"note: ratings from {n_raters} raters, fewer than the {target} this study needs to fill ({TARGET_COLUMN} in "
        "the export): the study did not fill, and every figure here rests on fewer answers than it was planned for"
    )


def objective_measures(design, doc, options):
    """(each system's values, their rank agreement, the human score's name, measures.csv's notes) of the stimuli's
    metrics.csv against the design's per-system score (its `standings`, read from the report's stats.json `doc`);
    None without --metrics."""
    if not options.metrics_path:
        return None
    clips = load_measure_clips(options.metrics_path)
    notes = load_measure_notes(options.metrics_path)
    reference = options.reference_name or study.NATURAL
    clips["condition"] = clips["condition"].replace({study.NATURAL: reference})
    keys = {*study.METRIC_KEYS, "matched"}
    measures = [c for c in clips.columns if c not in keys and clips[c].notna().any()]
    standing = design.standings(doc)
    scores = pd.DataFrame(standing.rows, columns=["system", "score", "low", "high"]).astype(
        {"score": float, "low": float, "high": float}
    )
    tables = item_table(clips, measures)
    values = system_values(tables, options.n_boot, options.seed)
    agreement = rank_agreement(tables, scores, reference, options.n_boot, options.seed)
    return values, agreement, standing.score, notes


def build_report(ratings_path, out_dir="report", options: Options | None = None, *, progress=True, quiet=False):
    """Run the whole analysis of a ratings file, of whichever design it holds, and write the report.

    Writes report.html, stats.json and the figures to `out_dir` (as `python -m analysis.report`), and prints
    the console summary unless `quiet`.

    Parameters
    ----------
    ratings_path : str or Path
        The export of the rating app (ratings.csv, or the answers of another test design).
    out_dir : str or Path
        The report folder.
    options : analysis.designs.Options or None
        The analysis's settings, plain data: the metrics, the catch threshold, the models, the bootstraps' seed and
        size, the error rate, the reference and its name, the indifference margin (None: every default).
    progress : bool
        Show a progress bar on stderr.
    quiet : bool
        Print nothing to stdout.

    Returns
    -------
    dict
        The stats.json document.

    Raises
    ------
    AnalysisError
        Bad input: one line naming the file and the line or column.
    """
    t0 = time.perf_counter()
    options = options or Options()
    design = design_of(ratings_path)
    check_design_options(design, options, ratings_path)
    data = design.prepare(ratings_path, options)
    target = study_target(ratings_path)  # before any work: a bad value is the file's problem
    out = cli.folder_to_write(out_dir, "the report's folder")  # a file in the way, or "" (the current folder)
    _prepare_out(out)
    bar = tqdm(
        total=design.steps,
        desc="analysis",
        unit="step",
        disable=not progress or not design.steps,
        leave=False,
        file=sys.stderr,
    )
    try:
        kept, everyone = design.analyse(data, options, bar)
    except AnalysisError as exc:
        bar.close()  # leave=False: the bar disappears, the error line stands alone
        raise AnalysisError(f"{ratings_path}: {exc}") from None
    figs = design.figures(data, kept, everyone, out / "figures")
    spread = sample_spread(sample_scores(data.kept))  # a stochastic system's samples (CONTRACTS §4); else empty
    meta = {
        **design.stats_head(),
        "input": str(ratings_path),
        "generated_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "seed": options.seed,
        "alpha": options.alpha,
        "figures": {k: str(Path(v).relative_to(out)) for k, v in figs.items()},
    }
    note = shortfall_note(data.counts["n_raters_total"], target)
    methods = methods_paragraph(design, data.rows, data.kept, data.counts, options, design.statistics_text(kept))
    methods = " ".join(filter(None, [methods, samples_sentence(spread)]))
    body = design.html(meta, data.counts, kept, everyone, figs)
    if not spread.empty:
        body.append(samples_html(spread))
    if note:  # right under the title, before any figure is read
        body.insert(1, f"<p class=warn>{html.escape(note)}</p>")
    extra = {} if target is None else {TARGET_COLUMN: target, "notes": [note] if note else []}
    if not spread.empty:
        extra["samples"] = report_html.records(spread)
    doc = report_html.clean({**meta, **data.counts, **extra, **design.stats_json(kept, everyone), "methods": methods})
    measures = objective_measures(design, doc, options)
    if measures is not None:
        values, agreement, score, notes = measures
        methods = " ".join(filter(None, [methods, measures_sentence(notes, agreement, score, options.n_boot,
                                                                     options.seed)]))  # fmt: skip
        body.append(measures_html(values, agreement, score, notes, options.n_boot))
        doc["methods"] = methods
        doc["measures"] = report_html.clean(
            {"score": score, "values": report_html.records(values), "agreement": report_html.records(agreement)}
        )
    whole_files.write_whole(out / "methods.txt", methods + "\n")
    body.append(f"<h2>Methods, for a paper</h2><p class=methods>{html.escape(methods)}</p>")
    whole_files.write_whole(out / "report.html", report_html.page(body))
    whole_files.write_whole(out / "stats.json", json.dumps(doc, indent=1, allow_nan=False))
    bar.update(bar.total - bar.n)
    bar.close()
    if not quiet:
        print(design.console(data.counts, kept, everyone))
        if not spread.empty:
            print("\n" + samples_console(spread))
        if measures is not None and not measures[1].empty:
            print("\n" + measures_console(measures[1], measures[2]))
        if note:
            print(f"\n{note}")
        print(f"\nReport: {out / 'report.html'}  ({time.perf_counter() - t0:.1f} s)")
    return doc


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m analysis.report", description=__doc__.splitlines()[0])
    ap.add_argument("ratings", help="ratings.csv exported by the rating app (CONTRACTS.md §6)")
    ap.add_argument("--out", default="report", help="report folder (default: report/)")
    ap.add_argument("--metrics", help="metrics.csv of the stimuli: correlate each metric with the clip mean rating")
    ap.add_argument(
        "--threshold",
        type=cli.number(int, 1, 6),
        default=DEFAULT_THRESHOLD,
        help=f"exclude raters who rated any catch clip at or above this (1-6; default {DEFAULT_THRESHOLD}, as "
        "in the paper; 6 keeps every rater)",
    )
    ap.add_argument("--no-mixed", action="store_true", help="skip the linear mixed model")
    ap.add_argument("--no-ordinal", action="store_true", help="skip the ordinal (cumulative-logit) mixed model")
    ap.add_argument(
        "--mixed-max-levels",
        type=cli.number(int, 1),
        default=MIXED_MAX_LEVELS,
        help="skip the mixed models when raters and clips both exceed this (their cost grows with the "
        f"cube of the smaller; default {MIXED_MAX_LEVELS})",
    )
    ap.add_argument(
        "--ordinal-max-ratings",
        type=cli.number(int, 1),
        default=ORDINAL_MAX_RATINGS,
        help="skip the ordinal model above this many test ratings (its cost grows with every rating; "
        f"default {ORDINAL_MAX_RATINGS})",
    )
    ap.add_argument("--seed", type=cli.number(int, 0, 2**32 - 1), default=0, help="bootstrap seed (default 0)")
    ap.add_argument(
        "--n-boot",
        type=cli.number(int, 10, 1_000_000),
        default=2000,
        help="bootstrap resamples (10-1000000; default 2000)",
    )
    ap.add_argument(
        "--alpha",
        type=cli.number(float, 0, 0.5, lo_open=True),
        default=0.05,
        help="family-wise error rate (0 < alpha <= 0.5; default 0.05)",
    )
    ap.add_argument(
        "--reference-name",
        help="the reference condition's own name, which the rows call NAT (acr; default: the export's reference_name "
        "column, else --study's, else NAT)",
    )
    ap.add_argument(
        "--reference",
        metavar="NAME",
        help="pairwise: the condition at log strength 0 and Elo 1000 (default: NAT, else the first by name)",
    )
    ap.add_argument(
        "--indifference",
        type=cli.number(float, 0.0, 1000.0),
        default=0.0,
        metavar="ELO",
        help="pairwise: conditions whose Elo lies within this of the one above in 95%% of the bootstrap resamples "
        "share a group, as the app's --pairing-indifference ties them (default 0: off)",
    )
    ap.add_argument("--study", help="the study file (STUDY.toml) the stimuli were built from: its reference's name")
    ap.add_argument("--quiet", action="store_true", help="no console summary or progress bar")
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    reference = args.reference_name
    if reference is None and args.study:
        reference = reference_from_study_file(args.study)
    if reference is None:
        reference = study_reference(args.ratings)
    options = Options(
        metrics_path=args.metrics,
        threshold=args.threshold,
        mixed=not args.no_mixed,
        seed=args.seed,
        n_boot=args.n_boot,
        alpha=args.alpha,
        mixed_max_levels=args.mixed_max_levels,
        ordinal=not args.no_ordinal,
        ordinal_max_ratings=args.ordinal_max_ratings,
        reference_name=reference,
        reference=args.reference,
        indifference=args.indifference,
    )
    build_report(args.ratings, args.out, options, progress=not args.quiet, quiet=args.quiet)
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
