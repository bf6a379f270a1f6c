"""The data and checkpoints a built-in stimulus job samples (make_stimuli): the prepared dataset (made from the
mocap when missing), each model's checkpoint (given, shipped, or trained into runs/) and the precision MG samples
in. torch is imported only inside the functions that train or sample: make_stimuli imports this module and stays
torch-free until then (docs/ARCHITECTURE.md, "Lazy imports that must stay")."""

import logging
import re
from pathlib import Path

from ..sampling import pretrained
from .files import StimuliError

log = logging.getLogger(__name__)


def ensure_dataset(args):
    """The prepared dataset path: --dataset if it exists, else prepared there from --data."""
    from ..data.prepare import default_data_dir, longest_takes, prepare, summary_table

    path = Path(args.dataset)
    if path.is_file():
        log.info(f"data: using the prepared dataset {path}")
        return path
    data = Path(args.data) if args.data else default_data_dir()
    if data is None or not data.is_dir():
        raise StimuliError(
            f"data folder {args.data or '../shared/data/bandai-namco-locomotion'} not found; "
            "pass --data DIR (a folder of .bvh/.bvh.gz takes) or --dataset FILE.npz"
        )
    log.info(f"data: preparing {data} -> {path}" + (" (quick subset)" if args.quick else ""))
    takes = longest_takes(data, per_category=10) if args.quick else None
    summary = prepare(data, path, takes=takes, seed=args.seed, progress=args.progress)
    log.info(summary_table(summary))
    return path


def checkpoints_in(folder):
    """Checkpoint files step_*.pt of a run folder (or its checkpoints/ subfolder), by step."""
    folder = Path(folder)
    if (folder / "checkpoints").is_dir():
        folder = folder / "checkpoints"
    files = [p for p in folder.glob("step_*.pt") if re.fullmatch(r"step_\d+\.pt", p.name)]
    return sorted(files, key=lambda p: int(p.stem.split("_")[1]))


def ensure_model(kind, args, dataset):
    """(final, earliest) checkpoint of `kind`: from --{kind}-checkpoint, else trained into runs/."""
    from ..training.train import finished, train  # torch: only when a model is trained

    given = getattr(args, f"{kind}_checkpoint")
    if given:
        path = Path(given)
        if not path.is_file():
            raise StimuliError(f"--{kind}-checkpoint {path}: no such file")
        siblings = checkpoints_in(path.parent)
        return path, siblings[0] if siblings else path
    if args.shipped:
        return pretrained.CHECKPOINTS[kind], pretrained.CHECKPOINTS["bad"]
    run = Path(args.runs) / f"{kind}_{args.config}"
    resume = (run / "resume.pt").is_file()
    if finished(kind, args.config, run, args.train_steps, args.precision):  # its resume state and last checkpoint
        log.info(f"models: reusing {kind} (config {args.config}) in {run}, trained to its last step")
        ckpts = checkpoints_in(run)
        return ckpts[-1], ckpts[0]
    log.info(f"models: {'resuming' if resume else 'training'} {kind} (config {args.config}) in {run}")
    train(
        kind,
        args.config,
        dataset,
        run,
        steps=args.train_steps,
        seed=args.seed,
        progress=args.progress,
        resume=resume,
        device=args.device,
        threads=args.threads or "auto",
        precision=args.precision,
    )
    ckpts = checkpoints_in(run)
    if not ckpts:
        raise StimuliError(f"{run}: training wrote no checkpoint")
    return ckpts[-1], ckpts[0]


def sampler_precision(args):
    """MG's sampler's precision: --sample-precision, else picked once per CPU (generation.sampling.precision)."""
    from ..training.devices import pick_device  # torch: only when the job samples

    chosen = pretrained.sampler_precision(str(pick_device(args.device)), args.sample_precision)
    log.info(f"models: MG samples in {chosen}")
    return chosen
