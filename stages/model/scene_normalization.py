"""Scene normalisation into [-1, 1]^3 and the axis-aligned box collider that gives each ray its near/far.

The similarity comes from scene.json's ``scene_box`` (or, without one, from a
padded box around the camera centres); it is a uniform scale plus a
translation, so ray directions are unchanged and distances scale by ``scale``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from stages.scene import SceneDataset, box_to_unit_transform
from stages.scene.normalization import camera_bounds_box


@dataclass
class SceneNormalization:
    """``x_unit = scale * x_world + offset``."""

    transform: np.ndarray
    """4x4 similarity, dataset world -> normalised box."""
    source: str
    """Where the box came from: 'scene_box' or 'camera_bounds'."""

    @property
    def scale(self) -> float:
        return float(np.cbrt(abs(np.linalg.det(self.transform[:3, :3]))))

    @classmethod
    def from_dataset(cls, ds: SceneDataset, camera_margin: float = 0.25) -> SceneNormalization:
        if ds.scene_box is not None:
            return cls(box_to_unit_transform(ds.scene_box[0], ds.scene_box[1]), "scene_box")
        centres = np.stack([np.asarray(f.c2w)[:3, 3] for f in ds.frames])
        lo, hi = camera_bounds_box(centres, camera_margin)
        return cls(box_to_unit_transform(lo, hi), "camera_bounds")

    def points(self, points: np.ndarray) -> np.ndarray:
        return np.asarray(points, float) @ self.transform[:3, :3].T + self.transform[:3, 3]

    def pose(self, c2w: np.ndarray) -> np.ndarray:
        """Camera-to-world in normalised coordinates (rotation kept orthonormal)."""
        out = np.asarray(c2w, dtype=np.float64).copy()
        out[:3, 3] = self.points(out[:3, 3])
        return out

    def to_dict(self) -> dict:
        return {"transform": self.transform.tolist(), "scale": self.scale, "source": self.source}

    @classmethod
    def from_dict(cls, data: dict) -> SceneNormalization:
        return cls(np.asarray(data["transform"], dtype=np.float64), str(data.get("source", "scene_box")))


def aabb_near_far(origins: torch.Tensor, directions: torch.Tensor, near_plane: float,
                  bound: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
    """Entry and exit distances of rays through the box [-bound, bound]^3 (slab method).

    Rays that miss the box get a tiny interval just past ``near_plane``: they
    render background, and nothing divides by zero.
    """
    d = torch.where(directions.abs() < 1e-9, torch.full_like(directions, 1e-9), directions)
    t1 = (-bound - origins) / d
    t2 = (bound - origins) / d
    t_enter = torch.minimum(t1, t2).amax(dim=-1)
    t_exit = torch.maximum(t1, t2).amin(dim=-1)
    nears = t_enter.clamp(min=near_plane)
    fars = torch.maximum(t_exit, nears + 1e-4)
    return nears, fars
