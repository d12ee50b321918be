"""`livescene dataset orient` on a ready dataset without a point cloud: points triangulated from its images at
the given poses (stages/dataset/triangulation.py). It sits with the poses tests for their textured COLMAP room."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
from poses_testdata import SMALL_CAMERA, orbit_poses, write_sequence
from scipy.spatial.transform import Rotation

from stages.dataset.orient import axis_misalignment_deg, orient_dataset
from stages.scene import Frame, SceneDataset, write_scene


def test_a_tilted_dataset_without_points_is_turned_by_its_triangulated_points(tmp_path: Path) -> None:
    src = tmp_path / "ready"
    poses = orbit_poses(16)
    write_sequence(src, poses)  # the room's floor is z = 0, its walls on x and y
    shutil.rmtree(src / "masks")  # id maps of the poses tests, not the dataset's one-hot masks
    tilt = Rotation.from_euler("xyz", [22.0, -9.0, 31.0], degrees=True).as_matrix()
    move = np.eye(4)
    move[:3, :3], move[:3, 3] = tilt, [3.0, -1.0, 0.5]
    frames = [Frame(file_path=f"images/frame_{k:05d}.png", c2w=move @ c2w, split="test" if k % 4 == 0 else "train")
              for k, c2w in enumerate(poses)]
    write_scene(SceneDataset(root=src, camera=SMALL_CAMERA, frames=frames, objects=[]), src)

    ds, how = orient_dataset(src, tmp_path / "oriented")
    assert how.turned and how.points.startswith("triangulated from the given poses")
    assert how.frame is not None and how.frame.up_source == "point normals"
    new_from_room = how.new_from_old[:3, :3] @ tilt
    assert axis_misalignment_deg(new_from_room) < 1.0
    assert new_from_room[2, 2] > np.cos(np.radians(1.0))  # z is up again
    assert (ds.root / "points3D.ply").is_file() and ds.nerfstudio["ply_file_path"] == "points3D.ply"
    # the same dataset gives the same turn (one thread, seeded)
    _, again = orient_dataset(src, tmp_path / "again")
    assert np.array_equal(again.new_from_old, how.new_from_old)
