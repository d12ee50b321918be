"""``livescene poses import``: a COLMAP model made elsewhere -> the POSES folder of ``livescene poses``.

The model (COLMAP GUI, ``colmap mapper``, ns-process-data) is read with pycolmap, its images are matched
to the frames the next stages use, and the same outputs as the pose stage are written without running
structure from motion: sparse/0, transforms.json, points3D.ply, scene.json, poses.json
(docs/poses.md "Importing a COLMAP model", docs/data-contract.md).

Matching with ``--frames``: the frames stage names an image-folder frame after the number in the source
name (``0001.jpg`` -> ``frame_00001.png``, stages/frames/frame_source.py), so a COLMAP image is matched to
the frame with the same number (frame id = last ``_`` token of the stem, as everywhere in the project).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pycolmap

from stages.scene import InputError, atomic_dir, frame_number_of, write_json

from .colmap_files import binary_file_problem, text_file_problem
from .errors import PoseQualityError
from .frame_list import frames_summary, image_names, read_frame_list, time_order
from .model_export import (
    SUPPORTED_CAMERA_MODELS,
    drop_frames,
    judge_camera_path,
    relative_file_path,
    transforms_dict,
    write_model_outputs,
)
from .quality_gate import check_trajectory, compact_names, intrinsics_warnings
from .trajectory_check import TrajectorySettings
from .up_check import check_model_up
from .world_frame import orient_reconstruction

STAGE_VERSION = "2"  # 2: the world frame is gravity- and wall-aligned (world_frame.py)
MODEL_FILES = ("cameras", "images", "points3D")
MODEL_LAYOUTS = (".", "sparse/0", "colmap/sparse/0", "0", "sparse")
"""Where a model may sit below ``--model``: the model folder itself, a COLMAP project (sparse/0), an
ns-process-data output folder (colmap/sparse/0), or a sparse folder (0)."""
ASPECT_TOLERANCE = 0.01
"""Largest relative difference of the x and y scale factors accepted as the same image resized (odd sizes
round: 1081 px -> 540 px)."""
EXPORT_FIX = ("copy the whole model folder again, or re-export it from COLMAP (GUI: File > Export model; "
              "command line: `colmap model_converter --input_path MODEL --output_path OUT --output_type BIN`)")


@dataclass
class ImportConfig:
    """What to import and which images the poses are for."""

    model_dir: Path
    """COLMAP model folder (cameras, images, points3D as .bin or .txt) or a folder holding sparse/0."""
    out_dir: Path
    """POSES folder to write (atomic)."""
    images_dir: Path | None = None
    """The folder the model was made from: COLMAP image names are paths inside it."""
    frames_dir: Path | None = None
    """FRAMES folder of `livescene frames`: COLMAP images are matched to frames by frame number."""
    min_registered: float = 0.8
    """Smallest accepted fraction of the frames (or images) that get a pose from the model."""
    orient: bool = True
    """Turn the model's world to z up and x, y along the walls (world_frame.py), as ``livescene poses`` does;
    False keeps the model's own frame."""
    trajectory: TrajectorySettings = field(default_factory=TrajectorySettings)
    """The camera-path gate of ``livescene poses`` (trajectory_check.py), applied to the imported cameras."""


@dataclass
class LocatedModel:
    """A model folder found below ``--model`` and the format of its files."""

    folder: Path
    binary: bool
    other_models: list[str] = field(default_factory=list)
    """Sibling numbered models (sparse/1, ...) that were not imported."""

    @property
    def suffix(self) -> str:
        return ".bin" if self.binary else ".txt"


def _model_files(folder: Path) -> dict[str, list[str]]:
    """Which of cameras/images/points3D exist in ``folder``, per suffix."""
    return {suffix: [n for n in MODEL_FILES if (folder / f"{n}{suffix}").is_file()] for suffix in (".bin", ".txt")}


def locate_model(model_dir: Path) -> LocatedModel:
    """The folder holding the model files, or an InputError naming what is missing."""
    model_dir = Path(model_dir)
    if not model_dir.is_dir():
        raise InputError(model_dir, "COLMAP model folder not found",
                         "pass the folder holding cameras, images and points3D (.bin or .txt), or the COLMAP project "
                         "folder holding sparse/0")
    for layout in MODEL_LAYOUTS:
        folder = (model_dir / layout) if layout != "." else model_dir
        if not folder.is_dir():
            continue
        found = _model_files(folder)
        if not (found[".bin"] or found[".txt"]):
            continue
        for suffix in (".bin", ".txt"):
            if len(found[suffix]) == len(MODEL_FILES):
                numbered = sorted(p.name for p in folder.parent.iterdir()
                                  if p.is_dir() and p.name.isdigit() and p != folder) if folder.name.isdigit() else []
                return LocatedModel(folder=folder, binary=suffix == ".bin", other_models=numbered)
        suffix = ".bin" if len(found[".bin"]) >= len(found[".txt"]) else ".txt"
        missing = [f"{n}{suffix}" for n in MODEL_FILES if n not in found[suffix]]
        present = [f"{n}{s}" for s in (".bin", ".txt") for n in found[s]]
        raise InputError(folder / missing[0], f"the COLMAP model is incomplete: {', '.join(present)} present, "
                         f"{', '.join(missing)} missing (COLMAP writes cameras, images and points3D together, all "
                         ".bin or all .txt)", EXPORT_FIX)
    looked = ", ".join(str(model_dir / p) if p != "." else str(model_dir) for p in MODEL_LAYOUTS)
    raise InputError(model_dir, f"no COLMAP model here (looked for cameras/images/points3D .bin or .txt in {looked})",
                     "pass the folder holding the model files, e.g. PROJECT/sparse/0 of the COLMAP GUI or the "
                     "output folder of ns-process-data")


def read_model(located: LocatedModel) -> pycolmap.Reconstruction:
    """Read the model with pycolmap and check that it was read whole.

    COLMAP's binary reader does not check for a short read (a truncated cameras.bin loads as a 1x1
    camera), so binary files are walked first (``colmap_files``); text files are checked against the
    counts in their headers.
    """
    folder = located.folder
    if located.binary:
        for name in MODEL_FILES:
            problem = binary_file_problem(folder / f"{name}.bin")
            if problem is not None:
                raise InputError(folder / f"{name}.bin", problem, EXPORT_FIX)
    rec = pycolmap.Reconstruction()
    try:
        if located.binary:
            rec.read_binary(folder)
        else:
            rec.read_text(folder)
    except (ValueError, RuntimeError, IndexError, MemoryError, OSError) as exc:
        if not located.binary:  # a short file makes another fail (points of a missing image): name the short one
            for name in MODEL_FILES:
                problem = text_file_problem(folder / f"{name}.txt")
                if problem is not None:
                    raise InputError(folder / f"{name}.txt", problem, EXPORT_FIX) from exc
        detail = str(exc).strip().splitlines()[0][:200] if str(exc).strip() else type(exc).__name__
        raise InputError(folder, f"pycolmap cannot read this {'binary' if located.binary else 'text'} COLMAP model "
                         f"({detail}): a file is truncated, corrupt or not a COLMAP model", EXPORT_FIX) from exc
    if not located.binary:
        read = {"cameras": rec.num_cameras(), "images": rec.num_images(), "points3D": rec.num_points3D()}
        for name in MODEL_FILES:
            problem = text_file_problem(folder / f"{name}.txt", read[name])
            if problem is not None:
                raise InputError(folder / f"{name}.txt", problem, EXPORT_FIX)
    return rec


def check_cameras(rec: pycolmap.Reconstruction, folder: Path) -> None:
    """Refuse camera models the contract's Camera cannot reproduce, and cameras with bogus numbers."""
    suffix_file = folder / ("cameras.bin" if (folder / "cameras.bin").is_file() else "cameras.txt")
    for cid, cam in rec.cameras.items():
        name = cam.model.name
        if name not in SUPPORTED_CAMERA_MODELS:
            raise InputError(suffix_file, f"camera {cid} uses the {name} model, which LiveScene cannot use (its rays "
                             "are pinhole with OpenCV radial-tangential distortion: "
                             f"{', '.join(SUPPORTED_CAMERA_MODELS)})",
                             "undistort the images to a pinhole camera (`colmap image_undistorter --input_path MODEL "
                             "--image_path IMAGES --output_path UNDIST`) and import UNDIST/sparse with --images "
                             "UNDIST/images, or re-run COLMAP with camera model OPENCV")
        params = np.asarray(cam.params, dtype=np.float64)
        focal = [params[i] for i in cam.focal_length_idxs()]
        if cam.width <= 0 or cam.height <= 0 or not np.isfinite(params).all() or min(focal) <= 0:
            raise InputError(suffix_file, f"camera {cid} has size {cam.width}x{cam.height} and parameters "
                             f"{params.tolist()}: not a usable camera", EXPORT_FIX)


def _image_size(path: Path) -> tuple[int, int]:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputError(path, "image unreadable", "restore the image (or re-extract the frames)")
    return int(image.shape[1]), int(image.shape[0])


def fit_cameras(rec: pycolmap.Reconstruction, sizes: dict[int, tuple[int, int, str]], model_folder: Path
                ) -> dict[int, list[float]]:
    """Bring every camera to the size of its images; returns the scale per rescaled camera.

    ``sizes``: camera id -> (width, height, an image name) of the images the poses are for. A model made at
    another resolution (full-size photos, frames downscaled) differs by one factor on both axes: the
    camera and the keypoints are rescaled so that sparse/0 stays consistent. Anything else (a crop, a 90
    degree turn) is refused: the poses would not fit the pixels.
    """
    scales: dict[int, list[float]] = {}
    for cid, (width, height, example) in sizes.items():
        cam = rec.cameras[cid]
        cw, ch = int(cam.width), int(cam.height)
        if (cw, ch) == (width, height):
            continue
        sx, sy = width / cw, height / ch
        if abs(sx / sy - 1.0) > ASPECT_TOLERANCE:
            turned = abs((height / cw) / (width / ch) - 1.0) <= ASPECT_TOLERANCE
            why = (" (turned by 90 degrees? OpenCV, which wrote the frames, applies a phone's EXIF orientation, "
                   "COLMAP does not)") if turned else " (cropped or stretched)"
            raise InputError(model_folder, f"camera {cid} of the model is {cw}x{ch} but its images, e.g. {example}, "
                             f"are {width}x{height}, another aspect ratio{why}",
                             "import a model made from these very images (same size, or a resize of them), or "
                             "estimate the poses with `livescene poses`")
        cam.rescale(new_width=width, new_height=height)
        for image in rec.images.values():
            if image.camera_id == cid:
                for point in image.points2D:
                    point.xy = point.xy * np.array([sx, sy])
        scales[cid] = [sx, sy]
    if scales:
        rec.update_point_3d_errors()  # COLMAP caches each point's error from its last bundle adjustment
    return scales


def _frame_number(name: str) -> int | None:
    return frame_number_of(Path(name).stem)


@dataclass
class Matched:
    """The images the poses are for, and which posed model image gives each its pose."""

    mapping: dict[str, str]
    """Posed COLMAP image name -> frame (image) name."""
    names: list[str]
    """Every frame (image) name: the denominator of the registered fraction."""
    source_index: dict[str, int | None]
    image_dir: Path
    extra: list[str]
    """Posed model images that match no frame (left out)."""


def match_frames(rec: pycolmap.Reconstruction, frames_dir: Path) -> Matched:
    """COLMAP images matched to the frames of a FRAMES folder by frame number."""
    frames = read_frame_list(frames_dir)
    by_number: dict[int, str] = {}
    for name in frames.names:
        number = frames.source_index.get(name)
        if number is None:
            number = _frame_number(name)
        if number is not None:
            by_number[number] = name
    posed = sorted(im.name for im in rec.images.values() if im.has_pose)
    numbers = {name: _frame_number(name) for name in posed}
    unnumbered = [n for n, k in numbers.items() if k is None]
    if unnumbered:
        raise InputError(frames_dir, f"COLMAP image names carry no frame number to match the frames by (e.g. "
                         f"{unnumbered[:3]}; frames are named like {frames.names[:2]})",
                         "pass --images with the folder the model was made from instead of --frames, or name the "
                         "images with their frame number (last '_' token or the whole stem: 0001.jpg, IMG_0001.jpg)")
    seen: dict[int, str] = {}
    for name, number in numbers.items():
        if number in seen:
            raise InputError(frames_dir, f"COLMAP images {seen[number]} and {name} carry the same frame number "
                             f"{number}", "import a model of one image sequence (one camera folder)")
        seen[number] = name  # type: ignore[index]
    mapping = {name: by_number[k] for name, k in numbers.items() if k in by_number}  # type: ignore[index]
    extra = [name for name in posed if name not in mapping]
    return Matched(mapping, frames.names, frames.source_index, frames.image_dir, extra)


def match_images(rec: pycolmap.Reconstruction, image_dir: Path) -> Matched:
    """COLMAP images found by name in the folder the model was made from."""
    if not image_dir.is_dir():
        raise InputError(image_dir, "image folder not found", "pass the folder the COLMAP model was made from")
    posed = sorted(im.name for im in rec.images.values() if im.has_pose)
    missing = [n for n in posed if not (image_dir / n).is_file()]
    if missing:
        raise InputError(image_dir, f"{len(missing)} of the {len(posed)} posed COLMAP images are not in this folder, "
                         f"e.g. {missing[:3]} (the folder holds e.g. {image_names(image_dir)[:3]})",
                         "pass the folder the model was made from (COLMAP's image path: the image names of the model "
                         "are paths inside it)")
    names = sorted(set(image_names(image_dir)) | {im.name for im in rec.images.values()})
    return Matched({n: n for n in posed}, names, {n: _frame_number(n) for n in names}, image_dir, [])


IMPORT_BROKEN_FIX = ("COLMAP's model holds cameras that no continuous path joins; remake it from the frames "
                     "(`livescene poses` runs structure from motion itself) or with more overlap between neighbouring "
                     "images")


def import_model(cfg: ImportConfig) -> dict[str, Any]:
    """Import ``cfg.model_dir``; write ``cfg.out_dir`` atomically and return the content of poses.json."""
    t_start = time.perf_counter()
    if (cfg.images_dir is None) == (cfg.frames_dir is None):
        raise InputError(Path("--images/--frames"), "give exactly one of --images and --frames",
                         "--frames FRAMES (output of `livescene frames`) or --images FOLDER (what COLMAP read)")
    located = locate_model(cfg.model_dir)
    out_abs = cfg.out_dir.resolve()
    for inside, what in ((located.folder, "the model"), (cfg.frames_dir or cfg.images_dir, "the images")):
        inside = Path(inside).resolve()  # type: ignore[arg-type]
        if inside == out_abs or out_abs in inside.parents:
            raise InputError(cfg.out_dir, f"the output folder holds {what} ({inside}); writing it would replace them",
                             "write the poses to another folder")
    timings: dict[str, float] = {}
    warnings_: list[str] = []
    with atomic_dir(cfg.out_dir, "poses", inputs=[cfg.model_dir, cfg.images_dir, cfg.frames_dir],
                    legacy=["poses.json"]) as out:
        t0 = time.perf_counter()
        rec = read_model(located)
        check_cameras(rec, located.folder)
        posed = sorted(im.name for im in rec.images.values() if im.has_pose)
        if not posed:
            raise InputError(located.folder, "the model has no image with a pose", EXPORT_FIX)
        timings["read"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        if cfg.frames_dir is not None:
            matched, origin, kind = match_frames(rec, cfg.frames_dir), cfg.frames_dir, "frames"
        else:
            origin, kind = Path(cfg.images_dir), "images"  # type: ignore[arg-type]
            matched = match_images(rec, origin)
        mapping, names, source_index, image_dir, extra = (matched.mapping, matched.names, matched.source_index,
                                                          matched.image_dir, matched.extra)
        registered = sorted(set(mapping.values()))
        required = max(cfg.min_registered, 2 / max(len(names), 1))  # a model needs two posed views

        def check_fraction(registered: list[str], trimmed: list[str]) -> float:
            fraction = len(registered) / len(names) if names else 0.0
            if fraction < required:
                kept = set(registered)
                unregistered = [n for n in names if n not in kept]
                dropped = f" ({len(trimmed)} dropped as jumps: {compact_names(trimmed)})" if trimmed else ""
                raise PoseQualityError(origin, f"only {len(registered)} of {len(names)} {kind} ({fraction:.0%}) have "
                                       f"a posed image in the COLMAP model {located.folder}{dropped}, below the "
                                       f"required {required:.0%}; {kind} without one: {compact_names(unregistered)}; "
                                       f"posed model images: {compact_names(posed)} (matched by the number in the "
                                       "name: 0001.jpg = frame_00001.png)",
                                       "import the model made from the images these frames were extracted from, "
                                       "extract the frames from the folder the model was made from (`livescene "
                                       "frames --video FOLDER`), or lower --min-registered if a partial model is "
                                       "acceptable")
            return fraction

        check_fraction(registered, [])
        if extra:
            warnings_.append(f"{len(extra)} posed model image(s) match no frame and are left out: "
                             f"{compact_names(extra)}")
        if cfg.frames_dir is not None and any(c != f for c, f in mapping.items()) and \
                frames_summary(cfg.frames_dir).get("source_kind") == "video":
            warnings_.append("the frames come from a video, numbered by decode position from 0; a model made from "
                             "other frames of it (ns-process-data numbers from 1 and subsamples) pairs by number "
                             "only by chance: make the model from FRAMES/images, or check with `livescene poses "
                             "compare`")
        if located.other_models:
            warnings_.append(f"{located.folder.parent} holds other models {located.other_models}; imported "
                             f"{located.folder.name}")

        sizes: dict[int, tuple[int, int, str]] = {}
        for cname, fname in sorted(mapping.items()):
            cid = rec.find_image_with_name(cname).camera_id
            if cid not in sizes:
                sizes[cid] = (*_image_size(image_dir / fname), fname)
        scales = fit_cameras(rec, sizes, located.folder)
        renamed = {c: f for c, f in mapping.items() if c != f}
        for cname, fname in renamed.items():  # sparse/0 then names the frames it is stored beside
            rec.find_image_with_name(cname).name = fname
        timings["match"] = time.perf_counter() - t0

        # the camera path is judged as `livescene poses` judges its own: a model made elsewhere can be a tripod clip
        ordered, times = time_order(names, source_index)
        judged = judge_camera_path(rec, ordered, times, set(registered), [len(posed)], cfg.trajectory)
        warnings_ += check_trajectory(judged, origin, cfg.trajectory, IMPORT_BROKEN_FIX)
        drop_frames(rec, judged.trimmed)
        trimmed = set(judged.trimmed)
        registered = [n for n in registered if n not in trimmed]
        fraction = check_fraction(registered, judged.trimmed)
        posed_or_trimmed = trimmed | set(registered)
        unregistered = [n for n in names if n not in posed_or_trimmed]

        t0 = time.perf_counter()
        frame = orient_reconstruction(rec) if cfg.orient else None
        up = check_model_up(rec) if frame is not None else None  # warns only (docs/poses.md, "World frame")
        if up is not None and (up_warning := up.warning()) is not None:
            warnings_.append(up_warning)
        file_paths = {f: relative_file_path(image_dir / f, cfg.out_dir) for f in registered}
        transforms = transforms_dict(rec, {f: source_index.get(f) for f in registered}, file_paths=file_paths)
        if "fl_x" in transforms:
            warnings_ += intrinsics_warnings(transforms["fl_x"], transforms["fl_y"], transforms["w"], transforms["h"])
        write_model_outputs(out, rec, transforms, source=f"livescene poses import of {located.folder}",
                            world_frame=None if frame is None else frame.as_dict())
        timings["export"] = time.perf_counter() - t0
        timings["total"] = time.perf_counter() - t_start
        cameras = list(rec.cameras.values())
        summary: dict[str, Any] = {
            "stage": "poses",
            "stage_version": STAGE_VERSION,
            "source": "import",
            "imported_from": {"model": str(located.folder.resolve()), "requested": str(cfg.model_dir),
                              "format": "binary" if located.binary else "text",
                              "images": kind, "images_dir": str(image_dir)},
            "pycolmap_version": pycolmap.__version__,
            "frames_dir": str(cfg.frames_dir) if cfg.frames_dir is not None else None,
            "masks_dir": None,
            "n_frames": len(names),
            "n_registered": len(registered),
            "registered_fraction": fraction,
            "registered": registered,
            "unregistered": unregistered,
            "trimmed": judged.trimmed,
            "trajectory": judged.as_dict(),
            "model_images_without_frame": extra,
            "renamed": renamed,
            "intrinsics_scale": {str(k): v for k, v in scales.items()},
            "mean_reprojection_error": float(rec.compute_mean_reprojection_error()),
            "n_points3D": int(rec.num_points3D()),
            "mean_track_length": float(rec.compute_mean_track_length()),
            "n_models": 1,
            "matcher": None,
            "camera": {"model": cameras[0].model.name, "params": [float(p) for p in cameras[0].params]},
            "n_cameras": len(cameras),
            "config": {"min_registered": cfg.min_registered, "orient": cfg.orient},
            "world_frame": None if frame is None else frame.as_dict(),
            **({} if up is None else {"up_check": up.as_dict()}),
            "warnings": warnings_,
            "timings": timings,
        }
        write_json(out / "poses.json", summary)
    return summary
