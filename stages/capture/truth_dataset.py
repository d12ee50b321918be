"""A scene dataset written straight from a capture's truth, so training needs no frames/poses/labels/states stage.

Images are the frames of ``video.mp4`` (what a user's pipeline would see, lossy)
or, with ``images="truth"``, the lossless PNGs of ``truth/images``. Poses,
intrinsics and dense per-frame states come from ``truth/transforms.json``,
one-hot masks from ``masks/*.png``, the scene box from ``truth/scene.json``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
from tqdm import tqdm

from stages.scene import (
    Frame,
    InputError,
    SceneDataset,
    atomic_dir,
    frame_id_of,
    label_map_to_onehot,
    make_split,
    read_key_frames,
    read_scene,
    read_yaml_mapping,
    write_mask,
    write_scene,
)
from stages.scene.transforms import camera_from_dict

ImageSource = Literal["video", "truth"]


class CaptureFolderError(InputError):
    """A capture folder that is missing a file or disagrees with itself."""


def _load_json(path: Path) -> dict:
    if not path.is_file():
        raise CaptureFolderError(path, "file not found", "point --capture to a folder written by `livescene capture`")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise CaptureFolderError(path, f"not valid JSON ({exc})", "regenerate the capture") from exc


def _read_mapping(path: Path) -> tuple[list[int], list[str]]:
    raw = read_yaml_mapping(path, "{id: object_name}", error=CaptureFolderError)
    try:
        items = sorted((int(k), str(v)) for k, v in raw.items())
    except (TypeError, ValueError) as exc:
        raise CaptureFolderError(path, "ids are not integers", "write {1: name, 2: name, ...}") from exc
    return [i for i, _ in items], [n for _, n in items]


def _video_frames(path: Path, wanted: set[int], expected: int) -> dict[int, np.ndarray]:
    """Decode ``video.mp4`` once, keeping the BGR frames whose index is in ``wanted``."""
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise CaptureFolderError(path, "OpenCV cannot open the video", "regenerate the capture, or use --images truth")
    out: dict[int, np.ndarray] = {}
    i = 0
    try:
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            if i in wanted:
                out[i] = frame
            i += 1
    finally:
        cap.release()
    if i != expected:
        raise CaptureFolderError(path, f"video has {i} frames but truth/transforms.json lists {expected}",
                                 "regenerate the capture (the video and the truth disagree)")
    return out


def capture_to_dataset(capture_dir: str | Path, out_dir: str | Path, *, split: str = "alternate",
                       split_n: int = 10, every: int = 1, images: ImageSource = "video",
                       progress: bool = True, replace: bool = False, masks: bool = True,
                       states: bool = True) -> SceneDataset:
    """Write the scene dataset of a capture's truth to ``out_dir`` (atomically) and return it, validated.

    ``every`` keeps every n-th video frame (source index 0, n, 2n, ...); key frames that fall
    on dropped frames are dropped with them. ``split`` is a ``stages.scene.make_split`` method
    applied to the kept frames in order. ``replace``: an existing ``out_dir`` that is not an earlier dataset
    is replaced too (``--force``). ``masks`` / ``states`` False leave out the masks / the frames' states and the key
    frames, as a room filmed without them; without both the room has no objects (nothing gives their pixels or
    states): no mapping and no prompts either.
    """
    cap = Path(capture_dir)
    out_dir = Path(out_dir)
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    tpath = cap / "truth" / "transforms.json"
    truth = _load_json(tpath)
    camera = camera_from_dict(truth, tpath, "top level")
    truth_frames = truth.get("frames")
    if not isinstance(truth_frames, list) or not truth_frames:
        raise CaptureFolderError(tpath, "no frames", "regenerate the capture")
    scene_info = _load_json(cap / "truth" / "scene.json")
    object_ids, objects = _read_mapping(cap / "mapping.yaml")
    key_frames = read_key_frames(cap / "key_frame_value.yaml", objects) if states else {}
    prompts = read_yaml_mapping(cap / "prompts.yaml", "{name: {synonyms: [...], description: ...}}",
                                error=CaptureFolderError, missing_ok=True)
    if not masks and not states:
        object_ids, objects, prompts = [], [], {}

    kept = [fr for fr in truth_frames if int(fr["source_index"]) % every == 0]
    splits = make_split(len(kept), split, n=split_n)  # type: ignore[arg-type]
    indices = [int(fr["source_index"]) for fr in kept]
    video = _video_frames(cap / "video.mp4", set(indices), len(truth_frames)) if images == "video" else {}
    id_to_channel = np.full(256, -1, dtype=np.int64)  # PNG id k -> mask channel; 0 and unknown -> background
    for channel, k in enumerate(object_ids):
        id_to_channel[k] = channel

    frames: list[Frame] = []
    with atomic_dir(out_dir, "dataset", inputs=[capture_dir], legacy=["scene.json"], force=replace) as tmp:
        (tmp / "images").mkdir()
        for fr, sp in tqdm(list(zip(kept, splits, strict=True)), desc="capture dataset", unit="frame",
                           disable=not progress):
            i = int(fr["source_index"])
            name = Path(fr["file_path"]).name
            if images == "video":
                bgr = video[i]
            else:
                bgr = cv2.imread(str(cap / "truth" / "images" / name), cv2.IMREAD_COLOR)
                if bgr is None:
                    raise CaptureFolderError(cap / "truth" / "images" / name, "lossless frame missing",
                                             "regenerate with write_truth_images: true, or use --images video")
            cv2.imwrite(str(tmp / "images" / name), bgr)
            if objects and masks:  # no masks without a mapping: the dataset contract pairs them
                mpath = cap / "masks" / name
                ids = cv2.imread(str(mpath), cv2.IMREAD_UNCHANGED)
                if ids is None or ids.shape != (camera.height, camera.width):
                    raise CaptureFolderError(mpath, "id mask missing or of the wrong size",
                                             f"regenerate the capture ({camera.width}x{camera.height} uint8 PNGs)")
                write_mask(tmp, frame_id_of(Path(name).stem),
                           label_map_to_onehot(id_to_channel[ids], len(objects)))
            frames.append(Frame(file_path=f"images/{name}", c2w=np.asarray(fr["transform_matrix"], dtype=np.float64),
                                state={k: float(v) for k, v in fr["state"].items()} if states and objects else None,
                                split=sp, source_index=i))
        known = {f.frame_id for f in frames}
        kept_keys = {fid: v for fid, v in key_frames.items() if fid in known}
        meta = {
            "units": scene_info.get("units", "m"),
            "units_per_metre": scene_info.get("units_per_metre", 1.0),
            "source": {"kind": "capture truth", "capture": str(cap.resolve()), "images": images, "every": every,
                       "split": split, "key_frames_dropped": sorted(set(key_frames) - known)},
        }
        left_out = [item for item, kept in (("masks", masks), ("states", states)) if not kept]
        if left_out:
            meta["source"]["left_out"] = left_out
        ds = SceneDataset(root=tmp, camera=camera, frames=frames, objects=objects, object_ids=object_ids,
                          key_frames=kept_keys, scene_box=np.asarray(scene_info["scene_box"], dtype=np.float64),
                          prompts=prompts, meta=meta)
        write_scene(ds, tmp)
        read_scene(tmp, validate=True, deep=True)  # publish only a dataset that passes the contract
    return read_scene(out_dir, validate=True)
