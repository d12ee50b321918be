"""Issue 18 done-when for export and videos, measured on the demo capture; prints the numbers (docs/export.md).

1. ``livescene export`` of a trained demo run at OBJECT = 0 and OBJECT = 1 (other objects closed), with the
   object parts: seconds per state and in all;
2. the two scene meshes compared in the capture's truth world (the dataset's world mapped by the inverse of
   pose_error.json's ``sim3`` when the dataset has estimated poses): Chamfer distance of the vertices outside
   the object's truth box (its parts' boxes swept over states 0..1, grown by ``--margin``), as a fraction of
   the scene extent (target <= 1 %), and inside it (where the change should be); for a drawer, how far the
   front of its exported part moved along the truth motion (truth: the drawer's travel); the scene vertices'
   median distance to the truth surfaces (the run's depth accuracy, not the fusion's);
3. a ``--seconds`` x ``--fps`` video of a state sweep of OBJECT at 256x192 (``livescene render
   --states-sweep``): render seconds and frames per second (goal <= 60 s, which needs >= 1 fps).

The load average is printed before and after: on the shared 2-core machine the times are pessimistic.

    .venv/bin/python benchmarks/export_and_video.py --run results/demo/runs/livescene \\
        [--data results/demo/dataset] [--capture results/demo/capture] [--object drawer] [--work /tmp/export_bench]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)
from stage_bench import peak_rss_mib

ROOT = Path(__file__).resolve().parents[1]


class Truth:
    """The capture's truth geometry: an object's swept box, the scene extent, distances to the truth surfaces."""

    def __init__(self, capture: Path, obj: str) -> None:
        from stages.capture import TruthRenderer

        renderer = TruthRenderer.from_capture(capture)
        self.model, self.scale = renderer.model, renderer.scale
        self.k = renderer.objects.index(obj)
        pts = [self.mesh(self.states(s), only_object=True)[0] for s in np.linspace(0, 1, 21)]
        p = np.concatenate(pts)
        self.box = np.stack([p.min(0), p.max(0)])
        box = json.loads((capture / "truth" / "scene.json").read_text())["scene_box"]
        self.extent = float(np.max(np.subtract(box[1], box[0])))

    def states(self, value: float) -> np.ndarray:
        out = np.zeros(len(self.model.joints))
        out[self.k] = value
        return out

    def mesh(self, states: np.ndarray, only_object: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Vertices (truth units) and triangles of every box, or of the object's boxes only."""
        verts, tris = self.model.mesh(self.model.part_poses(states))
        if only_object:
            keep = np.flatnonzero(self.model.part_object == self.k + 1)
            verts = verts.reshape(-1, 8, 3)[keep].reshape(-1, 3)
            tris = (tris.reshape(-1, 12, 3)[keep] - (8 * keep)[:, None, None]
                    + (8 * np.arange(len(keep)))[:, None, None]).reshape(-1, 3)
        return verts * self.scale, tris

    def travel(self) -> tuple[np.ndarray | None, float]:
        """Unit direction (truth world) and length of a prismatic object's travel from state 0 to 1; (None, 0) else."""
        joint = self.model.joints[self.k]
        if joint.kind != "prismatic":
            return None, 0.0
        d = self.model.object_frames[self.k][:3, :3] @ joint.axis
        return d / np.linalg.norm(d), abs(joint.limits[1] - joint.limits[0]) * self.scale

    def distances(self, points: np.ndarray, states: np.ndarray, only_object: bool = False) -> np.ndarray:
        """Distance of each point to the truth surface at ``states`` (open3d ray-casting scene, exact)."""
        import open3d as o3d

        verts, tris = self.mesh(states, only_object)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(verts.astype(np.float32)), o3d.core.Tensor(tris.astype(np.uint32)))
        return scene.compute_distance(o3d.core.Tensor(np.asarray(points, dtype=np.float32))).numpy()


def world_to_truth(dataset: Path) -> np.ndarray:
    """Dataset world -> truth world: inverse of pose_error.json's sim3 next to the dataset, else the identity."""
    from stages.evaluate.truth_source import read_sim3

    pose_error = dataset.parent / "pose_error.json"
    if pose_error.is_file():
        return np.linalg.inv(read_sim3(pose_error))
    return np.eye(4)


def vertices(path: Path) -> np.ndarray:
    import open3d as o3d

    return np.asarray(o3d.io.read_triangle_mesh(str(path)).vertices)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", type=Path, default=ROOT / "results" / "demo" / "runs" / "livescene")
    p.add_argument("--data", type=Path, help="the run's dataset (default: from the run's config)")
    p.add_argument("--capture", type=Path, help="the demo capture (default: <dataset>/../capture)")
    p.add_argument("--object", default="drawer")
    p.add_argument("--margin", type=float, default=0.05, help="truth box growth, truth units (metres)")
    p.add_argument("--views", type=int, default=0, help="training poses per state (0 = the exporter's default)")
    p.add_argument("--scale", type=float, default=0.5)
    p.add_argument("--fps", type=float, default=12.0)
    p.add_argument("--seconds", type=float, default=5.0)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "livescene-export-bench")
    p.add_argument("--skip-video", action="store_true")
    args = p.parse_args()

    import torch

    from stages.export import ExportOptions, export_run
    from stages.export.geometry_compare import chamfer_distance, inside_box
    from stages.model import load_run
    from stages.model.render_cli import main as render_main
    from stages.model.run import dataset_of_run
    from stages.scene import read_scene

    torch.set_num_threads(args.threads)
    if not (args.run / "model.pt").is_file():
        raise SystemExit(f"{args.run}: no model.pt; train the demo first (`make run`, or `livescene train --data "
                         "results/demo/dataset --out results/demo/runs/livescene`) or pass --run")
    load = {"before": os.getloadavg()}
    t = time.perf_counter()
    run = load_run(args.run)
    dataset_dir = dataset_of_run(args.run, args.data)
    ds = read_scene(dataset_dir, validate=False)
    load_s = time.perf_counter() - t
    capture = args.capture or dataset_dir.parent / "capture"
    truth = Truth(capture, args.object)
    box, extent = truth.box, truth.extent
    to_truth = world_to_truth(dataset_dir)

    args.work.mkdir(parents=True, exist_ok=True)
    out = args.work / "export"
    options = ExportOptions(objects=True, scale=args.scale, **({"views": args.views} if args.views else {}))
    combos = [{args.object: 0.0}, {args.object: 1.0}]
    t, cpu = time.perf_counter(), time.process_time()
    doc = export_run(run, ds, combos, out, options, run_info={"run": str(args.run)})
    export_s, export_cpu = time.perf_counter() - t, time.process_time() - cpu

    closed, opened = (out / r["folder"] for r in doc["exports"])
    a, b = vertices(closed / "scene_mesh.ply"), vertices(opened / "scene_mesh.ply")
    at, bt = (x @ to_truth[:3, :3].T + to_truth[:3, 3] for x in (a, b))
    unit = float(np.cbrt(abs(np.linalg.det(to_truth[:3, :3]))))  # dataset units -> truth units
    in_a, in_b = inside_box(at, box, margin=args.margin), inside_box(bt, box, margin=args.margin)
    static = chamfer_distance(at[~in_a], bt[~in_b])
    moving = chamfer_distance(at[in_a], bt[in_b])
    parts = [vertices(f / "objects" / f"{args.object}_mesh.ply") @ to_truth[:3, :3].T + to_truth[:3, 3]
             for f in (closed, opened)]
    empty = not all(len(x) for x in parts)  # an undertrained run's part may have no surface at a state
    part = {"vertices": [len(x) for x in parts],
            "chamfer_between_states": None if empty else round(chamfer_distance(*parts), 4)}
    direction, travel = truth.travel()
    if direction is not None and not empty:  # a drawer: where its front is, along the truth motion, closed and open
        front = [float(np.percentile(x @ direction, 95)) for x in parts]
        part.update({"truth_travel": round(travel, 4), "front_shift": round(front[1] - front[0], 4)})
    scene_accuracy = [round(float(np.median(truth.distances(x, truth.states(s)))), 4)
                      for x, s in ((at, 0.0), (bt, 1.0))]
    result = {
        "run": str(args.run), "dataset": str(dataset_dir), "object": args.object, "threads": args.threads,
        "load_run_s": round(load_s, 2),
        "export": {"views": doc["views"], "render_size": doc["render_size"], "voxel_dataset_units": doc["voxel"],
                   "voxel_truth_units": doc["voxel"] * unit,
                   "seconds_total": round(export_s, 1), "cpu_seconds_total": round(export_cpu, 1),
                   "seconds_per_state": [r["timings_s"]["total"] for r in doc["exports"]],
                   "timings_per_state": [r["timings_s"] for r in doc["exports"]],
                   "scene_vertices": [r["files"]["scene_mesh"]["vertices"] for r in doc["exports"]],
                   "part_vertices": [r["files"][f"objects/{args.object}_mesh"]["vertices"] for r in doc["exports"]],
                   "bytes": sum(f["bytes"] for r in doc["exports"] for f in r["files"].values())},
        "geometry": {"scene_extent": extent, "truth_box": box.tolist(), "margin": args.margin,
                     "static_chamfer": round(static, 4), "static_chamfer_over_extent": round(static / extent, 5),
                     "static_vertices": [int((~in_a).sum()), int((~in_b).sum())],
                     "inside_box_chamfer": round(moving, 4),
                     "scene_median_distance_to_truth": scene_accuracy,
                     "part": part},
    }
    shutil.copy(closed / "thumbnail.png", args.work / "thumbnail_closed.png")
    shutil.copy(opened / "thumbnail.png", args.work / "thumbnail_open.png")

    if not args.skip_video:
        video = args.work / "sweep.mp4"
        shutil.rmtree(args.work / "sweep_frames", ignore_errors=True)  # time a full render, not a resume
        t, cpu = time.perf_counter(), time.process_time()
        code = render_main(["--run", str(args.run), "--states-sweep", args.object, "--width", "256", "--height", "192",
                            "--fps", str(args.fps), "--seconds", str(args.seconds), "--out", str(video),
                            "--threads", str(args.threads), *(["--data", str(args.data)] if args.data else [])])
        wall, video_cpu = time.perf_counter() - t, time.process_time() - cpu
        n = round(args.fps * args.seconds)
        result["video"] = {"exit": code, "frames": n, "size": [256, 192], "seconds_wall": round(wall, 1),
                           "cpu_seconds": round(video_cpu, 1), "fps_rendered": round(n / wall, 3),
                           "video_bytes": video.stat().st_size if code == 0 else 0}
    load["after"] = os.getloadavg()
    result["loadavg"] = {k: [round(x, 2) for x in v] for k, v in load.items()}
    # this process's max RSS: the export, the video and the truth geometry they are compared with (and the
    # capture's rendering when it was not cached)
    result["peak_rss_mib"] = round(peak_rss_mib(), 1)
    (args.work / "result.json").write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))
    g, e = result["geometry"], result["export"]
    print(f"\nexport: {e['seconds_total']} s for 2 states ({e['seconds_per_state']} s each; target <= 60 s; "
          f"{e['cpu_seconds_total']} CPU s), {e['views']} views at {e['render_size']}")
    print(f"static part Chamfer: {g['static_chamfer']} = {100 * g['static_chamfer_over_extent']:.2f} % of the "
          f"scene extent (target <= 1 %); inside the truth box {g['inside_box_chamfer']}")
    print(f"{args.object} part: {g['part']}; scene vertices' median distance to the truth surfaces "
          f"{g['scene_median_distance_to_truth']}")
    if "video" in result:
        v = result["video"]
        print(f"video: {v['frames']} frames 256x192 in {v['seconds_wall']} s ({v['fps_rendered']} fps; goal <= 60 s; "
              f"{v['cpu_seconds']} CPU s)")
    print(f"peak memory {result['peak_rss_mib']:.0f} MiB (process max RSS); load average before "
          f"{result['loadavg']['before']}, after {result['loadavg']['after']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
