"""Handheld-like camera paths: an orbit or a walk, plus smooth hand shake."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from stages.scene import look_at

from .spec import CameraPathSpec, CaptureSpec, CaptureSpecError

MIN_DISTANCE_M = 0.05
"""A camera this near its target (metres) looks in whatever direction its hand shake gives it."""
MIN_TILT_FROM_VERTICAL_DEG = 1.0
"""A camera looking (almost) straight up or down has no defined roll: ``look_at``'s right vector vanishes."""


def seeded_rng(seed: int, label: str) -> np.random.Generator:
    """An independent random stream per purpose, stable across Python runs (crc32, not hash())."""
    return np.random.default_rng([int(seed), zlib.crc32(label.encode())])


def shake(times_s: np.ndarray, amplitude: float, frequency_hz: float, rng: np.random.Generator) -> np.ndarray:
    """``[n, 3]`` smooth pseudo-random offsets: three sinusoids per axis around ``frequency_hz``."""
    out = np.zeros((len(times_s), 3))
    if amplitude <= 0:
        return out
    for axis in range(3):
        freqs = frequency_hz * rng.uniform(0.5, 1.8, size=3)
        phases = rng.uniform(0, 2 * np.pi, size=3)
        weights = rng.uniform(0.5, 1.0, size=3)
        wave = sum(w * np.sin(2 * np.pi * f * times_s + p) for f, p, w in zip(freqs, phases, weights, strict=True))
        out[:, axis] = amplitude * wave / weights.sum()
    return out


def _orbit_centres(path: CameraPathSpec, times_s: np.ndarray) -> np.ndarray:
    az = np.deg2rad(path.start_deg + path.speed_deg_s * times_s)
    tx, ty, _ = path.target
    return np.stack([tx + path.radius * np.sin(az), ty - path.radius * np.cos(az),
                     np.full_like(az, path.height)], axis=1)


def _walk_centres(path: CameraPathSpec, times_s: np.ndarray) -> np.ndarray:
    pts = np.asarray(path.waypoints, dtype=np.float64)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.clip(path.speed_m_s * times_s, 0.0, arc[-1])
    return np.stack([np.interp(s, arc, pts[:, k]) for k in range(3)], axis=1)


def check_view_directions(centres: np.ndarray, target: np.ndarray, spec_path: str | Path) -> None:
    """Refuse a path whose camera sits on its target or right above or below it (NaN or spinning poses)."""
    back = centres - target
    dist = np.linalg.norm(back, axis=1)
    tilt = np.degrees(np.arcsin(np.clip(np.linalg.norm(back[:, :2], axis=1) / np.maximum(dist, 1e-12), 0.0, 1.0)))
    bad = np.flatnonzero((dist < MIN_DISTANCE_M) | (tilt < MIN_TILT_FROM_VERTICAL_DEG))
    if bad.size:
        i = int(bad[0])
        on_target = dist[i] < MIN_DISTANCE_M
        where = "on camera.target" if on_target else "straight above or below camera.target"
        fix = (f"keep the path at least {MIN_DISTANCE_M:g} m from camera.target" if on_target else
               f"move camera.target or the path so that the camera sees the target at least "
               f"{MIN_TILT_FROM_VERTICAL_DEG:g} degree off vertical")
        raise CaptureSpecError(
            spec_path, f"the camera of frame {i} (of {bad.size} such frames) at {np.round(centres[i], 3).tolist()} m "
            f"is {where} {[float(x) for x in target]}, where its view direction or roll is undefined",
            f"{fix} (camera.waypoints, or camera.radius and camera.height)")


def check_camera_in_free_space(centres: np.ndarray, spec: CaptureSpec, spec_path: str | Path) -> None:
    """Refuse a path whose camera leaves the room or enters a carcass or a piece of furniture: it would film the
    walls from outside or the inside of a box, and its frames would show nothing of the room the spec describes."""
    room = np.asarray(spec.room, dtype=np.float64)
    lo = np.array([-room[0] / 2, -room[1] / 2, 0.0]) + MIN_DISTANCE_M
    hi = np.array([room[0] / 2, room[1] / 2, room[2]]) - MIN_DISTANCE_M
    outside = np.flatnonzero(((centres < lo) | (centres > hi)).any(axis=1))
    if outside.size:
        i = int(outside[0])
        raise CaptureSpecError(
            spec_path, f"the camera of frame {i} (of {outside.size} such frames) at {np.round(centres[i], 3).tolist()} "
            f"m is outside the room, or within {MIN_DISTANCE_M:g} m of a wall, the floor or the ceiling (room "
            f"{[float(v) for v in spec.room]}: x and y centred on 0, floor at z = 0)",
            "keep the camera path inside the room (camera.radius and camera.height, or camera.waypoints; hand "
            "shake adds camera.jitter.position)")
    boxes = [(f"objects[{i}] ({o.name})", o) for i, o in enumerate(spec.objects)]  # named as validate_spec names them
    boxes += [(f"furniture[{i}] ({f.name})", f) for i, f in enumerate(spec.furniture)]
    for where, box in boxes:
        yaw = np.radians(box.yaw_deg)
        d = centres - np.asarray(box.position, dtype=np.float64)
        local_x = np.cos(yaw) * d[:, 0] + np.sin(yaw) * d[:, 1]  # the footprint's own axes (turned back by yaw)
        local_y = -np.sin(yaw) * d[:, 0] + np.cos(yaw) * d[:, 1]
        inside = np.flatnonzero((np.abs(local_x) < box.size[0] / 2) & (np.abs(local_y) < box.size[1] / 2)
                                & (d[:, 2] > 0.0) & (d[:, 2] < box.size[2]))
        if inside.size:
            i = int(inside[0])
            raise CaptureSpecError(
                spec_path, f"the camera of frame {i} (of {inside.size} such frames) at "
                f"{np.round(centres[i], 3).tolist()} m is inside {where}",
                "route the camera path around it (camera.radius and camera.height, or camera.waypoints)")


def _camera_centres(spec: CaptureSpec, positions: np.ndarray) -> np.ndarray:
    """``[len(positions), 3]`` camera centres in metres before hand shake (the path's smoothed positions) at frame
    positions (frame index, fractional between frames)."""
    path = spec.camera
    n = spec.video.n_frames
    if path.kind == "orbit":
        return _orbit_centres(path, positions / spec.video.fps)
    if n <= 2:
        return _walk_centres(path, positions / spec.video.fps)
    frames = _walk_centres(path, np.arange(n) / spec.video.fps)
    # corners of the polyline would jerk the camera; a short moving average over frames rounds them
    k = max(1, min(5, n // 8))
    padded = np.concatenate([np.repeat(frames[:1], k, 0), frames, np.repeat(frames[-1:], k, 0)])
    kernel = np.ones(2 * k + 1) / (2 * k + 1)
    frames = np.stack([np.convolve(padded[:, a], kernel, mode="valid") for a in range(3)], axis=1)
    # between frames the camera goes straight (the polyline's corners are already rounded over 2k frames);
    # np.interp returns a frame's own value at its position (bit for bit) and holds the ends: the walk stands
    # still before its first and after its last frame
    return np.stack([np.interp(positions, np.arange(n), frames[:, a]) for a in range(3)], axis=1)


def _shaken_path(spec: CaptureSpec, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres (metres) and hand-shake rotation vectors at frame positions, both ``[len(positions), 3]``."""
    positions = np.asarray(positions, dtype=np.float64)
    times_s = positions / spec.video.fps
    rng = seeded_rng(spec.seed, "camera-shake")
    j = spec.camera.jitter
    centres = _camera_centres(spec, positions) + shake(times_s, j.position, j.frequency_hz, rng)
    return centres, shake(times_s, np.deg2rad(j.rotation_deg), j.frequency_hz, rng)


def _poses(centres: np.ndarray, angles: np.ndarray, target: np.ndarray) -> np.ndarray:
    """One ``look_at`` per camera, as the frames' poses have always been made (their bits depend on it)."""
    poses = np.empty((len(centres), 4, 4))
    for i in range(len(centres)):
        pose = look_at(centres[i], target)
        pose[:3, :3] = pose[:3, :3] @ Rotation.from_rotvec(angles[i]).as_matrix()
        poses[i] = pose
    return poses


def _poses_batched(centres: np.ndarray, angles: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``_poses`` in array operations: 700 times faster for the thousands of sub-frame and row times of a blurred,
    rolled capture (a ``look_at`` each took 0.3 ms, 0.7 s a frame). The same arithmetic, row by row; the same
    bits as ``_poses`` for every preset's frames when this was written, but only ``camera_path`` promises those."""
    back = centres - target
    back = back / np.linalg.norm(back, axis=1, keepdims=True)
    right = np.cross(np.array([0.0, 0.0, 1.0]), back)
    right = right / np.linalg.norm(right, axis=1, keepdims=True)
    poses = np.zeros((len(centres), 4, 4))
    poses[:, :3, 0], poses[:, :3, 1], poses[:, :3, 2], poses[:, :3, 3] = right, np.cross(back, right), back, centres
    poses[:, 3, 3] = 1.0
    poses[:, :3, :3] = poses[:, :3, :3] @ Rotation.from_rotvec(angles).as_matrix()
    return poses


def camera_poses_at(spec: CaptureSpec, positions: np.ndarray) -> np.ndarray:
    """``[len(positions), 4, 4]`` camera-to-world poses (OpenGL axes, metres) at frame positions: ``i`` is video
    frame i's time, ``i + 0.25`` a quarter of a frame interval later (a sub-frame exposure or a sensor row).

    At integer positions these are ``camera_path``'s poses (to the last bit or two: see ``_poses_batched``): the
    hand shake is a sum of sinusoids of time, drawn from the same seeded stream whatever the positions. Unchecked:
    ``camera_path`` has checked the frames' poses, and a camera between two frames stays within a frame's motion
    of them."""
    centres, angles = _shaken_path(spec, positions)
    return _poses_batched(centres, angles, np.asarray(spec.camera.target, dtype=np.float64))


def camera_path(spec: CaptureSpec, spec_path: str | Path = "<spec>") -> np.ndarray:
    """``[n_frames, 4, 4]`` camera-to-world poses (OpenGL axes) in metres; refuses a path whose camera sits on its
    target, looks straight down or up at it, or leaves the free space of the room."""
    centres, angles = _shaken_path(spec, np.arange(spec.video.n_frames))
    target = np.asarray(spec.camera.target, dtype=np.float64)
    check_view_directions(centres, target, spec_path)
    check_camera_in_free_space(centres, spec, spec_path)
    return _poses(centres, angles, target)
