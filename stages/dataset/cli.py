"""``livescene dataset``: assemble the stage outputs into one validated scene dataset.

    livescene dataset assemble --frames FRAMES --poses POSES|transforms.json [--labels LABELS]
                               [--states STATES] [--prompts prompts.yaml] --out DS
    livescene dataset orient --data READY_DS [--points PLY | --no-triangulate] --out DS

``orient`` writes a copy of a ready dataset (poses that came with the data) in the upright, wall-aligned
world of the poses stage, or unchanged with the reason (docs/poses.md, "World frame").

``livescene scene validate DS`` / ``info DS`` check and summarise the result (docs/data-contract.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from stages.scene.cli_errors import cli_errors

from .assemble import AssembleConfig, assemble_scene


def build_parser(prog: str = "livescene dataset") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
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
    a.add_argument("--copy-images", action="store_true", help="copy images and masks instead of hard-linking them")
    a.add_argument("--out", required=True, type=Path, help="scene dataset folder to write")
    a.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    o = sub.add_parser("orient", help="copy a ready dataset into the upright, wall-aligned world")
    o.add_argument("--data", required=True, type=Path, help="scene dataset whose poses came with the data (only read)")
    o.add_argument("--points", type=Path, default=None,
                   help="point cloud in the poses' world (default: the dataset's ply_file_path)")
    o.add_argument("--no-triangulate", action="store_true",
                   help="without a point cloud, keep the world instead of triangulating points from the images at "
                        "their given poses (COLMAP, about a second per image on one core)")
    o.add_argument("--seed", type=int, default=0, help="COLMAP's random seed for the triangulation")
    o.add_argument("--out", required=True, type=Path, help="folder of the oriented copy")
    return parser


@cli_errors(ValueError, sigterm=True)
def assemble(args: argparse.Namespace) -> int:
    config = AssembleConfig(frames=args.frames, poses=args.poses, out=args.out, labels=args.labels,
                            states=args.states, prompts=args.prompts, split=args.split, split_n=args.split_n,
                            test_fraction=args.test_fraction, copy_images=args.copy_images,
                            progress=not args.no_progress)
    ds = assemble_scene(config)
    splits = {s: len(ds.frames_in(s)) for s in ("train", "test")}
    print(f"{args.out}: scene dataset, {len(ds.frames)} frames ({splits['train']} train, {splits['test']} test), "
          f"objects {ds.objects}, {len(ds.meta.get('unregistered_frames', []))} frames without a pose dropped")
    return 0


@cli_errors(ValueError)  # its triangulation is one long COLMAP call, which a SIGTERM handler would wait for
def orient(args: argparse.Namespace) -> int:
    from .orient import orient_dataset  # imported on use: it loads open3d and pycolmap

    ds, how = orient_dataset(args.data, args.out, args.points, triangulate=not args.no_triangulate, seed=args.seed)
    verb = "turned upright" if how.turned else "world kept"
    print(f"{args.out}: {len(ds.frames)} frames, {verb}: {how.reason}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return {"assemble": assemble, "orient": orient}[args.command](args)
