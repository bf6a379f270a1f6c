"""Captions burned into a video from word-timed transcripts: the current phrase at the bottom, a keyword highlighted.

`phrases` groups one speaker's timed words into phrases: a pause of PAUSE_S, or more words than LINES lines hold
at the video's size, starts a new one. A phrase is shown from its first word's start until HOLD_S after its last
word's end, or until that speaker's next phrase begins. `CaptionLayer` draws each phrase (or the two speakers'
phrases at once, the agent's lowest) once with PIL, in a bold sans-serif TEXT_SHARE of the frame high, white on a
dark translucent band, the other speaker's words tinted, a highlighted word in dark text on yellow; and blends it
into every yuv420p frame it is on, into the luma plane per pixel and the chroma planes per 2x2 block, as the
rasteriser blends the figure. Captions are drawn from the item's words alone, so every condition's video of an
item shows the same pixels there.
"""

import functools
from dataclasses import dataclass

import numpy as np

from moglow_eval.core.user_files import shown_text

from .camera import frame_size
from .yuv import TO_U, TO_V, TO_Y

TEXT_SHARE = 0.05  # the text's size (em) as a share of the frame height: 32 px at 640, legible on a phone
LINES = 2  # the most lines a phrase takes
WIDTH_SHARE = 0.92  # of the frame width a line may take (phrases are cut for a square frame of the same height)
BOTTOM_SHARE = 0.03  # of the frame height left under the captions
PAUSE_S = 0.7  # a pause this long between words starts a new phrase
HOLD_S = 0.6  # a phrase stays this long after its last word
BAND = (0, 0, 0, 190)  # the band behind the text: black, 75% opaque (the figure shows faintly through)
TEXT = {0: (255, 255, 255), 1: (196, 236, 204)}  # by speaker: the agent white, the other tinted as its figure
KEY_FILL, KEY_TEXT = (255, 212, 0), (20, 20, 20)  # a highlighted word: dark on yellow


@dataclass(frozen=True)
class Phrase:
    start: float
    end: float
    words: tuple  # ((text, highlighted), ...)
    speaker: int = 0  # 0: the agent (or the one person), 1: the interlocutor


# The share of the frame's height the captions may take from the bottom (LINES lines, their band, the margin): the
# framing leaves it free of the body (rendering.framing). Every part of it is a share of the frame, so it is one
# share at every video size.
ROOM = (LINES * 1.25 * TEXT_SHARE + 2 * 0.35 * TEXT_SHARE + BOTTOM_SHARE) + 0.01


def room(size=None):
    """ROOM under its old name, for scripts that call it: the size it took never changed the share."""
    return ROOM


@functools.lru_cache(maxsize=4)
def _font(px):
    from matplotlib import font_manager
    from PIL import ImageFont

    return ImageFont.truetype(font_manager.findfont("DejaVu Sans:bold"), px)


def _lines(words, font, width):
    """The words [(text, highlighted)] wrapped into lines no wider than `width` pixels."""
    lines, line = [], []
    for w in words:
        trial = " ".join(t for t, _ in [*line, w])
        if line and font.getlength(trial) > width:
            lines.append(line)
            line = []
        line.append(w)
    return lines + ([line] if line else [])


def phrases(words, size, speaker=0):
    """Phrases of one speaker's words [(start s, end s, text, highlighted)], in time order: a new phrase after a
    pause of PAUSE_S, or where the words would take more than LINES lines at this video size."""
    font, width = _font(int(round(TEXT_SHARE * size))), WIDTH_SHARE * size
    # Only text that can be drawn: a control character stops the text layout (raqm) with a traceback.
    words = [(a, b, shown_text(str(t)), key) for a, b, t, key in words]
    groups = []
    for w in sorted((w for w in words if w[2]), key=lambda w: w[0]):
        g = groups[-1] if groups else None
        fits = g is not None and len(_lines([(x[2], x[3]) for x in g + [w]], font, width)) <= LINES
        if g is not None and w[0] - g[-1][1] < PAUSE_S and fits:
            g.append(w)
        else:
            groups.append([w])
    out = []
    for k, g in enumerate(groups):
        end = g[-1][1] + HOLD_S
        if k + 1 < len(groups):
            end = min(end, groups[k + 1][0][0])
        out.append(Phrase(g[0][0], end, tuple((w[2], bool(w[3])) for w in g), speaker))
    return out


class CaptionLayer:
    """The captions of one video: `apply(frame, t)` blends the phrases on at time t into a yuv420p frame of `size`
    (a side, or (width, height)): the text a share of the height, centred across the width."""

    def __init__(self, all_phrases, size):
        self.width, self.height = frame_size(size)
        self.phrases = sorted(all_phrases, key=lambda p: (p.start, p.speaker))
        self.cache = {}

    def active(self, t):
        """The phrases on at time t, at most one a speaker (the latest begun), the agent's first."""
        on = {}
        for p in self.phrases:
            if p.start <= t < p.end:
                on[p.speaker] = p
        return tuple(on[s] for s in sorted(on))

    def apply(self, frame, t):
        """Blend the captions on at time t (seconds) into `frame` (flat yuv420p of width x height) in place."""
        shown = self.active(t)
        if not shown:
            return frame
        if shown not in self.cache:
            self.cache[shown] = _layer(shown, self.width, self.height)
        r0, luma, alpha, chroma, calpha = self.cache[shown]
        n, h = self.width * self.height, len(luma)
        y = frame[:n].reshape(self.height, self.width)[r0 : r0 + h]
        y[:] = (y * (1 - alpha) + luma + 0.5).astype(np.uint8)
        for k, plane in enumerate((frame[n : n + n // 4], frame[n + n // 4 :])):
            c = plane.reshape(self.height // 2, self.width // 2)[r0 // 2 : (r0 + h) // 2]
            c[:] = (c * (1 - calpha) + chroma[k] + 0.5).astype(np.uint8)
        return frame


def _image(shown, size, frame_height=None):
    """An RGBA image [H, size, 4] of the phrases `shown` (the agent's lowest), each line on its band, the text
    TEXT_SHARE of `frame_height` (None: `size`, a square frame)."""
    from PIL import Image, ImageDraw

    px = int(round(TEXT_SHARE * (frame_height or size)))
    font, width = _font(px), WIDTH_SHARE * size
    line_h, pad = int(round(1.25 * px)), int(round(0.35 * px))
    blocks = [(p, _lines(list(p.words), font, width)) for p in reversed(shown)]  # the agent's drawn last, lowest
    height = sum(len(lines) * line_h + 2 * pad for _, lines in blocks) + 2
    height += height % 2
    im = Image.new("RGBA", (size, height), (0, 0, 0, 0))
    draw = ImageDraw.Draw(im)
    top = 0
    space = font.getlength(" ")
    for p, lines in blocks:
        longest = max(font.getlength(" ".join(t for t, _ in line)) for line in lines)
        left = (size - longest) / 2
        draw.rounded_rectangle(
            [left - pad, top, left + longest + pad, top + len(lines) * line_h + 2 * pad], radius=pad, fill=BAND
        )
        for k, line in enumerate(lines):
            x = (size - font.getlength(" ".join(t for t, _ in line))) / 2
            y = top + pad + k * line_h
            for text, key in line:
                w = font.getlength(text)
                if key:
                    draw.rounded_rectangle([x - 3, y - 1, x + w + 3, y + line_h - 2], radius=4, fill=KEY_FILL)
                draw.text((x, y), text, font=font, fill=KEY_TEXT if key else TEXT[p.speaker])
                x += w + space
        top += len(lines) * line_h + 2 * pad
    return np.asarray(im)


def _layer(shown, width, height):
    """(first row, premultiplied luma [H, W], alpha [H, W], premultiplied chroma [2, H/2, W/2], chroma alpha) of
    the caption image for `shown`, placed BOTTOM_SHARE above the frame's bottom on an even row."""
    rgba = _image(shown, width, height).astype(np.float32)
    h = len(rgba)
    r0 = height - h - int(round(BOTTOM_SHARE * height))
    r0 -= r0 % 2
    a = rgba[..., 3] / 255.0
    rgb = rgba[..., :3]
    luma = (rgb @ TO_Y + 16) * a

    def blocks(x):  # the mean of each 2x2 block, as the chroma planes sample the frame
        return x.reshape(h // 2, 2, width // 2, 2).mean((1, 3))

    chroma = np.stack([blocks((rgb @ to + 128) * a) for to in (TO_U, TO_V)])
    return max(r0, 0), luma.astype(np.float32), a.astype(np.float32), chroma.astype(np.float32), blocks(a)
