"""A dataset's key frames as training targets: matched to its frames, in [0, 1] (docs/data-contract.md,
"Key frames and the time axis").

The published LiveScene datasets give states only at key frames, in the unit of whoever annotated them (a door's
angle, a drawer's travel), keyed on ``<name>_<fid>`` where the reference compares frame *numbers*
(``frame_5`` is the image ``frame_00005``). Here they become what the model trains on: each key frame tied to
one frame of transforms.json, and each object's values brought into [0, 1] by the same rule as the states stage's.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from .dataset import Frame, SceneDataset
from .errors import SceneError
from .keyframes import frame_number_of

KEPT = "key values within [0, 1]: kept as given"


def key_value_range(values: Sequence[float]) -> tuple[float, float, str] | None:
    """(lo, hi, why) that maps an object's key values to [0, 1]; None when they cannot be mapped (one value
    outside [0, 1] on every key frame). Values already within [0, 1] are kept: min-max would stretch whatever span
    the key frames cover to the whole range, so an object that stays shut, annotated with a little noise, would
    read as fully open."""
    lo, hi = float(min(values)), float(max(values))
    if lo >= 0.0 and hi <= 1.0:
        return 0.0, 1.0, KEPT
    if hi > lo:
        return lo, hi, "min-max of key frames"
    return None


def match_key_frames(key_ids: Iterable[str], frames: Sequence[Frame]) -> tuple[dict[str, int], list[str]]:
    """Each key frame's index into ``frames``: the frame of the same id, else the one frame whose id carries the
    same number (the reference compares ``int(fid)``, so ``frame_5`` names ``frame_00005``); and the key frames
    that match no frame."""
    by_id = {f.frame_id: i for i, f in enumerate(frames)}
    by_number: dict[int, int | None] = {}
    for i, f in enumerate(frames):
        n = frame_number_of(f.frame_id)
        if n is not None:
            by_number[n] = None if n in by_number else i  # two frames of one number: neither is meant
    matched: dict[str, int] = {}
    unmatched: list[str] = []
    for fid in key_ids:
        if fid in by_id:
            matched[fid] = by_id[fid]
            continue
        n = frame_number_of(fid)
        i = by_number.get(n) if n is not None else None
        if i is None:
            unmatched.append(fid)
        else:
            matched[fid] = i
    return matched, unmatched


@dataclass
class KeyFrameStates:
    """Key frames per frame index, normalised; the ranges used and what was rescaled, for the run's record."""

    by_frame: dict[int, dict[str, float]] = field(default_factory=dict)
    """Frame index -> {object: state in [0, 1]}."""
    ranges: dict[str, dict] = field(default_factory=dict)
    """Object -> {"lo", "hi", "source"} of the normalisation."""

    @property
    def rescaled(self) -> dict[str, dict]:
        """The objects whose key values were mapped (not kept as given)."""
        return {o: r for o, r in self.ranges.items() if (r["lo"], r["hi"]) != (0.0, 1.0)}


def key_frame_states(ds: SceneDataset) -> KeyFrameStates:
    """The dataset's key frames tied to its frames (unmatched ones left out: ``validate_scene`` names them) and
    normalised per object: by the fixed range ``scene.json`` gives in ``state_ranges`` ``{object: [lo, hi]}``; else,
    where the frames carry states (this project's datasets, whose key frames the states stage wrote in the frames'
    [0, 1]), by ``key_value_range``, the states stage's rule; else, where key frames are all there is (the published
    form), by the min and max of the object's key values, as the reference normalises them. A value outside a
    fixed range, or one value outside [0, 1] on every key frame, is an error naming ``key_frame_value.yaml``."""
    kpath = ds.root / "key_frame_value.yaml"
    matched, _ = match_key_frames(ds.key_frames, ds.frames)
    fixed = _fixed_ranges(ds)
    published = ds.states_at_key_frames_only
    out = KeyFrameStates()
    for name in ds.objects:
        values = [ds.key_frames[fid][name] for fid in matched if name in ds.key_frames[fid]]
        if not values:
            continue
        lo, hi = min(values), max(values)
        if name in fixed:
            lo, hi = fixed[name]
            outside = [v for v in values if not lo <= v <= hi]
            if outside:
                raise SceneError(kpath, f"{name!r} has key value {outside[0]} outside its range [{lo}, {hi}] of "
                                 "scene.json state_ranges", "fix the value or widen the range in scene.json")
            rng: tuple[float, float, str] | None = (lo, hi, "scene.json state_ranges")
        elif published and hi > lo:
            rng = (float(lo), float(hi), "min-max of key frames, as the reference normalises them")
        else:
            rng = key_value_range(values)
        if rng is None:
            raise SceneError(kpath, f"{name!r} has the single value {values[0]} on every key frame, which "
                             "min-max normalisation cannot map to [0, 1]",
                             f"give its range in scene.json: \"state_ranges\": {{\"{name}\": [LO, HI]}}")
        out.ranges[name] = {"lo": rng[0], "hi": rng[1], "source": rng[2]}
    for fid, i in sorted(matched.items(), key=lambda kv: kv[1]):
        row = out.by_frame.setdefault(i, {})
        for name, v in ds.key_frames[fid].items():
            r = out.ranges.get(name)
            if r is None:
                continue
            # kept values stay the same floats: a dataset of [0, 1] key frames trains bit for bit as before
            row[name] = v if (r["lo"], r["hi"]) == (0.0, 1.0) else (v - r["lo"]) / (r["hi"] - r["lo"])
    return out


def _fixed_ranges(ds: SceneDataset) -> dict[str, tuple[float, float]]:
    spath = ds.root / "scene.json"
    raw = ds.meta.get("state_ranges") or {}
    if not isinstance(raw, dict):
        raise SceneError(spath, "state_ranges is not a mapping of object to [lo, hi]",
                         "write \"state_ranges\": {\"cabinet\": [0, 90]}")
    out: dict[str, tuple[float, float]] = {}
    for name, pair in raw.items():
        if name not in ds.objects:
            raise SceneError(spath, f"state_ranges names unknown object {name!r}",
                             f"use the names of mapping.yaml {ds.objects}")
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError) as exc:
            raise SceneError(spath, f"state_ranges[{name!r}] = {pair!r} is not [lo, hi]",
                             "write two numbers, lo below hi") from exc
        if not (np.isfinite([lo, hi]).all() and lo < hi):
            raise SceneError(spath, f"state_ranges[{name!r}] = {pair!r} is not [lo, hi] with lo below hi",
                             "write two finite numbers, lo below hi")
        out[str(name)] = (lo, hi)
    return out


def frame_times(frames: Sequence[Frame]) -> np.ndarray:
    """Each frame's time t in [0, 1], the axis along which learned states and key frames are interpolated: by the
    frames' numbers, not their order in transforms.json (which a merge or another tool may shuffle; the reference
    takes ``int(fid) / max``): the video index (``source_index``) where every frame has one, else the number in the
    frame id where every frame has a distinct one, else the position in the file. Numbered 0..n-1 in file order,
    t equals ``np.linspace(0, 1, n)`` bit for bit."""
    n = len(frames)
    if n <= 1:
        return np.zeros(n)
    numbers: list[int | None] = [f.source_index for f in frames]
    if any(v is None for v in numbers):
        numbers = [frame_number_of(f.frame_id) for f in frames]
    if any(v is None for v in numbers) or len(set(numbers)) < n:
        numbers = list(range(n))
    x = np.asarray(numbers, dtype=np.float64)
    lo, hi = x.min(), x.max()
    if hi == lo:
        return np.zeros(n)
    t = (x - lo) * (1.0 / (hi - lo))  # linspace's own arithmetic: index times step, the end set exactly
    t[x == hi] = 1.0
    return t
