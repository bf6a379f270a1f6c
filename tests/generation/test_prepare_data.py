"""prepare_data (issue 2): the dataset contract, splits by take, windows, history, augmentation, CLI."""

import gzip

import numpy as np
import pytest
from helpers.paths import BANDAI, DATA, small_take_names

from generation.data import prepare as prepare_data
from generation.data.prepare import find_takes, prepare, window_starts
from generation.motion import skeleton
from generation.motion.features import load_take, mirror, reverse, to_features

pytestmark = pytest.mark.full  # the full tier: the data set in ../shared

SPLITS = ("train", "valid", "test")


@pytest.fixture(scope="module")
def ds(small_dataset):
    with np.load(small_dataset) as f:
        return {k: f[k] for k in f.files}


def test_contract_keys_and_shapes(ds):
    for s in SPLITS:
        n = len(ds[f"{s}_x"])
        assert n > 0
        assert ds[f"{s}_x"].shape == (n, 80, 63) and ds[f"{s}_x"].dtype == np.float32
        assert ds[f"{s}_c"].shape == (n, 80, 3) and ds[f"{s}_c"].dtype == np.float32
        assert ds[f"{s}_labels"].shape == ds[f"{s}_take"].shape == ds[f"{s}_start"].shape == (n,)
        assert ds[f"{s}_labels"].dtype.kind == "U"
    for s in ("valid", "test"):
        n = len(ds[f"{s}_x"])
        assert ds[f"{s}_hist"].shape == (n, 10, 63) and ds[f"{s}_hist_c"].shape == (n, 10, 3)
        assert (ds[f"{s}_start"] >= 10).all()
    assert float(ds["fps"]) == 20.0 and int(ds["window"]) == 80 and int(ds["tau"]) == 10
    assert list(ds["joint_names"]) == skeleton.JOINT_NAMES
    np.testing.assert_array_equal(ds["parents"], skeleton.PARENTS)
    for k, d in (("x_mean", 63), ("x_std", 63), ("c_mean", 3), ("c_std", 3)):
        assert ds[k].shape == (d,) and np.isfinite(ds[k]).all()
    assert (ds["x_std"] > 0).all() and (ds["c_std"] > 0).all()


def test_splits_by_take_and_balanced(ds):
    takes = {s: set(ds[f"{s}_take"]) for s in SPLITS}
    assert not (takes["train"] & takes["valid"]) and not (takes["train"] & takes["test"])
    assert not (takes["valid"] & takes["test"])
    for s in ("valid", "test"):
        cats = {}
        for take, label in zip(ds[f"{s}_take"], ds[f"{s}_labels"]):
            cats.setdefault(str(label), set()).add(str(take))
        # every category that has long-enough takes is held out, with the same number of takes
        assert set(cats) == {
            "run",
            "walk",
            "walk_backward",
            "walk_turn_left",
            "walk_turn_right",
            "sidestep_left",
            "sidestep_right",
        }  # dashes are all shorter than 4.5 s
        assert len({len(v) for v in cats.values()}) == 1, cats


def test_standardisation_from_train_only(ds):
    tx = ds["train_x"].reshape(-1, 63).astype(np.float64)
    np.testing.assert_allclose(ds["x_mean"], tx.mean(0), atol=1e-5)
    np.testing.assert_allclose(ds["x_std"], np.maximum(tx.std(0), 1e-3), rtol=1e-4, atol=1e-6)
    tc = ds["train_c"].reshape(-1, 3).astype(np.float64)
    np.testing.assert_allclose(ds["c_mean"], tc.mean(0), atol=1e-6)
    everything = np.concatenate([ds[f"{s}_x"].reshape(-1, 63) for s in SPLITS])
    assert not np.allclose(ds["x_mean"], everything.mean(0), atol=1e-5)


def test_windows_and_history_are_the_source_frames(ds):
    for s in ("valid", "test"):
        for i in (0, len(ds[f"{s}_x"]) - 1):
            take, start = str(ds[f"{s}_take"][i]), int(ds[f"{s}_start"][i])
            path = next(BANDAI.glob(f"*/data/{take}.bvh.gz"))
            x, c = to_features(load_take(path, 20.0), 20.0)
            np.testing.assert_array_equal(ds[f"{s}_x"][i], x[start : start + 80])
            np.testing.assert_array_equal(ds[f"{s}_c"][i], c[start : start + 80])
            np.testing.assert_array_equal(ds[f"{s}_hist"][i], x[start - 10 : start])
            np.testing.assert_array_equal(ds[f"{s}_hist_c"][i], c[start - 10 : start])


def test_augmentation_in_train_only(ds):
    assert (ds["valid_aug"] == 0).all() and (ds["test_aug"] == 0).all()
    counts = np.bincount(ds["train_aug"], minlength=4)
    assert counts.min() == counts.max() > 0  # original, mirrored, reversed, both: one window each
    take = str(ds["train_take"][0])
    path = next(BANDAI.glob(f"*/data/{take}.bvh.gz"))
    x, c = to_features(load_take(path, 20.0), 20.0)
    variants = {0: (x, c), 1: mirror(x, c), 2: reverse(x, c), 3: reverse(*mirror(x, c))}
    for i in np.flatnonzero(ds["train_take"] == take):
        vx, vc = variants[int(ds["train_aug"][i])]
        s = int(ds["train_start"][i])
        np.testing.assert_array_equal(ds["train_x"][i], vx[s : s + 80])
        np.testing.assert_allclose(ds["train_c"][i], vc[s : s + 80], atol=1e-7)


def test_window_starts_cover_the_tail():
    assert window_starts(100, 80, 20).tolist() == [0, 20]
    assert window_starts(105, 80, 20).tolist() == [0, 20, 25]
    assert window_starts(105, 80, 20, first=10).tolist() == [10, 25]
    assert window_starts(79, 80, 20).tolist() == []
    assert window_starts(89, 80, 20, first=10).tolist() == []


def test_split_is_seeded(tmp_path):
    names = small_take_names(3)
    a = prepare(BANDAI, tmp_path / "a.npz", takes=names, seed=1, workers=1, progress=False)
    b = prepare(BANDAI, tmp_path / "b.npz", takes=names, seed=1, workers=1, progress=False)
    prepare(BANDAI, tmp_path / "c.npz", takes=names, seed=2, workers=1, progress=False)
    test_takes = {k: set(np.load(tmp_path / f"{k}.npz")["test_take"]) for k in "abc"}
    assert a["rows"] == b["rows"] and test_takes["a"] == test_takes["b"]
    assert test_takes["a"] != test_takes["c"]
    with np.load(tmp_path / "a.npz") as fa, np.load(tmp_path / "b.npz") as fb:
        np.testing.assert_array_equal(fa["train_x"], fb["train_x"])


def _copy_takes(dst, names):
    dst.mkdir()
    for n in names:
        src = next(BANDAI.glob(f"*/data/{n}.bvh.gz"))
        (dst / src.name).write_bytes(src.read_bytes())
    return dst


def test_cli_summary(tmp_path, capsys):
    data = _copy_takes(tmp_path / "data", small_take_names(3))
    out = tmp_path / "ds.npz"
    assert prepare_data.main(["--data", str(data), "--out", str(out), "--quiet", "--workers", "1"]) == 0
    text = capsys.readouterr().out
    assert "walk_turn_left" in text and "total" in text and "windows_test" in text
    with np.load(out) as f:
        assert len(f["test_x"]) > 0


def test_cli_errors(tmp_path, capsys, monkeypatch):
    data = _copy_takes(tmp_path / "data", small_take_names(1)[:2])
    bad = data / "dataset-2_walk_bad_001.bvh"
    src = next((BANDAI / "dataset-2" / "data").glob("dataset-2_walk_*.bvh.gz"))
    text = gzip.decompress(src.read_bytes()).decode().split("\n")
    k = next(i for i, line in enumerate(text) if line.startswith("Frame Time")) + 3
    text[k] = text[k].rsplit(" ", 1)[0]  # one value short
    bad.write_text("\n".join(text))
    assert prepare_data.main(["--data", str(data), "--out", str(tmp_path / "o.npz"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {bad}:{k + 1}: wrong number of values: expected 132 values, got 131\n"
    assert prepare_data.main(["--data", str(tmp_path / "nowhere"), "--quiet"]) == 2
    assert "nowhere: data directory not found" in capsys.readouterr().err
    monkeypatch.setattr(prepare_data, "DEFAULT_DATA", prepare_data.Path("no") / "such" / "dir")
    monkeypatch.chdir(tmp_path)
    assert prepare_data.main(["--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: no --data given") and "--data DIR" in err and err.count("\n") == 1


def test_default_data_dir_found():
    assert prepare_data.default_data_dir() == BANDAI.resolve()


def test_full_prepare(tmp_path):
    """All 1067 takes (the default run): every category but the too-short dashes is held out equally."""
    summary = prepare(BANDAI, tmp_path / "full.npz", progress=False)
    assert summary["n_takes"] == len(find_takes(BANDAI)) == 1067
    held = {(r["category"], r["split"]): r["takes"] for r in summary["rows"] if r["split"] != "train"}
    for cat in ("run", "walk", "walk_backward", "walk_turn_left", "walk_turn_right"):
        assert held[(cat, "valid")] == held[(cat, "test")] == 4
    assert summary["n_windows"]["test"] >= 60


# Four walks, long enough for a held-out window each, and one take that is not locomotion.
UPSTREAM_TAKES = {
    "bandai-namco-locomotion": [f"dataset-1_walk_{s}.bvh.gz" for s in ("sad_002", "sad_001", "proud_001", "proud_002")],
    "bandai-namco-actions": ["dataset-1_bow_active_001.bvh.gz"],
}


def test_reads_the_published_repository_layout(tmp_path, capsys):
    """A clone of BandaiNamcoResearchInc/Bandai-Namco-Research-Motiondataset with its data.zip unpacked:
    uncompressed .bvh (and .json labels) under dataset/Bandai-Namco-Research-Motiondataset-N/data/ (docs/data.md).
    prepare_data reads the walks and skips the takes that are not locomotion."""
    data = tmp_path / "dataset" / "Bandai-Namco-Research-Motiondataset-1" / "data"
    data.mkdir(parents=True)
    for folder, names in UPSTREAM_TAKES.items():
        for name in names:
            src = DATA / folder / "dataset-1" / "data" / name
            (data / name.removesuffix(".gz")).write_bytes(gzip.decompress(src.read_bytes()))
            label = src.with_name(name.removesuffix(".bvh.gz") + ".json")
            (data / label.name).write_bytes(label.read_bytes())
    clone = tmp_path / "dataset"
    assert [p.name for p in find_takes(clone)] == sorted(
        n.removesuffix(".gz") for n in UPSTREAM_TAKES["bandai-namco-locomotion"]
    )
    out = tmp_path / "upstream.npz"
    assert prepare_data.main(["--data", str(clone), "--out", str(out), "--quiet", "--workers", "1"]) == 0
    assert "walk" in capsys.readouterr().out
    with np.load(out) as ds:
        assert {str(t) for s in SPLITS for t in ds[f"{s}_take"]} == {
            n.removesuffix(".bvh.gz") for n in UPSTREAM_TAKES["bandai-namco-locomotion"]
        }
        assert set(ds["train_labels"]) == {"walk"} and len(ds["valid_x"]) > 0 and len(ds["test_x"]) > 0
        # the uncompressed file gives the same features as the shared gzip copy
        take = str(ds["test_take"][0])
        x, _ = to_features(load_take(BANDAI / "dataset-1" / "data" / f"{take}.bvh.gz", 20.0), 20.0)
        start = int(ds["test_start"][0])
        np.testing.assert_array_equal(ds["test_x"][0], x[start : start + 80])
