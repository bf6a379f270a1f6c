"""What a built study's cameras frame (generation.own_study.scene through rendering.framing): with the mesh style,
the body model's surface, not only the joints, and two people in the wide frame of the study's aspect. SMPL-H takes
with the arms hanging or spread wide, through a synthetic body model whose fingers go on beyond their last joints and
whose head reaches above the head joint further than a stick figure's (tests/helpers/smpl_fixtures.py): the fast
tier."""

import csv

import numpy as np
import pytest
from helpers import figure_pixels, smpl_fixtures

from generation.make_stimuli import main as make_stimuli

SIZE, FRAMES = 160, 33  # (a clip is at least 1 s)


def _study(root, two):
    """A mesh study of two conditions and two items, one with the arms hanging, one with them spread wide; `two`:
    beside an interlocutor."""
    turn = np.linspace(0, 2 * np.pi, FRAMES)
    for sub, phase in (("real", 0.0), ("sys", 1.0), ("other", 2.0)):
        (root / sub).mkdir(parents=True)
        # The arms hanging, the bowed head's top highest; the arms spread wide, the fingertips furthest out.
        for k, (mean, swing) in enumerate(((1.2, 0.1), (0.5, 0.05))):
            lowered = mean + swing * np.sin(turn + phase)
            smpl_fixtures.write_arms_take(root / sub / f"i{k}.npz", lowered)
    (root / "models").mkdir()
    smpl_fixtures.write_body_model(root / "models" / "SMPLH_NEUTRAL.npz", "smplh", tips=0.03, head=(0.08, 0.14))
    text = (
        'reference = "real"\nseed = 1\nn_training = 1\n[conditions]\nreal = "real"\nSYS = "sys"\n'
        '[catch]\nmake = ["jitter"]\nn = 1\n[skeleton]\nsmpl_model = "models/SMPLH_NEUTRAL.npz"\n'
        '[render]\nstyle = "mesh"\nview = "front"\nframing = "upper"\n'
    )
    if two:
        text = text.replace('view = "front"\n', "") + '[interlocutor]\nfolder = "other"\n'
    (root / "study.toml").write_text(text)
    return root / "study.toml"


@pytest.mark.full  # mesh studies built: the full tier (the fast tier stays short)
@pytest.mark.parametrize("two", [False, True], ids=["one person", "two people"])
def test_no_mesh_leaves_a_built_studys_frame(tmp_path, two):
    """Every video of the set: the study's frame (two people: 3:1, the default; one: square), and no body's pixel
    on its left, right or top edge in any frame, the meshes' fingertips and heads included."""
    study = _study(tmp_path / "s", two)
    argv = ["--study", str(study), "--out", str(tmp_path / "o"), "--size", str(SIZE), "--quiet", "--workers", "1"]
    assert make_stimuli(argv) == 0
    with open(tmp_path / "o" / "manifest.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    width = 3 * SIZE if two else SIZE
    assert rows and {(int(r["width"]), int(r["height"])) for r in rows} == {(width, SIZE)}
    for r in rows:
        frames, _ = figure_pixels.decode(tmp_path / "o" / r["video"])
        assert frames.shape[1:3] == (SIZE, width)
        for t, rgb in enumerate(frames):
            body = figure_pixels.agent(rgb) | figure_pixels.partner(rgb)
            assert body.sum() > 100, (r["condition"], t)
            assert not figure_pixels.touches_edge(body, border=1), (r["condition"], r["role"], t)
