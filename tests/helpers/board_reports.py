"""Exports and reports for the board's tests (tests/analysis/test_board.py): a stimulus folder's test clips answered
by a seeded crowd in each design's export format (CONTRACTS §6, §8), written as the app writes them, then reported by
`analysis.report` with cheap settings. The crowd follows `quality` (a score per condition), so the order is known."""

from __future__ import annotations

import csv
from itertools import combinations
from pathlib import Path

import numpy as np

from moglow_eval.core import study

PAIR_COLUMNS = ["rater_id", "item", "clip_a", "clip_b", "condition_a", "condition_b", "preference", "role"]


def manifest_rows(manifest) -> list[dict]:
    with open(manifest, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _clips(manifest, role="test"):
    """{item: {condition: clip_id}} of the manifest's clips of `role`, matched clips only (no motion_item), and
    {(item, condition): clip_id} of its mismatched ones."""
    matched, mismatched = {}, {}
    for r in manifest_rows(manifest):
        if r["role"] != role:
            continue
        if r.get("motion_item"):
            mismatched[(r["item"], r["condition"])] = (r["clip_id"], r["motion_item"])
        else:
            matched.setdefault(r["item"], {})[r["condition"]] = r["clip_id"]
    return matched, mismatched


def _write(path, columns, rows) -> Path:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        w.writerows(rows)
    return Path(path)


def acr_export(manifest, path, quality, n_raters=12, seed=0) -> Path:
    """ratings.csv: every rater rates every test clip (1..5 around its condition's quality) and the catch clips
    low (nobody is excluded); each rater's crowd-platform id is `external_id`, PID0, PID1, ..., as the app writes."""
    rng = np.random.default_rng(seed)
    test, _ = _clips(manifest)
    catch = [r for r in manifest_rows(manifest) if r["role"] == "catch" and r["condition"] == study.CATCH]
    rows = []
    for k in range(n_raters):
        for item, by_cond in sorted(test.items()):
            for cond, clip in sorted(by_cond.items()):
                rating = int(np.clip(round(quality[cond] + rng.normal(0, 0.8)), 1, 5))
                rows.append([f"r{k}", clip, cond, rating, "test", item, f"PID{k}"])
        rows += [[f"r{k}", c["clip_id"], c["condition"], 1, "catch", c["item"], f"PID{k}"] for c in catch]
    return _write(path, ["rater_id", "clip_id", "condition", "rating", "role", "item", "external_id"], rows)


def _prefer(rng, qa, qb):
    """A five-level preference for A over B, from the Bradley-Terry odds of the qualities."""
    p = 1 / (1 + np.exp(-(qa - qb)))
    u = rng.random()
    return 2 if u < p / 2 else 1 if u < p else 0 if u < p + 0.1 * (1 - p) else -1 if rng.random() < 0.5 else -2


def pairwise_export(manifest, path, quality, n_raters=12, seed=0) -> Path:
    """pairs.csv: every rater votes on every pair of conditions of every test item, sides at random, and on one
    catch pair (the catch item's NAT clip against its BAD clip), preferring NAT."""
    rng = np.random.default_rng(seed)
    test, _ = _clips(manifest)
    catch, _ = _clips(manifest, "catch")
    rows = []
    for k in range(n_raters):
        for item, by_cond in sorted(test.items()):
            for a, b in combinations(sorted(by_cond), 2):
                if rng.random() < 0.5:
                    a, b = b, a
                pref = _prefer(rng, quality[a], quality[b])
                rows.append([f"r{k}", item, by_cond[a], by_cond[b], a, b, pref, "test"])
        item, by_cond = sorted(catch.items())[0]
        nat, bad = by_cond[study.NATURAL], by_cond[study.CATCH]
        rows.append([f"r{k}", item, nat, bad, study.NATURAL, study.CATCH, 2, "catch"])
    return _write(path, PAIR_COLUMNS, rows)


def matched_export(manifest, path, quality, column, n_raters=12, seed=0) -> Path:
    """The appropriateness family's pairs.csv (`column` names what the mismatched motion was made for): every rater
    compares each system's matched and mismatched clip of every test item, preferring the matched one more the
    higher the system's quality."""
    rng = np.random.default_rng(seed)
    test, mismatched = _clips(manifest)
    catch, _ = _clips(manifest, "catch")
    rows = []
    for k in range(n_raters):
        for item, by_cond in sorted(test.items()):
            for cond, clip in sorted(by_cond.items()):
                other, other_item = mismatched[(item, cond)]
                pref = _prefer(rng, quality[cond] - 2.5, 0.0)
                if rng.random() < 0.5:
                    rows.append([f"r{k}", item, clip, other, cond, cond, pref, "test", "a", other_item])
                else:
                    rows.append([f"r{k}", item, other, clip, cond, cond, -pref, "test", "b", other_item])
        item, by_cond = sorted(catch.items())[0]
        nat, bad = by_cond[study.NATURAL], by_cond[study.CATCH]
        rows.append([f"r{k}", item, nat, bad, study.NATURAL, study.CATCH, 2, "catch", "", ""])
    return _write(path, [*PAIR_COLUMNS, "matched", column], rows)


def parallel_export(manifest, path, quality, n_raters=12, seed=0) -> Path:
    """The parallel ratings.csv: every rater rates every condition of every test item on one page (0..100), and a
    catch page with the BAD clip well below NAT."""
    rng = np.random.default_rng(seed)
    test, _ = _clips(manifest)
    catch, _ = _clips(manifest, "catch")
    rows, page = [], 0
    for k in range(n_raters):
        for item, by_cond in sorted(test.items()):
            page += 1
            for cond, clip in sorted(by_cond.items()):
                rating = int(np.clip(round(20 * quality[cond] + rng.normal(0, 10)), 0, 100))
                rows.append([f"r{k}", f"p{page}", item, clip, cond, rating, "test"])
        item, by_cond = sorted(catch.items())[0]
        page += 1
        for cond, clip in sorted(by_cond.items()):
            rows.append([f"r{k}", f"p{page}", item, clip, cond, 5 if cond == study.CATCH else 90, "catch"])
    return _write(path, ["rater_id", "page_id", "item", "clip_id", "condition", "rating", "role"], rows)


def export(design, manifest, path, quality, n_raters=12, seed=0) -> Path:
    """The export of `design` (one of moglow_eval.core.study.DESIGNS) for the stimuli of `manifest`."""
    if design in study.MISMATCH_COLUMN:
        return matched_export(manifest, path, quality, study.MISMATCH_COLUMN[design], n_raters, seed)
    make = {"acr": acr_export, "pairwise": pairwise_export, "parallel": parallel_export}[design]
    return make(manifest, path, quality, n_raters, seed)


def report(export_path, out, **options) -> dict:
    """`analysis.report` of the export with cheap settings (few resamples, no mixed models); its stats.json."""
    from analysis.designs import Options
    from analysis.report import build_report

    settings = dict(n_boot=40, mixed=False, ordinal=False, **options)
    return build_report(export_path, out, Options(**settings), progress=False, quiet=True)
