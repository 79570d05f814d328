"""A small headless-Chromium driver over the DevTools protocol (for the dashboard test and screenshots).

Why not selenium: the DevTools websocket needs only ``websocket-client``
(already a test dependency) and the ``chromium`` binary, no chromedriver
version to match.  Chromium runs with a fresh, empty profile in a temp folder
and no network services of its own.
"""
from __future__ import annotations

import base64
import itertools
import json
import os
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Optional

START_TIMEOUT_S = 30.0  # wall s for Chromium to open its DevTools port
COMMAND_TIMEOUT_S = 30.0  # wall s for one DevTools command
WINDOW = (1400, 940)  # browser window, px
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--disable-dev-shm-usage", "--hide-scrollbars", "--mute-audio")


def find_chromium() -> Optional[str]:
    """Path of a Chromium/Chrome binary, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return None


class Browser:
    """``with Browser() as b: b.open(url); b.eval("1+1"); b.screenshot(path)``."""

    def __init__(self, binary: Optional[str] = None, window=WINDOW):
        self.binary = binary or find_chromium()
        if not self.binary:
            raise FileNotFoundError("no chromium binary on PATH (apt-get install chromium)")
        self.window = window
        self.profile = tempfile.mkdtemp(prefix="dashboard-chromium-")
        self.proc = None
        self.ws = None
        self._ids = itertools.count(1)

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.close()

    def start(self):
        import websocket

        self.proc = subprocess.Popen(
            [self.binary, *CHROMIUM_FLAGS, f"--user-data-dir={self.profile}", "--remote-debugging-port=0",
             f"--window-size={self.window[0]},{self.window[1]}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = Path(self.profile) / "DevToolsActivePort"
        end = time.monotonic() + START_TIMEOUT_S
        while not (port_file.exists() and port_file.read_text().strip()):
            if self.proc.poll() is not None or time.monotonic() > end:
                raise RuntimeError(f"chromium did not start (exit {self.proc.poll()})")
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10))
        page = next(t for t in targets if t.get("type") == "page")
        self.ws = websocket.create_connection(page["webSocketDebuggerUrl"], timeout=COMMAND_TIMEOUT_S,
                                              suppress_origin=True)
        self.call("Page.enable")
        self.call("Runtime.enable")

    def call(self, method: str, **params):
        """Send one DevTools command and return its result (events in between are skipped)."""
        msg_id = next(self._ids)
        self.ws.send(json.dumps({"id": msg_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == msg_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})

    def open(self, url: str):
        self.call("Page.navigate", url=url)

    def eval(self, expression: str):
        """Value of a JavaScript expression (awaits promises)."""
        r = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if r.get("exceptionDetails"):
            raise RuntimeError(f"javascript error: {r['exceptionDetails'].get('text')}")
        return r.get("result", {}).get("value")

    def wait_for(self, expression: str, timeout: float = 30.0, every: float = 0.1):
        """Poll a JavaScript expression until it is truthy; returns its value."""
        end = time.monotonic() + timeout
        while True:
            try:
                v = self.eval(expression)
            except RuntimeError:
                v = None
            if v:
                return v
            if time.monotonic() > end:
                raise TimeoutError(f"timed out waiting for {expression}")
            time.sleep(every)

    def screenshot(self, path) -> Path:
        data = self.call("Page.captureScreenshot", format="png", captureBeyondViewport=False)["data"]
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_bytes(base64.b64decode(data))
        os.replace(tmp, path)
        return path

    def close(self):
        try:
            if self.ws is not None:
                self.ws.close()
        finally:
            if self.proc is not None and self.proc.poll() is None:
                self.proc.terminate()
                try:
                    self.proc.wait(10)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(10)
            shutil.rmtree(self.profile, ignore_errors=True)


def main(argv=None) -> int:
    """``python -m dashboard.browser URL OUT.png [--after-s T]``: screenshot a dashboard page
    (for the README) once the mission shown has reached T simulated seconds."""
    from sim.cli import positive_number, tool_parser

    p = tool_parser("python -m dashboard.browser", "Screenshot a dashboard page with headless Chromium.")
    p.add_argument("url", help="the page, e.g. http://127.0.0.1:4568/")
    p.add_argument("out", help="PNG file to write")
    p.add_argument("--after-s", type=positive_number, default=None, metavar="SECONDS",
                   help="wait until the page shows at least this mission time")
    p.add_argument("--timeout", type=positive_number, default=3600.0, help="give up after this many wall s")
    a = p.parse_args(argv)
    with Browser() as b:
        b.open(a.url)
        b.wait_for("Number(document.body.dataset.version) > 0", a.timeout)
        if a.after_s:
            b.wait_for(f"Number(document.getElementById('fig-t').dataset.value) >= {a.after_s}", a.timeout, 1.0)
        time.sleep(1.0)  # let the images of the last message decode
        print(b.screenshot(a.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
