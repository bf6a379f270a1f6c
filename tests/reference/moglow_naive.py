"""MoGlow's inverse computed the plain way: the reference for generation.models.mg_stream.MGStream."""

import torch

from generation.models.flows import coupling_scale


@torch.no_grad()
def inverse_naive(model, z, history, c):
    """The same as MoGlow.inverse (z [B, n, 63], history [B, tau, 63], c [B, tau + n, 3], all standardised ->
    x [B, n, 63]), computed the plain way: for each frame, every coupling's nn.LSTM is called on that frame with
    its carried (h, c) state. The benchmark's baseline and the tests' reference."""
    tau = model.tau
    steps = list(model.flow.layers)
    states = [None] * len(steps)
    hist, outs = history, []
    style = [model.style_of(history)] if model.config["history_style"] else []  # fixed: the seed history's
    for t in range(z.shape[1]):
        ctrl = c[:, t : t + tau + 1]
        cond = torch.cat([hist.flatten(1), ctrl.flatten(1), *style], dim=1)[:, :, None]  # [B, cond_dim, 1]
        y = z[:, t][:, :, None]
        for k in reversed(range(len(steps))):
            actnorm, linear, coupling = steps[k].layers
            y_a = y[:, : coupling.c_a]
            inp = torch.cat([y_a, cond], dim=1).permute(2, 0, 1)  # [1 frame, B, channels]
            h, states[k] = coupling.net.lstm(inp, states[k])
            out = coupling.net.out(h).permute(1, 2, 0)
            shift, scale = out[:, 0::2], coupling_scale(out[:, 1::2])
            y = torch.cat([y_a, y[:, coupling.c_a :] / scale - shift], dim=1)
            y = linear.inverse(y)[0]
            y = actnorm.inverse(y)[0]
        x_t = y[:, :, 0] + (model.step_base(hist[:, -1], c[:, t + tau]) if model.config["residual"] else 0)
        outs.append(x_t)
        hist = torch.cat([hist[:, 1:], x_t[:, None]], dim=1)
    return torch.stack(outs, dim=1)
