"""``livescene evaluate``: metrics, unseen-state control and grounding of a trained run.

    livescene evaluate --run RUN --data DS --out DIR [--truth CAPTURE] [--pose-alignment pose_error.json]

Writes DIR/metrics.json (per-image PSNR/SSIM with mean, std and 95% CI, LPIPS or
why not, unseen-combination PSNR over the image and the moved objects, grounding
IoU per query and view and mIoU), DIR/timings.json (render seconds and fps: kept
apart so metrics.json is the same for every evaluation of one trained model) and
PNG renders for the report.
"""

from __future__ import annotations

import argparse
import json
import sys

from stages.evaluate.unseen_states import OBSERVED_WITHIN
from stages.scene import InputError
from stages.scene.cli_errors import cli_errors


def build_parser(prog: str = "livescene evaluate") -> argparse.ArgumentParser:
    from stages.language.cli import add_encoder_arguments

    p = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True, help="trained run folder (stages.model)")
    p.add_argument("--data", default=None, help="scene dataset (default: the one in the run's config.yaml)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars (for logs)")
    p.add_argument("--truth", default=None, help="synthetic capture folder with truth/ (enables unseen combinations)")
    p.add_argument("--pose-alignment", default=None,
                   help="pose_error.json of `livescene poses compare` (needed when the run used COLMAP poses and "
                        "frames carry no source_index)")
    p.add_argument("--out", required=True, help="output folder (metrics.json, renders/, unseen/, grounding/)")
    p.add_argument("--max-views", type=int, default=None, help="held-out views to evaluate (default: all)")
    p.add_argument("--unseen-views", type=int, default=3, help="held-out poses for unseen combinations")
    p.add_argument("--levels", default="0,0.5,1", help="levels of the unseen-combination test")
    p.add_argument("--locality-views", type=int, default=8,
                   help="held-out poses of the locality test (needs --truth; 0 = skip)")
    p.add_argument("--max-unseen-renders", type=int, default=48,
                   help="most unseen-combination renders: fewer poses for a room of many objects (0 = no cap)")
    p.add_argument("--max-locality-pairs", type=int, default=40,
                   help="most (pose, object) pairs of the locality test: fewer poses for many objects (0 = no cap)")
    p.add_argument("--novelty-min", type=float, default=0.25,
                   help="least L-inf distance to training states for a combination to count as unseen")
    p.add_argument("--observed-within", type=float, default=OBSERVED_WITHIN,
                   help="an object takes a level in the unseen combinations only where a training frame holds it "
                        "within this distance of the level (negative: every level)")
    p.add_argument("--grounding-threshold", type=float, default=0.5, help="relevancy threshold of the grounding IoU")
    p.add_argument("--scale", type=float, default=1.0,
                   help="render and compare at this fraction of the image size (e.g. 0.5 on a CPU: 4x fewer rays)")
    p.add_argument("--max-side", type=int, default=0,
                   help="render and compare at the dataset's size divided by the smallest integer factor that brings "
                        "its longer side to at most this many pixels (0 = full size; instead of --scale)")
    p.add_argument("--no-grounding", action="store_true", help="skip grounding (no text encoder is loaded)")
    p.add_argument("--no-renders", action="store_true", help="write metrics.json only")
    p.add_argument("--device", default="cpu")
    add_encoder_arguments(p)
    return p


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    return _evaluate(build_parser().parse_args(argv))


def _evaluate(args: argparse.Namespace) -> int:
    from pathlib import Path

    from stages.language.grounding import Grounder
    from stages.language.vocabulary import ObjectVocabulary
    from stages.model.run import dataset_of_run, open_run
    from stages.scene import read_scene

    from .evaluation import EvaluateConfig, evaluate_run, render_scale_for
    from .truth_source import TruthSource

    for flag in ("max_unseen_renders", "max_locality_pairs"):
        if getattr(args, flag) < 0:
            raise InputError(f"--{flag.replace('_', '-')}", f"{getattr(args, flag)} is negative",
                             "pass a number of renders, or 0 for no cap")
    data = dataset_of_run(args.run, args.data)
    try:
        levels = tuple(float(v) for v in args.levels.split(",") if v.strip())
    except ValueError as exc:
        raise InputError("--levels", f"{args.levels!r} is not a list of numbers", "write e.g. 0,0.5,1") from exc
    if not 0.0 < args.scale <= 1.0:
        raise InputError("--scale", f"{args.scale} is not in (0, 1]", "pass e.g. --scale 0.5 (or 1 for full size)")
    if args.max_side < 0 or 0 < args.max_side < 16:
        raise InputError("--max-side", f"{args.max_side} pixels",
                         "give at least 16 pixels, e.g. 480, or 0 for full size")
    if args.max_side and args.scale != 1.0:
        raise InputError("--max-side", "given with --scale", "pass one of them: --scale picks a fraction, --max-side "
                         "a size")
    ds = read_scene(data)
    scale = render_scale_for(ds, args.max_side) if args.max_side else args.scale
    truth = None
    if args.truth and not ds.objects:  # a static field: unseen combinations and locality move objects
        print(f"{args.truth}: not used: the dataset has no objects, so there are no state combinations or locality "
              "to test against the truth (held-out views only)", file=sys.stderr)
    elif args.truth:
        same_world = str(ds.meta.get("units", "")).lower() != "colmap"
        truth = TruthSource.from_capture(args.truth, args.pose_alignment, same_world=same_world).after_turn(ds.meta)
        if sorted(truth.object_ids) != sorted(ds.objects):  # another room's truth: its renders would be compared
            raise InputError(Path(args.truth) / "mapping.yaml", f"the truth capture's objects "
                             f"{sorted(truth.object_ids)} are not the dataset's {sorted(ds.objects)}",
                             "pass --truth the capture this dataset was made from")
    grounder = None
    if not args.no_grounding:
        from stages.language.cli import encoder_from_args

        vocab = ObjectVocabulary.from_prompts(ds.objects, ds.prompts, Path(data) / "prompts.yaml")
        grounder = Grounder(vocab, encoder_from_args(args))
    cfg = EvaluateConfig(max_views=args.max_views, unseen_views=args.unseen_views, levels=levels,
                         novelty_min=args.novelty_min, grounding_threshold=args.grounding_threshold,
                         observed_within=args.observed_within if args.observed_within >= 0 else None,
                         save_renders=not args.no_renders, render_scale=scale,
                         locality_views=args.locality_views,
                         max_unseen_renders=args.max_unseen_renders or None,
                         max_locality_pairs=args.max_locality_pairs or None, progress=not args.no_progress)
    run = open_run(args.run, args.device)
    run.check_dataset(ds)
    extra = {"run": str(args.run), "device": args.device,
             "encoder": getattr(grounder.encoder, "name", None) if grounder else None}
    metrics = evaluate_run(run, ds, args.out, truth, grounder, cfg, extra)
    timings = json.loads((Path(args.out) / "timings.json").read_text())
    print(json.dumps(headline(metrics, timings), indent=2))
    return 0


def headline(metrics: dict, timings: dict | None = None) -> dict:
    """The numbers a person reads first (the full detail is in metrics.json, the render speed in timings.json)."""
    held = metrics["held_out"]
    unseen = metrics["unseen_combinations"]
    ground = metrics["grounding"]
    out = {"psnr": held["psnr"]["mean"], "psnr_std": held["psnr"]["std"], "ssim": held["ssim"]["mean"],
           "lpips": held["lpips_status"] if held["lpips"] is None else held["lpips"]["mean"],
           "psnr_ci95": held["psnr"].get("ci95"),
           "fps": ((timings or {}).get("held_out") or {}).get("fps"), "views": held["psnr"]["n"]}
    if unseen.get("status") == "computed":
        out |= {"unseen_psnr": unseen["psnr"]["mean"], "unseen_psnr_moved": unseen["psnr_moved"]["mean"],
                "unseen_n": unseen["n_unseen"], "seen_reference_psnr": unseen["seen_reference"]["psnr"]["mean"]}
    else:
        out["unseen"] = unseen.get("status")
    if ground.get("status") == "computed":
        for key, value in ground.items():
            if key.startswith("miou"):
                out[f"grounding_{key}"] = value
        out["grounding_per_query"] = {f'{q["query"]} ({q["kind"]} of {q["object"]})':
                                      {src: q[src]["iou"]["mean"] for src in ground["sources"]}
                                      for q in ground["queries"]}
    else:
        out["grounding"] = ground.get("status")
    return out
