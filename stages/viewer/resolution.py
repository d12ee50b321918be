"""Render sizes: the full resolution as a pixel budget, fitted to the client's aspect, and the preview size.

``--resolution 128x96`` is read as a number of pixels (12,288 rays), not a fixed box: a render costs in
proportion to its rays, so a wide browser window gets 148x83 at the same latency instead of a smaller
image, and a 4:3 window gets exactly 128x96.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from stages.scene import InputError

_SIZE = re.compile(r"^\s*(\d+)\s*[xX*]\s*(\d+)\s*$")
MIN_SIDE = 8
"""No render is smaller than this many pixels on a side (a preview of a very slow model still shows something)."""


@dataclass(frozen=True)
class Resolution:
    """A render size in pixels."""

    width: int
    height: int

    @property
    def pixels(self) -> int:
        return self.width * self.height

    def __str__(self) -> str:
        return f"{self.width}x{self.height}"

    @classmethod
    def parse(cls, text: str, source: str = "--resolution") -> Resolution:
        m = _SIZE.match(text or "")
        if not m:
            raise InputError(source, f"{text!r} is not WIDTHxHEIGHT", "write e.g. --resolution 128x96")
        width, height = int(m.group(1)), int(m.group(2))
        if width < MIN_SIDE or height < MIN_SIDE:
            raise InputError(source, f"{text!r} is smaller than {MIN_SIDE}x{MIN_SIDE}",
                             "give at least 8 pixels on each side, e.g. 128x96")
        return cls(width, height)


def fit_to_aspect(pixels: int, aspect: float) -> Resolution:
    """The size with about ``pixels`` pixels and width / height = ``aspect`` (each side at least MIN_SIDE)."""
    aspect = aspect if math.isfinite(aspect) and aspect > 0 else 4 / 3
    width = max(MIN_SIDE, round(math.sqrt(pixels * aspect)))
    height = max(MIN_SIDE, round(width / aspect))
    return Resolution(width, height)


def preview_pixels(full_pixels: int, rays_per_second: float | None, budget_s: float) -> int:
    """Pixels of a preview that renders in about ``budget_s``: at most a quarter of the full image.

    Before the first render has measured the speed, the preview is a quarter of the full image (half each side).
    """
    quarter = max(MIN_SIDE * MIN_SIDE, full_pixels // 4)
    if not rays_per_second or rays_per_second <= 0:
        return quarter
    return int(min(quarter, max(MIN_SIDE * MIN_SIDE, rays_per_second * budget_s)))
