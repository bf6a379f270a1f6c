"""MGStream: MoGlow's sampler, the flow of generation.models.moglow inverted one frame at a time with fused weights.

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
    steps at once, one batched matmul per layer: layer 1's recurrent and history/control products side by side
    (weights [Whh | Wc | bias | 0] on the input [h_{t-1}; history, control; 1; 0]), layer 2's recurrent product
    with its bias the same way ([Whh | bias | 0] on [h_{t-1}; 1; 0]), inputs padded to a multiple of 16 columns
    (one 1184-deep product runs ~7% faster at 30 streams on an Intel Xeon than two of 512 and 672, and within 3%
    either way on an AMD EPYC); (2) per step only what depends on the previous step's output is left: layer 1's
    lower-half product, layer 2's 2048x512 input product, the cells, the output layer, the coupling and the 63x63
    inverse, all in place on preallocated buffers through views made once (the flow's value alternates between
    two buffers); (3) weights are fused once (actnorm folded into the inverse linear map, the coupling's
    SCALE_OFFSET into the output bias, shift/scale rows contiguous, gates reordered to i, f, o, g so one sigmoid
    covers three); (4) no autograd. Starts with h = 0 (paper footnote 2).

    precision="bfloat16" reads the big products' weights (the LSTMs' recurrent, history/control and layer-2 input
    weights, 98% of the bytes, with the LSTM biases that ride in them) and their inputs in bfloat16; the products
    still add up in float32, and the gates, cells, states, output layers and inverse maps stay float32. On some CPU
    kinds that runs many streams faster, on others slower, and one stream gains nothing anywhere
    (bench/RESULTS.md#sampling-bfloat16). It is the same model to within bfloat16's rounding of those weights
    (RESULTS has its motion figures). The default is float32.

    Two memory layouts compute the same thing (they differ only in float rounding):
    "row": activations [B, features], weights stored [in, out], every product X @ W;
    "col": activations [features, B], weights stored [out, in] as nn.LSTM keeps them, every product W @ X.
    Which is faster depends on the CPU and its BLAS, by a wide margin either way (bench/notes/2026-11-25-history.md), so
    layout=None takes `default_layout`, a fixed choice per device type, CPU vendor and batch size (never a timing,
    so the same inputs give the same bits run after run); pass a layout to fix it.
    """

    def __init__(
        self,
        model,
        history,
        history_control,
        temperature=1.0,
        generator=None,
        layout=None,
        precision="float32",
        style=None,
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
        self._fdim = fd = 1 if rows else 0  # the feature dimension of activations
        # The inputs of each layer's batched product, for all K steps: [h; history, control; 1; 0] for layer 1,
        # [h; 1; 0] for the others (the 1 meets the layer's bias; the zeros pad to a multiple of 16). h and c of
        # every layer: step k overwrites its own slice after the frame's batched products have read last frame's
        # values.
        cond_dim = w["cond_dim"]
        self._x = [torch.zeros(k_steps, *shape(n), **new) for n in w["in_cols"]]
        for x, extra in zip(self._x, [cond_dim] + [0] * (layers - 1)):
            x.narrow(fd + 1, hid + extra, 1).fill_(1.0)
        self.h = [x.narrow(fd + 1, 0, hid) for x in self._x]
        self._x1_cond = self._x[0].narrow(fd + 1, hid, cond_dim)  # refilled every frame from self.cond
        self.c = [torch.zeros(k_steps, *shape(hid), **new) for _ in range(layers)]
        self.gates = [torch.empty(k_steps, *shape(4 * hid), **new) for _ in range(layers)]
        self.out = torch.empty(*shape(w["n_out"]), **new)
        self.cond = torch.zeros(b, cond_dim, **new)  # this frame's history and control, flattened
        if model.config["history_style"]:  # the seed history's mean pose: the same for every frame
            # `style` [B, 63] (standardised) replaces it, e.g. the mean of a longer real seed than tau frames
            self.cond[:, cond_dim - model.pose_dim :] = model.style_of(self.hist) if style is None else style
        # (weight, x) -> the operands of torch.mm/addmm for "W x": (x, W) in rows, (W, x) in columns.
        self._mm = (lambda wt, x: (x, wt)) if rows else (lambda wt, x: (wt, x))
        # self.cond as every step's slice of layer 1's input (a view: refilled in place).
        self._cond_k = self.cond.expand(k_steps, b, -1) if rows else self.cond.T.expand(k_steps, -1, b)
        # Per-step views made once: making the same narrow views at every step of every frame costs more than it looks.
        # y, the flow's running value, alternates between two buffers: step k reads one and writes the other.
        self._y = [torch.empty(*shape(model.pose_dim), **new) for _ in range(2)]
        c_a, n_b = w["c_a"], w["n_out"] // 2
        halves = [(y.narrow(fd, 0, c_a), y.narrow(fd, c_a, y.shape[fd] - c_a)) for y in self._y]
        self._out_shift, self._out_scale = self.out.narrow(fd, 0, n_b), self.out.narrow(fd, n_b, n_b)
        self._steps = []
        for i, k in enumerate(reversed(range(k_steps))):  # sampling runs the flow's steps last to first
            cells = [
                _cell_views(self.gates[layer][k], self.c[layer][k], self.h[layer][k], fd, hid)
                for layer in range(layers)
            ]
            y_in, y_out = self._y[i % 2], self._y[1 - i % 2]
            wih = [w["Wih"][layer][k] if layer else None for layer in range(layers)]
            self._steps.append(
                (w["Wx"][k], wih, w["Wo"][k], w["bo"][k], w["Winv"][k], w["bn"][k], cells, y_in, *halves[i % 2], y_out)
            )
        self._y_first, self._y_last = self._y[0], self._y[k_steps % 2]

    @torch.no_grad()
    def step(self, control, z=None):
        with torch.inference_mode(self._inference):
            return self._step(control, z)

    def _frame_start(self):
        """Gate pre-activations from this frame's shared inputs and last frame's states, all K steps at once."""
        w, mm, low = self.w, self._mm, self.low
        self._x1_cond.copy_(self._cond_k)
        for wt, x, gates in zip(w["Whh"], self._x, self.gates):
            if low is None:
                torch.bmm(*mm(wt, x), out=gates)
            else:
                gates.copy_(torch.bmm(*mm(wt, x.to(low))))

    def _add_product(self, gates, wt, x):
        """gates += the product of wt and x (in bfloat16 with `precision`, the sum in float32)."""
        if self.low is None:
            return gates.addmm_(*self._mm(wt, x))
        return gates.add_(torch.mm(*self._mm(wt, x.to(self.low))))

    def _step(self, control, z):
        b, mm, fd = self.hist.shape[0], self._mm, self._fdim
        ctrl = torch.cat([self.hist_c, control.to(self.device, self.dtype)[:, None]], dim=1)
        n_hist, n_ctrl = self.hist[0].numel(), ctrl[0].numel()
        self.cond[:, :n_hist] = self.hist.flatten(1)
        self.cond[:, n_hist : n_hist + n_ctrl] = ctrl.flatten(1)
        self._frame_start()
        if z is None:
            z = (
                torch.randn(b, self.model.pose_dim, generator=self.generator, dtype=self.dtype, device="cpu").to(
                    self.device
                )
                * self.temperature
            )
        self._y_first.copy_(z if fd else z.T)
        out, shift, scale = self.out, self._out_shift, self._out_scale
        for wx, wih, wo, bo, winv, bn, cells, y, y_a, y_b, y_next in self._steps:
            gates, s, g, i, f, o, c, h = cells[0]
            gates.addmm_(*mm(wx, y_a))
            _cell(s, g, i, f, o, c, h)
            for layer in range(1, len(cells)):
                gates, s, g, i, f, o, c, h_next = cells[layer]
                self._add_product(gates, wih[layer], h)
                _cell(s, g, i, f, o, c, h_next)
                h = h_next
            torch.addmm(bo, *mm(wo, h), out=out)
            # The coupling inverted in place: y_b <- y_b / sigmoid(scale) - shift (y_a passes through).
            y_b.div_(scale.sigmoid_()).sub_(shift)
            # Inverse LU linear map with the inverse actnorm folded in: x = diag(e^-logs) W^-1 y - bias.
            torch.addmm(bn, *mm(winv, y), out=y_next)
        # A copy, never a view of the buffer (with one stream, .T.contiguous() would return the view itself).
        y = (self._y_last if fd else self._y_last.T).clone(memory_format=torch.contiguous_format)
        if self.model.config["residual"]:
            y = y + self.model.step_base(self.hist[:, -1], ctrl[:, -1])
        self.hist = torch.cat([self.hist[:, 1:], y[:, None]], dim=1)
        self.hist_c = ctrl[:, 1:]
        return y


LAYOUTS = ("row", "col")
LOW_PRECISION = ("Whh", "Wih")  # the weights that `precision` stores in bfloat16 (98% of the bytes)
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

    Measured at the paper's size (bench/notes/2026-11-25-history.md): on AMD Zen 3 with MKL "row" is faster for 1
    and 30 streams; on this project's Intel Xeon host "row" is faster for one stream and "col" for 30. cuBLAS takes
    either: "row"."""
    chosen = os.environ.get("MOGLOW_LAYOUT")
    if chosen:
        if chosen not in LAYOUTS:
            raise ValueError(f"MOGLOW_LAYOUT must be one of {LAYOUTS}, got {chosen!r}")
        return chosen
    if torch.device(device).type != "cpu" or cpu_vendor() == "AuthenticAMD" or batch < BATCHED:
        return "row"
    return "col"


def _cell_views(gates, c, h, dim, hid):
    """The views the LSTM cell works on, gates in the order i, f, o, g along `dim`: (gates, the three sigmoid
    gates, g, i, f, o, c, h)."""
    s = gates.narrow(dim, 0, 3 * hid)
    return gates, s, gates.narrow(dim, 3 * hid, hid), *(s.narrow(dim, j * hid, hid) for j in range(3)), c, h


def _cell(s, g, i, f, o, c, h):
    """LSTM cell in place on views from _cell_views: the gates overwritten, c updated, h written."""
    s.sigmoid_()
    g.tanh_()
    c.mul_(f).addcmul_(i, g)
    torch.tanh(c, out=h).mul_(o)


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
            w = {n: _map_tensors(x, lambda v: v.mT.contiguous()) for n, x in w.items()}
        for n in LOW_PRECISION if low is not None else ():
            w[n] = _map_tensors(w[n], lambda v: v.to(low))
        cached = model._fused = (key, w)
    return cached[1]


def _map_tensors(x, fn):
    """fn applied to a tensor, or to each tensor of a list; anything else as it is."""
    if isinstance(x, list):
        return [_map_tensors(v, fn) for v in x]
    return fn(x) if torch.is_tensor(x) else x


def _padded(n):
    """n rounded up to a multiple of 16: the width of the batched products' inputs (measured ~7% faster than
    an odd width such as 663)."""
    return n + -n % 16


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
    # The batched weights of every layer [K, 4H, in_cols]: recurrent, history/control for layer 1, the bias (met by
    # an input of 1), then zeros up to a multiple of 16.
    wc = w.pop("Wc")
    cond_dim = wc.shape[2]
    w["Whh"], in_cols = [], []
    for layer in range(layers):
        parts = [torch.stack(whh[layer])] + ([wc] if layer == 0 else []) + [torch.stack(bias[layer])[:, :, None]]
        n = sum(part.shape[2] for part in parts)
        in_cols.append(_padded(n))
        w["Whh"].append(torch.cat(parts + [wc.new_zeros(k, 4 * hid, in_cols[-1] - n)], dim=2))
    w["Wih"] = [None] + [torch.stack(v).contiguous() for v in wih[1:]]
    w.update(K=k, H=hid, c_a=c_a, cond_dim=cond_dim, in_cols=in_cols, n_out=w["Wo"].shape[1])
    return w
