"""Dense states from sparse key frames vs the truth, per interpolation method, on synthetic captures.

For each capture preset (default: demo and stiff) this generates the capture
(or reuses one under --work), lists every video frame in a frames.csv as
`livescene frames` would, runs `livescene states` with each method on the
capture's key_frame_value.yaml (and on a sparser copy that keeps every other
key frame), and prints the mean / max absolute error against
truth/states.csv, per object and overall, as a Markdown table.

    .venv/bin/python docs/scripts/states_error.py [--presets demo stiff] [--work /tmp/states_error]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from stages.states import METHODS, StatesConfig, compute_states

ROOT = Path(__file__).resolve().parents[2]


def capture_dir(preset: str, work: Path) -> Path | None:
    spec_path = ROOT / "config" / "captures" / f"{preset}.yaml"
    if not spec_path.is_file():
        return None
    out = work / preset
    if not (out / "truth" / "states.csv").is_file():
        from stages.capture import generate_capture, load_spec

        generate_capture(load_spec(spec_path), out, progress=False)
    return out


def write_frames_csv(capture: Path, path: Path) -> None:
    truth = pd.read_csv(capture / "truth" / "states.csv")
    frames = truth[["frame", "source_index"]].drop_duplicates().sort_values("source_index")
    frames = frames.assign(timestamp=np.nan, sharpness=np.nan)
    frames.to_csv(path, index=False)


def sparser(keys: Path, out: Path) -> int:
    data = yaml.safe_load(keys.read_text())
    names = sorted(data, key=lambda k: int(k.rsplit("_", 1)[-1]))
    kept = names[::2] if names[-1] in names[::2] else [*names[::2], names[-1]]
    out.write_text(yaml.safe_dump({k: data[k] for k in kept}, sort_keys=False))
    return len(kept)


def errors(capture: Path, keys: Path, frames_csv: Path, work: Path) -> dict[str, dict[str, tuple[float, float]]]:
    truth = pd.read_csv(capture / "truth" / "states.csv").set_index(["source_index", "object"])["value"]
    out: dict[str, dict[str, tuple[float, float]]] = {}
    for method in METHODS:
        dest = work / f"states_{method}"
        # the capture's key values are already normalised to [0, 1]: keep them (no min-max stretch)
        compute_states(StatesConfig(key_frames=keys, frames=frames_csv, out=dest, method=method,
                                    ranges={"*": (0.0, 1.0)}))
        pred = pd.read_csv(dest / "states.csv").set_index(["source_index", "object"])["value"]
        diff = (pred - truth.reindex(pred.index)).abs()
        per_object = {obj: (float(d.mean()), float(d.max())) for obj, d in diff.groupby(level="object")}
        per_object["all"] = (float(diff.mean()), float(diff.max()))
        out[method] = per_object
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--presets", nargs="+", default=["demo", "stiff"])
    p.add_argument("--work", type=Path, default=None, help="folder for captures and outputs (default: temporary)")
    args = p.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="states_error_"))
    print("| capture | key frames | object | " + " | ".join(f"{m} MAE / max" for m in METHODS) + " |")
    print("|---|---|---|" + "---|" * len(METHODS))
    for preset in args.presets:
        t0 = time.perf_counter()
        capture = capture_dir(preset, work)
        if capture is None:
            print(f"| {preset} | - | - | " + " | ".join(f"skipped: no config/captures/{preset}.yaml"
                                                        for _ in METHODS) + " |")
            continue
        frames_csv = work / f"{preset}_frames.csv"
        write_frames_csv(capture, frames_csv)
        keys = capture / "key_frame_value.yaml"
        sparse = work / f"{preset}_sparser_keys.yaml"
        variants = [(f"{len(yaml.safe_load(keys.read_text()))} (capture)", keys),
                    (f"{sparser(keys, sparse)} (every other)", sparse)]
        for label, key_file in variants:
            result = errors(capture, key_file, frames_csv, work / f"{preset}_{key_file.stem}")
            for obj in result[METHODS[0]]:
                cells = " | ".join(f"{result[m][obj][0]:.4f} / {result[m][obj][1]:.3f}" for m in METHODS)
                print(f"| {preset} | {label} | {obj} | {cells} |")
        print(f"<!-- {preset}: {time.perf_counter() - t0:.1f} s including capture generation -->")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
