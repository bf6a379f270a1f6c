"""A person's drawing colour as the files carry it ("#RRGGBB") and as the rater's page names it.

The renderer owns the colours it draws; a study of your own motion writes the interlocutor's into study.json
(CONTRACTS §4), and the rater's page names it from there with `colour_name`, so the page's words follow the study
file's `[interlocutor] colour` and never a colour the videos do not show.
"""

from __future__ import annotations

import colorsys
import re

HEX = re.compile(r"#[0-9a-fA-F]{6}")  # fullmatch

# Hue bands (degrees, upper bound exclusive) and the plain word a rater would use for each; a colour whose
# saturation is below GREY_SATURATION is named by its lightness instead.
HUE_NAMES = ((15, "red"), (45, "orange"), (70, "yellow"), (170, "green"), (200, "teal"), (260, "blue"),
             (290, "purple"), (340, "pink"), (361, "red"))  # fmt: skip
GREY_SATURATION = 0.15


def from_hex(text: str) -> tuple[float, float, float]:
    """The text "#RRGGBB" as rgb in 0..1; ValueError for anything else."""
    if not isinstance(text, str) or not HEX.fullmatch(text):
        raise ValueError(f'must be "#RRGGBB", got {text!r}')
    return tuple(int(text[k : k + 2], 16) / 255 for k in (1, 3, 5))


def to_hex(rgb) -> str:
    """rgb in 0..1 as "#rrggbb" (each channel rounded to the nearest of 256 levels)."""
    return "#" + bytes(min(255, max(0, round(float(c) * 255))) for c in rgb).hex()


def colour_name(rgb) -> str:
    """The plain English word for rgb in 0..1: "green" for the interlocutor's default, "grey" for a colour with
    little saturation (with "light" or "dark" at the ends), else its hue band's name."""
    hue, light, sat = colorsys.rgb_to_hls(*(float(c) for c in rgb))
    if sat < GREY_SATURATION or light < 0.08 or light > 0.95:
        if light < 0.08:
            return "black"
        if light > 0.95:
            return "white"
        return "dark grey" if light < 0.3 else "light grey" if light > 0.75 else "grey"
    degrees = hue * 360
    return next(name for upper, name in HUE_NAMES if degrees < upper)
