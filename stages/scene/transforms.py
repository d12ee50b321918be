"""Read and write ``transforms.json`` in nerfstudio and Blender forms.

nerfstudio form: shared ``fl_x, fl_y, cx, cy, w, h`` (+ ``k1.. p2``) and
``frames[].transform_matrix`` (camera to world, OpenGL axes). Blender form:
``camera_angle_x`` and frames whose ``file_path`` may lack an extension
(``./images/frame_00012`` with ``.png`` implied). Per-frame intrinsics in
nerfstudio form override the shared ones.

``file_path`` is resolved from the folder the file is in, as nerfstudio does
(``data_dir / file_path``), so ``../frames/images/frame_00001.png`` is valid.
``camera_model`` is honoured: the perspective models read as a pinhole with
OpenCV radial-tangential distortion (the six coefficients nerfstudio reads for
them); fisheye and panoramic models are refused (docs/data-contract.md).
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from .camera import DISTORTION_KEYS, Camera, distortion_fold
from .errors import SceneError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".PNG", ".JPG", ".JPEG")
PERSPECTIVE_MODELS = ("SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV")
"""nerfstudio's ``camera_model`` values it treats as a perspective camera with k1..k4, p1, p2."""
UNSUPPORTED_MODELS = ("OPENCV_FISHEYE", "FISHEYE624", "EQUIRECTANGULAR", "OMNIDIRECTIONALSTEREO_L",
                      "OMNIDIRECTIONALSTEREO_R", "VR180_L", "VR180_R", "ORTHOPHOTO")
"""nerfstudio models whose rays are not pinhole + radial-tangential: reading their coefficients as
OpenCV's would bend every ray, so they are refused instead."""
UNDISTORT_FIX = ("undistort the images to a pinhole camera first (`colmap image_undistorter`, then "
                 "`livescene poses import` of the undistorted model; or `livescene poses` on the undistorted "
                 "images) and write camera_model PINHOLE or OPENCV")


def load_json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise SceneError(path, "file not found", "point to a scene folder that holds transforms.json")
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))  # a BOM, as some Windows editors save, is allowed
    except json.JSONDecodeError as exc:
        raise SceneError(path, f"not valid JSON ({exc})", "repair or regenerate the file") from exc
    except UnicodeDecodeError as exc:
        raise SceneError(path, f"is not UTF-8 text ({exc.reason} at byte {exc.start})",
                         "save the file as UTF-8 (JSON's encoding)") from exc
    if not isinstance(data, dict):
        raise SceneError(path, "top level is not a JSON object", "regenerate the file")
    return data


def check_camera_model(d: dict[str, Any], path: Path, where: str) -> str:
    """The ``camera_model`` of ``d`` (PINHOLE when absent, as nerfstudio assumes), or a SceneError."""
    model = d.get("camera_model", "PINHOLE")
    if model in PERSPECTIVE_MODELS:
        return str(model)
    if model in UNSUPPORTED_MODELS:
        raise SceneError(path, f"{where}: camera_model {model} is not supported (LiveScene's rays are pinhole with "
                         "OpenCV radial-tangential distortion; its coefficients would be misread)", UNDISTORT_FIX)
    raise SceneError(path, f"{where}: unknown camera_model {model!r}",
                     f"write one of {', '.join(PERSPECTIVE_MODELS)} (nerfstudio's names)")


def _distortion(d: dict[str, Any], path: Path, where: str) -> dict[str, float]:
    """k1..k4, p1, p2 from named keys or nerfstudio's ``distortion_params`` list [k1, k2, k3, k4, p1, p2]."""
    if "distortion_params" in d and not any(k in d for k in DISTORTION_KEYS):
        params = d["distortion_params"]
        if not isinstance(params, list) or len(params) != 6:
            raise SceneError(path, f"{where}: distortion_params is not a list of 6 numbers [k1, k2, k3, k4, p1, p2]",
                             "write the six coefficients or the named keys k1, k2, k3, k4, p1, p2")
        values = dict(zip(("k1", "k2", "k3", "k4", "p1", "p2"), params, strict=True))
    else:
        values = {k: d[k] for k in DISTORTION_KEYS if k in d}
    out = {}
    for k, v in values.items():
        try:
            value = float(v)
        except (TypeError, ValueError) as exc:
            raise SceneError(path, f"{where}: distortion coefficient {k} = {v!r} is not a number",
                             "re-export the camera intrinsics") from exc
        if not np.isfinite(value):
            raise SceneError(path, f"{where}: distortion coefficient {k} is not finite",
                             "re-export the camera intrinsics")
        if value != 0.0:
            out[k] = value
    return out


FRAME_INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h", *DISTORTION_KEYS, "distortion_params")
"""Keys that give a frame intrinsics of its own (nerfstudio reads each from the frame when the top level lacks it)."""
SHARED_CAMERA_KEYS = (*FRAME_INTRINSIC_KEYS, "camera_angle_x", "camera_model")


def frame_camera_dict(top: dict[str, Any], frame: dict[str, Any]) -> dict[str, Any] | None:
    """The intrinsics of a frame that gives any of its own (None: it takes the shared camera), completed by the
    top level's: nerfstudio's per-key reading, so ``fl_x``, ``cx`` .. per frame with one ``w``, ``h`` at the top
    level is a camera per frame. Where both give a key, the frame's value is taken (this project's writer never
    writes both)."""
    if not any(k in frame for k in FRAME_INTRINSIC_KEYS):
        return None
    merged = {k: top[k] for k in SHARED_CAMERA_KEYS if k in top}
    merged.update({k: frame[k] for k in SHARED_CAMERA_KEYS if k in frame})
    return merged


def camera_from_dict(d: dict[str, Any], path: Path, where: str, image_hw: tuple[int, int] | None = None) -> Camera:
    """Intrinsics from a nerfstudio- or Blender-style dictionary."""
    check_camera_model(d, path, where)
    if "camera_angle_x" in d and "fl_x" not in d:
        if image_hw is None and not ("w" in d and "h" in d):
            raise SceneError(path, f"{where}: Blender form without w/h and no image to read the size from",
                             "add \"w\" and \"h\" or make the first image readable")
        h, w = (int(d["h"]), int(d["w"])) if "w" in d and "h" in d else image_hw  # type: ignore[misc]
        return Camera.from_fov(float(d["camera_angle_x"]), w, h)
    missing = [k for k in ("fl_x", "w", "h") if k not in d]
    if missing:
        raise SceneError(path, f"{where}: missing intrinsics {missing}",
                         "give fl_x, fl_y, cx, cy, w, h (nerfstudio) or camera_angle_x (Blender)")
    w, h = int(d["w"]), int(d["h"])
    fx = float(d["fl_x"])
    fy = float(d.get("fl_y", fx))
    cx = float(d.get("cx", w / 2.0))
    cy = float(d.get("cy", h / 2.0))
    for name, val in (("fl_x", fx), ("fl_y", fy), ("cx", cx), ("cy", cy)):
        if not np.isfinite(val):
            raise SceneError(path, f"{where}: {name} is not finite", "re-export the camera intrinsics")
    if fx <= 0 or fy <= 0 or w <= 0 or h <= 0:
        raise SceneError(path, f"{where}: focal length and image size must be positive",
                         "re-export the camera intrinsics")
    camera = Camera(fx=fx, fy=fy, cx=cx, cy=cy, width=w, height=h, distortion=_distortion(d, path, where))
    if (fold := _fold(camera)) is not None:  # rays there would be wrong, silently (docs/data-contract.md)
        coefficients = ", ".join(f"{k} {v:g}" for k, v in camera.distortion.items())
        raise SceneError(path, f"{where}: the lens distortion ({coefficients}) cannot be inverted at every pixel of "
                         f"the {w}x{h} image: {fold}", "re-estimate the intrinsics (`livescene poses`: RADIAL fits "
                         "k2 to balance k1), or undistort the images to a pinhole camera (`colmap image_undistorter`) "
                         "and write camera_model PINHOLE")
    return camera


@lru_cache(maxsize=256)
def _fold_of(key: tuple) -> str | None:
    fx, fy, cx, cy, w, h, distortion = key
    return distortion_fold(Camera(fx=fx, fy=fy, cx=cx, cy=cy, width=w, height=h, distortion=dict(distortion)))


def _fold(camera: Camera) -> str | None:
    """``distortion_fold`` once per distinct camera: frames with intrinsics of their own mostly repeat one."""
    if not camera.has_distortion:
        return None
    return _fold_of((camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height,
                     tuple(sorted(camera.distortion.items()))))


def camera_to_dict(camera: Camera) -> dict[str, Any]:
    out: dict[str, Any] = {
        "camera_model": "OPENCV" if camera.has_distortion else "PINHOLE",
        "fl_x": camera.fx,
        "fl_y": camera.fy,
        "cx": camera.cx,
        "cy": camera.cy,
        "w": camera.width,
        "h": camera.height,
    }
    for k in DISTORTION_KEYS:
        if k in camera.distortion:
            out[k] = camera.distortion[k]
    return out


def parse_pose(value: Any, path: Path, where: str) -> np.ndarray:
    """A 4x4 rigid camera-to-world matrix, or a SceneError naming the frame."""
    try:
        m = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SceneError(path, f"{where}: transform_matrix is not numeric", "re-export the poses") from exc
    if m.shape == (3, 4):
        m = np.vstack([m, [0, 0, 0, 1]])
    if m.shape != (4, 4):
        raise SceneError(path, f"{where}: transform_matrix has shape {m.shape}, expected 4x4",
                         "write a 4x4 camera-to-world matrix")
    if not np.isfinite(m).all():
        raise SceneError(path, f"{where}: transform_matrix has NaN or infinite entries",
                         "drop the frame or re-run pose estimation")
    r = m[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-3) or np.linalg.det(r) < 0:
        raise SceneError(path, f"{where}: transform_matrix rotation is not orthonormal (not a rigid pose)",
                         "write camera-to-world rotations without scale or shear")
    if not np.allclose(m[3], [0, 0, 0, 1], atol=1e-6):
        raise SceneError(path, f"{where}: last row of transform_matrix is {m[3].tolist()}, expected [0, 0, 0, 1]",
                         "write an affine 4x4 matrix")
    return m


def resolve_image_path(root: Path, file_path: str) -> Path:
    """The image file a frame names; Blender form may leave out the extension."""
    p = (root / file_path).resolve() if not Path(file_path).is_absolute() else Path(file_path)
    if p.suffix in IMAGE_SUFFIXES or p.exists():
        return p
    for suffix in IMAGE_SUFFIXES:
        candidate = p.with_name(p.name + suffix)
        if candidate.exists():
            return candidate
    return p.with_name(p.name + ".png")
