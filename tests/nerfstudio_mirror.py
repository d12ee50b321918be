"""How nerfstudio's own dataparser (``nerfstudio/data/dataparsers/nerfstudio_dataparser.py``, 1.1.x) reads a
transforms.json, re-stated for tests that cannot install nerfstudio (it wants a CUDA stack).

Mirrored, not copied: the behaviours a dataset must satisfy for ``ns-train --data DIR`` to run:
- ``data_dir`` is the folder of transforms.json; an image is ``data_dir / file_path`` (not resolved
  further), and every image must open (nerfstudio opens the first to choose a downscale, and all to train);
- intrinsics at the top level, else the same key in every frame; distortion from ``k1 k2 k3 k4 p1 p2``
  (or ``distortion_params``), missing ones are 0;
- ``camera_model`` names the camera type (absent: perspective); an unknown name is a KeyError there;
- ``{train,val,test}_filenames``: when any is present, the requested split must be present and every
  listed name must be an image of a frame; ``ns-train`` asks for ``train`` and ``val``, ``ns-eval`` for ``test``;
- ``applied_transform`` is a 3x4 matrix; ``ply_file_path`` is read as ``data_dir / ply_file_path``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

CAMERA_TYPES = {"SIMPLE_PINHOLE": "PERSPECTIVE", "PINHOLE": "PERSPECTIVE", "SIMPLE_RADIAL": "PERSPECTIVE",
                "RADIAL": "PERSPECTIVE", "OPENCV": "PERSPECTIVE", "OPENCV_FISHEYE": "FISHEYE",
                "EQUIRECTANGULAR": "EQUIRECTANGULAR", "FISHEYE624": "FISHEYE624"}
INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")


class NotReadable(AssertionError):
    """What nerfstudio would stop on (an assertion, KeyError or RuntimeError there)."""


@dataclass
class NerfstudioView:
    data_dir: Path
    image_filenames: list[Path]
    """``data_dir / file_path`` of every frame, sorted as nerfstudio sorts them."""
    splits: dict[str, list[Path]]
    """Images per split for train, val and test (empty when the file has no split lists)."""
    camera_type: str
    intrinsics: list[dict[str, float]]
    """fl_x, fl_y, cx, cy, w, h per image."""
    distortion: list[list[float]]
    """[k1, k2, k3, k4, p1, p2] per image."""
    applied_transform: np.ndarray | None
    ply_file: Path | None


def _distortion(d: dict) -> list[float]:
    if "distortion_params" in d:
        return [float(x) for x in d["distortion_params"]]
    return [float(d.get(k, 0.0)) for k in ("k1", "k2", "k3", "k4", "p1", "p2")]


def read_like_nerfstudio(data: Path) -> NerfstudioView:
    data = Path(data)
    path = data if data.suffix == ".json" else data / "transforms.json"
    data_dir = path.parent
    meta = json.loads(path.read_text())
    frames = sorted(meta["frames"], key=lambda f: str(data_dir / Path(f["file_path"])))
    filenames = [data_dir / Path(f["file_path"]) for f in frames]
    for name in filenames:
        if cv2.imread(str(name), cv2.IMREAD_UNCHANGED) is None:
            raise NotReadable(f"image {name} does not open")
    intrinsics = []
    for f in frames:
        values = {}
        for key in INTRINSIC_KEYS:
            if key not in meta and key not in f:
                raise NotReadable(f"{key} neither at the top level nor in frame {f['file_path']}")
            values[key] = float(meta[key] if key in meta else f[key])
        intrinsics.append(values)
    has_distortion = any(k in meta for k in ("k1", "k2", "k3", "p1", "p2", "distortion_params"))
    distortion = [_distortion(meta) if has_distortion else _distortion(f) for f in frames]
    model = meta.get("camera_model")
    if model is not None and model not in CAMERA_TYPES:
        raise NotReadable(f"camera_model {model!r} is not a nerfstudio camera model")
    splits: dict[str, list[Path]] = {}
    listed = any(f"{s}_filenames" in meta for s in ("train", "val", "test"))
    for split in ("train", "val", "test"):
        key = f"{split}_filenames"
        if key not in meta:
            if listed:
                raise NotReadable(f"{key} is missing while other split lists are given")
            continue
        names = {data_dir / Path(x) for x in meta[key]}
        unknown = names - set(filenames)
        if unknown:
            raise NotReadable(f"{key} names images of no frame: {sorted(map(str, unknown))[:3]}")
        splits[split] = [n for n in filenames if n in names]
    applied = None
    if "applied_transform" in meta:
        applied = np.asarray(meta["applied_transform"], dtype=np.float64)
        if applied.shape != (3, 4):
            raise NotReadable(f"applied_transform has shape {applied.shape}, nerfstudio appends [0, 0, 0, 1] to 3x4")
    ply = None
    if "ply_file_path" in meta:
        ply = data_dir / meta["ply_file_path"]
        if not ply.is_file():
            raise NotReadable(f"ply_file_path {ply} does not exist")
    return NerfstudioView(data_dir=data_dir, image_filenames=filenames, splits=splits,
                          camera_type=CAMERA_TYPES.get(model, "PERSPECTIVE") if model else "PERSPECTIVE",
                          intrinsics=intrinsics, distortion=distortion, applied_transform=applied, ply_file=ply)
