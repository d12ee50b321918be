"""Where one training step spends its time: torch.profiler over a few steps of one method (issue 16).

Builds the trainer as ``train_throughput.py`` does (same preset, overrides and demo work folder), runs warm-up
steps from ``--start-step``, then profiles ``--steps`` steps and prints the ops that take the most device time
(CUDA) or CPU time, and on CUDA the number of kernel launches per step. ``--out`` also writes the whole table.

    .venv/bin/python benchmarks/profile_step.py --preset gpu-paper --device cuda --rays 4096 --language
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from train_throughput import add_run_arguments, bench_config, bench_inputs, resolve_start_step

from stages.scene.machine import machine_info, machine_line


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_arguments(p)
    p.add_argument("--method", default="livescene")
    p.add_argument("--language", action="store_true", help="train with the language table")
    p.add_argument("--steps", type=int, default=5, help="profiled steps")
    p.add_argument("--rows", type=int, default=25)
    p.add_argument("--out", type=Path, default=None, help="write the whole table here")
    args = p.parse_args()
    resolve_start_step(args)

    import torch
    from torch.profiler import ProfilerActivity, profile

    from stages.model.trainer import Trainer

    dataset, targets = bench_inputs(args)
    args.warmup = max(args.warmup, 1)
    args.steps = max(args.steps, 1)
    cfg = bench_config(args, args.method, args.language, dataset, targets)
    with tempfile.TemporaryDirectory() as out:
        trainer = Trainer(cfg, out, device=args.device, progress=False)
        cuda = trainer.device.type == "cuda"
        trainer.step = args.start_step
        for _ in range(args.warmup):
            trainer.train_step()
            trainer.step += 1
        activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])
        if cuda:
            torch.cuda.synchronize()
        with profile(activities=activities) as prof:
            for _ in range(args.steps):
                trainer.train_step()
                trainer.step += 1
            if cuda:
                torch.cuda.synchronize()
    averages = prof.key_averages()
    sort = "self_device_time_total" if cuda else "self_cpu_time_total"
    print(f"\n{args.method}, language {'on' if args.language else 'off'}, preset {args.preset}, {args.device}, "
          f"{cfg.train.batch_rays} rays, {args.steps} profiled steps (times are totals over them)\n"
          f"machine: {machine_line(machine_info(args.device))}\n")
    print(averages.table(sort_by=sort, row_limit=args.rows, max_name_column_width=60))
    if cuda:
        kernels = [e for e in prof.events() if e.device_type == torch.autograd.DeviceType.CUDA]
        device_us = sum(e.device_time for e in kernels if e.device_time > 0)
        print(f"kernels per step: {len(kernels) / args.steps:.0f}; device busy per step: "
              f"{device_us / args.steps / 1000:.1f} ms")
    if args.out is not None:
        args.out.write_text(averages.table(sort_by=sort, row_limit=-1, max_name_column_width=80))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
