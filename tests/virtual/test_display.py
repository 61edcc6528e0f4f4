"""The set-up's page server on 127.0.0.1 with websocket clients of its own (no browser): which
page's pointer is the racket."""

from __future__ import annotations

import json
import time

import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")
websockets_sync = pytest.importorskip("websockets.sync.client")

from bounce_cli.virtual.display import Display, View  # noqa: E402


def pointer(page, y: float) -> None:
    page.send(json.dumps({"type": "pointer", "y": y, "clock": time.perf_counter()}))


def heights(display: Display, expect: int, timeout_s: float = 5.0) -> list[float]:
    """The next ``expect`` pointer heights the server took (m), or those it took in time."""
    got: list[float] = []
    deadline = time.monotonic() + timeout_s
    while len(got) < expect and time.monotonic() < deadline:
        try:
            got.append(display.pointer.get(timeout=0.05)[1])
        except Exception:
            continue
    return got


@pytest.fixture
def served():
    """A mouse-racket Display on 127.0.0.1 (a free port) and its websocket address."""
    display = Display(View(low_m=0.0, high_m=1.0), mouse=True, port=0)
    display.start()
    try:
        yield display, display.url.replace("http://", "ws://") + "ws"
    finally:
        display.stop()


def test_one_page_s_pointer_is_the_racket_and_a_second_page_only_watches(served):
    """With ``--racket mouse`` every connected page sent its pointer, and the racket jumped
    between an experimenter's page and the subject's screen. The first page that points is
    the racket until it closes; then the next page that points is."""
    display, ws = served
    with websockets_sync.connect(ws, open_timeout=5) as first, \
            websockets_sync.connect(ws, open_timeout=5) as second:
        pointer(first, 0.25)
        assert heights(display, 1) == [0.25]
        pointer(second, 0.75)  # watching only: not taken
        pointer(first, 0.5)
        assert heights(display, 2, timeout_s=1.0) == [0.5]
    with websockets_sync.connect(ws, open_timeout=5) as third:
        deadline = time.monotonic() + 5.0
        while display.connections > 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        pointer(third, 0.75)  # the first page closed: the next one that points is taken
        assert heights(display, 1) == [0.75]


def test_a_page_whose_pointer_height_is_not_finite_does_not_take_the_racket(served):
    """Ownership went to the first page that sent a pointer message, before its height was
    checked: a page sending NaN (a broken script, a page without a pointer) took the racket
    and kept the subject's page from moving it."""
    display, ws = served
    with websockets_sync.connect(ws, open_timeout=5) as broken, \
            websockets_sync.connect(ws, open_timeout=5) as subject:
        pointer(broken, float("nan"))  # json.dumps writes NaN, which the server parses
        time.sleep(0.2)
        pointer(subject, 0.5)
        assert heights(display, 1) == [0.5]
