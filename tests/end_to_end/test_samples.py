"""A stochastic system's samples in a study (issue 64): K samples per item in a condition's folder
(ITEM/SAMPLE.EXT), drawn once per item at build time or per rater and unit by the app, and their spread. A whole
study with samples, built, served, rated, exported and reported, is the demo challenge's
(tests/end_to_end/test_challenge_demo.py)."""

import csv
import random
from pathlib import Path

import pandas as pd
import pytest
from helpers.own_study_data import make_study

from analysis.stats.samples import sample_scores, sample_spread
from generation.own_study.inputs import drawn_sample, match_items
from generation.own_study.study_file import read_study_file
from rating_app.store.samples import draw, group

pytestmark = pytest.mark.full  # the real actions in ../shared
K = 3


def _rows(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_one_draw_per_item_is_seeded_and_stable_when_a_condition_joins(tmp_path):
    study = make_study(tmp_path / "in", n_items=3, n_catch=1, samples=K)
    spec = read_study_file(study)
    assert spec.sample_draw == "item"
    files, samples = match_items(spec)
    chosen = {i: p.stem for i, p in files["SYS_B"].items()}
    assert set(samples) == {"SYS_B"} and all(len(v) == K for v in samples["SYS_B"].values())
    assert chosen == {i: drawn_sample(spec.seed, "SYS_B", i, [str(k) for k in range(1, K + 1)]) for i in chosen}
    # another seed draws otherwise for some item; a condition that joins changes no other condition's draw
    other = {i: drawn_sample(spec.seed + 1, "SYS_B", i, list(map(str, range(1, K + 1)))) for i in chosen}
    draws = [drawn_sample(s, "SYS_B", "item00", list(map(str, range(1, K + 1)))) for s in range(40)]
    assert len(set(draws)) == K and (other != chosen or len(chosen) < 2)
    spec.conditions["SYS_C"] = spec.conditions["SYS_B"]
    assert {i: p.stem for i, p in match_items(spec)[0]["SYS_B"].items()} == chosen


def test_a_draw_is_the_same_for_one_rater_and_unit_and_even_over_raters():
    clips = [_clip(f"s{k}aaaaaaaaaaaaa", "SYS", "test", "i1", str(k)) for k in (10, 2, 1)] + [
        _clip("naaaaaaaaaaaaaaa", "NAT", "test", "i1", "")
    ]
    every, samples = group(clips)
    head = "s1aaaaaaaaaaaaa"  # the first by sample name ("2" before "10")
    assert samples == {head: (head, "s2aaaaaaaaaaaaa", "s10aaaaaaaaaaaaa")}
    assert {c.clip_id: c.sample_of for c in every}["s10aaaaaaaaaaaaa"] == head
    assert draw("seed", 7, "u", head, samples) == draw("seed", 7, "u", head, samples)
    assert draw("seed", 7, "u", "naaaaaaaaaaaaaaa", samples) == "naaaaaaaaaaaaaaa"
    counts = pd.Series([draw("seed", r, "u", head, samples) for r in range(3000)]).value_counts()
    assert len(counts) == 3 and counts.min() > 850  # about 1000 each
    assert [draw("other", r, "u", head, samples) for r in range(50)] != [
        draw("seed", r, "u", head, samples) for r in range(50)
    ]


def _clip(cid, cond, role, item, sample):
    from rating_app.store.manifest import ManifestClip

    return ManifestClip(cid, cond, role, item, Path("/x.mp4"), 30, 30.0, sample=sample)


@pytest.mark.parametrize("sigma", [0.0, 0.6])
def test_the_spread_between_samples_is_found_when_it_is_there(sigma):
    rng = random.Random(1)
    rows = []
    for item in range(12):
        base = rng.gauss(3, 0.5)
        for sample in range(5):
            true = base + rng.gauss(0, sigma)
            rows += [dict(condition="SYS", item=f"i{item}", sample=str(sample), rating=true + rng.gauss(0, 0.8),
                          role="test") for _ in range(20)]  # fmt: skip
    (row,) = sample_spread(sample_scores(pd.DataFrame(rows))).to_dict("records")
    assert row["samples_per_item"] == 5 and row["df_samples"] == 12 * 4
    if sigma:
        assert row["p"] < 1e-6 and 0.4 < row["sigma_sample"] < 0.8
    else:
        assert row["p"] > 0.001 and row["sigma_sample"] < 0.15


@pytest.mark.parametrize(
    "layout, needle",
    [
        ({"a/1.bvh": "", "b.bvh": ""}, "has folders of samples (ITEM/SAMPLE.EXT) and files"),
        ({"a/1.bvh": "", "a/2.bvh": "", "b/1.bvh": ""}, "1 samples, where other items of condition SYS have 2"),
        ({"a/-x.bvh": "", "b/1.bvh": ""}, "is not letters, digits"),
    ],
)
def test_a_bad_folder_of_samples_is_one_line(tmp_path, layout, needle):
    from generation.own_study.inputs import condition_samples
    from generation.stimuli.files import StimuliError

    for name, text in layout.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    with pytest.raises(StimuliError, match="^" + str(tmp_path)) as e:
        condition_samples("SYS", tmp_path)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_the_reference_takes_no_samples(tmp_path):
    study = make_study(tmp_path / "in", n_items=2, n_catch=1)
    real = tmp_path / "in" / "real"
    for f in list(real.iterdir()):
        (real / f.name.split(".")[0]).mkdir()
        f.rename(real / f.name.split(".")[0] / ("1" + f.name[len(f.name.split(".")[0]) :]))
    with pytest.raises(Exception, match="is real motion, one file per item"):
        match_items(read_study_file(study))


def test_a_bad_draw_key_is_one_line(tmp_path):
    from generation.own_study.study_keys import StudyFileError

    study = make_study(tmp_path / "in", n_items=2, n_catch=1, extra_toml='[samples]\ndraw = "clip"\n')
    with pytest.raises(StudyFileError, match=r"\[samples\] draw: must be 'item' or 'rater', got 'clip'"):
        read_study_file(study)
