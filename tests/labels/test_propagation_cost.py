"""Mask propagation composes each frame's map to an annotation from its neighbour's (docs/labels-states.md, "Masks
on key frames only: propagation"): one flow step per frame and direction, each flow computed once and released
after use, and, when every flow moves pixels by whole pixels, exactly the maps of following each pixel through the
whole chain of flows."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
from labelset_writers import HEIGHT, WIDTH, make_label_maps, write_png

from stages.labels import LabelsConfig, ingest_labels
from stages.labels.optical_flow import FrameFlows
from stages.labels.propagation import STEP_SIGMA_PX, make_key_frame, read_track, walk


def _count_flow_use(monkeypatch) -> dict[str, int]:
    """Count ``FrameFlows.sample`` calls and the most flows held in memory at once."""
    seen = {"samples": 0, "most_held": 0}
    sample = FrameFlows.sample

    def counting(self, i, j, pos):
        seen["samples"] += 1
        out = sample(self, i, j, pos)
        seen["most_held"] = max(seen["most_held"], len(self._flow))
        return out

    monkeypatch.setattr(FrameFlows, "sample", counting)
    return seen


def _frames(root: Path, n: int) -> Path:
    """A FRAMES folder of ``n`` textured frames (48 x 64) sliding 1 px right per frame, ids 00000, 00001, ..."""
    texture = cv2.GaussianBlur(np.random.default_rng(0).integers(0, 255, (HEIGHT, WIDTH + n), np.uint8), (5, 5), 1.5)
    frames = root / "frames"
    (frames / "images").mkdir(parents=True)
    rows = ["frame,source_index,timestamp,sharpness"]
    for i in range(n):
        cv2.imwrite(str(frames / "images" / f"frame_{i:05d}.png"), texture[:, n - i:n - i + WIDTH])
        rows.append(f"frame_{i:05d}.png,{i},{0.1 * i},1.0")
    (frames / "frames.csv").write_text("\n".join(rows) + "\n")
    return frames


def test_the_cost_is_one_step_per_frame_and_direction(tmp_path, monkeypatch) -> None:
    """Frames 0..g annotated at both ends. The walk back from g to 0 and the walk on from 0 to g take g steps each
    (the g - 1 frames between, plus one onto the other annotation for its leave-one-out estimate), two flow samplings
    a step: 4 g samplings, linear in g (following every frame through the whole chain to both annotations took
    (g - 1) g steps plus 2 g for the leave-one-out: 40 samplings for g = 4, 544 for g = 16). Each of the 2 g flows is
    computed once, at most one pair is held at a time, and the scratch folder is gone afterwards."""
    label = make_label_maps()["00000"]
    for g in (4, 16):
        root = tmp_path / f"gap{g}"
        frames = _frames(root, g + 1)
        src = write_png(root, {"00000": label, f"{g:05d}": label})
        seen = _count_flow_use(monkeypatch)
        summary = ingest_labels(LabelsConfig(input=src, frames=frames, out=root / "out", progress=False))
        assert len(summary["propagated_frames"]) == g - 1
        assert seen["samples"] == 4 * g, (g, seen)
        assert seen["most_held"] == 2, seen  # the flows i -> j and j -> i of the step in hand
        report = json.loads((root / "out" / "propagation.json").read_text())
        assert report["flow"]["flows_computed"] == 2 * g
        assert report["leave_one_out"]["n"] == 2
        assert not [p for p in (root / "out").rglob("*") if p.name.startswith(".propagation")]


class IntegerFlows:
    """Flows given exactly, in whole pixels: each frame pair moves the frame by one of a few steps (5 px, or 1 to 2
    px) and a block by the opposite step; the way back is the step back, missing by (0, 1) px on a tenth of the
    pixels (a round trip of 1 px^2: kept after a 5 px step, whose tolerance is 0.5 + 0.01 * 51 = 1.01 px^2,
    an occlusion after a short one) and by (2, 1) px on a twentieth (5 px^2: always an occlusion)."""

    STEPS = ((5, 0), (-5, 0), (0, 5), (0, -5), (1, -1), (2, 1))

    def __init__(self, shape: tuple[int, int], n: int, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self.fields: dict[tuple[int, int], np.ndarray] = {}
        for i in range(n - 1):
            step = np.float32(self.STEPS[rng.integers(len(self.STEPS))])
            there = np.broadcast_to(step, (*shape, 2)).copy()
            there[8:16, 10:20] = -step
            back = np.broadcast_to(-step, (*shape, 2)).copy()
            back[rng.random(shape) < 0.1] += np.float32([0, 1])
            back[rng.random(shape) < 0.05] += np.float32([2, 1])
            self.fields[(i, i + 1)], self.fields[(i + 1, i)] = there, back

    def sample(self, i: int, j: int, pos: np.ndarray) -> np.ndarray:
        f = self.fields[(i, j)]
        return cv2.remap(f, pos[..., 0], pos[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def _chained(flows: IntegerFlows, key: int, target: int, shape: tuple[int, int]):
    """The definition: every pixel of ``target`` followed through each flow to ``key``, the flow sampled at the
    tracked position, the round trip checked at each step; also whether it stayed inside the frame all along."""
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    pos = np.dstack([xs, ys])
    valid = np.ones(shape, bool)
    always_inside = np.ones(shape, bool)
    variance = np.zeros(shape, np.float32)
    step = 1 if key > target else -1
    for s in range(target, key, step):
        w_there = flows.sample(s, s + step, pos)
        new = pos + w_there
        w_back = flows.sample(s + step, s, new)
        err2 = ((w_there + w_back) ** 2).sum(-1)
        tol = 0.01 * ((w_there ** 2).sum(-1) + (w_back ** 2).sum(-1)) + 0.5
        inside = (new[..., 0] >= -0.5) & (new[..., 0] <= w - 0.5) & (new[..., 1] >= -0.5) & (new[..., 1] <= h - 0.5)
        valid &= (err2 <= tol) & inside
        always_inside &= inside
        variance += STEP_SIGMA_PX ** 2 + err2 / 4.0
        pos = new
    return pos, variance, valid, always_inside


def _at(pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices of whole-pixel positions, clamped to the 24 x 32 frame."""
    return pos[..., 1].astype(int).clip(0, 23), pos[..., 0].astype(int).clip(0, 31)


def test_composed_maps_equal_the_chained_tracks_for_whole_pixel_flows() -> None:
    """Whole-pixel flows land every pixel on a pixel, where sampling the neighbour's map reads it exactly: each
    frame's composed map to frame 0 (walking on from it) and to frame 6 (walking back) gives the same position,
    variance and validity as the chain, bit for bit, wherever the chain stays inside the frame, and the same
    labels and confidence there; a track that leaves the frame has confidence 0 either way."""
    shape = (24, 32)
    flows = IntegerFlows(shape, 7)
    annotation = np.zeros(shape, np.uint16)
    annotation[4:18, 6:22] = 1
    annotation[10:14, 22:30] = 2
    for key, stop in ((0, 6), (6, 0)):
        kf = make_key_frame(key, annotation)
        for s, state in walk(flows, kf, stop):
            pos, variance, valid, inside = _chained(flows, key, s, shape)
            kept = valid & inside
            assert kept.sum() > 20 and (~valid & inside).sum() > 20, s
            if abs(s - key) > 1:  # round trips that missed by 1 px^2 and were kept widen sigma
                assert (variance[kept] > abs(s - key) * STEP_SIGMA_PX ** 2).any(), s
            np.testing.assert_array_equal(state[..., :2][inside], pos[inside])
            np.testing.assert_array_equal(state[..., 2][inside], variance[inside])
            np.testing.assert_array_equal(state[..., 3][inside] == 1.0, valid[inside])
            track = read_track(kf, state)
            labels = annotation[_at(pos)]
            np.testing.assert_array_equal(track.labels[inside], labels[inside])
            assert (track.confidence[~inside] == 0).all()
            d = kf.boundary_distance[_at(pos)]
            expected = np.array([0.5 * (1 + math.erf((dv - 0.5) / math.sqrt(2 * v))) for dv, v in
                                 zip(d[inside], variance[inside], strict=True)], np.float32)
            expected[~valid[inside]] = 0.0
            np.testing.assert_allclose(track.confidence[inside], expected, atol=1e-6)
