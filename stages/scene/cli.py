"""``livescene scene``: validate and inspect scene datasets.

Assembling one is the dataset stage's job (``livescene dataset assemble``): it reads the frames, poses,
labels and states stages, which this shared contract package must not import (docs/data-contract.md,
"Stage order"). ``livescene scene assemble`` still works: the ``livescene`` dispatcher runs the dataset
stage's command for it.
"""

from __future__ import annotations

import argparse
import json
import sys

from .atomic_io import write_json
from .cli_errors import cli_errors
from .dataset import read_scene
from .exposure import estimate_exposure
from .key_frame_states import key_frame_states


def build_parser(prog: str = "livescene scene") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    v = sub.add_parser("validate", help="check a scene dataset against the contract")
    v.add_argument("path", help="scene dataset folder (holds transforms.json)")
    v.add_argument("--deep", action="store_true", help="also open every image to check its size")
    i = sub.add_parser("info", help="print a JSON summary of a scene dataset")
    i.add_argument("path")
    e = sub.add_parser("exposure", help="measure how much the frames' exposure varies (per-frame log gains)")
    e.add_argument("path")
    e.add_argument("--out", default=None, help="write the estimate (spread, per-frame log gains) to this JSON file")
    return parser


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "assemble":  # `livescene scene assemble` is routed to the dataset stage by stages.cli
        print("error: assemble is a command of the dataset stage: run `livescene dataset assemble` "
              "(or `python -m stages.dataset assemble`) with the same options", file=sys.stderr)
        return 2
    args = build_parser().parse_args(argv)
    ds = read_scene(args.path, validate=True, deep=getattr(args, "deep", False))
    if args.command == "validate":
        print(f"{args.path}: valid scene dataset, {len(ds.frames)} frames, objects {ds.objects}")
        if ds.split_note:
            print(f"note: transforms.json names no split: {ds.split_note}; {len(ds.frames_in('test'))} of "
                  f"{len(ds.frames)} frames held out")
        for name, r in key_frame_states(ds).rescaled.items():
            fixed = r["source"] == "scene.json state_ranges"
            hint = "" if fixed else "; a fixed range goes in scene.json \"state_ranges\""
            print(f"note: {ds.root / 'key_frame_value.yaml'}: {name!r} key values {r['lo']:g}..{r['hi']:g} are "
                  f"mapped to [0, 1] ({r['source']}{hint})")
        if ds.objects and not ds.has_masks:  # valid, but not for every method: say which
            print(f"warning: {ds.root / 'mapping.yaml'}: names objects {ds.objects} but the dataset has no masks/: "
                  "LiveScene and CoNeRF-style refuse it (only masks train their probability field) and no grounding "
                  "can be evaluated; MK-Planes trains on it; fix: ingest masks (`livescene labels`, then "
                  "`livescene dataset assemble --labels`)", file=sys.stderr)
    elif args.command == "exposure":
        est = estimate_exposure(ds)
        if args.out:
            write_json(args.out, est.to_dict())
        spread = "not measurable (no overlapping neighbours)" if est.spread is None else f"{est.spread:.4f}"
        print(f"{args.path}: exposure spread {spread} (std of the log gains over {int(est.tied.sum())} frames, "
              f"{est.pairs} compared pairs)")
    else:
        splits = {s: len(ds.frames_in(s)) for s in ("train", "test")}
        print(json.dumps({"frames": len(ds.frames), "objects": ds.objects, "splits": splits,
                          "camera": {"w": ds.camera.width, "h": ds.camera.height, "fx": ds.camera.fx},
                          "key_frames": len(ds.key_frames), "has_masks": ds.has_masks,
                          "scene_box": None if ds.scene_box is None else ds.scene_box.tolist()}, indent=2))
    return 0
