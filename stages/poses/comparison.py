"""Pose accuracy against reference poses: similarity alignment, centre, rotation and focal errors.

Structure from motion recovers poses up to a similarity (scale, rotation,
translation), so the reference is first brought into the estimate's world
with a least-squares similarity fitted to the frames both files hold
(paired by name, or by order when asked: ``frame_matching``). The centre
error is then expressed in reference units relative to the scene extent, so
it reads the same whatever unit COLMAP picked.

Two fits are offered. ``centres`` is the classic Umeyama fit to the camera
centres alone (ATE style). Its rotation is poorly determined when the
centres lie near a line or a short arc (a walk along one wall, the tiny test
scene), and that error then shows up as a constant rotation error in every
frame. ``poses`` (the default) fits the rotation to the centres and the
camera orientations together, each term normalised so that neither
dominates, and the scale and translation to the centres given that rotation.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import numpy as np
import pycolmap

from stages.scene import InputError, frame_id_of

from .conventions import axis_misalignment_deg, rotation_angle_deg
from .frame_matching import match_frames
from .pose_sources import PoseEntry, read_pose_set


def scene_extent(truth_path: Path, truth_centres: np.ndarray, extent: float | None) -> tuple[float, str]:
    """Length that centre errors are divided by: the longest side of the reference scene box."""
    if extent is not None:
        return float(extent), "given"
    scene_json = Path(truth_path).parent / "scene.json"
    if scene_json.is_file():
        box = json.loads(scene_json.read_text()).get("scene_box")
        if box is not None:
            box = np.asarray(box, dtype=np.float64)
            return float(np.max(box[1] - box[0])), f"longest side of scene_box in {scene_json}"
    span = truth_centres.max(0) - truth_centres.min(0)
    return float(np.max(span)), "longest side of the box around the reference camera centres (no scene.json)"


def _stats(values: np.ndarray) -> dict[str, float]:
    return {"mean": float(np.mean(values)), "median": float(np.median(values)), "max": float(np.max(values))}


def similarity_from_centres(src: np.ndarray, tgt: np.ndarray) -> np.ndarray | None:
    """4x4 similarity ``tgt ~ S @ src`` fitted to points (Umeyama, via pycolmap); None when degenerate."""
    sim = pycolmap.estimate_sim3d(src=np.asarray(src, np.float64), tgt=np.asarray(tgt, np.float64))
    if sim is None:
        return None
    out = np.eye(4)
    out[:3, :3] = float(sim.scale) * np.asarray(sim.rotation.matrix())
    out[:3, 3] = np.asarray(sim.translation)
    return out


def similarity_from_poses(src: np.ndarray, tgt: np.ndarray) -> np.ndarray | None:
    """4x4 similarity mapping the world of camera-to-world poses ``src`` [N,4,4] onto that of ``tgt``.

    The rotation maximises ``trace(R^T M)`` with ``M`` the sum of two
    cross-covariances, each normalised to unit size: orientations
    (``sum R_tgt R_src^T / N``) and centred camera centres (divided by their
    RMS spread); solved with an SVD as in Umeyama's method. Scale and
    translation then follow from the centres by least squares.
    """
    src, tgt = np.asarray(src, np.float64), np.asarray(tgt, np.float64)
    cs, ct = src[:, :3, 3], tgt[:, :3, 3]
    ds, dt = cs - cs.mean(0), ct - ct.mean(0)
    spread_s, spread_t = np.sqrt((ds**2).sum(1).mean()), np.sqrt((dt**2).sum(1).mean())
    if spread_s < 1e-12 or spread_t < 1e-12:
        return None
    m = np.einsum("nij,nkj->ik", tgt[:, :3, :3], src[:, :3, :3]) / len(src)
    m += dt.T @ ds / (len(src) * spread_s * spread_t)
    u, _, vt = np.linalg.svd(m)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rot = u @ d @ vt
    scale = float(np.sum(dt * (ds @ rot.T)) / np.sum(ds**2))
    if scale <= 0:
        return None
    out = np.eye(4)
    out[:3, :3] = scale * rot
    out[:3, 3] = ct.mean(0) - scale * rot @ cs.mean(0)
    return out


def compare_poses(pred_path: Path, truth_path: Path, extent: float | None = None,
                  align: str = "poses", match: str = "id") -> dict[str, Any]:
    """Errors of ``pred_path`` poses against ``truth_path`` poses.

    Either side is a transforms.json or a COLMAP model folder. ``align``: ``poses`` (centres and
    orientations) or ``centres`` (Umeyama on centres only). ``match``: ``id`` pairs frames by name
    (frame id, image stem or image path, whichever pairs most), ``order`` by position.
    """
    pred_set, truth_set = read_pose_set(pred_path), read_pose_set(truth_path)
    matched = match_frames(pred_set, truth_set, match)
    pred_m = np.array([p.c2w for p, _ in matched.pairs])
    truth_m = np.array([t.c2w for _, t in matched.pairs])
    pred_c, truth_c = pred_m[:, :3, 3], truth_m[:, :3, 3]
    if align == "centres":
        sim3 = similarity_from_centres(truth_c, pred_c)
    elif align == "poses":
        sim3 = similarity_from_poses(truth_m, pred_m)
    else:
        raise ValueError(f"unknown alignment {align!r}; use 'poses' or 'centres'")
    if sim3 is None:
        if min(np.ptp(pred_c, axis=0).max(), np.ptp(truth_c, axis=0).max()) < 1e-12:
            raise InputError(pred_path, "no similarity aligns the camera centres (degenerate configuration)",
                             "check that the cameras move (centres must not coincide)")
        # both sets move, yet no rotation with a positive scale maps one onto the other: a mirror image
        raise InputError(pred_path, f"no similarity aligns the camera centres with {truth_set.path}: the cameras "
                         "move in both, so one world is probably the mirror image of the other (a handedness flip)",
                         "check both files' conventions (a transforms.json holds OpenGL camera-to-world matrices, a "
                         "COLMAP model world-to-camera ones with OpenCV axes) and that no axis was negated")
    scale = float(np.cbrt(np.linalg.det(sim3[:3, :3])))
    rot = sim3[:3, :3] / scale
    aligned = truth_c @ sim3[:3, :3].T + sim3[:3, 3]
    extent_value, extent_source = scene_extent(truth_set.path, truth_c, extent)
    centre_err = np.linalg.norm(pred_c - aligned, axis=1) / scale  # in reference units
    centre_rel = centre_err / extent_value
    rot_err = np.array([rotation_angle_deg(p[:3, :3], rot @ t[:3, :3]) for p, t in zip(pred_m, truth_m, strict=True)])

    cam_pred, cam_truth = pred_set.camera, truth_set.camera
    size_ratio = cam_truth.width / cam_pred.width  # frames may have been extracted downscaled
    fx, fy = cam_pred.fx * size_ratio, cam_pred.fy * size_ratio
    pred_ids = [frame_label(p) for p, _ in matched.pairs]
    truth_ids = [frame_label(t) for _, t in matched.pairs]
    return {
        "pred": str(pred_path),
        "truth": str(truth_path),
        "matched_by": matched.matched_by,
        "match_counts": matched.counts,
        "n_matched": len(matched.pairs),
        "n_truth_frames": len(truth_set.entries),
        "n_pred_frames": len(pred_set.entries),
        "truth_frames_missing_in_pred": [frame_label(t) for t in matched.unmatched_truth],
        "alignment": align,
        "sim3": sim3.tolist(),
        "sim3_note": "maps reference (truth) world coordinates to predicted world coordinates: x_pred = sim3 @ x_truth",
        "scale": scale,
        "axes_misalignment_deg": axis_misalignment_deg(rot),
        "axes_note": "angle between the two worlds' axes up to relabelling and sign (0 = axis-aligned alike)",
        "scene_extent": extent_value,
        "scene_extent_source": extent_source,
        "centre_error_relative": _stats(centre_rel),
        "centre_error_truth_units": _stats(centre_err),
        "rotation_error_deg": _stats(rot_err),
        "focal_error": {
            "pred_fx_at_truth_size": fx, "pred_fy_at_truth_size": fy,
            "truth_fx": cam_truth.fx, "truth_fy": cam_truth.fy,
            "relative_fx": abs(fx - cam_truth.fx) / cam_truth.fx,
            "relative_fy": abs(fy - cam_truth.fy) / cam_truth.fy,
        },
        "per_frame": [{"frame": f, **({"truth_frame": tf} if tf != f else {}),
                       "centre_error_relative": float(c), "rotation_error_deg": float(r)}
                      for f, tf, c, r in zip(pred_ids, truth_ids, centre_rel, rot_err, strict=True)],
    }


def frame_label(entry: PoseEntry) -> str:
    """A frame's name in the report: its frame id (last ``_`` token of the stem), as before matching by name."""
    return frame_id_of(Path(entry.file_path).stem) if entry.file_path else entry.label


def summary_lines(report: dict[str, Any]) -> list[str]:
    c, r, f = report["centre_error_relative"], report["rotation_error_deg"], report["focal_error"]
    return [
        f"frames matched: {report['n_matched']} of {report['n_truth_frames']} reference frames "
        f"(by {report['matched_by']})",
        f"camera centre error / scene extent ({report['scene_extent']:.3g}): mean {c['mean']:.3%}, "
        f"median {c['median']:.3%}, max {c['max']:.3%}",
        f"rotation error (deg): mean {r['mean']:.3f}, median {r['median']:.3f}, max {r['max']:.3f}",
        f"focal length error: fx {f['relative_fx']:.2%}, fy {f['relative_fy']:.2%} "
        f"(pred {f['pred_fx_at_truth_size']:.1f} vs truth {f['truth_fx']:.1f} px)",
        f"world axes against the reference's (up to relabelling and sign): {report['axes_misalignment_deg']:.2f} deg",
    ]
