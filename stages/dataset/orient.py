"""``livescene dataset orient``: a ready dataset turned into the upright, wall-aligned world of the poses stage.

Poses that come with the data (a nerfstudio folder from ``ns-process-data``, a dataset exported elsewhere) lie
in whatever world their tool left them in; COLMAP's leaves a room's floor and walls at 20-30 degrees to the
axes, and every field of the model stage factorises space into axis-aligned planes (docs/poses.md, "World
frame": the upright world was worth 0.5-1.1 dB held-out on the demo). This writes a copy of the dataset whose
poses, point cloud and scene box are in the frame ``stages.poses.world_frame`` estimates from the dataset's
own point cloud (``ply_file_path``, or ``--points``; without one, points triangulated from its images at the
given poses, triangulation.py); the source folder is only read.

The world is kept as it is, and the copy says why, when

- there is no point cloud and triangulation is off: the cameras' up vector alone is biased by their pitch
  (20 degrees on the demo capture), so turning by it could tilt an upright dataset;
- the points show no floor or ceiling (the up vector would come from the cameras alone);
- the dataset's axes already lie within ``ALIGNED_DEG`` of the estimated ones, up to a relabelling of
  the axes (a dataset written from a capture's truth, or already oriented).

Images and masks are hard-linked into the copy (copied across file systems), so it stands on its own.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d

from stages.poses.model_export import inlier_points, scene_box, write_ply
from stages.poses.world_frame import NORMAL_NEIGHBOURS, WorldFrame, estimate_world_frame
from stages.scene import SceneDataset, SceneError, atomic_dir, read_scene, write_scene
from stages.scene.masks import mask_path
from stages.scene.transforms import resolve_image_path

from .assemble import POINTS_NAME, place_image

ALIGNED_DEG = 1.0
"""A dataset whose axes lie this close to the estimated ones (up to a signed permutation) keeps its world."""


@dataclass
class Orientation:
    """What ``orient_dataset`` did and why."""

    turned: bool
    reason: str
    new_from_old: np.ndarray
    """4x4 rigid motion applied to the poses and points (identity when not turned)."""
    frame: WorldFrame | None
    """The estimated frame (None without a point cloud)."""
    misalignment_deg: float | None
    """Largest angle between one of the dataset's axes and the nearest estimated axis (None without points)."""
    points: str | None

    def as_dict(self, source: Path) -> dict[str, Any]:
        return {"turned": self.turned, "reason": self.reason, "new_from_old": self.new_from_old.tolist(),
                "misalignment_deg": self.misalignment_deg, "points": self.points, "from": str(source),
                "world_frame": None if self.frame is None else self.frame.as_dict(),
                "rule": "docs/poses.md, 'World frame'; turned only with a point cloud that shows a floor or "
                        f"ceiling, and only when the axes are more than {ALIGNED_DEG} degrees off"}


def axis_misalignment_deg(rotation: np.ndarray) -> float:
    """Largest angle (degrees) between a row of ``rotation`` and the nearest coordinate axis, either sign."""
    nearest = np.clip(np.abs(np.asarray(rotation, dtype=np.float64)).max(axis=1), -1.0, 1.0)
    return float(np.degrees(np.arccos(nearest)).max())


def _points_path(ds: SceneDataset, points: Path | None) -> Path | None:
    if points is not None:
        return Path(points)
    ply = ds.nerfstudio.get("ply_file_path")
    return None if ply is None else ds.root / str(ply)


def _read_points(path: Path) -> o3d.geometry.PointCloud:
    if not path.is_file():
        raise SceneError(path, "point cloud not found", "pass --points PLY, or drop ply_file_path from transforms.json")
    cloud = o3d.io.read_point_cloud(str(path))
    if not len(cloud.points):
        raise SceneError(path, "no points could be read (not a PLY point cloud, or empty)",
                         "pass --points with the dataset's sparse point cloud (e.g. COLMAP's points3D.ply)")
    return cloud


def estimate_orientation(ds: SceneDataset, cloud: o3d.geometry.PointCloud | None, points: str | None
                         ) -> Orientation:
    """Decide whether and how to turn ``ds`` (see the module docstring)."""
    keep = np.eye(4)
    if cloud is None:
        return Orientation(False, "no point cloud (ply_file_path or --points) and no triangulation: the cameras' "
                                  "up vector alone is biased by their pitch", keep, None, None, None)
    kept = np.asarray(inlier_points(cloud).points)
    c2w = np.stack([np.asarray(f.c2w, dtype=np.float64) for f in ds.frames])
    if len(kept) <= NORMAL_NEIGHBOURS:
        return Orientation(False, f"{len(kept)} points after outlier removal: too few for normals", keep, None,
                           None, points)
    frame = estimate_world_frame(kept, c2w)
    off = axis_misalignment_deg(frame.rotation)
    if frame.up_source != "point normals":
        return Orientation(False, "the points show no floor or ceiling: up would come from the cameras alone",
                           keep, frame, off, points)
    if off <= ALIGNED_DEG:
        return Orientation(False, f"axes already within {off:.2f} degrees of the room's", keep, frame, off, points)
    matrix = np.eye(4)
    matrix[:3] = frame.matrix
    return Orientation(True, f"axes {off:.1f} degrees off the room's", matrix, frame, off, points)


def _inside(rel: str) -> bool:
    parts = Path(rel).parts
    return not Path(rel).is_absolute() and ".." not in parts


def orient_dataset(src: str | Path, out: str | Path, points: str | Path | None = None, triangulate: bool = True,
                   seed: int = 0) -> tuple[SceneDataset, Orientation]:
    """Write ``src`` to ``out`` in the upright world (or unchanged, with the reason); return both.

    Without a point cloud (``points`` or the dataset's ``ply_file_path``) and with ``triangulate``, the points
    are triangulated from the dataset's images at their given poses (triangulation.py)."""
    src, out = Path(src), Path(out)
    if src.resolve() == out.resolve():
        raise SceneError(out, "the output folder is the dataset itself", "write the oriented copy elsewhere")
    ds = read_scene(src)
    ppath = _points_path(ds, None if points is None else Path(points))
    cloud = _read_points(ppath) if ppath is not None else None
    origin = None if ppath is None else str(ppath)
    if cloud is None and triangulate:
        from .triangulation import triangulate_dataset  # imported on use: COLMAP runs only here

        cloud = triangulate_dataset(ds, seed)
        origin = f"triangulated from the given poses ({len(cloud.points)} points)"
    orient = estimate_orientation(ds, cloud, origin)
    m = orient.new_from_old

    frames, names = [], {}
    for f in ds.frames:
        rel = f.file_path if _inside(f.file_path) else f"images/{Path(f.file_path).name}"
        source = resolve_image_path(ds.root, f.file_path)
        if names.setdefault(rel, source) != source:
            raise SceneError(src / "transforms.json", f"two frames' images would share {rel!r} in the copy",
                             "give the images distinct file names")
        frames.append(replace(f, file_path=rel, c2w=m @ np.asarray(f.c2w, dtype=np.float64)))

    nerfstudio = dict(ds.nerfstudio)
    applied = np.eye(4)
    if "applied_transform" in nerfstudio:
        given = np.asarray(nerfstudio["applied_transform"], dtype=np.float64)
        applied[: given.shape[0]] = given
    nerfstudio["applied_transform"] = (m @ applied)[:3].tolist()  # nerfstudio's record of what moved the poses
    box = ds.scene_box
    turned_cloud = None
    if cloud is not None:
        nerfstudio["ply_file_path"] = POINTS_NAME
        turned_cloud = o3d.geometry.PointCloud(cloud)
        turned_cloud.transform(m)
    meta = dict(ds.meta)
    if turned_cloud is not None and (orient.turned or box is None):
        # turned: the given box no longer fits the room; kept without a box of its own (a published set rendered
        # upright): the points give one, where the box around the cameras alone leaves out the walls they face
        centres = np.stack([f.c2w[:3, 3] for f in frames])
        box, box_info = scene_box(turned_cloud, centres)
        meta.update(box_info, scene_box_rule="open3d statistical outlier removal on the "
                                             f"{'turned ' if orient.turned else ''}points, grown to include the "
                                             "camera centres")
    meta["orientation"] = orient.as_dict(src)
    new = replace(ds, frames=frames, scene_box=box, meta=meta, nerfstudio=nerfstudio)

    with atomic_dir(out, "dataset", inputs=[src], legacy=["scene.json"]) as tmp:
        for rel, source in names.items():
            (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
            place_image(source, tmp / rel, copy=False)
        if ds.has_masks:
            (tmp / "masks").mkdir()
            for f in ds.frames:
                mask = mask_path(ds.root, f.frame_id)
                if mask.is_file():
                    place_image(mask, mask_path(tmp, f.frame_id), copy=False)
        if turned_cloud is not None:
            write_ply(turned_cloud, tmp / POINTS_NAME)
        write_scene(new, tmp)
        read_scene(tmp)  # the copy must satisfy the contract before it replaces anything
    return read_scene(out, validate=False), orient
