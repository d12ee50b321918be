"""Export a trained run's geometry at chosen object states: render the training poses, fuse, write (docs/export.md).

For each state combination: every training pose (or an even subset, ``views``) is rendered at
``scale`` of the dataset's resolution with rgb, depth, accumulation (and the object probabilities
with ``objects``), fused into a TSDF volume over the scene box, and written as a mesh, a point
cloud and a thumbnail; ``export.json`` records sizes, vertex counts and timings.
"""

from __future__ import annotations

import os
import time
from collections.abc import Collection, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from tqdm import tqdm

from stages.scene import Camera, InputError, SceneDataset, atomic_dir, write_json
from stages.scene.dataset import file_stem

from .mesh_io import FORMATS, write_geometry
from .object_parts import ObjectPartFusion
from .state_spec import full_state, state_slug
from .thumbnail import overview_view, write_thumbnail
from .tsdf_fusion import FusionSettings, TSDFFusion, fusable_depth
from .world_up import world_up_axis

EXPORT_FORMAT = 1
"""Version of export.json (bump when its keys change: the report reads it)."""


class Renderable(Protocol):
    """What the exporter needs of a run: ``stages.model.LoadedRun`` (or a test double)."""

    @property
    def objects(self) -> list[str]: ...

    def render(self, camera: Camera, c2w: np.ndarray, states: Any = None, frame_index: int | None = None,
               outputs: Collection[str] = ...) -> dict[str, np.ndarray]: ...


@dataclass(frozen=True)
class ExportOptions:
    """Every knob of an export; docs/export.md gives the defaults' reasons."""

    fmt: str = "ply"
    objects: bool = False
    """Also export each object's part from the probability field."""
    views: int = 16
    """Training poses rendered per state, evenly spread (0 = all): rendering is nearly all of the time."""
    scale: float = 0.5
    """Render size relative to the dataset images."""
    resolution: int = 256
    """Voxels along the scene box's longest side."""
    prob_threshold: float = 0.5
    """An object's pixels: rendered probability >= this."""
    trunc_voxels: float = 5.0
    min_accumulation: float = 0.5
    edge_ratio: float = 0.05
    thumbnail_width: int = 320

    def check(self) -> None:
        if self.fmt not in FORMATS:
            raise InputError("--format", f"unknown format {self.fmt!r}", f"choose one of {list(FORMATS)}")
        if not 0 < self.scale <= 4:
            raise InputError("--scale", f"render scale {self.scale} is outside (0, 4]", "use e.g. 0.5")
        if not 16 <= self.resolution <= 2048:
            raise InputError("--resolution", f"{self.resolution} voxels is outside 16..2048", "use e.g. 256")
        if not 0 < self.prob_threshold < 1:
            raise InputError("--prob-threshold", f"{self.prob_threshold} is not in (0, 1)", "use e.g. 0.5")
        if self.views < 0 or self.views == 1:
            # the fusion keeps a voxel seen by two views at least (min_weight): one view never gives a surface
            raise InputError("--views", f"{self.views} views", "give 0 (all training poses) or 2 or more: a surface "
                             "is kept where two views at least agree")


def export_box(dataset: SceneDataset, run: Any) -> np.ndarray:
    """[[min], [max]] the export is cropped to: scene.json's scene box, else the run's normalisation cube."""
    if dataset.scene_box is not None:
        return np.asarray(dataset.scene_box, dtype=np.float64)
    norm = getattr(run, "norm", None)
    if norm is None:
        raise InputError(dataset.root / "scene.json", "no scene_box, and the run has no scene normalisation",
                         "add a scene_box to scene.json (`livescene scene` writes one)")
    inv = np.linalg.inv(norm.transform)
    corners = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]) @ inv[:3, :3].T + inv[:3, 3]
    return np.stack([corners.min(0), corners.max(0)])


def training_views(dataset: SceneDataset, count: int = 0) -> list[tuple[int, Camera, np.ndarray]]:
    """(frame index, camera, c2w) of the training frames (all frames when none is marked), ``count`` evenly."""
    frames = [(i, f) for i, f in enumerate(dataset.frames) if (f.split or "train") == "train"]
    frames = frames or list(enumerate(dataset.frames))
    if count and count < len(frames):
        picks = np.linspace(0, len(frames) - 1, count).round().astype(int)
        frames = [frames[k] for k in picks]
    return [(i, dataset.camera_of(f), np.asarray(f.c2w, dtype=np.float64)) for i, f in frames]


def render_camera(camera: Camera, scale: float) -> Camera:
    """The training camera at ``scale``, as an ideal pinhole: the fusion projects voxels without lens distortion,
    so the renders must have none either (the run renders any pinhole, docs/model.md)."""
    cam = camera.scaled(scale) if scale != 1 else camera
    return Camera(fx=cam.fx, fy=cam.fy, cx=cam.cx, cy=cam.cy, width=cam.width, height=cam.height)


def renders_probabilities(run: Renderable, camera: Camera, c2w: np.ndarray) -> bool:
    """Whether the run renders per-object probabilities (LiveScene's probability field): a 1-pixel probe."""
    if not run.objects:
        return False
    probe = Camera(fx=camera.fx, fy=camera.fy, cx=0.5, cy=0.5, width=1, height=1)
    try:
        out = run.render(probe, c2w, None, outputs=("probs",))
    except (KeyError, ValueError, RuntimeError, AttributeError):
        return False
    probs = out.get("probs")
    return probs is not None and probs.shape[-1] == len(run.objects) + 1


def _count(geometry: Any) -> dict[str, int]:
    if hasattr(geometry, "triangles"):
        return {"vertices": len(geometry.vertices), "triangles": len(geometry.triangles)}
    return {"points": len(geometry.points)}


def export_state(run: Renderable, views: Sequence[tuple[int, Camera, np.ndarray]], box: np.ndarray,
                 states: Mapping[str, float], options: ExportOptions, out_dir: Path,
                 progress: bool = True, up: str = "+y") -> dict[str, Any]:
    """Render, fuse and write one state combination into ``out_dir``; returns its export.json record."""
    t0 = time.perf_counter()
    voxel = float(np.max(box[1] - box[0])) / options.resolution
    settings = FusionSettings(voxel=voxel, trunc_voxels=options.trunc_voxels,
                              min_accumulation=options.min_accumulation, edge_ratio=options.edge_ratio)
    scene = TSDFFusion(box, settings)
    parts = ObjectPartFusion(run.objects, box, settings, options.prob_threshold) if options.objects else None
    outputs = ("rgb", "depth", "accumulation", *(("probs",) if options.objects else ()))
    render_s = fuse_s = 0.0
    slug = state_slug(dict(states))
    for _, camera, c2w in tqdm(views, desc=f"export {slug}", unit="view", disable=not progress):
        cam = render_camera(camera, options.scale)
        t = time.perf_counter()
        out = run.render(cam, c2w, dict(states), outputs=outputs)
        render_s += time.perf_counter() - t
        t = time.perf_counter()
        z = fusable_depth(cam, out["depth"], out["accumulation"], settings)
        scene.integrate(cam, c2w, out["rgb"], z)
        if parts is not None:
            parts.integrate(cam, c2w, out["rgb"], z, out["probs"])
        fuse_s += time.perf_counter() - t

    t = time.perf_counter()
    geometry: dict[str, Any] = {"scene_mesh": scene.extract_mesh(), "scene_points": scene.extract_points()}
    if parts is not None:
        for name, fusion in parts.parts.items():
            stem = file_stem(name)  # a name is no path (checked where it is read; kept so here too)
            geometry[f"objects/{stem}_mesh"] = fusion.extract_mesh()
            geometry[f"objects/{stem}_points"] = fusion.extract_points()
    extract_s = time.perf_counter() - t

    t = time.perf_counter()
    files: dict[str, dict[str, Any]] = {}
    for key, geom in geometry.items():
        rel = f"{key}.{options.fmt}"
        size = write_geometry(out_dir / rel, geom, up=up)
        files[key] = {"path": f"{out_dir.name}/{rel}", "bytes": size, **_count(geom)}
    first_camera = views[0][1]
    thumb_cam, thumb_pose = overview_view(first_camera, [v[2] for v in views], options.thumbnail_width)
    write_thumbnail(out_dir / "thumbnail.png", geometry["scene_mesh"], thumb_cam, thumb_pose)
    write_s = time.perf_counter() - t
    return {
        "states": dict(states), "folder": out_dir.name, "files": files,
        "thumbnail": f"{out_dir.name}/thumbnail.png",
        "pixels_fused": {"scene": scene.pixels_fused,
                         **({n: f.pixels_fused for n, f in parts.parts.items()} if parts else {})},
        "timings_s": {"render": round(render_s, 3), "fuse": round(fuse_s, 3), "extract": round(extract_s, 3),
                      "write": round(write_s, 3), "total": round(time.perf_counter() - t0, 3)},
    }


def export_run(run: Renderable, dataset: SceneDataset, combos: Sequence[Mapping[str, float]], out: str | Path,
               options: ExportOptions, progress: bool = True, run_info: Mapping[str, Any] | None = None
               ) -> dict[str, Any]:
    """Export every state combination into ``out`` (written atomically, with export.json); returns export.json."""
    options.check()
    t0 = time.perf_counter()
    views = training_views(dataset, options.views)
    box = export_box(dataset, run)
    if options.objects and not renders_probabilities(run, views[0][1], views[0][2]):
        where = (run_info or {}).get("run", "--run")
        raise InputError(where, "--objects needs per-object probabilities, and this run renders none "
                         f"(objects: {run.objects})",
                         "export a LiveScene run trained on a dataset with masks, or leave out --objects")
    full = [full_state(dict(c), run.objects) for c in combos] or [full_state({}, run.objects)]
    if not run.objects:  # a room without objects has one state: "all=0" and "all=1" both name it
        full = full[:1]
    slugs = [state_slug(s) for s in full]
    if len(set(slugs)) != len(slugs):
        raise InputError("--states", "the same state combination is given twice", "give each combination once")
    up = world_up_axis([f.c2w for f in dataset.frames])
    out = Path(out)
    records = []
    with atomic_dir(out, "export", inputs=[dataset.root], legacy=["export.json"]) as tmp:
        for states, slug in zip(full, slugs, strict=True):
            (tmp / slug).mkdir()
            record = export_state(run, views, box, states, options, tmp / slug, progress, up=up)
            records.append(record)
        cam = render_camera(views[0][1], options.scale)
        doc = {
            "format": EXPORT_FORMAT, **dict(run_info or {}), "dataset": str(dataset.root),
            "objects": list(run.objects), "options": asdict(options),
            "views": len(views), "view_frames": [dataset.frames[i].frame_id for i, _, _ in views],
            "render_size": [cam.width, cam.height], "box": box.tolist(), "world_up": up,
            # the files' unit is the dataset's: metres for a capture's truth, an arbitrary scale for COLMAP's poses
            # (glTF reads metres, so such a room opens at COLMAP's scale)
            "units": dataset.meta.get("units"),
            "voxel": float(np.max(box[1] - box[0])) / options.resolution,
            "exports": records, "total_seconds": round(time.perf_counter() - t0, 3),
            "loadavg": [round(x, 2) for x in os.getloadavg()],
        }
        write_json(tmp / "export.json", doc)
    return doc
