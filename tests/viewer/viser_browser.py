"""The real viser web client in headless Chromium, driven like a user, reading the images the server sends.

Controls are used through the page: a slider is focused and moved with the keyboard (End = max, Home = min,
arrows = one step), text is typed with ``Input.insertText`` and buttons are clicked in the DOM, so every change
reaches the server through viser's own client and websocket, as a user's would.

Images: the client's websocket runs in a web worker, so the DevTools Network domain is enabled in that worker
(auto-attach) and every binary frame the server sends is decoded. The frame layout is viser 1.1.1's
(``viser/infra/_infra.py``, ``_message_producer``): 8 bytes msgpack length, 8 bytes compressed length, the
zstd-compressed msgpack ``{"messages": [...]}`` (then raw numpy buffers, which images do not use); a background
image is a ``BackgroundImageMessage`` whose ``rgb_data`` is the PNG or JPEG file.
"""

from __future__ import annotations

import base64
import json
import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import msgspec
import numpy as np
import zstandard
from chromium_page import Chromium

_FIND_CONTROL = """
(label, selector) => {
  const lab = Array.from(document.querySelectorAll('label')).find(l => l.textContent.trim() === label);
  if (!lab) return null;
  let e = lab;
  while (e && !e.querySelector(selector)) e = e.parentElement;
  return e ? e.querySelector(selector) : null;
}"""


@dataclass(frozen=True)
class ReceivedImage:
    """One background image as the browser received it."""

    image: np.ndarray
    """uint8 RGB ``[H, W, 3]``."""
    format: str
    received: float
    """``time.perf_counter()`` when the test read it from the DevTools pipe."""


def decode_viser_frame(payload: bytes) -> list[dict]:
    """The messages of one server -> client websocket frame (viser 1.1.1 wire layout)."""
    raw_len = int.from_bytes(payload[:8], "little")
    packed_len = int.from_bytes(payload[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(payload[16:16 + packed_len], max_output_size=raw_len)
    return list(msgspec.msgpack.decode(inner)["messages"])


class ViserPage:
    """A viser page in a Chromium tab; ``images`` collects every background image received, in order."""

    def __init__(self, browser: Chromium, url: str, width: int = 640, height: int = 480) -> None:
        self.browser = browser
        self.images: list[ReceivedImage] = []
        self._page_session = browser.session
        self._workers: set[str] = set()
        browser.send("Emulation.setDeviceMetricsOverride",
                     {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
        browser.send("Target.setAutoAttach", {"autoAttach": True, "waitForDebuggerOnStart": True, "flatten": True})
        browser.send("Network.enable")
        browser.load(url)

    # -- DevTools plumbing --------------------------------------------------------------------------------------
    def _send_to(self, session: str, method: str, params: dict | None = None) -> dict:
        saved, self.browser.session = self.browser.session, session
        try:
            return self.browser.send(method, params)
        finally:
            self.browser.session = saved

    def pump(self) -> None:
        """Read what Chromium has sent: attach to new workers, decode new frames."""
        self.browser.send("Runtime.evaluate", {"expression": "0"})  # a round trip collects pending events
        keep = []
        for event in self.browser.events:
            method = event.get("method")
            if method == "Target.attachedToTarget":
                session = event["params"]["sessionId"]
                if session not in self._workers:
                    self._workers.add(session)
                    self._send_to(session, "Network.enable")
                    self._send_to(session, "Runtime.runIfWaitingForDebugger")
            elif method == "Network.webSocketFrameReceived":
                response = event["params"]["response"]
                if response.get("opcode") == 2:
                    self._read_frame(base64.b64decode(response["payloadData"]))
            else:
                keep.append(event)
        self.browser.events[:] = keep

    def _read_frame(self, payload: bytes) -> None:
        now = time.perf_counter()
        for message in decode_viser_frame(payload):
            if message.get("type") == "BackgroundImageMessage" and message.get("rgb_data"):
                data = np.frombuffer(message["rgb_data"], dtype=np.uint8)
                bgr = cv2.imdecode(data, cv2.IMREAD_COLOR)
                self.images.append(ReceivedImage(np.ascontiguousarray(bgr[..., ::-1]), message["format"], now))

    def wait_until(self, condition: Callable[[], bool], timeout: float = 60.0, what: str = "condition") -> None:
        deadline = time.monotonic() + timeout
        while True:
            self.pump()
            if condition():
                return
            if time.monotonic() > deadline:
                raise TimeoutError(f"{what} not reached within {timeout:.0f} s")
            time.sleep(0.02)

    def next_image(self, after: int, timeout: float = 60.0,
                   accept: Callable[[ReceivedImage], bool] = lambda _image: True) -> ReceivedImage:
        """The first received image with index >= ``after`` that ``accept`` takes."""
        found: list[ReceivedImage] = []

        def arrived() -> bool:
            found[:] = [im for im in self.images[after:] if accept(im)]
            return bool(found)

        self.wait_until(arrived, timeout, "a new background image")
        return found[0]

    # -- controls ------------------------------------------------------------------------------------------------
    def _evaluate(self, script: str):
        return self.browser.evaluate(script)

    def has_control(self, label: str, selector: str) -> bool:
        return bool(self._evaluate(f"!!({_FIND_CONTROL})({json.dumps(label)}, {json.dumps(selector)})"))

    def wait_for_control(self, label: str, selector: str = "input, [role=slider]", timeout: float = 60.0) -> None:
        self.wait_until(lambda: self.has_control(label, selector), timeout, f"control {label!r}")

    def _focus(self, label: str, selector: str) -> None:
        ok = self._evaluate(f"(() => {{ const e = ({_FIND_CONTROL})({json.dumps(label)}, {json.dumps(selector)});"
                            f" if (!e) return false; e.focus(); return document.activeElement === e; }})()")
        if not ok:
            raise LookupError(f"no focusable {selector} under the label {label!r} on the viser page")

    def press(self, key: str, code: int) -> None:
        for kind in ("keyDown", "keyUp"):
            self.browser.send("Input.dispatchKeyEvent",
                              {"type": kind, "key": key, "code": key, "windowsVirtualKeyCode": code})

    def slider_key(self, label: str, key: str) -> None:
        """Focus the slider labelled ``label`` and press ``key`` (End, Home, ArrowRight, ArrowLeft)."""
        codes = {"End": 35, "Home": 36, "ArrowLeft": 37, "ArrowRight": 39}
        self._focus(label, "[role=slider]")
        self.press(key, codes[key])

    def slider_value(self, label: str) -> float | None:
        value = self._evaluate(f"(() => {{ const e = ({_FIND_CONTROL})({json.dumps(label)}, '[role=slider]');"
                               f" return e ? e.getAttribute('aria-valuenow') : null; }})()")
        return None if value is None else float(value)

    def type_text(self, label: str, text: str) -> None:
        """Replace the text of the input labelled ``label`` by typing ``text``."""
        self._focus(label, "input")
        self._evaluate("document.activeElement.select()")
        self.browser.send("Input.insertText", {"text": text})

    def click_button(self, text: str) -> None:
        ok = self._evaluate(f"(() => {{ const b = Array.from(document.querySelectorAll('button'))"
                            f".find(b => b.textContent.trim() === {json.dumps(text)}); if (!b) return false;"
                            f" b.click(); return true; }})()")
        if not ok:
            raise LookupError(f"no button {text!r} on the viser page")
