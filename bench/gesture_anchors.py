"""The gesture measures against the published implementations, on the same clips: BEAT's BeatAlign (Liu et al.
2022, PantoMatrix/PantoMatrix scripts/BEAT_2022/utils/metric.py) and GENEA 2022's FGD and Hellinger distance
(genea-workshop/genea_numerical_evaluations). Their code is run from the user's own clones, in a Python that has
librosa (BEAT's onsets); nothing of theirs is copied here or into the product.

The clips: a built gesture study's matched test clips and BAD's catch clips (its stimulus folder), with each item's
agent voice from the study's `[audio] folder`.

- BeatAlign: (a) their GAHR on our motion beats and onsets against ours (the formula, both directions); (b) their
  whole pipeline as their trainer runs it (16 kHz audio, librosa's onsets backtracked to the RMS minimum, the right
  wrist's speed minima with argrelextrema, order 2, at 15 fps, sigma 0.3 s) against ours, per clip and per condition.
- FGD: (a) their Fréchet distance (pytorch-fid's) on our features against ours; (b) their embedding network trained
  by their recipe (train_iter: L1 on poses and their differences, Adam 5e-4, betas 0.5, 0.999, batch 64, chunks of
  30 frames every 15, positions only; as many epochs as make our STEPS steps) on the study's reference, each
  condition's FGD against the reference, beside ours (gesture.csv).
- Hellinger: their `hellinger` on our histograms, and their histograms (calc_histogram's velocity, x30 for 30 fps,
  bins of 0.05 from 0 to 49) against ours, for the hands.

    PY -m pip install librosa seaborn   # PY: a scratch environment, outside the checkout
    PY bench/gesture_anchors.py --stimuli DIR --study STUDY.toml --beat CLONE --genea CLONE
"""

import argparse
import csv
import importlib.util
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from generation.metrics import gesture_fgd, gesture_timing, joint_groups, motion_histograms, voice  # noqa: E402
from generation.own_study.speech import read_voices  # noqa: E402
from generation.own_study.study_file import read_study_file  # noqa: E402
from moglow_eval.core import study  # noqa: E402
from moglow_eval.core.clip import load_clip  # noqa: E402
from moglow_eval.core.skeleton_names import side  # noqa: E402
from rendering.audio import RATE  # noqa: E402

SR_BEAT = 16_000  # BEAT's audio rate, as its trainer hands the waveform to load_audio


def load_module(path, name):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read_clips(stimuli):
    """[(clip_id, condition, item, joints, names, parents, fps)] of the matched test clips and BAD's catch clips."""
    with open(stimuli / "manifest.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    out = []
    for r in rows:
        wanted = r["role"] == "test" and not r.get("motion_item") or r["condition"] == study.CATCH
        if wanted and r.get("style", "stick") in ("", "stick"):
            c = load_clip(stimuli / r["motion"])
            names = [str(n) for n in c["joint_names"]]
            out.append((r["clip_id"], r["condition"], r["item"], c["joints"].astype(np.float64), names,
                        np.asarray(c["parents"]), float(c["fps"])))  # fmt: skip
    return out


# ---------------------------------------------------------------- BeatAlign
def beat_pipeline(metric, joints, names, parents, fps, samples, seconds):
    """BEAT's BeatAlign of one clip as their trainer computes it, and with the onset times at the audio's own rate."""
    import librosa
    from scipy.signal import argrelextrema

    wave16 = librosa.resample(samples.astype(np.float32), orig_sr=RATE, target_sr=SR_BEAT)
    align = metric.alignment(0.3, 2)
    _, _, onset_bt_rms = align.load_audio(wave16, 0, int(seconds), without_file=True, sr_audio=SR_BEAT)
    right = [j for j in joint_groups.wrists(names) if side(names[j]) == "right"]
    wrist = right[0] if right else joint_groups.wrists(names)[-1]
    pos15 = joint_groups.about_root(joints, parents)[1::2, wrist]  # their loader keeps every other frame of 30 fps
    vel = np.linalg.norm(np.diff(pos15, axis=0), axis=1)
    beats = argrelextrema(vel, np.less, order=align.order)
    as_run = align.calculate_align(None, None, onset_bt_rms, None, None, beats, None, None, None, 15)
    onset_times = librosa.frames_to_time(onset_bt_rms, sr=SR_BEAT)  # their call leaves sr at librosa's 22050
    fixed = metric.alignment.GAHR(beats[0] / 15, onset_times, 0.3)
    return as_run, fixed, onset_times


def beat_align_part(metric, clips, voices):
    import librosa

    rows, onset_gaps, formula = [], [], []
    for cid, cond, item, joints, names, parents, fps in clips:
        samples = voices[item][: int(len(joints) / fps * RATE)]
        ours = voice.onsets(samples, RATE)
        try:
            beats = gesture_timing.motion_beats(joints, fps, names, parents)
            mine = gesture_timing.beat_align(beats, ours)
        except gesture_timing.Undefined:
            continue
        # (a) their GAHR on identical beats and onsets: over the onsets (their code), and with the roles swapped
        formula.append((metric.alignment.GAHR(beats, ours, 0.3), mine,
                        metric.alignment.GAHR(ours, beats, 0.3)))  # fmt: skip
        as_run, fixed, theirs = beat_pipeline(metric, joints, names, parents, fps, samples, len(joints) / fps)
        if len(theirs) and len(ours):
            onset_gaps.append(np.abs(theirs[:, None] - ours[None]).min(axis=1).mean())
        rows.append((cond, mine, as_run, fixed, len(ours), len(theirs)))
    f = np.array(formula)
    print(f"BeatAlign over {len(rows)} clips (librosa {librosa.__version__})")
    swapped = np.abs(f[:, 2] - f[:, 1]).max()
    print(f"  their GAHR with the roles as the papers write them vs ours: max |diff| {swapped:.2e}")
    print(f"  their GAHR as their code averages (over onsets) vs ours (over beats): mean {f[:, 0].mean():.3f} vs "
          f"{f[:, 1].mean():.3f}, correlation {np.corrcoef(f[:, 0], f[:, 1])[0, 1]:.2f}")  # fmt: skip
    n_ours, n_theirs = np.mean([r[4] for r in rows]), np.mean([r[5] for r in rows])
    print(f"  onsets: ours {n_ours:.1f} a clip, librosa's backtracked {n_theirs:.1f}; theirs "
          f"{np.mean(onset_gaps) * 1000:.0f} ms from our nearest on average")  # fmt: skip
    table = {}
    for cond, mine, as_run, fixed, _, _ in rows:
        table.setdefault(cond, []).append((mine, as_run, fixed))
    print("  per condition: ours | BEAT's pipeline as run | BEAT's with onset times at 16 kHz")
    for cond in study.condition_order(table):
        v = np.array(table[cond])
        print(f"    {cond:<8} {v[:, 0].mean():.3f} | {v[:, 1].mean():.3f} | {v[:, 2].mean():.3f}  ({len(v)} clips)")
    v = np.array([r[1:4] for r in rows])
    print(
        f"  per clip, correlation of ours with BEAT's as run {np.corrcoef(v[:, 0], v[:, 1])[0, 1]:.2f}, "
        f"with the corrected {np.corrcoef(v[:, 0], v[:, 2])[0, 1]:.2f}"
    )


# ---------------------------------------------------------------- FGD and Hellinger
def genea_fgd(genea, clips, reference, parents, steps=gesture_fgd.STEPS, n_frames=30):
    """{condition: FGD} by GENEA's network trained on `reference` (joints) by their recipe, positions about the root,
    for as many epochs as make `steps` of their batches (their 10 epochs are of hours of motion; here a study's
    reference fills a batch or two)."""
    import torch

    sys.path.insert(0, str(genea / "FGD"))
    train_ae = load_module(genea / "FGD" / "train_AE.py", "genea_train_ae")
    evaluator = load_module(genea / "FGD" / "embedding_space_evaluator.py", "genea_evaluator")
    torch.manual_seed(0)
    rows = [joint_groups.about_root(j, parents).reshape(len(j), -1) for j in reference]
    mean, std = np.concatenate(rows).mean(0), np.maximum(np.concatenate(rows).std(0), 1e-2)

    def chunks(js, stride=n_frames // 2):
        out = []
        for j in js:
            r = (joint_groups.about_root(j, parents).reshape(len(j), -1) - mean) / std
            out += [r[i : i + n_frames] for i in range(0, len(r) - n_frames, stride)]
        return torch.tensor(np.array(out), dtype=torch.float32)

    data = chunks(reference)
    net = train_ae.EmbeddingNet(data.shape[2], n_frames)
    opt = torch.optim.Adam(net.parameters(), lr=0.0005, betas=(0.5, 0.999))
    g = torch.Generator().manual_seed(0)
    for _ in range(-(-steps // max(1, len(data) // 64))):
        order = torch.randperm(len(data), generator=g)
        for k in range(0, len(order) - 63, 64):  # their DataLoader: batch 64, shuffled, the last short batch dropped
            train_ae.train_iter(data[order[k : k + 64]], net, opt)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ae.bin"
        torch.save({"pose_dim": data.shape[2], "n_frames": n_frames, "gen_dict": net.state_dict()}, path)
        ev = evaluator.EmbeddingSpaceEvaluator(str(path), n_frames, torch.device("cpu"))
    out = {}
    for cond in study.condition_order({c[1] for c in clips}):
        ev.reset()
        with torch.no_grad():
            ev.push_real_samples(data)
            ev.push_generated_samples(chunks([c[3] for c in clips if c[1] == cond]))
        out[cond] = ev.get_fgd(use_feat_space=True)
    return out, evaluator


def fgd_part(genea, clips, stimuli):
    names, parents, fps = clips[0][4], clips[0][5], clips[0][6]
    ref_clips = [c[3] for c in clips if c[1] == study.NATURAL]
    t0 = time.perf_counter()
    theirs, evaluator = genea_fgd(genea, clips, ref_clips, parents)
    seconds = time.perf_counter() - t0
    # (a) the Fréchet distance itself, on identical features
    enc = gesture_fgd.GestureEncoder.train(ref_clips, parents, fps, seed=0, cache=False)
    ref = np.concatenate([enc.features(j) for j in ref_clips])
    diffs = {}
    for cond in study.condition_order({c[1] for c in clips}):
        mine = np.concatenate([enc.features(c[3]) for c in clips if c[1] == cond])
        ours = gesture_fgd.fgd(mine, ref)
        theirs_f = evaluator.EmbeddingSpaceEvaluator.calculate_frechet_distance(
            mine.mean(0), np.cov(mine, rowvar=False), ref.mean(0), np.cov(ref, rowvar=False)
        )
        diffs[cond] = (ours, theirs_f, len(mine))
    text = ", ".join(f"{c} {a:.6g} and {b:.6g} ({n} chunks)" for c, (a, b, n) in diffs.items())
    print(f"FGD: ours and their Fréchet distance on identical features: {text}")
    with open(stimuli / study.GESTURE_FILE, newline="") as f:
        ours = {r["condition"]: float(r["fgd"]) for r in csv.DictReader(f)}
    print(
        f"  their network trained by their recipe on the reference ({seconds:.0f} s), each condition against the "
        "whole reference; ours (gesture.csv; our reference's row is its split half):"
    )
    for cond, value in theirs.items():
        print(f"    {cond:<8} GENEA {value:10.4g} | ours {ours.get(cond, float('nan')):10.4g}")
    hands = joint_groups.groups(names)["hands"]
    hist = load_module(genea / "hellinger_distance.py", "genea_hellinger")
    calc = load_module(genea / "calc_histogram.py", "genea_histogram")
    bins = np.arange(0, 49 + 0.05, 0.05)

    def theirs_hist(js):
        speeds = np.concatenate([calc.compute_velocity(joint_groups.about_root(j, parents)[:, hands]) for j in js])
        return sum(np.histogram(speeds[:, i], bins=bins)[0] for i in range(speeds.shape[1]))

    def ours_hist(js):
        return sum(motion_histograms.histograms(j, fps, hands, parents)["speed"] for j in js)

    print("Hellinger distance of the hands' speed histogram against the reference: GENEA's bins | ours")
    for cond in study.condition_order({c[1] for c in clips}):
        js = [c[3] for c in clips if c[1] == cond]
        a, b = ours_hist(js), ours_hist(ref_clips)
        same = abs(hist.hellinger(a, b) - motion_histograms.hellinger(a, b))
        print(
            f"    {cond:<8} {hist.hellinger(theirs_hist(js), theirs_hist(ref_clips)):.3f} | "
            f"{motion_histograms.hellinger(a, b):.3f}   (their function on our histograms: |diff| {same:.1e})"
        )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stimuli", type=Path, required=True, help="a built gesture study's stimulus folder")
    ap.add_argument("--study", type=Path, required=True, help="its study file (the agent's voices)")
    ap.add_argument("--beat", type=Path, required=True, help="a clone of PantoMatrix/PantoMatrix")
    ap.add_argument("--genea", type=Path, required=True, help="a clone of genea-workshop/genea_numerical_evaluations")
    args = ap.parse_args()
    clips = read_clips(args.stimuli)
    spec = read_study_file(args.study)
    spec.fps = clips[0][6]
    lengths = {c[2]: len(c[3]) for c in clips}
    agent, _ = read_voices(spec, lengths)
    print(f"load average {os.getloadavg()[0]:.2f}; {len(clips)} clips of {args.stimuli}")
    metric = load_module(args.beat / "scripts" / "BEAT_2022" / "utils" / "metric.py", "beat_metric")
    beat_align_part(metric, clips, agent)
    fgd_part(args.genea, clips, args.stimuli)


if __name__ == "__main__":
    main()
