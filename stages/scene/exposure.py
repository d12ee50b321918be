"""How much a dataset's exposure and white balance vary from frame to frame (docs/model.md, "Exposure").

A phone's auto exposure scales every pixel of a frame by a gain per colour channel. Two neighbouring
frames of a video see mostly the same surfaces, so after aligning them by dense optical flow (OpenCV's
DIS) the central log ratio of their colours is the difference of their log gains; surfaces that moved,
pixels the flow cannot follow (forward-backward check), edges, clipped pixels and, where the dataset has
masks, the movable objects (a door turning towards the light changes its shading, not the exposure) are left
out. A least squares fit over the pairs of frames 1, 3 and 9 apart gives every frame's log gain (zero mean), and the
spread of those gains says whether a per-frame colour correction is worth learning.

On the synthetic captures, whose gains are known: constant exposure reads 0.0005-0.0008, a jitter of 0.04 reads
0.038 and one of 0.10 reads 0.102 (docs/model.md, "Exposure", has the table).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .dataset import Frame, SceneDataset
from .errors import InputError
from .masks import mask_path

OFFSETS = (1, 3, 9)
"""Frame distances of the pairs that are compared. Each pair's ratio carries a small bias where the scene itself
changes (an opening door, its shadow); along a chain of neighbours those biases add up, and the longer links
hold the chain straight (on the `study` capture, of constant exposure, 1/2/3 read 0.0054 and 1/3/9 0.0037)."""
WINDOW = 0.02
"""Half-width in log gain of the values the ratio is taken from, around the running estimate: the pixels whose
colour the gain alone changed agree to about the 8-bit step; a moving object's or shadow's pixels do not, and
would pull a plain median towards them."""
MAX_SIDE = 320
"""Frames are compared at this longest side: a global gain does not need detail, and the flow is ~10x faster
than at a phone's 960 px."""
MIN_PIXELS = 500
"""Fewer usable pixels than this: the pair does not overlap enough to say anything."""
FB_LIMIT_PX = 0.5
"""Forward-backward flow disagreement (at the compared size) above which a pixel is not trusted."""
GAIN_STEP = 1e-4
"""Grid of the log gains returned (a 0.01 % brightness step, under a tenth of the 8-bit step)."""
MIN_CORRELATION = 0.8
"""Least correlation of the two frames' aligned grey values (blind to a gain): below it the flow matched things
that are not the same surfaces (frames that do not overlap, an unordered collection)."""
CLIP = (8, 247)
"""8-bit values outside this range may be clipped in either frame: their ratio is not the gain's."""
MAX_LOG_GAIN = 10.0
"""Largest |log gain| a saved estimate may hold (a factor of 22000, 14 stops): beyond it, or NaN, the file is
corrupt, and training would clip that frame's channel to black or white without a word."""
MASK_MARGIN_PX = 2
"""Object masks are grown by this many pixels (at the compared size) before their pixels are left out: a
propagated mask's edge is a pixel or two off, and an object's border mixes it with the room."""


@dataclass
class ExposureEstimate:
    """Per-frame log gains of a frame sequence and their spread."""

    frame_ids: list[str]
    """Frames in the order compared (playback order)."""
    log_gains: np.ndarray
    """[N, 3] log gain per frame and RGB channel, zero mean over the frames that were tied to a neighbour."""
    pairs: int
    """Pairs of frames that overlapped enough to be compared."""
    tied: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    """[N] whether the frame took part in at least one compared pair."""
    inputs_sha256: str = ""
    """Digest of the measured image and mask files (``inputs_digest``): a saved estimate is only used for those."""
    masked: bool = False
    """Whether the movable objects' pixels were left out (the dataset has masks)."""

    @property
    def spread(self) -> float | None:
        """Standard deviation of the tied frames' log gains over frames, averaged over channels; None when
        fewer than 3 frames are tied (an unordered photo collection, or frames that do not overlap)."""
        g = self.log_gains[self.tied]
        return float(g.std(axis=0).mean()) if len(g) >= 3 else None

    def to_dict(self) -> dict:
        """The estimate as JSON (``livescene scene exposure --out``, the workflow's ``exposure`` rule). The gains
        are written in full: JSON's shortest repr reads back to the same doubles, so a trainer reading the file
        divides its images exactly as one that measured them itself."""
        return {"spread": self.spread, "pairs": self.pairs, "frames": len(self.frame_ids),
                "tied_frames": int(self.tied.sum()), "offsets": list(OFFSETS), "max_side": MAX_SIDE,
                "inputs_sha256": self.inputs_sha256, "masked": self.masked,
                "untied": [f for f, t in zip(self.frame_ids, self.tied, strict=True) if not t],
                "log_gains": {f: [float(v) for v in g] for f, g in zip(self.frame_ids, self.log_gains, strict=True)}}


def _small(rgb: np.ndarray) -> np.ndarray:
    """RGB float [0, 1] -> uint8 at MAX_SIDE (area-averaged)."""
    img = np.clip(np.asarray(rgb, np.float32) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    s = MAX_SIDE / max(img.shape[:2])
    if s < 1.0:
        img = cv2.resize(img, (round(img.shape[1] * s), round(img.shape[0] * s)), interpolation=cv2.INTER_AREA)
    return img


def static_map(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """[H, W] bool at the compared ``shape``: True where a frame's one-hot mask ([H', W', objects + 1], background
    last) shows no object, the objects grown by MASK_MARGIN_PX. Integer operations only (area averaging of 0/255
    and a dilation), so the same pixels are left out on every machine."""
    objects = np.where(mask[..., -1], 0, 255).astype(np.uint8)
    if objects.shape != shape:
        objects = cv2.resize(objects, (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
    grown = cv2.dilate(objects, np.ones((2 * MASK_MARGIN_PX + 1,) * 2, np.uint8))
    return grown == 0


def pair_log_ratio(a: np.ndarray, b: np.ndarray, flow: cv2.DISOpticalFlow, static_a: np.ndarray | None = None,
                   static_b: np.ndarray | None = None) -> np.ndarray | None:
    """Median of log(b / a) per channel over the pixels of ``a`` that ``b`` sees ([3]), or None without overlap.

    ``a``, ``b``: uint8 RGB of one size; ``static_a``, ``static_b``: their ``static_map``s, each when known
    (pixels on a movable object in either frame are left out)."""
    ga, gb = cv2.cvtColor(a, cv2.COLOR_RGB2GRAY), cv2.cvtColor(b, cv2.COLOR_RGB2GRAY)
    fwd = flow.calc(ga, gb, None)
    bwd = flow.calc(gb, ga, None)
    h, w = ga.shape
    xx, yy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    mx, my = xx + fwd[..., 0], yy + fwd[..., 1]
    b_on_a = cv2.remap(b, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    back = cv2.remap(bwd, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    consistent = np.hypot(fwd[..., 0] + back[..., 0], fwd[..., 1] + back[..., 1]) < FB_LIMIT_PX
    inside = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    # interpolation across an edge mixes two colours: keep the smoother 60 % of the image
    grad = edge_strength(ga)
    smooth = grad <= np.percentile(grad, 60)
    lo, hi = CLIP
    unclipped = (a.min(-1) > lo) & (a.max(-1) < hi) & (b_on_a.min(-1) > lo) & (b_on_a.max(-1) < hi)
    ok = consistent & inside & smooth & unclipped
    if static_a is not None:
        ok &= static_a
    if static_b is not None:
        ok &= static_b[np.clip(np.rint(my), 0, h - 1).astype(np.intp), np.clip(np.rint(mx), 0, w - 1).astype(np.intp)]
    if int(ok.sum()) < MIN_PIXELS:
        return None
    with np.errstate(invalid="ignore", divide="ignore"):  # a flat region: no variance, correlation NaN
        r = np.corrcoef(ga[ok].astype(np.float64), cv2.cvtColor(b_on_a, cv2.COLOR_RGB2GRAY)[ok])[0, 1]
    if not r >= MIN_CORRELATION:  # NaN too: two flat frames show nothing to match, whatever their brightness
        return None
    return central_value(np.log(b_on_a[ok].astype(np.float64)) - np.log(a[ok].astype(np.float64)))


def edge_strength(grey: np.ndarray) -> np.ndarray:
    """Squared Sobel gradient magnitude [H, W] of a uint8 image, in exact integers.

    Not ``cv2.magnitude`` of float gradients: it approximates the square root (250 comes out as 250.0000153), and
    differently in its vector and scalar code, and which code a pixel takes depends on where the allocator put the
    array; so two runs could put a few different pixels under the percentile and read a gain that differs in its
    last digits (docs/model.md, "Exposure"). Squaring is monotonic: the same pixels fall under a percentile of it
    as under one of the exact magnitude."""
    gx = cv2.Sobel(grey, cv2.CV_16S, 1, 0).astype(np.int32)
    gy = cv2.Sobel(grey, cv2.CV_16S, 0, 1).astype(np.int32)
    return gx * gx + gy * gy


def central_value(d: np.ndarray, iterations: int = 3) -> np.ndarray:
    """The centre [3] of the largest cluster of log ratios [P, 3]: the median, then the median of the values within
    WINDOW of it, repeated (a mode seeker: a door that changes a fifth of the pixels moves the plain median)."""
    centre = np.median(d, axis=0)
    for _ in range(iterations):
        near = (np.abs(d - centre) < WINDOW).all(axis=1)
        if int(near.sum()) < MIN_PIXELS:
            break
        centre = np.median(d[near], axis=0)
    return centre


def estimate_log_gains(images: Iterable[np.ndarray], frame_ids: Sequence[str],
                       masks: Iterable[np.ndarray | None] | None = None) -> ExposureEstimate:
    """Per-frame log gains of ``images`` (RGB float [0, 1], in playback order; each is shrunk as it comes, so a
    long phone video is never held at full size); ``masks``: the frames' one-hot object masks (None for a frame
    without one), whose objects are left out of the comparison."""
    small = [_small(im) for im in images]
    static: list[np.ndarray | None] | None = None
    if masks is not None:
        static = [None if m is None else static_map(m, im.shape[:2]) for m, im in zip(masks, small, strict=True)]
    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    n = len(small)
    rows, rhs = [], []
    for s in OFFSETS:
        for i in range(n - s):
            if small[i].shape != small[i + s].shape:
                continue
            d = pair_log_ratio(small[i], small[i + s], flow, *((static[i], static[i + s]) if static else ()))
            if d is None:
                continue
            rows.append((i, i + s))
            rhs.append(d)
    tied = np.zeros(n, bool)
    for i, j in rows:
        tied[i] = tied[j] = True
    gains = np.zeros((n, 3))
    if rows:
        a = np.zeros((len(rows) + 1, n))
        for k, (i, j) in enumerate(rows):
            a[k, i], a[k, j] = -1.0, 1.0
        a[-1, tied] = 1.0  # the gains' mean is free (the field takes it): fix it at zero
        y = np.vstack([np.asarray(rhs), np.zeros((1, 3))])
        gains, *_ = np.linalg.lstsq(a, y, rcond=None)
        gains[~tied] = 0.0
        # on a grid far finer than the estimate's accuracy (~3e-3): another machine's LAPACK may differ in the
        # least-squares fit's last bits, which would round some training pixels the other way
        gains = np.round(gains / GAIN_STEP) * GAIN_STEP
    return ExposureEstimate(list(frame_ids), gains, len(rows), tied, masked=static is not None)


def playback_order(ds: SceneDataset) -> list[Frame]:
    """The dataset's frames in the order they were filmed: by source index when every frame has one, else as
    listed in transforms.json."""
    if all(f.source_index is not None for f in ds.frames):
        return sorted(ds.frames, key=lambda f: f.source_index)
    return list(ds.frames)


def inputs_digest(ds: SceneDataset) -> str:
    """SHA-256 over the image (and, with masks, mask) files of the dataset's frames in playback order: what a
    saved estimate was measured on."""
    h = hashlib.sha256()
    for f in playback_order(ds):
        h.update(f"{f.frame_id}:".encode())
        h.update(ds.image_path(f).read_bytes())
        mask = mask_path(ds.root, f.frame_id)
        if ds.has_masks and mask.is_file():  # a dataset may list frames_without_masks
            h.update(mask.read_bytes())
    return h.hexdigest()


def estimate_exposure(ds: SceneDataset, use_masks: bool = True) -> ExposureEstimate:
    """Per-frame log gains of every frame of a dataset, train and test, in playback order; the movable objects
    left out where the dataset has masks (``use_masks``)."""
    frames = playback_order(ds)
    masks = (ds.load_mask_or_none(f) for f in frames) if use_masks and ds.has_masks else None
    est = estimate_log_gains((ds.load_image(f) for f in frames), [f.frame_id for f in frames], masks)
    est.inputs_sha256 = inputs_digest(ds)
    return est


def read_exposure(path: str | Path, ds: SceneDataset) -> ExposureEstimate:
    """A saved estimate (``ExposureEstimate.to_dict``) of ``ds``'s frames, checked to be of the same images."""
    path = Path(path)
    remeasure = f"measure them again: livescene scene exposure {ds.root} --out {path}"
    try:
        data = json.loads(path.read_text())
        gains = data["log_gains"]
        ids, untied, digest = list(gains), set(data["untied"]), str(data["inputs_sha256"])
        log_gains = np.array([[float(v) for v in gains[f]] for f in ids], dtype=np.float64).reshape(len(ids), 3)
        pairs = int(data["pairs"])
    except FileNotFoundError:
        raise InputError(path, "no such exposure file", remeasure) from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(path, f"not an exposure estimate ({type(exc).__name__}: {exc})", remeasure) from None
    bad = np.argwhere(~(np.abs(log_gains) <= MAX_LOG_GAIN))  # NaN and inf fail the comparison too
    if len(bad):
        frame, channel = ids[bad[0][0]], "RGB"[bad[0][1]]
        raise InputError(path, f"the log gain of frame {frame} ({channel}) is {log_gains[tuple(bad[0])]!r}, not a "
                         f"finite number within +-{MAX_LOG_GAIN:g} (a factor of e^{MAX_LOG_GAIN:g} no camera's "
                         f"exposure moves within one video; {len(bad)} such value(s))", remeasure)
    order = [f.frame_id for f in playback_order(ds)]
    if ids != order:
        missing, extra = sorted(set(order) - set(ids)), sorted(set(ids) - set(order))
        what = (f"frames {missing[:4]} of the dataset are missing" if missing
                else f"it names frames {extra[:4]} the dataset does not have" if extra
                else "its frames are in another order")
        raise InputError(path, f"measured on other frames than {ds.root}'s: {what}", remeasure)
    if digest != inputs_digest(ds):
        raise InputError(path, f"measured on other images or masks than {ds.root}'s (their digest differs)",
                         remeasure)
    return ExposureEstimate(ids, log_gains, pairs, np.array([f not in untied for f in ids]), digest,
                            bool(data.get("masked", False)))
