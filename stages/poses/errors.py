"""Errors of the pose stage: each says which frames, what went wrong and what to try."""

from __future__ import annotations

from stages.scene import InputError


class PoseQualityError(InputError):
    """Too few frames received a pose (the registration quality gate failed)."""


class StaticCameraError(InputError):
    """The camera does not move, so there is no baseline to triangulate from."""


class DegenerateTrajectoryError(PoseQualityError):
    """Frames registered, but the camera path is implausible (mostly one spot, or broken by jumps)."""
