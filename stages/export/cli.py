"""``livescene export``: a coloured mesh and point cloud of the room at chosen object states (docs/export.md).

    livescene export --run RUN --states "cabinet=1,drawer=0" [--states "cabinet=0"] --format ply|obj|glb \\
                     --out DIR [--objects]
"""

from __future__ import annotations

import argparse
import json

from stages.scene.cli_errors import cli_errors

from .exporter import ExportOptions, export_run
from .mesh_io import FORMATS
from .state_spec import parse_state_string


def build_parser(prog: str = "livescene export") -> argparse.ArgumentParser:
    d = ExportOptions()
    p = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True, help="run folder written by `livescene train`")
    p.add_argument("--states", action="append", default=[], metavar='"OBJ=V,OBJ=V"',
                   help="one state combination (repeatable); objects not named are closed (0); "
                        "default: one export with every object closed")
    p.add_argument("--format", default=d.fmt, choices=FORMATS, help="mesh and point-cloud format (default ply)")
    p.add_argument("--out", required=True, help="folder to write (replaced atomically): one subfolder per "
                   "combination with scene_mesh, scene_points, thumbnail.png; export.json")
    p.add_argument("--objects", action="store_true",
                   help="also export each object's part (pixels of high rendered object probability)")
    p.add_argument("--data", help="the run's dataset (default: the one in the run's config)")
    p.add_argument("--views", type=int, default=d.views,
                   help="training poses rendered per state, evenly spread (default 16; 0 = all)")
    p.add_argument("--scale", type=float, default=d.scale, help="render size relative to the dataset images")
    p.add_argument("--resolution", type=int, default=d.resolution,
                   help="TSDF voxels along the scene box's longest side")
    p.add_argument("--prob-threshold", type=float, default=d.prob_threshold,
                   help="object pixels: rendered probability at least this (--objects)")
    p.add_argument("--device", default="cpu", help="cpu | cuda")
    p.add_argument("--threads", type=int, default=0, help="torch CPU threads (0 = torch's default)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    return p


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    import torch  # after argument parsing: --help stays fast

    from stages.model import load_run
    from stages.model.run import dataset_of_run
    from stages.scene import read_scene

    if args.threads > 0:
        torch.set_num_threads(args.threads)
    options = ExportOptions(fmt=args.format, objects=args.objects, views=args.views, scale=args.scale,
                            resolution=args.resolution, prob_threshold=args.prob_threshold)
    options.check()
    run = load_run(args.run, device=args.device)
    combos = [parse_state_string(s, run.objects) for s in args.states]
    run.warn_if_states_unread([name for combo in combos for name in combo])
    dataset = read_scene(dataset_of_run(args.run, args.data), validate=False)
    run.check_dataset(dataset)
    doc = export_run(run, dataset, combos, args.out, options, progress=not args.no_progress,
                     run_info={"run": str(args.run), "method": run.method, "step": run.step})
    empty = [r["states"] for r in doc["exports"] if r["files"]["scene_mesh"]["vertices"] == 0]
    if empty:  # nothing above the density threshold: what a run of too few steps gives
        import warnings

        warnings.warn(f"{args.out}: the scene mesh is empty at {len(empty)} of {len(doc['exports'])} state "
                      f"combinations (e.g. {empty[0]}): no surface that two views agree on is dense enough to mesh. "
                      f"Causes: a run of too few steps (this one: {run.step}; the workflow trains 1500), a "
                      f"--resolution too fine for the renders (now {args.resolution} voxels at --scale {args.scale}: "
                      "a voxel smaller than a pixel's footprint is seen by too few views), or a --data that is not "
                      "the run's dataset; fix: train it longer, or lower --resolution / raise --scale",
                      stacklevel=2)
    summary = {"out": args.out, "total_seconds": doc["total_seconds"],
               "exports": [{"states": r["states"], "scene_vertices": r["files"]["scene_mesh"]["vertices"],
                            "seconds": r["timings_s"]["total"]} for r in doc["exports"]]}
    print(json.dumps(summary))
    return 0
