"""Poses to compare, read from a transforms.json or from a COLMAP model folder.

Each frame keeps what can identify it (its file path or COLMAP image name,
its source index, its position in the file) so that ``frame_matching`` can
pair frames of the same capture however the two sides named them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import numpy as np
import pycolmap

from stages.scene import Camera, InputError
from stages.scene.transforms import camera_from_dict, load_json, parse_pose

from .conventions import c2w_opengl_from_cam_from_world

COLMAP_MODEL_FILES = ("cameras", "images")
"""A folder is read as a COLMAP model when it holds these (``.bin`` or ``.txt``)."""


@dataclass
class PoseEntry:
    """One posed frame of a pose file."""

    position: int
    """Index of the frame in the file (transforms.json frames list; COLMAP: image name order)."""
    file_path: str | None
    """transforms.json ``file_path`` or the COLMAP image name; None when the frame carries neither."""
    source_index: int | None
    """``source_index`` of the frame when the file records one (this project's extension)."""
    c2w: np.ndarray
    """4x4 camera-to-world, OpenGL camera axes."""

    @property
    def label(self) -> str:
        """How the frame is named in reports: the image stem, else its position."""
        if self.file_path:
            return Path(self.file_path).stem
        if self.source_index is not None:
            return f"source_index {self.source_index}"
        return f"#{self.position} (no file_path)"


@dataclass
class PoseSet:
    """The posed frames of one file and its shared camera."""

    path: Path
    kind: str
    """``transforms.json`` or ``COLMAP model``."""
    entries: list[PoseEntry]
    camera: Camera


def is_colmap_model(path: Path) -> bool:
    path = Path(path)
    return path.is_dir() and all((path / f"{n}.bin").is_file() or (path / f"{n}.txt").is_file()
                                 for n in COLMAP_MODEL_FILES)


def read_pose_set(path: Path) -> PoseSet:
    """Posed frames of a transforms.json, a COLMAP model folder, or a folder holding either.

    A folder is read as a COLMAP model (``cameras``/``images`` ``.bin``/``.txt``), else its
    ``transforms.json``, else its ``sparse/0`` model.
    """
    path = Path(path)
    if path.is_dir():
        if is_colmap_model(path):
            return _read_colmap(path)
        if (path / "transforms.json").is_file():
            return _read_transforms(path / "transforms.json")
        if is_colmap_model(path / "sparse" / "0"):
            return _read_colmap(path / "sparse" / "0")
        raise InputError(path, "folder holds neither a COLMAP model (cameras/images .bin or .txt) nor a "
                               "transforms.json", "pass a transforms.json or a COLMAP model folder such as sparse/0")
    return _read_transforms(path)


def _optional_int(value: Any) -> int | None:
    try:
        return int(value) if value is not None else None
    except (TypeError, ValueError):
        return None


def _read_transforms(path: Path) -> PoseSet:
    data = load_json(path)
    frames = data.get("frames")
    if not isinstance(frames, list) or not frames:
        raise InputError(path, "no frames", "pass a transforms.json with a non-empty frames list")
    entries = []
    for k, frame in enumerate(frames):
        if not isinstance(frame, dict):
            raise InputError(path, f"frame {k} is not a JSON object", "regenerate the file")
        file_path = frame.get("file_path")
        file_path = str(file_path) if file_path not in (None, "") else None
        where = f"frame {k} ({file_path or 'no file_path'})"
        entries.append(PoseEntry(position=k, file_path=file_path,
                                 source_index=_optional_int(frame.get("source_index")),
                                 c2w=parse_pose(frame.get("transform_matrix"), path, where)))
    return PoseSet(path=path, kind="transforms.json", entries=entries,
                   camera=camera_from_dict(data, path, "top level"))


def _read_colmap(folder: Path) -> PoseSet:
    try:
        rec = pycolmap.Reconstruction(str(folder))
    except Exception as exc:  # pycolmap raises its own error types for unreadable models
        raise InputError(folder, f"COLMAP model unreadable ({exc})", "re-export the model from COLMAP") from exc
    cameras = list(rec.cameras.values())
    if not cameras:
        raise InputError(folder, "COLMAP model without cameras", "re-export the model from COLMAP")
    cam = cameras[0]  # the focal error is reported for the first camera; poses are compared frame by frame
    camera = Camera(fx=float(cam.focal_length_x), fy=float(cam.focal_length_y), cx=float(cam.principal_point_x),
                    cy=float(cam.principal_point_y), width=int(cam.width), height=int(cam.height))
    images = sorted((img for img in rec.images.values() if img.has_pose), key=lambda img: img.name)
    if not images:
        raise InputError(folder, "COLMAP model without posed images", "re-run or re-export the reconstruction")
    entries = []
    for k, img in enumerate(images):
        pose = img.cam_from_world()
        entries.append(PoseEntry(position=k, file_path=img.name, source_index=None,
                                 c2w=c2w_opengl_from_cam_from_world(pose.rotation.matrix(), pose.translation)))
    return PoseSet(path=folder, kind="COLMAP model", entries=entries, camera=camera)
