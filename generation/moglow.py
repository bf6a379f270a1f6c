"""MG (MoGlow, §4): an autoregressive, causal conditional Glow that generates one pose frame at a time.

Each frame x_t [63] passes one level of K steps (actnorm -> LU linear -> affine coupling). Every coupling
network is a 2-layer LSTM reading [lower half of x_t, poses t-tau..t-1, control t-tau..t] and carrying its
hidden state from frame to frame, followed by a zero-initialised linear layer. Whole history frames are
dropped with rate 0.95 in training, so the model must listen to the control (§4, §5.2).

Training runs each coupling LSTM over a whole window at once (frames tau..T-1, history from the window,
h = 0 at frame tau): that equals the frame-by-frame flow, because every other layer acts frame-wise.
Sampling (MGStream) runs the same flow inverted, one frame at a time, with pre-fused weights.
"""
import torch
from torch import nn

from .flows import Chain, FlowStep, MotionFlow, gaussian_logp

DEFAULTS = dict(K=16, hidden=512, lstm_layers=2, tau=10, dropout=0.95)


class LSTMNet(nn.Module):
    """Coupling network of MG: LSTM over frames of [x_a, cond], then a zero-initialised linear layer."""

    def __init__(self, in_channels, cond_channels, out_channels, hidden, layers):
        super().__init__()
        self.lstm = nn.LSTM(in_channels + cond_channels, hidden, num_layers=layers, batch_first=True)
        self.out = nn.Linear(hidden, out_channels)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, x_a, cond):
        h, _ = self.lstm(torch.cat([x_a, cond], dim=1).transpose(1, 2).contiguous())  # zero initial state
        return self.out(h).transpose(1, 2)


class MoGlow(MotionFlow):
    kind = "mg"

    def __init__(self, config, pose_dim=63, control_dim=3):
        super().__init__({**DEFAULTS, **config}, pose_dim, control_dim)
        cfg = self.config
        self.tau = cfg["tau"]
        self.cond_dim = self.tau * pose_dim + (self.tau + 1) * control_dim
        c_a = pose_dim // 2
        self.flow = Chain(*[
            FlowStep(pose_dim, LSTMNet(c_a, self.cond_dim, 2 * (pose_dim - c_a), cfg["hidden"], cfg["lstm_layers"]))
            for _ in range(cfg["K"])])

    def make_cond(self, x, c):
        """Conditioning of frames tau..T-1 of a window: [poses t-tau..t-1, control t-tau..t] -> [B, n, cond_dim].
        While training, each history pose frame is dropped (zeroed: the mean pose) with probability `dropout`."""
        tau, n = self.tau, x.shape[1] - self.tau
        hist = x.unfold(1, tau, 1)[:, :n].transpose(2, 3)  # [B, n, tau, 63], oldest first
        if self.training and self.config["dropout"] > 0:
            keep = torch.rand(hist.shape[:3] + (1,), device=x.device) >= self.config["dropout"]
            hist = hist * keep.to(hist.dtype)
        ctrl = c.unfold(1, tau + 1, 1).transpose(2, 3)  # [B, n, tau + 1, 3]
        return torch.cat([hist.flatten(2), ctrl.flatten(2)], dim=2)

    def forward(self, x, c):
        """Window x [B, T, 63], c [B, T, 3] (standardised) -> (z [B, T - tau, 63] for frames tau..T-1, logdet [B])."""
        if x.shape[1] <= self.tau:
            raise ValueError(f"MG needs windows longer than tau={self.tau} frames, got {x.shape[1]}")
        cond = self.make_cond(x, c).transpose(1, 2)
        z, logdet = self.flow(x[:, self.tau:].transpose(1, 2), cond)
        return z.transpose(1, 2), logdet

    def nll(self, x, c):
        """Negative log-likelihood of frames tau..T-1 in nats per dimension (standardised data), per element."""
        z, logdet = self(x, c)
        return -(gaussian_logp(z) + logdet) / z[0].numel()

    @torch.no_grad()
    def inverse(self, z, history, c):
        """Frames from latents: z [B, n, 63], history [B, tau, 63], c [B, tau + n, 3] (all standardised)
        -> x [B, n, 63]. The exact inverse of forward (used by the tests); sampling = random z."""
        stream = MGStream(self, history, c[:, :self.tau])
        return torch.stack([stream.step(c[:, self.tau + t], z=z[:, t]) for t in range(z.shape[1])], dim=1)

    @torch.no_grad()
    def inverse_naive(self, z, history, c):
        """The same as inverse, computed the plain way: for each frame, every coupling's nn.LSTM is called
        on that frame with its carried (h, c) state. The benchmark's baseline and the tests' reference."""
        tau = self.tau
        steps = list(self.flow.layers)
        states = [None] * len(steps)
        hist, outs = history, []
        for t in range(z.shape[1]):
            ctrl = c[:, t:t + tau + 1]
            cond = torch.cat([hist.flatten(1), ctrl.flatten(1)], dim=1)[:, :, None]  # [B, cond_dim, 1]
            y = z[:, t][:, :, None]
            for k in reversed(range(len(steps))):
                actnorm, linear, coupling = steps[k].layers
                y_a = y[:, :coupling.c_a]
                inp = torch.cat([y_a, cond], dim=1).transpose(1, 2)
                h, states[k] = coupling.net.lstm(inp, states[k])
                out = coupling.net.out(h).transpose(1, 2)
                shift, scale = out[:, 0::2], torch.sigmoid(out[:, 1::2] + 2.0)
                y = torch.cat([y_a, y[:, coupling.c_a:] / scale - shift], dim=1)
                y = linear.inverse(y)[0]
                y = actnorm.inverse(y)[0]
            x_t = y[:, :, 0]
            outs.append(x_t)
            hist = torch.cat([hist[:, 1:], x_t[:, None]], dim=1)
        return torch.stack(outs, dim=1)


class MGStream:
    """Real-time MG sampling: one control frame in, one pose out (both standardised).

        stream = MGStream(model, history [B, tau, 63], history_control [B, tau, 3], temperature, generator)
        x_t = stream.step(control_t [B, 3])      # [B, 63]

    Fast because (1) the part of every coupling LSTM's gates that depends only on the history, the control
    and the previous frame's hidden state (the same inputs for all K steps of a frame) is computed for all
    K steps at once, in one matmul and one batched matmul per LSTM layer at the start of the frame; (2)
    weights are fused and pre-transposed once (actnorm folded into the inverse linear map, the coupling's
    '+2' into the output bias, shift/scale rows made contiguous); (3) no autograd. Starts with h = 0
    (paper footnote 2).
    """

    def __init__(self, model, history, history_control, temperature=1.0, generator=None):
        self.model, self.tau = model, model.tau
        self.temperature, self.generator = temperature, generator
        p = next(model.parameters())
        self.dtype, self.device = p.dtype, p.device
        self.hist = history.to(self.device, self.dtype).clone()          # [B, tau, 63]
        self.hist_c = history_control.to(self.device, self.dtype).clone()  # [B, tau, 3]
        b = self.hist.shape[0]
        self.w = w = fused_weights(model)
        # (h, c) of every LSTM layer, for all K steps at once: [K, B, H]
        self.h = [torch.zeros(w["K"], b, w["H"], dtype=self.dtype, device=self.device) for _ in w["Whh"]]
        self.c = [torch.zeros_like(h) for h in self.h]

    @torch.no_grad()
    def step(self, control, z=None):
        w, b = self.w, self.hist.shape[0]
        k_steps, hid, c_a, layers = w["K"], w["H"], w["c_a"], len(w["Whh"])
        ctrl = torch.cat([self.hist_c, control.to(self.device, self.dtype)[:, None]], dim=1)
        cond = torch.cat([self.hist.flatten(1), ctrl.flatten(1)], dim=1)
        # Gate pre-activations from this frame's shared inputs and last frame's states, all K steps at once.
        pre = [torch.baddbmm(torch.addmm(w["b"][0], cond, w["Wc"]).view(b, k_steps, 4 * hid).transpose(0, 1),
                             self.h[0], w["Whh"][0])]
        pre += [torch.baddbmm(w["b"][l], self.h[l], w["Whh"][l]) for l in range(1, layers)]
        if z is None:
            z = torch.randn(b, self.model.pose_dim, generator=self.generator, dtype=self.dtype,
                            device="cpu").to(self.device) * self.temperature
        y = z.to(self.device, self.dtype)
        new_h = [torch.empty_like(h) for h in self.h]
        new_c = [torch.empty_like(c) for c in self.c]
        for k in reversed(range(k_steps)):
            y_a = y[:, :c_a]
            h, c = lstm_cell(torch.addmm(pre[0][k], y_a, w["Wx"][k]), self.c[0][k])
            new_h[0][k], new_c[0][k] = h, c
            for l in range(1, layers):
                h, c = lstm_cell(torch.addmm(pre[l][k], h, w["Wih"][l][k]), self.c[l][k])
                new_h[l][k], new_c[l][k] = h, c
            out = torch.addmm(w["bo"][k], h, w["Wo"][k])
            n_b = out.shape[1] // 2
            y_b = y[:, c_a:] / torch.sigmoid(out[:, n_b:]) - out[:, :n_b]
            # Inverse LU linear map with the inverse actnorm folded in: x = y W^-T diag(e^-logs) - bias.
            y = torch.addmm(w["bn"][k], torch.cat([y_a, y_b], dim=1), w["Winv"][k])
        self.h, self.c = new_h, new_c
        self.hist = torch.cat([self.hist[:, 1:], y[:, None]], dim=1)
        self.hist_c = ctrl[:, 1:]
        return y


def lstm_cell(gates, c):
    i, f, g, o = gates.chunk(4, dim=1)
    c = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(g)
    return torch.sigmoid(o) * torch.tanh(c), c


@torch.no_grad()
def fused_weights(model):
    """Pre-fused, pre-transposed inference weights of all K steps (cached on the model until it changes)."""
    key = tuple((p.data_ptr(), p._version) for p in model.parameters())
    cached = getattr(model, "_fused", None)
    if cached is not None and cached[0] == key:
        return cached[1]
    c_a, layers = model.pose_dim // 2, model.config["lstm_layers"]
    acc = {n: [] for n in ("Wx", "Wc", "Wo", "bo", "Winv", "bn")}
    whh, wih, bias = [[] for _ in range(layers)], [[] for _ in range(layers)], [[] for _ in range(layers)]
    for step in model.flow.layers:
        actnorm, linear, coupling = step.layers
        lstm, out = coupling.net.lstm, coupling.net.out
        w_ih = lstm.weight_ih_l0
        acc["Wx"].append(w_ih[:, :c_a].T)
        acc["Wc"].append(w_ih[:, c_a:].T)
        for l in range(layers):
            whh[l].append(getattr(lstm, f"weight_hh_l{l}").T)
            wih[l].append(getattr(lstm, f"weight_ih_l{l}").T)
            bias[l].append(getattr(lstm, f"bias_ih_l{l}") + getattr(lstm, f"bias_hh_l{l}"))
        # Output rows: shifts first, then scale logits with the coupling's +2 folded into the bias.
        acc["Wo"].append(torch.cat([out.weight[0::2], out.weight[1::2]]).T)
        acc["bo"].append(torch.cat([out.bias[0::2], out.bias[1::2] + 2.0]))
        inv = linear.inverse_weight() * torch.exp(-actnorm.logs[0])  # diag(e^-logs) W^-1
        acc["Winv"].append(inv.T)
        acc["bn"].append(-actnorm.bias[0, :, 0])
    w = {n: torch.stack(v).contiguous() for n, v in acc.items()}
    k, hid = len(model.flow.layers), model.config["hidden"]
    # All K steps' history/control projections side by side: one [cond_dim, K * 4H] matmul per frame.
    w["Wc"] = w["Wc"].permute(1, 0, 2).reshape(-1, k * 4 * hid).contiguous()
    w["Whh"] = [torch.stack(v).contiguous() for v in whh]
    w["Wih"] = [None] + [torch.stack(v).contiguous() for v in wih[1:]]
    w["b"] = [torch.stack(bias[0]).reshape(-1)] + [torch.stack(v)[:, None] for v in bias[1:]]
    w.update(K=k, H=hid, c_a=c_a)
    model._fused = (key, w)
    return w
