"""Parameter count versus number of objects (1..10) for every method, at the cpu-demo and gpu-paper presets.

Models are built on torch's meta device (no memory, no time), with each
method's preset overlay from config/model/methods/. Writes one long CSV
(scale, method, objects, planes_per_scale, field/proposal/probability/total
parameters) and prints the total per method. The report can call
``stages.compare.method_comparison.params_vs_objects`` directly for the same table.

    .venv/bin/python benchmarks/params_vs_objects.py [--out params_vs_objects.csv] [--max-objects 10]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import pandas as pd
import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)

from stages.compare.method_comparison import ALL_METHODS, params_vs_objects
from stages.scene import atomic_path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=str(Path(tempfile.gettempdir()) / "livescene-bench" / "params_vs_objects.csv"),
                   help="CSV to write (default: under the temp folder; the repository is left as it is)")
    p.add_argument("--max-objects", type=int, default=10)
    p.add_argument("--scales", nargs="+", default=["cpu-demo", "gpu-paper"])
    args = p.parse_args()
    table = pd.concat([params_vs_objects(ALL_METHODS, range(1, args.max_objects + 1), s) for s in args.scales],
                      ignore_index=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out, suffix=".csv") as tmp:
        table.to_csv(tmp, index=False)
    for scale, part in table.groupby("scale", sort=False):
        print(f"\ntotal parameters, {scale} preset")
        print(part.pivot(index="objects", columns="method", values="total_params").to_string())
        print(f"planes per scale, {scale} preset")
        print(part.pivot(index="objects", columns="method", values="planes_per_scale").to_string())
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
