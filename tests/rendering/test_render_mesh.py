"""The mesh body (issue 54): an SMPL-H clip drawn as its skinned mesh through a synthetic body model of smplx's
layout (tests/helpers/smpl_fixtures.py), checked against the joints' projection in the decoded video: the
silhouette covers the wrists, elbows and head, both hands are in frame, the face mask sits over the head, and the
body's colour is not the background's. Front and upper framing; the one-line errors of the inputs it cannot draw."""

import csv

import numpy as np
import pytest
from helpers import smpl_fixtures
from helpers.bvh_fixtures import write_zeroeggs
from helpers.figure_pixels import decode
from helpers.own_study_data import NO_GESTURE_MEASURES
from helpers.paths import ROOT

from analysis.designs import Options
from generation.data.skinning import MeshSource, smpl_mesh
from generation.data.smpl_files import SmplError, smpl_positions
from generation.make_stimuli import main as make_stimuli
from generation.stimuli.mesh_track import MeshTrack
from rendering.blinding import check_one_size
from rendering.camera import Projector, camera_targets
from rendering.encode import MESH_RATE_BITS_PER_ROW, frame_bits
from rendering.errors import RenderError
from rendering.framing import item_camera
from rendering.mp4_layout import read_layout
from rendering.raster import STYLES, FrameDrawer
from rendering.render import MESH_CHUNK, RenderOptions, render_clip

SIZE = 640
WRISTS, ELBOWS, HEAD = (20, 21), (18, 19), 15


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mesh")
    model, motion, clip = smpl_fixtures.smplh_take(folder, frames=40)
    return folder, model, motion, clip


def body_pixels(frame):
    """The mesh's colour (a blue, shaded), and the mask's (a light warm tone), in a decoded RGB frame."""
    rgb = frame.astype(np.int16)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    body = (b - r > 40) & (b > g)
    mask = (r - b > 35) & (r - g > 12) & (r > 150)
    return body, mask


def projected(clip, camera, t):
    """The joints of frame t in image (column, row), and their depth."""
    proj = Projector(camera, SIZE, SIZE)
    target = camera_targets(clip["joints"], clip["fps"], camera)[t]
    cam = proj.to_camera(clip["joints"][t], target + proj.offset)
    xy = proj.to_screen(cam)
    return np.stack([xy[:, 0], SIZE - xy[:, 1]], 1), cam[:, 2], proj.focal


def near(mask, point, radius=4):
    c, r = np.round(point).astype(int)
    return bool(mask[max(r - radius, 0) : r + radius + 1, max(c - radius, 0) : c + radius + 1].any())


@pytest.mark.parametrize("framing", ["full", "upper"])
def test_the_mesh_covers_the_joints_and_masks_the_face(take, tmp_path, framing):
    folder, model, motion, clip = take
    camera = item_camera([clip["joints"]], clip["joint_names"], clip["parents"], clip["fps"], "front", framing)
    out = tmp_path / f"{framing}.mp4"
    n = render_clip(clip, out, RenderOptions(SIZE, camera, STYLES["mesh"], rate_seed=0), mesh=smpl_mesh(motion, model))
    frames, fps = decode(out)
    assert n == len(frames) == 40 and fps == 30
    background = frames[0][5, 5].astype(int)
    for t in (0, 20, 39):
        body, mask = body_pixels(frames[t])
        xy, depth, focal = projected(clip, camera, t)
        assert body.mean() > 0.02, f"frame {t}: no body"
        assert np.abs(frames[t][body].mean(0) - background).max() > 60  # the body's colour is not the background's
        for j in (*WRISTS, *ELBOWS):
            assert 0 <= xy[j, 0] < SIZE and 0 <= xy[j, 1] < SIZE, f"frame {t}: joint {j} out of frame"
            assert near(body | mask, xy[j]), f"frame {t}: joint {j} at {xy[j]} not covered"
        # The face mask: over the head, facing this camera; its pixels lie within the head's radius of the joint.
        head_px = 0.2 * focal / depth[HEAD]
        rows, cols = np.nonzero(mask)
        assert len(rows) > 0.2 * head_px**2, f"frame {t}: {len(rows)} mask pixels"
        dist = np.hypot(cols - xy[HEAD, 0], rows - xy[HEAD, 1])
        assert np.quantile(dist, 0.95) < 1.2 * head_px
        # Nothing of the mask below the chin (a stray pixel or two: the encoder's ringing at the body's edge).
        assert mask[int(xy[HEAD, 1] + 1.5 * head_px) :].sum() < 0.01 * len(rows)


def test_the_mesh_is_skinned_a_chunk_at_a_time(take, tmp_path):
    """Rendering memory does not grow with the clip: the vertices are asked for at most MESH_CHUNK frames at once."""
    folder, model, motion, clip = take
    source = smpl_mesh(motion, model)
    asked = []

    class Spy:
        faces, mask, n_frames = source.faces, source.mask, source.n_frames

        def vertices(self, a, b):
            asked.append((a, b))
            return source.vertices(a, b)

    render_clip(clip, tmp_path / "x.mp4", RenderOptions(size=64, style=STYLES["mesh"]), mesh=Spy())
    assert asked and max(b - a for a, b in asked) <= MESH_CHUNK and asked[-1][1] == 40


def test_other_motion_cannot_take_the_mesh_style(take):
    folder, model, motion, clip = take
    with pytest.raises(RenderError, match="SMPL-family parameter files.*stick or solid"):
        FrameDrawer(clip["parents"], clip["joint_names"], 64, style=STYLES["mesh"])


def test_a_model_that_does_not_fit_is_one_line(take, tmp_path):
    folder, model, motion, clip = take
    arrays = dict(np.load(model))
    arrays["f"] = arrays["f"] + len(arrays["v_template"])
    np.savez(tmp_path / "bad_faces.npz", **arrays)
    arrays = dict(np.load(model))
    arrays["weights"] = arrays["weights"][:-5]
    np.savez(tmp_path / "bad_weights.npz", **arrays)
    for name, needle in (("bad_faces", "indexes vertices outside"), ("bad_weights", "do not fit its")):
        with pytest.raises(SmplError, match=needle) as e:
            smpl_mesh(motion, tmp_path / f"{name}.npz")
        assert f"{name}.npz" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(SmplError, match="no body model file") as e:
        smpl_mesh(motion, tmp_path / "missing.npz")
    assert "missing.npz" in str(e.value)
    assert isinstance(smpl_mesh(motion, model), MeshSource)


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def smpl_study(root, style='["stick", "mesh"]', model_kind="smplh"):
    """A study of two conditions of three SMPL-H items each, the body model named in the study file (the gesture
    measures off: drawing is this module's subject)."""
    for sub, seed in (("real", 0), ("sys", 1)):
        (root / sub).mkdir(parents=True)
        for k in range(3):
            smpl_fixtures.write_motion(root / sub / f"i{k}.npz", "smplh", frames=36, fps=30.0, seed=seed + 10 * k)
    (root / "models").mkdir()
    smpl_fixtures.write_body_model(root / "models" / "SMPLH_NEUTRAL.npz", model_kind)
    (root / "study.toml").write_text(
        'reference = "real"\nn_training = 1\n[conditions]\nreal = "real"\nSYS = "sys"\n[catch]\nn = 1\n'
        '[skeleton]\nsmpl_model = "models/SMPLH_NEUTRAL.npz"\n'
        f'[render]\nview = "front"\nframing = "upper"\nstyle = {style}\n' + NO_GESTURE_MEASURES
    )
    return root / "study.toml"


@pytest.mark.full  # a whole study built and rendered twice over
def test_a_study_draws_every_clip_as_stick_and_mesh(tmp_path):
    """`[render] style = ["stick", "mesh"]`: every clip in both styles, the mesh ones skinned from their files (the
    BAD clip's broken with its joints), with the style column; the mesh videos show the body in its colour."""
    study_file = smpl_study(tmp_path / "s")
    assert make_stimuli(["--study", str(study_file), "--out", str(tmp_path / "o"), "--size", "128", "--quiet"]) == 0
    rows = _rows(tmp_path / "o" / "manifest.csv")
    assert {r["style"] for r in rows} == {"stick", "mesh"}
    by_style = {
        s: sorted((r["condition"], r["item"], r["role"]) for r in rows if r["style"] == s) for s in ("stick", "mesh")
    }
    assert by_style["stick"] == by_style["mesh"] and any(c == "BAD" for c, _, _ in by_style["mesh"])
    # One rate for the set: the stick videos too at the mesh's, every frame after the first two at its budget.
    check_one_size([tmp_path / "o" / r["video"] for r in rows])
    budget = frame_bits(128, 30.0, MESH_RATE_BITS_PER_ROW) // 8
    assert 0 <= read_layout(tmp_path / "o" / rows[0]["video"]).sample_sizes[-1] - budget <= 16
    for r in rows:
        frames, _ = decode(tmp_path / "o" / r["video"])
        body, _ = body_pixels(frames[len(frames) // 2])
        assert (body.mean() > 0.04) == (r["style"] == "mesh"), (
            r["style"],
            r["condition"],
            body.mean(),
        )  # a body, not lines


def test_the_mesh_style_refuses_other_motion_in_one_line(tmp_path, capsys):
    root = tmp_path / "s"
    for sub in ("real", "sys"):
        (root / sub).mkdir(parents=True)
        for k in range(3):
            write_zeroeggs(root / sub / f"i{k}.bvh", frames=30, seed=k)
    (root / "study.toml").write_text(
        'reference = "real"\nn_training = 1\n[conditions]\nreal = "real"\nSYS = "sys"\n[render]\nstyle = "mesh"\n'
    )
    assert make_stimuli(["--study", str(root / "study.toml"), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "i0.bvh: the mesh style draws SMPL-family parameter files" in err[0]
    assert "can use stick or solid" in err[0] and not (tmp_path / "o").exists()


def test_the_mesh_follows_its_clips_joints(take):
    """MeshTrack: a clip that is its file turned, scaled and moved gets the file's mesh turned, scaled and moved
    exactly; a joint moved on its own (a catch clip's break) moves the vertices it skins by as much."""
    folder, model, motion, clip = take
    source = smpl_mesh(motion, model)
    verts, joints = source.posed(0, 10)
    yaw = np.radians(70)
    rot = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    moved = 0.9 * joints.astype(np.float64) @ rot.T + np.array([0.3, -0.1, 2.0])
    got = MeshTrack(source, moved, np.arange(10)).vertices(0, 10)
    want = 0.9 * verts.astype(np.float64) @ rot.T + np.array([0.3, -0.1, 2.0])
    assert np.abs(got - want).max() < 1e-4
    broken = moved.copy()
    broken[:, 20] += (0.0, 0.2, 0.0)  # the left wrist raised 20 cm: the hand's vertices follow it
    got = MeshTrack(source, broken, np.arange(10)).vertices(0, 10)
    hand = source.weights[:, 20] == 1.0
    shift = got - want
    assert np.allclose(shift[:, hand, 1], 0.2, atol=0.03) and np.abs(shift[:, ~hand]).max() < 0.03


def test_the_mesh_and_the_joints_agree(tmp_path):
    """The mesh is posed as the joints are: smplx's skinning gives the same joints as the reader, hand mean (a BEAT2
    file) and SMPL-X expressions included."""
    arrays = smpl_fixtures.body_model_arrays("smplx")
    arrays["shapedirs"] = np.random.default_rng(0).normal(0, 0.002, arrays["shapedirs"].shape[:2] + (20,))
    np.savez(tmp_path / "SMPLX.npz", **arrays)
    motion = smpl_fixtures.motion_arrays("smplx", frames=12)
    np.savez(tmp_path / "take.npz", **motion, expressions=np.random.default_rng(1).normal(0, 1, (12, 10)))
    joints = smpl_positions(tmp_path / "take.npz", tmp_path / "SMPLX.npz")[0]
    _, posed = smpl_mesh(tmp_path / "take.npz", tmp_path / "SMPLX.npz").posed(0, 12)
    assert np.abs(posed - joints).max() < 1e-4


@pytest.mark.parametrize("kind", ["smplh", "smplx"])
def test_the_skinning_is_smplxs(tmp_path, kind):
    """MeshSource.posed, written out in numpy, gives smplx.lbs.lbs's vertices and joints to float32's precision:
    with pose blend shapes, vertices skinned to several joints each, a body shape and (SMPL-X) an expression that
    changes from frame to frame, across a chunk boundary."""
    import torch
    from smplx.lbs import lbs

    rng = np.random.default_rng(2)
    arrays = smpl_fixtures.body_model_arrays(kind)
    arrays["posedirs"] = rng.normal(0, 0.003, arrays["posedirs"].shape).astype(np.float32)
    spread = arrays["weights"] + rng.random(arrays["weights"].shape) * (rng.random(arrays["weights"].shape) < 0.1)
    arrays["weights"] = (spread / spread.sum(1, keepdims=True)).astype(np.float32)
    arrays["shapedirs"] = rng.normal(0, 0.002, arrays["shapedirs"].shape[:2] + (20,)).astype(np.float32)
    np.savez(tmp_path / "model.npz", **arrays)
    motion = smpl_fixtures.motion_arrays(kind, frames=40)
    motion["poses"] = motion["poses"] + rng.normal(0, 0.3, motion["poses"].shape)
    np.savez(tmp_path / "take.npz", **motion, expressions=rng.normal(0, 1, (40, 10)))
    source = smpl_mesh(tmp_path / "take.npz", tmp_path / "model.npz")
    assert (kind == "smplx") == (len(source.coef) == 40)  # SMPL-X: a shape per frame, its expression's
    verts, joints = source.posed(3, 40)
    coef = source.coef[3:40] if len(source.coef) > 1 else np.repeat(source.coef, 37, 0)
    tensors = (coef, source.poses[3:40].astype(np.float32), source.template, source.shapedirs, source.posedirs)
    tensors += (source.regressor, source.parents, source.weights)
    with torch.no_grad():  # (copies: the model's arrays are shared, read-only)
        want_v, want_j = (x.numpy() for x in lbs(*(torch.from_numpy(np.array(x)) for x in tensors)))
    shift = source.trans[3:40, None].astype(np.float32)
    assert np.abs(verts - (want_v + shift)).max() < 2e-5 and np.abs(joints - (want_j + shift)).max() < 2e-5
    assert np.abs(verts - verts.mean(1, keepdims=True)).max() > 0.3  # a body, not a point


@pytest.fixture(scope="module")
def two_style_set(tmp_path_factory):
    """A study of SMPL-H clips drawn stick and mesh (3 items, 2 conditions), from the front, hips up, at 320 px."""
    root = tmp_path_factory.mktemp("two_style")
    study_file = smpl_study(root / "s")
    assert make_stimuli(["--study", str(study_file), "--out", str(root / "o"), "--size", "320", "--quiet"]) == 0
    return root / "o" / "manifest.csv"


@pytest.mark.browser
def test_a_stick_and_mesh_study_in_a_real_browser_reports_the_style(two_style_set, tmp_path):
    """Debian's chromium rates clips of both styles (the mesh videos play and show the body); a crowd fills the
    study through the API; the report of the export has the condition x style analysis with both styles.
    SAVE_SCREENSHOTS=1 writes docs/img/mesh_trial.png (the page showing a mesh clip)."""
    import os
    import shutil

    from helpers.browser import STATE, chrome, waiting
    from helpers.design_client import post
    from helpers.servers import in_thread
    from PIL import Image
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC

    from analysis.report import build_report
    from rating_app import create_app
    from rating_app.store.db import app_engine

    styles = {r["clip_id"]: r["style"] for r in _rows(two_style_set)}
    db = f"sqlite:///{tmp_path / 'r.sqlite'}"
    settings = dict(admin_token="t", design="acr", ratings_per_clip=2, clips_per_rater=6, sessions_per_client=0)
    app = create_app(manifest=two_style_set, db_url=db, min_view=0.3, **settings)
    with in_thread(app) as url:
        browser = chrome(tmp_path, "1280,900")
        seen, meshes = set(), 0
        try:
            wait = waiting(browser, 60)
            browser.get(url + "/?PROLIFIC_PID=meshpid1")
            browser.find_element(By.ID, "consent").click()
            wait.until(EC.element_to_be_clickable((By.ID, "start"))).click()
            wait.until(EC.visibility_of_element_located((By.ID, "intro")))
            browser.find_element(By.ID, "intro-go").click()
            for _ in range(14):
                wait.until(lambda d: d.execute_script(STATE)["section"] in ("trial", "rating-intro", "done"))
                s = browser.execute_script(STATE)
                if s["section"] == "done":
                    break
                if s["section"] == "rating-intro":
                    browser.find_element(By.ID, "rating-go").click()
                    wait.until(lambda d: d.execute_script(STATE)["section"] != "rating-intro")
                    continue
                wait.until(lambda d: all(d.execute_script(STATE)["ended"]))
                seen.add(browser.find_element(By.CSS_SELECTOR, "#trial video").get_attribute("src"))
                shot = tmp_path / f"shot{len(seen)}.png"
                browser.save_screenshot(str(shot))
                body, mask = body_pixels(np.asarray(Image.open(shot).convert("RGB")))
                meshes += body.mean() > 0.01 and mask.sum() > 20  # a skinned body, masked, on the page
                if meshes == 1 and os.environ.get("SAVE_SCREENSHOTS") == "1":
                    shutil.copy(shot, ROOT / "docs" / "img" / "mesh_trial.png")
                button = (
                    (By.ID, "continue")
                    if s["label"] == "Example"
                    else (By.CSS_SELECTOR, "button.rate[data-rating='4']")
                )
                wait.until(EC.element_to_be_clickable(button)).click()
                key = (s["section"], s["label"], s["count"])
                wait.until(lambda d: (lambda t: (t["section"], t["label"], t["count"]) != key)(d.execute_script(STATE)))
            assert len(seen) >= 3 and meshes >= 1
            assert not [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
        finally:
            browser.quit()

    app = create_app(manifest=two_style_set, db_url=db, min_view=0, **settings)  # the API crowd waits for nothing
    client = app.test_client()
    bad = {cid for cid, r in ((r["clip_id"], r) for r in _rows(two_style_set)) if r["condition"] == "BAD"}
    for i in range(30):  # raters who rate BAD 1 (they pass the catch trials), the mesh 4-5 and the stick figure 2-3
        r = client.post("/api/sessions", json={})
        if r.status_code == 409:
            break
        token = r.json["session"]
        while "trial" in (r := client.get(f"/api/sessions/{token}/next")).json:
            trial = r.json["trial"]
            assert client.get(trial["video_url"]).status_code == 200
            cid = trial["clip_id"]
            spread = (ord(cid[0]) + i) % 2  # some spread within each cell: raters differ on each clip
            rating = (
                None
                if trial["phase"] == "training"
                else 1
                if cid in bad
                else spread + (4 if styles[cid] == "mesh" else 2)
            )
            assert post(client, token, trial, rating=rating).status_code == 201
    export = client.get("/admin/export.csv", headers={"Authorization": "Bearer t"}).get_data(as_text=True)
    app_engine(app).dispose()
    (tmp_path / "ratings.csv").write_text(export)
    stats = build_report(tmp_path / "ratings.csv", tmp_path / "report", Options(n_boot=50), quiet=True)
    assert stats["style"]["styles"] == ["stick", "mesh"]
    assert "condition:style" in stats["style"]["anova"]["terms"]


def test_two_people_as_meshes(take, tmp_path):
    """A two-person video in the mesh style: the agent's mesh in its colour, the interlocutor's (placed facing it,
    1.6 m away) in the partner's one neutral colour, both faces masked, both in frame through the pair's camera."""
    from helpers import figure_pixels

    from rendering.framing import pair_camera

    folder, model, motion, clip = take
    other = smpl_fixtures.write_motion(folder / "other.npz", "smplh", frames=40, fps=30.0, seed=5)
    raw, names, parents, fps = smpl_positions(other, model)
    turn = np.diag([-1.0, 1.0, -1.0])  # half a turn about Y: facing the agent
    placed = raw @ turn.T + np.array([0.0, 0.0, 1.6])
    partner_mesh = MeshTrack(smpl_mesh(other, model), placed, np.arange(40))
    partner = dict(joints=placed, parents=parents, joint_names=names, fps=fps)
    people = [(clip["joint_names"], clip["parents"], None), (names, parents, placed)]
    camera, target = pair_camera([clip["joints"]], people)
    out = tmp_path / "two.mp4"
    options = RenderOptions(SIZE, camera, STYLES["mesh"], target=target, rate_seed=0)
    render_clip(clip, out, options, mesh=smpl_mesh(motion, model), partner=partner, partner_mesh=partner_mesh)
    frames, _ = decode(out)
    for t in (0, 20, 39):
        body, mask = body_pixels(frames[t])
        green = figure_pixels.partner(frames[t])
        assert body.mean() > 0.01 and green.mean() > 0.01, t  # two bodies, each in its own colour
        cols = lambda m: np.nonzero(m)[1].mean()  # noqa: E731
        assert abs(cols(body) - cols(green)) > 0.1 * SIZE  # side by side
        assert mask.sum() > 50  # faces masked


def test_the_mesh_on_every_pixel_draws_the_same_body(take):
    """Style.mesh_grid = 1 (every frame pixel, through Agg's buffer over the shadow) and 2 (the default: 2x2 blocks)
    draw the body in the same place and colour."""
    from dataclasses import replace

    folder, model, motion, clip = take
    source = smpl_mesh(motion, model)
    camera = item_camera([clip["joints"]], clip["joint_names"], clip["parents"], clip["fps"], "front", "upper")
    target = camera_targets(clip["joints"], clip["fps"], camera)[10]
    verts = source.vertices(10, 11)
    drawn = []
    for grid in (1, 2):
        drawer = FrameDrawer(clip["parents"], clip["joint_names"], 256, camera, replace(STYLES["mesh"], mesh_grid=grid),
                             meshes=[source])  # fmt: skip
        drawer.draw(clip["joints"][10], target, [verts[0]])
        drawn.append(body_pixels(drawer.rgb())[0])
        drawer.close()
    assert drawn[0].mean() > 0.02 and (drawn[0] & drawn[1]).sum() > 0.85 * drawn[0].sum()
