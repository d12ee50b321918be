"""Locality of control: moving one object changes that object's pixels and nothing else.

For a held-out view and an object ``j``, the run renders the view with
``kappa_j = 0`` and ``kappa_j = 1`` (every other object at the view's own
state). The truth renderer gives the object's *swept region*: its pixels at
several states between 0 and 1, and the pixels its cast shadows fall on
(where the renderer reports shadow casters), dilated by 2 px (edges are
blurred by anti-aliasing and the camera). Moving the object legitimately
changes exactly those pixels. The mean absolute change of the model's image
outside that region (x255) must stay small (a state change that repaints
the room is not control), and the change inside it must be visible. The
truth renderer's own change outside the region is reported alongside (about 0
when the region holds every shadow).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from stages.scene import Camera, Frame

from .metrics import summarize

SWEPT_STATES = 5
"""Truth states in [0, 1] whose object pixels make up the swept region."""
DILATE_PX = 2
OUTSIDE_LIMIT_X255 = 1.0
"""Mean change outside the swept region, in 1/255 steps, below which a state change counts as local."""

RenderFn = Callable[[Frame, dict[str, float]], np.ndarray]
"""(frame, states) -> the run's rgb [H, W, 3] at the evaluation camera."""


class _Renders:
    """Renders of one view keyed by their state vector: the objects' 0 / 1 renders and the swept region's end
    states repeat (an object already at 0 or 1 in the view's own state makes its lo or hi render the view's own,
    shared by every other object at 0 or 1), and rendering a state again gives the same image."""

    def __init__(self, render: Callable[[dict[str, float]], Any]) -> None:
        self.render, self.done = render, {}

    def __call__(self, states: dict[str, float]) -> Any:
        key = tuple(sorted(states.items()))
        if key not in self.done:
            self.done[key] = self.render(states)
        return self.done[key]


def swept_region(truth_render: Callable[[dict[str, float]], dict[str, Any]], obj: int, name: str,
                 base: dict[str, float], shape: tuple[int, int]) -> np.ndarray:
    """Pixels [H, W] the truth object ``name`` (id ``obj``) or its cast shadows cover at any of SWEPT_STATES
    states, dilated; ``truth_render`` gives the truth renderer's output at the view for a state vector."""
    region = np.zeros(shape, dtype=bool)
    for value in np.linspace(0.0, 1.0, SWEPT_STATES):
        out = truth_render(dict(base, **{name: float(value)}))
        region |= out["ids"] == obj
        if "shadow_ids" in out:  # [lights, H, W]: which object casts the shadow on each pixel
            region |= (np.asarray(out["shadow_ids"]) == obj).any(axis=0)
    size = 2 * DILATE_PX + 1
    return cv2.dilate(region.astype(np.uint8), np.ones((size, size), np.uint8)) > 0


def locality(render: RenderFn, truth: Any, frames: Sequence[Frame], camera_of: Callable[[Frame], Camera],
             objects: Sequence[str], progress: bool = True) -> dict[str, Any]:
    """Per object: the model's and the truth's mean change outside / inside the swept region, x255."""
    records = []
    for frame in tqdm(frames, desc="locality views", unit="view", disable=not progress):  # 2-4 renders per object
        camera = camera_of(frame)
        own = {o: float(v) for o, v in (truth.state_for(frame) or frame.state or {}).items()}
        base = {o: own.get(o, 0.0) for o in objects}
        tcam = truth.camera_for(camera.width, camera.height)
        c2w, _ = truth.pose_for(frame)
        model_render = _Renders(lambda st, f=frame: render(f, st))
        truth_render = _Renders(lambda st, c=c2w, t=tcam: truth.renderer.render(c, st, camera=t))
        for name in objects:
            if name not in truth.object_ids:
                continue
            region = swept_region(truth_render, truth.object_ids[name], name, base, (camera.height, camera.width))
            lo, hi = dict(base, **{name: 0.0}), dict(base, **{name: 1.0})
            model = np.abs(np.asarray(model_render(lo), np.float64) - np.asarray(model_render(hi), np.float64))
            t_lo = truth_render(lo)["rgb"]
            t_hi = truth_render(hi)["rgb"]
            true = np.abs(np.asarray(t_lo, np.float64) - np.asarray(t_hi, np.float64))
            model, true = model.mean(axis=-1) * 255.0, true.mean(axis=-1) * 255.0
            records.append({
                "frame": frame.frame_id, "object": name, "region_pixels": int(region.sum()),
                "model_outside_x255": float(model[~region].mean()) if (~region).any() else None,
                "model_inside_x255": float(model[region].mean()) if region.any() else None,
                "truth_outside_x255": float(true[~region].mean()) if (~region).any() else None,
                "truth_inside_x255": float(true[region].mean()) if region.any() else None,
            })
    per_object = {}
    for name in objects:
        rows = [r for r in records if r["object"] == name]
        outside = summarize([r["model_outside_x255"] for r in rows])
        inside = summarize([r["model_inside_x255"] for r in rows])
        per_object[name] = {
            "model_outside_x255": outside, "model_inside_x255": inside,
            "truth_outside_x255": summarize([r["truth_outside_x255"] for r in rows]),
            "truth_inside_x255": summarize([r["truth_inside_x255"] for r in rows]),
            "local": (outside["mean"] is not None and inside["mean"] is not None
                      and outside["mean"] <= OUTSIDE_LIMIT_X255 and inside["mean"] > outside["mean"]),
        }
    return {"status": "computed", "outside_limit_x255": OUTSIDE_LIMIT_X255, "swept_states": SWEPT_STATES,
            "dilate_px": DILATE_PX, "records": records, "objects": per_object,
            "all_local": bool(per_object) and all(v["local"] for v in per_object.values())}
