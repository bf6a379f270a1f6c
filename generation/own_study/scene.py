"""What each item's videos show besides the clip's motion: where the people stand, the camera, the other person.

One person: every clip is placed with its root at the origin, facing +Z where the names tell left from right
(`place`), and one camera frames all of an item's clips (rendering.framing.item_camera), leaving the captions'
room free. Two people (a study with `[interlocutor]`): every clip of an item (every condition's, the mismatched
and catch clips too) stands beside the item's real interlocutor as the study file says
(generation.own_study.placing), and one fixed camera frames the agent's clips and the interlocutor together in the
study's wide frame (rendering.framing.pair_camera); the interlocutor is written once per item as a clip the render
workers read, drawn in one colour in every style. Where each person is on screen sets the side of their voice in a
stereo mix. With the mesh style, each camera frames the meshes' surfaces, not only their joints (`reach`).
"""

from dataclasses import dataclass, field

import numpy as np

from moglow_eval.core import study
from moglow_eval.core.clip import save_clip
from moglow_eval.core.skeleton_names import body_root, side
from rendering.camera import Projector
from rendering.framing import item_camera, pair_camera, steady
from rendering.raster import PARTNER_COLOUR, STYLES, one_colour

from ..motion.features import rotate_y
from .placing import place_pair


def place(joints, names, parents):
    """A clip with its body's root (core.skeleton_names.body_root) at the origin on the floor at frame 0, turned to
    face +Z where the names tell the left joints from the right (else only moved): no start position or heading
    tells a condition."""
    out = np.asarray(joints, dtype=np.float64).copy()
    out[..., [0, 2]] -= out[0, body_root(names, parents), [0, 2]]
    left = [j for j, n in enumerate(names) if side(n) == "left"]
    right = [j for j, n in enumerate(names) if side(n) == "right"]
    if left and right:
        across = out[0, left].mean(0) - out[0, right].mean(0)
        yaw = np.arctan2(-across[2], across[0])  # facing = across x up, as features.root_trajectory
        out = rotate_y(out, -yaw)
    return out.astype(np.float32)


@dataclass
class Scene:
    """Per item: the camera, and for two people the fixed look-at point, the partner's clip file and where each
    person is on screen (-1 left .. 1 right)."""

    cameras: dict = field(default_factory=dict)
    targets: dict = field(default_factory=dict)
    partners: dict = field(default_factory=dict)  # {item: the placed partner's clip file, for the render workers}
    partner_sources: dict = field(default_factory=dict)  # {item: the partner's own motion file}
    partner_joints: dict = field(default_factory=dict)  # {item: the placed partner's joints [T, J, 3]}
    sides: dict = field(default_factory=dict)
    colour: tuple = PARTNER_COLOUR
    aspect: float = 1.0  # the frame's width over its height (rendering.render.RenderOptions.aspect)

    def job(self, item, style):
        """A render job's keywords (generation.stimuli.render_pool: RenderOptions' fields and render_clip's
        `partner`) for a clip of `item` drawn in `style` (a key of rendering.raster.STYLES)."""
        out = dict(camera=self.cameras[item], style=STYLES[style])
        if self.aspect != 1:
            out["aspect"] = self.aspect
        if item in self.partners:
            out.update(partner=str(self.partners[item]), target=self.targets[item])
            out["partner_style"] = one_colour(STYLES[style], self.colour)
        return out


def _screen_x(camera, target, joints, root, aspect=1.0):
    """Where a body's mean root (joint `root`) falls across the frame (`aspect` times as wide as high), -1 (left
    edge) .. 1 (right edge)."""
    proj = Projector(camera, 2 * aspect, 2)
    cam = proj.to_camera(np.asarray(joints)[:, root].mean(0), np.asarray(target) + proj.offset)
    return float(proj.to_screen(cam)[0] / aspect - 1.0)


def _reach(clips, reach):
    """The most each joint's drawing reaches beyond it over `clips` (StudyClip) [J], or None without `reach`."""
    if reach is None:
        return None
    return np.max([reach(c) for c in clips], axis=0)


def _reference_first(clips):
    """An item's clips with the reference's own clip first (the `recorded` placement is set by it)."""
    return sorted(clips, key=lambda c: (c.condition != study.NATURAL or bool(c.motion_item), c.role != "test"))


def stage(clips, skeleton, spec, partners, folder, room=0.0, reach=None):
    """Place every clip (StudyClip, joints replaced) and make each item's Scene; `skeleton` (names, parents) of
    the agents, `partners` {item: Motion} of the interlocutors (empty: one person), `folder` where the placed
    partners are written, `room` the captions' share of the frame, `reach` (with the mesh style) a pair of
    functions giving how far a clip's and a partner's mesh reaches beyond each joint
    (generation.own_study.mesh_clips)."""
    names, parents = skeleton
    aspect = spec.aspect or 1.0
    scene = Scene(colour=spec.colour or PARTNER_COLOUR, aspect=aspect)
    by_item = {}
    for c in clips:
        by_item.setdefault(c.item, []).append(c)
    framing = spec.framing or "full"
    for item, group in by_item.items():
        if not partners:
            for c in group:
                c.joints = place(c.joints, names, parents)
            # Facing measured from the reference's clips, and held to steps (framing.steady): a system that joins
            # the study changes its item's camera, and so the other clips' videos, only if it leaves the frame.
            facing = [c.joints for c in group if c.condition == study.NATURAL] or None
            joints = [c.joints for c in group]
            around = _reach(group, reach and reach[0])
            scene.cameras[item] = steady(
                item_camera(joints, names, parents, spec.fps, spec.view, framing, room, facing, aspect, around)
            )
            continue
        group = _reference_first(group)
        other = partners[item]
        roots = (body_root(names, parents), body_root(other.names, other.parents))
        placed, partner = place_pair([c.joints for c in group], names, other.joints, other.names, spec.placement,
                                     spec.distance, spec.opened, roots)  # fmt: skip
        for c, joints in zip(group, placed):
            c.joints = joints
        people = [(names, parents, None), (other.names, other.parents, partner)]
        # The view and the look-at point from the reference's clips, the camera held to steps (pair_camera): a
        # system that joins the study changes its item's videos only if it leaves the frame.
        facing = [c.joints for c in group if c.condition == study.NATURAL and c.role != "catch" and not c.motion_item]
        facing = facing or None
        around = (_reach(group, reach and reach[0]), reach and reach[1](other))
        camera, target = pair_camera(placed, people, spec.view, framing, room, aspect, facing, around)
        scene.cameras[item], scene.targets[item] = camera, target
        scene.partners[item] = folder / f"partner_{len(scene.partners)}.npz"
        save_clip(scene.partners[item], partner, other.parents, other.names, spec.fps)
        scene.partner_sources[item], scene.partner_joints[item] = other.path, partner
        scene.sides[item] = tuple(_screen_x(camera, target, j, r, aspect) for j, r in zip((placed[0], partner), roots))
    return scene
