"""Throughput of the poses stage (`livescene poses`: COLMAP through pycolmap) on the demo capture's frames (or
``--capture``'s).

The capture is rendered and its frames extracted once into ``--work`` (child processes); then this process runs
``estimate_poses`` ``--repeats`` times as the workflow does (one thread, seed 0, the capture's masks, auto
matcher, default features), writing a fresh POSES folder each time. The stage times its own steps
(poses.json ``timings``), and those are what is printed, median over the repeats:

- ``precheck``: the still-camera check on cheap feature tracks, before COLMAP;
- ``masks``: the object masks turned into COLMAP masks;
- ``extract``: SIFT feature extraction (pycolmap ``extract_features``);
- ``match``: matching with two-view verification;
- ``map``: incremental mapping (all models);
- ``export``: world frame, transforms.json, sparse model, point cloud, scene box;
- ``other``: what the stage does not time apart: reading the frame list, the feature-motion check between
  matching and mapping, the registration and camera-path gates (``total`` less the steps above);
- ``total``: the whole call.

Each row gives seconds, images per call, ms per image, images/s and the 1-minute load average before and after
the repeats (the same for every row: one call times them all). ``--parallel`` runs COLMAP on ``--threads``
(results then vary run to run, docs/poses.md "Repeatability"). A run is in docs/poses.md, "Benchmark (poses)"::

    .venv/bin/python benchmarks/poses_throughput.py
    .venv/bin/python benchmarks/poses_throughput.py --capture config/captures/tiny.yaml --repeats 1  # smoke
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics

import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)
from stage_bench import (
    Row,
    add_input_arguments,
    capture_folder,
    check_repeats,
    frames_folder,
    load_span,
    print_table,
    work_folder,
)

from stages.scene.machine import contention

STEPS = ("precheck", "masks", "extract", "match", "map", "export", "total")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_input_arguments(p, repeats=2)
    p.add_argument("--threads", type=int, default=1, help="COLMAP threads with --parallel (the workflow passes 1)")
    p.add_argument("--parallel", action="store_true", help="run extraction, matching and mapping on --threads")
    p.add_argument("--no-masks", action="store_true", help="without the capture's object masks")
    args = p.parse_args()
    check_repeats(p, args)
    import pycolmap

    from stages.poses import PosesConfig, estimate_poses

    work = work_folder(args)
    frames = frames_folder(work, args.capture)
    masks = None if args.no_masks else capture_folder(work, args.capture) / "masks"
    out = work / "poses-bench"
    cfg = PosesConfig(frames_dir=frames, out_dir=out, masks_dir=masks, threads=args.threads,
                      deterministic=not args.parallel, progress=False)
    before = contention()
    load0 = os.getloadavg()[0]
    summaries = [estimate_poses(cfg) for _ in range(args.repeats)]
    load = load_span(load0)
    shutil.rmtree(out, ignore_errors=True)
    n = summaries[0]["n_frames"]
    rows = [Row(step, [s["timings"][step] for s in summaries], n, "image", load)
            for step in STEPS if all(step in s["timings"] for s in summaries)]
    other = [s["timings"]["total"] - sum(v for k, v in s["timings"].items() if k != "total") for s in summaries]
    rows.insert(-1, Row("other (untimed: frame list, motion check, gates)", other, n, "image", load))
    registered = statistics.median(s["n_registered"] for s in summaries)
    print_table(f"poses: {frames} ({n} images, {registered:g} registered, matcher {summaries[0]['matcher']}, "
                f"{'masks' if masks else 'no masks'}, {args.threads if args.parallel else 1} COLMAP thread(s), "
                f"pycolmap {pycolmap.__version__})", rows, before, args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
