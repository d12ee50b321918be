"""``livescene labels``: ingest object masks (npy, PNG id maps, COCO, LabelMe) as canonical LiveScene masks."""

from __future__ import annotations

import argparse
from pathlib import Path

from stages.scene.cli_errors import cli_errors

from .ingest import LabelsConfig, ingest_labels


def build_parser(prog: str = "livescene labels") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__)
    p.add_argument("--input", required=True, type=Path,
                   help="mask folder (masks/<fid>.npy, <name>_<fid>.png id maps, grey or palette, LabelMe <fid>.json, "
                        "or one folder of binary PNGs per object), a folder holding masks/, or a COCO / LabelMe .json "
                        "file")
    p.add_argument("--format", default="auto", choices=["auto", "npy", "png", "coco", "labelme", "objects"])
    p.add_argument("--mapping", type=Path, default=None,
                   help="name table {id: name}: LiveScene mapping.yaml or CoNeRF mapping.yml "
                        "(default: found next to the input; COCO may use its categories instead)")
    p.add_argument("--frames", required=True, type=Path, help="FRAMES folder (images/ + frames.csv)")
    p.add_argument("--out", required=True, type=Path, help="LABELS folder to write")
    p.add_argument("--missing-masks", default="propagate", choices=["propagate", "leave", "refuse"],
                   help="frames without an annotation: propagate the annotated frames to them by optical flow "
                        "(default; writes confidence.csv and propagation.json), leave them without masks "
                        "(the mask loss skips them), or refuse (docs/labels-states.md)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return p


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    config = LabelsConfig(input=args.input, frames=args.frames, out=args.out, format=args.format,
                          mapping=args.mapping, progress=not args.no_progress, missing_masks=args.missing_masks)
    summary = ingest_labels(config)
    print(f"{args.out}: {summary['n_labelled']}/{summary['n_frames']} frames labelled ({summary['format']}), "
          f"objects {summary['objects']}, {len(summary['frames_without_masks'])} without masks, "
          f"{len(summary['unreliable_frames'])} unreliable (object under H*W/300 pixels and a quarter of its "
          "median size)")
    if "propagation" in summary:
        prop = summary["propagation"]
        loo = prop["leave_one_out_mean_iou"]
        print(f"{args.out}: {len(summary['propagated_frames'])} frames propagated from "
              f"{len(summary['annotated_frames'])} annotated ones by optical flow, mean confidence "
              f"{prop['mean_confidence']:.3f}; leave-one-out IoU "
              + (f"{loo:.3f} over {prop['leave_one_out_n']} annotated frames" if loo is not None
                 else "not measured (needs two annotated frames)")
              + f" ({args.out / 'propagation.json'})")
    return 0
