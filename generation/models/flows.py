"""Normalising-flow layers shared by FL and MoGlow (Glow, Kingma & Dhariwal 2018; MoGlow §3).

Every layer maps a sequence x [B, C, T] (channels = pose features, T = frames) to y of the same size
(SqueezeTime changes the shape) and returns the log|det dy/dx| per batch element:

    y, logdet = layer(x, cond)        # logdet: [B]
    x, logdet_inv = layer.inverse(y, cond)   # logdet_inv == -logdet

`cond` is the conditioning sequence [B, Cc, T] (control, and for MoGlow the pose history); layers
that do not need it ignore it.
"""

import contextlib
import math

import numpy as np
import scipy.linalg
import torch
from torch import nn

# The arithmetic of the networks inside a flow (training's coupling networks, MGStream's big products): the name of
# a config field or option -> the lower dtype, None for plain float32.
PRECISIONS = {"float32": None, "bfloat16": torch.bfloat16}


def _sum_over_ranks(total, count):
    """total / count, both added over the ranks of torch.distributed when it is running."""
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        both = torch.cat([total.flatten(), total.new_tensor([count])])
        torch.distributed.all_reduce(both)
        return (both[:-1] / both[-1]).view_as(total)
    return total / count


def run_net(layer, x_a, cond):
    """`layer.net(x_a, cond)` as float32 (x_a's dtype). With `layer.net_dtype` set (set_net_precision), the network
    runs under autocast to that dtype: only the coupling and prior networks, never the invertible maps or the
    log-determinants, so the flow stays exactly invertible and its likelihood is still computed in float32."""
    dtype = getattr(layer, "net_dtype", None)
    ctx = torch.autocast(x_a.device.type, dtype=dtype) if dtype is not None else contextlib.nullcontext()
    with ctx:
        h = layer.net(x_a, cond)
    return h.to(x_a.dtype)


def set_net_precision(flow, dtype):
    """Run every coupling and prior network of `flow` in `dtype` (None: the weights' own dtype). Mixed-precision
    training (train.py's 'precision' field): the weights and Adam stay float32."""
    for module in flow.modules():
        if isinstance(module, (AffineCoupling, Split)):
            module.net_dtype = dtype


class ActNorm(nn.Module):
    """Per-channel affine map y = (x + bias) * exp(logs); initialised on the first batch it sees so
    that y has zero mean and unit variance per channel (data-dependent initialisation).

    The initial scale is capped at 1/min_std: a channel that is (nearly) constant on the first batch, like
    the root's own x/z in root-frame poses, would otherwise get a huge scale that turns every later
    optimiser update of its bias into a jump of the same size."""

    def __init__(self, channels, min_std=0.05):
        super().__init__()
        self.bias = nn.Parameter(torch.zeros(1, channels, 1))
        self.logs = nn.Parameter(torch.zeros(1, channels, 1))
        self.register_buffer("initialized", torch.tensor(False))
        self.min_std = min_std
        # Python mirror of `initialized`: reading the buffer on every call would make a GPU wait each time.
        self._ready = False

    def _load_from_state_dict(self, *args, **kwargs):
        super()._load_from_state_dict(*args, **kwargs)
        self._ready = False  # read the loaded flag again on the next call

    @torch.no_grad()
    def initialize(self, x):
        """Per-channel mean and std of the first batch. Under torch.distributed every rank sees only its shard,
        so the sums are added over ranks: every rank gets the statistics of the whole batch, the same as one
        process would (unsynchronised ranks would start from different flows, as reported of StyleGestures' code)."""
        count = x.shape[0] * x.shape[2]
        mean = _sum_over_ranks(x.sum(dim=(0, 2), keepdim=True), count)
        std = _sum_over_ranks((x - mean).pow(2).sum(dim=(0, 2), keepdim=True), count).sqrt()  # two passes: exact
        self.bias.copy_(-mean)
        self.logs.copy_(-torch.log(std.clamp_min(self.min_std)))
        self.initialized.fill_(True)

    def forward(self, x, cond=None):
        if not self._ready:
            if not self.initialized:
                self.initialize(x)
            self._ready = True
        y = (x + self.bias) * torch.exp(self.logs)
        return y, self.logs.sum().expand(x.shape[0]) * x.shape[2]

    def inverse(self, y, cond=None):
        x = y * torch.exp(-self.logs) - self.bias
        return x, -self.logs.sum().expand(y.shape[0]) * y.shape[2]


class InvertibleLinearLU(nn.Module):
    """Invertible 1x1 linear map over channels, W = P L (U + diag(sign_s * exp(log_s))), with L unit lower
    triangular, U strictly upper triangular and P a fixed permutation (Glow §3.2, LU form).
    log|det W| = sum(log_s) per frame. Initialised to a random orthogonal matrix."""

    def __init__(self, channels):
        super().__init__()
        # Random orthogonal start from torch's RNG, so torch.manual_seed makes models reproducible.
        w, _ = torch.linalg.qr(torch.randn(channels, channels, dtype=torch.float64))
        p, lower, upper = scipy.linalg.lu(w.numpy())
        s = np.diag(upper)
        self.register_buffer("P", torch.tensor(p, dtype=torch.float32))
        self.register_buffer("sign_s", torch.tensor(np.sign(s), dtype=torch.float32))
        self.register_buffer("l_mask", torch.tril(torch.ones(channels, channels), -1))
        self.lower = nn.Parameter(torch.tensor(lower, dtype=torch.float32))
        self.upper = nn.Parameter(torch.tensor(np.triu(upper, 1), dtype=torch.float32))
        self.log_s = nn.Parameter(torch.tensor(np.log(np.abs(s)), dtype=torch.float32))

    def weight(self):
        eye = torch.eye(self.P.shape[0], dtype=self.P.dtype, device=self.P.device)
        lower = self.lower * self.l_mask + eye
        upper = self.upper * self.l_mask.T + torch.diag(self.sign_s * torch.exp(self.log_s))
        return self.P @ lower @ upper

    def inverse_weight(self):
        # Inverted in float64 (the matrix is small): float32 inversion errors would add up over many steps.
        return torch.linalg.inv(self.weight().double()).to(self.lower.dtype)

    def forward(self, x, cond=None):
        y = torch.einsum("ij,bjt->bit", self.weight(), x)
        return y, self.log_s.sum().expand(x.shape[0]) * x.shape[2]

    def inverse(self, y, cond=None):
        x = torch.einsum("ij,bjt->bit", self.inverse_weight().to(y.dtype), y)
        return x, -self.log_s.sum().expand(y.shape[0]) * y.shape[2]


# The coupling's scale is sigmoid(raw + SCALE_OFFSET): with the zero-initialised last layer every coupling starts
# at scale sigmoid(2) ~ 0.88, near the identity but contracting a little (Glow's choice). MGStream folds the offset
# into its fused output bias, so this is the one place it is defined.
SCALE_OFFSET = 2.0


def coupling_scale(raw):
    """The affine coupling's scale from the network's raw scale output: sigmoid(raw + SCALE_OFFSET) > 0."""
    return torch.sigmoid(raw + SCALE_OFFSET)


class AffineCoupling(nn.Module):
    """Affine coupling (Glow §3.3): the first half x_a passes unchanged; the second half becomes
    y_b = (x_b + shift) * scale with (shift, raw) = net(x_a, cond) and scale = coupling_scale(raw) > 0.

    `net(x_a [B, Ca, T], cond [B, Cc, T]) -> [B, 2 * Cb, T]` must end in a zero-initialised layer, so that
    the coupling starts near the identity (scale = sigmoid(2) everywhere, shift = 0)."""

    def __init__(self, channels, net):
        super().__init__()
        self.c_a = channels // 2
        self.net = net

    def _shift_scale(self, x_a, cond):
        h = run_net(self, x_a, cond)
        shift, raw = h[:, 0::2], h[:, 1::2]
        return shift, coupling_scale(raw)

    def forward(self, x, cond=None):
        x_a, x_b = x[:, : self.c_a], x[:, self.c_a :]
        shift, scale = self._shift_scale(x_a, cond)
        y_b = (x_b + shift) * scale
        return torch.cat([x_a, y_b], dim=1), torch.log(scale).sum(dim=(1, 2))

    def inverse(self, y, cond=None):
        y_a, y_b = y[:, : self.c_a], y[:, self.c_a :]
        shift, scale = self._shift_scale(y_a, cond)
        x_b = y_b / scale - shift
        return torch.cat([y_a, x_b], dim=1), -torch.log(scale).sum(dim=(1, 2))


class SqueezeTime(nn.Module):
    """[B, C, T] -> [B, 2C, T/2]: each pair of neighbouring frames becomes one frame with twice the channels
    (volume preserving). `squeeze(cond)` applies the same to the control, which is never split."""

    def forward(self, x, cond=None):
        return squeeze_time(x), x.new_zeros(x.shape[0])

    def inverse(self, y, cond=None):
        return unsqueeze_time(y), y.new_zeros(y.shape[0])


def squeeze_time(x):
    b, c, t = x.shape
    if t % 2:
        raise ValueError(f"squeeze along time needs an even number of frames, got {t}")
    return x.reshape(b, c, t // 2, 2).permute(0, 1, 3, 2).reshape(b, 2 * c, t // 2)


def unsqueeze_time(y):
    b, c2, t = y.shape
    return y.reshape(b, c2 // 2, 2, t).permute(0, 1, 3, 2).reshape(b, c2 // 2, 2 * t)


class Split(nn.Module):
    """Multi-scale split (Glow §3, 'split'): the second half of the channels leaves the flow for the latent.

    Glow gives the leaving half a learned Gaussian prior conditioned on the half that stays (and here the
    control); we write that prior as a bijection z_b = (x_b - mu) * exp(-log_sigma), so the leaving part is
    standard normal and the layer is an ordinary invertible layer with a log-determinant. The model takes
    channels [c_keep:] out after it. `net(x_keep, cond) -> [B, 2 * (C - c_keep), T]`, zero-initialised."""

    def __init__(self, channels, net):
        super().__init__()
        self.c_keep = channels // 2
        self.net = net

    def _mu_logsigma(self, x_a, cond):
        h = run_net(self, x_a, cond)
        return h[:, 0::2], h[:, 1::2]

    def forward(self, x, cond=None):
        x_a, x_b = x[:, : self.c_keep], x[:, self.c_keep :]
        mu, log_sigma = self._mu_logsigma(x_a, cond)
        z_b = (x_b - mu) * torch.exp(-log_sigma)
        return torch.cat([x_a, z_b], dim=1), -log_sigma.sum(dim=(1, 2))

    def inverse(self, y, cond=None):
        y_a, z_b = y[:, : self.c_keep], y[:, self.c_keep :]
        mu, log_sigma = self._mu_logsigma(y_a, cond)
        x_b = z_b * torch.exp(log_sigma) + mu
        return torch.cat([y_a, x_b], dim=1), log_sigma.sum(dim=(1, 2))


class Chain(nn.Module):
    """Layers applied in order; log-determinants add up. FlowStep = Chain(ActNorm, LU linear, coupling)."""

    def __init__(self, *layers):
        super().__init__()
        self.layers = nn.ModuleList(layers)

    def forward(self, x, cond=None):
        total = x.new_zeros(x.shape[0])
        for layer in self.layers:
            x, logdet = layer(x, cond)
            total = total + logdet
        return x, total

    def inverse(self, y, cond=None):
        total = y.new_zeros(y.shape[0])
        for layer in reversed(self.layers):
            y, logdet = layer.inverse(y, cond)
            total = total + logdet
        return y, total


def FlowStep(channels, net):
    """One Glow step of flow: actnorm -> invertible linear (LU) -> affine coupling."""
    return Chain(ActNorm(channels), InvertibleLinearLU(channels), AffineCoupling(channels, net))


class ConvNet(nn.Module):
    """FL's coupling network: conv over frames t-1..t+1 of [x_a, cond], a 1x1 hidden conv, and a
    zero-initialised 1x1 output conv (MoGlow §3.3, §5.2: 2 hidden conv layers)."""

    def __init__(self, in_channels, cond_channels, out_channels, hidden, kernel=3):
        super().__init__()
        self.layers = nn.Sequential(
            nn.Conv1d(in_channels + cond_channels, hidden, kernel, padding=kernel // 2),
            nn.ReLU(),
            nn.Conv1d(hidden, hidden, 1),
            nn.ReLU(),
            ZeroConv1d(hidden, out_channels),
        )

    def forward(self, x_a, cond):
        return self.layers(x_a if cond is None else torch.cat([x_a, cond], dim=1))


class ZeroConv1d(nn.Conv1d):
    """1x1 conv initialised to zero, so a coupling/prior starts at the identity/standard normal."""

    def __init__(self, in_channels, out_channels):
        super().__init__(in_channels, out_channels, 1)
        nn.init.zeros_(self.weight)
        nn.init.zeros_(self.bias)


def gaussian_logp(z):
    """log N(z; 0, I) summed over all but the batch dimension."""
    return -0.5 * (z.pow(2) + math.log(2 * math.pi)).flatten(1).sum(1)


class MotionFlow(nn.Module):
    """Base of the two motion models: holds the data statistics (so a checkpoint samples without the
    dataset) and the config it was built from."""

    def __init__(self, config, pose_dim, control_dim):
        super().__init__()
        self.config = dict(config)
        self.pose_dim, self.control_dim = pose_dim, control_dim
        self.register_buffer("x_mean", torch.zeros(pose_dim))
        self.register_buffer("x_std", torch.ones(pose_dim))
        self.register_buffer("c_mean", torch.zeros(control_dim))
        self.register_buffer("c_std", torch.ones(control_dim))

    def set_stats(self, x_mean, x_std, c_mean, c_std):
        for name, v in dict(x_mean=x_mean, x_std=x_std, c_mean=c_mean, c_std=c_std).items():
            getattr(self, name).copy_(torch.as_tensor(np.asarray(v), dtype=getattr(self, name).dtype))

    def standardize_x(self, x):
        return (x - self.x_mean) / self.x_std

    def standardize_c(self, c):
        return (c - self.c_mean) / self.c_std

    def unstandardize_x(self, x):
        return x * self.x_std + self.x_mean

    def unstandardize_c(self, c):
        return c * self.c_std + self.c_mean
