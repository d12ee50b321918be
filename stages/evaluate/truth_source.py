"""The ground truth of a synthetic capture, seen from the model's world.

The dataset world may be the truth world (a dataset written from the truth)
or a COLMAP world (estimated poses: arbitrary scale, turned upright and to
the walls by the poses stage; docs/poses.md "World frame").
For a dataset frame, the truth pose is taken, in order of preference:

1. from ``truth/transforms.json`` by the frame's ``source_index`` (the very
   camera that took the image: no alignment error enters the comparison);
2. by mapping the dataset pose into the truth world with the inverse of the
   similarity in ``pose_error.json`` (``sim3`` maps truth world -> pred world,
   written by ``livescene poses compare``);
3. as the dataset pose itself, only when the dataset is in truth units.

The model always renders at the dataset pose with the dataset camera (the
world it was trained in); the truth renders at the truth pose with the truth
camera scaled to the dataset's image size. When both 1 and 2 are possible the
residual of the alignment is reported, so a reader can judge it.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import yaml

from stages.scene import Camera, Frame, InputError, apply_similarity_to_pose
from stages.scene.transforms import camera_from_dict


class TruthRendererLike(Protocol):
    """What evaluation needs of ``stages.capture.TruthRenderer``."""

    def render(self, c2w: np.ndarray, states: Any, camera: Camera | None = None) -> dict[str, np.ndarray]: ...


@dataclass
class TruthSource:
    """A truth renderer plus the truth poses, states, camera and object ids of the capture."""

    renderer: TruthRendererLike
    camera: Camera
    """Intrinsics of the truth capture (full resolution)."""
    object_ids: dict[str, int]
    """Object name -> pixel value of the renderer's ``ids`` (mapping.yaml of the capture)."""
    poses: dict[int, np.ndarray] = field(default_factory=dict)
    """Source video index -> truth camera-to-world (OpenGL)."""
    states: dict[int, dict[str, float]] = field(default_factory=dict)
    """Source video index -> dense truth state."""
    sim3: np.ndarray | None = None
    """4x4 similarity truth world -> dataset world (pose_error.json), when the dataset uses estimated poses."""
    same_world: bool = True
    """True when dataset poses are in truth coordinates (dataset written from the truth)."""
    origin: str = ""
    """Where the truth came from (for metrics.json)."""

    @classmethod
    def from_capture(cls, capture_dir: str | Path, pose_alignment: str | Path | None = None,
                     same_world: bool = True) -> TruthSource:
        capture_dir = Path(capture_dir)
        from stages.capture import TruthRenderer  # imported on use: only an evaluation with --truth needs it

        tpath = capture_dir / "truth" / "transforms.json"
        if not tpath.is_file():
            raise InputError(tpath, "no truth transforms.json in this capture",
                             "pass --truth the folder written by `livescene capture`")
        data = json.loads(tpath.read_text())
        camera = camera_from_dict(data, tpath, "top level")
        poses, states = {}, {}
        for i, fr in enumerate(data.get("frames", [])):
            idx = int(fr.get("source_index", i))
            poses[idx] = np.asarray(fr["transform_matrix"], dtype=np.float64)
            if isinstance(fr.get("state"), Mapping):
                states[idx] = {str(k): float(v) for k, v in fr["state"].items()}
        mpath = capture_dir / "mapping.yaml"
        try:
            mapping = yaml.safe_load(mpath.read_text()) or {}
            object_ids = {str(name): int(k) for k, name in mapping.items()}
        except (OSError, yaml.YAMLError, ValueError, AttributeError) as exc:
            raise InputError(mpath, f"cannot read the capture's object ids ({exc})",
                             "regenerate the capture") from exc
        sim3 = read_sim3(pose_alignment) if pose_alignment else None
        return cls(renderer=TruthRenderer.from_capture(capture_dir), camera=camera, object_ids=object_ids,
                   poses=poses, states=states, sim3=sim3, same_world=same_world and sim3 is None,
                   origin=str(capture_dir))

    def after_turn(self, meta: Mapping[str, Any]) -> TruthSource:
        """This source for a dataset whose scene.json ``meta`` may record a turn by ``livescene dataset orient``.

        A turned copy of a dataset in the truth's own world is no longer in it: the turn (``new_from_old``)
        maps truth to dataset poses, so it serves as the pose alignment (docs/poses.md, "Ready datasets")."""
        turned = meta.get("orientation") or {}
        if not (turned.get("turned") and self.same_world):
            return self
        return dataclasses.replace(self, sim3=np.asarray(turned["new_from_old"], dtype=np.float64), same_world=False)

    def camera_for(self, width: int, height: int) -> Camera:
        """The truth camera at the dataset's image size (the dataset may use downscaled images)."""
        if (width, height) == (self.camera.width, self.camera.height):
            return self.camera
        factor = width / self.camera.width
        cam = self.camera.scaled(factor)
        if (cam.width, cam.height) != (width, height):
            raise InputError(self.origin, f"truth images are {self.camera.width}x{self.camera.height}, the dataset's "
                             f"{width}x{height}: not one scale factor", "evaluate on a dataset of the same capture")
        return cam

    def pose_for(self, frame: Frame) -> tuple[np.ndarray, str]:
        """Truth camera-to-world of a dataset frame and how it was obtained (see module docstring)."""
        if frame.source_index is not None and frame.source_index in self.poses:
            return self.poses[frame.source_index], "source_index"
        if self.sim3 is not None:
            return apply_similarity_to_pose(np.linalg.inv(self.sim3), np.asarray(frame.c2w, float)), "sim3"
        if self.same_world:
            return np.asarray(frame.c2w, float), "dataset pose (same world)"
        raise InputError(self.origin, f"frame {frame.file_path} has no source_index in the truth and no pose alignment",
                         "pass --pose-alignment pose_error.json from `livescene poses compare`")

    def state_for(self, frame: Frame) -> dict[str, float] | None:
        if frame.source_index is not None and frame.source_index in self.states:
            return self.states[frame.source_index]
        return frame.state

    def alignment_residual(self, frames: list[Frame]) -> dict[str, float] | None:
        """How far sim3-mapped truth camera centres land from the dataset's, relative to the camera spread."""
        if self.sim3 is None:
            return None
        pairs = [(self.poses[f.source_index], f.c2w) for f in frames
                 if f.source_index is not None and f.source_index in self.poses]
        if not pairs:
            return None
        mapped = np.array([apply_similarity_to_pose(self.sim3, t)[:3, 3] for t, _ in pairs])
        pred = np.array([np.asarray(p, float)[:3, 3] for _, p in pairs])
        spread = float(np.linalg.norm(pred.max(0) - pred.min(0))) or 1.0
        err = np.linalg.norm(mapped - pred, axis=1)
        return {"mean_centre_error": float(err.mean()), "max_centre_error": float(err.max()),
                "relative_to_camera_spread": float(err.mean() / spread), "n_frames": len(pairs)}


def read_sim3(path: str | Path) -> np.ndarray:
    """The 4x4 ``sim3`` (truth world -> pred world) of a pose_error.json."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        sim3 = np.asarray(data["sim3"], dtype=np.float64)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(path, f"no readable 'sim3' ({exc})",
                         "write it with `livescene poses compare --pred P --truth T --out pose_error.json`") from exc
    if sim3.shape != (4, 4) or not np.isfinite(sim3).all() or abs(np.linalg.det(sim3[:3, :3])) < 1e-12:
        raise InputError(path, f"sim3 is not a finite invertible 4x4 matrix (shape {sim3.shape})",
                         "re-run `livescene poses compare`")
    return sim3
