"""Does the camera's motion determine the focal length? A check without truth (docs/poses.md, "Known focal
length").

Structure from motion sees the focal length through the turning of the view. Cameras that only translate leave it
free: in their common frame, squeezing the scene and the camera centres across the view by ``s`` and dividing the
focal length by ``s`` gives every frame the same image (RADIAL's k1 and k2 follow as k1 / s^2 and k2 / s^4). A small
turn by ``a`` moves a pixel ``u`` px from the centre by ``f a + u^2 a / f``; the second term tells the focal, but it
points away from the centre, as the flow of a motion along the view does, so a camera that walks straight ahead
explains it by other point depths: on the walkfwd captures every frame registered at a normal reprojection error with
the focal 13-26 % off, while a camera walking sideways with the same hand shake (0.9 degrees of spread) got it within
1 %. The check therefore measures two numbers of the registered cameras: how far their viewing directions spread (the
root mean square of their angles to the mean viewing direction) and how much of the camera path runs along the mean
viewing direction. A spread under ``WARN_BELOW_DEG`` with a path mostly forward (over ``FORWARD_ABOVE``) gives a
warning naming the fix, a known focal length. It never changes the model.

Measured before choosing (docs/poses.md): the bundle adjustment cost's rise with the focal held 10 % off was 0.07 %
and 0.7 % on the two forward walks and 0.76-0.95 % on orbits with the focal within 3 %, so it does not separate
them, and five bundle adjustments cost 0.2-28 s; the two numbers here separate them and cost about a millisecond.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pycolmap

WARN_BELOW_DEG = 10.0
"""Warn when the viewing directions spread less than this (RMS angle to their mean; chosen from measurements:
docs/poses.md, "Known focal length")."""
FORWARD_ABOVE = 0.5
"""... and when more than this share of the camera path runs along the mean viewing direction (docs/poses.md)."""
FIX = "give --focal / --focal-35mm (the scene sheet's camera column)"


@dataclass
class FocalCheck:
    axis_spread_deg: float
    """RMS angle between the registered cameras' viewing directions and their mean direction."""
    forward_share: float
    """The camera path's length along the mean viewing direction over its whole length (1 = straight ahead, 0 =
    sideways)."""
    n_cameras: int
    focal_px: float
    focal: str
    """How the focal length was set: ``estimated``, ``given`` (kept as given) or ``given, refined``."""

    @property
    def poorly_constrained(self) -> bool:
        return self.focal != "given" and self.axis_spread_deg < WARN_BELOW_DEG and self.forward_share > FORWARD_ABOVE

    def as_dict(self) -> dict[str, Any]:
        return {
            "axis_spread_deg": self.axis_spread_deg,
            "forward_share": self.forward_share,
            "n_cameras": self.n_cameras,
            "focal_px": self.focal_px,
            "focal": self.focal,
            "warn_below_deg": WARN_BELOW_DEG,
            "forward_above": FORWARD_ABOVE,
            "poorly_constrained": self.poorly_constrained,
            "rule": "poorly constrained when the RMS angle of the registered cameras' viewing directions to their "
            "mean direction is under warn_below_deg and the share of the camera path along it over forward_above "
            "(a camera walking ahead without turning); docs/poses.md",
        }

    def warning(self) -> str | None:
        if not self.poorly_constrained:
            return None
        fix = FIX if self.focal == "estimated" else "leave out --refine-focal to keep the focal length given"
        return (
            f"the focal length ({self.focal_px:.1f} px, {self.focal}) is poorly constrained: the viewing directions "
            f"of the {self.n_cameras} cameras spread only {self.axis_spread_deg:.1f} degrees (RMS about their mean, "
            f"under {WARN_BELOW_DEG:g}) and {self.forward_share:.0%} of the camera path runs along the view (over "
            f"{FORWARD_ABOVE:.0%}), as in a walk straight ahead; structure from motion cannot tell the focal length "
            "from that motion, and every frame registers with a normal reprojection error while it is off (13-26 % "
            f"on the forward walks measured in docs/poses.md), with the poses drifting; fix: {fix}"
        )


def check_model_focal(
    reconstruction: pycolmap.Reconstruction, order: list[str] | None = None, focal: str = "estimated"
) -> FocalCheck:
    """``check_focal`` on the registered images of a model, in the playback ``order`` of their names (default: image
    id order), and its first camera's focal length."""
    images = sorted(reconstruction.images.values(), key=lambda image: image.image_id)
    if order is not None:
        rank = {name: k for k, name in enumerate(order)}
        images.sort(key=lambda image: rank.get(image.name, len(rank)))
    rotations, centres = [], []
    for image in images:
        if image.has_pose:
            pose = image.cam_from_world()
            rotation = pose.rotation.matrix()
            rotations.append(rotation)
            centres.append(-rotation.T @ pose.translation)
    camera = next(iter(reconstruction.cameras.values()))
    return check_focal(np.array(rotations), np.array(centres), float(camera.mean_focal_length()), focal)


def check_focal(
    cam_from_world: np.ndarray, centres: np.ndarray, focal_px: float, focal: str = "estimated"
) -> FocalCheck:
    """The spread of the viewing directions of cameras ``cam_from_world`` [N, 3, 3] (COLMAP / OpenCV axes: the view
    is the third row) with centres [N, 3] in path order, and the path's share along the mean view."""
    rotations = np.asarray(cam_from_world, dtype=np.float64).reshape(-1, 3, 3)
    views = rotations[:, 2, :]
    mean = views.mean(axis=0)
    norm = float(np.linalg.norm(mean))
    if len(views) == 0 or norm < 1e-9:  # no camera, or views spread all round: nothing to warn about
        spread = 90.0 if len(views) else 0.0
        mean = np.zeros(3)
    else:
        mean /= norm
        spread = float(np.degrees(np.sqrt(np.mean(np.arccos(np.clip(views @ mean, -1.0, 1.0)) ** 2))))
    steps = np.diff(np.asarray(centres, dtype=np.float64).reshape(-1, 3), axis=0)
    length = float(np.sum(np.linalg.norm(steps, axis=1)))
    forward = float(np.sum(np.abs(steps @ mean)) / length) if length > 0 else 0.0
    return FocalCheck(
        axis_spread_deg=spread, forward_share=forward, n_cameras=len(views), focal_px=focal_px, focal=focal
    )
