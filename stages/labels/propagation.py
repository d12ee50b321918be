"""Propagate key-frame masks to every frame by composed optical flow, with occlusion checks and confidence.

For a frame ``t`` between annotated frames ``a < t < b`` every pixel of ``t`` is tracked back to ``a`` and
forward to ``b`` through the flows of neighbouring frames, and takes the label found there (re-seeding: each
segment starts afresh from its own two annotations, so errors never carry past an annotated frame). Frames
before the first or after the last annotation are tracked to the one annotation they have.

The tracks are not followed pixel by pixel through the whole chain (that costs one step per frame between ``t``
and the annotation, for every ``t``: quadratic in the gap). Each frame's *map* to an annotation is composed from
its neighbour's, one step nearer the annotation (``compose_step``): a pixel moves by the flow to the neighbour
and takes the neighbour's map where it lands, sampled bilinearly. A walk from the annotation outwards (``walk``)
so costs one step per frame. With flows that move pixels by whole pixels the maps are exactly the chained tracks;
otherwise they differ by the interpolation of neighbouring tracks (docs/labels-states.md measures it).

Each step of a track is checked forward-backward (Sundaram, Brox and Keutzer, ECCV 2010): a pixel whose
round trip misses by more than ``0.01 (|w|^2 + |w_back|^2) + 0.5`` px^2 is occluded (or left the view) in
the next frame, and the track loses its say; a composed map is valid where the pixel's own step passes and the
neighbour's map, read where it lands, is at least half valid. A surviving track's label is wrong only if its
drift crosses an object boundary of the annotation, so its confidence is ``Phi((d - 0.5) / sigma)``, with ``d``
the distance of the landing point from the nearest pixel of another label and ``sigma`` the accumulated drift:
``STEP_SIGMA_PX`` per step plus a quarter of each step's squared round-trip error (the pixel's own step plus the
neighbour's accumulated variance where it lands). Confidence therefore falls with the number of steps (distance
to the annotation), near boundaries, and behind occlusions.

The two directions are fused per pixel with weights falling linearly with the distance to their
annotation, each direction's vote spread by its confidence. docs/labels-states.md describes the outputs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.special import ndtr

from .optical_flow import FrameFlows

STEP_SIGMA_PX = 0.5
"""Drift (px, along a boundary's normal) assumed per chained flow step even when the round trip closes:
the typical end-point error of DIS on textured frames; consistent-but-wrong flow is invisible to the check."""


@dataclass(frozen=True)
class KeyFrame:
    """An annotated frame, ready to be sampled by tracks."""

    index: int
    """Position in frame order."""
    labels: np.ndarray
    """uint16 H x W: 0 background, k = canonical object k."""
    boundary_distance: np.ndarray
    """float32 H x W: distance (px) from each pixel to the nearest pixel of another label."""


@dataclass(frozen=True)
class Track:
    """The labels one annotation gives a frame, and how much to trust them."""

    labels: np.ndarray
    """uint16 H x W."""
    confidence: np.ndarray
    """float32 H x W in [0, 1]; 0 where the track was occluded or left the view."""
    key: int
    """Index of the annotated frame it came from."""


@dataclass(frozen=True)
class Propagated:
    """A frame's propagated labels."""

    index: int
    """Position in frame order."""
    labels: np.ndarray
    """uint16 H x W."""
    confidence: np.ndarray
    """float32 H x W in [0, 1] (1 on annotated frames)."""
    previous_key: int | None
    """Index of the annotated frame before it (None before the first one)."""
    next_key: int | None
    """Index of the annotated frame after it (None after the last one)."""

    @property
    def distance(self) -> int:
        """Frames to the nearest annotated frame (0 on an annotated frame)."""
        return min(abs(self.index - k) for k in (self.previous_key, self.next_key) if k is not None)


def make_key_frame(index: int, labels: np.ndarray) -> KeyFrame:
    labels = np.ascontiguousarray(labels, dtype=np.uint16)
    h, w = labels.shape
    dist = np.full((h, w), float(h + w), np.float32)
    for k in np.unique(labels):
        inside = (labels == k).astype(np.uint8)
        if inside.all():
            continue
        d = cv2.distanceTransform(inside, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        dist = np.where(inside > 0, d, dist)
    return KeyFrame(index=index, labels=labels, boundary_distance=dist.astype(np.float32))


class KeyFrames(Mapping[int, KeyFrame]):
    """Annotated label maps by frame position, turned into ``KeyFrame`` on first use and cached for the few
    a frame needs (their float distance maps would not fit in memory for a long high-resolution video)."""

    def __init__(self, labels: Mapping[int, np.ndarray], cache_size: int = 4) -> None:
        self._labels = labels
        self._cache: dict[int, KeyFrame] = {}
        self._cache_size = cache_size

    def __getitem__(self, index: int) -> KeyFrame:
        if index not in self._labels:
            raise KeyError(index)
        if index not in self._cache:
            if len(self._cache) >= self._cache_size:
                self._cache.pop(next(iter(self._cache)))
            self._cache[index] = make_key_frame(index, self._labels[index])
        return self._cache[index]

    def __contains__(self, index: object) -> bool:  # without building the KeyFrame (Mapping's default would)
        return index in self._labels

    def __iter__(self) -> Iterator[int]:
        return iter(self._labels)

    def __len__(self) -> int:
        return len(self._labels)

    def label_map(self, index: int) -> np.ndarray:
        """The annotation itself (uint16, 0 background)."""
        return self._labels[index]


def _sample(field: np.ndarray, pos: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
    return cv2.remap(field, pos[..., 0], pos[..., 1], interpolation, borderMode=cv2.BORDER_REPLICATE)


def _squared_length(v: np.ndarray) -> np.ndarray:
    """``(v ** 2).sum(-1)`` of ``H x W x 2`` vectors, the same float32 values: numpy's sum over an axis of two
    (x^2 + y^2) took half of each tracking step, three times a step, at 960x540."""
    return np.square(v[..., 0]) + np.square(v[..., 1])


def _grid(h: int, w: int) -> np.ndarray:
    """``H x W x 2`` float32 pixel positions (x, y) of a frame."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    return np.dstack([xs, ys])


def start_map(key: KeyFrame) -> np.ndarray:
    """The map of the annotated frame to itself: every pixel at its own position, no drift, valid."""
    h, w = key.labels.shape
    state = np.zeros((h, w, 4), np.float32)
    state[..., :2] = _grid(h, w)
    state[..., 3] = 1.0
    return state


def compose_step(flows: FrameFlows, there: np.ndarray, s: int, n: int, grid: np.ndarray,
                 step_sigma: float = STEP_SIGMA_PX) -> np.ndarray:
    """The map of frame ``s`` to an annotated frame from the map ``there`` of its neighbour ``n`` (one step nearer
    the annotation): each pixel of ``s`` moves by the flow s -> n and takes ``there``'s position, accumulated
    variance and validity where it lands (bilinear), its own step's round-trip check and drift added.

    A map is ``H x W x 4`` float32: x, y in the annotated frame, variance (px^2), validity (1 or 0). Two flow
    samplings per frame: the whole segment costs one step per frame instead of one per frame and frame between
    it and the annotation."""
    h, w = grid.shape[:2]
    w_there = flows.sample(s, n, grid)
    new = grid + w_there
    w_back = flows.sample(n, s, new)
    err2 = _squared_length(w_there + w_back)
    tol = 0.01 * (_squared_length(w_there) + _squared_length(w_back)) + 0.5
    inside = (new[..., 0] >= -0.5) & (new[..., 0] <= w - 0.5) & (new[..., 1] >= -0.5) & (new[..., 1] <= h - 0.5)
    state = _sample(there, new)
    state[..., 2] = (step_sigma ** 2 + err2 / 4.0) + state[..., 2]
    state[..., 3] = ((err2 <= tol) & inside & (state[..., 3] >= 0.5)).astype(np.float32)
    return state


def walk(flows: FrameFlows, key: KeyFrame, stop: int, step_sigma: float = STEP_SIGMA_PX,
         after_step: Callable[[int, int], None] | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """The maps of frames ``key.index -/+ 1``, ..., ``stop`` to the annotated frame ``key``, each composed from the
    previous one (``compose_step``); ``after_step(s, n)`` is called once the flows between s and n are used."""
    h, w = key.labels.shape
    grid = _grid(h, w)
    state = start_map(key)
    step = 1 if stop > key.index else -1
    for s in range(key.index + step, stop + step, step):
        state = compose_step(flows, state, s, s - step, grid, step_sigma)
        if after_step is not None:
            after_step(s, s - step)
        yield s, state


def read_track(key: KeyFrame, state: np.ndarray) -> Track:
    """Labels and confidence a frame's map to ``key`` gives: the annotation where each pixel lands (nearest),
    trusted by ``Phi((d - 0.5) / sigma)``, 0 where the track was occluded or left the view."""
    pos = np.ascontiguousarray(state[..., :2])
    labels = _sample(key.labels, pos, cv2.INTER_NEAREST)
    d = _sample(key.boundary_distance, pos)
    confidence = ndtr((d - 0.5) / np.sqrt(np.maximum(state[..., 2], 1e-12))).astype(np.float32)
    confidence[state[..., 3] < 0.5] = 0.0
    return Track(labels=labels.astype(np.uint16), confidence=confidence, key=key.index)


def track(flows: FrameFlows, key: KeyFrame, target: int, step_sigma: float = STEP_SIGMA_PX) -> Track:
    """Follow every pixel of frame ``target`` to the annotated frame ``key`` and read its label there (the walk
    from ``key`` to ``target``: one step per frame between them)."""
    state = start_map(key)
    for _, state in walk(flows, key, target, step_sigma):  # noqa: B007 (the last map is the target's)
        pass
    return read_track(key, state)


def fuse(a: Track, b: Track | None, target: int, n_labels: int) -> tuple[np.ndarray, np.ndarray]:
    """Labels and confidence from one or two tracks; ``n_labels`` counts background too.

    A track votes ``c`` for its label and spreads ``1 - c`` evenly over all labels (no information when
    occluded); the votes are weighted by ``1 - distance / gap``. The confidence is the winning label's
    share above chance, rescaled to [0, 1].
    """
    if b is None:
        return a.labels, a.confidence
    gap = abs(b.key - a.key)
    wa, wb = abs(b.key - target) / gap, abs(target - a.key) / gap
    u = 1.0 / n_labels
    same = a.labels == b.labels
    ca, cb = a.confidence, b.confidence
    vote_a = ca + (1 - ca) * u
    vote_b = cb + (1 - cb) * u
    score_a = wa * vote_a + wb * np.where(same, vote_b, (1 - cb) * u)
    score_b = wb * vote_b + wa * np.where(same, vote_a, (1 - ca) * u)
    # ties (both occluded, equal weights) go to the nearer annotation
    pick_a = score_a > score_b if wb > wa else score_a >= score_b
    labels = np.where(pick_a, a.labels, b.labels)
    best = np.where(pick_a, score_a, score_b)
    confidence = np.clip((best - u) / (1 - u), 0.0, 1.0).astype(np.float32)
    return labels.astype(np.uint16), confidence


def neighbours(keys: list[int], target: int) -> tuple[int | None, int | None]:
    """The annotated frames just before and just after ``target`` (``keys`` sorted)."""
    before = [k for k in keys if k < target]
    after = [k for k in keys if k > target]
    return (before[-1] if before else None), (after[0] if after else None)


def propagate_to(flows: FrameFlows, keys: Mapping[int, KeyFrame], target: int, n_labels: int,
                 step_sigma: float = STEP_SIGMA_PX) -> Propagated:
    """The labels of frame ``target`` from the annotated frames around it (not ``target`` itself)."""
    order = sorted(k for k in keys if k != target)
    if not order:
        raise ValueError("no annotated frame to propagate from")
    prev, nxt = neighbours(order, target)
    tracks = [track(flows, keys[k], target, step_sigma) for k in (prev, nxt) if k is not None]
    labels, confidence = fuse(tracks[0], tracks[1] if len(tracks) > 1 else None, target, n_labels)
    return Propagated(index=target, labels=labels, confidence=confidence, previous_key=prev, next_key=nxt)


def iou_per_object(pred: np.ndarray, truth: np.ndarray, n_objects: int) -> dict[int, float | None]:
    """IoU per object (1-based); None when the object is in neither map (nothing to score)."""
    out: dict[int, float | None] = {}
    for k in range(1, n_objects + 1):
        p, t = pred == k, truth == k
        union = int(np.count_nonzero(p | t))
        out[k] = None if union == 0 else int(np.count_nonzero(p & t)) / union
    return out


def mean_of(values: list[float | None]) -> float | None:
    """Mean of the finite values, None when there are none."""
    kept = [v for v in values if v is not None and math.isfinite(v)]
    return sum(kept) / len(kept) if kept else None
