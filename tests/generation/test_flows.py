"""Flow layers and both models: invertibility and log-determinants (one generic test), ActNorm init,
MG causality. All at small sizes."""

import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from helpers.paths import BANDAI
from reference.moglow_naive import inverse_naive

from generation.models.fl import FL
from generation.models.flows import (
    ActNorm,
    AffineCoupling,
    Chain,
    ConvNet,
    FlowStep,
    InvertibleLinearLU,
    Split,
    SqueezeTime,
    set_net_precision,
)
from generation.models.mg_stream import MGStream
from generation.models.moglow import LSTMNet, MoGlow
from generation.motion.features import load_take, root_trajectory, rotate_y, to_features
from generation.motion.skeleton import FEET

C, CC, T, TAU = 6, 2, 4, 3

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def perturb(module, scale=0.1):
    """Move every parameter off its initial value (zero-initialised layers would make couplings trivial)."""
    with torch.no_grad():
        for p in module.parameters():
            p.add_(scale * torch.randn_like(p))
    return module


def layer_case(make):
    """Case for a layer acting on x [B, C, T] with cond [B, CC, T]."""

    def build(dtype):
        layer = make().to(dtype)
        cond = torch.randn(3, CC, T, dtype=dtype)
        layer(torch.randn(3, C, T, dtype=dtype) * 2 + 1, cond)  # data-dependent init where there is one
        perturb(layer)
        layer.eval()

        def fwd(x):
            return layer(x.reshape(-1, C, T), cond[: x.reshape(-1, C, T).shape[0]])

        def inv(y):
            return layer.inverse(y, cond[: y.shape[0]])[0]

        return fwd, inv, torch.randn(3, C, T, dtype=dtype)

    return build


def fl_case(dtype):
    model = FL(dict(L=2, K=2, hidden=8)).to(dtype)
    c = torch.randn(3, T, 3, dtype=dtype)
    model(torch.randn(3, T, 63, dtype=dtype), c)
    perturb(model, 0.05).eval()

    def fwd(x):
        return model(x.reshape(-1, T, 63), c[: x.reshape(-1, T, 63).shape[0]])

    def inv(z):
        return model.inverse(z, c[: z.shape[0]])[0]

    return fwd, inv, torch.randn(3, T, 63, dtype=dtype)


def mg_case(dtype, residual=False, carry_feet=False, history_style=False):
    """MG as a map from the frames after the history to their latents; its inverse is the streaming sampler."""
    config = dict(K=2, hidden=8, tau=TAU, residual=residual, carry_feet=carry_feet, history_style=history_style)
    model = MoGlow(config).to(dtype)
    if carry_feet:  # data statistics away from 0 and 1, so that the feet's carry goes through them
        g = torch.Generator().manual_seed(1)
        model.set_stats(
            torch.randn(63, generator=g),
            0.5 + torch.rand(63, generator=g),
            torch.randn(3, generator=g),
            0.5 + torch.rand(3, generator=g),
        )
    n = 3
    hist = torch.randn(3, TAU, 63, dtype=dtype)
    c = torch.randn(3, TAU + n, 3, dtype=dtype)
    model(torch.randn(3, TAU + n, 63, dtype=dtype), c)
    perturb(model, 0.05).eval()

    def fwd(x):
        x = x.reshape(-1, n, 63)
        return model(torch.cat([hist[: len(x)], x], dim=1), c[: len(x)])

    def inv(z):
        return model.inverse(z, hist[: len(z)], c[: len(z)])

    return fwd, inv, torch.randn(3, n, 63, dtype=dtype)


CASES = {
    "actnorm": layer_case(lambda: ActNorm(C)),
    "lu_linear": layer_case(lambda: InvertibleLinearLU(C)),
    "coupling_conv": layer_case(lambda: AffineCoupling(C, ConvNet(C // 2, CC, 2 * (C - C // 2), 8))),
    "coupling_lstm": layer_case(lambda: AffineCoupling(C, LSTMNet(C // 2, CC, 2 * (C - C // 2), 8, 2))),
    "squeeze_time": layer_case(SqueezeTime),
    "split": layer_case(lambda: Split(C, ConvNet(C // 2, CC, 2 * (C - C // 2), 8))),
    "flow_step": layer_case(lambda: FlowStep(C, ConvNet(C // 2, CC, 2 * (C - C // 2), 8))),
    "chain": layer_case(lambda: Chain(*[FlowStep(C, ConvNet(C // 2, CC, 2 * (C - C // 2), 8)) for _ in range(3)])),
    "fl_model": fl_case,
    "mg_model": mg_case,
    "mg_model_residual": lambda dtype: mg_case(dtype, residual=True),
    "mg_model_carry_feet": lambda dtype: mg_case(dtype, residual=True, carry_feet=True),
    "mg_model_history_style": lambda dtype: mg_case(dtype, residual=True, carry_feet=True, history_style=True),
}


@pytest.mark.parametrize("name", list(CASES))
def test_invertible_and_logdet_matches_jacobian(name):
    torch.manual_seed(0)
    # float32: inverse(forward(x)) == x
    fwd, inv, x = CASES[name](torch.float32)
    with torch.no_grad():
        y, logdet = fwd(x)
        assert logdet.shape == (x.shape[0],)
        err = (inv(y) - x).abs().max().item()
        assert err < 1e-4, err
    # float64: logdet == log|det J| from autograd, per batch element
    torch.manual_seed(0)
    fwd, inv, x = CASES[name](torch.float64)
    x1 = x[:1]
    _, logdet = fwd(x1)
    jac = torch.autograd.functional.jacobian(lambda v: fwd(v)[0].reshape(-1), x1)
    sign, logabsdet = torch.linalg.slogdet(jac.reshape(jac.shape[0], -1))
    assert sign != 0
    assert abs(logabsdet.item() - logdet[0].item()) < 1e-3, (name, logabsdet.item(), logdet[0].item())
    # the layer is not the identity (the test would pass trivially otherwise)
    if name != "squeeze_time":
        assert not torch.allclose(fwd(x)[0].reshape(x.shape), x, atol=1e-3)


@pytest.mark.parametrize("name", ["coupling_conv", "coupling_lstm", "split", "chain", "fl_model"])
def test_bfloat16_networks_leave_the_flow_float32_and_invertible(name):
    """Mixed precision (train.py's 'precision'): the networks run in bfloat16, while the outputs, the
    log-determinants and the inverse stay float32 and exact, since a coupling's inverse sees the same network
    output as its forward."""
    torch.manual_seed(0)
    fwd, inv, x = CASES[name](torch.float32)
    with torch.no_grad():
        y32, logdet32 = fwd(x)
        model = next(c.cell_contents for c in fwd.__closure__ if isinstance(c.cell_contents, torch.nn.Module))
        seen = []
        for net in (m.net for m in model.modules() if isinstance(m, (AffineCoupling, Split))):
            net.register_forward_hook(lambda mod, args, out: seen.append(out.dtype))
        set_net_precision(model, torch.bfloat16)
        y, logdet = fwd(x)
        assert seen and set(seen) == {torch.bfloat16}
        assert y.dtype == logdet.dtype == torch.float32
        assert (inv(y) - x).abs().max().item() < 1e-4
        assert 0 < (y - y32).abs().max().item() < 0.1  # the networks' rounding shows, and stays small
        set_net_precision(model, None)
        assert torch.equal(fwd(x)[0], y32)


LSTM_WITHOUT_AVX512 = """
import torch
from generation.models.moglow import LSTMNet, lstm_runs_in
torch.manual_seed(0)
net = LSTMNet(4, 3, 6, 16, 2)
torch.nn.init.normal_(net.out.weight, 0, 0.1)
x, c = torch.randn(2, 4, 9), torch.randn(2, 3, 9)
y32 = net(x, c)
with torch.autocast("cpu", dtype=torch.bfloat16):
    y = net(x, c)
y.float().sum().backward()
print(lstm_runs_in("cpu", torch.bfloat16), y.dtype, (y.float() - y32).abs().max().item())
"""


def test_bfloat16_lstm_falls_back_to_float32_where_onednn_has_none():
    """oneDNN builds no bfloat16 LSTM on a CPU without AVX-512 (CI's AMD host): there LSTMNet runs its LSTM in
    float32 and its output layer in bfloat16, instead of failing. ONEDNN_MAX_CPU_ISA makes this CPU such a one."""
    env = {**os.environ, "ONEDNN_MAX_CPU_ISA": "AVX2", "OMP_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", LSTM_WITHOUT_AVX512], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    probe, dtype, diff = out.stdout.split()
    assert (probe, dtype) == ("False", "torch.bfloat16")
    assert 0 < float(diff) < 0.05  # the output layer's rounding, nothing more


def test_actnorm_initialises_to_zero_mean_unit_variance():
    torch.manual_seed(1)
    x = torch.randn(16, 5, 30) * torch.tensor([0.1, 1, 3, 10, 0.5])[None, :, None] + torch.arange(5.0)[None, :, None]
    layer = ActNorm(5)
    y, _ = layer(x)
    assert torch.allclose(y.mean(dim=(0, 2)), torch.zeros(5), atol=1e-5)
    assert torch.allclose(y.std(dim=(0, 2), unbiased=False), torch.ones(5), atol=1e-4)
    y2, _ = layer(x * 2)  # initialised once only
    assert not torch.allclose(y2.std(dim=(0, 2), unbiased=False), torch.ones(5), atol=0.1)


def test_lu_linear_starts_orthogonal_with_unit_lower():
    torch.manual_seed(2)
    layer = InvertibleLinearLU(7)
    w = layer.weight()
    assert torch.allclose(w @ w.T, torch.eye(7), atol=1e-5)
    lower = layer.lower * layer.l_mask + torch.eye(7)
    assert torch.equal(torch.diagonal(lower), torch.ones(7))
    assert torch.allclose(layer(torch.randn(2, 7, 3))[1], torch.zeros(2), atol=1e-5)  # |det| = 1


def test_coupling_starts_near_identity():
    layer = AffineCoupling(C, ConvNet(C // 2, CC, 2 * (C - C // 2), 8))
    x = torch.randn(2, C, T)
    y, _ = layer(x, torch.randn(2, CC, T))
    assert torch.equal(y[:, : C // 2], x[:, : C // 2])
    assert torch.allclose(y[:, C // 2 :], x[:, C // 2 :] * torch.sigmoid(torch.tensor(2.0)))


def test_mg_is_causal():
    """Changing the pose or control of frame t+1 leaves everything up to frame t exactly unchanged,
    in the likelihood pass (latents) and in sampling (generated poses)."""
    torch.manual_seed(3)
    model = perturb(MoGlow(dict(K=2, hidden=8, tau=TAU)), 0.05).eval()
    x, c = torch.randn(2, TAU + 6, 63), torch.randn(2, TAU + 6, 3)
    with torch.no_grad():
        z, _ = model(x, c)
        t = TAU + 2
        x2, c2 = x.clone(), c.clone()
        x2[:, t + 1] += 1.0
        c2[:, t + 1] += 1.0
        z2, _ = model(x2, c2)
        assert torch.equal(z2[:, : t + 1 - TAU], z[:, : t + 1 - TAU])
        assert not torch.equal(z2[:, t + 1 - TAU], z[:, t + 1 - TAU])
        # sampling: the same latents, the control changed from frame 3 of the generated part on
        zs = torch.randn(2, 6, 63)
        a = model.inverse(zs, x[:, :TAU], c)
        c3 = c.clone()
        c3[:, TAU + 3 :] += 1.0
        b = model.inverse(zs, x[:, :TAU], c3)
        assert torch.equal(a[:, :3], b[:, :3])
        assert not torch.equal(a[:, 3], b[:, 3])


@pytest.mark.parametrize("layout", ["row", "col"])
def test_mg_residual_samples_steps_from_the_previous_pose(layout):
    """With `residual` the flow's output is the step from the previous pose: the streaming sampler (either layout)
    equals the plain per-frame inverse, and the same weights without `residual` give the same steps, not poses."""
    torch.manual_seed(5)
    model = MoGlow(dict(K=2, hidden=8, tau=TAU, residual=True))
    hist, c = torch.randn(2, TAU, 63), torch.randn(2, TAU + 4, 3)
    model(torch.randn(2, TAU + 4, 63), c)
    perturb(model, 0.05).eval()
    z = torch.randn(2, 4, 63)
    fast = model.inverse(z, hist, c, layout=layout)
    assert torch.allclose(fast, inverse_naive(model, z, hist, c), atol=1e-5)
    with torch.no_grad():
        pred = model.predict_frames(torch.cat([hist, fast], dim=1), c, z)
    assert torch.allclose(pred, fast, atol=1e-4)
    plain = MoGlow(dict(K=2, hidden=8, tau=TAU))
    plain.load_state_dict(model.state_dict())
    first = plain.eval().inverse(z[:, :1], hist, c[:, : TAU + 1], layout=layout)
    assert torch.allclose(fast[:, 0] - hist[:, -1], first[:, 0], atol=1e-5)
    assert not torch.allclose(fast[:, 0], first[:, 0], atol=1e-2)


@pytest.mark.full  # a real turning walk from ../shared
def test_mg_carry_feet_sees_the_previous_feet_from_the_new_root():
    """With `carry_feet` the feet's base is where the previous frame's feet are, seen from frame t's root (real
    mocap, through features.to_features): a foot planted on the floor has a step of 0. The rest of the body's
    base is the previous pose."""
    joints = load_take(next(BANDAI.glob("dataset-2/data/*walk-turn-left*.bvh.gz")))[:40]
    x, c = (torch.from_numpy(a) for a in to_features(joints))
    root, yaw = root_trajectory(joints)
    seen = np.array(joints[:-1], dtype=np.float64)  # frame t-1's joints in frame t's root frame
    seen[..., 0] -= root[1:, None, 0]
    seen[..., 2] -= root[1:, None, 1]
    seen = rotate_y(seen, -yaw[1:, None])
    model = MoGlow(dict(K=1, hidden=8, tau=TAU, residual=True, carry_feet=True))
    g = torch.Generator().manual_seed(2)
    model.set_stats(x.mean(0), x.std(0).clamp_min(0.01), c.mean(0) + 0.1 * torch.randn(3, generator=g), c.std(0))
    base = model.unstandardize_x(model.step_base(model.standardize_x(x[:-1]), model.standardize_c(c[1:])))
    base = base.unflatten(-1, (21, 3)).double().numpy()
    np.testing.assert_allclose(base[:, FEET], seen[:, FEET], atol=2e-5)
    others = [j for j in range(21) if j not in FEET]
    np.testing.assert_allclose(base[:, others], x[:-1].unflatten(-1, (21, 3))[:, others].double(), atol=2e-5)
    assert np.abs(base[:, FEET] - x[:-1].unflatten(-1, (21, 3))[:, FEET].double().numpy()).max() > 0.02  # it moved


@pytest.mark.parametrize("layout", ["row", "col"])
def test_mg_history_style_reads_the_seed_history_for_every_frame(layout):
    """With `history_style` every frame's couplings read the mean of the window's first tau poses: the streaming
    sampler (either layout) equals the plain inverse and predict_frames, and the output follows the style input
    after the history has slid out of the tau-frame window (here frame TAU + 1 on), where nothing else of it is
    left."""
    torch.manual_seed(6)
    model = MoGlow(dict(K=2, hidden=8, tau=TAU, residual=True, history_style=True))
    assert model.cond_dim == TAU * 63 + (TAU + 1) * 3 + 63
    n = TAU + 3
    hist, c = torch.randn(2, TAU, 63), torch.randn(2, TAU + n, 3)
    model(torch.randn(2, TAU + n, 63), c)
    perturb(model, 0.05).eval()
    z = torch.randn(2, n, 63)
    fast = model.inverse(z, hist, c, layout=layout)
    assert torch.allclose(fast, inverse_naive(model, z, hist, c), atol=1e-5)
    with torch.no_grad():
        pred = model.predict_frames(torch.cat([hist, fast], dim=1), c, z)
        assert torch.allclose(pred, fast, atol=1e-4)
        cond = model.make_cond(torch.cat([hist, fast], dim=1), c)
    assert torch.equal(cond[:, :, -63:], hist.mean(dim=1, keepdim=True).expand(-1, n, -1))
    # The same last tau frames before frame TAU + 1, another seed history's mean before them: another frame.
    other = hist + torch.randn(2, 1, 63)
    other[:, 1:] = hist[:, 1:]
    a = model.inverse(z, hist, c, layout=layout)
    b = model.inverse(z, other, c, layout=layout)
    assert not torch.allclose(a[:, -1], b[:, -1], atol=1e-4)

    # The sampler's `style` replaces the seed history's mean: given that mean it changes nothing; given another
    # mean, the frames change.
    def last(style):
        stream = MGStream(model, hist, c[:, :TAU], layout=layout, style=style)
        with torch.no_grad():
            return [stream.step(c[:, TAU + t], z=z[:, t]) for t in range(n)][-1]

    assert torch.allclose(last(hist.mean(dim=1)), a[:, -1], atol=1e-6)
    assert not torch.allclose(last(other.mean(dim=1)), a[:, -1], atol=1e-4)


def test_mg_style_span_averages_more_real_frames_only_in_training():
    """With `style_span` N, a training batch's style input is the mean of the window's first k frames, k drawn
    from tau..N per batch (over many batches every k turns up, and no other); in eval mode (validation, sampling,
    the likelihood reported) it is the history's mean, as without the field."""
    torch.manual_seed(7)
    model = MoGlow(dict(K=1, hidden=8, tau=TAU, dropout=0.0, history_style=True, style_span=TAU + 4))
    x, c = torch.randn(3, TAU + 6, 63), torch.randn(3, TAU + 6, 3)
    means = [x[:, :k].mean(dim=1) for k in range(TAU + 7)]

    def frames_used():
        style = model.make_cond(x, c)[:, 0, -63:]
        return [k for k in range(TAU + 7) if torch.allclose(style, means[k], atol=1e-6)]

    model.eval()
    assert frames_used() == [TAU]
    model.train()
    seen = {k for _ in range(60) for k in frames_used()}
    assert seen == set(range(TAU, TAU + 5))
    short = MoGlow(dict(K=1, hidden=8, tau=TAU, dropout=0.0, history_style=True, style_span=TAU + 40)).train()
    assert max(short.style_frames(TAU + 6) for _ in range(60)) == TAU + 6  # never past the window's end


def test_mg_history_dropout_only_in_training():
    torch.manual_seed(4)
    model = MoGlow(dict(K=1, hidden=8, tau=TAU, dropout=0.95))
    x, c = torch.randn(64, TAU + 2, 63), torch.randn(64, TAU + 2, 3)
    hist = model.make_cond(x, c)[..., : TAU * 63].reshape(64, 2, TAU, 63)
    dropped = (hist == 0).all(dim=-1).float().mean().item()
    assert 0.9 < dropped < 0.99
    model.eval()
    assert (model.make_cond(x, c)[..., : TAU * 63] != 0).all()


def test_actnorm_follows_a_loaded_init_flag():
    """Loading an uninitialised state into a used ActNorm makes it initialise again on the next batch."""
    norm = ActNorm(3)
    norm(torch.randn(8, 3, 5) * 5 + 2)
    norm.load_state_dict(ActNorm(3).state_dict())
    y, _ = norm(torch.randn(16, 3, 7) * 3 + 1)
    assert bool(norm.initialized)
    assert torch.allclose(y.mean(dim=(0, 2)), torch.zeros(3), atol=1e-5)
    assert torch.allclose(y.std(dim=(0, 2), unbiased=False), torch.ones(3), atol=1e-4)
