"""Write a synthetic capture: what a user would bring (video, masks, key frames, names) and, apart, the truth.

Layout (see docs/captures.md and the file contracts)::

    video.mp4                   mp4v, lossy
    masks/frame_{i:05d}.png     uint8 id map, 0 background, k = mapping id
    mapping.yaml                {1: name, 2: name, ...}
    key_frame_value.yaml        {frame_{i:05d}: {name: value}}, sparse, optional noise
    prompts.yaml                {name: {synonyms: [...], description: ...}}
    capture.json                name, fps, n_frames, size, seed, timings, generator version
    truth/transforms.json       nerfstudio form, every video frame, dense "state"
    truth/states.csv            frame, source_index, object, value
    truth/depth/frame_*.npy     float32 z-depth (along the viewing axis) in output units
    truth/images/frame_*.png    lossless frames (the video's source, with its gains and noise), when write_truth_images
    truth/scene.json            scene box, units, joints, lights
    truth/spec.yaml             the full spec: TruthRenderer rebuilds the scene from it
    truth/texture_atlas.npz     the surface textures with the inputs they came from (a cache for truth renders)
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from tqdm import tqdm

from stages.scene import atomic_dir
from stages.scene.transforms import camera_to_dict

from .camera_effects import FrameRenderer, SensorNoise
from .camera_path import camera_path, seeded_rng
from .renderer import ATLAS_FILE, SceneRenderer
from .spec import CaptureSpec, camera_effects, spec_to_dict
from .state_schedule import state_table

GENERATOR_VERSION = "1"


def frame_name(i: int) -> str:
    return f"frame_{i:05d}"


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    return np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)


def frame_gains(spec: CaptureSpec) -> np.ndarray | None:
    """Per-frame RGB gains [n_frames, 3] of the simulated auto exposure and white balance (None without them).

    Drawn from their own seeded stream, and None (no multiplication, not even by one, which would round some
    pixels the other way in float64) without jitter: such a spec renders byte for byte as before the option."""
    v = spec.video
    if not (v.exposure_jitter or v.white_balance_jitter):
        return None
    rng = np.random.default_rng([spec.seed, 0xE7])
    log_gain = rng.normal(0.0, v.exposure_jitter, (v.n_frames, 1)) + rng.normal(0.0, v.white_balance_jitter,
                                                                                (v.n_frames, 3))
    return np.exp(log_gain)


def key_frame_values(spec: CaptureSpec, states: np.ndarray) -> dict[str, dict[str, float]]:
    """Sparse annotations ``{frame_{i:05d}: {name: value}}`` with optional Gaussian noise."""
    kf = spec.key_frames
    n = len(states)
    picks = list(range(0, n, kf.every))
    if kf.include_last and n - 1 not in picks:
        picks.append(n - 1)
    rng = seeded_rng(spec.seed, "annotation-noise")
    out: dict[str, dict[str, float]] = {}
    for i in picks:
        row = {}
        for j, name in enumerate(spec.object_names):
            value = states[i, j] + (rng.normal(0.0, kf.noise_std) if kf.noise_std > 0 else 0.0)
            row[name] = round(float(np.clip(value, 0.0, 1.0)), kf.decimals)
        out[frame_name(i)] = row
    return out


def scene_info(spec: CaptureSpec, renderer: SceneRenderer) -> dict[str, Any]:
    """truth/scene.json: scene box, units and each object's joint, in output units."""
    s = spec.units.per_metre
    objects = []
    for o, joint, frame in zip(spec.objects, renderer.model.joints, renderer.model.object_frames, strict=True):
        objects.append({
            "name": o.name,
            "kind": o.kind,
            "joint": joint.kind,
            "axis_world": (frame[:3, :3] @ joint.axis).tolist(),
            "pivot_world": ((frame[:3, :3] @ joint.pivot + frame[:3, 3]) * s).tolist(),
            "limits": [float(v) * (1.0 if joint.kind == "revolute" else s) for v in joint.limits],
            "limits_unit": "rad" if joint.kind == "revolute" else spec.units.name,
        })
    return {
        "scene_box": (renderer.model.room_box * s).tolist(),
        "units": spec.units.name,
        "units_per_metre": s,
        "depth": "z-depth: distance along the camera's viewing axis, in units",
        "world_up": [0.0, 0.0, 1.0],
        "lights": [{"position": (np.asarray(li.position) * s).tolist(), "intensity": li.intensity}
                   for li in spec.render.lights],
        "objects": objects,
    }


def generate_capture(spec: CaptureSpec, out_dir: str | Path, progress: bool = True, replace: bool = False) -> Path:
    """Render every frame of ``spec`` and write the capture folder atomically; returns ``out_dir``.

    ``replace``: an existing ``out_dir`` that is not an earlier capture is replaced too (``--force``).
    """
    out_dir = Path(out_dir)
    t_start = time.perf_counter()
    renderer = SceneRenderer(spec)
    t_setup = time.perf_counter() - t_start
    states = state_table(spec)
    poses = camera_path(spec)
    poses[:, :3, 3] *= spec.units.per_metre
    names = spec.object_names
    v = spec.video
    render_s = write_s = 0.0
    gains = frame_gains(spec)
    frames = FrameRenderer(spec, renderer)
    noise = SensorNoise(spec)
    with atomic_dir(out_dir, "capture", legacy=["capture.json"], force=replace) as tmp:
        for sub in ("masks", "truth/depth", "truth/images"):
            (tmp / sub).mkdir(parents=True, exist_ok=True)
        video_path = tmp / "video.mp4"
        writer = cv2.VideoWriter(str(video_path), cv2.VideoWriter_fourcc(*"mp4v"), v.fps, (v.width, v.height))
        if not writer.isOpened():
            raise RuntimeError("OpenCV cannot open an mp4v video writer; install an OpenCV build with FFmpeg")
        frames_json = []
        rows = []
        try:
            for i in tqdm(range(v.n_frames), desc=f"capture {spec.name}", unit="frame", disable=not progress):
                t0 = time.perf_counter()
                out = frames.render(i, poses[i], states[i])
                t1 = time.perf_counter()
                rgb = out["rgb"] if gains is None else out["rgb"] * gains[i]  # untouched without jitter
                if noise.on:  # likewise
                    rgb = noise(rgb)
                bgr = to_uint8(rgb)[..., ::-1]
                writer.write(np.ascontiguousarray(bgr))
                name = frame_name(i)
                cv2.imwrite(str(tmp / "masks" / f"{name}.png"), out["ids"].astype(np.uint8))
                np.save(tmp / "truth" / "depth" / f"{name}.npy", out["depth"])
                if spec.write_truth_images:
                    cv2.imwrite(str(tmp / "truth" / "images" / f"{name}.png"), bgr)
                state = {n: float(states[i, j]) for j, n in enumerate(names)}
                frames_json.append({"file_path": f"images/{name}.png", "transform_matrix": poses[i].tolist(),
                                    "source_index": i, "time_s": i / v.fps, "state": state})
                rows += [(f"{name}.png", i, n, float(states[i, j])) for j, n in enumerate(names)]
                render_s += t1 - t0
                write_s += time.perf_counter() - t1
        finally:
            writer.release()
        if not spec.write_truth_images:
            (tmp / "truth" / "images").rmdir()

        truth = tmp / "truth"
        transforms = camera_to_dict(renderer.camera)
        transforms["frames"] = frames_json
        (truth / "transforms.json").write_text(json.dumps(transforms, indent=1) + "\n")
        with (truth / "states.csv").open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["frame", "source_index", "object", "value"])
            w.writerows(rows)
        (truth / "scene.json").write_text(json.dumps(scene_info(spec, renderer), indent=1) + "\n")
        (truth / "spec.yaml").write_text(yaml.safe_dump(spec_to_dict(spec), sort_keys=False))
        renderer.write_atlas(truth / ATLAS_FILE)

        (tmp / "mapping.yaml").write_text(yaml.safe_dump({k: n for k, n in enumerate(names, start=1)}))
        (tmp / "key_frame_value.yaml").write_text(
            yaml.safe_dump(key_frame_values(spec, states), sort_keys=False))
        prompts = {o.name: {"synonyms": list(o.synonyms), "description": o.description} for o in spec.objects}
        (tmp / "prompts.yaml").write_text(yaml.safe_dump(prompts, sort_keys=False))
        meta = {
            "name": spec.name,
            "fps": v.fps,
            "n_frames": v.n_frames,
            "width": v.width,
            "height": v.height,
            "seed": spec.seed,
            "objects": names,
            "generator": "stages.capture",
            "generator_version": GENERATOR_VERSION,
            "truth_images": "truth/images (lossless PNG)" if spec.write_truth_images else None,
            "frame_gains": None if gains is None else gains.round(5).tolist(),
            **({"camera_effects": {**effects, "renders_per_frame": frames.renders_per_frame}}
               if (effects := camera_effects(v)) is not None else {}),  # absent without: capture.json as before
            "timings": {"setup_s": round(t_setup, 3), "render_s": round(render_s, 3), "write_s": round(write_s, 3),
                        "total_s": round(time.perf_counter() - t_start, 3)},
        }
        (tmp / "capture.json").write_text(json.dumps(meta, indent=1) + "\n")
    return out_dir
