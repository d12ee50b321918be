"""Helpers of the report tests: fake but complete stage outputs of one scene, and the report inputs manifest
that names them (Chromium is in tests/chromium_page.py)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[2]
ARTIFACTS = REPO / "test-artifacts" / "report"


def _png(path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), rgb[..., ::-1])


def fake_inputs(res: Path, data: Path, methods: tuple[str, ...] = ("livescene", "conerf")) -> dict[str, Any]:
    """The report inputs manifest of a make_fake_results tree (runs named by their run.json, as the workflow
    does)."""
    return {"dataset": str(data), "poses": str(res / "poses"), "pose_error": str(res / "pose_error.json"),
            "states": str(res / "states"), "benchmarks": str(res / "benchmarks"),
            "runs": {m: str(res / "runs" / m / "run.json") for m in methods},
            "eval": {m: str(res / "eval" / m) for m in methods},
            "sweep": {methods[0]: str(res / "sweep" / methods[0])},
            "control": {methods[0]: str(res / "control" / methods[0])}}


def write_inputs(path: Path, manifest: dict[str, Any]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(manifest, indent=1))
    return path


def make_fake_results(root: Path, data: Path, *, methods: tuple[str, ...] = ("livescene", "conerf"),
                      objects: tuple[str, ...] = ("object0", "object1", "object2")) -> Path:
    """One folder of stage outputs (same file names and keys as the stages write), with synthetic numbers and
    images; fake_inputs names its parts."""
    rng = np.random.default_rng(1)
    res = root / "fake"
    bench = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
    for name, s in [("capture", 3.1), ("poses", 12.5), ("train_livescene", 150.2), ("train_conerf", 151.0),
                    ("evaluate_livescene", 40.0)]:
        (res / "benchmarks").mkdir(parents=True, exist_ok=True)
        (res / "benchmarks" / f"{name}.tsv").write_text(bench + f"{s}\t0:00:{int(s) % 60:02d}\t300.5\t900\t280\t"
                                                          f"290\t1\t2\t0.9\t{s * 0.9}\n")
    (res / "poses").mkdir(parents=True)
    (res / "poses" / "poses.json").write_text(json.dumps({
        "n_frames": 6, "n_registered": 6, "registered_fraction": 1.0, "mean_reprojection_error": 0.41,
        "n_points3D": 197, "matcher": "exhaustive", "timings": {"total": 3.6}}))
    (res / "pose_error.json").write_text(json.dumps({
        "n_matched": 6, "scale": 5.5, "centre_error_relative": {"mean": 0.007, "median": 0.008, "max": 0.015},
        "rotation_error_deg": {"mean": 1.4, "median": 1.4, "max": 1.9},
        "focal_error": {"relative_fx": 0.09, "relative_fy": 0.09}}))
    (res / "states").mkdir()
    (res / "states" / "states.json").write_text(json.dumps({
        "methods": {"object0": "pchip"},
        "leave_one_out": {"object0": {"linear": {"mae": 0.2, "max": 0.4, "n": 5},
                                      "pchip": {"mae": 0.1, "max": 0.3, "n": 5}}}}))
    from stages.scene import read_scene

    ds = read_scene(data)
    test_ids = [f.frame_id for f in ds.frames_in("test")]
    for k, m in enumerate(methods):
        run = res / "runs" / m
        run.mkdir(parents=True)
        (run / "run.json").write_text(json.dumps({"method": m, "status": "completed", "train_seconds": 150.0,
                                                  "steps": 400 + k, "eval_psnr": 20.0 + k, "peak_memory_mib": 800.0,
                                                  "params": {"total": 1_000_000 + k},
                                                  "machine": {"cpu": "Test CPU @ 2.50GHz", "logical_cores": 2,
                                                              "torch": "2.13.0", "torch_cpu_capability": "AVX2"}}))
        # the first method's config carries trust floors it passes; the others' have no trust section (an older
        # run), so the TrustConfig defaults apply and flag their 400 steps as undertrained
        config = {"method": m, "seed": 0}
        if k == 0:
            config["trust"] = {"min_steps": 100, "min_psnr": 15.0, "min_grounding_miou": 0.3}
        (run / "config.yaml").write_text(yaml.safe_dump(config))
        rows = ["wall_s,step,loss,eval_psnr"] + [f"{10 * i:.1f},{i * 50},{0.3 / (i + 1):.4f},"
                                                 f"{12 + i + k:.2f}" for i in range(8)]
        (run / "train_log.csv").write_text("\n".join(rows) + "\n")
        ev = res / "eval" / m
        views = []
        for i, fid in enumerate(test_ids):
            _png(ev / "renders" / f"{fid}.png", rng.integers(0, 255, (ds.camera.height, ds.camera.width, 3),
                                                             dtype=np.uint8))
            # every later method exactly 1 dB better on every view: LiveScene (first) is behind
            views.append({"frame": fid, "file_path": f"images/frame_{fid}.png", "psnr": 20.0 + k + 0.5 * i,
                          "ssim": 0.7})
        queries = []
        for j, obj in enumerate(objects):
            _png(ev / "grounding" / f"probs_{obj}_{test_ids[0]}.png",
                 np.repeat(rng.integers(0, 255, (ds.camera.height, ds.camera.width, 1), dtype=np.uint8), 3, -1))
            # per-view IoUs that differ between methods in both directions: no measurable difference
            ious = [0.5 + 0.1 * ((i + j + k) % 3 - 1) for i in range(len(test_ids))]
            queries.append({"query": obj, "object": obj, "kind": "name",
                            "probs": {"iou": {"mean": float(np.mean(ious))}, "per_view": ious, "frames": test_ids}})
        records = []
        for i, fid in enumerate(test_ids[:2]):
            for c, states in enumerate([{"object0": 0.0, "object1": 1.0, "object2": 0.0},
                                        {"object0": 1.0, "object1": 0.0, "object2": 0.5}]):
                # LiveScene about 2 dB above the others on every unseen render: ahead
                psnr = 18.0 - 2.0 * min(k, 1) + 0.3 * (i + c) + (0.2 if (i + c + k) % 2 else -0.2)
                records.append({"frame": fid, "combination": c, "states": states, "unseen": True, "rendered": True,
                                "psnr": psnr})
            records.append({"frame": fid, "combination": 2, "states": {"object0": 0.5, "object1": 0.5,
                                                                      "object2": 0.5},
                            "unseen": False, "rendered": False, "psnr": None})
        if k:  # a render the first method lacks: unpaired, left out
            records.append({"frame": test_ids[-1], "combination": 0, "states": records[0]["states"], "unseen": True,
                            "rendered": True, "psnr": 5.0})
        metrics = {"held_out": {"views": views, "psnr": {"mean": 20.0 + k}, "ssim": {"mean": 0.7}, "lpips": None,
                                "lpips_status": "not available: torchvision is not installed"},
                   "unseen_combinations": {"status": "computed", "psnr": {"mean": 18.0}, "psnr_moved": {"mean": 15.0},
                                           "ssim": {"mean": 0.6}, "records": records,
                                           # 2 of 3 poses: the room's combinations were over the render budget
                                           "views": 2, "views_asked": 3, "max_renders": 4, "views_cut": True,
                                           "combinations": [{"unseen": True}, {"unseen": True}, {"unseen": False}],
                                           # object2 was never seen open: level 1 is left out of the test
                                           "observed_within": 0.125,
                                           "training_range": {"object0": [0.0, 1.0], "object1": [0.0, 1.0],
                                                              "object2": [0.0, 0.6]},
                                           "levels_not_observed": {"object2": [1.0]}},
                   "grounding": {"status": "computed", "threshold": 0.5, "sources": ["probs"], "queries": queries,
                                 "miou_probs": 0.5, "miou_probs_name": 0.5},
                   # the first method keeps its changes local; the others leak 3/255 onto the rest of the room
                   # fewer poses than asked because the test split is short: not the budget, no note
                   "locality": {"status": "computed", "outside_limit_x255": 1.0, "views": 2, "views_asked": 8,
                                "max_pairs": 40, "views_cut": False, "objects": {
                       obj: {"model_outside_x255": {"mean": 0.2 + 3.0 * min(k, 1), "n": 2},
                             "truth_outside_x255": {"mean": 0.5, "n": 2},
                             "model_inside_x255": {"mean": 30.0, "n": 2}, "truth_inside_x255": {"mean": 35.0, "n": 2},
                             "local": k == 0} for obj in ds.objects}}}
        (ev / "metrics.json").write_text(json.dumps(metrics))
        (ev / "timings.json").write_text(json.dumps({"held_out": {"render_seconds": 1.2, "views": len(test_ids),
                                                                  "fps": 2.5 + k}, "seconds": 3.0}))
    sweep = res / "sweep" / methods[0]
    entry = {}
    for obj in objects:
        files = []
        for i in range(3):  # visibly different images per state
            files.append(f"{obj}_{i:02d}.png")
            _png(sweep / files[-1], np.full((12, 16, 3), 40 + 80 * i, dtype=np.uint8))
        entry[obj] = {"values": [0.0, 0.5, 1.0], "images": files}
    (sweep / "sweep.json").write_text(json.dumps({"frame": test_ids[0], "objects": entry}))
    control = res / "control" / methods[0]
    _png(control / "command_00.png", np.full((12, 16, 3), 128, dtype=np.uint8))
    (control / "commands.json").write_text(json.dumps({"commands": [
        {"command": "open the object0", "states": {"object0": 1.0, "object1": 0.0},
         "beyond_training": {"object0": {"state": 1.0, "training_range": [0.01, 0.48]}},
         "image": str(control / "command_00.png")},
        {"command": "open the fridge", "error": "no object named 'fridge'"}]}))
    return res
