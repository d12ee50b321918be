"""Fill the frames no annotation covers: propagate the key-frame masks, score them, write the outputs.

Writes into the LABELS folder being built (docs/labels-states.md, "Masks on key frames only"):

    masks/<fid>.npy          for every propagated frame (same contract as an annotated one)
    confidence/<fid>.png     per-pixel confidence of a propagated frame, uint8 0..255 (255 = 1)
    confidence.csv           one row per frame: nearest annotated frames, distance, mean confidence
                             overall and per object (annotated frames: 1)
    propagation.json         method and settings, leave-one-out IoU per held-out annotated frame and
                             object, mean confidence by distance, timings
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from tqdm import tqdm

from stages.scene import label_map_to_onehot, write_mask

from .frame_set import FrameSet
from .optical_flow import FLOW_MAX_SIDE, FrameFlows
from .propagation import STEP_SIGMA_PX, KeyFrames, iou_per_object, mean_of, propagate_to

METHOD = ("OpenCV DIS optical flow (MEDIUM preset) chained over neighbouring frames, every pixel tracked to "
          "the annotated frames before and after it, forward-backward occlusion check at each step, the two "
          "directions fused with weights falling linearly with the distance to their annotation")


@dataclass
class PropagationResult:
    """What the labels summary needs from a propagation run."""

    frames: list[str]
    """Propagated frame ids in frame order (their label maps went to ``on_frame`` and masks/)."""
    mean_confidence: dict[str, float]
    """Propagated frame id -> mean pixel confidence."""
    sources: dict[str, list[str | None]]
    """Propagated frame id -> [previous annotated frame id, next annotated frame id]."""
    report: dict = field(default_factory=dict)
    """The content of propagation.json."""


def _frame_row(fid: str, prev: str | None, nxt: str | None, nearest: str, distance: int,
               labels: np.ndarray, confidence: np.ndarray | None, names: list[str]) -> dict:
    row: dict = {"frame": fid, "annotated": confidence is None, "previous_key": prev or "", "next_key": nxt or "",
                 "nearest_key": nearest, "distance": distance,
                 "mean_confidence": 1.0 if confidence is None else round(float(confidence.mean()), 5)}
    for k, name in enumerate(names, start=1):
        inside = labels == k
        if not inside.any():
            row[f"confidence_{name}"] = None
        else:
            row[f"confidence_{name}"] = 1.0 if confidence is None else round(float(confidence[inside].mean()), 5)
    return row


def leave_one_out(flows: FrameFlows, keys: KeyFrames, held_out: int, frame_ids: tuple[str, ...],
                  names: list[str]) -> dict:
    """Propagate to an annotated frame from the other annotations only; IoU per object against its annotation."""
    result = propagate_to(flows, keys.without(held_out), held_out, len(names) + 1)
    ious = iou_per_object(result.labels, keys.label_map(held_out), len(names))
    return {"frame": frame_ids[held_out],
            "previous_key": None if result.previous_key is None else frame_ids[result.previous_key],
            "next_key": None if result.next_key is None else frame_ids[result.next_key],
            "distance": result.distance,
            "iou": {names[k - 1]: None if v is None else round(v, 5) for k, v in ious.items()},
            "mean_iou": _round(mean_of(list(ious.values()))),
            "mean_confidence": round(float(result.confidence.mean()), 5)}


def _round(v: float | None, digits: int = 5) -> float | None:
    return None if v is None else round(v, digits)


def propagate_missing(tmp: Path, frames: FrameSet, annotated: dict[str, np.ndarray], names: list[str], *,
                      progress: bool = True, max_side: int = FLOW_MAX_SIDE,
                      step_sigma: float = STEP_SIGMA_PX,
                      on_frame: Callable[[str, np.ndarray], None] | None = None) -> PropagationResult:
    """Propagate ``annotated`` (frame id -> uint16 map at frame size) to every other frame of ``frames``.

    Writes the masks, confidence maps, confidence.csv and propagation.json into ``tmp`` (the atomic
    staging folder of the LABELS output) and calls ``on_frame(fid, labels)`` for each propagated frame.
    """
    ids = frames.frame_ids
    index_of = {f: i for i, f in enumerate(ids)}
    keys = KeyFrames({index_of[f]: lab for f, lab in annotated.items()})
    order = sorted(keys)
    n_labels = len(names) + 1
    flows = FrameFlows(frames.images, (frames.height, frames.width), max_side=max_side)
    rows: list[dict] = []
    loo: list[dict] = []
    result = PropagationResult(frames=[], mean_confidence={}, sources={})
    position = {k: j for j, k in enumerate(order)}
    (tmp / "confidence").mkdir(exist_ok=True)
    t0 = time.perf_counter()
    loo_s = 0.0

    def run_loo(j: int) -> None:
        nonlocal loo_s
        if len(order) < 2:
            return
        start = time.perf_counter()
        loo.append(leave_one_out(flows, keys, order[j], ids, names))
        loo_s += time.perf_counter() - start

    bar = tqdm(total=len(ids), desc="propagate masks", unit="frame", disable=not progress)
    for t, fid in enumerate(ids):
        bar.update()
        if t in position:
            j = position[t]
            if j >= 1:
                # every flow between the annotations around order[j - 1] is cached now: score it, then free memory
                run_loo(j - 1)
                flows.forget_before(order[j - 1])
            rows.append(_frame_row(fid, fid, fid, fid, 0, annotated[fid], None, names))
            continue
        p = propagate_to(flows, keys, t, n_labels, step_sigma)
        prev = None if p.previous_key is None else ids[p.previous_key]
        nxt = None if p.next_key is None else ids[p.next_key]
        write_mask(tmp, fid, label_map_to_onehot(p.labels.astype(np.int64) - 1, len(names)))
        path = tmp / "confidence" / f"{fid}.png"
        if not cv2.imwrite(str(path), np.round(p.confidence * 255).astype(np.uint8)):
            raise OSError(f"could not write {path}")
        nearest = ids[min((k for k in (p.previous_key, p.next_key) if k is not None), key=lambda k: abs(k - t))]
        rows.append(_frame_row(fid, prev, nxt, nearest, p.distance, p.labels, p.confidence, names))
        result.frames.append(fid)
        result.mean_confidence[fid] = float(p.confidence.mean())
        result.sources[fid] = [prev, nxt]
        if on_frame is not None:
            on_frame(fid, p.labels)
    run_loo(len(order) - 1)
    bar.close()
    total_s = time.perf_counter() - t0

    # tmp is the atomic staging folder of LABELS: plain writes are safe here
    table = pd.DataFrame(rows)
    table.to_csv(tmp / "confidence.csv", index=False)
    by_distance = table[~table["annotated"]].groupby("distance")["mean_confidence"].mean()
    result.report = {
        "method": METHOD,
        "flow": {"algorithm": "DIS", "preset": "MEDIUM", "max_side": max_side, "scale": round(flows.scale, 6),
                 "flows_computed": flows.computed},
        "occlusion_check": "forward-backward: |w + w_back|^2 > 0.01 (|w|^2 + |w_back|^2) + 0.5 px^2 "
                           "(Sundaram et al. 2010), or the track leaves the image",
        "confidence": f"Phi((d - 0.5) / sigma), d = distance to another label in the annotation, sigma^2 = "
                      f"{step_sigma}^2 px^2 per step + round-trip error^2 / 4; 0 where occluded",
        "step_sigma_px": step_sigma,
        "annotated_frames": [ids[i] for i in order],
        "propagated_frames": len(result.frames),
        "n_frames": len(ids),
        "mean_confidence": _round(float(table.loc[~table["annotated"], "mean_confidence"].mean())
                                  if result.frames else None),
        "confidence_by_distance": {int(d): round(float(v), 5) for d, v in by_distance.items()},
        "leave_one_out": _summarise_loo(loo, names, len(order)),
        "timings": {"total_s": round(total_s, 3), "leave_one_out_s": round(loo_s, 3),
                    "per_frame_ms": round(1000 * (total_s - loo_s) / max(len(result.frames), 1), 2)},
    }
    return result


def _summarise_loo(loo: list[dict], names: list[str], n_keys: int) -> dict:
    if n_keys < 2:
        return {"skipped": "leave-one-out needs at least two annotated frames", "frames": []}
    per_object = {n: _round(mean_of([r["iou"][n] for r in loo])) for n in names}
    return {
        "rule": "each annotated frame predicted from the other annotations only and scored against its own "
                "annotation; its nearest annotations are then up to twice as far as for the frames between "
                "annotations, so this is a pessimistic estimate",
        "frames": loo,
        "mean_iou": per_object,
        "min_iou": {n: _round(min((r["iou"][n] for r in loo if r["iou"][n] is not None), default=None))
                    for n in names},
        "mean_iou_all": _round(mean_of([r["mean_iou"] for r in loo])),
        "n": len(loo),
    }

