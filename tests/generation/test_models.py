"""Sampling API and CLI of trained tiny FL/MG checkpoints: reproducibility, streaming, fast vs plain MG."""

import subprocess
import sys

import numpy as np
import pytest
import torch
from reference.moglow_naive import inverse_naive

from generation.models.moglow import MoGlow
from generation.sampling.sample import SampleError, load_model, mg_stream, sample_fl, sample_mg
from generation.sampling.sample import main as sample_main
from generation.training.config import load_config, model_config
from moglow_eval.core.clip import load_clip

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def last_ckpt(run):
    return sorted((run / "checkpoints").glob("step_*.pt"))[-1]


@pytest.fixture(scope="module")
def test_split(small_dataset):
    with np.load(small_dataset) as d:
        return {k: d[f"test_{k}"][:4] for k in ("x", "c", "hist", "hist_c")}


def test_checkpoint_reload_reproduces_sample(tiny_runs, test_split):
    s = test_split
    for kind in ("mg", "fl"):
        a_model, b_model = load_model(last_ckpt(tiny_runs[kind])), load_model(last_ckpt(tiny_runs[kind]))
        assert a_model.kind == kind and not a_model.training and a_model.step == 150
        if kind == "mg":
            a = sample_mg(a_model, s["c"], s["hist"], s["hist_c"], temperature=0.8, seed=5)
            b = sample_mg(b_model, s["c"], s["hist"], s["hist_c"], temperature=0.8, seed=5)
            other = sample_mg(b_model, s["c"], s["hist"], s["hist_c"], temperature=0.8, seed=6)
        else:
            a = sample_fl(a_model, s["c"], temperature=0.8, seed=5)
            b = sample_fl(b_model, s["c"], temperature=0.8, seed=5)
            other = sample_fl(b_model, s["c"], temperature=0.8, seed=6)
        assert a.shape == s["x"].shape and a.dtype == np.float32 and np.isfinite(a).all()
        np.testing.assert_array_equal(a, b)
        assert not np.allclose(a, other)


def test_samples_are_in_the_data_range(tiny_runs, test_split):
    """Un-standardised output: poses in metres near the data's scale (a trained model, temperature 0.7)."""
    s = test_split
    model = load_model(last_ckpt(tiny_runs["mg"]))
    x = sample_mg(model, s["c"], s["hist"], s["hist_c"], temperature=0.7, seed=0)
    mean, std = model.x_mean.cpu().numpy(), model.x_std.cpu().numpy()  # the model is on CUDA where there is one
    assert np.abs((x - mean) / std).mean() < 3.0
    head_y = x[..., 3 * 4 + 1]  # the head is above the hips in the root frame
    assert (head_y > 0.2).mean() > 0.9


def test_streaming_matches_batch_sampling(tiny_runs, test_split):
    s = test_split
    model = load_model(last_ckpt(tiny_runs["mg"]))
    batch = sample_mg(model, s["c"], s["hist"], s["hist_c"], temperature=1.0, seed=3)
    step = mg_stream(model, s["hist"], s["hist_c"], temperature=1.0, seed=3)
    frames = np.stack([step(s["c"][:, t]) for t in range(12)], axis=1)
    np.testing.assert_allclose(frames, batch[:, :12], rtol=0, atol=1e-6)


@pytest.mark.parametrize("layout", ["row", "col"])
def test_fast_sampler_matches_plain_lstm_and_inverts_forward(tiny_runs, test_split, layout):
    """MGStream (fused weights, either layout) == nn.LSTM called per step; and forward(inverse(z)) == z."""
    model = load_model(last_ckpt(tiny_runs["mg"]))
    s = test_split
    dev = model.x_mean.device  # load_model puts it on CUDA where there is one
    hist = model.standardize_x(torch.from_numpy(s["hist"]).to(dev))
    c = model.standardize_c(torch.from_numpy(np.concatenate([s["hist_c"], s["c"][:, :15]], axis=1)).to(dev))
    z = torch.randn(4, 15, 63, generator=torch.Generator().manual_seed(0)).to(dev)
    fast = model.inverse(z, hist, c, layout=layout)
    plain = inverse_naive(model, z, hist, c)
    assert torch.allclose(fast, plain, atol=1e-5), (fast - plain).abs().max()
    one = model.inverse(z[:1], hist[:1], c[:1], layout=layout)  # one stream
    assert torch.allclose(one, plain[:1], atol=1e-5), (one - plain[:1]).abs().max()
    with torch.no_grad():
        z_back, _ = model(torch.cat([hist, fast], dim=1), c)
    assert torch.allclose(z_back, z, atol=1e-3), (z_back - z).abs().max()


@pytest.mark.parametrize("layout", ["row", "col"])
def test_bfloat16_sampler_follows_float32_and_repeats_its_bits(tiny_runs, test_split, layout):
    """precision="bfloat16" reads the big products in bfloat16 and keeps the rest float32: near the float32
    stream (not on its bits), and the same bits run after run."""
    from generation.models.mg_stream import MGStream

    model = load_model(last_ckpt(tiny_runs["mg"]))
    s, dev = test_split, model.x_mean.device
    hist = model.standardize_x(torch.from_numpy(s["hist"]).to(dev))
    hist_c = model.standardize_c(torch.from_numpy(s["hist_c"]).to(dev))
    c = model.standardize_c(torch.from_numpy(s["c"][:, :15]).to(dev))
    z = torch.randn(4, 15, 63, generator=torch.Generator().manual_seed(0)).to(dev)

    def frames(precision):
        stream = MGStream(model, hist, hist_c, layout=layout, precision=precision)
        return stream, torch.stack([stream.step(c[:, t], z=z[:, t]) for t in range(15)], dim=1)

    (full, x32), (low, x16), (_, again) = frames("float32"), frames("bfloat16"), frames("bfloat16")
    assert full.w["Whh"][0].dtype == torch.float32
    assert low.w["Whh"][0].dtype == low.w["Wih"][1].dtype == torch.bfloat16 and low.h[0].dtype == torch.float32
    assert x16.dtype == torch.float32 and torch.equal(x16, again)
    gap = (x16 - x32).abs().max()
    assert 1e-6 < gap < 0.05, gap  # standardised units: bfloat16's rounding, not another model
    with pytest.raises(ValueError, match="precision"):
        MGStream(model, hist, hist_c, precision="float16")


def test_temperature_zero_is_deterministic(tiny_runs, test_split):
    s = test_split
    model = load_model(last_ckpt(tiny_runs["fl"]))
    np.testing.assert_array_equal(sample_fl(model, s["c"], 0.0, seed=1), sample_fl(model, s["c"], 0.0, seed=2))


def test_sampling_errors(tiny_runs, test_split, tmp_path):
    mg = load_model(last_ckpt(tiny_runs["mg"]))
    with pytest.raises(SampleError, match="FL"):
        sample_fl(mg, test_split["c"])
    with pytest.raises(SampleError, match="tau"):
        sample_mg(mg, test_split["c"], test_split["hist"][:, :3], test_split["hist_c"][:, :3])
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(SampleError, match="bad.pt"):
        load_model(bad)


def test_sample_cli_writes_clips(tiny_runs, small_dataset, tmp_path, capsys):
    for kind in ("mg", "fl"):
        out = tmp_path / kind
        args = [
            "--checkpoint",
            str(last_ckpt(tiny_runs[kind])),
            "--data",
            str(small_dataset),
            "--split",
            "test",
            "--n",
            "2",
            "--out",
            str(out),
        ]
        if kind == "mg":  # the real command line once; in-process for the rest (saves a torch start-up)
            r = subprocess.run(
                [sys.executable, "-m", "generation.sampling.sample", *args], capture_output=True, text=True
            )
            assert r.returncode == 0, r.stderr
        else:
            assert sample_main(args) == 0
        clips = sorted(out.glob("*.npz"))
        assert len(clips) == 2
        clip = load_clip(clips[0])
        assert clip["joints"].shape == (80, 21, 3) and clip["fps"] == 20.0
        assert np.isfinite(clip["joints"]).all()
        assert clip["joints"][:, :, 1].min() > -0.3  # roughly above the floor
    capsys.readouterr()
    assert (
        sample_main(
            ["--checkpoint", str(tmp_path / "none.pt"), "--data", str(small_dataset), "--out", str(tmp_path / "x")]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "none.pt" in err and len(err.strip().splitlines()) == 1


def test_paper_configs_build_models_of_the_papers_size():
    mg = MoGlow(model_config(load_config("mg", "paper")))
    assert len(mg.flow.layers) == 16
    lstm = mg.flow.layers[0].layers[2].net.lstm
    assert (lstm.hidden_size, lstm.num_layers) == (512, 2)
    assert mg.cond_dim == 10 * 63 + 11 * 3
    n_lstm = sum(p.numel() for s in mg.flow.layers for p in s.layers[2].net.lstm.parameters())
    assert 280e6 < 4 * n_lstm < 300e6  # ~292 MB of LSTM weights read per generated frame
    fl_cfg = load_config("fl", "paper")
    assert (fl_cfg.L, fl_cfg.K) == (4, 32)


def test_layout_is_a_fixed_choice_never_a_timing(tiny_runs, monkeypatch):
    """The two layouts round differently, so the choice must not depend on a timing (issue 15, item 5)."""
    from generation.models.mg_stream import LAYOUTS, MGStream, cpu_vendor, default_layout

    model = load_model(last_ckpt(tiny_runs["mg"]))
    hist, hist_c = torch.zeros(3, model.tau, 63), torch.zeros(3, model.tau, 3)
    monkeypatch.delenv("MOGLOW_LAYOUT", raising=False)
    assert default_layout("cpu", 1) == "row"
    assert default_layout("cpu", 30) == ("row" if cpu_vendor() == "AuthenticAMD" else "col")
    assert default_layout("cuda", 30) == "row" and default_layout(torch.device("cuda:0"), 1) == "row"
    assert MGStream(model, hist, hist_c).layout == default_layout("cpu", 3)
    other = next(name for name in LAYOUTS if name != default_layout("cpu", 3))
    monkeypatch.setenv("MOGLOW_LAYOUT", other)
    assert MGStream(model, hist, hist_c).layout == other
    monkeypatch.setenv("MOGLOW_LAYOUT", "diagonal")
    with pytest.raises(ValueError, match="MOGLOW_LAYOUT"):
        MGStream(model, hist, hist_c)
    monkeypatch.delenv("MOGLOW_LAYOUT")
    with pytest.raises(ValueError, match="layout"):
        MGStream(model, hist, hist_c, layout="diagonal")


@pytest.mark.parametrize("layout", ["row", "col"])
@pytest.mark.parametrize("streams", [1, 3])
def test_stream_frames_are_the_callers_own(tiny_runs, layout, streams):
    """A frame returned by step() is a tensor of its own: the next step(), which reuses the stream's buffers,
    leaves it as it was, and it matches the frame that a fresh stream gives for the same inputs."""
    from generation.models.mg_stream import MGStream

    model = load_model(last_ckpt(tiny_runs["mg"]))
    g = torch.Generator().manual_seed(1)
    hist, hist_c = torch.randn(streams, model.tau, 63, generator=g), torch.randn(streams, model.tau, 3, generator=g)
    c, z = torch.randn(2, streams, 3, generator=g), torch.randn(2, streams, 63, generator=g)
    dev = model.x_mean.device
    hist, hist_c, c, z = hist.to(dev), hist_c.to(dev), c.to(dev), z.to(dev)
    stream = MGStream(model, hist, hist_c, layout=layout)
    first = stream.step(c[0], z=z[0])
    kept = first.clone()
    second = stream.step(c[1], z=z[1])
    assert torch.equal(first, kept)
    assert not torch.equal(first, second)
    assert torch.equal(first, MGStream(model, hist, hist_c, layout=layout).step(c[0], z=z[0]))


@pytest.mark.parametrize("kind, precision", [("mg", "float32"), ("mg", "bfloat16"), ("fl", "float32")])
def test_two_sampling_processes_give_identical_bits(tiny_runs, small_dataset, tmp_path, kind, precision):
    """The same checkpoint, seed and inputs in two fresh processes: the same clip files, byte for byte (on a GPU
    too: MG's products go through cuBLAS, FL's convolutions through cuDNN)."""
    outs = []
    for run in ("a", "b"):
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "generation.sampling.sample",
                "--checkpoint",
                str(last_ckpt(tiny_runs[kind])),
                "--data",
                str(small_dataset),
                "--n",
                "3",
                "--seed",
                "4",
                "--precision",
                precision,
                "--out",
                str(tmp_path / run),
            ],
            capture_output=True,
            text=True,
        )
        assert r.returncode == 0, r.stderr
        outs.append(sorted((tmp_path / run).glob("*.npz")))
    assert len(outs[0]) == 3
    for a, b in zip(*outs):
        assert np.array_equal(load_clip(a)["joints"], load_clip(b)["joints"])


def test_non_finite_samples_never_become_clips(tiny_runs, test_split, small_dataset, tmp_path, capsys):
    """A model whose inverse gives NaN (here: one poisoned weight) stops the sample CLI and make_stimuli with one
    line each, instead of writing clips that would render as broken videos."""
    from generation.make_stimuli import sample_condition

    ck = torch.load(last_ckpt(tiny_runs["mg"]), weights_only=True)
    name = next(k for k, v in ck["state"].items() if k.endswith("weight") and v.is_floating_point())
    ck["state"][name].view(-1)[0] = float("nan")
    poisoned = tmp_path / "poisoned.pt"
    torch.save(ck, poisoned)
    out = tmp_path / "clips"
    args = ["--checkpoint", str(poisoned), "--data", str(small_dataset), "--n", "2", "--out", str(out)]
    assert sample_main(args) == 2
    err = capsys.readouterr().err
    assert "poisoned.pt" in err and "NaN or inf" in err and len(err.strip().splitlines()) == 1
    assert not out.exists() or not list(out.glob("*.npz"))
    arrays = {k: test_split[k] for k in ("x", "c", "hist", "hist_c")}
    with pytest.raises(SampleError, match="poisoned.pt: 2 of 2 sampled windows hold NaN or inf"):
        sample_condition("mg", poisoned, arrays, [0, 1], 1.0, 0, None)
    assert sample_condition("mg", last_ckpt(tiny_runs["mg"]), arrays, [0, 1], 1.0, 0, None).shape == (2, 80, 63)
