"""State sweeps: renders of one held-out view while one object's state runs from 0 to 1.

The report's sliders scrub these images, so each object gets its own sweep with the other
objects held at the view's own state.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from stages.scene import InputError, atomic_dir, read_scene, write_json


def slug(name: str) -> str:
    """A file-name-safe form of an object name: letters and digits of any script kept ("冰箱", "шкаф"), the rest
    '-', at most 80 characters (a file name holds 255 bytes)."""
    return re.sub(r"[^\w-]+", "-", name).strip("-")[:80].strip("-") or "object"


def object_stems(names: list[str]) -> dict[str, str]:
    """Object name -> a file stem no other object of the scene shares, in any letter case: "Drawer" and "drawer",
    or "kid's drawer" and "kid s drawer", have one slug, so the second and later get their position appended."""
    stems: dict[str, str] = {}
    taken: set[str] = set()
    for i, name in enumerate(names):
        stem = base = slug(name)
        n = i + 1
        while stem.casefold() in taken:
            stem, n = f"{base}-{n}", n + 1
        taken.add(stem.casefold())
        stems[name] = stem
    return stems


def render_sweeps(run_dir: str | Path, data_dir: str | Path, out_dir: str | Path, *, steps: int = 5,
                  scale: float = 0.5, device: str = "cpu", frame_id: str | None = None,
                  progress: bool = True) -> dict:
    """Render ``steps`` states in [0, 1] of every object at one test view; write PNGs and sweep.json."""
    import cv2

    from stages.model import load_run

    if steps < 2:
        raise InputError("--steps", f"{steps} states cannot show a change", "pass --steps 2 or more")
    if not 0 < scale <= 1:
        raise InputError("--scale", f"{scale} is not in (0, 1]", "pass a resolution factor such as 0.5")
    ds = read_scene(data_dir)
    frames = ds.frames_in("test") or ds.frames
    frame = frames[0] if frame_id is None else ds.frame_by_id(frame_id)
    run = load_run(run_dir, device=device)
    if run.frame_ids and [f.frame_id for f in ds.frames] != run.frame_ids:  # a frame index would mean another frame
        raise InputError(data_dir, "is not the dataset the run was trained on (its frames differ from the run's)",
                         "pass the run's dataset")
    camera = ds.camera_of(frame).scaled(scale) if scale != 1 else ds.camera_of(frame)
    index = ds.frames.index(frame)
    if run.state_mode == "learned":  # the other objects at the states the run renders there, not the dataset's
        base = {name: float(v) for name, v in zip(run.objects, run.state_vector(None, index), strict=True)}
    else:
        base = {name: float((frame.state or {}).get(name, 0.0)) for name in run.objects}
    values = np.linspace(0.0, 1.0, steps).round(4).tolist()
    summary: dict = {"run": str(run_dir), "dataset": str(data_dir), "frame": frame.frame_id, "scale": scale,
                     "width": camera.width, "height": camera.height, "base_state": base, "objects": {}}
    start = time.perf_counter()
    jobs = [(name, k, v) for name in run.objects for k, v in enumerate(values)]
    stems = object_stems(list(run.objects))
    with atomic_dir(out_dir, "sweep", inputs=[run_dir, data_dir], legacy=["sweep.json"]) as tmp:
        for name, k, value in tqdm(jobs, desc="sweep", disable=not progress):
            states = dict(base, **{name: value})
            out = run.render(camera, frame.c2w, states, frame_index=index)
            rgb = np.clip(np.asarray(out["rgb"])[..., ::-1] * 255 + 0.5, 0, 255).astype(np.uint8)
            file = f"{stems[name]}_{k:02d}.png"
            if not cv2.imwrite(str(tmp / file), rgb):
                raise OSError(f"could not write {tmp / file}")
            entry = summary["objects"].setdefault(name, {"values": values, "images": []})
            entry["images"].append(file)
        summary["seconds"] = round(time.perf_counter() - start, 3)
        summary["renders"] = len(jobs)
        write_json(tmp / "sweep.json", summary)
    return summary
