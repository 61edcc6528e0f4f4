"""A real browser for the set-up's page: headless Chromium driven over its DevTools protocol
(a websocket; the ``websockets`` client the ``virtual`` extra brings). Tests that need it skip
with a reason where Chromium is not installed (Debian's package: ``apt-get install
chromium``; CI installs it)."""

from __future__ import annotations

import base64
import itertools
import json
import shutil
import subprocess
import time
import urllib.request
from pathlib import Path

import pytest

CHROMIUM = next((shutil.which(name) for name in ("chromium", "chromium-browser",
                                                  "google-chrome") if shutil.which(name)), None)


class Page:
    """One page of a headless Chromium: screenshot, reload, pointer moves, close."""

    def __init__(self, url: str, folder: Path, width: int = 1280, height: int = 720):
        from websockets.sync.client import connect

        profile = folder / "chromium-profile"
        self.width, self.height = width, height
        self.process = subprocess.Popen(
            [CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu",
             "--no-first-run", "--disable-extensions", f"--user-data-dir={profile}",
             "--remote-debugging-port=0", f"--window-size={width},{height}", url],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = profile / "DevToolsActivePort"
        deadline = time.monotonic() + 30.0
        while not port_file.is_file() or not port_file.read_text().strip():
            if time.monotonic() > deadline or self.process.poll() is not None:
                self.close()
                raise RuntimeError("headless Chromium did not start")
            time.sleep(0.05)
        port = int(port_file.read_text().split()[0])
        targets = []
        while not targets:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list") as response:
                targets = [t for t in json.load(response) if t.get("type") == "page"]
            if time.monotonic() > deadline:
                raise RuntimeError("headless Chromium opened no page")
            time.sleep(0.05)
        self._connection = connect(targets[0]["webSocketDebuggerUrl"], max_size=2 ** 26)
        self.socket = self._connection.__enter__()
        self._ids = itertools.count(1)

    def call(self, method: str, **params):
        """One DevTools command; its result (events in between are skipped)."""
        ident = next(self._ids)
        self.socket.send(json.dumps({"id": ident, "method": method, "params": params}))
        while True:
            message = json.loads(self.socket.recv(timeout=30.0))
            if message.get("id") == ident:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message.get("result", {})

    def screenshot(self, path: Path) -> Path:
        data = self.call("Page.captureScreenshot", format="png")["data"]
        path.write_bytes(base64.b64decode(data))
        return path

    def reload(self) -> None:
        self.call("Page.reload", ignoreCache=True)

    def evaluate(self, expression: str):
        """A JavaScript expression's value in the page."""
        return self.call("Runtime.evaluate", expression=expression,
                         returnByValue=True)["result"].get("value")

    def move_pointer(self, x: float, y: float) -> None:
        """The mouse to (x, y) in CSS pixels from the page's top left."""
        self.call("Input.dispatchMouseEvent", type="mouseMoved", x=x, y=y)

    def close(self) -> None:
        if hasattr(self, "_connection"):
            self._connection.__exit__(None, None, None)
        self.process.terminate()
        try:
            self.process.wait(10.0)
        except subprocess.TimeoutExpired:
            self.process.kill()


@pytest.fixture
def browser(tmp_path):
    """``browser(url)`` opens the url in headless Chromium (skips without one); closed after
    the test."""
    if CHROMIUM is None:
        pytest.skip("headless Chromium is not installed (apt-get install chromium)")
    pages: list[Page] = []

    def open_page(url: str, **size) -> Page:
        page = Page(url, tmp_path / f"browser{len(pages)}", **size)
        pages.append(page)
        return page

    yield open_page
    for page in pages:
        page.close()
