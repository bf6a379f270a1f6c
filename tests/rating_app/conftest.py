"""Fixtures the rating app's test modules share: the design tests' stimulus folders (small, big, the catch pool's),
and a running study's folders with a new system's (add-condition and its hostile submissions)."""

import pytest
from helpers.catch_pool import CATCH_ITEMS
from helpers.fake_stimuli import write_fake_stimuli, write_stimulus_mp4
from helpers.study_folders import N_ITEMS, one_size


@pytest.fixture(scope="module")
def stimuli(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("design_stimuli"), catch_nat=True)


@pytest.fixture(scope="module")
def big_stimuli(tmp_path_factory):
    """The balance tests' set: 3 conditions x 30 items with their mismatched clips, 4 catch items (BAD + NAT, MG,
    FL), 3 training clips."""
    return write_fake_stimuli(
        tmp_path_factory.mktemp("big_stimuli"),
        n_items=30,
        n_catch=4,
        n_frames=4,
        metrics=False,
        catch_nat=True,
        mismatched=True,  # served only by the matched-against-mismatched designs
    )


@pytest.fixture(scope="module")
def pool_stimuli(tmp_path_factory):
    """The catch-pool tests' set: 3 conditions x 30 items with their mismatched clips, 12 catch items (BAD + NAT, MG,
    FL), 3 training clips."""
    return write_fake_stimuli(
        tmp_path_factory.mktemp("pool_stimuli"),
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
