"""Camera poses with COLMAP (pycolmap 4.2.1), a registration quality gate, and pose-error reports."""

from .comparison import compare_poses
from .config import PosesConfig
from .conventions import (
    c2w_opengl_from_cam_from_world,
    cam_from_world_from_c2w_opengl,
    quaternion_wxyz_from_rotation,
    rotation_angle_deg,
    rotation_from_quaternion_wxyz,
)
from .errors import PoseQualityError, StaticCameraError
from .pipeline import estimate_poses

__all__ = [
    "PoseQualityError",
    "PosesConfig",
    "StaticCameraError",
    "c2w_opengl_from_cam_from_world",
    "cam_from_world_from_c2w_opengl",
    "compare_poses",
    "estimate_poses",
    "quaternion_wxyz_from_rotation",
    "rotation_angle_deg",
    "rotation_from_quaternion_wxyz",
]
