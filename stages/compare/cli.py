"""``livescene compare``: train every method for the same wall-clock budget on one dataset and print one table.

    livescene compare --data DS --methods livescene mk-planes ... --budget-s 120 --out DIR
    livescene compare --data DS --replay DIR --out DIR2     # DIR's steps and schedule, no clock: reproducible
    livescene compare params --out results/params_vs_objects.csv [--scale cpu-demo] [--max-objects 10]
    livescene compare preset --method conerf --scale cpu-demo --out conerf.yaml   # for `livescene train --preset`

DIR gets compare.csv, compare.json, one run folder per method (config.yaml,
train_log.csv, run.json, model.pt) and one <method>.log of its training process.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from stages.scene import atomic_path, write_yaml
from stages.scene.cli_errors import cli_errors

from .method_comparison import (
    ALL_METHODS,
    CompareConfig,
    compare_methods,
    format_table,
    method_preset,
    params_vs_objects,
)


def build_parser(prog: str = "livescene compare") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="scene dataset folder every method trains on")
    p.add_argument("--out", required=True, help="output folder (compare.csv, compare.json, a run per method)")
    p.add_argument("--methods", nargs="+", default=list(ALL_METHODS), choices=list(ALL_METHODS),
                   help="methods to train, in order (default: all)")
    p.add_argument("--budget-s", type=float, default=120.0, help="wall-clock training seconds per method (120)")
    p.add_argument("--scale", "--preset", dest="scale", default="cpu-demo",
                   help="base preset: cpu-demo or gpu-paper (each method adds config/model/methods/<m>.yaml)")
    p.add_argument("--seed", type=int, default=0, help="seed of every run (default 0)")
    p.add_argument("--device", default="cpu", help="cpu or cuda (default cpu)")
    p.add_argument("--max-steps", type=int, default=0, help="override the preset's max_steps (schedule length)")
    p.add_argument("--eval-frames", type=int, default=4, help="held-out frames rendered per method (0 = all)")
    p.add_argument("--eval-scale", type=int, default=1,
                   help="render scored frames at 1/N resolution vs area-downsampled images (CPU shortcut; 1)")
    p.add_argument("--replay", help="output folder of an earlier comparison: train each method for its recorded "
                                    "steps and learning-rate schedule, without the clock (bit-identical on CPU)")
    p.add_argument("--in-process", action="store_true",
                   help="train in this process instead of one process per method (peak memory is then shared)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="config override applied to every method (repeatable)")
    return p


def _params_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="livescene compare params",
                                description="parameter count versus number of objects, per method, as a CSV")
    p.add_argument("--out", required=True, help="CSV to write")
    p.add_argument("--scale", default="cpu-demo", help="preset scale (cpu-demo or gpu-paper)")
    p.add_argument("--max-objects", type=int, default=10, help="objects 1..N (default 10)")
    p.add_argument("--methods", nargs="+", default=list(ALL_METHODS), choices=list(ALL_METHODS))
    return p


def _preset_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="livescene compare preset",
                                description="write a method's full preset (base scale + its overlay)")
    p.add_argument("--method", required=True, choices=list(ALL_METHODS))
    p.add_argument("--scale", default="cpu-demo", help="preset scale (cpu-demo or gpu-paper)")
    p.add_argument("--out", required=True, help="YAML to write; use it as `livescene train --preset FILE`")
    return p


@cli_errors()
def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "params":
        a = _params_parser().parse_args(argv[1:])
        table = params_vs_objects(a.methods, range(1, a.max_objects + 1), a.scale)
        with atomic_path(Path(a.out), suffix=".csv") as tmp:
            table.to_csv(tmp, index=False)
        print(table.pivot(index="objects", columns="method", values="total_params").to_string())
        return 0
    if argv and argv[0] == "preset":
        a = _preset_parser().parse_args(argv[1:])
        write_yaml(Path(a.out), method_preset(a.method, a.scale))
        print(a.out)
        return 0
    args = build_parser().parse_args(argv)
    cfg = CompareConfig(data=args.data, out=args.out, methods=list(args.methods), budget_s=args.budget_s,
                        scale=args.scale, seed=args.seed, device=args.device, max_steps=args.max_steps,
                        overrides=list(args.overrides), eval_frames=args.eval_frames,
                        eval_scale=args.eval_scale,
                        replay=args.replay or "", isolate=not args.in_process)
    table = compare_methods(cfg)
    print(format_table(table))
    failed = table["status"].astype(str).str.startswith("failed").any()
    return 1 if failed else 0
