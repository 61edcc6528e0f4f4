"""The virtual set-up's screen: a page served on this machine that draws the ball and the
racket from a websocket stream, and the mouse as a racket.

The server is starlette on uvicorn (the ``virtual`` extra), run in a thread of its own beside
the physics: starlette because it is a small, well-kept ASGI toolkit with websockets built in
(one page and one socket need no framework), uvicorn because it is the reference ASGI server
and runs in a background thread with its own event loop, so the physics keeps the main thread
(and Ctrl-C). The page (``page.html``, one file, no build step) draws the latest frame on a
canvas at the screen's refresh, full screen on a click or ``F``, with the trial's countdown and
score; it reconnects by itself after a reload or a dropped connection.

**Latency.** Each frame carries the server clock (``time.perf_counter``) of the racket sample
it shows. The page keeps the offset of its clock (``performance.now``) to the server's from
ping-pong exchanges (the one with the shortest round trip wins, as NTP does) and reports, for
every frame it draws, the server-clock time at which the drawing finished. The delay from
racket sample to drawn frame is therefore measured on one clock; what it leaves out is the
screen's own scan-out and the projector's processing, which only a photodiode measures.
"""

from __future__ import annotations

import asyncio
import json
import math
import queue
import socket
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from importlib import resources
from typing import Any, Iterator

from ..errors import ConfigError

#: how long ``wait_for_page`` polls between looks, s
_POLL_S = 0.05


def _require_server():
    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
        import websockets  # noqa: F401
    except ImportError:
        raise ConfigError("the virtual set-up's screen needs starlette, uvicorn and websockets "
                          "(python -m pip install 'bounce-cli[virtual]'), or run it with "
                          "--headless") from None


@dataclass
class Status:
    """What the page shows beside the ball: ``phase`` is waiting | countdown | trial | rest |
    done; ``remaining_s`` counts down the phase; ``score`` is the trial's bounces."""

    phase: str = "waiting"
    trial: int = 0
    trials: int = 0
    remaining_s: float = 0.0
    score: int = 0
    best: int = 0
    message: str = ""
    duration_s: float = 0.0


@dataclass
class View:
    """The world the page shows: heights from ``low_m`` to ``high_m`` (m, the page's bottom to
    its top); ``target_m``, when set, is drawn as a line (the ball's target height)."""

    low_m: float
    high_m: float
    target_m: float | None = None


@dataclass
class Display:
    """The page and its websocket, served at ``http://host:port/`` from a thread of its own.

    ``publish`` (from the physics' thread) hands the page the latest ball and racket; the
    page's drawn frames come back as rows of ``latency``; with ``mouse=True`` the page's
    pointer heights (m, on the server's clock) arrive in ``pointer``."""

    view: View
    mouse: bool = False
    host: str = "127.0.0.1"
    port: int = 8765
    delay_s: float = 0.0
    status: Status = field(default_factory=Status)
    latency: list[dict[str, Any]] = field(default_factory=list)
    pointer: "queue.Queue[tuple[float, float]]" = field(default_factory=queue.Queue)
    connections: int = 0  # connected now
    _opened: int = 0  # connections so far: each one's number in latency.csv
    #: the page whose pointer is the racket (``mouse``): the first that points, until it
    #: closes; other pages watch
    _pointer_page: int | None = None
    _frames: deque = field(default_factory=lambda: deque(maxlen=100_000))
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _wakers: set = field(default_factory=set)
    _loop: Any = None
    _server: Any = None
    _thread: threading.Thread | None = None

    # -- the physics' side ------------------------------------------------------------------
    def start(self) -> str:
        """Serve the page; the URL it is at. A port in use is a one-line error."""
        _require_server()
        import uvicorn

        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise ConfigError(f"--port {self.port}: cannot serve the page there "
                              f"({exc.strerror or exc})") from None
        self.port = sock.getsockname()[1]
        config = uvicorn.Config(self._app(), log_level="warning", lifespan="off",
                                ws="auto", ws_ping_interval=None)
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._server.run, kwargs={"sockets": [sock]},
                                        name="bounce-virtual-display", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + 10.0
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise ConfigError(f"the page's server did not start on port {self.port}")
            time.sleep(0.01)
        return self.url

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def stop(self) -> None:
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def wait_for_page(self, timeout_s: float | None = None) -> bool:
        """Block until a page is connected (True) or ``timeout_s`` passed (False)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while self.connections == 0:
            if deadline is not None and time.monotonic() > deadline:
                return False
            time.sleep(_POLL_S)
        return True

    def publish(self, trial: int, sample: int, t_s: float, racket_m: float, ball_m: float,
                clock_s: float, impact: bool = False) -> None:
        """The ball and the racket at racket sample ``sample`` of ``trial`` (trial time
        ``t_s``), obtained at server clock ``clock_s``; shown ``delay_s`` after that."""
        status = self.status
        frame = {"type": "frame", "trial": trial, "sample": sample, "t": t_s,
                 "racket": _finite(racket_m), "ball": _finite(ball_m), "clock": clock_s,
                 "impact": impact,
                 "phase": status.phase, "remaining": status.remaining_s,
                 "score": status.score, "best": status.best, "trials": status.trials,
                 "message": status.message, "duration": status.duration_s}
        with self._lock:
            self._frames.append(frame)
        self._wake()

    def show_status(self, **changes: Any) -> None:
        """Change what the page shows beside the ball (and send it at once)."""
        for key, value in changes.items():
            setattr(self.status, key, value)
        with self._lock:
            last = dict(self._frames[-1]) if self._frames else {
                "type": "frame", "trial": 0, "sample": -1, "t": 0.0, "racket": None,
                "ball": None, "impact": False}
        last.update({"phase": self.status.phase, "remaining": self.status.remaining_s,
                     "score": self.status.score, "best": self.status.best,
                     "trials": self.status.trials, "trial": self.status.trial or last["trial"],
                     "message": self.status.message, "duration": self.status.duration_s,
                     "clock": time.perf_counter(),
                     "sample": -1})
        with self._lock:
            self._frames.append(last)
        self._wake()

    def pointer_samples(self, duration_s: float, t0_clock: float) -> Iterator[tuple[float, float]]:
        """The pointer's heights as racket samples (trial time from ``t0_clock``), in
        increasing time, until ``duration_s`` of wall clock; nothing while no page is there
        (the physics takes the silence as a gap and the ball waits)."""
        while not self.pointer.empty():  # what came before the trial
            self.pointer.get_nowait()
        last = -math.inf
        while True:
            now = time.perf_counter() - t0_clock
            if now > duration_s:
                return
            try:
                clock, x = self.pointer.get(timeout=min(0.05, max(duration_s - now, 1e-3)))
            except queue.Empty:
                continue
            t = clock - t0_clock
            if t <= last or t < 0.0 or not math.isfinite(x):
                continue
            if t > duration_s:
                return
            last = t
            yield t, x

    # -- the server's side ------------------------------------------------------------------
    def _wake(self) -> None:
        loop = self._loop
        if loop is not None:
            for event in list(self._wakers):
                loop.call_soon_threadsafe(event.set)

    def _frame_due(self) -> dict | None:
        """The latest frame whose time to be shown has come (``delay_s`` after its sample)."""
        with self._lock:
            if not self._frames:
                return None
            if self.delay_s <= 0.0:
                return self._frames[-1]
            due = time.perf_counter() - self.delay_s
            while len(self._frames) > 1 and self._frames[1]["clock"] <= due:
                self._frames.popleft()
            return self._frames[0] if self._frames[0]["clock"] <= due else None

    def _app(self):
        from starlette.applications import Starlette
        from starlette.responses import HTMLResponse
        from starlette.routing import Route, WebSocketRoute
        from starlette.websockets import WebSocketDisconnect

        page = resources.files("bounce_cli.virtual").joinpath("page.html").read_text("utf-8")
        display = self

        async def index(request):
            view = {"low": display.view.low_m, "high": display.view.high_m,
                    "target": display.view.target_m, "mouse": display.mouse}
            return HTMLResponse(page.replace("/*VIEW*/null", json.dumps(view)),
                                headers={"Cache-Control": "no-store"})

        async def stream(websocket):
            await websocket.accept()
            display._loop = asyncio.get_running_loop()
            wake = asyncio.Event()
            display._wakers.add(wake)
            display.connections += 1
            display._opened += 1
            connection = display._opened

            async def send_frames():
                sent = None
                while True:
                    frame = display._frame_due()
                    if frame is not None and frame is not sent:
                        await websocket.send_text(json.dumps(frame, allow_nan=False))
                        sent = frame
                    if display.delay_s > 0.0:
                        await asyncio.sleep(0.002)
                    else:
                        await wake.wait()
                        wake.clear()

            async def receive():
                while True:
                    message = json.loads(await websocket.receive_text())
                    kind = message.get("type")
                    if kind == "ping":
                        await websocket.send_text(json.dumps({
                            "type": "pong", "page": message.get("page"),
                            "server": time.perf_counter()}))
                    elif kind == "drawn":
                        display._drawn(message, connection)
                    elif kind == "pointer":
                        display._pointed(message, connection)

            sender = asyncio.ensure_future(send_frames())
            try:
                await receive()
            except (WebSocketDisconnect, RuntimeError, ValueError):
                pass
            finally:
                sender.cancel()
                display._wakers.discard(wake)
                display.connections -= 1
                if display._pointer_page == connection:  # the next page that points
                    display._pointer_page = None

        return Starlette(routes=[Route("/", index), WebSocketRoute("/ws", stream)])

    def _drawn(self, message: dict, connection: int) -> None:
        """A frame the page drew: its delay from the racket sample, on the server's clock."""
        try:
            sample, trial = int(message["sample"]), int(message["trial"])
            drawn, clock = float(message["drawn"]), float(message["clock"])
        except (KeyError, TypeError, ValueError):
            return
        if sample < 0 or not (math.isfinite(drawn) and math.isfinite(clock)):
            return
        self.latency.append({"trial": trial, "sample": sample, "t_s": message.get("t"),
                             "connection": connection, "delay_ms": 1e3 * (drawn - clock),
                             "round_trip_ms": message.get("rtt")})

    def _pointed(self, message: dict, connection: int) -> None:
        """The pointer's height on page ``connection`` (0 at the bottom, 1 at the top), on
        the server's clock, as a racket height in metres; only the page that pointed first
        (and is still open) moves the racket: a second page, an experimenter's, watches."""
        try:
            y, clock = float(message["y"]), float(message["clock"])
        except (KeyError, TypeError, ValueError):
            return
        if not (math.isfinite(y) and math.isfinite(clock)):
            return  # no height: the page does not take the racket with it
        if self._pointer_page is None:
            self._pointer_page = connection
        if connection == self._pointer_page:
            self.pointer.put((clock, self.view.low_m + y * (self.view.high_m - self.view.low_m)))


def _finite(value: float) -> float | None:
    """JSON has no NaN: a missing height is null on the page."""
    return value if math.isfinite(value) else None


def latency_summary(rows: list[dict[str, Any]]) -> str:
    """'median m ms, 99th percentile p ms over n frames' of the drawn frames' delays."""
    import numpy as np

    delays = np.array([row["delay_ms"] for row in rows], float)
    if delays.size == 0:
        return "no frame drawn"
    return (f"sample to drawn frame: median {np.median(delays):.1f} ms, 99th percentile "
            f"{np.percentile(delays, 99):.1f} ms over {delays.size} frames")


class MouseSource:
    """``--racket mouse``: the pointer's height on the page as the racket, sampled at each
    frame the page draws (about 60 Hz, on the server's clock), for trying the set-up without
    a lab. A trial lasts ``duration_s`` of wall clock; while no page is connected no samples
    come and the ball waits (a gap)."""

    live = True

    def __init__(self, display: Display):
        self.display = display

    @property
    def description(self) -> str:
        return "mouse: the pointer's height on the page"

    def samples(self, trial: int, duration_s: float) -> Iterator[tuple[float, float]]:
        return self.display.pointer_samples(duration_s, time.perf_counter())
