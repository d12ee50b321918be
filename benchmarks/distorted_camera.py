"""A lens-distorted dataset against its pinhole twin, trained and exported; prints the numbers (docs/data-contract.md,
"Lens distortion").

Both datasets are rendered by a capture's truth renderer at the same poses and states: once through the capture's
pinhole camera, once through the same camera with ``--k1``/``--k2`` (the renderer casts each pixel's ray through
``stages.scene.generate_rays``, which undoes the distortion, so the images are exactly those of the distorted
camera, not a resampling of the pinhole ones; their corners see more of the room). Then:

1. LiveScene (cpu-demo preset, ``--steps``, seed 0) on each dataset; held-out PSNR of the full test images rendered
   at each dataset's own camera (``stages.compare.method_comparison.score_run``), and the distorted run rendered
   through the *pinhole* camera against the pinhole dataset's test images: the room it learned, undistorted;
2. the controls: the distorted images trained as if the camera were a pinhole (coefficients dropped, what a reader
   that ignores them would do), and the pinhole dataset trained with seed 1 (the noise floor of every number);
3. ``livescene export`` of each run (all objects closed, every training view at twice the images' size): Chamfer
   distance of each run's scene points to the pinhole run's, and the median distance of its mesh vertices to the
   truth surfaces.

The load average is printed before and after: on the shared 2-core machine the times are pessimistic.

    .venv/bin/python benchmarks/distorted_camera.py [--work /tmp/distorted_bench] [--steps 500]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)

ROOT = Path(__file__).resolve().parents[1]


def livescene(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "stages.cli", *args], cwd=ROOT, check=True)


def render_dataset(source: Path, capture: Path, camera, out: Path) -> None:
    """``source``'s frames (poses, states, split) rendered by the capture's truth renderer through ``camera``:
    images, one-hot masks from the rendered object ids, and ``camera`` as the dataset's intrinsics."""
    from stages.capture import TruthRenderer
    from stages.scene import label_map_to_onehot, read_scene, write_mask, write_scene

    ds = read_scene(source)
    renderer = TruthRenderer.from_capture(capture)
    channel = np.full(256, -1, dtype=np.int64)  # rendered id -> mask channel (0 and unknown: background)
    for c, k in enumerate(ds.object_ids):
        channel[k] = c
    (out / "images").mkdir(parents=True)
    for frame in ds.frames:
        r = renderer.render(frame.c2w, frame.state, camera=camera)
        bgr = np.clip(r["rgb"][..., ::-1] * 255.0 + 0.5, 0, 255).astype(np.uint8)
        cv2.imwrite(str(out / frame.file_path), bgr)
        write_mask(out, frame.frame_id, label_map_to_onehot(channel[r["ids"]], ds.n_objects))
    write_scene(dataclasses.replace(ds, root=out, camera=camera), out)
    read_scene(out, validate=True, deep=True)


def held_out_at(run_dir: Path, images: Path, camera) -> float:
    """Mean PSNR of ``run_dir`` rendered through ``camera`` at the test frames of the dataset ``images``."""
    from stages.evaluate.metrics import psnr
    from stages.model import load_run
    from stages.scene import read_scene

    ds = read_scene(images)
    run = load_run(run_dir)
    scores = []
    for f in ds.frames_in("test"):
        out = run.render(camera, f.c2w, None, frame_index=ds.frames.index(f), outputs=("rgb",))
        scores.append(psnr(out["rgb"], ds.load_image(f)))
    return float(np.mean(scores))


def export_points(run_dir: Path, out: Path) -> tuple[np.ndarray, np.ndarray]:
    """(scene points, scene mesh vertices) of ``livescene export`` at its default state (all objects closed)."""
    import open3d as o3d

    # every training view at twice the tiny capture's size: at 48x36 its parts came out fragmentary (docs/export.md)
    livescene(
        "export",
        "--run",
        str(run_dir),
        "--out",
        str(out),
        "--views",
        "0",
        "--scale",
        "2",
        "--threads",
        "2",
        "--no-progress",
    )
    record = json.loads((out / "export.json").read_text())["exports"][0]
    files = {k: out / v["path"] for k, v in record["files"].items()}
    points = np.asarray(o3d.io.read_point_cloud(str(files["scene_points"])).points)
    vertices = np.asarray(o3d.io.read_triangle_mesh(str(files["scene_mesh"])).vertices)
    return points, vertices


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--spec", type=Path, default=ROOT / "config" / "captures" / "tiny.yaml")
    p.add_argument("--k1", type=float, default=-0.1)
    p.add_argument("--k2", type=float, default=0.02)
    p.add_argument("--steps", type=int, default=500)
    p.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "livescene-distorted-bench")
    p.add_argument("--skip-control", action="store_true", help="leave out the run that drops the coefficients")
    args = p.parse_args()

    from export_and_video import Truth

    from stages.compare.method_comparison import score_run
    from stages.export.geometry_compare import chamfer_distance
    from stages.scene import read_scene, write_scene

    load = {"before": os.getloadavg()}
    t0 = time.perf_counter()
    work = args.work
    capture, source = work / "capture", work / "source"
    if not (capture / "capture.json").is_file():
        livescene("capture", "--spec", str(args.spec), "--out", str(capture), "--no-progress")
    if not (source / "transforms.json").is_file():
        livescene(
            "capture", "dataset", "--capture", str(capture), "--out", str(source), "--images", "truth", "--no-progress"
        )
    pinhole = read_scene(source).camera
    lens = dataclasses.replace(pinhole, distortion={"k1": args.k1, "k2": args.k2})
    flat = dataclasses.replace(lens, distortion={})  # the distorted images read as a pinhole
    datasets = {"pinhole": (pinhole, "pinhole"), "distorted": (lens, "distorted"), "as_pinhole": (flat, "distorted")}
    if args.skip_control:
        del datasets["as_pinhole"]
    for name, (camera, images) in datasets.items():
        folder = work / f"ds_{name}"
        if (folder / "transforms.json").is_file():
            continue
        if images == name:
            render_dataset(source, capture, camera, folder)
        else:  # the same images and masks, the camera's coefficients left out
            ds = read_scene(work / f"ds_{images}")
            folder.mkdir()
            for sub in ("images", "masks"):
                (folder / sub).symlink_to(ds.root.resolve() / sub)
            write_scene(dataclasses.replace(ds, root=folder, camera=camera), folder)
    r = np.hypot(pinhole.width / 2 / pinhole.fx, pinhole.height / 2 / pinhole.fy)
    print(
        f"camera {pinhole.width}x{pinhole.height}, fx {pinhole.fx:.2f}; k1 {args.k1}, k2 {args.k2}: the corner "
        f"({r:.3f} focal lengths out) moves by {abs(args.k1 * r**3 + args.k2 * r**5) * pinhole.fx:.2f} px"
    )

    truth = Truth(capture, read_scene(source).objects[0])
    # run name -> (dataset, seed); the second pinhole seed is the noise floor of every number
    runs = {name: (name, 0) for name in datasets} | {"pinhole_seed1": ("pinhole", 1)}
    rows: dict[str, dict[str, float]] = {}
    points: dict[str, np.ndarray] = {}
    for name, (data, seed) in runs.items():
        run = work / f"run_{name}"
        if not (run / "model.pt").is_file():
            t = time.perf_counter()
            livescene("train", "--data", str(work / f"ds_{data}"), "--out", str(run), "--max-steps", str(args.steps),
                      "--seed", str(seed), "--no-progress")  # fmt: skip
            print(f"{name}: trained {args.steps} steps in {time.perf_counter() - t:.0f} s")
        own = score_run(run, work / f"ds_{data}", eval_frames=1000)
        rows[name] = {
            "held_out_psnr_own_camera": own["psnr"],
            "held_out_psnr_through_pinhole_vs_pinhole_images": held_out_at(run, work / "ds_pinhole", pinhole),
        }
        points[name], verts = export_points(run, work / f"export_{name}")
        rows[name]["mesh_to_truth_median"] = float(np.median(truth.distances(verts, np.zeros(len(truth.model.joints)))))
    for name in runs:
        rows[name]["chamfer_to_pinhole_run"] = chamfer_distance(points[name], points["pinhole"])
    load["after"] = os.getloadavg()
    extent = truth.extent
    print(f"scene extent {extent:.2f} (truth units); {args.steps} steps each")
    print(
        "| dataset | held-out PSNR, own camera | distorted run through the pinhole vs pinhole images | "
        "scene points' Chamfer to the pinhole run's | mesh vertices to truth, median |"
    )
    print("|---|---|---|---|---|")
    for name, row in rows.items():
        print(
            f"| {name} | {row['held_out_psnr_own_camera']:.2f} dB | "
            f"{row['held_out_psnr_through_pinhole_vs_pinhole_images']:.2f} dB | "
            f"{row['chamfer_to_pinhole_run']:.4f} ({100 * row['chamfer_to_pinhole_run'] / extent:.2f} % of extent) | "
            f"{row['mesh_to_truth_median']:.4f} |"
        )
    print(json.dumps({"rows": rows, "load": load, "wall_s": round(time.perf_counter() - t0, 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
