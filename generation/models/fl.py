"""FL: a conditional Glow over whole fixed-length pose sequences (MoGlow §3.3-3.4, §5.2 'FL').

The window x [B, T, 63] is one point of the flow; the control c [B, T, 3] of the same frames conditions
every coupling. L levels of K steps; between levels the sequence is squeezed along time (two frames ->
one with twice the channels), the control squeezed with it but never split; after each level but the last,
half the channels leave for the latent. Exact log-likelihood.
"""

from dataclasses import asdict, dataclass, field

import torch
from torch import nn

from .flows import Chain, ConvNet, FlowStep, MotionFlow, Split, gaussian_logp, squeeze_time, unsqueeze_time

_ONE_UP = {"min": 1}  # field metadata: the bounds the training config checks (training.config)


@dataclass(frozen=True)
class FLConfig:
    """FL's size, in the paper's names (L levels of K steps) and at the paper's values."""

    L: int = field(default=4, metadata=_ONE_UP)
    K: int = field(default=32, metadata=_ONE_UP)
    hidden: int = field(default=512, metadata=_ONE_UP)
    kernel: int = field(default=3, metadata=_ONE_UP)


class FL(MotionFlow):
    kind = "fl"

    def __init__(self, config, pose_dim=63, control_dim=3):
        # A checkpoint's model_config is a plain dict; the dataclass fills its defaults and refuses unknown keys.
        super().__init__(asdict(FLConfig(**config)), pose_dim, control_dim)
        cfg = self.config
        self.levels = nn.ModuleList()
        self.splits = nn.ModuleList()
        ch, cc = pose_dim, control_dim
        self.level_channels = []
        for level in range(cfg["L"]):
            if level > 0:
                ch, cc = 2 * ch, 2 * cc
            c_a = ch // 2
            self.levels.append(
                Chain(
                    *[
                        FlowStep(ch, ConvNet(c_a, cc, 2 * (ch - c_a), cfg["hidden"], cfg["kernel"]))
                        for _ in range(cfg["K"])
                    ]
                )
            )
            self.level_channels.append(ch)
            if level < cfg["L"] - 1:
                keep = ch // 2
                self.splits.append(Split(ch, ConvNet(keep, cc, 2 * (ch - keep), cfg["hidden"], cfg["kernel"])))
                ch = keep

    def check_length(self, t):
        k = 2 ** (self.config["L"] - 1)
        if t % k:
            raise ValueError(f"FL with {self.config['L']} levels needs a window length divisible by {k}, got {t}")

    def forward(self, x, c):
        """x [B, T, 63], c [B, T, 3] (standardised) -> (z [B, T * 63], logdet [B])."""
        self.check_length(x.shape[1])
        h, cond = x.transpose(1, 2), c.transpose(1, 2)
        logdet = x.new_zeros(x.shape[0])
        zs = []
        for level, chain in enumerate(self.levels):
            if level > 0:
                h, cond = squeeze_time(h), squeeze_time(cond)
            h, ld = chain(h, cond)
            logdet = logdet + ld
            if level < len(self.levels) - 1:
                split = self.splits[level]
                h, ld = split(h, cond)
                logdet = logdet + ld
                zs.append(h[:, split.c_keep :].flatten(1))
                h = h[:, : split.c_keep]
        zs.append(h.flatten(1))
        return torch.cat(zs, dim=1), logdet

    def inverse(self, z, c):
        """z [B, T * 63], c [B, T, 3] -> (x [B, T, 63], logdet of the inverse map [B])."""
        b, t = c.shape[0], c.shape[1]
        self.check_length(t)
        conds = [c.transpose(1, 2)]
        for _ in range(1, len(self.levels)):
            conds.append(squeeze_time(conds[-1]))
        # Cut z into the parts that left at each level (in forward order) and the final one.
        sizes, ts = [], t
        for level, ch in enumerate(self.level_channels):
            if level > 0:
                ts //= 2
            sizes.append((ch - ch // 2, ts) if level < len(self.levels) - 1 else (ch, ts))
        parts = list(torch.split(z, [a * b_ for a, b_ in sizes], dim=1))
        logdet = z.new_zeros(b)
        h = parts[-1].reshape(b, *sizes[-1])
        for level in reversed(range(len(self.levels))):
            if level < len(self.levels) - 1:
                z_out = parts[level].reshape(b, *sizes[level])
                h, ld = self.splits[level].inverse(torch.cat([h, z_out], dim=1), conds[level])
                logdet = logdet + ld
            h, ld = self.levels[level].inverse(h, conds[level])
            logdet = logdet + ld
            if level > 0:
                h = unsqueeze_time(h)
        return h.transpose(1, 2), logdet

    def nll(self, x, c, keep=None, history=None):
        """Negative log-likelihood in nats per dimension of the standardised data, per batch element.
        (`keep`, `history`: MG's history dropout mask and noisy history; FL has no history.)"""
        z, logdet = self(x, c)
        return -(gaussian_logp(z) + logdet) / z.shape[1]

    @torch.no_grad()
    def sample(self, c, temperature=1.0, generator=None):
        """Standardised control [B, T, 3] -> standardised poses [B, T, 63]."""
        z = (
            torch.randn(c.shape[0], c.shape[1] * self.pose_dim, generator=generator, dtype=c.dtype, device="cpu").to(
                c.device
            )
            * temperature
        )
        return self.inverse(z, c)[0]
