"""MGStream: MoGlow's sampler, the flow of generation.moglow inverted one frame at a time with fused weights.

The model (moglow.MoGlow) is what training sees; this is the inference engine that sampling uses. It reads the
model's parameters only, fuses them once per layout (cached on the model until a parameter changes), and is
checked against the plain per-frame inverse in tests/reference/moglow_naive.py.
"""

import os

import torch

from .flows import PRECISIONS, SCALE_OFFSET


class MGStream:
    """Real-time MG sampling: one control frame in, one pose out (both standardised).

        stream = MGStream(model, history [B, tau, 63], history_control [B, tau, 3], temperature, generator)
        x_t = stream.step(control_t [B, 3])      # [B, 63]

    Where the time goes (paper size: 73M LSTM weights, all read once per frame) and how it is cut:
    (1) everything in the coupling LSTMs' gates that is known at the start of a frame is computed for all K
    steps at once: layer 1's history+control part (one batched matmul; the input padded to a multiple of 16
    columns, layer 1's bias folded into the padding) and the recurrent h_{t-1} products of every layer (one
    batched matmul per layer); (2) per step only what depends on the previous step's output is
    left: layer 1's lower-half product, layer 2's 2048x512 input product, the cells, the output layer and
    the 63x63 inverse, all accumulated in place into preallocated buffers; (3) weights are fused once
    (actnorm folded into the inverse linear map, the coupling's SCALE_OFFSET into the output bias, shift/scale rows
    contiguous, gates reordered to i, f, o, g so one sigmoid covers three); (4) no autograd.
    Starts with h = 0 (paper footnote 2).

    precision="bfloat16" reads the big products' weights (the LSTMs' recurrent, history/control and layer-2 input
    weights, 98% of the bytes) and their inputs in bfloat16; the products still add up in float32, and the gates,
    cells, states, output layers and inverse maps stay float32. On a CPU with AVX512-BF16 that runs 30 streams
    about 1.85x faster; it is the same model to within bfloat16's rounding of those weights (bench/RESULTS.md has its
    motion figures), and it is slower on CPUs without bfloat16 arithmetic. The default is float32.

    Two memory layouts compute the same thing (they differ only in float rounding):
    "row": activations [B, features], weights stored [in, out], every product X @ W;
    "col": activations [features, B], weights stored [out, in] as nn.LSTM keeps them, every product W @ X.
    Which is faster depends on the CPU and its BLAS, by up to 2.8x either way (bench/RESULTS.md), so
    layout=None takes `default_layout`, a fixed choice per device type, CPU vendor and batch size (never a timing,
    so the same inputs give the same bits run after run); pass a layout to fix it.
    """

    def __init__(
        self, model, history, history_control, temperature=1.0, generator=None, layout=None, precision="float32"
    ):
        self.model, self.tau = model, model.tau
        self.temperature, self.generator = temperature, generator
        p = next(model.parameters())
        self.dtype, self.device = p.dtype, p.device
        self.hist = history.to(self.device, self.dtype).clone()  # [B, tau, 63]
        self.hist_c = history_control.to(self.device, self.dtype).clone()  # [B, tau, 3]
        b = self.hist.shape[0]
        self.layout = layout or default_layout(self.device, b)
        if self.layout not in LAYOUTS:
            raise ValueError(f"MGStream: layout must be one of {LAYOUTS}, got {self.layout!r}")
        if precision not in PRECISIONS:
            raise ValueError(f"MGStream: precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
        self.low = PRECISIONS[precision]  # the big products' dtype, None for float32
        self.w = w = fused_weights(model, self.layout, self.low)
        k_steps, hid, layers = w["K"], w["H"], len(w["Whh"])
        rows = self.layout == "row"
        shape = (lambda n: (b, n)) if rows else (lambda n: (n, b))
        # Buffers are updated in place; created under inference mode they may only be changed under it.
        self._inference = torch.is_inference_mode_enabled()
        new = dict(dtype=self.dtype, device=self.device)
        # (h, c) of every LSTM layer for all K steps: step k overwrites its own slice after the frame's
        # batched products have read last frame's values.
        self.h = [torch.zeros(k_steps, *shape(hid), **new) for _ in range(layers)]
        self.c = [torch.zeros(k_steps, *shape(hid), **new) for _ in range(layers)]
        self.gates = [torch.empty(k_steps, *shape(4 * hid), **new) for _ in range(layers)]
        self.out = torch.empty(*shape(w["n_out"]), **new)
        self.y_ab = torch.empty(*shape(model.pose_dim), **new)
        self.cond = torch.zeros(b, w["cond_cols"], **new)
        self.cond[:, w["cond_dim"]] = 1.0
        # (weight, x) -> the operands of torch.mm/addmm for "W x": (x, W) in rows, (W, x) in columns.
        self._mm = (lambda wt, x: (x, wt)) if rows else (lambda wt, x: (wt, x))
        # The cond buffer as every step's input of the batched layer-1 product (a view: refilled in place).
        self._expand_k = (lambda x: x.expand(k_steps, b, -1)) if rows else (lambda x: x.T.expand(k_steps, -1, b))
        self._cond_k = self._expand_k(self.cond)
        self._fdim = 1 if rows else 0  # the feature dimension of activations
        # Per-step views made once: indexing [K, ...] tensors 16x per frame costs more than it looks.
        self._steps = [
            (
                w["Wx"][k],
                [w["Wih"][layer][k] if layer else None for layer in range(layers)],
                w["Wo"][k],
                w["bo"][k],
                w["Winv"][k],
                w["bn"][k],
                [g[k] for g in self.gates],
                [c[k] for c in self.c],
                [h[k] for h in self.h],
            )
            for k in range(k_steps)
        ]

    @torch.no_grad()
    def step(self, control, z=None):
        with torch.inference_mode(self._inference):
            return self._step(control, z)

    def _frame_start(self):
        """Gate pre-activations from this frame's shared inputs and last frame's states, all K steps at once."""
        w, gates, mm, low = self.w, self.gates, self._mm, self.low
        for layer in range(len(gates)):
            if low is None:
                torch.bmm(*mm(w["Whh"][layer], self.h[layer]), out=gates[layer])
            else:
                gates[layer].copy_(torch.bmm(*mm(w["Whh"][layer], self.h[layer].to(low))))
            if layer > 0:
                gates[layer].add_(w["b"][layer])
        if low is None:
            gates[0].baddbmm_(*mm(w["Wc"], self._cond_k))
        else:
            gates[0].add_(torch.bmm(*mm(w["Wc"], self._expand_k(self.cond.to(low)))))

    def _add_product(self, gates, wt, x):
        """gates += the product of wt and x (in bfloat16 with `precision`, the sum in float32)."""
        if self.low is None:
            return gates.addmm_(*self._mm(wt, x))
        return gates.add_(torch.mm(*self._mm(wt, x.to(self.low))))

    def _step(self, control, z):
        w, b, mm, fd = self.w, self.hist.shape[0], self._mm, self._fdim
        c_a, n_b, hid = w["c_a"], w["n_out"] // 2, w["H"]
        ctrl = torch.cat([self.hist_c, control.to(self.device, self.dtype)[:, None]], dim=1)
        cond = self.cond  # [B, cond_dim + pad]: history, control, then 1 (layer 1's bias) and zeros
        cond[:, : self.hist[0].numel()] = self.hist.flatten(1)
        cond[:, self.hist[0].numel() : w["cond_dim"]] = ctrl.flatten(1)
        self._frame_start()
        if z is None:
            z = (
                torch.randn(b, self.model.pose_dim, generator=self.generator, dtype=self.dtype, device="cpu").to(
                    self.device
                )
                * self.temperature
            )
        y = z.to(self.device, self.dtype)
        if fd == 0:
            y = y.T  # [63, B]
        out, y_ab = self.out, self.y_ab
        out_shift, out_scale = out.narrow(fd, 0, n_b), out.narrow(fd, n_b, n_b)
        ab_a, ab_b = y_ab.narrow(fd, 0, c_a), y_ab.narrow(fd, c_a, y_ab.shape[fd] - c_a)
        for wx, wih, wo, bo, winv, bn, gates, cs, hs in reversed(self._steps):
            y_a = y.narrow(fd, 0, c_a)
            h = lstm_cell_(gates[0].addmm_(*mm(wx, y_a)), cs[0], hs[0], fd, hid)
            for layer in range(1, len(gates)):
                h = lstm_cell_(self._add_product(gates[layer], wih[layer], h), cs[layer], hs[layer], fd, hid)
            torch.addmm(bo, *mm(wo, h), out=out)
            ab_a.copy_(y_a)
            torch.div(y.narrow(fd, c_a, ab_b.shape[fd]), out_scale.sigmoid_(), out=ab_b).sub_(out_shift)
            # Inverse LU linear map with the inverse actnorm folded in: x = diag(e^-logs) W^-1 y - bias.
            y = torch.addmm(bn, *mm(winv, y_ab))
        y = y if fd else y.T.contiguous()
        if self.model.config["residual"]:
            y = y + self.model.step_base(self.hist[:, -1], ctrl[:, -1])
        self.hist = torch.cat([self.hist[:, 1:], y[:, None]], dim=1)
        self.hist_c = ctrl[:, 1:]
        return y


LAYOUTS = ("row", "col")
LOW_PRECISION = ("Whh", "Wih", "Wc")  # the weights that `precision` stores in bfloat16 (98% of the bytes)
BATCHED = 8  # streams from which a batch's products favour "col" on Intel CPUs (measured at 1 and 30)


def cpu_vendor():
    """The CPU's vendor string from /proc/cpuinfo ("GenuineIntel", "AuthenticAMD", ...); "" where unknown."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("vendor_id"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def default_layout(device, batch=1):
    """The layout for a device and batch size, fixed per device type, CPU vendor and batch so that sampling never
    depends on a timing race (the two layouts round differently). MOGLOW_LAYOUT=row|col overrides it.

    Measured at the paper's size (bench/RESULTS.md): on AMD Zen 3 with MKL "row" is faster for 1 and 30 streams
    (2.8x and 1.2-1.4x); on this project's Intel Xeon host "row" is 1.9x faster for one stream and "col" 1.2x
    faster for 30. cuBLAS takes either: "row"."""
    chosen = os.environ.get("MOGLOW_LAYOUT")
    if chosen:
        if chosen not in LAYOUTS:
            raise ValueError(f"MOGLOW_LAYOUT must be one of {LAYOUTS}, got {chosen!r}")
        return chosen
    if torch.device(device).type != "cpu" or cpu_vendor() == "AuthenticAMD" or batch < BATCHED:
        return "row"
    return "col"


def lstm_cell_(gates, c, h, dim, hid):
    """LSTM cell in place: gates in the order i, f, o, g along `dim` (overwritten), c updated, h written.
    Returns h."""
    s = gates.narrow(dim, 0, 3 * hid).sigmoid_()
    g = gates.narrow(dim, 3 * hid, hid).tanh_()
    c.mul_(s.narrow(dim, hid, hid)).addcmul_(s.narrow(dim, 0, hid), g)
    return torch.tanh(c, out=h).mul_(s.narrow(dim, 2 * hid, hid))


@torch.no_grad()
def fused_weights(model, layout="col", low=None):
    """Pre-fused inference weights of all K steps: [K, out, in] for "col", [K, in, out] for "row"; those of
    LOW_PRECISION in the dtype `low` where given. Cached on the model, one layout and dtype at a time (293 MB at
    the paper's size in float32), until its parameters change."""
    key = (layout, low, tuple((p.data_ptr(), p._version) for p in model.parameters()))
    cached = getattr(model, "_fused", None)
    if cached is None or cached[0] != key:
        w = _fuse_columns(model)
        if layout == "row":
            w = {
                n: (
                    [None if v is None else v.mT.contiguous() for v in x]
                    if isinstance(x, list)
                    else x.mT.contiguous()
                    if torch.is_tensor(x)
                    else x
                )
                for n, x in w.items()
            }
        for n in LOW_PRECISION if low is not None else ():
            w[n] = [None if v is None else v.to(low) for v in w[n]] if isinstance(w[n], list) else w[n].to(low)
        cached = model._fused = (key, w)
    return cached[1]


def _cond_columns(cond_dim):
    """Columns of the fused history/control weights: cond_dim, then one for layer 1's bias, then zeros up to a
    multiple of 16 (measured ~7% faster than 663 wide)."""
    return cond_dim + 1 + -(cond_dim + 1) % 16


def _fuse_columns(model):
    c_a, layers, hid = model.pose_dim // 2, model.config["lstm_layers"], model.config["hidden"]
    # nn.LSTM's gate order is i, f, g, o; reorder to i, f, o, g (one sigmoid over the first three).
    order = torch.cat([torch.arange(2 * hid), torch.arange(3 * hid, 4 * hid), torch.arange(2 * hid, 3 * hid)])
    acc = {n: [] for n in ("Wx", "Wc", "Wo", "bo", "Winv", "bn")}
    whh, wih, bias = [[] for _ in range(layers)], [[] for _ in range(layers)], [[] for _ in range(layers)]
    for step in model.flow.layers:
        actnorm, linear, coupling = step.layers
        lstm, out = coupling.net.lstm, coupling.net.out
        w_ih = lstm.weight_ih_l0[order]
        acc["Wx"].append(w_ih[:, :c_a])
        acc["Wc"].append(w_ih[:, c_a:])
        for layer in range(layers):
            whh[layer].append(getattr(lstm, f"weight_hh_l{layer}")[order])
            wih[layer].append(getattr(lstm, f"weight_ih_l{layer}")[order])
            bias[layer].append((getattr(lstm, f"bias_ih_l{layer}") + getattr(lstm, f"bias_hh_l{layer}"))[order])
        # Output rows: shifts first, then scale logits with the coupling's offset folded into the bias.
        acc["Wo"].append(torch.cat([out.weight[0::2], out.weight[1::2]]))
        acc["bo"].append(torch.cat([out.bias[0::2], out.bias[1::2] + SCALE_OFFSET])[:, None])
        acc["Winv"].append(linear.inverse_weight() * torch.exp(-actnorm.logs[0]))  # diag(e^-logs) W^-1
        acc["bn"].append(-actnorm.bias[0])  # [63, 1]
    w = {n: torch.stack(v).contiguous() for n, v in acc.items()}
    k = len(model.flow.layers)
    # History/control weights [K, 4H, _cond_columns]: layer 1's bias in the first padding column (the input
    # there is 1), then zeros.
    cond_dim = w["Wc"].shape[2]
    pad = _cond_columns(cond_dim) - cond_dim
    w["Wc"] = torch.cat([w["Wc"], torch.stack(bias[0])[:, :, None], w["Wc"].new_zeros(k, 4 * hid, pad - 1)], dim=2)
    w["Whh"] = [torch.stack(v).contiguous() for v in whh]
    w["Wih"] = [None] + [torch.stack(v).contiguous() for v in wih[1:]]
    w["b"] = [torch.stack(v)[:, :, None].contiguous() for v in bias]  # [K, 4H, 1]
    w.update(K=k, H=hid, c_a=c_a, cond_dim=cond_dim, cond_cols=cond_dim + pad, n_out=w["Wo"].shape[1])
    return w
