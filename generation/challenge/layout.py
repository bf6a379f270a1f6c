"""A team's submission folder, walked as hostile: which motion file is which item's which sample, and every entry
that should not be there.

The layout (docs/challenge.md): with one sample per item, `TEAM/ITEM.EXT`; with K samples (a stochastic system),
`TEAM/ITEM/SAMPLE.EXT`, K files in each item's folder, SAMPLE any name (`1` .. `5`). EXT is any format the study
reader takes (generation.data.motion_files.EXTENSIONS). Nothing is opened here: a symbolic link, a FIFO, a device, a
name that is not plain text, a folder deeper than the layout or a folder of too many entries is one problem each,
found from the directory entries alone, so a hostile folder costs a listing and no more.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from pathlib import Path

from ..data.motion_files import EXTENSIONS, motion_stem

MAX_ENTRIES = 100_000  # entries of one submission folder looked at; past it the folder is not a submission
NAME_MAX = 200  # characters of a file or folder name


@dataclass(frozen=True)
class Problem:
    """One problem of a submission: the file (or folder) it is in, the item and sample it concerns ("" when none),
    the check that found it and one line saying what is wrong and what to do."""

    file: str
    item: str
    sample: str
    check: str
    text: str


@dataclass
class Submission:
    """What a team's folder holds: {item: {sample: path}} of the motion files found where the layout puts them, and
    the problems of every other entry."""

    team: str
    folder: Path
    files: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)

    def add(self, where, check, text, item="", sample=""):
        self.problems.append(Problem(str(where), item, sample, check, text))


# What a team's report says of a file or folder that cannot be read: the organiser's permissions (an archive unpacked
# with its own), or the team's, are to be mended before the intake can read what it holds.
UNREADABLE = "make it readable (chmod a+rX), or send it again"


def plain_name(name: str) -> bool:
    """A name that prints as itself: printable, not hidden, at most NAME_MAX characters."""
    return name.isprintable() and not name.startswith(".") and 0 < len(name) <= NAME_MAX


def shown(name) -> str:
    """A name as a report line may show it: as itself when plain, else Python's ascii() of it."""
    return name if plain_name(name) else ascii(name)


def _entries(folder: Path, sub: Submission, budget: list, item=""):
    """The entries of `folder` (name, lstat) in name order, at most what is left of the budget of MAX_ENTRIES; None,
    and the problem said, where the folder cannot be listed."""
    out = []
    try:
        with os.scandir(folder) as it:
            for entry in it:
                budget[0] -= 1
                if budget[0] < 0:
                    sub.add(folder, "entry", f"more than {MAX_ENTRIES} entries: not a submission folder; send the "
                            "motion files alone")  # fmt: skip
                    break
                out.append((entry.name, entry.stat(follow_symlinks=False)))
    except OSError as e:  # one team's folder that cannot be listed is that team's problem, not every team's stop
        sub.add(folder, "read", f"the folder cannot be read ({e.strerror or e}): {UNREADABLE}", item)
        return None
    return sorted(out, key=lambda e: e[0])


def unreadable(path) -> str | None:
    """Why a file cannot be opened for reading (its error's words), or None where it can."""
    try:
        with open(path, "rb"):
            return None
    except OSError as e:
        return e.strerror or str(e)


def _regular(where, st, sub, item="", sample="") -> bool:
    """Whether an entry is a regular file; else one problem naming what it is."""
    if stat.S_ISLNK(st.st_mode):
        sub.add(where, "entry", "a symbolic link: send the file itself (a link may point anywhere)", item, sample)
    elif not stat.S_ISREG(st.st_mode):
        sub.add(where, "entry", "not a regular file (a pipe, a device or a socket): send motion files only", item,
                sample)  # fmt: skip
    else:
        return True
    return False


def read_submission(team: str, folder, items, samples: int) -> Submission:
    """The motion files of `folder` by item and sample, and the problems of its layout: names of no test item,
    files of no motion format, links and special files, folders where the layout has none (`samples` == 1) or
    files where it has folders, and a wrong number of samples. `items`: the test items' names."""
    folder = Path(folder)
    sub = Submission(team, folder)
    items = set(items)
    budget = [MAX_ENTRIES]
    entries = _entries(folder, sub, budget)
    if entries is None:  # nothing in it can be told apart: that one problem, not one an item
        return sub
    for name, st in entries:
        where = folder / name if plain_name(name) else folder / shown(name)
        if not plain_name(name):
            sub.add(where, "entry", "a name that is not plain printable text: name each file ITEM.EXT")
            continue
        if stat.S_ISDIR(st.st_mode):
            _item_folder(sub, folder / name, name, items, samples, budget)
            continue
        if not _regular(where, st, sub):
            continue
        item = motion_stem(name)
        if item is None:
            sub.add(where, "entry", f"not a motion file (expected ITEM{' or ITEM'.join(EXTENSIONS)}): remove it")
        elif item not in items:
            sub.add(where, "entry", f"{item} is not a test item: remove it, or rename it to its item's name", item)
        elif samples > 1:
            sub.add(where, "samples", f"one file for {item}, where the rules ask for {samples} samples in a folder "
                    f"{item}/ (1{_ext(name)} .. {samples}{_ext(name)})", item)  # fmt: skip
            _claim(sub, item, "1", where)
        else:
            _claim(sub, item, "", where)
    used = {_ext(path.name) for by_sample in sub.files.values() for path in by_sample.values()}
    ext = used.pop() if len(used) == 1 else None  # the format the team's files share, if they share one
    for item in sorted(items - set(sub.files)):
        sub.add(folder / item, "missing", f"no motion for test item {item}: add {_missing(item, samples, ext)}", item)
    return sub


def _missing(item, samples, ext) -> str:
    """What to add for a missing item, in the format `ext` of the team's other files where they share one (else
    None)."""
    if samples > 1:
        return f"a folder {item}/ of {samples} samples ({f'1{ext} .. {samples}{ext}' if ext else 'SAMPLE.EXT'})"
    return f"{item}{ext}, as the other items" if ext else f"{item}.EXT, EXT one of {', '.join(EXTENSIONS)}"


def _claim(sub, item, sample, where) -> None:
    """`where` as `item`'s `sample` ("" where the layout has one file an item), or a problem naming both files where
    another file is that sample already (ITEM.bvh beside ITEM.npz, 1.bvh beside 1.npz, ITEM.npz beside ITEM/):
    which of them the team meant is the team's to say."""
    taken = sub.files.setdefault(item, {})
    if sample in taken:
        sub.add(where, "entry", f"two files for {item}{'/' + sample if sample else ''}: {taken[sample].name} and "
                f"{where.name}: keep one", item, sample)  # fmt: skip
        return
    taken[sample] = where


def _ext(name):
    return next((e for e in EXTENSIONS if name.endswith(e)), "")


def _item_folder(sub, path: Path, item: str, items, samples: int, budget):
    if item not in items:
        sub.add(path, "entry", f"{item} is not a test item: remove the folder, or name it after its item", item)
        return
    if samples == 1:
        sub.add(path, "samples", f"a folder, where the rules ask for one file {item}.EXT: give one sample, as a "
                "file", item)  # fmt: skip
    entries = _entries(path, sub, budget, item)
    if entries is None:  # given, but unread: its one problem says so (not "0 samples", not "missing")
        sub.files.setdefault(item, {})
        return
    found = {}
    for name, st in entries:
        where = path / name if plain_name(name) else path / shown(name)
        if not plain_name(name):
            sub.add(where, "entry", "a name that is not plain printable text: name each sample SAMPLE.EXT", item)
            continue
        if stat.S_ISDIR(st.st_mode):
            sub.add(where, "entry", f"a folder inside {item}/: the samples are files, {item}/SAMPLE.EXT", item)
            continue
        if not _regular(where, st, sub, item, name):
            continue
        sample = motion_stem(name)
        if sample is None:
            sub.add(where, "entry", "not a motion file: remove it", item)
            continue
        _claim(sub, item, sample, where)
        found[sample] = where
    if samples > 1 and len(found) != samples:
        sub.add(path, "samples", f"{len(found)} samples of {item}, where the rules ask for {samples}: "
                f"{'add' if len(found) < samples else 'remove'} {abs(samples - len(found))}", item)  # fmt: skip
