"""Text on a frame, sized by the picture it is on so that it stays legible when the picture is small.

:func:`text_size` is the font size for a panel of a given side: at least :data:`MIN_TEXT` pixels
(capital letters 10 pixels high in Pillow's own font), and in proportion beyond 392 pixels, so
that a frame drawn at 1,024 pixels and shown at 320 reads as one drawn at 320.  :func:`fitted`
shrinks a font until a text fits the room it has (never below :data:`FLOOR`);
:func:`draw_runs` draws a line of differently coloured runs on a pale backing that leaves the
picture under it visible.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

from PIL import Image, ImageDraw, ImageFont

__all__ = ["FLOOR", "MIN_TEXT", "Font", "cut", "draw_runs", "fitted", "font", "text_size", "text_width"]

#: the smallest font size a frame's text is drawn at, as wide as the frame allows
MIN_TEXT = 14
#: the size below which :func:`fitted` does not shrink a text (it is then cut short instead)
FLOOR = 9
#: pixels of panel per pixel of font size, past :data:`MIN_TEXT`
_PER_PIXEL = 28

Font = ImageFont.ImageFont | ImageFont.FreeTypeFont


def text_size(side: float) -> int:
    """The font size of a frame's text on a panel ``side`` pixels across: 14 at 320 and below,
    18 at 512, 37 at 1,024."""
    return max(MIN_TEXT, round(float(side) / _PER_PIXEL))


@lru_cache(maxsize=64)
def font(size: int) -> Font:
    """Pillow's own font at ``size`` pixels (its fixed bitmap font where FreeType is missing)."""
    try:
        return ImageFont.load_default(size=int(size))
    except (TypeError, ImportError, OSError):  # an old Pillow, or no FreeType: the one bitmap size
        return ImageFont.load_default()


def text_width(text: str, f: Font) -> float:
    return float(f.getlength(text))


def fitted(text: str, size: int, room: float) -> Font:
    """The font of the largest size up to ``size`` at which ``text`` is at most ``room`` pixels
    wide, but not below :data:`FLOOR`."""
    s = int(size)
    while s > FLOOR and text_width(text, font(s)) > room:
        s -= 1
    return font(s)


def cut(text: str, f: Font, room: float) -> str:
    """``text``, cut short with an ellipsis until it is at most ``room`` pixels wide."""
    if text_width(text, f) <= room:
        return text
    while len(text) > 1 and text_width(text + "…", f) > room:
        text = text[:-1]
    return text + "…"


def draw_runs(
    picture: Image.Image,
    xy: tuple[float, float],
    runs: Sequence[tuple[str, tuple[int, int, int]]],
    f: Font,
    backing: float = 0.75,
    pad: int = 2,
) -> tuple[int, int, int, int]:
    """Draw ``runs`` (text, colour), one after the other on one line, with the line's top-left at
    ``xy``, over a white backing of opacity ``backing`` (0: none) just as large as the text plus
    ``pad``; the box covered, ``(left, top, right, bottom)``."""
    d = ImageDraw.Draw(picture)
    text = "".join(t for t, _ in runs)
    x0, y0 = int(round(xy[0])), int(round(xy[1]))
    b = d.textbbox((x0, y0), text or " ", font=f)
    box = (
        max(int(b[0]) - pad, 0),
        max(int(b[1]) - pad, 0),
        min(int(math.ceil(b[2])) + pad, picture.width),
        min(int(math.ceil(b[3])) + pad, picture.height),
    )
    if backing > 0 and box[2] > box[0] and box[3] > box[1]:
        region = picture.crop(box)
        picture.paste(Image.blend(region, Image.new(region.mode, region.size, (255, 255, 255)), backing), box[:2])
    x = float(x0)
    for i, (t, colour) in enumerate(runs):
        d.text((x, y0), t, fill=colour, font=f)
        if i + 1 < len(runs):
            x += text_width(t, f)
    return box
