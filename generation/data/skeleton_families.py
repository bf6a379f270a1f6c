"""The skeleton families people bring to a study, told apart by joint names, and the unit a file's body is in.

Many families share the CMU-style names (`Hips`, `LeftUpLeg`, `LeftArm`, `Spine1`): CMU itself, Mixamo, ZeroEGGS,
BEAT and LaFAN1. Their units differ (CMU's own 5.64 cm, centimetres for the others), so a family's name alone
does not settle the unit: with `units = "auto"` the standing body's height does (`choose_unit`). Each candidate
unit is tried in turn, the family's own first, and the first that makes the body a person's height is taken.
"""

from dataclasses import dataclass

from moglow_eval.core.cli import UserError

HUMAN_HEIGHT_M = (1.2, 2.2)  # a standing person, child to tall adult, head to toe
INCH = 0.0254
CMU_UNIT = INCH / 0.45  # the CMU ASF/BVH unit: inches / 0.45 (about 5.64 cm)
# Tried in this order after the family's own unit. Their human ranges do not overlap (m 1.2-2.2, cm 120-220,
# mm 1200-2200, inches 47-87, CMU units 21-39), so the order decides nothing between them.
CANDIDATES = (("m", 1.0), ("cm", 0.01), ("mm", 0.001), ("inches", INCH), ("CMU units (5.64 cm)", CMU_UNIT))


@dataclass(frozen=True)
class Family:
    name: str
    unit: str  # a name from CANDIDATES
    needs: frozenset = frozenset()  # every one of these joint names
    prefix: str = ""  # ... or a joint name starting with this
    lacks: frozenset = frozenset()  # ... and none of these
    gesture: bool = False  # a speech-gesture data set's skeleton: a study of it gets the gesture measures

    def matches(self, names):
        if self.prefix and not any(n.startswith(self.prefix) for n in names):
            return False
        return self.needs <= names and not self.lacks & names


# Most specific first: the first family that matches names the file.
FAMILIES = (
    Family("Bandai-Namco", "cm", frozenset({"joint_Root", "Hips", "UpperLeg_L", "UpperArm_R"})),
    Family(
        "GENEA 2022/2023 (Talking With Hands)",
        "cm",
        frozenset({"b_root", "b_spine0", "b_r_upleg", "b_l_arm"}),
        gesture=True,
    ),
    Family("Mixamo", "cm", prefix="mixamorig"),
    Family("ZeroEGGS/BEAT", "cm", frozenset({"Hips", "Spine3", "Neck1", "RightHandThumb1"}), gesture=True),
    Family("CMU", "CMU units (5.64 cm)", frozenset({"Hips", "LHipJoint", "RHipJoint", "LowerBack", "LeftUpLeg"})),
    Family("LaFAN1", "cm", frozenset({"Hips", "LeftToe", "RightToe", "Spine2"}), lacks=frozenset({"Spine3"})),
)


class UnitError(UserError):
    """No candidate unit gives the body a person's height; the message names the file and every try."""


def family(names):
    """The Family whose joint names these are, or None."""
    names = set(names)
    return next((f for f in FAMILIES if f.matches(names)), None)


def choose_unit(height, names, where):
    """(metres per unit, what was taken) for a body `height` file units tall, standing.

    The family's unit (where the names tell one) is tried first, then m, cm, mm, inches and CMU units; the first that
    gives a height within HUMAN_HEIGHT_M wins. UnitError naming the file, the skeleton and each unit's height
    otherwise."""
    fam = family(names)
    units = dict(CANDIDATES)
    order = ([fam.unit] if fam else []) + [u for u, _ in CANDIDATES if not fam or u != fam.unit]
    lo, hi = HUMAN_HEIGHT_M
    tried = []
    for unit in order:
        metres = height * units[unit]
        if lo <= metres <= hi:
            return units[unit], f"{fam.name + ' skeleton, ' if fam else ''}{unit}"
        tried.append(f"{unit} gives {metres:.3g} m")
    skeleton = f"a {fam.name} skeleton" if fam else "a skeleton of no family known here"
    raise UnitError(
        f"{where}: the body is {height:.4g} units tall, no standing person's height ({lo:g}-{hi:g} m) in any unit "
        f"tried for {skeleton}: {', '.join(tried)}; set [skeleton] units in the study file"
    )
