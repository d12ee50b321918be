"""Latency of `livescene view`: a slider moved in the browser -> the new full-resolution image in the browser.

The viewer is started in this process exactly as `livescene view` builds it (stages.viewer.cli.build_viewer);
viser's real web client runs in headless Chromium at 640x480 (a 4:3 canvas, so 128x96 renders are exactly
128x96) and is driven through the DevTools protocol (tests/viewer/viser_browser.py). Each move presses End or
Home on the first object's slider (state 0 -> 1 -> 0 ...), then waits for the PNG (the still, full-resolution
image; previews are JPEG) to arrive in the browser. Moves are ``--gap`` seconds apart, as a user clicking the
slider, so each is an isolated change that the viewer renders at full resolution at once (render_loop.py).

Printed: the load average (`cat /proc/loadavg`) before and after, one JSON line with every latency, and
median / p90 of

- ``end_to_end_s``: key press sent to Chromium -> image decoded from the websocket frame the browser received;
- ``to_server_s``: key press -> the server's slider callback asking for the render (browser, websocket, viser);
- ``server_s``: that request -> image ready (the render loop's latency);
- ``render_s``: the render alone;
- ``to_browser_s``: image ready -> decoded from the frame the browser received (PNG encoding, websocket, DevTools);
- ``cpu_s_per_move``: this process's CPU time (rendering, viser, the DevTools client) per move.

    .venv/bin/python benchmarks/viewer_latency.py --run RUN [--data DS] [--moves 20] [--threads 2]

The figures depend on how busy the machine is: read them with the load average printed next to them.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)
from stage_bench import peak_rss_mib

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests"), str(ROOT / "tests" / "viewer")]
# as `livescene view` does, before torch loads OpenMP (docs/viewer.md)
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def loadavg() -> str:
    return Path("/proc/loadavg").read_text().strip()


def quantile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, round(q * (len(ordered) - 1))))]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True, help="trained run folder")
    p.add_argument("--data", default=None, help="its dataset (default: from the run's config.yaml)")
    p.add_argument("--moves", type=int, default=20)
    p.add_argument("--resolution", default="128x96")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--gap", type=float, default=1.0, help="seconds between moves (default 1)")
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    args = p.parse_args(argv)

    import numpy as np
    import torch
    from chromium_page import Chromium
    from viser_browser import ViserPage

    from stages.viewer.cli import build_parser, build_viewer
    from stages.viewer.resolution import Resolution

    print(f"load before: {loadavg()}   (cat /proc/loadavg)")
    print(f"cpus: {os.cpu_count()}, torch threads: {args.threads}, OMP_WAIT_POLICY={os.environ['OMP_WAIT_POLICY']}, "
          f"torch {torch.__version__}")
    view_args = ["--run", args.run, "--port", "0", "--no-encoder", "--threads", str(args.threads), "--resolution",
                 args.resolution, "--device", args.device, *(["--data", args.data] if args.data else [])]
    viewer = build_viewer(build_parser().parse_args(view_args))
    full = Resolution.parse(args.resolution)
    frames = []
    lock = threading.Lock()

    def sent(_client: int, frame) -> None:
        with lock:
            frames.append(frame)

    viewer.add_frame_listener(sent)
    binary = shutil.which("chromium") or shutil.which("chromium-browser")
    if binary is None:
        print("error: chromium not found; fix: apt-get install -y chromium", file=sys.stderr)
        viewer.stop()
        return 2
    profile = Path(tempfile.mkdtemp(prefix="viewer-bench-chromium-"))
    browser = Chromium(binary, profile)
    results: dict = {"run": args.run, "resolution": str(full), "threads": args.threads, "moves": []}
    try:
        browser.open_page()
        page = ViserPage(browser, viewer.url, width=640, height=480)
        page.wait_until(lambda: len(viewer.sessions()) >= 1, timeout=120, what="the page connecting")
        name = viewer.objects[0]
        page.wait_for_control(name, "[role=slider]", timeout=120)
        page.next_image(0, timeout=300, accept=lambda im: im.format == "png")  # the first still image
        session = viewer.sessions()[0]
        session.loop.wait_idle(300)
        viewer.set_states(dict.fromkeys(viewer.objects, 0.0))
        session.loop.wait_idle(300)
        time.sleep(args.gap)
        cpu0 = time.process_time()
        for i in range(args.moves):
            value = 1.0 if i % 2 == 0 else 0.0
            page.pump()  # read every image already sent, so the next one is the answer to this move
            before = len(page.images)
            with lock:
                sent_before = len(frames)
            t0 = time.perf_counter()
            page.slider_key(name, "End" if value == 1.0 else "Home")
            got = page.next_image(before, timeout=300, accept=lambda im: im.format == "png"
                                  and im.image.shape[:2] == (full.height, full.width))
            with lock:
                mine = [f for f in frames[sent_before:] if f.final and f.request.states[0] == value]
            if not mine or not np.array_equal(mine[-1].image, got.image):
                raise RuntimeError(f"move {i}: the browser got an image that is not the render of {name}={value}")
            frame = mine[-1]
            ready = frame.request.submitted + frame.latency_s
            results["moves"].append({"value": value, "end_to_end_s": round(got.received - t0, 4),
                                     "to_server_s": round(frame.request.submitted - t0, 4),
                                     "server_s": round(frame.latency_s, 4), "render_s": round(frame.render_s, 4),
                                     "to_browser_s": round(got.received - ready, 4), "size": str(frame.resolution)})
            session.loop.wait_idle(300)
            time.sleep(args.gap)
        cpu = time.process_time() - cpu0
        results["cpu_s_per_move"] = round(cpu / max(args.moves, 1), 3)
    finally:
        browser.close()
        viewer.stop()
        shutil.rmtree(profile, ignore_errors=True)
    results["load_after"] = loadavg()
    results["peak_rss_mib"] = round(peak_rss_mib(), 1)  # the viewer's
    print(json.dumps(results))
    moves = results["moves"]
    for key in ("end_to_end_s", "to_server_s", "server_s", "render_s", "to_browser_s"):
        values = [m[key] for m in moves]
        print(f"{key:>13}: median {statistics.median(values):.3f} s, p90 {quantile(values, 0.9):.3f} s, "
              f"min {min(values):.3f}, max {max(values):.3f}  ({len(values)} moves)")
    print(f"cpu_s_per_move: {results['cpu_s_per_move']:.3f} s  (this process: rendering + viser + DevTools client)")
    print(f"peak memory: {results['peak_rss_mib']:.0f} MiB  (this process's max RSS: the viewer and its renders)")
    print(f"load after: {results['load_after']}   (cat /proc/loadavg)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
