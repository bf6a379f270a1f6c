"""The mesh style in a study of your own motion (`[render] style = "mesh"`): which files can be drawn as a skinned
mesh, and each clip's MeshSpec for its render job (generation.stimuli.mesh_track)."""

from moglow_eval.core import study
from rendering.raster import MESH_INPUTS, STYLES

from ..data import seamless_files
from ..data.smpl_files import is_smpl_file
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


def mesh_spec(c, joints, motions, spec):
    """The MeshSpec of a study clip (builder.StudyClip) drawn as `joints`: the file its motion came from (a
    mismatched clip's: its motion item's; a tool-made BAD clip's: the reference's, which it breaks; a BAD clip of the
    user's own: that file), from the frame it starts at."""
    if c.path:  # a dyadic mismatched clip: its condition's motion for a mismatched interlocutor
        path = c.path
    elif c.condition == study.CATCH:
        own = c.note == "own"
        path = folder_files(study.CATCH, spec.catch_folder)[c.item] if own else motions[study.NATURAL][c.item].path
    else:
        path = motions[c.condition][c.motion_item or c.item].path
    return MeshSpec(
        str(path), str(spec.smpl_model), spec.smpl_type, spec.face, joints, spec.fps, c.start, spec.hand_mean
    )


def partner_mesh_spec(scene, item, spec):
    """The MeshSpec of an item's interlocutor (own_study.scene.Scene): its file, drawn as placed."""
    joints = scene.partner_joints[item]
    path = str(scene.partner_sources[item])
    return MeshSpec(path, str(spec.smpl_model), spec.smpl_type, spec.face, joints, spec.fps, 0, spec.hand_mean)
