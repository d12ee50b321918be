"""``livescene dataset assemble``: frames + poses + labels + states -> one validated scene dataset.

Only frames that have a pose are kept (COLMAP may fail to register some); the
dropped ones are listed in scene.json. ``--poses`` may be a POSES folder of
``livescene poses`` (transforms.json + scene.json) or any nerfstudio
transforms.json, such as the truth poses of a synthetic capture (its scene.json,
when next to it, gives the scene box; truth states in it are ignored: states
come from STATES).

It joins the outputs of the frames, poses, labels and states stages, so it is a
stage of its own after them, not part of the shared ``stages.scene`` contract
(docs/data-contract.md, "Stage order").
"""

from __future__ import annotations

import json
import os
import shutil
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
from tqdm import tqdm

from stages.scene import (
    Camera,
    Frame,
    SceneDataset,
    SceneError,
    atomic_dir,
    frame_id_of,
    make_split,
    read_key_frames,
    read_scene,
    read_yaml_mapping,
    write_scene,
)
from stages.scene.dataset import NERFSTUDIO_KEYS
from stages.scene.masks import check_mask_array, mask_path
from stages.scene.splits import SplitMethod
from stages.scene.transforms import camera_from_dict, frame_camera_dict, load_json, parse_pose
from stages.states import read_states_csv

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg"}
POINTS_NAME = "points3D.ply"
"""The point cloud's name in a scene dataset (that of COLMAP's export and of the poses stage)."""


class AssembleError(SceneError):
    """Stage outputs that do not fit together into one scene dataset."""


@dataclass
class AssembleConfig:
    """The stage folders `livescene dataset assemble` joins, and where it writes."""

    frames: Path
    """FRAMES folder (images/ + frames.csv)."""
    poses: Path
    """POSES folder (transforms.json + scene.json) or a transforms.json file (e.g. CAPTURE/truth/transforms.json)."""
    out: Path
    """Scene dataset folder to write."""
    labels: Path | None = None
    """LABELS folder (masks/, mapping.yaml, labels.json); None = a dataset without masks."""
    states: Path | None = None
    """STATES folder (states.csv, key_frame_value.yaml); None = frames without states."""
    prompts: Path | None = None
    """prompts.yaml {object: {synonyms, description}} to include."""
    split: SplitMethod = "alternate"
    """Train/test split rule (see stages.scene.make_split)."""
    split_n: int = 10
    """n of the every_n split."""
    test_fraction: float = 0.1
    """Test fraction of the fraction split."""
    copy_images: bool = False
    """Copy images and masks instead of hard-linking them (links fall back to copies across file systems)."""
    progress: bool = True
    """Show a progress bar."""


@dataclass(frozen=True)
class PosedFrame:
    """A registered frame: its image name, pose and source index."""

    name: str
    c2w: np.ndarray
    camera: Camera | None
    source_index: int | None


@dataclass(frozen=True)
class Poses:
    """What a poses transforms.json gives the dataset."""

    path: Path
    shared: Camera | None
    """The top level's camera (None: every frame has its own)."""
    frames: list[PosedFrame]
    scene: dict[str, Any]
    """scene.json beside it, or {}."""
    points: Path | None
    """Its point cloud (``ply_file_path``)."""
    nerfstudio: dict[str, Any]
    """nerfstudio's records of the poses' world (``applied_transform``, ...), kept in the dataset."""


def read_poses(poses: Path, image_hw: tuple[int, int] | None = None) -> Poses:
    """A poses transforms.json (nerfstudio or Blender form); ``image_hw`` sizes a Blender camera without w/h."""
    tpath = poses / "transforms.json" if poses.is_dir() else poses
    data = load_json(tpath)
    raw = data.get("frames")
    if not isinstance(raw, list) or not raw:
        raise AssembleError(tpath, "no registered frames", "re-run `livescene poses` (or check the file)")
    shared = None
    if "fl_x" in data or "camera_angle_x" in data:
        shared = camera_from_dict(data, tpath, "top level", image_hw)
    frames = []
    seen: dict[str, int] = {}
    for i, fr in enumerate(raw):
        where = f"frames[{i}]"
        if not isinstance(fr, dict) or "file_path" not in fr or "transform_matrix" not in fr:
            raise AssembleError(tpath, f"{where} lacks file_path or transform_matrix", "re-export the poses")
        name = Path(str(fr["file_path"])).name
        if Path(name).suffix.lower() not in IMAGE_SUFFIXES:
            name += ".png"
        if name in seen:
            raise AssembleError(tpath, f"frames[{seen[name]}] and {where} both give a pose for {name}",
                                "keep one entry per image (the later one would silently replace the earlier)")
        seen[name] = i
        own = frame_camera_dict(data, fr)
        cam = camera_from_dict(own, tpath, where, image_hw) if own is not None else None
        if cam is None and shared is None:
            raise AssembleError(tpath, f"{where}: no intrinsics", "give fl_x, fl_y, cx, cy, w, h or camera_angle_x")
        src = fr.get("source_index")
        frames.append(PosedFrame(name, parse_pose(fr["transform_matrix"], tpath, f"{where} ({name})"), cam,
                                 None if src is None else int(src)))
    spath = tpath.with_name("scene.json")
    scene = load_json(spath) if spath.is_file() else {}
    ply = data.get("ply_file_path")
    points = None if ply is None else tpath.parent / str(ply)
    if points is not None and not points.is_file():
        raise AssembleError(tpath, f"ply_file_path {ply!r} names no file", "re-run `livescene poses`, or drop the key")
    kept = {k: data[k] for k in NERFSTUDIO_KEYS if k in data and k != "ply_file_path"}
    return Poses(tpath, shared, frames, scene, points, kept)


def list_images(frames_dir: Path) -> tuple[Path, dict[str, str], dict[str, int]]:
    """(image folder, frame id -> image name, image name -> source index from frames.csv)."""
    image_dir = frames_dir / "images" if (frames_dir / "images").is_dir() else frames_dir
    if not image_dir.is_dir():
        raise AssembleError(frames_dir, "frames folder not found", "pass the FRAMES folder of `livescene frames`")
    names = sorted(p.name for p in image_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not names:
        raise AssembleError(image_dir, "no images", "extract frames with `livescene frames`")
    by_id = {frame_id_of(Path(n).stem): n for n in names}
    src: dict[str, int] = {}
    csv = frames_dir / "frames.csv"
    if csv.is_file():
        table = pd.read_csv(csv)
        if {"frame", "source_index"} <= set(table.columns):
            src = {str(f): int(s) for f, s in zip(table["frame"], table["source_index"], strict=True)}
    return image_dir, by_id, src


def read_labels(labels: Path) -> tuple[list[int], list[str], dict[str, Any]]:
    mpath = labels / "mapping.yaml"
    raw = read_yaml_mapping(mpath, "{int_id: object_name}", error=AssembleError)
    if not raw:
        raise AssembleError(mpath, "no objects", "run `livescene labels` first")
    items = sorted((int(k), str(v)) for k, v in raw.items())
    lpath = labels / "labels.json"
    summary = json.loads(lpath.read_text()) if lpath.is_file() else {}
    return [i for i, _ in items], [n for _, n in items], summary


def read_states(states: Path) -> tuple[dict[str, dict[str, float]], list[str], Path]:
    """(frame id -> {object: value}, object names in first-seen order, states.csv path)."""
    spath = states / "states.csv" if states.is_dir() else states
    table = read_states_csv(spath)
    out: dict[str, dict[str, float]] = {}
    for fname, obj, value in zip(table["frame"], table["object"], table["value"], strict=True):
        out.setdefault(frame_id_of(Path(str(fname)).stem), {})[str(obj)] = float(value)
    return out, list(dict.fromkeys(str(o) for o in table["object"])), spath


def place_image(src: Path, dst: Path, copy: bool) -> None:
    """``src`` at ``dst`` by a hard link (no second copy of a video's frames and masks: every stage replaces its
    outputs by renaming new files in, so a link never sees its source change), or a copy."""
    if not copy:
        try:
            os.link(src, dst)
            return
        except OSError:
            pass
    shutil.copy2(src, dst)


def assemble_scene(config: AssembleConfig) -> SceneDataset:
    """Join the stage outputs, write the dataset atomically, validate it (deep) and return it."""
    image_dir, image_by_id, src_of_name = list_images(config.frames)
    any_image = cv2.imread(str(image_dir / next(iter(image_by_id.values()))), cv2.IMREAD_UNCHANGED) \
        if image_by_id else None
    poses = read_poses(config.poses, None if any_image is None else any_image.shape[:2])
    tpath, shared, posed, scene_json, points = poses.path, poses.shared, poses.frames, poses.scene, poses.points
    registered = {frame_id_of(Path(p.name).stem): p for p in posed}
    use = [(fid, registered[fid]) for fid in image_by_id if fid in registered]
    if not use:
        raise AssembleError(tpath, f"no pose matches an image of {image_dir} (poses name e.g. "
                            f"{[p.name for p in posed[:3]]}, images e.g. {list(image_by_id.values())[:3]})",
                            "pass the poses estimated from these frames (frame ids must match)")
    unregistered = sorted(image_by_id[f] for f in image_by_id if f not in registered)

    first = cv2.imread(str(image_dir / image_by_id[use[0][0]]), cv2.IMREAD_UNCHANGED)
    if first is None:
        raise AssembleError(image_dir / image_by_id[use[0][0]], "image unreadable", "re-extract the frames")
    height, width = first.shape[:2]
    camera = shared if shared is not None else use[0][1].camera
    assert camera is not None
    if (camera.width, camera.height) != (width, height):
        factor = width / camera.width
        if not np.isclose(height / camera.height, factor) or not (factor.is_integer() or (1 / factor).is_integer()):
            raise AssembleError(tpath, f"poses are for {camera.width}x{camera.height} images but the frames are "
                                f"{width}x{height}", "estimate poses on these frames (or an integer downscale)")
        camera = camera.scaled(factor)

    objects: list[str] = []
    object_ids: list[int] = []
    label_summary: dict[str, Any] = {}
    if config.labels is not None:
        object_ids, objects, label_summary = read_labels(config.labels)
    states: dict[str, dict[str, float]] = {}
    key_frames: dict[str, dict[str, float]] = {}
    if config.states is not None:
        states, state_objects, spath = read_states(config.states)
        if objects and set(state_objects) != set(objects):
            raise AssembleError(spath, f"states are for objects {state_objects} but {config.labels}/mapping.yaml "
                                f"names {objects}", "ingest labels and states for the same objects (same names)")
        if not objects:
            objects, object_ids = state_objects, list(range(1, len(state_objects) + 1))
        kpath = (config.states if config.states.is_dir() else config.states.parent) / "key_frame_value.yaml"
        key_frames = read_key_frames(kpath, objects)
    prompts: dict[str, Any] = {}
    if config.prompts is not None:
        prompts = read_yaml_mapping(config.prompts, "{object: {synonyms: [...], description: ...}}",
                                    error=AssembleError)
        unknown = sorted(set(map(str, prompts)) - set(objects)) if objects else []
        if unknown:
            raise AssembleError(config.prompts, f"prompts for unknown objects {unknown} (objects {objects})",
                                "use the object names of mapping.yaml")

    def source_index(fid: str, p: PosedFrame) -> int | None:
        name = image_by_id[fid]
        if name in src_of_name:
            return src_of_name[name]
        if p.source_index is not None:
            return p.source_index
        return int(fid) if fid.isdigit() else None

    use.sort(key=lambda item: (source_index(*item) if source_index(*item) is not None else 0, item[0]))
    splits = make_split(len(use), config.split, n=config.split_n, test_fraction=config.test_fraction)
    used_ids = {fid for fid, _ in use}
    without_masks: list[str] = []
    inputs = [config.frames, config.poses, config.labels, config.states]
    with atomic_dir(config.out, "dataset", inputs=inputs, legacy=["scene.json"]) as tmp:
        (tmp / "images").mkdir()
        frames: list[Frame] = []
        for (fid, p), split in tqdm(list(zip(use, splits, strict=True)), desc="assemble", unit="frame",
                                    disable=not config.progress):
            name = image_by_id[fid]
            place_image(image_dir / name, tmp / "images" / name, config.copy_images)
            state = None
            if config.states is not None:
                state = states.get(fid)
                missing = [o for o in objects if state is None or o not in state]
                if missing:
                    raise AssembleError(spath, f"frame {name} has no state for {missing}",
                                        "run `livescene states` on the frames.csv of these frames")
            cam = None
            if p.camera is not None:  # per-frame intrinsics, brought to the image size like the shared ones
                cam = p.camera if p.camera.width == width else p.camera.scaled(width / p.camera.width)
            frames.append(Frame(file_path=f"images/{name}", c2w=p.c2w, state=state, split=split, camera=cam,
                                source_index=source_index(fid, p)))
            if config.labels is not None:
                src_mask = mask_path(config.labels, fid)
                if not src_mask.is_file():
                    without_masks.append(fid)
                    continue
                try:
                    arr = np.load(src_mask, mmap_mode="r", allow_pickle=False)
                except (ValueError, OSError, EOFError) as exc:
                    raise AssembleError(src_mask, f"cannot read the mask ({exc})",
                                        "re-run `livescene labels` to write it again") from exc
                check_mask_array(arr, src_mask, height, width, len(objects))
                (tmp / "masks").mkdir(exist_ok=True)
                place_image(src_mask, mask_path(tmp, fid), config.copy_images)  # linked as the images are
        if config.labels is not None and frames and len(without_masks) == len(frames):
            raise AssembleError(config.labels / "masks", f"none of the {len(frames)} frames has a mask here "
                                "(<frame id>.npy, as `livescene labels` writes them)",
                                "pass the folder `livescene labels --out` wrote (masks/*.npy, mapping.yaml, "
                                "labels.json), not the annotations it reads; or leave out --labels for a dataset "
                                "without masks")
        meta: dict[str, Any] = {k: v for k, v in scene_json.items() if k not in ("scene_box",)}
        meta.update({
            "assembled_from": {"frames": str(config.frames), "poses": str(tpath),
                               "labels": None if config.labels is None else str(config.labels),
                               "states": None if config.states is None else str(config.states)},
            "split_rule": config.split,
            "unregistered_frames": unregistered,
        })
        if config.labels is not None:
            meta["frames_without_masks"] = without_masks
            meta["unreliable_mask_frames"] = {f: v for f, v in label_summary.get("unreliable_frames", {}).items()
                                              if f in used_ids}
        box = scene_json.get("scene_box")
        ds = SceneDataset(root=tmp, camera=camera, frames=frames, objects=objects, object_ids=object_ids,
                          key_frames={f: v for f, v in key_frames.items() if f in used_ids},
                          scene_box=None if box is None else np.asarray(box, dtype=np.float64),
                          prompts=prompts, meta=meta)
        ds.nerfstudio.update(poses.nerfstudio)  # the poses' world as nerfstudio recorded it (applied_transform)
        if points is not None:  # the poses' point cloud travels with the dataset (nerfstudio, `dataset orient`)
            place_image(points, tmp / POINTS_NAME, config.copy_images)
            ds.nerfstudio["ply_file_path"] = POINTS_NAME
        write_scene(ds, tmp)
        try:
            with warnings.catch_warnings(record=True) as said:
                warnings.simplefilter("always")
                read_scene(tmp, validate=True, deep=True)
            for w in said:  # e.g. states clamped to [0, 1]: named where the file will be
                warnings.warn(str(w.message).replace(str(tmp), str(config.out)), w.category, stacklevel=2)
        except SceneError as exc:  # name the file where it will be, not in the temporary folder
            where = exc.path.relative_to(tmp) if exc.path.is_relative_to(tmp) else exc.path
            raise AssembleError(config.out / where, exc.problem, exc.fix) from None
    return read_scene(config.out, validate=False)
