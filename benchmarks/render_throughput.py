"""Render throughput of a trained run on the demo capture's held-out views (issue 16: >= 1 fps at 256x192, 2 threads).

Trains LiveScene on the demo dataset for ``--steps`` (once, cached in ``--work``) unless ``--run`` names a
trained run, then renders ``--views`` held-out views at full size, twice each:

- ``rgb``: the fast path the evaluation uses for plain images (no probabilities, no language);
- ``all``: rgb, depth, accumulation, probabilities and the language embedding.

Prints seconds per view (median and best), fps, rays/s, the training rays/s of the same run (median of
its train_log.csv) and the ratio, the peak memory of the renders (this process's max RSS: the dataset is made
and the run trained in child processes; on CUDA also the allocator's peak) and the 1-minute load average
before and after::

    .venv/bin/python benchmarks/render_throughput.py --work /tmp/render_bench
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

from demo_dataset import DEMO_SPEC
from stage_bench import dataset_folder, peak_rss_mib, trained_run

from stages.scene.machine import machine_info


def training_rays_per_s(run: Path) -> float | None:
    with (run / "train_log.csv").open() as fh:
        values = [float(r["rays_per_s"]) for r in csv.DictReader(fh) if r.get("rays_per_s")]
    values = [v for v in values if v > 0]
    return statistics.median(values) if values else None


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "livescene-bench-demo")
    p.add_argument("--run", type=Path, help="a trained run folder (default: train one on the demo)")
    p.add_argument("--steps", type=int, default=2000, help="training steps of the run made here")
    p.add_argument("--views", type=int, default=4)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--device", default="cpu")
    args = p.parse_args()
    import torch

    from stages.model import load_run
    from stages.scene import read_scene

    torch.set_num_threads(args.threads)
    args.work.mkdir(parents=True, exist_ok=True)
    dataset = dataset_folder(args.work, DEMO_SPEC)  # made in a child process: not in this one's peak memory
    run_dir = args.run or trained_run(args.work, dataset, args.steps)
    run = load_run(run_dir, device=args.device)
    ds = read_scene(dataset)
    test = ds.frames_in("test")
    frames = [test[i * len(test) // args.views] for i in range(args.views)]
    if args.device.startswith("cuda"):
        torch.cuda.reset_peak_memory_stats()
    load0 = os.getloadavg()[0]
    results = {}
    for name, outputs in (("rgb", ("rgb",)), ("all", ("rgb", "depth", "accumulation", "probs", "language"))):
        run.render(ds.camera_of(frames[0]), frames[0].c2w, frames[0].state, outputs=outputs)  # warm-up
        times = []
        for _ in range(args.repeats):
            for f in frames:
                t0 = time.perf_counter()
                run.render(ds.camera_of(f), f.c2w, f.state, outputs=outputs)
                times.append(time.perf_counter() - t0)
        cam = ds.camera_of(frames[0])
        median = statistics.median(times)
        results[name] = {"seconds_median": round(median, 3), "seconds_best": round(min(times), 3),
                         "fps": round(1 / median, 2), "rays_per_s": round(cam.width * cam.height / median),
                         "size": [cam.width, cam.height], "renders": len(times)}
    train = training_rays_per_s(run_dir)
    out = {"run": str(run_dir), "steps": run.step, "threads": torch.get_num_threads(), "device": args.device,
           "render_chunk": run.config.train.render_chunk, **results, "training_rays_per_s": train,
           "render_over_training": round(results["rgb"]["rays_per_s"] / train, 2) if train else None,
           "peak_rss_mib": round(peak_rss_mib(), 1),
           "cuda_peak_mib": round(torch.cuda.max_memory_allocated() / 2**20, 1) if args.device.startswith("cuda")
           else None,
           "load_before_after": [round(load0, 2), round(os.getloadavg()[0], 2)],
           "machine": machine_info(args.device)}
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
