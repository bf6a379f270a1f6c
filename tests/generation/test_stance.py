"""The stance-foot loss (training/stance.py): its geometry, its contacts, the mode it reads, and its gradient."""

import numpy as np
import pytest
import torch
from helpers.paths import takes

from generation.data.dataset import load_dataset
from generation.metrics.objective import foot_skating
from generation.motion import skeleton
from generation.motion.features import load_take, rotate_y, to_features, to_world
from generation.sampling.sample import load_model
from generation.training.stance import (
    contacts,
    foot_world_steps,
    posture_offset,
    posture_spread,
    stance_height,
    stance_loss,
    stance_speed,
)

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_foot_steps_are_world_steps_seen_from_the_previous_root():
    """Random poses under a control that turns hard: the same displacement as features.to_world gives."""
    g = np.random.default_rng(0)
    x = g.normal(0, 0.3, (12, 63))
    c = np.stack([g.normal(0.05, 0.02, 12), g.normal(0, 0.02, 12), g.normal(0, 0.3, 12)], axis=1)
    world = to_world(x, c).astype(np.float64)[..., [0, 2]]  # [T, 21, 2] (x, z)
    yaw = np.concatenate([[0.0], np.cumsum(c[1:, 2])])
    expected = rotate_y(world[1:] - world[:-1], -yaw[:-1, None])  # in frame t-1's root
    got = foot_world_steps(*(torch.from_numpy(a[None]) for a in (x[:-1], x[1:], c[1:])))[0]
    feet = np.reshape(skeleton.FEET, (-1, 2))
    np.testing.assert_allclose(got.numpy(), expected[:, feet], atol=1e-5)


@pytest.mark.full  # real walks from ../shared
@pytest.mark.parametrize("category", ["walk", "walk-turn-left"])
def test_stance_speed_of_real_motion_is_the_foot_skating_metric(category):
    for path in takes(category, 3):
        joints = load_take(path, 20.0)[:80]
        x, c = (torch.from_numpy(a)[None].double() for a in to_features(joints))
        speed = stance_speed(x[:, :-1], x[:, 1:], c[:, 1:], contacts(x, 1), 20.0)
        assert float(speed) == pytest.approx(foot_skating(joints, 20.0), rel=1e-4)


def test_contacts_need_both_frames_down():
    x = torch.zeros(1, 4, 63)
    x[0, 2, 3 * skeleton.INDEX["Toes_L"] + 1] = 0.05  # left toe lifted in frame 2 only
    contact = contacts(x, 1)[0]  # pairs (0,1), (1,2), (2,3)
    assert contact[:, 0].tolist() == [True, False, False] and contact[:, 1].all()


@pytest.mark.parametrize("temperature", [0.0, 1.0])
def test_mg_predicted_frames_are_its_stream(tiny_runs, small_dataset, temperature):
    """Fed the frames its own stream made from latents z as history, MG predicts those frames from the same z."""
    model = load_model(sorted((tiny_runs["mg"] / "checkpoints").glob("step_*.pt"))[-1])
    dev = model.x_mean.device  # load_model puts it on CUDA where there is one
    valid = load_dataset(small_dataset).splits["valid"]
    x, c = valid.x[:3, :30].to(dev), valid.c[:3, :30].to(dev)
    z = temperature * torch.randn(3, 30 - model.tau, 63, generator=torch.Generator().manual_seed(0)).to(dev)
    with torch.no_grad():
        made = model.inverse(z, x[:, : model.tau], c)
        again = model.predict_frames(torch.cat([x[:, : model.tau], made], dim=1), c, None if temperature == 0 else z)
        other = model.predict_frames(x, c, z)
    assert torch.allclose(again, made, atol=1e-4), (again - made).abs().max()
    assert not torch.allclose(other, made, atol=1e-2)  # a different history predicts differently


def descend(model, loss, steps=15):
    """(loss before, loss after) `steps` Adam steps on `loss()` over the model's parameters."""
    before = float(loss().detach())
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    for _ in range(steps):
        opt.zero_grad()
        loss().backward()
        opt.step()
    return before, float(loss().detach())


@pytest.mark.parametrize("kind", ["mg", "fl"])
def test_stance_loss_trains_the_stance_feet_still(tiny_runs, small_dataset, kind):
    model = load_model(sorted((tiny_runs[kind] / "checkpoints").glob("step_*.pt"))[-1]).train()
    if kind == "mg":
        model.config["dropout"] = 0.0
    split = load_dataset(small_dataset).splits["train"]
    x, c = split.x[:8, :32].to(model.x_mean.device), split.c[:8, :32].to(model.x_mean.device)

    before, after = descend(model, lambda: stance_loss(model, x, c, 20.0).mean())
    assert after < 0.7 * before, (before, after)


def test_posture_offset_is_the_mean_pose_shift_and_ignores_per_window_differences():
    """0 for the real windows themselves and for windows that only trade postures among themselves; a whole-batch
    shift of one joint by d metres gives d^2 / 21."""
    g = torch.Generator().manual_seed(0)
    real = torch.randn(6, 10, 63, generator=g, dtype=torch.float64)
    assert float(posture_offset(real, real)) == 0.0
    assert float(posture_offset(real.flip(0), real)) == pytest.approx(0.0, abs=1e-12)  # the same set, reordered
    shifted = real.clone()
    shifted[..., 3 * skeleton.INDEX["Hand_L"] + 1] -= 0.09  # FL's hands once hung 9 cm low
    assert float(posture_offset(shifted, real)) == pytest.approx(0.09**2 / skeleton.N_JOINTS)


def test_posture_offset_by_category_sees_offsets_that_cancel_in_the_batch():
    """Two categories leaning opposite ways by d: the batch's mean pose is right (0), the categories' are not (d^2
    per shifted joint over 21); with one category it is the plain batch-mean offset."""
    g = torch.Generator().manual_seed(0)
    real = torch.randn(6, 10, 63, generator=g, dtype=torch.float64)
    cats = torch.tensor([0, 0, 0, 1, 1, 1])
    lean = real.clone()
    head_z = 3 * skeleton.INDEX["Head"] + 2
    lean[:3, :, head_z] += 0.06
    lean[3:, :, head_z] -= 0.06
    assert float(posture_offset(lean, real)) == pytest.approx(0.0, abs=1e-12)
    assert float(posture_offset(lean, real, cats)) == pytest.approx(0.06**2 / skeleton.N_JOINTS)
    shifted = real + 0.01
    one = torch.zeros(6, dtype=torch.long)
    assert float(posture_offset(shifted, real, one)) == pytest.approx(float(posture_offset(shifted, real)))
    assert float(posture_offset(real.flip(0), real, torch.tensor([1, 1, 1, 0, 0, 0]).flip(0))) != 0.0  # paired
    assert float(posture_offset(real[[1, 0, 2, 4, 3, 5]], real, cats)) == pytest.approx(0.0, abs=1e-12)


def test_posture_term_pulls_a_shifted_fl_back(tiny_runs, small_dataset):
    """Trained on the posture term alone against windows whose left hand is raised by 9 cm, a tiny FL's samples
    move their mean pose towards them."""
    model = load_model(sorted((tiny_runs["fl"] / "checkpoints").glob("step_*.pt"))[-1]).train()
    split = load_dataset(small_dataset).splits["train"]
    x, c = split.x[:8, :32].to(model.x_mean.device).clone(), split.c[:8, :32].to(model.x_mean.device)
    hand_y = 3 * skeleton.INDEX["Hand_L"] + 1
    x[..., hand_y] += 0.09 / model.x_std[hand_y]  # standardised units
    z = torch.randn(8, 32, 63, generator=torch.Generator().manual_seed(1)).to(x.device)

    def term():
        return stance_loss(model, x, c, 20.0, z=z, posture=1.0).mean() - stance_loss(model, x, c, 20.0, z=z).mean()

    before, after = descend(model, term)
    assert before > 0.09**2 / skeleton.N_JOINTS / 2 and after < before / 2, (before, after)


def test_posture_spread_is_the_gap_in_how_far_postures_spread_over_windows():
    """0 for the real windows, reordered or shifted as a whole (the mean is posture_offset's); windows that all
    share one posture, as FL's did, pay for the real windows' spread; a joint whose windows spread wider
    gives that gap squared over 21."""
    g = torch.Generator().manual_seed(0)
    real = torch.randn(8, 10, 63, generator=g, dtype=torch.float64) * 0.05
    assert float(posture_spread(real, real)) == 0.0
    assert float(posture_spread(real.flip(0) + 0.2, real)) == pytest.approx(0.0, abs=1e-12)
    same = real - real.mean(dim=1, keepdim=True) + real.mean(dim=(0, 1))  # one posture, the same motion
    spread = real.mean(dim=1).std(dim=0).reshape(skeleton.N_JOINTS, 3).pow(2).sum(-1).mean()
    assert float(posture_spread(same, real)) == pytest.approx(float(spread))
    wider = real.clone()
    k = 3 * skeleton.INDEX["Head"]
    wider[..., k] += torch.linspace(-0.05, 0.05, 8, dtype=torch.float64)[:, None]  # one joint, a per-window offset
    gap = wider[..., k].mean(1).std() - real[..., k].mean(1).std()
    assert float(gap) > 0.01
    assert float(posture_spread(wider, real)) == pytest.approx(float(gap) ** 2 / skeleton.N_JOINTS)
    assert float(posture_spread(real[:1], real[:1])) == 0.0  # one window has no spread to match


def test_spread_term_spreads_a_collapsed_fl(tiny_runs, small_dataset):
    """Trained on the spread term alone, a tiny FL whose samples' postures spread less over windows than the real
    windows' moves towards their spread."""
    model = load_model(sorted((tiny_runs["fl"] / "checkpoints").glob("step_*.pt"))[-1]).train()
    split = load_dataset(small_dataset).splits["train"]
    x, c = split.x[:8, :32].to(model.x_mean.device).clone(), split.c[:8, :32].to(model.x_mean.device)
    x = x + (torch.arange(8, dtype=x.dtype, device=x.device) - 3.5)[:, None, None] * 0.5  # postures spread wide
    z = torch.randn(8, 32, 63, generator=torch.Generator().manual_seed(1)).to(x.device)

    def term():
        return stance_loss(model, x, c, 20.0, z=z, spread=1.0).mean() - stance_loss(model, x, c, 20.0, z=z).mean()

    before, after = descend(model, term)
    assert before > 0 and after < before / 2, (before, after)


def test_stance_height_counts_the_planted_feet_only():
    """0 for the real frames themselves; a planted foot raised by h metres gives h, a swinging foot raised gives 0,
    and a foot that bobs by +-h around the real one gives h (the gap is absolute: bobbing is not cancelled)."""
    g = torch.Generator().manual_seed(0)
    real = torch.randn(2, 6, 63, generator=g, dtype=torch.float64) * 0.05
    down = torch.zeros(2, 6, 2, dtype=torch.bool)
    down[:, :, 0] = True  # the left foot down in every frame, the right one never
    assert float(stance_height(real, real, down).abs().max()) == 0.0
    left = [3 * skeleton.INDEX[j] + 1 for j in ("Foot_L", "Toes_L")]
    right = [3 * skeleton.INDEX[j] + 1 for j in ("Foot_R", "Toes_R")]
    raised = real.clone()
    raised[..., left] += 0.02
    assert stance_height(raised, real, down).tolist() == pytest.approx([0.02, 0.02])
    swing = real.clone()
    swing[..., right] += 0.05
    assert float(stance_height(swing, real, down).abs().max()) == pytest.approx(0.0, abs=1e-12)
    bob = real.clone()
    bob[:, 0::2, left[0]] += 0.01
    bob[:, 1::2, left[0]] -= 0.01
    assert stance_height(bob, real, down).tolist() == pytest.approx([0.005, 0.005])  # the ankle of (ankle, toe)
    assert float(stance_height(raised, real, torch.zeros_like(down)).abs().max()) == 0.0  # no contact, no term


def test_height_term_pulls_a_floating_mg_foot_down(tiny_runs, small_dataset):
    """Trained on the height term alone against windows whose feet are 3 cm lower than the model predicts them,
    a tiny MG's predicted stance feet move towards the real height."""
    model = load_model(sorted((tiny_runs["mg"] / "checkpoints").glob("step_*.pt"))[-1]).train()
    model.config["dropout"] = 0.0
    split = load_dataset(small_dataset).splits["train"]
    x, c = split.x[:8, :32].to(model.x_mean.device).clone(), split.c[:8, :32].to(model.x_mean.device)
    for j in ("Foot_L", "Toes_L", "Foot_R", "Toes_R"):
        k = 3 * skeleton.INDEX[j] + 1
        x[..., k] -= 0.03 / model.x_std[k]  # standardised units: every foot 3 cm lower than the model learnt

    def term():
        return stance_loss(model, x, c, 20.0, height=1.0).mean() - stance_loss(model, x, c, 20.0).mean()

    before, after = descend(model, term)
    assert before > 0.02 and after < before / 2, (before, after)
