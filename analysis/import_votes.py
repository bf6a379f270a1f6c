"""Pairwise votes from another tool into this project's pairs.csv (CONTRACTS §8), for analysis.report.

    python -m analysis.import_votes BATTLES.csv --out pairs.csv

Reads the GENEA leaderboard's "battle" files (Nagy et al. 2025, arXiv:2511.01233; one row per vote: user,
input_code, model_a, model_b, winner, is_strong, juiceOptions, juiceOtherReason). Each vote keeps its 5 levels
(winner and is_strong become a preference -2..2 for model_a, moglow_eval.core.votes), its ticked reasons (ids
joined by `;`) and its free text (unquoted from the file's JSON string). A file whose every vote pairs a system X
with X_Mismatched (the speech-mismatch study) becomes an appropriateness export instead: both sides are X, and
`matched` says which side showed the motion made for the speech heard.

The battle files name no clips, so each (input_code, model) gets a stable 16-character id (a SHA-256 prefix):
the same clip gets the same id in every vote and every import. Every row is a test vote: the leaderboard's files
carry no catch trials.
"""

import csv
import hashlib
import json
import os
import sys
from pathlib import Path

from moglow_eval.core import cli, votes
from moglow_eval.core.cli import UserError

REQUIRED = ("user", "input_code", "model_a", "model_b", "winner")
MAX_BYTES = 512 * 2**20  # a battle file of 16,000 votes is about 2 MB; far larger is not one
PAIRS = ("rater_id", "item", "clip_a", "clip_b", "condition_a", "condition_b", "preference", "role")
REASONS = (votes.REASONS_COLUMN, votes.REASON_TEXT_COLUMN)


class VotesFileError(UserError):
    """A battle file that cannot be read: one line naming the file and line."""


def clip_id(item: str, model: str) -> str:
    """The stable id of the clip `model` made for `item` (lower-case hex, so a valid clip id, CONTRACTS §4)."""
    return hashlib.sha256(f"{item}\0{model}".encode()).hexdigest()[:16]


def _reasons(raw: str, where: str) -> str:
    """juiceOptions (a JSON list of ids; `{}`, `[]` or empty for none) as ids joined by `;`."""
    raw = raw.strip()
    if raw in ("", "{}", "[]"):
        return ""
    try:
        ids = json.loads(raw)
    except ValueError:
        raise VotesFileError(f"{where}: juiceOptions {raw[:40]!r} is not a JSON list") from None
    if not isinstance(ids, list) or not all(isinstance(i, str) and i.isidentifier() for i in ids):
        raise VotesFileError(f"{where}: juiceOptions {raw[:40]!r} is not a list of reason ids")
    if any(len(i) > votes.REASON_ID_MAX for i in ids):
        raise VotesFileError(f"{where}: a reason id in juiceOptions is over {votes.REASON_ID_MAX} characters")
    return votes.REASON_SEPARATOR.join(dict.fromkeys(ids))


def _text(raw: str) -> str:
    """juiceOtherReason: JSON-quoted text in the leaderboard's files; kept as it is where it is not."""
    raw = raw.strip()
    if len(raw) >= 2 and raw[0] == raw[-1] == '"':
        try:
            text = json.loads(raw)
            if isinstance(text, str):
                return text
        except ValueError:
            pass
    return raw


def _rows(path: Path):
    """The battle file's votes as dicts, with their line numbers; VotesFileError on a file that is not one."""
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise VotesFileError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if size > MAX_BYTES:
        raise VotesFileError(
            f"{path}: {size / 2**20:.0f} MB is larger than a battle file can be ({MAX_BYTES >> 20} MB)"
        )
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in REQUIRED if c not in (reader.fieldnames or ())]
            if missing:
                raise VotesFileError(f"{path}: not a battle file: no column {', '.join(missing)}")
            rows = [(reader.line_num, r) for r in reader]
    except UnicodeDecodeError:
        raise VotesFileError(f"{path}: not UTF-8 text") from None
    except csv.Error as exc:
        raise VotesFileError(f"{path}: not a CSV file ({exc})") from None
    if not rows:
        raise VotesFileError(f"{path}: no votes")
    return rows


def _vote(path, line, r):
    where = f"{path}:{line}"
    item, a, b = (str(r.get(k) or "").strip() for k in ("input_code", "model_a", "model_b"))
    user = str(r.get("user") or "").strip()
    for name, value in (("user", user), ("input_code", item), ("model_a", a), ("model_b", b)):
        if not value:
            raise VotesFileError(f"{where}: empty {name}")
    if a == b:
        raise VotesFileError(f"{where}: model {a} on both sides of a vote")
    try:
        pref = votes.battle_to_preference(str(r.get("winner") or "").strip(), str(r.get("is_strong") or ""))
    except ValueError as exc:
        raise VotesFileError(f"{where}: {exc}") from None
    return {
        "rater_id": user,
        "item": item,
        "clip_a": clip_id(item, a),
        "clip_b": clip_id(item, b),
        "condition_a": a,
        "condition_b": b,
        "preference": pref,
        "role": "test",
        votes.REASONS_COLUMN: _reasons(str(r.get("juiceOptions") or ""), where),
        votes.REASON_TEXT_COLUMN: _text(str(r.get("juiceOtherReason") or "")),
    }


def _as_appropriateness(path, out):
    """A speech-mismatch file's votes as appropriateness rows (both sides the system; `matched` the side that
    showed the motion made for the speech heard), or None when the file is not such a study."""
    suffix = votes.MISMATCH_SUFFIX
    if not any(v["condition_a"].endswith(suffix) or v["condition_b"].endswith(suffix) for _, v in out):
        return None
    rows = []
    for line, v in out:
        a, b = v["condition_a"], v["condition_b"]
        if a == b + suffix:
            system, matched = b, "b"
        elif b == a + suffix:
            system, matched = a, "a"
        else:
            raise VotesFileError(
                f"{path}:{line}: {a} against {b}: a speech-mismatch file pairs each system X only with {'X' + suffix}"
            )
        rows.append({**v, "condition_a": system, "condition_b": system, "matched": matched, "mismatched_item": ""})
    return rows


def import_votes(path, out_path) -> dict:
    """Convert a GENEA leaderboard battle file into pairs.csv.

    Parameters
    ----------
    path : str or Path
        The battle file (CSV with user, input_code, model_a, model_b, winner, is_strong, juiceOptions,
        juiceOtherReason).
    out_path : str or Path
        Where to write pairs.csv; written whole or not at all.

    Returns
    -------
    dict
        design ("pairwise" or "appropriateness"), n_votes, n_raters, conditions (sorted).

    Raises
    ------
    UserError
        One line naming the file and line: a missing column, an empty field, an unknown winner, a strength that
        is not True or False, reasons that are not a JSON list of ids, a mismatch file pairing other systems.
    """
    path, out_path = Path(path), Path(out_path)
    out = [(line, _vote(path, line, r)) for line, r in _rows(path)]
    rows = _as_appropriateness(path, out)
    design = "pairwise" if rows is None else "appropriateness"
    rows = [v for _, v in out] if rows is None else rows
    columns = [*PAIRS, *(("matched", "mismatched_item") if design == "appropriateness" else ()), *REASONS]
    tmp = out_path.with_name(out_path.name + ".part")
    try:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=columns, lineterminator="\n")
            w.writeheader()
            w.writerows(rows)
        os.replace(tmp, out_path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise VotesFileError(f"{out_path}: cannot be written ({exc.strerror or exc})") from None
    conds = sorted({r["condition_a"] for r in rows} | {r["condition_b"] for r in rows})
    return {"design": design, "n_votes": len(rows), "n_raters": len({r["rater_id"] for r in rows}), "conditions": conds}


def build_parser():
    ap = cli.ArgumentParser(prog="python -m analysis.import_votes", description=__doc__.splitlines()[0])
    ap.add_argument("battles", help="a GENEA leaderboard battle file (CSV, one vote per row)")
    ap.add_argument("--out", default="pairs.csv", help="the pairs.csv to write (default: pairs.csv)")
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    s = import_votes(args.battles, args.out)
    print(
        f"{args.out}: {s['n_votes']} votes from {s['n_raters']} raters on {len(s['conditions'])} conditions "
        f"({s['design']}); next: python -m analysis.report {args.out}"
    )
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
