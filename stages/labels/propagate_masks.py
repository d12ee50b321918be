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

import itertools
import tempfile
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
from .propagation import STEP_SIGMA_PX, KeyFrames, Track, fuse, iou_per_object, mean_of, read_track, walk

METHOD = ("OpenCV DIS optical flow (MEDIUM preset) chained over neighbouring frames, every pixel tracked to "
          "the annotated frames before and after it (each frame's map to an annotation composed from its "
          "neighbour's: one step per frame), forward-backward occlusion check at each step, the two "
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


def leave_one_out(held_out: int, before: Track | None, after: Track | None, label_map: np.ndarray,
                  frame_ids: tuple[str, ...], names: list[str]) -> dict:
    """An annotated frame predicted from its neighbouring annotations only (``before`` and ``after``: its tracks to
    them), IoU per object against its own annotation."""
    tracks = [t for t in (before, after) if t is not None]
    labels, confidence = fuse(tracks[0], tracks[1] if len(tracks) > 1 else None, held_out, len(names) + 1)
    ious = iou_per_object(labels, label_map, len(names))
    return {"frame": frame_ids[held_out],
            "previous_key": None if before is None else frame_ids[before.key],
            "next_key": None if after is None else frame_ids[after.key],
            "distance": min(abs(held_out - t.key) for t in tracks),
            "iou": {names[k - 1]: None if v is None else round(v, 5) for k, v in ious.items()},
            "mean_iou": _round(mean_of(list(ious.values()))),
            "mean_confidence": round(float(confidence.mean()), 5)}


def _round(v: float | None, digits: int = 5) -> float | None:
    return None if v is None else round(v, digits)


def propagate_missing(tmp: Path, frames: FrameSet, annotated: dict[str, np.ndarray], names: list[str], *,
                      progress: bool = True, max_side: int = FLOW_MAX_SIDE,
                      step_sigma: float = STEP_SIGMA_PX,
                      on_frame: Callable[[str, np.ndarray], None] | None = None) -> PropagationResult:
    """Propagate ``annotated`` (frame id -> uint16 map at frame size) to every other frame of ``frames``.

    Writes the masks, confidence maps, confidence.csv and propagation.json into ``tmp`` (the atomic
    staging folder of the LABELS output) and calls ``on_frame(fid, labels)`` for each propagated frame.

    Each segment between two annotations ``a < b`` is walked twice, one flow step per frame each time: from ``b``
    back to ``a`` (the tracks to ``b`` are parked in a scratch folder inside ``tmp``, and so are the flows), then
    from ``a`` on to ``b``, fusing each frame's two tracks and writing it. Both walks go one frame further, onto
    the other annotation, for its leave-one-out estimate.
    """
    ids = frames.frame_ids
    index_of = {f: i for i, f in enumerate(ids)}
    keys = KeyFrames({index_of[f]: lab for f, lab in annotated.items()})
    order = sorted(keys)
    n_labels = len(names) + 1
    rows: dict[int, dict] = {}
    loo: list[dict] = []
    result = PropagationResult(frames=[], mean_confidence={}, sources={})
    (tmp / "confidence").mkdir(exist_ok=True)
    for k in order:
        rows[k] = _frame_row(ids[k], ids[k], ids[k], ids[k], 0, annotated[ids[k]], None, names)
    t0 = time.perf_counter()
    loo_s = 0.0
    bar = tqdm(total=len(ids) - len(order), desc="propagate masks", unit="frame", disable=not progress)

    def write(t: int, before: Track | None, after: Track | None) -> None:
        tracks = [tr for tr in (before, after) if tr is not None]
        labels, confidence = fuse(tracks[0], tracks[1] if len(tracks) > 1 else None, t, n_labels)
        fid = ids[t]
        prev = None if before is None else ids[before.key]
        nxt = None if after is None else ids[after.key]
        distance = min(abs(t - tr.key) for tr in tracks)
        nearest = min(tracks, key=lambda tr: abs(tr.key - t)).key
        write_mask(tmp, fid, label_map_to_onehot(labels.astype(np.int64) - 1, len(names)))
        path = tmp / "confidence" / f"{fid}.png"
        if not cv2.imwrite(str(path), np.round(confidence * 255).astype(np.uint8)):
            raise OSError(f"could not write {path}")
        rows[t] = _frame_row(fid, prev, nxt, ids[nearest], distance, labels, confidence, names)
        result.mean_confidence[fid] = float(confidence.mean())
        result.sources[fid] = [prev, nxt]
        if on_frame is not None:
            on_frame(fid, labels)
        bar.update()

    def held_out(j: int, before: Track | None, after: Track | None) -> None:
        nonlocal loo_s
        if len(order) >= 2:
            start = time.perf_counter()
            loo.append(leave_one_out(order[j], before, after, keys.label_map(order[j]), ids, names))
            loo_s += time.perf_counter() - start

    # the scratch folder lives in the staging folder, so an interrupted run leaves nothing behind in LABELS
    with tempfile.TemporaryDirectory(prefix=".propagation-", dir=tmp) as scratch_name:
        scratch = Path(scratch_name)
        flows = FrameFlows(frames.images, (frames.height, frames.width), max_side=max_side, spill=scratch)
        to_previous: Track | None = None  # the track of the last annotation passed to the one before it
        bounds: list[int | None] = [None, *order, None]
        for j, (a, b) in enumerate(itertools.pairwise(bounds)):
            to_next: Track | None = None  # the track of ``a`` to ``b`` (leave-one-out)
            if b is not None:  # from b back to a (or to the first frame), parking what the walk on needs
                stop = 0 if a is None else a
                keep = a is not None
                tick = time.perf_counter()
                for s, state in walk(flows, keys[b], stop, step_sigma,
                                     after_step=lambda i, n, keep=keep: flows.release(i, n, keep=keep)):
                    track = read_track(keys[b], state)
                    if s == a:
                        to_next = track
                        loo_s += time.perf_counter() - tick
                    else:
                        np.save(scratch / f"labels_{s}.npy", track.labels)
                        np.save(scratch / f"confidence_{s}.npy", track.confidence)
                    tick = time.perf_counter()
            if a is None:  # frames before the first annotation: its track only
                for s in range(0, b):
                    write(s, None, _parked_track(scratch, s, b))
                continue
            held_out(j - 1, to_previous, to_next)
            stop = len(ids) - 1 if b is None else b
            tick = time.perf_counter()
            for s, state in walk(flows, keys[a], stop, step_sigma,
                                 after_step=lambda i, n: flows.release(i, n, keep=False)):
                track = read_track(keys[a], state)
                if s == b:
                    to_previous = track
                    loo_s += time.perf_counter() - tick
                else:
                    write(s, track, None if b is None else _parked_track(scratch, s, b))
                tick = time.perf_counter()
    bar.close()
    total_s = time.perf_counter() - t0
    result.frames = [ids[t] for t in sorted(rows) if t not in keys]

    # tmp is the atomic staging folder of LABELS: plain writes are safe here
    table = pd.DataFrame([rows[t] for t in sorted(rows)])
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


def _parked_track(scratch: Path, s: int, key: int) -> Track:
    """Frame ``s``'s track to ``key``, parked by the walk back from ``key`` (read once, then deleted)."""
    paths = scratch / f"labels_{s}.npy", scratch / f"confidence_{s}.npy"
    track = Track(labels=np.load(paths[0]), confidence=np.load(paths[1]), key=key)
    for path in paths:
        path.unlink()
    return track


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

