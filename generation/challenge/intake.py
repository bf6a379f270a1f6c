"""Check teams' submissions against the released test inputs, every problem at once, and write a report per team.

    python -m generation.challenge.intake --inputs SPEECH/ --fps 30 [--samples 5] --out intake/ TEAM/ [TEAM/ ...]
    python -m generation.challenge.intake --inputs SPEECH/ --fps 30 --teams SUBMISSIONS/ --out intake/
    moglow-eval intake ...

SPEECH/ holds the test items' speech (ITEM.wav or ITEM.flac): their names are the items, their lengths what each
motion must last. Each TEAM/ folder is one team's submission (generation.challenge.layout); with --teams, every
folder inside SUBMISSIONS/ is one. For every team, intake/TEAM/intake.csv lists each problem (the file, the item, the
sample, the check, what is wrong and what to do) and intake/TEAM/intake.html shows it as a page an organiser can
send; intake/teams.csv and intake/index.html hold one row per team: its items, samples, files, problems and verdict.

The exit status: 0 every team accepted, 1 a team refused (its problems listed), 2 unusable (a command-line input
that cannot be read, or a team folder that is not one), each with one line naming it. docs/challenge.md walks the
organiser's steps.
"""

from __future__ import annotations

import os
import stat
import sys
from collections import Counter
from pathlib import Path

from tqdm import tqdm

from moglow_eval.core import cli, whole_files
from moglow_eval.core.cli import UserError
from rendering.audio import audio_seconds
from rendering.errors import RenderError

from ..data.motion_files import Skeleton
from ..stimuli import files
from . import intake_page
from .checks import FORMATS, Rules, check_file, file_format
from .layout import NAME_MAX, UNREADABLE, Problem, Submission, plain_name, read_submission, shown, unreadable

SPEECH_EXTENSIONS = (".wav", ".flac")
PROBLEM_COLUMNS = ("team", "file", "item", "sample", "check", "problem")
TEAM_COLUMNS = ("team", "verdict", "items", "items_given", "samples_per_item", "files", "problems", "format")
EXIT_REFUSED = 1


def read_inputs(folder) -> dict[str, float]:
    """{item: seconds of its speech} of the released inputs' speech folder; UserError naming what is wrong."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserError(f"{folder}: not a folder of the test items' speech (ITEM.wav)")
    items = {}
    for entry in sorted(os.scandir(folder), key=lambda e: e.name):
        name = entry.name
        # Hidden files (.DS_Store, macOS's ._ copies) and files that are not speech (a readme, transcripts) are not
        # items; a speech file that cannot name an item is refused, as a skipped one would leave its item unchecked.
        if name.startswith(".") or not name.lower().endswith(SPEECH_EXTENSIONS):
            continue
        if not plain_name(name):
            raise UserError(f"{folder}/{shown(name)}: a speech file's name is its item's: rename it to print as itself")
        if not name.endswith(SPEECH_EXTENSIONS):
            raise UserError(f"{folder / name}: name speech files ITEM.wav or ITEM.flac, the extension in lower case")
        if not stat.S_ISREG(entry.stat(follow_symlinks=False).st_mode):
            raise UserError(f"{folder / name}: not a regular file (a link or a special file): give the speech itself")
        item = name.rsplit(".", 1)[0]
        if item in items:
            raise UserError(f"{folder}: two speech files for item {item} (.wav and .flac): give one")
        try:
            seconds = audio_seconds(folder / name)
        except RenderError as e:
            raise UserError(str(e)) from None
        # Each item's length is what every team's motion is checked against: one the file does not tell, or no
        # sound at all, would leave the item unchecked or refuse every team.
        if seconds is None:
            raise UserError(f"{folder / name}: its length is not in its header: write it again (a FLAC with its "
                            "sample count, or a WAV)")  # fmt: skip
        if seconds <= 0:
            raise UserError(f"{folder / name}: holds no sound: give the item's speech")
        items[item] = seconds
    if not items:
        raise UserError(f"{folder}: no speech files (ITEM.wav or ITEM.flac): the test items are named by them")
    return items


def check_team(team: str, folder, inputs: dict, rules: Rules, bar=None) -> tuple[Submission, dict]:
    """A team's submission and its row of the table (TEAM_COLUMNS): every problem of its layout and of its files."""
    folder = Path(folder)
    samples = rules.samples_of(folder, inputs)
    sub = read_submission(team, folder, inputs, samples)
    formats = {}
    for item, by_sample in sorted(sub.files.items()):
        for sample, path in sorted(by_sample.items()):
            why = unreadable(path)
            if why is None:
                formats[path] = file_format(path)
            else:  # said as what it is, not as a file in no format the study reader takes
                sub.add(path, "read", f"cannot be read ({why}): {UNREADABLE}", item, sample)
    counts = Counter(formats.values())
    usual = counts.most_common(1)[0][0] if counts else ""
    for item, by_sample in sorted(sub.files.items()):
        for sample, path in sorted(by_sample.items()):
            if path not in formats:
                continue
            if formats[path] != usual:
                sub.problems.append(Problem(str(path), item, sample, "format", f"{FORMATS[formats[path]]}, where the "
                                            f"rest are {FORMATS[usual]}: give every file in one format"))  # fmt: skip
                continue
            sub.problems.extend(check_file(path, item, sample, inputs[item], rules, formats[path]))
            if bar is not None:
                bar.update()
    n_files = sum(len(s) for s in sub.files.values())
    row = {
        "team": team,
        "verdict": "refused" if sub.problems else "accepted",
        "items": len(inputs),
        "items_given": len(sub.files),
        "samples_per_item": samples,
        "files": n_files,
        "problems": len(sub.problems),
        "format": FORMATS.get(usual, ""),
    }
    return sub, row


def write_csv(path: Path, columns, rows) -> None:
    """A table of the intake written whole or not at all, with LF line ends (stimuli.files.write_csv)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    files.write_csv(path, columns, rows, line_end="\n")


def write_text(path: Path, text: str) -> None:
    """A report written whole or not at all (core.whole_files), its folder made first."""
    path.parent.mkdir(parents=True, exist_ok=True)
    whole_files.write_whole(path, text)


def relative(path, folder) -> str:
    """A problem's file as the team knows it: its path inside the team's folder (the folder itself as NAME/)."""
    try:
        inside = Path(path).relative_to(folder)
    except ValueError:
        return str(path)
    return str(inside) if inside.parts else f"{Path(folder).name}/"


def problem_rows(sub: Submission) -> list[dict]:
    # A reader's message names the file by the path the intake gave it: the team reads it inside its own folder,
    # without the organiser's folders (which the team's page would otherwise show it).
    inside = f"{sub.folder}{os.sep}"
    return [
        {
            "team": sub.team,
            "file": relative(p.file, sub.folder),
            "item": p.item,
            "sample": p.sample,
            "check": p.check,
            "problem": p.text.replace(inside, ""),
        }  # fmt: skip
        for p in sub.problems
    ]


def team_folders(args) -> dict[str, Path]:
    """{team: folder} from the positional folders or --teams; UserError for a folder that is not one."""
    if args.teams and args.folders:
        raise UserError("give TEAM folders or --teams with a folder of them, not both")
    if args.teams:
        parent = Path(args.teams)
        if not parent.is_dir():
            raise UserError(f"{parent}: not a folder of teams' submissions")
        # Every entry is a team, a file or a link too (judged unusable below, never skipped unsaid), but for hidden
        # ones: an organiser's .git or .DS_Store is no submission.
        folders = [parent / e.name for e in sorted(os.scandir(parent), key=lambda e: e.name) if e.name[:1] != "."]
    else:
        folders = [Path(f) for f in args.folders]
    if not folders:
        raise UserError("no submission: give TEAM folders, or --teams with a folder of them")
    out = {}
    for folder in folders:
        team = folder.resolve().name if folder.name in ("", ".", "..") else folder.name
        if not plain_name(team):
            raise UserError(
                f"{ascii(str(folder))}: a team folder's name must be plain printable text, not hidden, at most "
                f"{NAME_MAX} characters (it names the team's report folder)"
            )
        if team in out:
            raise UserError(f"{folder}: two submissions for team {team} ({out[team]} and {folder})")
        out[team] = folder
    return out


def out_folder(out: str, teams: dict) -> Path:
    """--out as a folder the reports may go to: not empty, not a file, not inside a submission, and no team's report
    folder (OUT/TEAM) its submission, as with --out set to the --teams folder: the reports would become part of the
    teams' folders, and the next intake would refuse each team for them."""
    path = cli.folder_to_write(out, "the reports' folder")
    for team, folder in teams.items():
        there = Path(folder).resolve()
        if path.resolve().is_relative_to(there) or (path / team).resolve() == there:
            raise UserError(f"--out {out}: the reports would be written into the submission {folder}")
    return path


def build_parser():
    ap = cli.ArgumentParser(
        prog="python -m generation.challenge.intake",
        description="Check teams' submissions against the test inputs, every problem at once; a report per team.",
    )
    ap.add_argument("folders", nargs="*", help="team folders (each one team's submission)")
    ap.add_argument("--teams", help="a folder whose every folder is one team's submission (instead of FOLDERS)")
    ap.add_argument("--inputs", required=True, help="the released test items' speech: ITEM.wav or ITEM.flac")
    ap.add_argument("--fps", required=True, type=cli.number(float, 5, 240), help="the dataset's frame rate")
    ap.add_argument("--samples", type=cli.number(int, 1, 100), default=1,
                    help="samples per item the rules ask for (a stochastic system's; default 1)")  # fmt: skip
    ap.add_argument("--or-one", action="store_true",
                    help="a team of one file per item (a deterministic system) gives one sample")  # fmt: skip
    ap.add_argument("--out", default="intake", help="the reports' folder (default intake/)")
    ap.add_argument("--max-speed", type=cli.number(float, 1, 1000), default=Rules.max_speed,
                    help=f"the fastest a joint may move, m/s (default {Rules.max_speed:g})")  # fmt: skip
    ap.add_argument("--max-bone-change", type=cli.number(float, 0.001, 10), default=Rules.max_bone_change,
                    help="joint positions: the share of its length a bone may change by "
                    f"(default {Rules.max_bone_change:g})")  # fmt: skip
    ap.add_argument("--units", default="auto", help="the files' units: auto, m, cm or mm (default auto)")
    ap.add_argument("--up", default="auto", choices=("auto", "y", "z"), help="the files' up axis (default auto)")
    ap.add_argument("--skeleton", help=".npy files: the skeleton JSON (names, parents)")
    ap.add_argument("--source-fps", type=cli.number(float, 5, 240), help=".npy files: their frame rate")
    ap.add_argument("--smpl-model", help="SMPL-family and Seamless files: the body model (.npz)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar, one line per team")
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    if args.units not in ("auto", "m", "cm", "mm"):
        raise UserError(f"--units must be auto, m, cm or mm, got {args.units!r}")
    inputs = read_inputs(args.inputs)
    teams = team_folders(args)
    if args.smpl_model is not None and not Path(args.smpl_model).is_file():
        raise UserError(f"--smpl-model {args.smpl_model}: no such file (the body model's .npz)")
    out = out_folder(args.out, teams)
    read = dict(units=args.units, up=args.up, source_fps=args.source_fps, smpl_model=args.smpl_model)
    if args.skeleton:
        read["skeleton"] = Skeleton.load(args.skeleton)
    rules = Rules(args.fps, args.samples, args.max_speed, args.max_bone_change, read, args.or_one)
    rows, unusable = [], []
    total = len(inputs) * args.samples * len(teams)
    with tqdm(total=total, desc="intake", unit="file", file=sys.stderr, disable=args.quiet) as bar:
        for team, folder in teams.items():
            if not folder.is_dir() or folder.is_symlink():
                unusable.append(f"{folder}: not a folder (a team's submission is a folder of motion files)")
                rows.append({"team": team, "verdict": "unusable", "items": len(inputs), "items_given": 0,
                             "samples_per_item": args.samples, "files": 0, "problems": 1, "format": ""})  # fmt: skip
                continue
            sub, row = check_team(team, folder, inputs, rules, bar)
            rows.append(row)
            problems = problem_rows(sub)
            write_csv(out / team / "intake.csv", PROBLEM_COLUMNS, problems)
            write_text(out / team / "intake.html", intake_page.team_page(row, problems, rules))
    write_csv(out / "teams.csv", TEAM_COLUMNS, rows)
    write_text(out / "index.html", intake_page.challenge_page(rows, rules))
    for row in rows:
        page = f" ({out / row['team'] / 'intake.html'})" if row["verdict"] != "unusable" else ""  # none is written
        print(f"{row['team']}: {row['verdict']}, {row['problems']} problem(s) in {row['files']} file(s) "
              f"for {row['items']} items{page}")  # fmt: skip
    if unusable:
        raise UserError(unusable[0] + (f" (and {len(unusable) - 1} more)" if len(unusable) > 1 else ""))
    return EXIT_REFUSED if any(r["verdict"] == "refused" for r in rows) else 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
