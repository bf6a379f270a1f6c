"""`rendering.reencode` never hands back the file it was given: a video with almost nothing in it is coded at the
encoder's finest step whatever its rates, so an encode can come out byte for byte as submitted (with the dither
seed the submitted file was made with, it does); such an encode is drawn again, and one that keeps coming out so
is refused with one line and no file. The sizes a study's videos keep are tests/rendering/test_set_rate.py's."""

import dataclasses

import pytest
from helpers.fake_stimuli import write_stimulus_mp4

from rendering import reencode as reencode_module
from rendering.encode import KEY_QP
from rendering.errors import RenderError
from rendering.mp4_layout import read_layout
from rendering.reencode import reencode


@pytest.fixture
def flat(tmp_path):
    """(a study's video, a submitted one made with dither seed 1): 64 px, a dark bar moving on white."""
    return write_stimulus_mp4(tmp_path / "like.mp4"), write_stimulus_mp4(tmp_path / "src.mp4", seed=1)


def test_an_encode_that_comes_out_as_submitted_is_drawn_again(flat, tmp_path):
    like, src = flat
    out = tmp_path / "out.mp4"
    reencode(src, out, like, seed=1)  # seed 1 first: the submitted file's own rates
    assert out.read_bytes() != src.read_bytes()
    assert read_layout(out).sample_sizes == read_layout(like).sample_sizes


def test_a_video_that_keeps_coming_out_as_submitted_is_refused(flat, tmp_path, monkeypatch):
    like, src = flat
    out = tmp_path / "out.mp4"
    monkeypatch.setattr(reencode_module, "ATTEMPTS", 1)  # the one draw: seed 1, which gives the submitted bytes
    with pytest.raises(RenderError, match=r"src\.mp4: encoded again 1 times, it came out as submitted") as e:
        reencode(src, out, like, seed=1)
    assert "\n" not in str(e.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["like.mp4", "src.mp4"]


def _short_first(monkeypatch, out, short_calls):
    """Record each encode's key frame quantiser, and read the encodes numbered in `short_calls` (from 1) as x264
    leaves a key frame that codes to within a filler unit of its budget: a byte short. x264 does that by chance at
    a small size, on a picture no small input makes on demand, so the test reads it so."""
    calls = []
    real_encode, real_layout = reencode_module._reencode, reencode_module.read_layout

    def encode(*args):
        calls.append(args[-1])
        return real_encode(*args)

    def layout(path):
        lay = real_layout(path)
        if path == out and len(calls) in short_calls:
            return dataclasses.replace(lay, sample_sizes=[lay.sample_sizes[0] - 1, *lay.sample_sizes[1:]])
        return lay

    monkeypatch.setattr(reencode_module, "_reencode", encode)
    monkeypatch.setattr(reencode_module, "read_layout", layout)
    return calls


def test_an_encode_a_few_bytes_short_is_drawn_again_with_its_key_frame_at_its_own_quantiser(
    flat, tmp_path, monkeypatch
):
    like, src = flat
    out = tmp_path / "out.mp4"
    calls = _short_first(monkeypatch, out, {1})
    reencode(src, out, like, seed=2)
    assert calls == [None, KEY_QP[0]]
    assert read_layout(out).sample_sizes == read_layout(like).sample_sizes


def test_a_video_that_never_comes_out_the_studys_sizes_is_refused(flat, tmp_path, monkeypatch):
    like, src = flat
    out = tmp_path / "out.mp4"
    monkeypatch.setattr(reencode_module, "ATTEMPTS", 4)
    calls = _short_first(monkeypatch, out, {1, 2, 3, 4})
    with pytest.raises(RenderError, match=r"src\.mp4: encoded again 4 times, its frames never came out the study"):
        reencode(src, out, like, seed=2)
    assert calls == [None, *KEY_QP]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["like.mp4", "src.mp4"]


def test_the_video_itself_or_the_studys_as_out_is_refused_and_left_as_it_was(flat, tmp_path, capsys):
    """An encode that fails removes its output: with OUT the video given (or --like's), that removed the video."""
    from helpers.cli import one_line_error

    like, src = flat
    before = {p: p.read_bytes() for p in (like, src)}
    for out, name in ((src, "the video to encode"), (like, "the study's video")):
        with pytest.raises(RenderError, match=f"{out}: is {name}"):
            reencode(src, out, like)
    for out, says in (
        ("", "python -m rendering.reencode: argument out: empty"),
        (str(tmp_path), f"OUT {tmp_path}: a folder"),
    ):
        code, line = one_line_error(reencode_module.main, [str(src), out, "--like", str(like)], capsys)
        assert code == 2 and line.startswith(f"error: {says}"), line
    assert {p: p.read_bytes() for p in (like, src)} == before
