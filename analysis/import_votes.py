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

import contextlib
import csv
import hashlib
import sys
from pathlib import Path

from moglow_eval.core import cli, user_files, votes, whole_files
from moglow_eval.core.cli import UserError

REQUIRED = ("user", "input_code", "model_a", "model_b", "winner")
MAX_BYTES = 512 * 2**20  # a battle file of 16,000 votes is about 2 MB; far larger is not one
MAX_CELL = 4096  # characters in a cell: the leaderboard's longest is a free text of a few hundred
PAIRS = ("rater_id", "item", "clip_a", "clip_b", "condition_a", "condition_b", "preference", "role")
REASONS = (votes.REASONS_COLUMN, votes.REASON_TEXT_COLUMN)


class VotesFileError(UserError):
    """A battle file that cannot be read: one line naming the file and line."""


def clip_id(item: str, model: str) -> str:
    """The stable id of the clip `model` made for `item` (lower-case hex, so a valid clip id, CONTRACTS §4)."""
    return hashlib.sha256(f"{item}\0{model}".encode()).hexdigest()[:16]


def _reasons(raw: str, where: str) -> str:
    """juiceOptions (a JSON list of ids; `{}`, `[]` or empty for none) as ids joined by `;`."""
    if raw in ("", "{}", "[]"):
        return ""
    ids = user_files.json_value(raw, f"{where}: juiceOptions", VotesFileError)
    if not isinstance(ids, list) or not all(isinstance(i, str) and i.isidentifier() for i in ids):
        raise VotesFileError(f"{where}: juiceOptions {raw[:40]!r} is not a list of reason ids")
    if any(len(i) > votes.REASON_ID_MAX for i in ids):
        raise VotesFileError(f"{where}: a reason id in juiceOptions is over {votes.REASON_ID_MAX} characters")
    return votes.REASON_SEPARATOR.join(dict.fromkeys(ids))


def _text(raw: str, where: str) -> str:
    """juiceOtherReason: JSON-quoted text in the leaderboard's files; kept as it is where it is not."""
    if len(raw) >= 2 and raw[0] == raw[-1] == '"':
        with contextlib.suppress(VotesFileError):
            text = user_files.json_value(raw, where, VotesFileError)
            if isinstance(text, str):
                return text
    return raw


@contextlib.contextmanager
def _rows(path: Path):
    """The battle file's votes as (line, {column: stripped cell}), read in a stream; VotesFileError, one line, on a
    file that is not one."""
    with user_files.csv_rows(path, MAX_BYTES, VotesFileError, "battle file", MAX_CELL) as (header, rows):
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise VotesFileError(f"{path}: not a battle file: no column {', '.join(missing)}")
        yield rows


def _vote(path, line, r):
    where = f"{path}:{line}"
    item, a, b, user = (r.get(k, "") for k in ("input_code", "model_a", "model_b", "user"))
    for name, value in (("user", user), ("input_code", item), ("model_a", a), ("model_b", b)):
        if not value:
            raise VotesFileError(f"{where}: empty {name}")
        if not value.isprintable():  # a terminal's escape in a name would reach the report's console and page
            raise VotesFileError(f"{where}: {name} {value[:40]!r} holds a control character")
    if a == b:
        raise VotesFileError(f"{where}: model {a} on both sides of a vote")
    try:
        pref = votes.battle_to_preference(r.get("winner", ""), r.get("is_strong", ""))
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
        votes.REASONS_COLUMN: _reasons(r.get("juiceOptions", ""), where),
        votes.REASON_TEXT_COLUMN: _text(r.get("juiceOtherReason", ""), where),
    }


def _is_mismatch(v) -> bool:
    suffix = votes.MISMATCH_SUFFIX
    return v["condition_a"].endswith(suffix) or v["condition_b"].endswith(suffix)


def _as_appropriateness(path, line, v):
    """A speech-mismatch vote as an appropriateness row (both sides the system; `matched` the side that showed the
    motion made for the speech heard)."""
    suffix = votes.MISMATCH_SUFFIX
    a, b = v["condition_a"], v["condition_b"]
    if a == b + suffix:
        system, matched = b, "b"
    elif b == a + suffix:
        system, matched = a, "a"
    else:
        raise VotesFileError(
            f"{path}:{line}: {a} against {b}: a speech-mismatch file pairs each system X only with {'X' + suffix}"
        )
    return {**v, "condition_a": system, "condition_b": system, "matched": matched, "mismatched_item": ""}


def _convert(path, rows, fh) -> dict:
    """Write the votes of `rows` to the text file `fh` as pairs.csv, one at a time; the summary. The first vote
    decides the design: a speech-mismatch vote makes the file an appropriateness export, in which every vote
    must be one; a mismatch vote after plain ones is refused at the first plain one."""
    w, design, first_plain, first_v = None, None, None, None
    raters, conds, n = set(), set(), 0
    for line, r in rows:
        v = _vote(path, line, r)
        if design is None:
            design = "appropriateness" if _is_mismatch(v) else "pairwise"
            extra = ("matched", "mismatched_item") if design == "appropriateness" else ()
            w = csv.DictWriter(fh, fieldnames=[*PAIRS, *extra, *REASONS], lineterminator="\n")
            w.writeheader()
        if design == "appropriateness":
            v = _as_appropriateness(path, line, v)
        elif _is_mismatch(v):
            _as_appropriateness(path, first_plain, first_v)  # raises, naming the first plain vote
        elif first_plain is None:
            first_plain, first_v = line, v
        w.writerow({k: user_files.defuse(x) for k, x in v.items()})
        raters.add(v["rater_id"])
        conds.update((v["condition_a"], v["condition_b"]))
        n += 1
    if not n:
        raise VotesFileError(f"{path}: no votes")
    return {"design": design, "n_votes": n, "n_raters": len(raters), "conditions": sorted(conds)}


def import_votes(path, out_path) -> dict:
    """Convert a GENEA leaderboard battle file into pairs.csv.

    Parameters
    ----------
    path : str or Path
        The battle file (CSV with user, input_code, model_a, model_b, winner, is_strong, juiceOptions,
        juiceOtherReason): a regular file, read in a stream.
    out_path : str or Path
        Where to write pairs.csv; written whole or not at all. Text cells a spreadsheet would evaluate (starting
        with = + - @, a tab or a carriage return) are written with a leading apostrophe, as the app's exports are.

    Returns
    -------
    dict
        design ("pairwise" or "appropriateness"), n_votes, n_raters, conditions (sorted).

    Raises
    ------
    UserError
        One line naming the file and line, at the first bad line: not a regular file, too large, not UTF-8, a
        line or cell too long, a missing column, an empty field, an unknown winner, a strength that is not True or
        False, reasons that are not a JSON list of ids (or nest too deep), a mismatch file pairing other systems.
    """
    path, out_path = Path(path), Path(out_path)
    if out_path.is_dir():
        raise VotesFileError(f"--out {out_path}: is a folder; give the pairs.csv to write")
    if out_path.exists() and path.exists() and out_path.samefile(path):  # it would replace the votes it reads
        raise VotesFileError(f"--out {out_path}: is the battle file itself; write the pairs elsewhere")
    try:
        with (
            whole_files.writing(out_path) as tmp,
            _rows(path) as rows,
            open(tmp, "x", newline="", encoding="utf-8") as fh,
        ):
            summary = _convert(path, rows, fh)
    except OSError as exc:
        raise VotesFileError(f"{out_path}: cannot be written ({exc.strerror or exc})") from None
    return summary


def build_parser():
    ap = cli.ArgumentParser(prog="python -m analysis.import_votes", description=__doc__.splitlines()[0])
    ap.add_argument("battles", help="a GENEA leaderboard battle file (CSV, one vote per row)")
    ap.add_argument("--out", default="pairs.csv", help="the pairs.csv to write (default: pairs.csv)")
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    s = import_votes(args.battles, args.out)
    votes_, raters = (f"{k} {w}{'' if k == 1 else 's'}" for k, w in ((s["n_votes"], "vote"), (s["n_raters"], "rater")))
    print(
        f"{args.out}: {votes_} from {raters} on {len(s['conditions'])} conditions "
        f"({s['design']}); next: python -m analysis.report {args.out}"
    )
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
