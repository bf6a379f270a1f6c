"""Session fixtures made once per test run, not once per xdist worker.

The suite runs on two workers (pyproject's addopts), and a session fixture is a session of each worker: the
`make_stimuli --quick` run alone took about 50 s on each of them. Here the first worker to ask builds the folder
under a file lock, in the run's base folder that the workers share, and the others wait and take the same one.
Every user of these fixtures only reads them, so sharing one copy is safe."""

import os
import shutil

from filelock import FileLock

BUILT = ".built"  # written last: a folder without it is a build that failed or was cut off


def built_once(tmp_path_factory, name, build):
    """The folder `name`, filled by `build(folder)` once for the whole run; without xdist, this session's own."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        folder = tmp_path_factory.mktemp(name)
        build(folder)
        return folder
    shared = tmp_path_factory.getbasetemp().parent  # pytest-N: this run's, the workers' basetemps inside it
    folder = shared / name
    with FileLock(str(shared / f"{name}.lock")):
        if not (folder / BUILT).is_file():
            shutil.rmtree(folder, ignore_errors=True)  # a failed build is built again, and fails its test too
            folder.mkdir()
            build(folder)
            (folder / BUILT).touch()
    return folder
