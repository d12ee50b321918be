"""``livescene states``: interpolate key-frame interaction variables to every extracted frame."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from stages.scene.cli_errors import cli_errors

from .errors import StateError
from .interpolation import METHODS
from .pipeline import StatesConfig, compute_states


def build_parser(prog: str = "livescene states") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__)
    p.add_argument("--key-frames", required=True, type=Path,
                   help="key_frame_value.yaml (LiveScene), annotations.yml (CoNeRF) or CSV (frame, object, value)")
    p.add_argument("--format", default="auto", choices=["auto", "livescene", "conerf", "csv"])
    p.add_argument("--frames", required=True, type=Path, help="FRAMES/frames.csv (or the FRAMES folder)")
    p.add_argument("--method", action="append", default=None, metavar="METHOD|OBJECT=METHOD",
                   help=f"interpolation, one of {', '.join(METHODS)} (default pchip); repeat with OBJECT=METHOD "
                        "to override one object")
    p.add_argument("--range", action="append", default=[], metavar="OBJECT=LO,HI",
                   help="fixed value range of an object (OBJECT may be '*' for all) instead of min-max of its "
                        "key frames; CoNeRF files default to -1,1")
    p.add_argument("--mapping", type=Path, default=None,
                   help="name table {id: name} (mapping.yaml, or CoNeRF mapping.yml): the scene's objects; "
                        "annotations naming others, or objects never annotated, are errors")
    p.add_argument("--allow-missing-frames", action="store_true",
                   help="use key frames on frames beyond the source's end (interpolation only); a key frame on a "
                        "frame the frames stage left out needs no flag")
    p.add_argument("--out", required=True, type=Path, help="STATES folder to write")
    return p


def parse_methods(items: list[str] | None) -> tuple[str, dict[str, str]]:
    default, per_object = "pchip", {}
    for item in items or []:
        if "=" in item:
            name, method = item.split("=", 1)
            per_object[name.strip()] = method.strip()
        else:
            default = item.strip()
    return default, per_object


def parse_ranges(items: list[str]) -> dict[str, tuple[float, float]]:
    out = {}
    for item in items:
        name, _, bounds = item.partition("=")
        parts = bounds.split(",")
        try:
            lo, hi = (float(v) for v in parts) if len(parts) == 2 else (math.nan, math.nan)
        except ValueError:
            lo, hi = math.nan, math.nan
        if not name or not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise StateError("--range", f"{item!r} is not OBJECT=LO,HI with finite LO < HI", "write e.g. door=0,90")
        out[name.strip()] = (lo, hi)
    return out


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    method, per_object = parse_methods(args.method)
    config = StatesConfig(key_frames=args.key_frames, frames=args.frames, out=args.out, format=args.format,
                          method=method, object_methods=per_object, ranges=parse_ranges(args.range),
                          mapping=args.mapping, allow_missing_frames=args.allow_missing_frames)
    summary = compute_states(config)
    for name in summary["objects"]:
        loo = summary["leave_one_out"][name]
        errs = ", ".join(f"{m} {v['mae']:.3f}" for m, v in loo.items() if v["mae"] is not None) or "n/a"
        print(f"{name}: {summary['n_key_frames'][name]} key frames, method {summary['methods'][name]}, "
              f"leave-one-out MAE {errs}")
    for name in summary["still"]:
        print(f"note: {name!r} barely moves in its key frames (values span {summary['key_span'][name]:.3f} of "
              f"[0, 1]): the capture does not show its other states, so they cannot be learned", file=sys.stderr)
    print(f"{args.out}: states for {summary['n_frames']} frames x {len(summary['objects'])} objects")
    return 0
