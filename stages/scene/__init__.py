"""The scene dataset contract shared by every stage: layout, cameras, rays, validation."""

from .atomic_io import (
    STAGE_MARKER,
    atomic_dir,
    atomic_path,
    guard_output_dir,
    guard_output_file,
    write_json,
    write_npy,
    write_text,
    write_yaml,
)
from .camera import Camera, generate_rays, look_at, opencv_to_opengl, opengl_to_opencv, project_points
from .dataset import Frame, SceneDataset, read_scene, validate_scene, write_scene
from .errors import InputError, SceneError
from .keyframes import frame_id_of, frame_number_of, read_key_frames, write_key_frames
from .masks import label_map_to_onehot, onehot_to_label_map, read_mask, write_mask
from .normalization import (
    apply_similarity_to_points,
    apply_similarity_to_pose,
    box_to_unit_transform,
)
from .splits import make_split
from .yaml_io import read_yaml_mapping

__all__ = [
    "STAGE_MARKER",
    "Camera",
    "Frame",
    "InputError",
    "SceneDataset",
    "SceneError",
    "apply_similarity_to_points",
    "apply_similarity_to_pose",
    "atomic_dir",
    "atomic_path",
    "box_to_unit_transform",
    "frame_id_of",
    "frame_number_of",
    "generate_rays",
    "guard_output_dir",
    "guard_output_file",
    "label_map_to_onehot",
    "look_at",
    "make_split",
    "onehot_to_label_map",
    "opencv_to_opengl",
    "opengl_to_opencv",
    "project_points",
    "read_key_frames",
    "read_mask",
    "read_scene",
    "read_yaml_mapping",
    "validate_scene",
    "write_json",
    "write_key_frames",
    "write_mask",
    "write_npy",
    "write_scene",
    "write_text",
    "write_yaml",
]
