"""``livescene report``: state sweeps for the sliders, one HTML page per scene, and the index page.

    livescene report sweep --run RUN --data DS --out DIR [--steps 5] [--scale 0.5]
    livescene report scene --scene NAME --inputs INPUTS.json --out PAGE.html [--index INDEX.html]
    livescene report index --summaries S1.json S2.json [--earlier S3.json] --out INDEX.html [--csv VERDICTS.csv]
                           [--digests DIGESTS.csv]

INPUTS.json names the file or folder of each role the page reads (dataset, poses, runs per method, ...);
the page reads nothing else. Format: docs/workflow.md, "The report".
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from stages.scene import InputError, write_json
from stages.scene.cli_errors import cli_errors


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
    p.add_argument("--inputs", required=True,
                   help="report inputs manifest (JSON, or YAML by suffix): role -> path of each input")
    p.add_argument("--methods", default="",
                   help="comma-separated methods of the scene, in page order ('' = those the manifest names)")
    p.add_argument("--plan-json", default="{}", help="JSON {rule: {needed, why}} from the workflow")
    p.add_argument("--views", type=int, default=3, help="held-out views in the image grid")
    p.add_argument("--out", required=True, help="HTML page to write")
    p.add_argument("--index", default="",
                   help="the index page this page links back to (and the summary's link is relative to)")
    p.add_argument("--summary", default="", help="also write the headline numbers (JSON) for the index")

    i = sub.add_parser("index", help="write the index page from the scenes' summaries (each links its page)")
    i.add_argument("--summaries", nargs="+", required=True, help="summary.json of each scene")
    i.add_argument("--pending", default="", help="comma-separated scenes of the sheet without a page yet")
    i.add_argument("--earlier", nargs="*", default=[],
                   help="summary.json of the sheet's other scenes whose pages an earlier run wrote: listed apart, "
                        "outside the verdicts and verdicts.csv")
    i.add_argument("--out", required=True, help="index HTML to write")
    i.add_argument("--csv", default="", help="also write every scene's paired verdicts here (one row per scene, "
                   "baseline and metric)")
    i.add_argument("--digests", default="", help="also write every scene's stage digests here (scene, stage, files, "
                   "digest): diff two machines' files to see where their runs part")
    return parser


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return {"sweep": _sweep, "scene": _scene, "index": _index}[args.command](args)


def _sweep(args: argparse.Namespace) -> int:
    from .sweep import render_sweeps

    summary = render_sweeps(args.run, args.data, args.out, steps=args.steps, scale=args.scale, device=args.device,
                            frame_id=args.frame, progress=not args.no_progress)
    print(f"{args.out}: {summary['renders']} renders of {len(summary['objects'])} objects at "
          f"{summary['width']}x{summary['height']} in {summary['seconds']:.1f} s")
    return 0


def _scene(args: argparse.Namespace) -> int:
    from stages.scene.atomic_io import write_text

    from .inputs import read_inputs
    from .scene_data import collect_scene
    from .scene_page import build_scene_page, scene_summary

    try:
        plan = json.loads(args.plan_json)
    except json.JSONDecodeError as exc:
        raise InputError("--plan-json", f"is not JSON ({exc})", "pass the plan the workflow writes") from exc
    methods = [m for m in args.methods.split(",") if m] or None
    sd = collect_scene(args.scene, read_inputs(args.inputs), methods=methods, plan=plan)
    page = Path(args.out)
    index = Path(args.index) if args.index else None
    html = build_scene_page(sd, views=args.views,
                            index=_link(index, page.parent) if index is not None else None)
    write_text(page, html)
    if args.summary:
        # the index links each page by the summary's "page"; without --index the page's own file URI serves
        link = _link(page, index.parent) if index is not None else page.resolve().as_uri()
        write_json(args.summary, scene_summary(sd, page=link))
    print(f"{args.out}: {len(html) / 1e6:.2f} MB")
    return 0


def _link(target: Path, start: Path) -> str:
    """A relative href from folder ``start`` to ``target`` (pages move together with their index)."""
    return Path(os.path.relpath(target, start)).as_posix()


def _index(args: argparse.Namespace) -> int:
    from stages.scene.atomic_io import write_text

    from .index_page import build_index, load_summaries
    from .verdict_table import verdict_rows, verdicts_csv

    summaries = load_summaries(args.summaries)
    earlier = load_summaries(args.earlier)
    write_text(Path(args.out), build_index(summaries, pending=[s for s in args.pending.split(',') if s],
                                           earlier=earlier))
    print(args.out)
    if args.csv:
        write_text(Path(args.csv), verdicts_csv(verdict_rows(summaries)))
        print(args.csv)
    if args.digests:
        from .digests import digests_csv

        write_text(Path(args.digests), digests_csv(summaries))
        print(args.digests)
    return 0
