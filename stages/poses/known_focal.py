"""A focal length the user knows (``livescene poses --focal`` / ``--focal-35mm``), as COLMAP users give it with
``--ImageReader.camera_params`` and a bundle adjustment that keeps it (docs/poses.md, "Known focal length").

A camera that walks straight ahead sees every point along nearly the same ray, so the focal length and the motion
along the view direction trade against each other and structure from motion can settle 13-26 % off while every
frame registers with a normal reprojection error (the walkfwd captures, docs/poses.md); a known focal removes
that freedom.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from stages.scene import InputError

FULL_FRAME_DIAGONAL_MM = 43.27
"""Diagonal of a 36 x 24 mm frame: a 35 mm-equivalent focal length is the focal for an image of that diagonal."""
MIN_DIAGONAL_FOV_DEG = 1.0
"""A given focal length narrower than this diagonal field of view is refused (a 35 mm equivalent of 2,500 mm)."""
MAX_DIAGONAL_FOV_DEG = 160.0
"""A given focal length wider than this diagonal field of view is refused: no pinhole camera model describes such a
lens (a 35 mm equivalent of 3.8 mm; phones' widest lenses are about 13 mm, 118 degrees)."""
REFINED_RATIO = (0.8, 1.25)
"""With ``--refine-focal``, a refined focal length outside these times the given one is warned of: the bound by which
the poses stage calls fx and fy of one camera too far apart (quality_gate.intrinsics_warnings)."""


@dataclass(frozen=True)
class KnownFocal:
    """A focal length in pixels of the frames as written, where it came from, and whether COLMAP may refine it."""

    focal_px: float
    given: str
    """The flag as given, e.g. ``--focal 1375`` or ``--focal-35mm 26``."""
    refine: bool
    width: int
    height: int

    def camera_params(self, model: str) -> str:
        """COLMAP's parameter string for ``model``: the focal, the principal point at the image centre (COLMAP's
        own default), distortion zero to start from (still estimated when the model has it)."""
        f, cx, cy = self.focal_px, self.width / 2.0, self.height / 2.0
        extra = {"SIMPLE_PINHOLE": 0, "SIMPLE_RADIAL": 1, "RADIAL": 2, "PINHOLE": 0, "OPENCV": 4}[model]
        focal = [f, f] if model in ("PINHOLE", "OPENCV") else [f]
        return ",".join(repr(float(v)) for v in [*focal, cx, cy, *[0.0] * extra])

    def refined_warning(self, focal_px: float) -> str | None:
        """A warning when bundle adjustment, let refine the given focal length (``refine``), ended at ``focal_px``
        outside ``REFINED_RATIO`` of it: a known value that moved that far is contradicted, not refined."""
        ratio = focal_px / self.focal_px
        if not self.refine or REFINED_RATIO[0] <= ratio <= REFINED_RATIO[1]:
            return None
        return (f"--refine-focal moved the given focal length ({self.given}: {self.focal_px:.1f} px) to "
                f"{focal_px:.1f} px ({100 * (ratio - 1):+.0f} %), outside {REFINED_RATIO[0]:g}..{REFINED_RATIO[1]:g} "
                "times it: bundle adjustment drifted (docs/poses.md, Known focal length) or the value given is wrong; "
                "fix: check the value and its unit, then leave out --refine-focal to keep it as given")

    def as_dict(self) -> dict[str, Any]:
        return {
            "focal_px": self.focal_px,
            "given": self.given,
            "refined": self.refine,
            "diagonal_fov_deg": diagonal_fov_deg(self.focal_px, self.width, self.height),
        }


def diagonal_fov_deg(focal_px: float, width: int, height: int) -> float:
    return 2.0 * math.degrees(math.atan(0.5 * math.hypot(width, height) / focal_px))


def known_focal(
    focal_px: float | None, focal_35mm: float | None, refine: bool, width: int, height: int, frames_dir: Path
) -> KnownFocal | None:
    """The focal length the flags give for frames of ``width`` x ``height``, or None when none is given.

    Raises InputError for both flags at once, a value that is not positive, ``refine`` without a focal, and a focal
    whose diagonal field of view is outside ``MIN_DIAGONAL_FOV_DEG`` .. ``MAX_DIAGONAL_FOV_DEG``."""
    if focal_px is not None and focal_35mm is not None:
        raise InputError(
            Path("--focal"),
            f"both --focal {focal_px:g} and --focal-35mm {focal_35mm:g} are given",
            "give one of them: --focal in pixels of the frames as written, or --focal-35mm as a phone's "
            "spec sheet states it",
        )
    if focal_px is None and focal_35mm is None:
        if refine:
            raise InputError(
                Path("--refine-focal"),
                "--refine-focal without a focal length to start from (without "
                "one the focal length is estimated and refined anyway)",
                "give --focal PX or --focal-35mm MM, or leave out --refine-focal",
            )
        return None
    flag, value = ("--focal", focal_px) if focal_px is not None else ("--focal-35mm", focal_35mm)
    assert value is not None
    if not math.isfinite(value) or value <= 0:
        raise InputError(
            Path(flag),
            f"{value:g} is not a positive focal length",
            "give the focal length in pixels of the frames (--focal) or in 35 mm-equivalent "
            "millimetres (--focal-35mm), e.g. --focal-35mm 26 for a phone's main camera",
        )
    diagonal = math.hypot(width, height)
    focal = value if focal_px is not None else value * diagonal / FULL_FRAME_DIAGONAL_MM
    fov = diagonal_fov_deg(focal, width, height)
    if not MIN_DIAGONAL_FOV_DEG <= fov <= MAX_DIAGONAL_FOV_DEG:
        unit = "px" if focal_px is not None else "mm (35 mm equivalent)"
        hint = (
            f"; --focal is in pixels of the frames as written ({width}x{height}): a focal length of the "
            f"full-size video shrinks with the frames"
            if focal_px is not None
            else ""
        )
        raise InputError(
            frames_dir,
            f"{flag} {value:g} {unit} gives the {width}x{height} frames a diagonal field of "
            f"view of {fov:.1f} degrees, outside {MIN_DIAGONAL_FOV_DEG:g}..{MAX_DIAGONAL_FOV_DEG:g}" + hint,
            "check the value and its unit (--focal: pixels of the frames; --focal-35mm: the "
            "35 mm-equivalent millimetres of a spec sheet), or leave both out to estimate it",
        )
    return KnownFocal(focal_px=float(focal), given=f"{flag} {value:g}", refine=refine, width=width, height=height)
