"""``livescene dataset``: assemble the stage outputs into one validated scene dataset.

    livescene dataset assemble --frames FRAMES --poses POSES|transforms.json [--labels LABELS]
                               [--states STATES] [--prompts prompts.yaml] --out DS

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
    a.add_argument("--copy-images", action="store_true", help="copy images instead of hard-linking them")
    a.add_argument("--out", required=True, type=Path, help="scene dataset folder to write")
    a.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return parser


@cli_errors(ValueError)
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


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return assemble(args)
