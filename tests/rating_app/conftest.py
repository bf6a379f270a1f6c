"""Fixtures the rating app's test modules share: the design tests' stimulus folders (small, big, the catch pool's),
a running study's folders with a new system's (add-condition and its hostile submissions), and the app's command run
in-process to a one-line error."""

import pytest
from helpers.catch_pool import CATCH_ITEMS
from helpers.fake_stimuli import write_fake_stimuli, write_stimulus_mp4
from helpers.once import built_once
from helpers.study_folders import N_ITEMS, one_size

# The three sets are read, never written, by every test that takes them: each is made once for the whole run
# (helpers.once), not once per module and worker.


@pytest.fixture(scope="session")
def stimuli(tmp_path_factory):
    folder = built_once(tmp_path_factory, "design_stimuli", lambda f: write_fake_stimuli(f, catch_nat=True))
    return folder / "manifest.csv"


@pytest.fixture(scope="session")
def big_stimuli(tmp_path_factory):
    """The balance tests' set: 3 conditions x 30 items with their mismatched clips, 4 catch items (BAD + NAT, MG,
    FL), 3 training clips."""
    return built_once(tmp_path_factory, "big_stimuli", _big) / "manifest.csv"


def _big(folder):
    write_fake_stimuli(
        folder,
        n_items=30,
        n_catch=4,
        n_frames=4,
        metrics=False,
        catch_nat=True,
        mismatched=True,  # served only by the matched-against-mismatched designs
    )


@pytest.fixture(scope="session")
def pool_stimuli(tmp_path_factory):
    """The catch-pool tests' set: 3 conditions x 30 items with their mismatched clips, 12 catch items (BAD + NAT, MG,
    FL), 3 training clips."""
    return built_once(tmp_path_factory, "pool_stimuli", _pool) / "manifest.csv"


def _pool(folder):
    write_fake_stimuli(
        folder,
        n_items=30,
        n_catch=CATCH_ITEMS,
        n_frames=4,
        metrics=False,
        catch_nat=True,
        mismatched=True,  # served only by the matched-against-mismatched designs
    )


@pytest.fixture(scope="session")
def stimulus_mp4(tmp_path_factory):
    return write_stimulus_mp4(tmp_path_factory.mktemp("mp4") / "ref.mp4")


@pytest.fixture
def folders(tmp_path, stimulus_mp4):
    """(the study's manifest, a new system's stimulus folder's manifest with NAT and SYS) in one-size sets."""
    study = write_fake_stimuli(tmp_path / "study", n_items=N_ITEMS, catch_nat=True)
    new = write_fake_stimuli(tmp_path / "new", n_items=N_ITEMS, conditions=("NAT", "SYS"), catch_nat=True, seed=1)
    one_size(study.parent, stimulus_mp4)
    one_size(new.parent, stimulus_mp4)
    return study, new


@pytest.fixture
def command_fails(capsys, monkeypatch):
    """fails(*args, needle=...): `python -m rating_app ARGS`'s main run in this process (a process each took a second
    or two), which must stop with one line on stderr that starts with "error: " and says `needle`, nothing on stdout,
    no traceback, and exit 2; returns that line. `serve` must stop before it serves: Flask's run would wait for ever,
    so here it fails the test. The commands' own processes: tests/rating_app/test_cli.py's test_serve_cli and
    test_export_cli_errors, tests/project/test_console.py."""
    from flask import Flask

    from rating_app.__main__ import main

    def served(*args, **kwargs):
        pytest.fail("serve started the app where it should have stopped with one line")

    monkeypatch.setattr(Flask, "run", served)

    def fails(*args, needle):
        capsys.readouterr()
        try:
            code = main([str(a) for a in args])
        except SystemExit as e:  # argparse's
            code = e.code
        out, err = capsys.readouterr()
        lines = err.strip().splitlines()
        assert code == 2 and out == "" and "Traceback" not in err, (code, out, err)
        assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], err
        return lines[0]

    return fails
