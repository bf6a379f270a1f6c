"""Where training runs: the device, the ranks of torch.distributed, and the coupling networks' arithmetic there."""

import os
import sys

import torch

from ..models import flows, moglow


def pick_device(device=None):
    """`device`, or CUDA when present, else the CPU; under torchrun a bare 'cuda' is the rank's own GPU."""
    device = torch.device(device) if device else torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device.type == "cuda" and device.index is None:
        return torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))
    return device


def join_ranks(device):
    """(rank, world size): (0, 1) alone; under torchrun, after joining the process group: nccl where the ranks
    train on CUDA, gloo on the CPU (also on a machine that has a GPU, when --device cpu asks for it)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world == 1:
        return 0, 1
    if not torch.distributed.is_initialized():
        torch.distributed.init_process_group("nccl" if device.type == "cuda" else "gloo")
    return torch.distributed.get_rank(), world


def set_precision(net, precision, device, says):
    """The coupling networks' arithmetic; where torch has no LSTM in that precision, MG's LSTMs keep float32
    (moglow.LSTMNet), and the first rank says so."""
    low = flows.PRECISIONS[precision]
    flows.set_net_precision(net, low)
    if says and low is not None and net.kind == "mg" and not moglow.lstm_runs_in(device.type, low):
        print(f"note: torch has no {precision} LSTM on this {device.type}: MG's LSTMs run in float32", file=sys.stderr)


def finite_on_every_rank(loss, world):
    """Whether the loss is finite on every rank (a rank that skipped its step alone would hang the others)."""
    finite = torch.isfinite(loss.detach()).to(torch.int32)
    if world > 1:
        torch.distributed.all_reduce(finite, op=torch.distributed.ReduceOp.MIN)
    return bool(finite)
