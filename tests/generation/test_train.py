"""Training: NLL falls on real data, files per CONTRACTS.md §3, reproducible and resumable, CLI errors."""

import csv
import json
import subprocess
import sys
from dataclasses import FrozenInstanceError, replace

import numpy as np
import pytest
import torch

from generation.data.dataset import DatasetError, batch_indices, category_weights
from generation.training.config import as_dict
from generation.training.train import (
    TrainError,
    build_model,
    draw_batch,
    learning_rate,
    load_config,
    main,
    make_optimiser,
    train,
)

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def rows(run):
    with open(run / "metrics.csv") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("kind", ["mg", "fl"])
def test_nll_falls_on_real_data(tiny_runs, kind):
    """150 steps of a tiny model on a small real training set: NLL well below its starting value."""
    m = rows(tiny_runs[kind])
    assert [int(r["step"]) for r in m] == [1, 50, 100, 150]
    first, last = float(m[0]["train_nll"]), float(m[-1]["train_nll"])
    assert last < first - 0.5, (first, last)
    assert all(abs(float(r["valid_nll"])) < 50 for r in m)  # valid NLL computed and finite (tiny sets overfit)


@pytest.mark.parametrize("kind", ["mg", "fl"])
def test_run_folder_follows_contract(tiny_runs, kind):
    run = tiny_runs[kind]
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["model"] == kind and cfg["seed"] == 0
    steps = sorted(int(p.stem.split("_")[1]) for p in (run / "checkpoints").glob("step_*.pt"))
    assert steps == [5, 10, 50, 100, 150]  # early checkpoints kept for the bad examples
    ck = torch.load(run / "checkpoints" / "step_0000005.pt", weights_only=True)
    for key in ("kind", "config", "state", "stats", "tau", "fps", "window", "step"):
        assert key in ck
    assert ck["kind"] == kind and ck["fps"] == 20.0 and ck["window"] == 80 and ck["step"] == 5


def state(run):
    ck = torch.load(sorted((run / "checkpoints").glob("step_*.pt"))[-1], weights_only=True)
    return ck["state"]


def test_seeded_run_is_reproducible_and_resume_is_exact(small_dataset, tmp_path):
    a = train("mg", "tiny", small_dataset, tmp_path / "a", steps=12, seed=1, progress=False)
    b = train("mg", "tiny", small_dataset, tmp_path / "b", steps=6, seed=1, progress=False)
    b = train("mg", "tiny", small_dataset, tmp_path / "b", steps=12, seed=1, progress=False, resume=True)
    c = train("mg", "tiny", small_dataset, tmp_path / "c", steps=12, seed=2, progress=False)
    sa, sb, sc = state(a), state(b), state(c)
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert not all(torch.equal(sa[k], sc[k]) for k in sa)
    assert [r["step"] for r in rows(b)] == ["1", "6", "12"]


def test_bfloat16_training_follows_float32_and_is_recorded(small_dataset, tmp_path):
    """precision 'bfloat16' (the coupling networks under autocast) trains the same model to nearly the same
    NLL as float32, not to the same bits, and the run's config.json says which it was."""
    a = train("mg", "tiny", small_dataset, tmp_path / "a", steps=30, progress=False)
    b = train("mg", "tiny", small_dataset, tmp_path / "b", steps=30, progress=False, precision="bfloat16")
    assert json.loads((b / "config.json").read_text())["precision"] == "bfloat16"
    assert json.loads((a / "config.json").read_text())["precision"] == "float32"
    nll_a, nll_b = (float(rows(r)[-1]["valid_nll"]) for r in (a, b))
    assert nll_a != nll_b and abs(nll_a - nll_b) < 0.05, (nll_a, nll_b)
    assert float(rows(a)[-1]["valid_nll"]) < float(rows(a)[0]["valid_nll"]) - 0.2


def test_float32_optimiser_keeps_the_bits_of_the_shipped_recipe():
    """The shipped models were trained with torch's one-tensor-at-a-time Adam; training's optimiser must give the
    same bits in float32 (so --retrain reproduces them), while bfloat16 runs may take the fused kernel."""
    cfg = load_config("mg", "tiny")
    x, c = torch.randn(4, 14, 63), torch.randn(4, 14, 3)
    states = []
    for make in (lambda net: make_optimiser(net, cfg), lambda net: torch.optim.Adam(net.parameters(), cfg.lr)):
        torch.manual_seed(0)
        net = build_model("mg", cfg)
        opt = make(net)
        for _ in range(3):
            opt.zero_grad()
            net.nll(x, c).mean().backward()
            opt.step()
        states.append(net.state_dict())
    assert all(torch.equal(states[0][k], states[1][k]) for k in states[0])
    assert make_optimiser(net, replace(cfg, precision="bfloat16")).defaults["fused"]


def test_history_noise_reaches_the_history_only():
    """history_noise perturbs the poses that MG's conditioning reads and leaves the target clean; without it the
    batch is drawn exactly as before (the shipped recipe's random stream), and FL never gets a history."""
    torch.manual_seed(0)
    tx, tc = torch.randn(20, 40, 63), torch.randn(20, 40, 3)
    cfg = replace(load_config("mg", "tiny"), train_window=30)
    net = build_model("mg", cfg)
    x0, c0, keep0, hist0, _ = draw_batch(net, tx, tc, cfg, 0, 3, 30)
    x1, c1, keep1, hist1, _ = draw_batch(net, tx, tc, replace(cfg, history_noise=0.05), 0, 3, 30)
    assert hist0 is None
    assert torch.equal(x0, x1) and torch.equal(c0, c1) and torch.equal(keep0, keep1)
    assert 0.04 < (hist1 - x1).std().item() < 0.06
    with torch.no_grad():  # couplings that read their conditioning (the last layers start at zero)
        for step in net.flow.layers:
            step.layers[2].net.out.weight.normal_(0, 0.1)
    net.train()
    assert not torch.equal(net.nll(x1, c1, keep1), net.nll(x1, c1, keep1, hist1))
    assert torch.equal(net.nll(x1, c1, keep1), net.nll(x1, c1, keep1, x1))
    fl_cfg = replace(load_config("fl", "tiny"), history_noise=0.05)
    assert draw_batch(build_model("fl", fl_cfg), tx, tc, fl_cfg, 0, 3, 32)[3] is None


def test_stance_latents_are_drawn_last_and_only_when_used():
    """With stance_temperature the stance loss's latents come with the batch (every rank draws the same and keeps
    its rows, as for the rest); without it, or before stance_start, the batch is drawn exactly as before."""
    torch.manual_seed(0)
    tx, tc = torch.randn(20, 40, 63), torch.randn(20, 40, 3)
    cfg = replace(load_config("mg", "tiny"), stance_weight=1.0, stance_start=2, stance_temperature=0.5)
    net = build_model("mg", cfg)
    drawn = draw_batch(net, tx, tc, cfg, 0, 3, 30)
    plain = draw_batch(net, tx, tc, replace(cfg, stance_temperature=0.0), 0, 3, 30)
    assert plain[4] is None and all(torch.equal(a, b) for a, b in zip(drawn[:3], plain[:3]))
    assert drawn[4].shape == drawn[0].shape and 0.45 < drawn[4].std().item() < 0.55
    assert draw_batch(net, tx, tc, cfg, 0, 1, 30)[4] is None  # before stance_start


def test_learning_rate_warms_up_then_holds_or_decays_to_lr_min():
    cfg = load_config("mg", {"lr": 1e-3, "warmup": 10, "steps": 110})
    lrs = [learning_rate(cfg, s) for s in range(110)]
    assert lrs[0] == pytest.approx(1e-4) and lrs[9] == pytest.approx(1e-3)
    assert all(a < b for a, b in zip(lrs[:10], lrs[1:10]))
    assert set(lrs[10:]) == {1e-3}  # no lr_min: constant after the warm-up
    cfg = replace(cfg, lr_min=1e-5)
    lrs = [learning_rate(cfg, s) for s in range(110)]
    assert lrs[10] == pytest.approx(1e-3) and lrs[-1] == pytest.approx(1e-5)
    assert all(a >= b for a, b in zip(lrs[10:], lrs[11:]))  # cosine: never rises
    assert lrs[60] == pytest.approx((1e-3 + 1e-5) / 2, rel=0.02)  # halfway down at mid-decay


def test_warm_restart_keeps_the_first_phase_and_starts_a_second():
    plain = load_config("mg", {"lr": 1e-3, "lr_min": 1e-4, "warmup": 10, "steps": 60})
    cfg = replace(plain, steps=100, restart_step=60, restart_lr=3e-4, restart_lr_min=3e-5)
    assert [learning_rate(cfg, s) for s in range(60)] == [learning_rate(plain, s) for s in range(60)]
    second = [learning_rate(cfg, s) for s in range(60, 100)]
    assert second[0] == pytest.approx(3e-5) and second[9] == pytest.approx(3e-4)  # warm-up again
    assert second[-1] == pytest.approx(3e-5) and all(a >= b for a, b in zip(second[9:], second[10:]))


def test_warm_restart_resets_adam_and_resumes_exactly(small_dataset, tmp_path):
    cfg = replace(load_config("mg", "tiny"), steps=10, restart_step=6, restart_lr=3e-4, restart_lr_min=3e-5)
    a = train("mg", cfg, small_dataset, tmp_path / "a", steps=10, seed=1, progress=False)
    b = train("mg", cfg, small_dataset, tmp_path / "b", steps=6, seed=1, progress=False)
    b = train("mg", cfg, small_dataset, tmp_path / "b", steps=10, seed=1, progress=False, resume=True)
    sa, sb = state(a), state(b)
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    opt = torch.load(a / "resume.pt", weights_only=True)["opt"]["state"]
    assert {int(v["step"]) for v in opt.values()} == {4}  # Adam counted afresh from step 6
    short = train("mg", cfg, small_dataset, tmp_path / "short", steps=5, seed=1, progress=False)
    assert json.loads((short / "config.json").read_text())["restart_step"] is None  # too short to restart


def test_warm_restart_config_errors():
    with pytest.raises(TrainError, match="'restart_step' must lie between 0 and 'steps'"):
        load_config("fl", {"steps": 100, "restart_step": 100, "restart_lr": 1e-4, "restart_lr_min": 1e-5})
    with pytest.raises(TrainError, match="needs 'restart_lr_min'"):
        load_config("fl", {"steps": 100, "restart_step": 50, "restart_lr": 1e-4})


def test_stance_loss_starts_at_its_step_and_is_booked(small_dataset, tmp_path):
    cfg = replace(load_config("mg", "tiny"), steps=6, valid_every=1, stance_weight=1.0, stance_start=3)
    run = train("mg", cfg, small_dataset, tmp_path / "a", seed=1, progress=False)
    stance = [float(r["train_stance"]) for r in rows(run)]
    assert stance[:3] == [0.0, 0.0, 0.0] and all(s > 0 for s in stance[3:])
    plain = replace(cfg, steps=3, stance_weight=0.0)
    plain = train("mg", plain, small_dataset, tmp_path / "b", seed=1, progress=False)
    assert [r["train_nll"] for r in rows(plain)] == [r["train_nll"] for r in rows(run)[:3]]
    with pytest.raises(TrainError, match="field 'stance_weight' must be at least 0"):
        load_config("fl", {"stance_weight": -1})


def test_category_weights_balance_the_categories():
    labels = np.array(["walk"] * 900 + ["side"] * 100)
    assert category_weights(labels, 0.0) is None  # uniform: batch_indices draws as it always has
    even = category_weights(labels, 1.0)
    assert even.sum() == pytest.approx(1) and even[labels == "side"].sum() == pytest.approx(0.5)
    half = category_weights(labels, 0.5)
    assert half[labels == "walk"].sum() / half[labels == "side"].sum() == pytest.approx(3.0)  # sqrt(900 / 100)
    drawn = np.concatenate([batch_indices(1000, 32, 0, step, even).numpy() for step in range(100)])
    assert 0.45 < np.mean(drawn >= 900) < 0.55  # against 0.1 without the weights
    assert np.array_equal(batch_indices(1000, 32, 3, 7, even), batch_indices(1000, 32, 3, 7, even))


def test_category_balance_draws_rare_categories_more_often(small_dataset, tmp_path):
    """A balanced run trains on other batches than a uniform one, reproducibly; a dataset without labels, or a
    negative balance, is a one-line config error."""
    cfg = replace(load_config("mg", "tiny"), steps=3, valid_every=1)
    plain = train("mg", cfg, small_dataset, tmp_path / "a", seed=1, progress=False)
    bal = replace(cfg, category_balance=1.0)
    b1 = train("mg", bal, small_dataset, tmp_path / "b", seed=1, progress=False)
    b2 = train("mg", bal, small_dataset, tmp_path / "c", seed=1, progress=False)
    assert [r["train_nll"] for r in rows(b1)] == [r["train_nll"] for r in rows(b2)]
    assert [r["train_nll"] for r in rows(b1)] != [r["train_nll"] for r in rows(plain)]
    with pytest.raises(TrainError, match="field 'category_balance' must be at least 0"):
        load_config("mg", {"category_balance": -0.5})
    d = dict(np.load(small_dataset))
    del d["train_labels"]
    unlabelled = tmp_path / "unlabelled.npz"
    np.savez(unlabelled, **d)
    with pytest.raises(TrainError, match="unlabelled.npz: config field 'category_balance' needs 'train_labels'"):
        train("mg", bal, unlabelled, tmp_path / "d", seed=1, progress=False)
    d["train_labels"] = np.array(["walk"] * 3)
    short = tmp_path / "short_labels.npz"
    np.savez(short, **d)
    with pytest.raises(DatasetError, match=r"short_labels.npz: 'train_labels' \(3,\) does not match \d+ windows"):
        train("mg", bal, short, tmp_path / "e", seed=1, progress=False)


def test_config_names_and_errors(tmp_path):
    assert load_config("mg", "tiny").K == 2
    assert load_config("fl", "cpu").model == "fl"
    for kind in ("fl", "mg"):
        for name in ("paper", "cpu", "tiny"):
            load_config(kind, name)
    bad = tmp_path / "bad.json"
    bad.write_text('{"model": "mg", "K": 2, "hiden": 8}')
    with pytest.raises(TrainError, match="unknown field 'hiden'"):
        load_config("mg", str(bad))
    bad.write_text('{"model": "mg",\n "K": }')
    with pytest.raises(TrainError, match="bad.json:2"):
        load_config("mg", str(bad))
    with pytest.raises(TrainError, match="'model' is 'fl'"):
        load_config("mg", {"model": "fl"})
    with pytest.raises(TrainError, match="config: field 'residual' must be true or false, got 'yes'"):
        load_config("mg", {"residual": "yes"})
    with pytest.raises(TrainError, match="unknown field 'residual'"):
        load_config("fl", {"residual": True})
    with pytest.raises(TrainError, match="config: field 'carry_feet' must be true or false, got 1"):
        load_config("mg", {"residual": True, "carry_feet": 1})
    with pytest.raises(TrainError, match="config: field 'history_style' must be true or false, got 'on'"):
        load_config("mg", {"history_style": "on"})
    with pytest.raises(TrainError, match="unknown field 'history_style'"):
        load_config("fl", {"history_style": True})
    with pytest.raises(TrainError, match="config: field 'style_span' needs 'history_style' true"):
        load_config("mg", {"style_span": 40})
    with pytest.raises(TrainError, match="config: field 'style_span' must be a whole number, got 20.5"):
        load_config("mg", {"history_style": True, "style_span": 20.5})
    with pytest.raises(TrainError, match="config: field 'spread_weight' must be at least 0, got -1"):
        load_config("fl", {"spread_weight": -1})
    with pytest.raises(TrainError, match="config: field 'carry_feet' needs 'residual' true"):
        load_config("mg", {"carry_feet": True})
    with pytest.raises(
        TrainError, match="config: field 'precision' must be one of \\['bfloat16', 'float32'\\], got 'half'"
    ):
        load_config("fl", {"precision": "half"})


def test_config_fields_are_checked_by_their_types(tmp_path):
    """The checks come from the dataclass fields: each type and bound gives one line naming the file and field,
    a whole float is taken as the whole number it is, and the config a run stores is plain data."""
    bad = tmp_path / "typed.json"
    cases = [
        ({"steps": 100.5}, "field 'steps' must be a whole number, got 100.5"),
        ({"lr": True}, "field 'lr' must be a number, got True"),
        ({"lr": "fast"}, "field 'lr' must be a number, got 'fast'"),
        ({"batch_size": 0}, "field 'batch_size' must be at least 1, got 0"),
        ({"dropout": 1.5}, "field 'dropout' must be at most 1, got 1.5"),
        ({"early_ckpts": [25, "x"]}, "field 'early_ckpts' must be a list of whole numbers, got \\[25, 'x'\\]"),
        ({"note": 3}, "field 'note' must be a string, got 3"),
        ({"lr_min": None, "steps": None}, "field 'steps' must be a whole number, got None"),
        ({"comments": {"lr": 3}}, "field 'comments' must map field names to short strings"),
        ({"comments": {"speed": "fast"}}, "field 'comments' names an unknown field 'speed'"),
        ({"comments": {"lr": "x" * 101}}, "field 'comments': the comment on 'lr' is over 100 characters .*"),
    ]
    for fields, message in cases:
        bad.write_text(json.dumps({"model": "mg", **fields}))
        with pytest.raises(TrainError, match=f"typed.json: {message}$"):
            load_config("mg", str(bad))
    bad.write_text(json.dumps({"model": "fl", "steps": 300.0, "early_ckpts": [5, 10], "lr_min": None}))
    cfg = load_config("fl", str(bad))
    assert cfg.steps == 300 and type(cfg.steps) is int and cfg.early_ckpts == (5, 10) and cfg.lr_min is None
    with pytest.raises(FrozenInstanceError):  # a run cannot change its config under the loop
        cfg.steps = 5
    assert as_dict(cfg)["early_ckpts"] == [5, 10] and as_dict(cfg)["K"] == 32  # FL's paper value, by default


def test_cli_errors_are_one_line(tmp_path, small_dataset, capsys):
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "generation.training.train",
            "--model",
            "mg",
            "--config",
            "tiny",
            "--data",
            str(tmp_path / "missing.npz"),
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert r.stderr.startswith("error: ") and "missing.npz" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert (
        main(["--model", "mg", "--config", "nosuch", "--data", str(small_dataset), "--out", str(tmp_path / "o")]) == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("error: config 'nosuch' not found") and len(err.strip().splitlines()) == 1
    # a take or a table given as the dataset: said as such (numpy's own words are about pickled data)
    take = tmp_path / "take.bvh"
    take.write_text("HIERARCHY\nROOT Hips\n")
    assert main(["--model", "mg", "--config", "tiny", "--data", str(take), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{take}: not an .npz archive, as a prepared dataset is" in err and len(err.strip().splitlines()) == 1


def test_ddp_two_cpu_processes_match_one(small_dataset, tmp_path):
    """torchrun with 2 gloo processes trains the same MG as one process (issue 15, item 8): the batch is split
    over the ranks, its random draws are shared, and ActNorm starts from the whole batch's statistics. The last
    steps add the stance loss on sampled latents, whose draws must be shared too."""
    import os
    import subprocess
    import sys

    import torch

    from generation.training.train import train

    steps = 12
    config = tmp_path / "mg_stance.json"
    config.write_text(
        json.dumps(
            as_dict(replace(load_config("mg", "tiny"), stance_weight=1.0, stance_start=8, stance_temperature=1.0))
        )
    )
    # On the CPU on any machine (gloo), a GPU machine included: two ranks cannot share one GPU under nccl.
    train("mg", str(config), small_dataset, tmp_path / "one", steps=steps, progress=False, threads=1, device="cpu")
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "torch.distributed.run",
            "--standalone",
            "--nproc_per_node",
            "2",
            "-m",
            "generation.training.train",
            "--model",
            "mg",
            "--config",
            str(config),
            "--data",
            str(small_dataset),
            "--out",
            str(tmp_path / "two"),
            "--steps",
            str(steps),
            "--threads",
            "1",
            "--device",
            "cpu",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    name = f"checkpoints/step_{steps:07d}.pt"
    one = torch.load(tmp_path / "one" / name, weights_only=True)["state"]
    two = torch.load(tmp_path / "two" / name, weights_only=True)["state"]
    assert one.keys() == two.keys()
    diff = torch.cat([(one[k].float() - two[k].float()).abs().flatten() for k in one])
    # Float rounding only: Adam turns the rounding of near-zero gradients into steps of up to lr (3e-3), so a
    # few weights differ by ~1e-4, the typical one by ~1e-6. Unsynchronised ActNorm statistics would move
    # whole channels by a large fraction of a std; shards with their own random draws, every weight by ~lr.
    assert diff.median() < 1e-5 and diff.max() < 2e-3, (diff.median(), diff.max())
    assert json.loads((tmp_path / "two" / "config.json").read_text())["ranks"] == 2


def test_core_share_leaves_a_busy_neighbour_its_core(monkeypatch):
    """With another process using one of 2 cores, training drops to one thread, and takes both back when the
    neighbour stops (issue 15, item 6). The machine's busy seconds and the clocks are given here, so the rule is
    tested whatever else the machine is doing."""
    import types

    from generation.training import threads

    clock = {"t": 0.0, "busy": 100.0, "own": 5.0}
    monkeypatch.setattr(threads, "_busy_seconds", lambda: clock["busy"])
    # threads' own name for the time module, not the module itself: the rest of the process keeps its clocks
    fake = types.SimpleNamespace(monotonic=lambda: clock["t"], process_time=lambda: clock["own"])
    monkeypatch.setattr(threads, "time", fake)

    def second(neighbour_cores, own_cores=1.0):
        clock["t"] += 1.0
        clock["own"] += own_cores
        clock["busy"] += own_cores + neighbour_cores

    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        share = threads.CoreShare(interval=0.5, cores=2)
        second(neighbour_cores=1.0)
        assert share.others() == pytest.approx(1.0)
        share.step()
        assert torch.get_num_threads() == 1
        second(neighbour_cores=0.05)  # the neighbour stopped: a little system noise is left
        share.step()
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


def test_core_share_sees_a_spinning_neighbour_in_proc_stat():
    """The real reading: a process spinning beside this one shows as at least most of a core of others' time (more
    where the machine is busier: others' time only adds)."""
    import time

    from generation.training.threads import CoreShare

    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        share = CoreShare(interval=0.5, cores=2)
        time.sleep(1.0)
        assert share.others() > 0.6
    finally:
        busy.kill()
        busy.wait()


def test_torch_threads_are_restored():
    """Library code sets torch's thread count only inside a block that restores it (CoreShare may change it)."""
    from generation.training.threads import torch_threads

    before = torch.get_num_threads()
    with torch_threads(1):
        assert torch.get_num_threads() == 1
        torch.set_num_threads(2)
    assert torch.get_num_threads() == before
    with torch_threads(None):
        assert torch.get_num_threads() == before


def test_init_fine_tunes_from_a_checkpoint_at_its_step(small_dataset, tmp_path):
    """--init: the run starts from the checkpoint's weights and step, Adam afresh, and trains on to the config's
    steps, as one run with a restart at that step would; a checkpoint of another size, of other data or already
    at the last step is refused in one line."""
    first = replace(load_config("mg", "tiny"), steps=6, ckpt_every=6, early_ckpts=())
    a = train("mg", first, small_dataset, tmp_path / "a", seed=1, progress=False)
    ckpt = a / "checkpoints" / "step_0000006.pt"
    fine = replace(
        first,
        steps=9,
        restart_step=6,
        restart_lr=1e-4,
        restart_lr_min=1e-5,
        foot_height_weight=5.0,
        stance_weight=1.0,
        stance_start=6,
        ckpt_every=9,
    )
    b = train("mg", fine, small_dataset, tmp_path / "b", seed=1, progress=False, init=ckpt)
    assert [r["step"] for r in rows(b)] == ["9"] and float(rows(b)[0]["train_stance"]) > 0
    assert torch.load(b / "checkpoints" / "step_0000009.pt", weights_only=True)["step"] == 9
    opt = torch.load(b / "resume.pt", weights_only=True)["opt"]["state"]
    assert {int(v["step"]) for v in opt.values()} == {3}  # three steps of a fresh Adam
    # The same bits as one run of the fine-tune's config from step 0: its first six steps are the first run's and
    # its restart at step 6 clears Adam, so the fine-tune took the checkpoint's weights and step as they were.
    whole = train("mg", fine, small_dataset, tmp_path / "c", seed=1, progress=False)
    assert all(torch.equal(state(b)[k], state(whole)[k]) for k in state(b))
    with pytest.raises(TrainError, match="step_0000006.pt: a mg checkpoint of size .* but the config builds"):
        train("mg", replace(fine, hidden=24), small_dataset, tmp_path / "d", progress=False, init=ckpt)
    with pytest.raises(TrainError, match=r"already at step 6; the config's 'steps' \(6\)"):
        train("mg", first, small_dataset, tmp_path / "e", progress=False, init=ckpt)
    other = torch.load(ckpt, weights_only=True)
    other["stats"]["x_std"] = [v * 2 for v in other["stats"]["x_std"]]
    torch.save(other, tmp_path / "other.pt")
    with pytest.raises(TrainError, match="other.pt: trained on data whose statistics differ .*'x_std'"):
        train("mg", fine, small_dataset, tmp_path / "f", progress=False, init=tmp_path / "other.pt")


def test_posture_by_category_reaches_the_loss(small_dataset, tmp_path):
    """With posture_by_category the posture term is matched within the batch's categories: the same run draws the
    same batches and books a larger stance loss than with the batch's mean alone (the categories' offsets do not
    cancel), and the run's config records it."""
    cfg = replace(
        load_config("fl", "tiny"),
        steps=4,
        valid_every=1,
        stance_weight=1.0,
        stance_start=2,
        stance_temperature=1.0,
        posture_weight=50.0,
        category_balance=0.5,
    )
    plain = train("fl", cfg, small_dataset, tmp_path / "a", seed=1, progress=False)
    by = train("fl", replace(cfg, posture_by_category=True), small_dataset, tmp_path / "b", seed=1, progress=False)
    a, b = ([float(r["train_stance"]) for r in rows(run)] for run in (plain, by))
    assert a[:2] == b[:2] == [0.0, 0.0] and b[2] > a[2] > 0
    assert json.loads((by / "config.json").read_text())["posture_by_category"] is True


def test_a_finished_run_is_reused_without_resuming_it(tiny_runs, tmp_path, monkeypatch):
    """make_stimuli reusing its runs (--quick again, the demo's later runs) takes the checkpoints of a run trained to
    its last step without resuming it: resuming builds the optimiser, whose first use in a process loads torch's
    compiler. A run short of the steps asked, of another model or config, or without its last checkpoint is
    resumed as before."""
    import shutil
    from types import SimpleNamespace

    from generation.stimuli import checkpoints
    from generation.training import train as train_module
    from generation.training.train import finished

    run = tmp_path / "mg_tiny"
    shutil.copytree(tiny_runs["mg"], run)
    assert finished("mg", "tiny", run, steps=150)
    assert not finished("mg", "tiny", run, steps=200)
    assert not finished("fl", "tiny", run, steps=150) and not finished("mg", "cpu", run, steps=150)
    calls = []
    monkeypatch.setattr(train_module, "train", lambda *a, **k: calls.append(a))
    args = SimpleNamespace(
        mg_checkpoint=None, shipped=False, runs=str(tmp_path), config="tiny", train_steps=150, precision=None
    )
    args.__dict__.update(seed=0, progress=False, device=None, threads=1)
    final, first = checkpoints.ensure_model("mg", args, "unused.npz")
    assert calls == [] and final.name == "step_0000150.pt" and first == checkpoints.checkpoints_in(run)[0]
    (run / "checkpoints" / "step_0000150.pt").unlink()
    checkpoints.ensure_model("mg", args, "unused.npz")
    assert len(calls) == 1  # resumed, as before
