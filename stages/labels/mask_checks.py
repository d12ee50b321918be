"""Checks of ingested masks for the ways video object trackers and labelling tools fail (docs/labels-states.md,
"Tracker failures"): an identity switch, an object lost or appearing out of nowhere between two neighbouring
frames, and the anti-aliased edges of an id map. They warn (labels.json ``mask_warnings``, stderr), never refuse:
each can have a real cause, and the user who knows the scene decides.

Only annotated frames that are neighbours in FRAMES (consecutive in frames.csv) are compared: between them the
camera and the objects move a little, so an object's pixels lie mostly where its own pixels were a frame before.
"""

from __future__ import annotations

import cv2
import numpy as np

SWITCH_SHARE = 0.5
"""An object's mask counts as taken from another object when at least this share of its pixels held that other
object in the previous frame ..."""
SWITCH_RATIO = 2.0
"""... and at least this many times as many of them as held the object itself."""
BETWEEN_SHARE = 0.1
"""A frame's id map counts as anti-aliased when at least this share of its edge pixels (a 3x3 window holding two
values) hold an id between a smaller and a larger id of their window (measured: at most 0.014 on the truth masks of
the synthetic captures, with 2-4 px boundary noise; 0.44 on the same masks blurred by a 3x3 Gaussian and rounded)."""


def overlap_counts(previous: np.ndarray, current: np.ndarray, n_objects: int) -> np.ndarray:
    """``[n + 1, n + 1]`` pixel counts: row = label in ``previous``, column = label in ``current`` (0 background,
    k = object k)."""
    k = n_objects + 1
    pairs = previous.astype(np.int64).ravel() * k + current.astype(np.int64).ravel()
    return np.bincount(pairs, minlength=k * k).reshape(k, k)


def identity_switches(
    previous_fid: str, fid: str, counts: np.ndarray, names: list[str], min_pixels: float
) -> list[dict]:
    """Objects of frame ``fid`` whose pixels held another object in ``previous_fid`` far more than themselves
    (``overlap_counts``): an identity switch, or one object's id taken by another (both ids on one object)."""
    found = []
    for k in range(1, len(names) + 1):
        area = int(counts[:, k].sum())
        if area < min_pixels:  # a sliver's overlaps say nothing
            continue
        others = counts[1:, k].copy()
        others[k - 1] = 0
        j = int(np.argmax(others)) + 1
        taken, own = int(counts[j, k]), int(counts[k, k])
        if taken >= SWITCH_SHARE * area and taken >= SWITCH_RATIO * own:
            found.append(
                {
                    "kind": "identity_switch",
                    "frame": fid,
                    "previous": previous_fid,
                    "object": names[k - 1],
                    "was": names[j - 1],
                    "share": round(taken / area, 3),
                    "own_share": round(own / area, 3),
                }
            )
    return found


def sudden_changes(
    pairs: list[tuple[str, str]],
    pixels: dict[str, dict[str, int]],
    at_border: dict[str, set[str]],
    names: list[str],
    min_pixels: float,
    usual: dict[str, float],
    share: float,
) -> list[dict]:
    """Objects that vanish from one neighbouring frame to the next while at least ``share`` of their usual size and
    ``min_pixels`` (a tracker that lost them), or appear so (found late, or a ghost). An object that leaves or enters
    the view fast is cut by the border there: its mask touches the border and is under its usual size (``at_border``:
    frame -> objects whose mask touches the image border); one hidden or revealed step by step is a sliver first."""
    found = []
    for previous, fid in pairs:
        for name in names:
            before, now = pixels[previous][name], pixels[fid][name]
            limit = max(min_pixels, share * usual[name])
            if before >= limit and now == 0 and not (name in at_border[previous] and before < usual[name]):
                found.append(
                    {
                        "kind": "vanishes",
                        "frame": fid,
                        "previous": previous,
                        "object": name,
                        "pixels_before": int(before),
                    }
                )
            elif now >= limit and before == 0 and not (name in at_border[fid] and now < usual[name]):
                found.append(
                    {"kind": "appears", "frame": fid, "previous": previous, "object": name, "pixels": int(now)}
                )
    return found


def border_objects(labels: np.ndarray, names: list[str]) -> set[str]:
    """The objects whose mask touches the image border (0 background, k = ``names[k - 1]``)."""
    edge = np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])
    return {names[k - 1] for k in np.unique(edge) if k}


def between_and_edge_pixels(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two ``bool [H, W]`` maps of an id map's pixels: those whose value lies strictly between the smallest and the
    largest value of their 3x3 window (the ribbon an anti-aliased or interpolated edge leaves: an edge between ids 0
    and 3 passes through 1 and 2; never the background 0, which nothing lies under), and the edge pixels, whose
    window holds two values or more."""
    v = values.astype(np.float32)  # exact for 16-bit ids
    kernel = np.ones((3, 3), np.uint8)
    low = cv2.erode(v, kernel, borderType=cv2.BORDER_REPLICATE)
    high = cv2.dilate(v, kernel, borderType=cv2.BORDER_REPLICATE)
    return (low < v) & (high > v), low != high


def between_id_edges(labels: np.ndarray) -> tuple[int, int]:
    """(edge pixels holding an object id between a smaller and a larger id of their 3x3 window, edge pixels): the
    trace of an anti-aliased id map or one resized with interpolation (``between_and_edge_pixels``)."""
    between, edges = between_and_edge_pixels(labels)
    return int(np.count_nonzero(between)), int(np.count_nonzero(edges))


def warning_line(w: dict) -> str:
    """One warning in words, naming the frames and objects."""
    if w["kind"] == "identity_switch":
        return (
            f"frame {w['frame']}: {w['object']}'s mask lies on {w['was']}'s pixels of frame {w['previous']} "
            f"({w['share']:.0%} of it, {w['own_share']:.0%} on its own): an identity switch?"
        )
    if w["kind"] == "vanishes":
        return (
            f"frame {w['frame']}: {w['object']} has no mask, after {w['pixels_before']} pixels in frame "
            f"{w['previous']}: lost by the tracker?"
        )
    if w["kind"] == "appears":
        return (
            f"frame {w['frame']}: {w['object']} appears with {w['pixels']} pixels, after none in frame "
            f"{w['previous']}: found late by the tracker, or a ghost?"
        )
    shown = ", ".join(w["frames"][:5]) + (", ..." if len(w["frames"]) > 5 else "")
    return (
        f"{len(w['frames'])} frame(s) ({shown}): up to {w['share']:.0%} of the id map's edge pixels hold an id "
        "between their neighbours' ids: anti-aliased edges, or masks resized with interpolation? (export id maps "
        "without anti-aliasing, resize them nearest-neighbour)"
    )
