"""appropriateness (CONTRACTS §10): each condition's motion for its own item's speech against its motion for another
item, under the same speech."""

from .base import OtherItemDesign


class Appropriateness(OtherItemDesign):
    name = "appropriateness"
