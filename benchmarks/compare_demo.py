"""Issue 7's done-when: the equal-budget comparison of every method on the ``demo`` capture, printed as a table.

1. generates the ``demo`` capture (config/captures/demo.yaml) unless ``--capture`` names one and writes its truth
   scene dataset (alternate split: even source frames held out) with ``stages.capture.capture_to_dataset``;
2. runs ``livescene compare`` on it: every method trains for ``--budget-s`` seconds of wall clock with the
   ``cpu-demo`` preset (+ its overlay in config/model/methods/), seed 0, one process per method, 2 torch
   threads; held-out frames are rendered and scored (PSNR, SSIM);
3. with ``--replay``, trains every method again for the recorded steps and schedule and prints whether each
   run's loss curve and PSNR are identical (reproducibility with the seed); a comparison already in the work
   folder is replayed instead of being run again.

Nothing is asserted: it prints measured numbers. Timings on the shared 2-core machine are pessimistic and
noisy (other jobs run at the same time), so the step count each method reaches in the budget varies.

    .venv/bin/python benchmarks/compare_demo.py [--work /tmp/compare_demo] [--budget-s 240] [--replay]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pandas as pd
from demo_dataset import cached_demo_dataset

from stages.compare.method_comparison import ALL_METHODS, CompareConfig, compare_methods, format_table


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--work", default="/tmp/compare_demo")
    p.add_argument("--capture", help="an existing capture folder (default: generate demo)")
    p.add_argument("--budget-s", type=float, default=240.0)
    p.add_argument("--methods", nargs="+", default=list(ALL_METHODS))
    p.add_argument("--eval-frames", type=int, default=4)
    p.add_argument("--eval-scale", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--replay", action="store_true", help="retrain for the recorded steps and compare")
    args = p.parse_args()
    work = Path(args.work)
    _, data = cached_demo_dataset(work, Path(args.capture) if args.capture else None)
    out = work / "compare"
    cfg = CompareConfig(data=str(data), out=str(out), methods=args.methods, budget_s=args.budget_s, seed=args.seed,
                        eval_frames=args.eval_frames, eval_scale=args.eval_scale)
    if args.replay and (out / "compare.csv").is_file():  # replay an earlier comparison in this work folder
        print(f"[compare] replaying {out} (delete it to compare afresh)")
        print(format_table(pd.read_csv(out / "compare.csv")))
    else:
        print(format_table(compare_methods(cfg)))
    if args.replay:
        again = compare_methods(CompareConfig(**{**cfg.__dict__, "out": str(work / "replay"), "replay": str(out)}))
        print(format_table(again))
        for m in args.methods:
            a = pd.read_csv(out / m / "train_log.csv")["loss"].to_numpy()
            b = pd.read_csv(work / "replay" / m / "train_log.csv")["loss"].to_numpy()
            pa = json.loads((out / "compare.json").read_text())["methods"]
            pb = json.loads((work / "replay" / "compare.json").read_text())["methods"]
            same_psnr = [r["psnr"] for r in pa if r["method"] == m] == [r["psnr"] for r in pb if r["method"] == m]
            print(f"{m}: {len(a)} vs {len(b)} steps, identical losses: {len(a) == len(b) and (a == b).all()}, "
                  f"identical PSNR: {same_psnr}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
