"""The gravity- and wall-aligned world frame (stages/poses/world_frame.py)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from stages.poses.world_frame import estimate_world_frame
from stages.scene.camera import look_at


def _room_points(rng: np.random.Generator, n: int = 3000, noise: float = 0.01) -> np.ndarray:
    """Points on the floor, ceiling and four walls of a 5 x 4 x 2.6 m room (z up), a little noisy."""
    size = np.array([5.0, 4.0, 2.6])
    faces = rng.integers(0, 6, n)
    pts = rng.uniform(0.0, 1.0, (n, 3)) * size
    axis, side = faces // 2, faces % 2
    pts[np.arange(n), axis] = side * size[axis]
    return pts - size / 2 + rng.normal(0.0, noise, (n, 3))


def _orbit(n: int = 30, pitch_target_z: float = -0.6) -> np.ndarray:
    """OpenGL camera-to-world poses on a 120-degree arc, looking down at a point below eye height."""
    c2w = []
    for a in np.radians(np.linspace(-60, 60, n)):
        eye = np.array([1.5 * np.cos(a), 1.5 * np.sin(a), 0.3])
        c2w.append(look_at(eye, np.array([0.0, 0.0, pitch_target_z])))
    return np.stack(c2w)


def _angle_to_axes(rotation: np.ndarray) -> float:
    """Degrees from ``rotation`` to the nearest rotation that permutes or flips axes."""
    best = 180.0
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product([1.0, -1.0], repeat=3):
            p = np.zeros((3, 3))
            p[range(3), perm] = signs
            if np.linalg.det(p) > 0:
                best = min(best, Rotation.from_matrix(p.T @ rotation).magnitude())
    return float(np.degrees(best))


def _move(points: np.ndarray, c2w: np.ndarray, old_from_room: np.ndarray, t: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    moved = c2w.copy()
    moved[:, :3, :3] = old_from_room @ c2w[:, :3, :3]
    moved[:, :3, 3] = c2w[:, :3, 3] @ old_from_room.T + t
    return points @ old_from_room.T + t, moved


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_tilted_room_comes_back_to_its_axes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    old_from_room = Rotation.random(random_state=seed).as_matrix()
    points, c2w = _move(_room_points(rng), _orbit(), old_from_room, rng.normal(0.0, 3.0, 3))
    frame = estimate_world_frame(points, c2w)
    new_from_room = frame.rotation @ old_from_room
    assert _angle_to_axes(new_from_room) < 0.5
    assert new_from_room[2] @ np.array([0.0, 0.0, 1.0]) > np.cos(np.radians(0.5))  # z is up, not a wall's normal
    assert (frame.up_source, frame.yaw_source) == ("point normals", "wall normals")
    assert frame.up_tilt_deg > 10.0  # the cameras look down: their up vector alone would tilt the room
    # the origin is the centre of the box around points and cameras
    turned = np.concatenate([points, c2w[:, :3, 3]]) @ frame.rotation.T + frame.translation
    np.testing.assert_allclose(turned.min(0), -turned.max(0), atol=1e-9)


def test_the_frame_is_a_rotation_and_repeats() -> None:
    rng = np.random.default_rng(3)
    points, c2w = _move(_room_points(rng), _orbit(), Rotation.random(random_state=3).as_matrix(), np.zeros(3))
    a, b = estimate_world_frame(points, c2w), estimate_world_frame(points, c2w)
    np.testing.assert_allclose(a.rotation @ a.rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(a.rotation) == pytest.approx(1.0)
    assert np.array_equal(a.matrix, b.matrix)


def test_without_walls_the_cameras_set_the_frame() -> None:
    """Points with no dominant planes (a blob) and no points at all fall back to the cameras' up and right."""
    rng = np.random.default_rng(4)
    c2w = _orbit(pitch_target_z=0.3)  # level cameras: their up is the room's up
    blob = rng.normal(0.0, 1.0, (2000, 3))
    for points in (blob, np.zeros((0, 3))):
        frame = estimate_world_frame(points, c2w)
        assert frame.yaw_source == "camera right vectors"
        # the blob's normals near the cameras' up nudge it (by chance, not towards a floor): a few degrees at most
        assert frame.rotation[2] @ np.array([0.0, 0.0, 1.0]) > np.cos(np.radians(3.0))
        right = c2w[:, :3, 0].sum(0)
        assert frame.rotation[0] @ (right / np.linalg.norm(right)) > np.cos(np.radians(3.0))
    assert estimate_world_frame(np.zeros((0, 3)), c2w).up_source == "camera up vectors"
