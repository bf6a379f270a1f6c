"""The export carries the manifest's style (CONTRACTS §4, §7): one clip per style, each its own stimulus, and a
`style` column in ratings.csv; a manifest without styles gives an export without the column."""

import pytest
from helpers.api_client import rate_everything
from helpers.fake_stimuli import write_fake_stimuli

from rating_app.store.manifest import load_manifest


@pytest.fixture(scope="module")
def styled(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("styled"), n_items=2, n_training=1, styles=("stick", "solid"))


def test_fake_stimuli_write_every_clip_in_each_style(styled, tmp_path):
    clips = load_manifest(styled)
    assert {c.style for c in clips} == {"stick", "solid"}
    per = {}
    for c in clips:
        per.setdefault((c.condition, c.role, c.item), []).append(c.style)
    assert all(sorted(v) == ["solid", "stick"] for v in per.values())
    plain = load_manifest(write_fake_stimuli(tmp_path / "plain", n_items=2, n_training=1))
    assert {c.style for c in plain} == {""} and len(plain) * 2 == len(clips)


def test_ratings_export_has_each_clips_style(make_app, styled, tmp_path):
    app = make_app(manifest=styled, ratings_per_clip=1, min_view=0)
    rows = rate_everything(app.test_client())
    style = {c.clip_id: c.style for c in load_manifest(styled)}
    assert rows and "style" in rows[0]
    assert all(r["style"] == style[r["clip_id"]] for r in rows)
    assert {r["style"] for r in rows} == {"stick", "solid"}


def test_an_export_without_styles_has_no_style_column(make_app, tmp_path):
    plain = write_fake_stimuli(tmp_path / "plain", n_items=2, n_training=1)
    rows = rate_everything(make_app(manifest=plain, ratings_per_clip=1, min_view=0).test_client())
    assert rows and "style" not in rows[0]


def test_row_style_joins_a_pairs_two_styles():
    from rating_app.designs.export_cells import row_style

    styles = {"a": "stick", "b": "solid", "c": "stick"}
    assert row_style({"clip_id": "a"}, styles) == "stick"
    assert row_style({"clip_a": "a", "clip_b": "c"}, styles) == "stick"
    assert row_style({"clip_a": "a", "clip_b": "b"}, styles) == "stick/solid"
    assert row_style({"clip_id": "zz"}, styles) == ""
