"""``livescene scene``: inspect, validate and assemble scene datasets."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .dataset import read_scene
from .errors import InputError


def build_parser(prog: str = "livescene scene") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    v = sub.add_parser("validate", help="check a scene dataset against the contract")
    v.add_argument("path", help="scene dataset folder (holds transforms.json)")
    v.add_argument("--deep", action="store_true", help="also open every image to check its size")
    i = sub.add_parser("info", help="print a JSON summary of a scene dataset")
    i.add_argument("path")
    a = sub.add_parser("assemble", help="join frames, poses, labels and states into one scene dataset")
    a.add_argument("--frames", required=True, type=Path, help="FRAMES folder (images/ + frames.csv)")
    a.add_argument("--poses", required=True, type=Path,
                   help="POSES folder (transforms.json + scene.json) or a transforms.json (e.g. capture truth)")
    a.add_argument("--labels", type=Path, default=None, help="LABELS folder of `livescene labels`")
    a.add_argument("--states", type=Path, default=None, help="STATES folder of `livescene states`")
    a.add_argument("--prompts", type=Path, default=None, help="prompts.yaml {object: {synonyms, description}}")
    a.add_argument("--split", default="alternate", choices=["alternate", "every_n", "fraction"])
    a.add_argument("--split-n", type=int, default=10, help="n of the every_n split")
    a.add_argument("--test-fraction", type=float, default=0.1, help="test share of the fraction split")
    a.add_argument("--copy-images", action="store_true", help="copy images instead of hard-linking them")
    a.add_argument("--out", required=True, type=Path, help="scene dataset folder to write")
    a.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return parser


def assemble(args: argparse.Namespace) -> int:
    from .assemble import AssembleConfig, assemble_scene

    config = AssembleConfig(frames=args.frames, poses=args.poses, out=args.out, labels=args.labels,
                            states=args.states, prompts=args.prompts, split=args.split, split_n=args.split_n,
                            test_fraction=args.test_fraction, copy_images=args.copy_images,
                            progress=not args.no_progress)
    try:
        ds = assemble_scene(config)
    except (InputError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    splits = {s: len(ds.frames_in(s)) for s in ("train", "test")}
    print(f"{args.out}: scene dataset, {len(ds.frames)} frames ({splits['train']} train, {splits['test']} test), "
          f"objects {ds.objects}, {len(ds.meta.get('unregistered_frames', []))} frames without a pose dropped")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "assemble":
        return assemble(args)
    try:
        ds = read_scene(args.path, validate=True, deep=getattr(args, "deep", False))
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.command == "validate":
        print(f"{args.path}: valid scene dataset, {len(ds.frames)} frames, objects {ds.objects}")
    else:
        splits = {s: len(ds.frames_in(s)) for s in ("train", "test")}
        print(json.dumps({"frames": len(ds.frames), "objects": ds.objects, "splits": splits,
                          "camera": {"w": ds.camera.width, "h": ds.camera.height, "fx": ds.camera.fx},
                          "key_frames": len(ds.key_frames), "has_masks": ds.has_masks,
                          "scene_box": None if ds.scene_box is None else ds.scene_box.tolist()}, indent=2))
    return 0
