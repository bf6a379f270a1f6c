"""analysis.demo's check of --items for a study with speech: the bounds it refuses outside are the ones the command
that makes that study takes (one fact, in moglow_eval.core.study), so the demo never refuses a size the study could
make, nor clears an earlier run for one it cannot."""

import pytest

from analysis.demo import DemoError, run_demo, speech_items
from generation.own_study import demo_dyad, demo_study
from moglow_eval.core.study import MISMATCH_COLUMN, TWO_PERSON_DEMO_DESIGNS


@pytest.mark.parametrize("design", ["acr", *MISMATCH_COLUMN])
def test_the_demos_items_bounds_are_its_study_commands_own(design, capsys):
    (low, high), _ = speech_items(design)
    maker = demo_dyad if design in TWO_PERSON_DEMO_DESIGNS else demo_study
    for n in (low, high):
        assert maker.build_parser().parse_args(["--out", "x", "--items", str(n)]).items == n
    for n in (low - 1, high + 1):
        with pytest.raises(SystemExit) as e:
            maker.build_parser().parse_args(["--out", "x", "--items", str(n)])
        assert e.value.code == 2 and "--items" in capsys.readouterr().err


def test_one_person_talking_takes_more_items_than_two_people(tmp_path):
    """Before the bounds were one fact, a study of one person talking was held to the two-person demo's thirty."""
    (_, one), _ = speech_items("appropriateness")
    (_, two), _ = speech_items("dyadic")
    assert one > two
    with pytest.raises(DemoError, match=f"two people talking has 3 to {two} items, not {two + 1}"):
        run_demo(tmp_path / "demo", design="dyadic", items=two + 1)
    assert not (tmp_path / "demo").exists()  # refused before it touched anything
