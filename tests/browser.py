"""A headless Chromium driven over the DevTools protocol: open a page, take screenshots.

One browser serves a whole test: the page loads once (viser's client and WebGL start once),
and :meth:`HeadlessChromium.wait_for` takes screenshots until what a person would see is
there, instead of guessing how long rendering takes.
"""

from __future__ import annotations

import base64
import contextlib
import io
import itertools
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path

import numpy as np

CHROMIUM = next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)

# Software WebGL (SwiftShader through ANGLE): no GPU on CI machines. --no-sandbox: CI runs as root.
FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu-sandbox",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-extensions",
    "--remote-debugging-port=0",
)


class HeadlessChromium:
    """``with HeadlessChromium() as browser: browser.open(url); pixels = browser.screenshot()``."""

    def __init__(self, width: int = 1000, height: int = 700, timeout: float = 30.0) -> None:
        assert CHROMIUM is not None, "Chromium is not installed"
        self.size = (width, height)
        self.timeout = timeout
        self._ids = itertools.count(1)
        self._socket = None

    def __enter__(self) -> HeadlessChromium:
        # Chromium's helper processes can still write into the profile just after the browser
        # exits: they share its session (killed together) and cleaning up may leave a file.
        self._profile = tempfile.TemporaryDirectory(ignore_cleanup_errors=True)
        width, height = self.size
        self._process = subprocess.Popen(
            [
                CHROMIUM,
                *FLAGS,
                f"--user-data-dir={self._profile.name}",
                f"--window-size={width},{height}",
                "about:blank",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        try:
            self._port = self._devtools_port()
        except BaseException:
            self._stop()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            if self._socket is not None:
                self._socket.close()
        finally:
            self._stop()

    def _stop(self) -> None:
        self._process.terminate()
        try:
            self._process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self._process.pid, signal.SIGKILL)  # helpers left in its session
        self._profile.cleanup()

    def _devtools_port(self) -> int:
        """The DevTools port Chromium chose, from the file it writes into its profile."""
        path = Path(self._profile.name) / "DevToolsActivePort"
        deadline = time.monotonic() + self.timeout
        while not (path.is_file() and path.read_text().strip()):
            assert self._process.poll() is None, f"Chromium exited with {self._process.returncode}"
            assert time.monotonic() < deadline, "Chromium did not open its DevTools port"
            time.sleep(0.1)
        return int(path.read_text().split()[0])

    def call(self, method: str, **params: object) -> dict:
        """One DevTools command; its result (events in between are skipped)."""
        message_id = next(self._ids)
        self._socket.send(json.dumps({"id": message_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self._socket.recv(timeout=self.timeout))
            if reply.get("id") == message_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def open(self, url: str) -> None:
        """Open `url` in a new page (a page made for it, so no navigation can swap it out)."""
        from websockets.sync.client import connect

        request = urllib.request.Request(f"http://127.0.0.1:{self._port}/json/new?{url}", method="PUT")
        with urllib.request.urlopen(request, timeout=self.timeout) as response:
            page = json.load(response)
        self._socket = connect(page["webSocketDebuggerUrl"], max_size=None, open_timeout=self.timeout)
        deadline = time.monotonic() + self.timeout
        while True:  # a new page answers "not attached to an active page" for a moment
            try:
                width, height = self.size
                self.call(
                    "Emulation.setDeviceMetricsOverride", width=width, height=height, deviceScaleFactor=1, mobile=False
                )
                return
            except RuntimeError:
                assert time.monotonic() < deadline, "the page never became active"
                time.sleep(0.1)

    def screenshot(self, path: Path | None = None) -> np.ndarray:
        """The page as RGB pixels, shape (height, width, 3); also written to `path` as PNG if given."""
        from PIL import Image

        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        if path is not None:
            Path(path).write_bytes(data)
        with Image.open(io.BytesIO(data)) as image:
            return np.asarray(image.convert("RGB"), dtype=np.int16)

    def wait_for(self, seen: Callable[[np.ndarray], bool], timeout: float | None = None) -> np.ndarray:
        """Screenshots until `seen(pixels)` holds or the time is up; the last screenshot."""
        deadline = time.monotonic() + (timeout or self.timeout)
        pixels = None
        while True:
            try:
                pixels = self.screenshot()
            except RuntimeError:
                if time.monotonic() > deadline:
                    raise
            if pixels is not None and (seen(pixels) or time.monotonic() > deadline):
                return pixels
            time.sleep(0.5)
