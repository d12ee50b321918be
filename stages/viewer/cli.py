"""``livescene view``: open a trained run in a live browser viewer (viser).

    livescene view --run RUN [--data DS] [--port 8080] [--device cpu|cuda] [--resolution 128x96]

Then open the printed address (http://127.0.0.1:8080/ by default) in a browser. The training cameras are
frustums; each object has a state slider; "Command" takes language commands ("open the fridge") that move
the sliders; "Relevancy query" shows a text query's relevancy map instead of colour. The render follows your
camera: a preview while it moves, the full resolution once it is still. Ctrl-C stops the viewer.

The full resolution defaults to 128x96 on the CPU (about 12k rays per image) and to the dataset's image size
on CUDA. Needs the optional package viser: pip install -e ".[viewer]".
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

from stages.language.cli import add_encoder_arguments, encoder_from_args
from stages.scene import InputError
from stages.scene.cli_errors import cli_errors

from .resolution import Resolution
from .viser_dependency import require_viser

CPU_RESOLUTION = "128x96"
CPU_CHUNK_RAYS = 4096
"""Rays per render call on the CPU: ~0.15 s each on 2 cores, so a newer request waits at most that long. A call
splits into 4 chunks for the render's worker threads (docs/model.md), so 2048 would make them 512 rays each,
where per-op overhead shows (0.53 s a 128x96 slider move against 0.41 s in one measurement each)."""
CUDA_CHUNK_RAYS = 1 << 16


def build_parser(prog: str = "livescene view") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True, help="run folder written by `livescene train`")
    p.add_argument("--data", default=None, help="the run's scene dataset (default: the one in the run's config.yaml)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this machine only; 0.0.0.0 to share on the network)")
    p.add_argument("--port", type=int, default=8080, help="port (the next free one is taken when it is busy)")
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"], help="where the model renders")
    p.add_argument("--resolution", default=None,
                   help="full render size WIDTHxHEIGHT, as a pixel budget fitted to the browser's aspect "
                        f"(default: {CPU_RESOLUTION} on cpu, the dataset's image size on cuda)")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    p.add_argument("--frame-budget", type=float, default=0.15,
                   help="seconds a preview may take while the view changes (default 0.15)")
    p.add_argument("--settle", type=float, default=0.25,
                   help="seconds without change after which the full resolution is rendered (default 0.25)")
    p.add_argument("--thumbnails", action="store_true",
                   help="draw each training frame's image in its frustum (off by default: from a training pose the "
                        "neighbouring frames' images hang right in front of the camera and hide the render)")
    p.add_argument("--no-encoder", action="store_true",
                   help="no text model: commands resolve objects by name, synonym and spelling; no relevancy queries")
    p.add_argument("--stop-after", type=float, default=0.0, help=argparse.SUPPRESS)  # seconds; for scripted runs
    add_encoder_arguments(p)
    return p


def check_address(host: str, port: int) -> None:
    """Refuse a port out of range or a host this machine cannot serve on: viser takes any socket error for a busy
    port and tries the next one without end, so the viewer would hang without a word."""
    import socket

    if not 0 <= port <= 65535:
        raise InputError("--port", f"{port} is not a port", "give a port from 1 to 65535, e.g. 8080 (0: any free one)")
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise InputError("--host", f"{host!r} is not an address of this machine ({exc})",
                         "give 127.0.0.1 (this machine only) or 0.0.0.0 (every network interface)") from exc
    family, _, _, _, address = infos[0]
    try:
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.bind((address[0], 0))  # any free port: only whether this machine has the address is asked
    except OSError as exc:
        raise InputError("--host", f"cannot serve on {host!r} ({exc.strerror or exc})",
                         "give 127.0.0.1 (this machine only), 0.0.0.0 (every network interface) or an address of "
                         "one of this machine's interfaces") from exc


def build_viewer(args: argparse.Namespace) -> Any:
    """Load the run and its dataset and start the viewer (``LiveViewer``) as ``args`` say."""
    import numpy as np
    import torch

    from stages.language.vocabulary import ObjectVocabulary
    from stages.model.run import dataset_of_run, open_run
    from stages.scene import generate_rays, read_scene

    from .language_controls import LanguageControls
    from .server import LiveViewer, ViewerOptions

    if args.device == "cuda" and not torch.cuda.is_available():
        raise InputError("--device", f"CUDA is not available to this torch ({torch.__version__})",
                         "use --device cpu, or install a CUDA build of the pinned torch into the venv")
    if args.threads is not None:
        if args.threads < 1:
            raise InputError("--threads", f"{args.threads} threads", "give 1 or more")
        torch.set_num_threads(args.threads)
    for flag, value in (("--frame-budget", args.frame_budget), ("--settle", args.settle)):
        if not value > 0:
            raise InputError(flag, f"{value} seconds", "give a positive number of seconds")
    check_address(args.host, args.port)
    run = open_run(args.run, args.device)
    data = dataset_of_run(args.run, args.data)
    ds = read_scene(data)
    if args.resolution:
        resolution = Resolution.parse(args.resolution)
    elif args.device == "cuda":
        resolution = Resolution(ds.camera.width, ds.camera.height)
    else:
        resolution = Resolution.parse(CPU_RESOLUTION)
    # one ray tells whether the run renders a language embedding (runs trained with --language-targets)
    camera = ds.camera_of(ds.frames[0])
    origin, direction = generate_rays(camera, ds.frames[0].c2w, u=np.array([camera.cx]), v=np.array([camera.cy]))
    probe = run.render_rays(origin, direction, run.state_vector(None), 0.0, ("language",))
    vocabulary = ObjectVocabulary.from_prompts(ds.objects, ds.prompts, Path(data) / "prompts.yaml")
    language = LanguageControls(vocabulary, None if args.no_encoder else (lambda: encoder_from_args(args)),
                                renders_language="language" in probe,
                                run_encoder=getattr(run, "language_encoder", None))
    options = ViewerOptions(host=args.host, port=args.port, full_pixels=resolution.pixels,
                            frame_budget_s=args.frame_budget, settle_s=args.settle,
                            chunk_rays=CUDA_CHUNK_RAYS if args.device == "cuda" else CPU_CHUNK_RAYS,
                            thumbnails=args.thumbnails)
    return LiveViewer(run, ds, language, options)


@cli_errors()
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # Must be set before torch loads OpenMP: with the default (spinning) wait policy two torch threads on a
    # busy 2-core machine burn ~3x the CPU time per render (docs/viewer.md); a viewer always shares its cores.
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    require_viser()
    viewer = build_viewer(args)
    n = len(viewer.objects)
    print(f"livescene view: {viewer.url}  ({n} object{'' if n == 1 else 's'}: {', '.join(viewer.objects)}; "
          f"full resolution {viewer.options.full_pixels} pixels; Ctrl-C stops)", flush=True)
    try:
        deadline = time.monotonic() + args.stop_after if args.stop_after > 0 else None
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        viewer.stop()
    return 0
