"""The scene dataset: read, write and validate the folder every stage shares.

Layout (that of the published LiveScene sets, plus optional extensions)::

    transforms.json        nerfstudio or Blender form; frames may carry
                           "state" {object: value}, "split", "source_index";
                           top level: train/val/test_filenames (nerfstudio's
                           split, mirrors "split"), applied_transform,
                           ply_file_path
    images/                one image per frame, frame id = last "_" token of the stem
    masks/<fid>.npy        bool H x W x (objects + 1), background last
    mapping.yaml           {int_id: object name}; channel order = sorted ids
    key_frame_value.yaml   {<name>_<fid>: {object: value}}, sparse
    prompts.yaml           optional {object: {synonyms: [...], description: str}}
    scene.json             optional: scene box, units, normalisation, provenance
"""

from __future__ import annotations

import hashlib
import json
import posixpath
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from .atomic_io import write_json, write_yaml
from .camera import Camera
from .errors import SceneError
from .keyframes import frame_id_of, frame_number_of, read_key_frames, write_key_frames
from .masks import mask_path, missing_mask_fix, read_mask
from .splits import reference_split
from .transforms import (
    camera_from_dict,
    camera_to_dict,
    check_camera_model,
    frame_camera_dict,
    load_json,
    parse_pose,
    resolve_image_path,
)
from .yaml_io import read_yaml_mapping

NERFSTUDIO_KEYS = ("applied_transform", "applied_scale", "ply_file_path", "orientation_override")
"""Top-level transforms.json keys of nerfstudio that this project does not interpret but keeps on a
read-write round trip (they describe the world of the poses; ``dataset orient`` composes its turn into
``applied_transform``)."""
SPLIT_KEYS = {"train_filenames": "train", "val_filenames": "test", "test_filenames": "test"}
"""nerfstudio's split lists -> this project's per-frame split. nerfstudio evaluates on ``val`` while
training and on ``test`` in ``ns-eval``, so both name the held-out frames."""


STATE_SEEN_WITHIN = 0.125
"""A state counts as seen for an object when a frame holds the object within this distance of it: the
evaluation's unseen combinations use only such levels, and ``livescene control`` names a state beyond them."""


def spans_closed_to_open(lo_hi: list[float] | None) -> bool:
    """Whether an object's ``[min, max]`` of states comes within ``STATE_SEEN_WITHIN`` of both 0 and 1 (True when
    unknown): where not, the report's slider and the viewer's say that renders beyond it extrapolate."""
    return lo_hi is None or (lo_hi[0] <= STATE_SEEN_WITHIN and lo_hi[1] >= 1.0 - STATE_SEEN_WITHIN)

@dataclass
class Frame:
    """One posed image of the capture."""

    file_path: str
    """Image path relative to the dataset root, as written in transforms.json."""
    c2w: np.ndarray
    """4x4 camera-to-world matrix, OpenGL camera axes."""
    state: dict[str, float] | None = None
    """Interaction variable per object name (0 closed, 1 open), when known."""
    split: str | None = None
    """"train" or "test"; None when the file does not say."""
    camera: Camera | None = None
    """Per-frame intrinsics; None = the dataset's shared camera."""
    source_index: int | None = None
    """Index of this frame in the source video, when it came from one."""

    @property
    def frame_id(self) -> str:
        return frame_id_of(Path(self.file_path).stem)


@dataclass
class SceneDataset:
    """A scene dataset in memory; images and masks stay on disk and load on demand."""

    root: Path
    camera: Camera
    frames: list[Frame]
    objects: list[str]
    """Object names in mask-channel order (background is the extra last channel)."""
    object_ids: list[int] = field(default_factory=list)
    """The ids of mapping.yaml, aligned with ``objects``."""
    key_frames: dict[str, dict[str, float]] = field(default_factory=dict)
    scene_box: np.ndarray | None = None
    """[[xmin, ymin, zmin], [xmax, ymax, zmax]] in the coordinates of the poses."""
    prompts: dict[str, dict[str, Any]] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    """Other scene.json fields (units, normalisation, provenance, ...)."""
    nerfstudio: dict[str, Any] = field(default_factory=dict)
    """Top-level transforms.json keys of nerfstudio as read: ``NERFSTUDIO_KEYS`` are written back (an
    absent ``applied_transform`` as the identity: the poses' world is the data's own); the split
    lists are only checked, ``write_scene`` writes them anew from the frames' splits."""
    split_note: str | None = None
    """How the split was derived when transforms.json names none (``reference_split``); None when it names one."""

    def __post_init__(self) -> None:
        if not self.object_ids:
            self.object_ids = list(range(len(self.objects)))

    @property
    def n_objects(self) -> int:
        return len(self.objects)

    @property
    def states_at_key_frames_only(self) -> bool:
        """The published form: key frames give states and no frame carries its own (the trainer learns them, and
        their values are normalised as the reference's, ``key_frame_states``)."""
        return bool(self.key_frames) and not any(f.state for f in self.frames)

    @property
    def has_masks(self) -> bool:
        return (self.root / "masks").is_dir()

    def camera_of(self, frame: Frame) -> Camera:
        return frame.camera or self.camera

    def image_path(self, frame: Frame) -> Path:
        return resolve_image_path(self.root, frame.file_path)

    def load_image(self, frame: Frame) -> np.ndarray:
        """RGB float32 image in [0, 1], ``[H, W, 3]`` (alpha composited on white if present)."""
        path = self.image_path(frame)
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise SceneError(path, "image missing or unreadable", "restore the image or drop the frame")
        check_image_size(self, frame, path, img)
        if img.ndim == 2:
            img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        scale = 65535.0 if img.dtype == np.uint16 else 255.0
        img = img.astype(np.float32) / scale
        if img.shape[2] == 4:
            alpha = img[..., 3:4]
            img = img[..., :3] * alpha + (1.0 - alpha)
        return np.ascontiguousarray(img[..., ::-1])

    def load_mask(self, frame: Frame) -> np.ndarray:
        cam = self.camera_of(frame)
        return read_mask(self.root, frame.frame_id, cam.height, cam.width, self.n_objects)

    def load_mask_or_none(self, frame: Frame) -> np.ndarray | None:
        """The frame's one-hot mask, or None where the dataset says it has none (``frames_without_masks``)."""
        try:
            return self.load_mask(frame)
        except SceneError:
            if frame.frame_id in set(map(str, self.meta.get("frames_without_masks", []))):
                return None
            raise

    def frame_by_id(self, frame_id: str) -> Frame:
        """The frame whose id (the last ``_`` token of its image name) is ``frame_id``, or else the one frame whose id
        is that number padded otherwise (``7`` for ``00007``, as key frames pair); an unknown id is refused, showing
        the ids the dataset has (and the id an image name given instead would have)."""
        found = next((f for f in self.frames if f.frame_id == frame_id), None)
        if found is None and frame_id.isdigit():  # a number: paired as a key frame is (an image name stays refused)
            from .key_frame_states import match_key_frames  # imports this module

            matched, _ = match_key_frames([frame_id], self.frames)
            found = self.frames[matched[frame_id]] if frame_id in matched else None
        if found is None:
            ids = [f.frame_id for f in self.frames]
            own = frame_id_of(frame_id)
            hint = f" (an image name? its id is {own!r})" if own != frame_id and own in ids else ""
            shown = ", ".join(ids[:4]) + (f", ... ({len(ids)} frames)" if len(ids) > 4 else "")
            raise SceneError(self.root / "transforms.json", f"no frame with id {frame_id!r}{hint}",
                             f"pick one of the dataset's frame ids: {shown}")
        return found

    def frames_in(self, split: str) -> list[Frame]:
        return [f for f in self.frames if (f.split or "train") == split]

    def state_matrix(self, frames: list[Frame] | None = None) -> np.ndarray:
        """``[n_frames, n_objects]`` states; NaN where a frame carries none. Where no frame of the dataset carries
        states (the published form: states only at key frames), a key frame's state, normalised as the trainer
        normalises it (``key_frame_states``), is its frame's: what a learned run was told at that frame."""
        frames = self.frames if frames is None else frames
        out = np.full((len(frames), self.n_objects), np.nan, dtype=np.float64)
        keyed: dict[str, dict[str, float]] = {}
        if self.states_at_key_frames_only:
            from .key_frame_states import key_frame_states

            keyed = {self.frames[i].frame_id: v for i, v in key_frame_states(self).by_frame.items()}
        for i, f in enumerate(frames):
            state = f.state or keyed.get(f.frame_id)
            if state:
                for j, name in enumerate(self.objects):
                    if name in state:
                        out[i, j] = state[name]
        return out

    def state_ranges(self, frames: list[Frame] | None = None) -> dict[str, list[float] | None]:
        """Per object, ``[min, max]`` of its states over ``frames``, by default the training frames (all frames
        where none is marked train); None where none has one."""
        matrix = self.state_matrix((self.frames_in("train") or self.frames) if frames is None else frames)
        out: dict[str, list[float] | None] = {}
        for name, column in zip(self.objects, matrix.T, strict=True):
            finite = column[np.isfinite(column)]
            out[name] = [float(finite.min()), float(finite.max())] if finite.size else None
        return out


def object_name_problem(name: str) -> str | None:
    """Why ``name`` cannot name an object, or None: names become file names (``objects/<name>_mesh.ply``, the
    per-object mask folders), so a path separator or a bare ``.`` / ``..`` would write outside an output folder."""
    if not name.strip():
        return "is empty"
    if "/" in name or "\\" in name:
        return "holds a path separator ('/' or '\\')"
    if name.strip() in (".", ".."):
        return "is a folder name ('.' or '..')"
    if any(ord(c) < 32 for c in name):
        return "holds a control character"
    return None


def fit_file_name(stem: str, limit: int = 160) -> str:
    """``stem`` when its UTF-8 form is at most ``limit`` bytes, else its start and a hash of the whole: a file name
    holds 255 bytes, and a stem built from object names (three names of 100 letters, or 100 CJK characters, which
    take 3 bytes each) passes that."""
    raw = stem.encode()
    if len(raw) <= limit:
        return stem
    return raw[:limit - 11].decode(errors="ignore") + "-" + hashlib.sha1(raw).hexdigest()[:10]


def file_stem(name: str) -> str:
    """An object name as a file name: path separators and a bare '.' / '..' replaced (names are checked where they
    are read; this keeps a file inside its folder whatever reaches it), long names fitted (``fit_file_name``)."""
    stem = name.replace("/", "-").replace("\\", "-")
    return "_" if stem.strip() in ("", ".", "..") else fit_file_name(stem)


def names_read_alike(names: list[str]) -> str | None:
    """Why two of ``names`` cannot name two objects, or None: names that differ only in letter case or punctuation
    ("Drawer" and "drawer", "drawer-2" and "drawer 2") read the same in a language command or relevancy query (names
    compare in lower case, words only: stages.language.vocabulary.normalize_phrase), so neither can be named; and
    on a file system that ignores case their files (``objects/<name>_mesh.ply``) would be one."""
    seen: dict[str, str] = {}
    for name in names:
        key = " ".join(re.findall(r"[^\W_]+", name.lower().replace("_", " ")))
        if key and key in seen and seen[key] != name:
            return (f"object names {seen[key]!r} and {name!r} differ only in letter case or punctuation, so a "
                    f"command or query reads both as {key!r}")
        seen.setdefault(key, name)
    return None


def _read_mapping(path: Path) -> tuple[list[int], list[str]]:
    if not path.is_file():
        return [], []
    raw = read_yaml_mapping(path, "{int_id: object_name}")
    items: list[tuple[int, str]] = []
    for k, v in raw.items():
        if isinstance(v, bool) or v is None:  # yes / on / null unquoted: YAML's boolean or nothing, not the word
            raise SceneError(path, f"id {k!r}: YAML reads the name as {v}, not as words",
                             f"quote the name: `{k}: 'yes'` (or whichever word it is)")
        try:
            items.append((int(k), str(v)))
        except (TypeError, ValueError) as exc:
            raise SceneError(path, f"id {k!r} is not an integer", "write {int_id: object_name}") from exc
    items.sort()
    names = [n for _, n in items]
    for n in names:
        if (problem := object_name_problem(n)) is not None:
            raise SceneError(path, f"object name {n!r} {problem}", "name the object in words (e.g. 'top drawer')")
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise SceneError(path, f"object names {dupes} appear more than once", "give each object one unique name")
    if (problem := names_read_alike(names)) is not None:
        raise SceneError(path, problem, "rename one of them in words (e.g. 'left drawer')")
    return [i for i, _ in items], names


def read_scene(root: str | Path, *, validate: bool = True, deep: bool = False) -> SceneDataset:
    """Read a scene dataset; with ``validate`` the contract is checked (``deep`` opens every image)."""
    root = Path(root)
    tpath = root / "transforms.json"
    data = load_json(tpath)
    object_ids, objects = _read_mapping(root / "mapping.yaml")
    frames_raw = data.get("frames")
    if not isinstance(frames_raw, list) or not frames_raw:
        raise SceneError(tpath, "no \"frames\" list (or it is empty)", "write one entry per posed image")

    image_hw = None
    if "camera_angle_x" in data and not ("w" in data and "h" in data):
        first = frames_raw[0].get("file_path", "") if isinstance(frames_raw[0], dict) else ""
        img = cv2.imread(str(resolve_image_path(root, first)), cv2.IMREAD_UNCHANGED)
        if img is not None:
            image_hw = img.shape[:2]
    check_camera_model(data, tpath, "top level")  # also when the intrinsics are per frame
    shared = None
    if any(k in data for k in ("fl_x", "camera_angle_x")):
        shared = camera_from_dict(data, tpath, "top level", image_hw)

    frames: list[Frame] = []
    clamped: list[str] = []
    for i, fr in enumerate(frames_raw):
        where = f"frames[{i}]"
        if not isinstance(fr, dict):
            raise SceneError(tpath, f"{where} is not an object", "write {file_path, transform_matrix}")
        for key in ("file_path", "transform_matrix"):
            if key not in fr:
                raise SceneError(tpath, f"{where} has no {key!r}", f"add {key!r} to every frame")
        where = f"{where} ({fr['file_path']})"
        c2w = parse_pose(fr["transform_matrix"], tpath, where)
        own = frame_camera_dict(data, fr)
        cam = camera_from_dict(own, tpath, where, image_hw) if own is not None else None
        if cam is None and shared is None:
            raise SceneError(tpath, f"{where}: no intrinsics at top level or in the frame",
                             "add fl_x, fl_y, cx, cy, w, h or camera_angle_x")
        state = fr.get("state")
        if state is not None:
            if not isinstance(state, dict):
                raise SceneError(tpath, f"{where}: state is not a mapping of object to value",
                                 "write \"state\": {object: value}")
            words = {str(k): v for k, v in state.items() if isinstance(v, (str, bool)) or v is None}
            if words:
                name, value = next(iter(words.items()))
                raise SceneError(tpath, f"{where}: state of {name!r} is {value!r}, not a number",
                                 "write each object's state as a number in [0, 1] (0 closed, 1 fully open)")
            state = {str(k): float(v) for k, v in state.items()}
            bad = [k for k, v in state.items() if not np.isfinite(v)]
            if bad:
                raise SceneError(tpath, f"{where}: state of {bad} is not finite",
                                 "re-run `livescene states` to interpolate the states")
            outside = {k: v for k, v in state.items() if not 0.0 <= v <= 1.0}
            if outside:  # the model's state axes span [0, 1]; beyond it the planes clamp silently
                clamped.append(f"{fr['file_path']} {outside}")
                state = {k: min(max(v, 0.0), 1.0) for k, v in state.items()}
        split = fr.get("split")
        if split is not None and split not in ("train", "test"):
            raise SceneError(tpath, f"{where}: split {split!r} is neither 'train' nor 'test'",
                             "write \"split\": \"train\" or \"test\"")
        src = fr.get("source_index")
        frames.append(Frame(file_path=str(fr["file_path"]), c2w=c2w, state=state, split=split, camera=cam,
                            source_index=None if src is None else int(src)))
    camera = shared or frames[0].camera  # type: ignore[assignment]
    _apply_split_lists(data, frames, tpath)
    split_note = None
    if all(f.split is None for f in frames):  # a published dataset names no split: the reference derives one
        blender = "camera_angle_x" in data and "fl_x" not in data
        splits, split_note = reference_split([f.file_path for f in frames], blender)
        for f, split in zip(frames, splits, strict=True):
            f.split = split
    nerfstudio = {k: data[k] for k in (*NERFSTUDIO_KEYS, *SPLIT_KEYS) if k in data}
    if "applied_transform" in nerfstudio:
        m = np.asarray(nerfstudio["applied_transform"], dtype=np.float64)
        if m.shape not in ((3, 4), (4, 4)) or not np.isfinite(m).all():
            raise SceneError(tpath, f"applied_transform has shape {m.shape} or non-finite entries, expected 3x4",
                             "write nerfstudio's 3x4 applied_transform, or drop the key if the world was not changed")
    ignored = [fr["file_path"] for fr in frames_raw if "mask_path" in fr]
    if ignored:  # nerfstudio's pixels to leave out (a person, the capturer's hand): not read here
        warnings.warn(f"{tpath}: {len(ignored)} frame(s) give nerfstudio's mask_path (pixels to leave out of "
                      f"training, e.g. {ignored[0]}); this project does not read it and trains on every pixel; fix: "
                      "crop or inpaint what those masks cover, or drop mask_path to silence this", stacklevel=2)
    if clamped:
        shown = "; ".join(clamped[:10]) + (f"; and {len(clamped) - 10} more" if len(clamped) > 10 else "")
        warnings.warn(f"{tpath}: states outside [0, 1] clamped to [0, 1] in {len(clamped)} frame(s): {shown}; fix: "
                      "re-run `livescene states` (it normalises key frames to [0, 1])", stacklevel=2)

    meta: dict[str, Any] = {}
    scene_box = None
    spath = root / "scene.json"
    if spath.is_file():
        meta = load_json(spath)
        if "scene_box" in meta:
            scene_box = np.asarray(meta.pop("scene_box"), dtype=np.float64)
            if scene_box.shape != (2, 3) or not np.isfinite(scene_box).all() or (scene_box[1] <= scene_box[0]).any():
                raise SceneError(spath, f"scene_box {scene_box.tolist()} is not [[min xyz], [max xyz]] with min < max",
                                 "re-estimate it with `livescene poses` or fix it by hand")
    prompts: dict[str, dict[str, Any]] = read_yaml_mapping(
        root / "prompts.yaml", "{name: {synonyms: [...], description: ...}}", missing_ok=True)

    key_frames = read_key_frames(root / "key_frame_value.yaml", objects or None)
    ds = SceneDataset(root=root, camera=camera, frames=frames, objects=objects, object_ids=object_ids,
                      key_frames=key_frames, scene_box=scene_box, prompts=prompts, meta=meta, nerfstudio=nerfstudio,
                      split_note=split_note)
    if validate:
        validate_scene(ds, deep=deep)
    return ds


def _apply_split_lists(data: dict[str, Any], frames: list[Frame], tpath: Path) -> None:
    """Per-frame split from nerfstudio's ``train/val/test_filenames`` (compared as paths from the
    dataset folder); a frame whose own ``split`` disagrees with the lists is an error."""
    by_path = {posixpath.normpath(f.file_path): f for f in frames}
    listed: dict[str, tuple[str, str]] = {}
    for key, split in SPLIT_KEYS.items():
        names = data.get(key)
        if names is None:
            continue
        if not isinstance(names, list):
            raise SceneError(tpath, f"{key} is not a list of file paths", f"write \"{key}\": [file_path, ...]")
        for n in names:
            norm = posixpath.normpath(str(n))
            if norm not in by_path:
                continue  # validate_scene names it, after the checks of the frames themselves
            if norm in listed and listed[norm][1] != split:
                raise SceneError(tpath, f"{n} is in both {listed[norm][0]} and {key}",
                                 "put every frame in one split only")
            listed[norm] = (key, split)
    for norm, (key, split) in listed.items():
        frame = by_path[norm]
        if frame.split is None:
            frame.split = split
        elif frame.split != split:
            raise SceneError(tpath, f"frame {frame.file_path} has split {frame.split!r} but is listed in {key}",
                             "regenerate the file (`livescene dataset assemble` writes both from one split)")


def split_lists(frames: list[Frame]) -> dict[str, list[str]]:
    """nerfstudio's split keys for frames that carry a split (a frame without one trains, as in
    ``SceneDataset.frames_in``); empty when no frame says."""
    if all(f.split is None for f in frames):
        return {}
    test = [f.file_path for f in frames if f.split == "test"]
    return {"train_filenames": [f.file_path for f in frames if (f.split or "train") == "train"],
            "val_filenames": test, "test_filenames": test}


def check_image_size(ds: SceneDataset, frame: Frame, path: Path, img: np.ndarray) -> None:
    """An image whose size is not its camera's (transforms.json's w / h) is refused, naming both sizes."""
    cam = ds.camera_of(frame)
    if img.shape[:2] != (cam.height, cam.width):
        raise SceneError(path, f"image is {img.shape[1]}x{img.shape[0]} but transforms.json says "
                         f"{cam.width}x{cam.height}", "rescale the intrinsics or the images "
                         "(`livescene scene validate --deep` checks every image)")


def validate_scene(ds: SceneDataset, *, deep: bool = False) -> None:
    """Check the contract; raise the first SceneError found, naming file, problem and fix."""
    tpath = ds.root / "transforms.json"
    seen: dict[str, str] = {}
    for f in ds.frames:
        if f.frame_id in seen:
            raise SceneError(tpath, f"frame id {f.frame_id!r} used by both {seen[f.frame_id]} and {f.file_path}",
                             "give every image a unique last '_' token in its name")
        seen[f.frame_id] = f.file_path
        path = ds.image_path(f)
        if not path.is_file():
            if "\\" in f.file_path:  # colmap2nerf on Windows writes .\images\x.png; nerfstudio reads "/" only
                raise SceneError(tpath, f"file_path {f.file_path!r} is a Windows path ('\\' separators)",
                                 "write the paths with '/' (e.g. images/frame_00000.png)")
            raise SceneError(path, f"image named by {tpath.name} ({f.file_path}) not found",
                             "restore the image or remove the frame from transforms.json")
        if f.state is not None and ds.objects:
            unknown = sorted(set(f.state) - set(ds.objects))
            if unknown:
                raise SceneError(tpath, f"frame {f.file_path}: state names unknown objects {unknown}",
                                 f"use the names of mapping.yaml {ds.objects}")
    known = {posixpath.normpath(f.file_path) for f in ds.frames}
    for key in SPLIT_KEYS:
        unknown = [n for n in ds.nerfstudio.get(key, []) if posixpath.normpath(str(n)) not in known]
        if unknown:
            raise SceneError(tpath, f"{key} names {len(unknown)} image(s) that no frame has, e.g. {unknown[:3]}",
                             f"list the file_path of frames in {key} (nerfstudio refuses unknown names too)")
    ply = ds.nerfstudio.get("ply_file_path")
    if ply is not None and not (ds.root / str(ply)).is_file():
        raise SceneError(tpath, f"ply_file_path {ply!r} names no file in {ds.root}",
                         "copy the point cloud next to transforms.json or drop ply_file_path")
    if deep:
        for f in ds.frames:
            img = cv2.imread(str(ds.image_path(f)), cv2.IMREAD_UNCHANGED)
            if img is None:
                raise SceneError(ds.image_path(f), "image unreadable", "re-extract the frame")
            check_image_size(ds, f, ds.image_path(f), img)
    if ds.has_masks:
        if not ds.objects:
            raise SceneError(ds.root / "mapping.yaml", "masks/ exists but mapping.yaml is missing or empty",
                             "write mapping.yaml {id: name} for the objects in the masks")
        unlabeled = set(map(str, ds.meta.get("frames_without_masks", [])))
        for f in ds.frames:
            path = mask_path(ds.root, f.frame_id)
            if not path.is_file():
                if f.frame_id in unlabeled:
                    continue
                problem, fix = missing_mask_fix(ds.root, f.frame_id, "ingest masks for every frame with `livescene "
                                                "labels`, or list the frame under frames_without_masks in scene.json")
                raise SceneError(path, f"frame {f.file_path} has no mask" + problem.removeprefix("mask file not found"),
                                 fix)
            cam = ds.camera_of(f)
            try:
                arr = np.load(path, mmap_mode="r", allow_pickle=False)
            except (ValueError, OSError) as exc:
                raise SceneError(path, f"cannot read mask ({exc})", "re-export the mask as .npy") from exc
            from .masks import check_mask_array

            check_mask_array(arr, path, cam.height, cam.width, ds.n_objects)
    _check_key_frames(ds)


def _check_key_frames(ds: SceneDataset) -> None:
    """Every key frame names a frame (by id or number, ``match_key_frames``). One whose image exists but has no
    entry in transforms.json (a frame COLMAP did not register, or one dropped after annotation) is left out with
    a warning, as the reference leaves it out; one that names no image at all is a typo, refused. Key values are
    normalised here once, so that a range that cannot be applied is named by validation, not by a training."""
    from .key_frame_states import key_frame_states, match_key_frames

    kpath = ds.root / "key_frame_value.yaml"
    _, unmatched = match_key_frames(ds.key_frames, ds.frames)
    if unmatched:
        images = ds.root / "images"
        numbers = {frame_number_of(p.stem) for p in images.iterdir()} if images.is_dir() else set()
        unposed = [fid for fid in unmatched if frame_number_of(fid) in numbers - {None}]
        missing = [fid for fid in unmatched if fid not in unposed]
        if missing:
            raise SceneError(kpath, f"the key frame of frame id {missing[0]!r} matches no frame of transforms.json "
                             f"nor any image of {images}", "key frames must name an image by its frame id (the last "
                             "'_' token of its name) or its number")
        warnings.warn(f"{kpath}: key frame(s) {unposed[:5]} name images that transforms.json has no pose for; they "
                      "are not used; fix: pose those frames, or drop them from the file to silence this",
                      stacklevel=3)
    key_frame_states(ds)


def _camera_keys(ds: SceneDataset) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """(top-level intrinsics, each frame's own): with frames of several cameras, a key sits at the top level only
    where every frame has the same value, since nerfstudio takes a top-level key over the frame's."""
    top = camera_to_dict(ds.camera)
    cams = [camera_to_dict(f.camera) if f.camera is not None else top for f in ds.frames]
    if all(c == top for c in cams):
        return top, [{} for _ in cams]
    common = {k: v for k, v in top.items() if all(c.get(k) == v for c in cams)}
    return common, [{k: v for k, v in c.items() if k not in common} for c in cams]


def write_scene(ds: SceneDataset, root: str | Path | None = None) -> Path:
    """Write the metadata files of a dataset (images and masks are written by the caller)."""
    root = Path(root) if root is not None else ds.root
    root.mkdir(parents=True, exist_ok=True)
    tdata, own = _camera_keys(ds)
    frames_out = []
    for f, intrinsics in zip(ds.frames, own, strict=True):
        entry: dict[str, Any] = {"file_path": f.file_path, "transform_matrix": np.asarray(f.c2w).tolist()}
        entry.update(intrinsics)
        if f.state is not None:
            entry["state"] = {k: float(v) for k, v in f.state.items()}
        if f.split is not None:
            entry["split"] = f.split
        if f.source_index is not None:
            entry["source_index"] = int(f.source_index)
        frames_out.append(entry)
    tdata["frames"] = frames_out
    tdata.update(split_lists(ds.frames))
    tdata["applied_transform"] = np.eye(4)[:3].tolist()  # unless ds.nerfstudio records one (below)
    kept = {k: v for k, v in ds.nerfstudio.items() if k in NERFSTUDIO_KEYS}
    tdata.update(json.loads(json.dumps(kept, default=_np_default)))
    write_json(root / "transforms.json", tdata)
    if ds.objects:
        write_yaml(root / "mapping.yaml", {int(i): n for i, n in zip(ds.object_ids, ds.objects, strict=True)})
    if ds.key_frames:
        write_key_frames(root / "key_frame_value.yaml", ds.key_frames)
    if ds.prompts:
        write_yaml(root / "prompts.yaml", ds.prompts)
    meta = dict(ds.meta)
    if ds.scene_box is not None:
        meta["scene_box"] = np.asarray(ds.scene_box).tolist()
    if meta:
        write_json(root / "scene.json", json.loads(json.dumps(meta, default=_np_default)))
    return root


def _np_default(obj: Any) -> Any:
    if isinstance(obj, np.generic | np.ndarray):
        return obj.tolist()
    raise TypeError(type(obj).__name__)
