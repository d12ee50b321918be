"""Per-frame object masks: ``masks/<fid>.npy``, bool ``H x W x (objects + 1)``, background last."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .atomic_io import write_npy
from .errors import SceneError


def mask_path(root: Path, frame_id: str) -> Path:
    return Path(root) / "masks" / f"{frame_id}.npy"


def check_mask_array(mask: np.ndarray, path: Path, height: int, width: int, n_objects: int) -> None:
    expected = (height, width, n_objects + 1)
    if mask.ndim != 3:
        raise SceneError(path, f"mask has {mask.ndim} dimensions, expected H x W x (objects + 1) = {expected}",
                         "re-export the masks with one channel per object plus a background channel")
    if mask.shape[2] != n_objects + 1 and mask.shape == (n_objects + 1, height, width):
        raise SceneError(path, f"mask is {mask.shape[0]} x {height} x {width}: channels first, where the layout is "
                         f"H x W x (objects + 1) = {expected}", "move the channel axis last: "
                         "np.save(path, np.moveaxis(np.load(path), 0, -1))")
    if mask.shape[2] != n_objects + 1:
        raise SceneError(path, f"mask has {mask.shape[2]} channels but mapping.yaml names {n_objects} objects "
                         f"({n_objects + 1} expected with background last)",
                         "re-export the masks with a background channel, or fix mapping.yaml")
    if mask.shape[:2] != (height, width):
        raise SceneError(path, f"mask is {mask.shape[1]}x{mask.shape[0]} but the image is {width}x{height}",
                         "resize the masks to the image size with `livescene labels` (integer factors only)")


def misnamed_mask(root: Path, frame_id: str) -> Path | None:
    """A mask file named by the frame's number but not by its id (``masks/12.npy`` for the image ``den_00012``):
    masks are found by id, so a download whose masks are padded otherwise than its images reads as masks missing."""
    if not frame_id.isdigit():
        return None
    for path in sorted((Path(root) / "masks").glob("*.npy")):
        if path.stem != frame_id and path.stem.isdigit() and int(path.stem) == int(frame_id):
            return path
    return None


def missing_mask_fix(root: Path, frame_id: str, fix: str) -> tuple[str, str]:
    """(problem, fix) for a frame whose ``masks/<id>.npy`` is missing: a mask of its number named otherwise is
    named, with the rename as the fix; else ``fix``."""
    other = misnamed_mask(root, frame_id)
    if other is None:
        return "mask file not found", fix
    return (f"mask file not found, but {other.name} carries the frame's number (masks are named by the frame id, "
            "the last '_' token of the image name, zeros included)",
            f"rename the masks after the images' ids: {other.name} -> {frame_id}.npy")


def read_mask(root: Path, frame_id: str, height: int, width: int, n_objects: int) -> np.ndarray:
    path = mask_path(root, frame_id)
    if not path.is_file():
        problem, fix = missing_mask_fix(root, frame_id, "ingest masks for every frame with `livescene labels`")
        raise SceneError(path, problem, fix)
    try:
        mask = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise SceneError(path, f"cannot read mask ({exc})", "re-export the mask as a .npy bool array") from exc
    check_mask_array(mask, path, height, width, n_objects)
    return mask.astype(bool, copy=False)


def write_mask(root: Path, frame_id: str, mask: np.ndarray) -> Path:
    path = mask_path(root, frame_id)
    write_npy(path, np.ascontiguousarray(mask, dtype=bool))
    return path


def label_map_to_onehot(labels: np.ndarray, n_objects: int) -> np.ndarray:
    """Integer label map (0..n-1 objects, n or -1 = background) -> one-hot bool mask."""
    labels = np.where(labels < 0, n_objects, labels)
    out = np.zeros((*labels.shape, n_objects + 1), dtype=bool)
    np.put_along_axis(out, labels[..., None].astype(np.int64), True, axis=-1)
    return out


def onehot_to_label_map(mask: np.ndarray) -> np.ndarray:
    """One-hot mask -> integer label map (background = number of objects)."""
    return np.argmax(mask, axis=-1).astype(np.int64)


UNRELIABLE_DIVISOR = 300
"""An object present on fewer than H*W/300 pixels of a frame makes that frame's masks unreliable (the reference's
rule, docs/method.md section 5) ..."""
USUAL_SHARE = 0.25
"""... unless that is at least a quarter of the object's usual size (``USUAL_QUANTILE`` of its pixel counts over
the frames where it is visible): an object that is small everywhere (a jewellery box, a knob) would otherwise make
every frame unreliable and switch the mask losses off for the whole scene."""
USUAL_QUANTILE = 0.5
"""The median: an object whose silhouette grows as it opens (a box's lid) is not a sliver when closed (the `stress`
capture's jewellery box, 31-190 pixels: with the 0.9 quantile 35 of its closed frames read as slivers)."""


def usual_sizes(counts: np.ndarray) -> np.ndarray:
    """[frames, objects] pixel counts -> [objects] each object's usual size: ``USUAL_QUANTILE`` of its counts over
    the frames that show it (0 for an object no frame shows)."""
    counts = np.asarray(counts, dtype=np.float64).reshape(len(counts), -1)
    return np.array([np.quantile(c[c > 0], USUAL_QUANTILE) if (c > 0).any() else 0.0 for c in counts.T])


def unreliable_masks(counts: np.ndarray, height: int, width: int) -> np.ndarray:
    """[frames, objects] pixel counts -> [frames, objects] bool: present, but too few pixels to trust.

    A sliver of a large object (entering the view, almost hidden) is unreliable as in the reference; a small
    object at its usual size is not. Where every object's usual size is at least 4 H W / 300 pixels this is the
    reference's rule exactly."""
    counts = np.asarray(counts, dtype=np.float64).reshape(len(counts), -1)
    usual = usual_sizes(counts)
    limit = np.minimum(height * width / UNRELIABLE_DIVISOR, USUAL_SHARE * usual)
    return (counts > 0) & (counts < limit)
