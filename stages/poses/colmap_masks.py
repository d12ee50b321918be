"""COLMAP feature masks from object masks: moving parts of the scene get no keypoints.

COLMAP reads ``<mask_path>/<image name>.png`` per image and extracts no
feature where the mask is 0 (black). Interactive objects (doors, drawers)
move during the capture, so features on them would vote for a wrong camera
motion; they are excluded, with a small dilation because mask edges are
rarely exact and SIFT support regions reach across them.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from stages.scene import InputError, frame_id_of, frame_number_of
from stages.scene.mask_images import colour_channels, read_mask_image

MASK_SUFFIXES = (".png", ".npy")


@dataclass
class MaskStats:
    """What the mask folder contributed."""

    frames_with_masks: int
    """Frames whose object mask was found."""
    frames_without_masks: list[str]
    """Frames for which no mask file exists (features extracted everywhere)."""
    mean_excluded_fraction: float
    """Mean fraction of image pixels excluded from feature extraction (after dilation)."""
    dilate_px: int
    """Dilation radius applied to the object masks, in pixels."""


def index_masks(masks_dir: Path) -> dict[str, Path]:
    """Mask files keyed on frame number (``frame_00012.png``, ``00012.npy``, ``IMG_12.png`` ... -> ``"12"``), or
    on frame id when a name has no number; hidden files (macOS's ``._`` copies) left out."""
    masks_dir = Path(masks_dir)
    if not masks_dir.is_dir():
        raise InputError(masks_dir, "mask folder not found", "pass the masks/ folder of the capture or labels stage")
    out: dict[str, Path] = {}
    for p in sorted(masks_dir.iterdir()):
        if p.suffix.lower() in MASK_SUFFIXES and p.is_file() and not p.name.startswith("."):
            out.setdefault(mask_key(p.stem), p)
    if not out:
        raise InputError(masks_dir, "no .png or .npy masks in the folder",
                         "pass a folder of per-frame id maps (PNG, 0 = static scene) or .npy masks")
    return out


def object_pixels(path: Path) -> np.ndarray:
    """Bool ``H x W``: True where any interactive object is.

    PNG / 2-D npy: an id map, 0 = static scene. 3-D npy: the one-hot
    ``H x W x (objects + 1)`` contract with background last.
    """
    if path.suffix.lower() == ".npy":
        try:
            arr = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise InputError(path, f"cannot read mask ({exc})", "re-export the mask as a .npy array") from exc
        if arr.ndim == 3:
            return ~arr[..., -1].astype(bool)
        if arr.ndim == 2:
            return arr.astype(bool) if arr.dtype == bool else arr != 0
        raise InputError(path, f"mask has {arr.ndim} dimensions", "write an H x W id map or H x W x (K+1) one-hot")
    img = read_mask_image(path)  # the labels stage's reading: a palette PNG's indices are its ids
    if img is None:
        raise InputError(path, "mask image unreadable", "re-export the mask as a PNG id map")
    ids = colour_channels(img)  # an alpha channel is no id
    return (ids != 0).any(axis=-1) if ids.ndim == 3 else ids != 0


def fit_to_image(mask: np.ndarray, height: int, width: int, path: Path) -> np.ndarray:
    """Resize a mask to the image size when only the scale differs (frames may be downscaled)."""
    if mask.shape == (height, width):
        return mask
    mh, mw = mask.shape
    if abs(mw / mh - width / height) > 0.01:
        raise InputError(path, f"mask is {mw}x{mh} but the frame is {width}x{height} (different aspect ratio)",
                         "pass masks made for these frames")
    return cv2.resize(mask.astype(np.uint8), (width, height), interpolation=cv2.INTER_NEAREST).astype(bool)


def mask_key(stem: str) -> str:
    """What pairs a mask with a frame: the frame number when the name has one (``IMG_4``, ``0004`` and
    ``frame_00004`` are frame 4, as the labels stage pairs them), else the frame id."""
    number = frame_number_of(stem)
    return str(number) if number is not None else frame_id_of(stem)


def write_colmap_masks(image_dir: Path, names: list[str], masks_dir: Path, out_dir: Path,
                       dilate_px: int | None = None) -> MaskStats:
    """Write ``out_dir/<name>.png`` (255 = use, 0 = ignore) for every image in ``names``."""
    masks = index_masks(masks_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    missing: list[str] = []
    fractions: list[float] = []
    radius = dilate_px
    for name in names:
        image = cv2.imread(str(image_dir / name), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise InputError(image_dir / name, "image unreadable", "re-extract the frames")
        h, w = image.shape
        if radius is None:
            radius = max(2, round(0.01 * float(np.hypot(h, w))))
        keep = np.full((h, w), 255, np.uint8)
        path = masks.get(mask_key(Path(name).stem))
        if path is None:
            missing.append(name)
        else:
            objects = fit_to_image(object_pixels(path), h, w, path).astype(np.uint8)
            if radius > 0:
                kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
                objects = cv2.dilate(objects, kernel)
            keep[objects > 0] = 0
        fractions.append(float(np.mean(keep == 0)))
        if not cv2.imwrite(str(out_dir / f"{name}.png"), keep):
            raise OSError(f"could not write {out_dir / name}.png")
    if len(missing) == len(names):
        raise InputError(masks_dir, f"no mask matches any frame (frames are named like {names[0]!r}, masks like "
                         f"{next(iter(masks.values())).name!r})",
                         "name masks by the frame id of the frames (frame_00012.png <-> frame_00012.png or 00012.npy)")
    if missing:
        warnings.warn(f"{masks_dir}: {len(missing)} of {len(names)} frames have no mask ({missing[0]} ...); "
                      "their features are extracted everywhere", stacklevel=2)
    return MaskStats(frames_with_masks=len(names) - len(missing), frames_without_masks=missing,
                     mean_excluded_fraction=float(np.mean(fractions)), dilate_px=int(radius or 0))
