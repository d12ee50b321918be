"""Mask propagation's rules (stages/labels/propagation.py's docstring) on flows given exactly instead of measured:
where a track lands, its confidence Phi((d - 0.5) / sigma), tracks that leave the view, how two tracks are fused,
and how a flow computed at a smaller size is read back at frame pixels."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from labelset_writers import write_png

from stages.labels import LabelsConfig, ingest_labels
from stages.labels.optical_flow import FrameFlows
from stages.labels.propagation import STEP_SIGMA_PX, Track, fuse, make_key_frame, propagate_to


class ShiftFlows:
    """Every pixel moves by (dx, dy) from each frame to the next (and back by the opposite): round trips close."""

    def __init__(self, dx: float, dy: float = 0.0) -> None:
        self.d = np.array([dx, dy], np.float32)

    def sample(self, i: int, j: int, pos: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.d if j > i else -self.d, pos.shape).astype(np.float32)


def phi(z: float) -> float:
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


def halves(right: int, height: int = 3, width: int = 10) -> np.ndarray:
    """Label 0 in columns 0..4, ``right`` in columns 5..9."""
    labels = np.zeros((height, width), np.uint16)
    labels[:, 5:] = right
    return labels


def test_a_track_lands_where_the_flow_carries_it_and_trusts_it_by_its_distance_to_the_boundary() -> None:
    """Frame 0 -> annotated frame 2, everything moving 1 px right per frame: column x lands on column x + 2 of the
    annotation (label 1 from column 5, so from column 3 here). Two steps of drift: sigma^2 = 2 * 0.5^2. The landing
    column c lies d = c - 4 (label 1) or 5 - c (label 0) px from the other label. Columns 8 and 9 land past the
    right edge: they left the view, confidence 0."""
    result = propagate_to(ShiftFlows(1.0), {2: make_key_frame(2, halves(1))}, 0, n_labels=2)
    np.testing.assert_array_equal(result.labels[0], [0, 0, 0, 1, 1, 1, 1, 1, 1, 1])
    sigma = math.sqrt(2 * STEP_SIGMA_PX ** 2)
    d = [abs(x + 2 - 4.5) + 0.5 for x in range(8)]  # c - 4 or 5 - c
    expected = [phi((dx - 0.5) / sigma) for dx in d] + [0.0, 0.0]
    np.testing.assert_allclose(result.confidence[0], expected, atol=1e-4)
    assert result.confidence[0, 2] == pytest.approx(0.7602, abs=1e-4)  # d = 1: Phi(0.5 / 0.7071) = Phi(0.7071)


def test_a_track_reads_only_labels_the_annotation_has() -> None:
    """Half a pixel of motion lands column 4 between a background pixel (0) and object 2: it takes one of them,
    never an id in between (object 1)."""
    result = propagate_to(ShiftFlows(0.5), {1: make_key_frame(1, halves(2))}, 0, n_labels=3)
    assert set(np.unique(result.labels).tolist()) <= {0, 2}


def _track(label: int, confidence: float, key: int) -> Track:
    return Track(labels=np.full((2, 2), label, np.uint16), confidence=np.full((2, 2), confidence, np.float32),
                 key=key)


def test_two_tracks_are_fused_by_their_distance_and_confidence() -> None:
    """Annotations at frames 0 (label 1) and 4 (label 2), 3 labels (u = 1/3), both tracks at confidence 0.8.
    Frame 1: weights 3/4 and 1/4; a vote is c + (1 - c) u = 13/15 for its label and (1 - c) u = 1/15 for the
    others, so label 1 scores 3/4 * 13/15 + 1/4 * 1/15 = 2/3 and label 2 scores 4/15; the confidence is the share
    above chance, (2/3 - 1/3) / (1 - 1/3) = 0.5. Frame 3 is the mirror image."""
    a, b = _track(1, 0.8, key=0), _track(2, 0.8, key=4)
    for target, label in ((1, 1), (3, 2)):
        labels, confidence = fuse(a, b, target, n_labels=3)
        assert (labels == label).all(), target
        np.testing.assert_allclose(confidence, 0.5, atol=1e-6)
    # two tracks that agree at confidence c give c: (c + (1 - c) u - u) / (1 - u) = c
    labels, confidence = fuse(_track(1, 0.8, key=0), _track(1, 0.8, key=4), 1, n_labels=3)
    assert (labels == 1).all()
    np.testing.assert_allclose(confidence, 0.8, atol=1e-6)


def test_two_occluded_tracks_leave_the_nearer_annotation_at_no_confidence() -> None:
    """Both tracks occluded (confidence 0): each label scores exactly 1/3, a tie the nearer annotation wins."""
    a, b = _track(1, 0.0, key=0), _track(2, 0.0, key=4)
    for target, label in ((1, 1), (3, 2)):
        labels, confidence = fuse(a, b, target, n_labels=3)
        assert (labels == label).all(), target
        np.testing.assert_array_equal(confidence, 0.0)


def test_a_flow_computed_at_a_smaller_size_is_read_back_at_frame_pixels() -> None:
    """A zoom about the centre, F(X) = 0.1 (X - 3.5) px, on an 8 x 8 frame whose flow is computed at half size:
    the small flow is the frame flow resized as the frames are (INTER_AREA) and measured in small pixels. Read back
    at frame pixels it gives F again (inside the small image's pixel centres: frame pixels 1..6)."""
    ys, xs = np.mgrid[0:8, 0:8].astype(np.float32)
    full = np.dstack([0.1 * (xs - 3.5), 0.1 * (ys - 3.5)]).astype(np.float32)
    flows = FrameFlows([Path("a.png"), Path("b.png")], (8, 8), max_side=4)
    assert flows.scale == 0.5
    small = cv2.resize(full, (4, 4), interpolation=cv2.INTER_AREA) * flows.scale
    flows.flow = lambda i, j: small  # the flow DIS would give on the half-size frames, given exactly
    got = flows.sample(0, 1, np.dstack([xs, ys]))
    np.testing.assert_allclose(got[1:7, 1:7], full[1:7, 1:7], atol=1e-5)


def test_confidence_csv_names_the_nearer_annotation(label_files) -> None:
    """Frames 00000 .. 00006, annotated at 00000 and 00006: 00002 is nearer 00000, 00004 nearer 00006."""
    labels = label_files.labels
    src = write_png(label_files.root, {"00000": labels["00000"], "00006": labels["00000"]})
    out = label_files.root / "out"
    ingest_labels(LabelsConfig(input=src, frames=label_files.frames, out=out, progress=False))
    table = pd.read_csv(out / "confidence.csv", dtype=str, keep_default_na=False).set_index("frame")
    assert table.loc["00002", "nearest_key"] == "00000" and table.loc["00004", "nearest_key"] == "00006"
    assert table.loc["00002", "distance"] == table.loc["00004", "distance"] == "1"


class UnclosedFlows:
    """No motion forward, but the flow back is off by ``miss`` px in x: each step's round trip misses by it."""

    def __init__(self, miss: float) -> None:
        self.miss = miss

    def sample(self, i: int, j: int, pos: np.ndarray) -> np.ndarray:
        back = np.array([self.miss if j < i else 0.0, 0.0], np.float32)
        return np.broadcast_to(back, pos.shape).astype(np.float32)


def test_a_round_trip_that_misses_is_an_occlusion_past_the_tolerance_and_widens_sigma_below_it() -> None:
    """One step, |w| = 0, |w_back| = m: occluded when m^2 > 0.01 m^2 + 0.5. m = 0.8: 0.64 > 0.5064, confidence 0.
    m = 0.6: 0.36 <= 0.5036, kept, sigma^2 = 0.5^2 + 0.36 / 4 = 0.34; column 4 lands on column 4, d = 1."""
    key = {1: make_key_frame(1, halves(1))}
    occluded = propagate_to(UnclosedFlows(0.8), key, 0, n_labels=2)
    np.testing.assert_array_equal(occluded.confidence, 0.0)
    kept = propagate_to(UnclosedFlows(0.6), key, 0, n_labels=2)
    np.testing.assert_array_equal(kept.labels[0], halves(1)[0])
    assert kept.confidence[0, 4] == pytest.approx(phi(0.5 / math.sqrt(0.34)), abs=1e-4)  # Phi(0.8575) = 0.804


def test_the_squared_length_is_numpys_sum_to_the_bit() -> None:
    """The tracking step's x^2 + y^2 gives the float32 values of ``(v ** 2).sum(-1)``, so masks and confidence maps
    stay byte for byte what they were."""
    from stages.labels.propagation import _squared_length

    v = np.random.default_rng(0).normal(scale=30.0, size=(37, 53, 2)).astype(np.float32)
    v[0, 0] = [1e-30, 1e-3]  # a square that underflows beside a small one
    assert _squared_length(v).dtype == np.float32
    assert _squared_length(v).tobytes() == (v ** 2).sum(-1).tobytes()
