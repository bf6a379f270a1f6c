"""The checks every key of a study file goes through: one StudyFileError naming the file and the key."""

from moglow_eval.core.cli import UserError


class StudyFileError(UserError):
    """A bad study file; the message names the file and the key."""


def err(path, key, message):
    return StudyFileError(f"{path}: {key}: {message}")


def unknown(path, table, keys, allowed):
    extra = sorted(set(keys) - allowed)
    if extra:
        where = f"[{table}] " if table else ""
        raise err(path, f"{where}{extra[0]}", f"unknown key (known: {', '.join(sorted(allowed))})")


def number(path, key, value, lo, hi, kind=float):
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind is int:
        ok = ok and isinstance(value, int)
    if not ok or not lo <= value <= hi:
        raise err(
            path, key, f"must be {'an integer' if kind is int else 'a number'} from {lo:g} to {hi:g}, got {value!r}"
        )
    return kind(value)


def folder(path, key, value):
    if not isinstance(value, str) or not value:
        raise err(path, key, f"must be a folder name, got {value!r}")
    folder = (path.parent / value).resolve()
    if not folder.is_dir():
        raise err(path, key, f"folder {folder} not found")
    return folder


def names(path, key, value):
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise err(path, key, f"must be a list of joint names, got {value!r}")
    return list(value)


def file(path, key, value):
    """A file named relative to the study file, which must exist."""
    if not isinstance(value, str) or not (path.parent / value).is_file():
        raise err(path, key, f"file {path.parent / str(value)} not found")
    return (path.parent / value).resolve()
