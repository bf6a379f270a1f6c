"""The mesh style in a study of your own motion (`[render] style = "mesh"`): which files can be drawn as a skinned
mesh, each clip's MeshSpec for its render job (generation.stimuli.mesh_track), and how far each clip's surface
reaches beyond its joints, for the camera to frame."""

import functools

import numpy as np

from moglow_eval.core import study
from rendering.raster import MESH_INPUTS, STYLES

from ..data import seamless_files
from ..data.skinning import surface_reach
from ..data.smpl_files import is_smpl_file, read_parameters
from ..stimuli.files import StimuliError
from ..stimuli.mesh_track import MeshSpec
from .inputs import folder_files


def wants_mesh(spec):
    return any(STYLES[s].body == "mesh" for s in spec.styles)


def check_mesh_inputs(spec, motions):
    """StimuliError, one line naming the first motion file that the mesh style cannot draw: anything but SMPL-family
    parameter files and Seamless Interaction's participant files (BVH, joint positions, clips)."""
    for by_item in motions.values():
        for m in by_item.values():
            if not (is_smpl_file(m.path) or seamless_files.is_seamless_file(m.path)):
                other = [s for s in spec.styles if STYLES[s].body != "mesh"] or ["stick", "solid"]
                raise StimuliError(
                    f"{m.path}: the mesh style draws {MESH_INPUTS} through a body model; this file can use "
                    f"{' or '.join(dict.fromkeys(other + ['stick', 'solid']))}"
                )


def _mesh_file(c, motions, spec):
    """The file a study clip's (builder.StudyClip) mesh is skinned from: the file its motion came from (a
    mismatched clip's: its motion item's; a tool-made BAD clip's: the reference's, which it breaks; a BAD clip of the
    user's own: that file)."""
    if c.path:  # a dyadic mismatched clip: its condition's motion for a mismatched interlocutor
        return c.path
    if c.condition == study.CATCH:
        own = c.note == "own"
        return folder_files(study.CATCH, spec.catch_folder)[c.item] if own else motions[study.NATURAL][c.item].path
    return motions[c.condition][c.motion_item or c.item].path


def mesh_spec(c, joints, motions, spec):
    """The MeshSpec of a study clip (builder.StudyClip) drawn as `joints`, from the frame it starts at."""
    path = _mesh_file(c, motions, spec)
    return MeshSpec(
        str(path), str(spec.smpl_model), spec.smpl_type, spec.face, joints, spec.fps, c.start, spec.hand_mean
    )


def clip_reach(c, motions, spec):
    """How far a study clip's mesh reaches beyond each of its joints [J] (generation.data.skinning.surface_reach)."""
    return file_reach(_mesh_file(c, motions, spec), spec)


def file_reach(path, spec):
    """How far the mesh of an SMPL-family or Seamless Interaction file reaches beyond each joint [J], in its body's
    shape (Seamless's files carry none: the model's mean shape)."""
    return _reach(str(path), str(spec.smpl_model), spec.smpl_type, spec.source_fps)


@functools.lru_cache(maxsize=256)
def _reach(path, model, smpl_type, source_fps):
    betas = np.zeros(0) if seamless_files.is_seamless_file(path) else read_parameters(path, source_fps)[2]
    return surface_reach(model, smpl_type, betas)


def partner_mesh_spec(scene, item, spec):
    """The MeshSpec of an item's interlocutor (own_study.scene.Scene): its file, drawn as placed."""
    joints = scene.partner_joints[item]
    path = str(scene.partner_sources[item])
    return MeshSpec(path, str(spec.smpl_model), spec.smpl_type, spec.face, joints, spec.fps, 0, spec.hand_mean)
