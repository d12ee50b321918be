"""Helpers of the report tests: a fake but complete results/<scene>/ tree, and headless Chromium
driven over the DevTools protocol on a pipe (--remote-debugging-pipe: fd 3 in, fd 4 out)."""

from __future__ import annotations

import base64
import contextlib
import fcntl
import json
import os
import subprocess
import time
from pathlib import Path

import cv2
import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[2]
ARTIFACTS = REPO / "test-artifacts" / "report"


class Chromium:
    """A headless Chromium page controlled with CDP messages (JSON, NUL-terminated) over a pipe."""

    def __init__(self, binary: str, profile: Path) -> None:
        pipe_r, self._to_child = os.pipe()
        self._from_child, pipe_w = os.pipe()
        # Move the child's ends above fd 4 first: dup2 onto the same number would keep close-on-exec,
        # and one end could sit on the other's target number.
        to_child_r, from_child_w = fcntl.fcntl(pipe_r, fcntl.F_DUPFD, 10), fcntl.fcntl(pipe_w, fcntl.F_DUPFD, 10)
        os.close(pipe_r)
        os.close(pipe_w)

        def wire_fds() -> None:  # the child reads commands on fd 3 and writes replies on fd 4
            os.dup2(to_child_r, 3)
            os.dup2(from_child_w, 4)

        self.proc = subprocess.Popen(
            [binary, "--headless", "--no-sandbox", "--disable-gpu", "--remote-debugging-pipe",
             f"--user-data-dir={profile}", "--no-first-run", "--window-size=1280,1600", "about:blank"],
            preexec_fn=wire_fds, close_fds=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self._buffer = b""
        self._next_id = 0
        self.events: list[dict] = []
        self.session: str | None = None

    def _read_message(self, deadline: float) -> dict:
        while b"\0" not in self._buffer:
            if time.monotonic() > deadline:
                raise TimeoutError("no DevTools message from chromium in time")
            chunk = os.read(self._from_child, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed its DevTools pipe")
            self._buffer += chunk
        raw, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(raw)

    def send(self, method: str, params: dict | None = None, *, timeout: float = 60.0, browser: bool = False) -> dict:
        """Send one command (to the page session unless browser=True) and return its result."""
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params or {}}
        if self.session and not browser:
            message["sessionId"] = self.session
        os.write(self._to_child, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            reply = self._read_message(deadline)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            self.events.append(reply)

    def wait_event(self, method: str, timeout: float = 60.0) -> dict:
        for i, event in enumerate(self.events):
            if event.get("method") == method:
                return self.events.pop(i)
        deadline = time.monotonic() + timeout
        while True:
            event = self._read_message(deadline)
            if event.get("method") == method:
                return event
            self.events.append(event)

    def open_page(self) -> None:
        target = self.send("Target.createTarget", {"url": "about:blank"}, browser=True)["targetId"]
        self.session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True},
                                 browser=True)["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            self.send(f"{domain}.enable")

    def load(self, url: str, timeout: float = 60.0) -> None:
        self.send("Page.navigate", {"url": url})
        self.wait_event("Page.loadEventFired", timeout)

    def evaluate(self, expression: str, *, await_promise: bool = False):
        result = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                                "awaitPromise": await_promise})
        if "exceptionDetails" in result:
            raise RuntimeError(f"page script failed: {result['exceptionDetails']}")
        return result["result"].get("value")

    def errors(self) -> list[str]:
        """Console errors, uncaught exceptions and error log entries (e.g. failed loads) seen so far."""
        found = []
        for e in self.events:
            p = e.get("params", {})
            if e.get("method") == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                found.append(f"console.{p['type']}: {[a.get('value') for a in p.get('args', [])]}")
            elif e.get("method") == "Runtime.exceptionThrown":
                found.append(f"exception: {p.get('exceptionDetails', {}).get('text')}")
            elif e.get("method") == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
                found.append(f"log: {p['entry'].get('text')} {p['entry'].get('url', '')}")
        return found

    def screenshot(self, path: Path) -> None:
        data = self.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True})["data"]
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(base64.b64decode(data))

    def close(self) -> None:
        with contextlib.suppress(RuntimeError, TimeoutError, OSError):
            self.send("Browser.close", browser=True, timeout=10)
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._to_child)
        os.close(self._from_child)


def _png(path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), rgb[..., ::-1])


def make_fake_results(root: Path, data: Path, *, methods: tuple[str, ...] = ("livescene", "conerf"),
                      objects: tuple[str, ...] = ("object0", "object1", "object2")) -> Path:
    """results/<scene>/ as the stages write it (same file names and keys), with synthetic numbers and images."""
    rng = np.random.default_rng(1)
    res = root / "fake"
    bench = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
    for name, s in [("capture", 3.1), ("poses", 12.5), ("train_livescene", 150.2), ("train_conerf", 151.0),
                    ("evaluate_livescene", 40.0)]:
        (res / "benchmarks").mkdir(parents=True, exist_ok=True)
        (res / "benchmarks" / f"{name}.tsv").write_text(bench + f"{s}\t0:00:{int(s) % 60:02d}\t300.5\t900\t280\t"
                                                          f"290\t1\t2\t0.9\t{s * 0.9}\n")
    (res / "poses").mkdir(parents=True)
    (res / "poses" / "poses.json").write_text(json.dumps({
        "n_frames": 6, "n_registered": 6, "registered_fraction": 1.0, "mean_reprojection_error": 0.41,
        "n_points3D": 197, "matcher": "exhaustive", "timings": {"total": 3.6}}))
    (res / "pose_error.json").write_text(json.dumps({
        "n_matched": 6, "scale": 5.5, "centre_error_relative": {"mean": 0.007, "median": 0.008, "max": 0.015},
        "rotation_error_deg": {"mean": 1.4, "median": 1.4, "max": 1.9},
        "focal_error": {"relative_fx": 0.09, "relative_fy": 0.09}}))
    (res / "states").mkdir()
    (res / "states" / "states.json").write_text(json.dumps({
        "methods": {"object0": "pchip"},
        "leave_one_out": {"object0": {"linear": {"mae": 0.2, "max": 0.4, "n": 5},
                                      "pchip": {"mae": 0.1, "max": 0.3, "n": 5}}}}))
    from stages.scene import read_scene

    ds = read_scene(data)
    test_ids = [f.frame_id for f in ds.frames_in("test")]
    for k, m in enumerate(methods):
        run = res / "runs" / m
        run.mkdir(parents=True)
        (run / "run.json").write_text(json.dumps({"method": m, "status": "completed", "train_seconds": 150.0,
                                                  "steps": 400 + k, "eval_psnr": 20.0 + k, "peak_memory_mib": 800.0,
                                                  "params": {"total": 1_000_000 + k}}))
        # the first method's config carries trust floors it passes; the others' have no trust section (an older
        # run), so the TrustConfig defaults apply and flag their 400 steps as undertrained
        config = {"method": m, "seed": 0}
        if k == 0:
            config["trust"] = {"min_steps": 100, "min_psnr": 15.0, "min_grounding_miou": 0.3}
        (run / "config.yaml").write_text(yaml.safe_dump(config))
        rows = ["wall_s,step,loss,eval_psnr"] + [f"{10 * i:.1f},{i * 50},{0.3 / (i + 1):.4f},"
                                                 f"{12 + i + k:.2f}" for i in range(8)]
        (run / "train_log.csv").write_text("\n".join(rows) + "\n")
        ev = res / "eval" / m
        views = []
        for i, fid in enumerate(test_ids):
            _png(ev / "renders" / f"{fid}.png", rng.integers(0, 255, (ds.camera.height, ds.camera.width, 3),
                                                             dtype=np.uint8))
            # every later method exactly 1 dB better on every view: LiveScene (first) is behind
            views.append({"frame": fid, "file_path": f"images/frame_{fid}.png", "psnr": 20.0 + k + 0.5 * i,
                          "ssim": 0.7})
        queries = []
        for j, obj in enumerate(objects):
            _png(ev / "grounding" / f"probs_{obj}_{test_ids[0]}.png",
                 np.repeat(rng.integers(0, 255, (ds.camera.height, ds.camera.width, 1), dtype=np.uint8), 3, -1))
            # per-view IoUs that differ between methods in both directions: no measurable difference
            ious = [0.5 + 0.1 * ((i + j + k) % 3 - 1) for i in range(len(test_ids))]
            queries.append({"query": obj, "object": obj, "kind": "name",
                            "probs": {"iou": {"mean": float(np.mean(ious))}, "per_view": ious, "frames": test_ids}})
        records = []
        for i, fid in enumerate(test_ids[:2]):
            for c, states in enumerate([{"object0": 0.0, "object1": 1.0, "object2": 0.0},
                                        {"object0": 1.0, "object1": 0.0, "object2": 0.5}]):
                # LiveScene about 2 dB above the others on every unseen render: ahead
                psnr = 18.0 - 2.0 * min(k, 1) + 0.3 * (i + c) + (0.2 if (i + c + k) % 2 else -0.2)
                records.append({"frame": fid, "combination": c, "states": states, "unseen": True, "rendered": True,
                                "psnr": psnr})
            records.append({"frame": fid, "combination": 2, "states": {"object0": 0.5, "object1": 0.5,
                                                                      "object2": 0.5},
                            "unseen": False, "rendered": False, "psnr": None})
        if k:  # a render the first method lacks: unpaired, left out
            records.append({"frame": test_ids[-1], "combination": 0, "states": records[0]["states"], "unseen": True,
                            "rendered": True, "psnr": 5.0})
        metrics = {"held_out": {"views": views, "psnr": {"mean": 20.0 + k}, "ssim": {"mean": 0.7}, "lpips": None,
                                "lpips_status": "not available: torchvision is not installed"},
                   "unseen_combinations": {"status": "computed", "psnr": {"mean": 18.0}, "psnr_moved": {"mean": 15.0},
                                           "ssim": {"mean": 0.6}, "records": records,
                                           "combinations": [{"unseen": True}, {"unseen": True}, {"unseen": False}]},
                   "grounding": {"status": "computed", "threshold": 0.5, "sources": ["probs"], "queries": queries,
                                 "miou_probs": 0.5, "miou_probs_name": 0.5},
                   # the first method keeps its changes local; the others leak 3/255 onto the rest of the room
                   "locality": {"status": "computed", "outside_limit_x255": 1.0, "objects": {
                       obj: {"model_outside_x255": {"mean": 0.2 + 3.0 * min(k, 1), "n": 2},
                             "truth_outside_x255": {"mean": 0.5, "n": 2},
                             "model_inside_x255": {"mean": 30.0, "n": 2}, "truth_inside_x255": {"mean": 35.0, "n": 2},
                             "local": k == 0} for obj in ds.objects}}}
        (ev / "metrics.json").write_text(json.dumps(metrics))
        (ev / "timings.json").write_text(json.dumps({"held_out": {"render_seconds": 1.2, "views": len(test_ids),
                                                                  "fps": 2.5 + k}, "seconds": 3.0}))
    sweep = res / "sweep" / methods[0]
    entry = {}
    for obj in objects:
        files = []
        for i in range(3):  # visibly different images per state
            files.append(f"{obj}_{i:02d}.png")
            _png(sweep / files[-1], np.full((12, 16, 3), 40 + 80 * i, dtype=np.uint8))
        entry[obj] = {"values": [0.0, 0.5, 1.0], "images": files}
    (sweep / "sweep.json").write_text(json.dumps({"frame": test_ids[0], "objects": entry}))
    control = res / "control" / methods[0]
    _png(control / "command_00.png", np.full((12, 16, 3), 128, dtype=np.uint8))
    (control / "commands.json").write_text(json.dumps({"commands": [
        {"command": "open the object0", "states": {"object0": 1.0, "object1": 0.0},
         "image": str(control / "command_00.png")},
        {"command": "open the fridge", "error": "no object named 'fridge'"}]}))
    return res
