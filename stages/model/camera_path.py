"""Camera paths for videos: nerfstudio's ``camera_path.json`` with per-keyframe object states (docs/export.md).

The file format is that of nerfstudio's viewer (read for reference: nerfstudio/cameras/camera_paths.py
and viewer/render_panel.py; no code copied):

- ``camera_path``: one entry per video frame, ``camera_to_world`` (16 numbers, row major, OpenGL
  camera axes, in the DATASET's world: that of its transforms.json), ``fov`` (VERTICAL field of
  view in degrees, the three.js convention: ``f = (H / 2) / tan(fov / 2)``);
- ``render_width``, ``render_height``, ``fps``, ``seconds``; ``camera_type`` must be perspective;
- ``keyframes``: the viewer's key poses; the viewer samples frame ``j`` of ``N`` at time
  ``duration * j / N``, where keyframe ``i`` sits at the sum of the transition times into keyframes
  ``1..i`` (``override_transition_sec`` when ``override_transition_enabled``, else
  ``default_transition_sec``; ``is_cycle`` adds the transition back to keyframe 0).

This project's extension: a keyframe may carry ``"states": {object: value}``; frame ``j`` takes each
object's state linearly interpolated in time between the keyframes that name it (held constant
before the first and after the last). A ``camera_path`` entry may carry its own ``"states"``, which
wins. Objects named nowhere take the caller's defaults (``--state``), else 0.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stages.scene import Camera, InputError, look_at

DEFAULT_TRANSITION_SEC = 1.0
"""Used when a file gives neither per-keyframe nor default transition times (equal spacing)."""


@dataclass
class PathFrame:
    """One video frame: pose (dataset world, OpenGL), intrinsics and the object states."""

    c2w: np.ndarray
    camera: Camera
    states: dict[str, float]


@dataclass
class CameraPath:
    frames: list[PathFrame]
    fps: float
    width: int
    height: int
    keyframes: list[dict[str, Any]] = field(default_factory=list)
    source: str = ""

    @property
    def seconds(self) -> float:
        return len(self.frames) / self.fps


def camera_from_fov(fov_deg: float, width: int, height: int) -> Camera:
    """Pinhole camera of a vertical field of view (nerfstudio / three.js), principal point at the centre."""
    f = 0.5 * height / math.tan(math.radians(fov_deg) / 2.0)
    return Camera(fx=f, fy=f, cx=width / 2.0, cy=height / 2.0, width=width, height=height)


def vertical_fov_deg(camera: Camera) -> float:
    return math.degrees(2.0 * math.atan(0.5 * camera.height / camera.fy))


def _number(value: Any, path: Path, where: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(path, f"{where} is {value!r}, not a number", f"write a number for {where}") from exc
    if not math.isfinite(v) or not lo <= v <= hi:
        raise InputError(path, f"{where} = {value!r} is outside [{lo:g}, {hi:g}]", f"fix {where}")
    return v


def _states(value: Any, objects: Sequence[str], path: Path, where: str) -> dict[str, float]:
    if not isinstance(value, Mapping):
        raise InputError(path, f"{where}.states is not a mapping", 'write "states": {"object": value}')
    unknown = sorted(set(map(str, value)) - set(objects))
    if unknown:
        raise InputError(path, f"{where}.states names unknown objects {unknown}", f"use {list(objects)}")
    return {str(k): _number(v, path, f"{where}.states.{k}", 0.0, 1.0) for k, v in value.items()}


def _matrix(value: Any, path: Path, where: str) -> np.ndarray:
    try:
        m = np.asarray(value, dtype=np.float64).reshape(4, 4)
    except (TypeError, ValueError) as exc:
        raise InputError(path, f"{where} is not 16 numbers", "write the 4x4 camera-to-world, row major") from exc
    if not np.isfinite(m).all() or abs(np.linalg.det(m[:3, :3])) < 1e-9:
        raise InputError(path, f"{where} is not a finite invertible pose", "write a camera-to-world matrix")
    return m


def keyframe_times(keyframes: Sequence[Mapping[str, Any]], default_sec: float, cycle: bool) -> np.ndarray:
    """Seconds at which each keyframe sits (and, for a cycle, the time of the return to keyframe 0, last)."""

    def transition(k: Mapping[str, Any]) -> float:
        sec = k.get("override_transition_sec")
        return float(sec) if k.get("override_transition_enabled") and sec is not None else default_sec

    times = [0.0]
    for k in keyframes[1:]:
        times.append(times[-1] + transition(k))
    if cycle and keyframes:
        times.append(times[-1] + transition(keyframes[0]))
    return np.asarray(times, dtype=np.float64)


def interpolate_states(times: np.ndarray, key_states: Sequence[Mapping[str, float]], t: float,
                       objects: Sequence[str], defaults: Mapping[str, float]) -> dict[str, float]:
    """Each object's state at time ``t``: linear between the keyframes that name it; ``defaults`` otherwise."""
    out = {}
    for name in objects:
        known = [(tk, ks[name]) for tk, ks in zip(times, key_states, strict=False) if name in ks]
        if not known:
            out[name] = float(defaults.get(name, 0.0))
            continue
        ts, vs = zip(*known, strict=True)
        out[name] = float(np.interp(t, ts, vs))  # holds the end values outside [first, last]
    return out


def read_camera_path(path: str | Path, objects: Sequence[str], defaults: Mapping[str, float] | None = None,
                     size: tuple[int, int] | None = None) -> CameraPath:
    """Read a camera_path.json; ``size`` (width, height) overrides the file's resolution, keeping the fov."""
    path = Path(path)
    defaults = dict(defaults or {})
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(path, f"cannot read the camera path ({exc})", "pass a camera_path.json") from exc
    if not isinstance(data, dict) or not isinstance(data.get("camera_path"), list) or not data["camera_path"]:
        raise InputError(path, 'no "camera_path" list of frames', "export the path from a viewer, or use --orbit")
    kind = str(data.get("camera_type", "perspective")).lower()
    if kind != "perspective":
        raise InputError(path, f"camera_type {kind!r} is not supported", "use a perspective camera path")
    for key in ("render_width", "render_height", "fps"):
        if key not in data:
            raise InputError(path, f"no {key!r}", f"add {key!r} (nerfstudio's camera_path.json has it)")
    width = int(_number(data["render_width"], path, "render_width", 1, 16384))
    height = int(_number(data["render_height"], path, "render_height", 1, 16384))
    fps = _number(data["fps"], path, "fps", 1e-3, 1000)
    if size is not None:
        width, height = size
    keyframes = data.get("keyframes") or []
    if not isinstance(keyframes, list):
        raise InputError(path, '"keyframes" is not a list', "write a list of keyframes (or leave it out)")
    key_states = [_states(k.get("states", {}), objects, path, f"keyframes[{i}]") for i, k in enumerate(keyframes)]
    cycle = bool(data.get("is_cycle", False))
    default_sec = float(data.get("default_transition_sec") or DEFAULT_TRANSITION_SEC)
    times = keyframe_times(keyframes, default_sec, cycle)
    if cycle and keyframes:
        key_states = [*key_states, key_states[0]]
    n = len(data["camera_path"])
    frames = []
    for j, entry in enumerate(data["camera_path"]):
        where = f"camera_path[{j}]"
        if not isinstance(entry, Mapping) or "camera_to_world" not in entry:
            raise InputError(path, f"{where} has no camera_to_world", "write 16 numbers per frame")
        c2w = _matrix(entry["camera_to_world"], path, f"{where}.camera_to_world")
        fov = _number(entry.get("fov", data.get("default_fov")), path, f"{where}.fov", 1e-3, 179.0)
        t = float(times[-1]) * j / n if len(times) > 1 else 0.0
        states = interpolate_states(times, key_states, t, objects, defaults)
        if "states" in entry:
            states.update(_states(entry["states"], objects, path, where))
        frames.append(PathFrame(c2w=c2w, camera=camera_from_fov(fov, width, height), states=states))
    return CameraPath(frames=frames, fps=fps, width=width, height=height, keyframes=list(keyframes),
                      source=str(path))


def path_to_json(cp: CameraPath) -> dict[str, Any]:
    """The nerfstudio form of a path (every frame explicit, with its states), for writing next to a video."""
    def entry(fr: PathFrame) -> dict[str, Any]:
        return {"camera_to_world": fr.c2w.reshape(-1).tolist(), "fov": vertical_fov_deg(fr.camera),
                "aspect": cp.width / cp.height, "states": dict(fr.states)}

    return {"camera_type": "perspective", "render_width": cp.width, "render_height": cp.height,
            "fps": cp.fps, "seconds": cp.seconds, "is_cycle": True,
            "default_fov": vertical_fov_deg(cp.frames[0].camera) if cp.frames else 50.0,
            "default_transition_sec": cp.seconds / max(len(cp.keyframes), 1),
            "keyframes": cp.keyframes, "camera_path": [entry(f) for f in cp.frames]}


# --- paths made from the training cameras -------------------------------------------------------


@dataclass(frozen=True)
class Orbit:
    """A circle fitted to the training cameras: the axis through ``target`` along ``up``."""

    target: np.ndarray
    up: np.ndarray
    centre: np.ndarray
    """The circle's centre: ``target`` moved along ``up`` to the cameras' mean height."""
    radius: float
    basis: np.ndarray
    """[2, 3]: two unit vectors spanning the circle's plane."""
    angles: np.ndarray
    """Azimuth of each training camera, radians, unwrapped in frame order."""

    def point(self, angle: float) -> np.ndarray:
        return self.centre + self.radius * (math.cos(angle) * self.basis[0] + math.sin(angle) * self.basis[1])

    def rotate(self, c2w: np.ndarray, angle: float) -> np.ndarray:
        """``c2w`` turned by ``angle`` about the orbit axis (Rodrigues)."""
        k = self.up
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        r = np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx
        out = np.asarray(c2w, dtype=np.float64).copy()
        out[:3, :3] = r @ out[:3, :3]
        out[:3, 3] = self.target + r @ (out[:3, 3] - self.target)
        return out


def _orbit_up(centres: np.ndarray, mean_up: np.ndarray) -> np.ndarray:
    """The normal of the plane the camera centres lie in, signed like the cameras' mean up vector.

    The mean up vector alone tilts towards the target when the cameras look down at it; the plane of
    an orbit-like capture is exact. Cameras on a line (or a point) have no plane: the mean up it is.
    """
    mean_up = mean_up / np.linalg.norm(mean_up)
    if len(centres) < 3:
        return mean_up
    _, sv, vt = np.linalg.svd(centres - centres.mean(0))
    if sv[1] < 1e-6 * max(sv[0], 1e-12) or sv[2] > 0.3 * sv[1]:  # no clear plane
        return mean_up
    normal = vt[2]
    return normal if normal @ mean_up >= 0 else -normal


def fit_orbit(c2ws: Sequence[np.ndarray]) -> Orbit:
    """The point the cameras look at (least squares over their optical axes), their mean up, a circle."""
    poses = np.asarray(c2ws, dtype=np.float64)
    centres, forward = poses[:, :3, 3], -poses[:, :3, 2]
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    up = _orbit_up(centres, poses[:, :3, 1].mean(0))
    proj = np.eye(3)[None] - forward[:, :, None] * forward[:, None, :]  # I - f f^T per camera
    a, b = proj.sum(0), np.einsum("nij,nj->i", proj, centres)
    if np.linalg.cond(a) < 1e6:
        target = np.linalg.solve(a, b)
    else:  # parallel axes (a forward-facing capture): a point ahead of the cameras
        spread = float(np.linalg.norm(centres.max(0) - centres.min(0))) or 1.0
        target = centres.mean(0) + forward.mean(0) * spread
    rel = centres - target
    height = float((rel @ up).mean())
    centre = target + up * height
    radial = rel - np.outer(rel @ up, up)
    radius = float(np.linalg.norm(radial, axis=1).mean()) or 1.0
    e1 = radial.mean(0) if np.linalg.norm(radial.mean(0)) > 1e-9 * radius else radial[0]
    e1 = e1 - up * (e1 @ up)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    angles = np.unwrap(np.arctan2(radial @ e2, radial @ e1))
    return Orbit(target=target, up=up, centre=centre, radius=radius, basis=np.stack([e1, e2]), angles=angles)


def orbit_path(c2ws: Sequence[np.ndarray], camera: Camera, n_frames: int, fps: float,
               states: Mapping[str, float], arc_deg: float | None = None) -> CameraPath:
    """Around the fitted orbit, looking at its target: over the training cameras' arc and back (a loop).

    ``arc_deg`` 360 (or a capture that surrounds the target) goes once round the full circle instead.
    """
    orbit = fit_orbit(c2ws)
    lo, hi = float(orbit.angles.min()), float(orbit.angles.max())
    if arc_deg is not None:
        mid, half = 0.5 * (lo + hi), math.radians(arc_deg) / 2
        lo, hi = mid - half, mid + half
    full = hi - lo >= math.radians(300)
    frames = []
    for j in range(n_frames):
        u = j / n_frames
        angle = lo + 2 * math.pi * u if full else lo + (hi - lo) * 0.5 * (1 - math.cos(2 * math.pi * u))
        c2w = look_at(orbit.point(angle), orbit.target, tuple(orbit.up))
        frames.append(PathFrame(c2w=c2w, camera=camera, states=dict(states)))
    keys = [{"matrix": frames[j].c2w.reshape(-1).tolist(), "fov": vertical_fov_deg(camera),
             "aspect": camera.width / camera.height, "states": dict(states)}
            for j in range(0, n_frames, max(n_frames // 4, 1))]
    return CameraPath(frames=frames, fps=fps, width=camera.width, height=camera.height, keyframes=keys,
                      source="orbit of the training cameras")


def states_sweep_path(c2ws: Sequence[np.ndarray], best_view: int, camera: Camera, n_frames: int, fps: float,
                      obj: str, states: Mapping[str, float], sway_deg: float = 10.0) -> CameraPath:
    """``obj`` goes 0 -> 1 -> 0 (linear; 1 at the middle frame) seen from training pose ``best_view``,
    the camera swaying +-``sway_deg`` about the orbit axis so that the parallax shows the depth."""
    orbit = fit_orbit(c2ws)
    base = np.asarray(c2ws[best_view], dtype=np.float64)
    frames = []
    for j in range(n_frames):
        u = j / n_frames
        st = dict(states)
        st[obj] = 1.0 - abs(1.0 - 2.0 * u)
        frames.append(PathFrame(c2w=orbit.rotate(base, math.radians(sway_deg) * math.sin(2 * math.pi * u)),
                                camera=camera, states=st))
    keys = []
    for j in (0, n_frames // 2):
        keys.append({"matrix": frames[j].c2w.reshape(-1).tolist(), "fov": vertical_fov_deg(camera),
                     "aspect": camera.width / camera.height, "states": dict(frames[j].states)})
    return CameraPath(frames=frames, fps=fps, width=camera.width, height=camera.height, keyframes=keys,
                      source=f"state sweep of {obj}")


def best_view_of(mask_fractions: Sequence[float]) -> int:
    """Index of the view where the object covers most of the image (the first one when none shows it)."""
    fr = np.asarray(mask_fractions, dtype=np.float64)
    return int(np.argmax(fr)) if fr.size and fr.max() > 0 else 0
