"""make_stimuli: the stimulus folder of one real --quick run (CONTRACTS.md §4), system import, bad input."""

import csv
import os
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
from helpers.cli import fails_with
from helpers.paths import DATA, ROOT, TEST_DATA

from generation import make_stimuli
from generation.motion.features import root_trajectory
from generation.stimuli import files, render_pool
from moglow_eval.core.clip import load_clip

CONDITION_NAMES = ("nat", "mg", "fl", "bad")


def read_csv(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def decode(path):
    """(frames decoded, width, height, pix_fmt, codec, audio?) by decoding the whole video with ffmpeg."""
    import imageio_ffmpeg

    r = subprocess.run(
        [
            imageio_ffmpeg.get_ffmpeg_exe(),
            "-hide_banner",
            "-nostats",
            "-i",
            str(path),
            "-map",
            "0:v:0",
            "-f",
            "framemd5",
            "-",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    frames = sum(1 for line in r.stdout.splitlines() if line and not line.startswith("#"))
    v = re.search(r"Video: (\w+).*?, (\w+)\(.*?\), (\d+)x(\d+)", r.stderr)
    return frames, int(v.group(3)), int(v.group(4)), v.group(2), v.group(1), "Audio:" in r.stderr


@pytest.fixture(scope="module")
def manifest(quick_stimuli):
    return read_csv(quick_stimuli / "manifest.csv")


def test_stimuli_quick_run_counts_and_columns(manifest, quick_stimuli):
    assert list(manifest[0]) >= ["clip_id", "condition", "role", "item", "video", "motion", "seed", "frames", "fps"]
    count = {}
    for m in manifest:
        count[m["role"], m["condition"]] = count.get((m["role"], m["condition"]), 0) + 1
    assert count["test", "NAT"] == count["test", "MG"] == count["test", "FL"] == 30
    assert not (quick_stimuli / files.BUILDING).exists()  # a finished set carries no mark of a build under way
    assert count["catch", "BAD"] == count["catch", "NAT"] == 4  # NAT: the reference of pairwise/parallel catches
    assert sum(v for (r, _), v in count.items() if r == "catch") == 16  # BAD, and NAT, MG, FL of each catch item
    training = {c for (r, c) in count if r == "training"}
    assert training >= {"NAT", "MG", "FL"} and sum(v for (r, _), v in count.items() if r == "training") >= 3
    ids = [m["clip_id"] for m in manifest]
    assert len(set(ids)) == len(ids) and all(re.fullmatch(r"[a-z0-9]{12,}", i) for i in ids)
    for m in manifest:
        assert (quick_stimuli / m["video"]).is_file() and (quick_stimuli / m["motion"]).is_file()
        assert (m["seed"] == "") == (m["condition"] == "NAT")
        assert (quick_stimuli / "sheets" / f"{m['clip_id']}.png").is_file()


def test_stimuli_every_video_decodes_as_stated(manifest, quick_stimuli):
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as pool:  # ffmpeg processes; threads just wait on them
        decoded = list(pool.map(lambda m: decode(quick_stimuli / m["video"]), manifest))
    for m, (frames, w, h, pix_fmt, codec, audio) in zip(manifest, decoded):
        assert (frames, w, h) == (int(m["frames"]), int(m["width"]), int(m["height"])), m["clip_id"]
        assert (pix_fmt, codec, audio) == ("yuv420p", "h264", False)
        data = (quick_stimuli / m["video"]).read_bytes()
        assert data.find(b"moov") < data.find(b"mdat")  # +faststart
    assert {int(m["frames"]) for m in manifest} == {80} and {m["fps"] for m in manifest} == {"20"}


def test_stimuli_conditions_share_items(manifest):
    items = {}
    for m in manifest:
        items.setdefault((m["role"], m["condition"]), set()).add(m["item"])
    assert items["test", "NAT"] == items["test", "MG"] == items["test", "FL"]
    assert len(items["test", "NAT"]) == 30
    assert items["training", "NAT"] == items["training", "MG"] == items["training", "FL"]
    assert not items["catch", "BAD"] & items["test", "NAT"]
    assert not items["training", "NAT"] & items["test", "NAT"]


def test_stimuli_no_name_reveals_the_condition(manifest, quick_stimuli):
    names = [p.name for sub in ("videos", "motion", "sheets") for p in (quick_stimuli / sub).iterdir()]
    assert len(names) == 3 * len(manifest)
    for name in names + [m["clip_id"] for m in manifest]:
        assert not any(c in name.lower() for c in CONDITION_NAMES), name
    assert {p.stem for p in (quick_stimuli / "videos").iterdir()} == {m["clip_id"] for m in manifest}
    # Clip files carry no condition either, and every clip starts at the origin facing +Z.
    for m in manifest[:12]:
        clip = load_clip(quick_stimuli / m["motion"])
        assert clip["joints"].shape == (80, 21, 3) and clip["control"].shape == (80, 3)
        assert not {"condition", "role"} & set(clip)
        root, yaw = root_trajectory(clip["joints"], 20.0)
        assert np.allclose(root[0], 0, atol=1e-4) and abs(yaw[0]) < 1e-4


def _condition_runs(conditions):
    """How many runs of equal neighbours a sequence has: 4 when grouped by condition, ~2/3 of its length at random."""
    return 1 + sum(a != b for a, b in zip(conditions, conditions[1:]))


def test_stimuli_files_tell_nothing_outside_their_pixels(manifest, quick_stimuli):
    """A bot that sorts clips by byte size, time stamp or creation order learns nothing (issue 11, finding 1)."""
    videos = [quick_stimuli / m["video"] for m in manifest]
    files = (
        videos
        + [quick_stimuli / m["motion"] for m in manifest]
        + [quick_stimuli / "sheets" / f"{m['clip_id']}.png" for m in manifest]
    )
    assert len({v.stat().st_size for v in videos}) == 1  # one size by construction (tests/rendering/test_blinding.py)
    assert len({f.stat().st_mtime_ns for f in files}) == 1  # one time stamp
    conditions = [m["condition"] for m in manifest]
    # Files were written in a random order: by creation (inode change) time the conditions are mixed.
    by_creation = sorted(manifest, key=lambda m: (quick_stimuli / m["motion"]).stat().st_ctime_ns)
    assert _condition_runs([m["condition"] for m in by_creation]) > len(manifest) / 3
    assert _condition_runs(conditions) > len(manifest) / 3  # and so are the manifest's rows


def test_stimuli_metrics_plausible_and_bad_clips_worse(manifest, quick_stimuli):
    rows = read_csv(quick_stimuli / "metrics.csv")
    # The catch kinds alternate (--catch-kinds mg-early,freeze): the early MG samples (a numeric seed) jitter and
    # stretch, the freezes slide a still body along (issue 37: a mix keeps their coded size among the test clips').
    kind = {m["clip_id"]: ("freeze" if m["seed"] == "freeze" else "BAD") for m in manifest if m["condition"] == "BAD"}
    assert sorted(kind.values()) == ["BAD", "BAD", "freeze", "freeze"]
    for r in rows:
        r["condition"] = kind.get(r["clip_id"], r["condition"])
    assert list(rows[0]) == [
        "clip_id",
        "condition",
        "role",
        "item",
        "foot_skating",
        "bone_length_std",
        "jerk",
        "control_error",
        "control_following",
        "acceleration",
    ]
    assert sorted(r["clip_id"] for r in rows) == sorted(m["clip_id"] for m in manifest)
    assert all(np.isfinite(float(r[k])) for r in rows for k in list(r)[4:])  # every metric defined
    val = lambda cond, key: np.array([float(r[key]) for r in rows if r["condition"] == cond])  # noqa: E731
    nat_skate = val("NAT", "foot_skating")
    assert np.isfinite(nat_skate).all() and np.median(nat_skate) < 0.1  # planted feet barely slide
    assert val("NAT", "bone_length_std").max() < 1e-3
    assert val("NAT", "control_error").max() < 0.01
    assert np.median(val("NAT", "control_following")) < 0.05  # real feet carry the body along its control
    assert np.median(val("BAD", "control_following")) > 2 * np.median(val("NAT", "control_following"))
    fmd = {r["condition"]: float(r["fmd"]) for r in read_csv(quick_stimuli / "fmd.csv")}
    assert set(fmd) == {"NAT", "MG", "FL"} and fmd["MG"] > fmd["NAT"] and fmd["FL"] > fmd["NAT"]  # NAT: the floor
    assert np.median(val("BAD", "jerk")) > 5 * np.median(val("NAT", "jerk"))
    assert val("BAD", "bone_length_std").min() > 10 * val("NAT", "bone_length_std").max()
    assert val("freeze", "foot_skating").min() > 3 * np.median(nat_skate)  # a frozen walker slides over the floor
    assert val("freeze", "jerk").max() < np.median(val("NAT", "jerk"))  # ... and stands still
    items = read_csv(quick_stimuli / "items.csv")
    assert {r["item"] for r in items} == {m["item"] for m in manifest if m["role"] != "catch"}


def _walk_takes(n):
    rows = [
        r
        for r in read_csv(DATA / "MANIFEST.csv")
        if r["locomotion"] == "walk" and float(r["seconds"]) > 5 and r["path"].startswith("bandai")
    ]
    return [DATA / r["path"] for r in rows[:n]]


def test_stimuli_import_bvh_folder_adds_a_condition(quick_stimuli, tmp_path, capsys):
    runs = quick_stimuli.parent / "runs"
    common = [
        "--quick",
        "--runs",
        str(runs),
        "--n-items",
        "4",
        "--n-catch",
        "1",
        "--n-training",
        "1",
        "--size",
        "96",
        "--workers",
        "1",
    ]
    assert make_stimuli.main(common + ["--export-items", str(tmp_path / "ask")]) == 0
    items = read_csv(tmp_path / "ask" / "items.csv")
    assert [r["role"] for r in items] == ["test"] * 4 + ["training"]
    ctrl = np.load(tmp_path / "ask" / items[0]["control"])
    assert ctrl["control"].shape == (80, 3) and ctrl["history"].shape == (10, 63)
    # "Another system": real walks, one BVH file per item, named by the item id.
    sysdir = tmp_path / "mocap"
    sysdir.mkdir()
    for row, take in zip(items, _walk_takes(len(items))):
        shutil.copy(take, sysdir / f"{row['item']}.bvh.gz")
    (sysdir / "notes.txt").write_text("ignored")
    mg = sorted((runs / "mg_tiny" / "checkpoints").glob("step_*.pt"))[-1]
    fl = sorted((runs / "fl_tiny" / "checkpoints").glob("step_*.pt"))[-1]
    out = tmp_path / "stimuli"
    capsys.readouterr()
    code = make_stimuli.main(
        [
            *common,
            "--out",
            str(out),
            "--mg-checkpoint",
            str(mg),
            "--fl-checkpoint",
            str(fl),
            "--system",
            f"MOCAP={sysdir}",
        ]
    )
    printed = capsys.readouterr()
    assert code == 0, printed.err[-2000:]
    man = read_csv(out / "manifest.csv")
    by = {}
    for m in man:
        by.setdefault((m["role"], m["condition"]), set()).add(m["item"])
    assert by["test", "MOCAP"] == by["test", "NAT"] == {i["item"] for i in items if i["role"] == "test"}
    assert by["training", "MOCAP"] == {items[-1]["item"]}
    assert not any("mocap" in m["clip_id"] or "mocap" in m["video"].lower() for m in man)
    for m in man:
        if m["condition"] == "MOCAP":
            assert decode(out / m["video"])[:3] == (80, 96, 96)
    metrics = [x for x in read_csv(out / "metrics.csv") if x["condition"] == "MOCAP"]
    assert len(metrics) == 5 and all(float(x["foot_skating"]) < 0.15 for x in metrics)  # real walks
    assert "MOCAP" in printed.out  # in the summary


def _error(argv, capsys):
    code = make_stimuli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    return code, err[-1] if err else ""


def test_stimuli_bad_input_one_line_errors(quick_stimuli, tmp_path, capsys):
    runs = quick_stimuli.parent / "runs"
    base = ["--quick", "--runs", str(runs), "--n-items", "4", "--n-catch", "1", "--out", str(tmp_path / "o")]
    code, err = _error(base + ["--system", "NOEQUALS"], capsys)
    assert code == 2 and err.startswith("error: ") and "NAME=DIR" in err
    code, err = _error(base + ["--system", f"X={tmp_path / 'missing'}"], capsys)
    assert code == 2 and "does not exist" in err
    code, err = _error(base + ["--system", f"mg={tmp_path}"], capsys)
    assert code == 2 and "built-in" in err
    code, err = _error(base + ["--data", str(tmp_path / "nodata"), "--dataset", str(tmp_path / "none.npz")], capsys)
    assert code == 2 and "nodata" in err
    code, err = _error(base + ["--precision", "half"], capsys)  # passed to training, which names it
    assert code == 2 and err.startswith("error: --precision") and "bfloat16" in err
    # A system folder that lacks items, then one whose BVH is broken.
    sysdir = tmp_path / "sys"
    sysdir.mkdir()
    code, err = _error(base + ["--system", f"S={sysdir}"], capsys)
    assert code == 2 and "no motion file for any of the" in err
    make_stimuli.main(base[:-2] + ["--export-items", str(tmp_path / "ask")])
    items = [r["item"] for r in read_csv(tmp_path / "ask" / "items.csv")]
    good = TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz"
    for it in items[1:]:
        shutil.copy(good, sysdir / f"{it}.bvh.gz")
    (sysdir / f"{items[0]}.bvh").write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 zero\n")
    capsys.readouterr()
    code, err = _error(base + ["--system", f"S={sysdir}"], capsys)
    assert code == 2 and err.startswith("error: ") and f"{items[0]}.bvh" in err
    # An existing stimulus set is not overwritten without --force.
    code, err = _error(["--quick", "--runs", str(runs), "--out", str(quick_stimuli)], capsys)
    assert code == 2 and "--force" in err


def _hostile_bvh(text, how):
    """A real take, broken the way an attacker or a careless exporter would break it."""
    lines = text.split("\n")
    at = next(i for i, line in enumerate(lines) if line.startswith("Frame Time"))
    if how.startswith("frame_time="):
        lines[at] = f"Frame Time: {how.split('=')[1]}"
    elif how == "huge_position":
        lines[at + 1] = "1e308 " + lines[at + 1].split(" ", 1)[1]
    elif how == "renamed_joint":
        return text.replace("Hand_R", "HandR", 1).encode()
    elif how == "non_utf8_name":
        return text.encode().replace(b"Hand_R", b"Hand\xff_R", 1)
    return "\n".join(lines).encode()


@pytest.mark.parametrize(
    "how, says",
    [
        ("frame_time=1e-9", "Frame Time must be between"),  # once tried to allocate 15 GB
        ("frame_time=1e308", "out of range"),  # once a ZeroDivisionError
        ("frame_time=inf", "out of range"),
        ("huge_position", "out of range"),  # once exit 0 with infinite joints
        ("renamed_joint", "has no joint 'Hand_R'"),  # once a KeyError
        ("non_utf8_name", "has no joint 'Hand_R'"),
    ],
)
def test_stimuli_hostile_system_file_one_line(quick_stimuli, tmp_path, capsys, how, says):
    runs = quick_stimuli.parent / "runs"
    base = ["--quick", "--runs", str(runs), "--n-items", "2", "--n-catch", "1", "--n-training", "0"]
    assert make_stimuli.main(base + ["--export-items", str(tmp_path / "ask")]) == 0
    items = [r["item"] for r in read_csv(tmp_path / "ask" / "items.csv")]
    sysdir = tmp_path / "sys"
    sysdir.mkdir()
    take = TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz"
    import gzip

    text = gzip.decompress(take.read_bytes()).decode()
    for it in items[1:]:
        shutil.copy(take, sysdir / f"{it}.bvh.gz")
    (sysdir / f"{items[0]}.bvh").write_bytes(_hostile_bvh(text, how))
    capsys.readouterr()
    code = make_stimuli.main(base + ["--out", str(tmp_path / "o"), "--system", f"S={sysdir}"])
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert code == 2 and "Traceback" not in err and last.startswith("error: ") and says in last, err[-500:]
    assert f"{items[0]}.bvh" in last


@pytest.mark.parametrize("module", ["generation.stimuli.render_pool", "generation.make_stimuli"])
def test_render_workers_load_no_torch(module):
    """make_stimuli's render workers start from a process that imports generation.stimuli.render_pool (the fork
    server, or each spawned worker): that import must not load torch (seconds and hundreds of MB per worker); nor
    must make_stimuli's own (--help, --export-items).
    Sampling and training import it where they run."""
    r = subprocess.run(
        [sys.executable, "-c", f"import sys, {module}; print('torch' in sys.modules)"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0 and r.stdout.strip() == "False", r.stderr[-500:]


def test_render_workers_are_forked_from_the_fork_server():
    """The workers come from multiprocessing's fork server, which has rendering loaded, instead of each being a
    fresh interpreter that imports it (about 0.6 s of CPU a worker): a worker's parent is the server, not the
    process that builds, and a second pool's workers come from the same server."""
    from concurrent.futures import ProcessPoolExecutor

    parents = []
    for _ in range(2):
        with ProcessPoolExecutor(1, mp_context=render_pool._workers_context()) as pool:
            parents.append(pool.submit(os.getppid).result())
    assert parents[0] != os.getpid() and parents[0] == parents[1]


def test_render_workers_do_not_run_the_commands_main_module_again(tmp_path):
    """A command run as `python -m` hands render_all two jobs on two workers: the module's own lines run once, in
    the command, not again in each worker, and both videos are made."""
    (tmp_path / "probe_main.py").write_text(
        "import os, sys\n"
        "import numpy as np\n"
        "with open('imported.txt', 'a') as f:\n"
        "    f.write(f'{os.getpid()}\\n')\n"
        "from generation.motion import skeleton\n"
        "from generation.stimuli.render_pool import render_all\n"
        "from moglow_eval.core.clip import save_clip\n"
        "if __name__ == '__main__':\n"
        "    joints = np.random.default_rng(0).normal(0, 0.3, (6, len(skeleton.PARENTS), 3)) + [0, 1, 0]\n"
        "    save_clip('c.npz', joints, skeleton.PARENTS, skeleton.JOINT_NAMES, 20.0)\n"
        "    render_all([('c.npz', f'{k}.mp4', None, 32, 'ultrafast') for k in range(2)], 2, progress=False)\n"
        "    assert sys.modules['__main__'].__file__.endswith('probe_main.py')  # given back after the start\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, "-m", "probe_main"], capture_output=True, text=True, cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr[-1500:]
    assert len((tmp_path / "imported.txt").read_text().split()) == 1
    assert (tmp_path / "0.mp4").stat().st_size > 0 and (tmp_path / "1.mp4").stat().st_size > 0


def test_a_condition_under_natural_motions_fmd_is_named_and_explained():
    """Issue 46: MG's FMD (126) under NAT's (139) was printed without a word on what that means."""
    from generation.stimuli.summary import below_floor

    rows = [dict(condition="NAT", fmd="139"), dict(condition="MG", fmd="126"), dict(condition="FL", fmd="160")]
    assert below_floor(rows) == ["MG"]
    assert below_floor(rows[:1] + rows[2:]) == [] and below_floor(rows[1:]) == []  # no NAT: no floor to be under


def _fails(capsys, *args):
    """make_stimuli's main in-process (a process each cost a few seconds; the command's own process:
    tests/project/test_console.py), which must stop with one line and exit 2; that line."""
    return fails_with(make_stimuli.main, ["--quiet", *map(str, args)], capsys, "error: ")


def _tree(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_a_failed_build_leaves_no_new_file_or_folder(tmp_path, capsys):
    """Issue 46: `--n-items 5000` left empty videos/, motion/ and sheets/ behind."""
    # A folder the build would create, two levels of it: nothing of it is left.
    _fails(capsys, "--n-items", 5000, "--out", tmp_path / "new" / "stimuli")
    assert _tree(tmp_path) == []
    # A folder that exists, with a file of the user's: only that file is left, after a failure before the clips
    # (too many items) and after one once the set's folders exist (a checkpoint that is not there).
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    for args in (("--n-items", 5000), ("--mg-checkpoint", tmp_path / "none.pt")):
        line = _fails(capsys, *args, "--out", out)
        assert _tree(out) == ["notes.txt"], (args, _tree(out))
    assert "none.pt: no such file" in line


def test_refusing_to_replace_a_set_touches_nothing(tmp_path, capsys):
    out = tmp_path / "stimuli"
    for sub in ("videos", "motion", "sheets"):
        (out / sub).mkdir(parents=True)
        (out / sub / "x").write_text("clip")
    (out / "manifest.csv").write_text("clip_id\n")
    before = _tree(out)
    assert "pass --force to replace it" in _fails(capsys, "--out", out)
    assert _tree(out) == before


def test_a_folder_of_the_users_own_named_as_a_sets_is_not_removed(tmp_path, capsys):
    """--out a study's own folder, whose items/ (or motion/, items.csv) is the user's: the build removed it as a
    set's, without --force; now it is refused at once, with --force too, and the folder left as it was."""
    for name in ("items", "motion", "items.csv"):
        out = tmp_path / name.replace(".", "_")
        (out / name / "take.bvh" if "." not in name else out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name / "take.bvh" if "." not in name else out / name).write_text("mine")
        before = _tree(out)
        line = _fails(capsys, "--out", out)
        slash = "" if "." in name else "/"
        assert line.startswith(f"error: --out {out}: holds {name}{slash}, which is no stimulus set's"), line
        assert "give another folder" in line and _tree(out) == before
        line = _fails(capsys, "--out", out, "--force")  # --force replaces a stimulus set, not what is no set's
        assert "which is no stimulus set's" in line and _tree(out) == before
    # what a killed build left (its folders, no manifest) is its own: marked when it began, replaced by the next
    killed = tmp_path / "killed"
    (killed / "videos").mkdir(parents=True)
    (killed / "videos" / "ab12.part.mp4").write_bytes(b"")
    with pytest.raises(files.StimuliError, match="no stimulus set's"):
        files.refuse_existing(killed, force=False)
    (killed / files.BUILDING).touch()
    files.prepare_out(killed, force=False)
    assert not any((killed / "videos").iterdir()) and (killed / files.BUILDING).exists()


def test_an_empty_flag_is_refused_not_read_as_left_out(tmp_path, capsys):
    """`--study "$STUDY"` with the variable unset built the built-in study in place of the user's (and an empty
    --data, --config or checkpoint ran on the shipped data and models)."""
    for flag in ("--study", "--data", "--config", "--mg-checkpoint", "--dataset"):
        line = _fails(capsys, flag, "", "--out", tmp_path / "set")
        assert line.endswith(f"argument {flag}: empty; give a value, or leave the flag out (see --help)"), line
    assert not (tmp_path / "set").exists()


def test_an_out_that_is_a_file_is_refused_before_any_work(tmp_path, capsys):
    """`--out ratings.csv` (a file given where the set's folder goes) said `ratings.csv/manifest.csv: Not a
    directory`, and only after the data was read; a file further up the path alike."""
    (tmp_path / "ratings.csv").write_text("clip_id\n")
    line = _fails(capsys, "--out", tmp_path / "ratings.csv")
    assert line == f"error: --out {tmp_path / 'ratings.csv'}: a file, not a folder", line
    line = _fails(capsys, "--out", tmp_path / "ratings.csv" / "set")
    assert line == f"error: --out {tmp_path / 'ratings.csv' / 'set'}: {tmp_path / 'ratings.csv'} is a file", line
    assert (tmp_path / "ratings.csv").read_text() == "clip_id\n" and capsys.readouterr().err == ""


def test_a_video_encoded_again_takes_the_next_key_quantiser_and_rate_seed():
    job = ("m.npz", "v.mp4", "", 64, "ultrafast", {"rate_seed": 7, "style": "stick"})
    for attempt, key_qp in enumerate(render_pool.KEY_QP, start=1):
        again = render_pool._again(job, attempt, seeded=True)
        assert again[:5] == job[:5] and again[5] == {"rate_seed": 7 + attempt, "style": "stick", "key_qp": key_qp}
    assert render_pool._again(job[:5], 1, seeded=False)[5] == {"key_qp": render_pool.KEY_QP[0]}
    assert (
        render_pool.RETRIES == len(render_pool.KEY_QP) and job[5]["rate_seed"] == 7
    )  # the job itself is left as it was


def test_a_table_that_fails_half_way_leaves_the_folders_earlier_one(tmp_path):
    """A build stopped while it writes manifest.csv (here a row the columns cannot hold, the tenth) leaves the
    earlier manifest as it was, not its first rows under the new header, and nothing beside it."""
    from generation.stimuli.files import write_csv

    path = tmp_path / "manifest.csv"
    write_csv(path, ["clip_id", "condition"], [{"clip_id": "a", "condition": "NAT"}])
    before = path.read_bytes()
    rows = [{"clip_id": f"c{i}", "condition": "MG"} for i in range(9)] + [{"clip_id": "x", "role": "test"}]
    with pytest.raises(ValueError):
        write_csv(path, ["clip_id", "condition"], rows)
    assert path.read_bytes() == before == b"clip_id,condition\r\na,NAT\r\n"
    assert os.listdir(tmp_path) == ["manifest.csv"]
