"""MG (MoGlow, §4): an autoregressive, causal conditional Glow that generates one pose frame at a time.

Each frame x_t [63] passes one level of K steps (actnorm -> LU linear -> affine coupling). Every coupling
network is a 2-layer LSTM reading [lower half of x_t, poses t-tau..t-1, control t-tau..t] and carrying its
hidden state from frame to frame, followed by a zero-initialised linear layer. Whole history frames are
dropped with rate 0.95 in training, so the model must listen to the control (§4, §5.2).

Training runs each coupling LSTM over a whole window at once (frames tau..T-1, history from the window,
h = 0 at frame tau): that equals the frame-by-frame flow, because every other layer acts frame-wise.
Sampling (mg_stream.MGStream) runs the same flow inverted, one frame at a time, with pre-fused weights.

`residual` (not in the paper; off in mg_paper): the flow models the step x_t - x_{t-1} from the previous pose
(standardised) instead of the pose itself. The shift depends on the history alone, so its Jacobian is 1 and the
NLL is still that of the poses; but the coupling networks no longer have to reproduce the previous pose to within
millimetres to keep the body still, and what they missed was MG's frame-to-frame jitter
(bench/notes/2026-11-25-history.md).

`carry_feet` (with `residual`; not in the paper): the feet's step is taken from where the root's step of frame t
(its control) carries the previous frame's feet, so that a foot planted on the floor has a step of 0. The rest of
the body steps from where it was. The shift still depends on the history and the control alone: Jacobian 1.

`history_style` (not in the paper; off in mg_paper): every frame's coupling networks also read the mean pose of the
window's first tau frames, the real history MG is seeded with. Once that history has slid out of the tau-frame
window, MG otherwise sees only its own frames, and drifts to an average walker within half a second (a sad
walker's hanging head straightens). The mean pose is a style input in the sense of StyleGestures (Alexanderson
et al. 2020), taken from the motion itself rather than a label, so it works for any skeleton and any data. It is
a function of the history, so the flows and the exact likelihood are unchanged.

`style_span` (with `history_style`; 0 by default): trained on the mean of its tau history frames alone, MG hardly
follows its style input, since the recent frames already tell it the posture of the next one. With `style_span` N >
tau, each training batch's style input is instead the mean of the window's first k real frames, k drawn per batch
from tau..N (as StyleGestures reads its style controls from the real motion around each frame): a style that also
speaks for the frames being predicted, which MG learns to follow (the posture kept in 0.85 of the held-out windows
against 0.78; bench/RESULTS.md model-realism). Validation, sampling and the likelihood MG reports read the history's
mean as before, so its NLL is the same quantity; a caller with a longer real seed may pass that seed's mean
(sample.sample_mg's `style`).
"""

import functools
from dataclasses import asdict, dataclass, field

import torch
from torch import nn

from ..motion.skeleton import FEET
from .flows import Chain, FlowStep, MotionFlow, gaussian_logp
from .mg_stream import MGStream

_ONE_UP, _ZERO_UP = {"min": 1}, {"min": 0}  # field metadata: the bounds the training config checks (training.config)


@dataclass(frozen=True)
class MGConfig:
    """MG's size and options: the paper's five fields at its values, then ours, off by default (module doc)."""

    K: int = field(default=16, metadata=_ONE_UP)
    hidden: int = field(default=512, metadata=_ONE_UP)
    lstm_layers: int = field(default=2, metadata=_ONE_UP)
    tau: int = field(default=10, metadata=_ONE_UP)
    dropout: float = field(default=0.95, metadata={"min": 0, "max": 1})
    residual: bool = False
    carry_feet: bool = False
    history_style: bool = False
    style_span: int = field(default=0, metadata=_ZERO_UP)  # frames


_FEET = torch.tensor(FEET)


@functools.cache
def lstm_runs_in(device_type, dtype):
    """Whether torch builds an LSTM kernel for `dtype` under autocast on `device_type`. oneDNN has no bfloat16 LSTM
    on CPUs without AVX-512 (it fails to create the primitive), so there LSTMNet runs its LSTM in float32 and the
    rest of the coupling network in bfloat16. Probed once per kind of device, forward and backward."""
    lstm = nn.LSTM(2, 2).to(device_type)
    try:
        with torch.autocast(device_type, dtype=dtype):
            h, _ = lstm(torch.zeros(1, 1, 2, device=device_type))
        h.float().sum().backward()
    except RuntimeError:
        return False
    return True


class LSTMNet(nn.Module):
    """Coupling network of MG: LSTM over frames of [x_a, cond], then a zero-initialised linear layer."""

    def __init__(self, in_channels, cond_channels, out_channels, hidden, layers):
        super().__init__()
        self.lstm = nn.LSTM(in_channels + cond_channels, hidden, num_layers=layers)  # frames first: no copy inside
        self.out = nn.Linear(hidden, out_channels)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, x_a, cond):
        # Joined straight into the LSTM's [frames, batch, channels] layout: one copy per coupling.
        z = torch.cat([x_a.permute(2, 0, 1), cond.permute(2, 0, 1)], dim=2)
        dev = z.device.type
        if torch.is_autocast_enabled(dev) and not lstm_runs_in(dev, torch.get_autocast_dtype(dev)):
            with torch.autocast(dev, enabled=False):
                h, _ = self.lstm(z.float())  # zero initial state
        else:
            h, _ = self.lstm(z)
        # Batch first again for the output layer: its weight gradient then adds the frames up in the order that
        # trained the shipped models, so float32 training keeps their bits.
        return self.out(h.transpose(0, 1)).transpose(1, 2)


class MoGlow(MotionFlow):
    kind = "mg"

    def __init__(self, config, pose_dim=63, control_dim=3):
        # A checkpoint's model_config is a plain dict; the dataclass fills its defaults and refuses unknown keys.
        super().__init__(asdict(MGConfig(**config)), pose_dim, control_dim)
        cfg = self.config
        self.tau = cfg["tau"]
        self.cond_dim = self.tau * pose_dim + (self.tau + 1) * control_dim + (pose_dim if cfg["history_style"] else 0)
        c_a = pose_dim // 2
        self.flow = Chain(
            *[
                FlowStep(pose_dim, LSTMNet(c_a, self.cond_dim, 2 * (pose_dim - c_a), cfg["hidden"], cfg["lstm_layers"]))
                for _ in range(cfg["K"])
            ]
        )

    def history_keep(self, batch, length, device=None):
        """Which history frames training keeps: bool [batch, length - tau, tau, 1], each dropped with probability
        `dropout`. Drawn for a whole batch so that ranks sharing it can each take their rows (train.py)."""
        n = length - self.tau
        return torch.rand(batch, n, self.tau, 1, device=device) >= self.config["dropout"]

    def make_cond(self, x, c, keep=None):
        """Conditioning of frames tau..T-1 of a window: [poses t-tau..t-1, control t-tau..t] (and with
        `history_style` the mean of poses 0..tau-1) -> [B, n, cond_dim]. While training, each history pose frame
        is dropped (zeroed: the mean pose) with probability `dropout`, as `keep` says (default: drawn here); the
        style input is never dropped: it stands for the whole seed history, which sampling always has."""
        tau, n = self.tau, x.shape[1] - self.tau
        hist = x.unfold(1, tau, 1)[:, :n].transpose(2, 3)  # [B, n, tau, 63], oldest first
        if self.training and self.config["dropout"] > 0:
            keep = self.history_keep(x.shape[0], x.shape[1], x.device) if keep is None else keep
            hist = hist * keep.to(hist.dtype)
        ctrl = c.unfold(1, tau + 1, 1).transpose(2, 3)  # [B, n, tau + 1, 3]
        parts = [hist.flatten(2), ctrl.flatten(2)]
        if self.config["history_style"]:
            parts.append(self.style_of(x[:, : self.style_frames(x.shape[1])])[:, None].expand(-1, n, -1))
        return torch.cat(parts, dim=2)

    def style_frames(self, length):
        """How many of a window's first frames the style input averages: tau, or while training with `style_span`
        a number drawn from tau..style_span (one per call, so one per pass over a batch, from torch's generator,
        which train.py seeds per step, so every rank of a run draws the same)."""
        span = min(self.config["style_span"], length)
        if not self.training or span <= self.tau:
            return self.tau
        return int(torch.randint(self.tau, span + 1, ()))

    @staticmethod
    def style_of(history):
        """The style input of `history_style`: the mean pose [B, 63] of the seed history [B, tau, 63]."""
        return history.mean(dim=1)

    def forward(self, x, c, keep=None, history=None):
        """Window x [B, T, 63], c [B, T, 3] (standardised) -> (z [B, T - tau, 63] for frames tau..T-1, logdet [B]).
        `keep`: history dropout mask while training (see history_keep); `history`: the poses [B, T, 63] that the
        conditioning reads instead of x (training's history noise)."""
        if x.shape[1] <= self.tau:
            raise ValueError(f"MG needs windows longer than tau={self.tau} frames, got {x.shape[1]}")
        src = x if history is None else history
        cond = self.make_cond(src, c, keep).transpose(1, 2)
        z, logdet = self.flow((x[:, self.tau :] - self.base(src, c)).transpose(1, 2), cond)
        return z.transpose(1, 2), logdet

    def base(self, history, c):
        """What the flow's output is added to, for frames tau..T-1 of a window (history [B, T, 63], c [B, T, 3])."""
        return self.step_base(history[:, self.tau - 1 : -1], c[:, self.tau :])

    def step_base(self, previous, control):
        """What frame t's flow output is added to: 0, or with `residual` the previous pose [..., 63], its feet
        carried by the root's step `control` [..., 3] with `carry_feet` (all standardised)."""
        if not self.config["residual"]:
            return previous.new_zeros(())
        if not self.config["carry_feet"]:
            return previous
        pose = self.unstandardize_x(previous).unflatten(-1, (-1, 3))  # [..., 21, 3], metres
        feet = pose[..., _FEET, :]
        forward, sideways, turn = (self.unstandardize_c(control)[..., None, i] for i in range(3))
        # Into the root frame of t: minus the root's step (x = left, z = forward), then minus its turn about +Y.
        px, pz = feet[..., 0] - sideways, feet[..., 2] - forward
        cos, sin = torch.cos(-turn), torch.sin(-turn)
        carried = torch.stack([cos * px + sin * pz, feet[..., 1], -sin * px + cos * pz], dim=-1)
        return self.standardize_x(pose.index_copy(-2, _FEET.to(previous.device), carried).flatten(-2))

    def nll(self, x, c, keep=None, history=None):
        """Negative log-likelihood of frames tau..T-1 in nats per dimension (standardised data), per element."""
        z, logdet = self(x, c, keep, history)
        return -(gaussian_logp(z) + logdet) / z[0].numel()

    def predict_frames(self, x, c, z=None, keep=None, history=None):
        """Frames tau..T-1 of a window x [B, T, 63], c [B, T, 3] from latents z [B, T - tau, 63] (None: zeros, the
        most likely frames), each predicted from the real history before it, all frames at once and
        differentiable (stance.stance_loss)."""
        src = x if history is None else history
        cond = self.make_cond(src, c, keep).transpose(1, 2)
        z = x.new_zeros(x.shape[0], x.shape[1] - self.tau, self.pose_dim) if z is None else z
        return self.flow.inverse(z.transpose(1, 2), cond)[0].transpose(1, 2) + self.base(src, c)

    @torch.no_grad()
    def inverse(self, z, history, c, layout=None):
        """Frames from latents: z [B, n, 63], history [B, tau, 63], c [B, tau + n, 3] (all standardised)
        -> x [B, n, 63]. The exact inverse of forward (used by the tests); sampling = random z."""
        stream = MGStream(self, history, c[:, : self.tau], layout=layout)
        return torch.stack([stream.step(c[:, self.tau + t], z=z[:, t]) for t in range(z.shape[1])], dim=1)
