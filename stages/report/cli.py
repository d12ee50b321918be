"""``livescene report``: state sweeps for the sliders, one HTML page per scene, and the index page.

    livescene report sweep --run RUN --data DS --out DIR [--steps 5] [--scale 0.5]
    livescene report scene --scene NAME --results results/NAME --data DS --methods a,b --out PAGE.html
    livescene report index --summaries results/*/report/summary.json --out reports/index.html
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from stages.scene import InputError, write_json


def build_parser(prog: str = "livescene report") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    s = sub.add_parser("sweep", help="render each object's state sweep at one held-out view (slider images)")
    s.add_argument("--run", required=True, help="run folder of `livescene train`")
    s.add_argument("--data", required=True, help="scene dataset the run was trained on")
    s.add_argument("--out", required=True, help="folder for <object>_<k>.png and sweep.json")
    s.add_argument("--steps", type=int, default=5, help="states per object, evenly from 0 to 1")
    s.add_argument("--scale", type=float, default=0.5, help="resolution factor of the renders")
    s.add_argument("--frame", default=None, help="frame id of the view (default: first test frame)")
    s.add_argument("--device", default="cpu")
    s.add_argument("--no-progress", action="store_true")

    p = sub.add_parser("scene", help="write the self-contained HTML page of one scene")
    p.add_argument("--scene", required=True, help="scene name")
    p.add_argument("--results", required=True, help="results/<scene> folder")
    p.add_argument("--data", default="", help="the scene dataset (for truth images and object names)")
    p.add_argument("--truth", default="", help="capture folder holding truth/ ('' = no truth)")
    p.add_argument("--methods", default="", help="comma-separated methods of the scene")
    p.add_argument("--plan-json", default="{}", help="JSON {rule: {needed, why}} from the workflow")
    p.add_argument("--stability", default="", help="summary.json of `livescene stability`")
    p.add_argument("--views", type=int, default=3, help="held-out views in the image grid")
    p.add_argument("--out", required=True, help="HTML page to write")
    p.add_argument("--summary", default="", help="also write the headline numbers (JSON) for the index")

    i = sub.add_parser("index", help="write reports/index.html from the scenes' summaries")
    i.add_argument("--summaries", nargs="+", required=True, help="summary.json of each scene")
    i.add_argument("--pending", default="", help="comma-separated scenes of the sheet without a page yet")
    i.add_argument("--out", required=True, help="index HTML to write")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return {"sweep": _sweep, "scene": _scene, "index": _index}[args.command](args)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _sweep(args: argparse.Namespace) -> int:
    from .sweep import render_sweeps

    summary = render_sweeps(args.run, args.data, args.out, steps=args.steps, scale=args.scale, device=args.device,
                            frame_id=args.frame, progress=not args.no_progress)
    print(f"{args.out}: {summary['renders']} renders of {len(summary['objects'])} objects at "
          f"{summary['width']}x{summary['height']} in {summary['seconds']:.1f} s")
    return 0


def _scene(args: argparse.Namespace) -> int:
    from stages.scene.atomic_io import write_text

    from .scene_data import collect_scene
    from .scene_page import build_scene_page, scene_summary

    try:
        plan = json.loads(args.plan_json)
    except json.JSONDecodeError as exc:
        raise InputError("--plan-json", f"is not JSON ({exc})", "pass the plan the workflow writes") from exc
    methods = [m for m in args.methods.split(",") if m]
    sd = collect_scene(args.scene, args.results, data=args.data or None, truth=args.truth or None, methods=methods,
                       plan=plan, stability=args.stability or None)
    html = build_scene_page(sd, views=args.views)
    write_text(Path(args.out), html)
    if args.summary:
        write_json(args.summary, scene_summary(sd))
    print(f"{args.out}: {len(html) / 1e6:.2f} MB")
    return 0


def _index(args: argparse.Namespace) -> int:
    from stages.scene.atomic_io import write_text

    from .index_page import build_index

    write_text(Path(args.out), build_index(args.summaries, pending=[s for s in args.pending.split(',') if s]))
    print(args.out)
    return 0
