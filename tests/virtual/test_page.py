"""The set-up's page for real: ``bounce virtual`` serving on 127.0.0.1, headless Chromium
drawing it, the latency log, a reload mid-session, the mouse as the racket."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time

import numpy as np
import pandas as pd
import pytest

import bounce_cli

pytestmark = pytest.mark.slow

#: the ball's and the racket's colours on the page (page.html)
BALL_RGB = (0xF0, 0xA0, 0x20)
RACKET_RGB = (0xD8, 0xDD, 0xE3)


def start_session(out, *settings: str):
    """``bounce virtual`` with a page on a free port, as a user starts it; (process, url,
    stderr lines so far: a list that fills while it runs)."""
    args = [sys.executable, "-m", "bounce_cli", "virtual", "--port", "0",
            "--out", str(out)]
    for setting in settings:
        args += ["--set", setting]
    process = subprocess.Popen(args, stderr=subprocess.PIPE, stdout=subprocess.PIPE,
                               text=True)
    lines: list[str] = []
    found = threading.Event()

    def read():
        for line in process.stderr:
            lines.append(line)
            if "http://127.0.0.1:" in line:
                found.set()

    process.reader = threading.Thread(target=read, daemon=True)
    process.reader.start()
    if not found.wait(60.0):
        process.kill()
        raise AssertionError("no URL printed: " + "".join(lines))
    url = re.search(r"http://127\.0\.0\.1:\d+/", "".join(lines)).group(0)
    return process, url, lines


def colour_share(path, rgb) -> float:
    import matplotlib.image

    image = (matplotlib.image.imread(path)[..., :3] * 255).round()
    return float(np.mean(np.all(np.abs(image - rgb) < 8, axis=-1)))


def test_the_page_draws_ball_and_racket_logs_latency_and_survives_a_reload(browser, tmp_path):
    out = tmp_path / "v"
    process, url, lines = start_session(
        out, "trials=2", "trial_s=4", "rest_s=1", "display.countdown_s=1")
    page = browser(url)
    time.sleep(2.5)  # the countdown, then the first trial's bounces
    shot = page.screenshot(tmp_path / "page.png")
    time.sleep(1.0)
    page.reload()  # mid-session: the page reconnects and the session goes on
    try:
        process.wait(60.0)
    finally:
        process.kill()
    assert process.returncode == 0, "".join(lines)
    assert colour_share(shot, BALL_RGB) > 1e-4 and colour_share(shot, RACKET_RGB) > 1e-3
    # the session over and its server gone, the page says so (it said "connection lost:
    # reconnecting" for ever)
    time.sleep(1.0)
    assert page.evaluate("document.getElementById('status').textContent") == "session over"
    assert page.evaluate("document.getElementById('message').textContent") == \
        "done: thank you"
    # ball and racket are drawn in a trial, not frozen on the screen between trials
    for phase, shown in (("trial", True), ("rest", False), ("countdown", False)):
        page.evaluate(f"frame = {{...frame, phase: '{phase}', ball: 0.5, racket: 0.0}}; "
                      "draw(); 0")
        between = page.screenshot(tmp_path / f"{phase}.png")
        assert (colour_share(between, BALL_RGB) > 1e-4) == shown, phase
        assert (colour_share(between, RACKET_RGB) > 1e-3) == shown, phase
    # a countdown's or rest's last frame drawn after its end says 1 second to go, not 0
    for phase, message in (("countdown", "get ready: 1"), ("rest", "rest: next trial in 1 s")):
        assert page.evaluate(
            f"frame = {{...frame, phase: '{phase}', remaining: 0}}; draw(); "
            "document.getElementById('message').textContent") == message
    latency = pd.read_csv(out / "latency.csv")
    assert list(latency.columns) == ["trial", "sample", "t_s", "connection", "delay_ms",
                                     "round_trip_ms"]
    assert set(latency["trial"]) == {1, 2} and latency["connection"].nunique() >= 2
    assert len(latency) > 100  # frames drawn at the screen's refresh over 8 s of trials
    delay = latency["delay_ms"].to_numpy()
    assert np.all(np.isfinite(delay)) and np.median(delay) < 250.0
    process.reader.join(10.0)
    summary = "".join(lines) + process.stdout.read()
    assert "sample to drawn frame: median" in summary, summary
    print(summary)
    # the page and the pacing do not touch the physics: the headless run's impacts
    headless = bounce_cli.run("virtual", set={"display.headless": True, "trials": 2,
                                              "trial_s": 4.0})
    a, b = headless.frames["impacts.csv"], pd.read_csv(out / "impacts.csv")
    assert len(a) == len(b) and np.allclose(a["t_s"], b["t_s"], atol=1e-9)


def test_the_mouse_is_the_racket(browser, tmp_path):
    """Pointer moves dispatched to the page (as a mouse would) are the recorded racket."""
    out = tmp_path / "m"
    low, high = -0.5, 1.5
    process, url, lines = start_session(
        out, "racket=mouse", "trials=1", "trial_s=3", "display.countdown_s=0",
        f"display.view_m=[{low},{high}]",
        "launch.mode=drop", "launch.height_m=1.0")
    page = browser(url, width=800, height=600)
    start = time.monotonic()
    try:
        while process.poll() is None and time.monotonic() - start < 30.0:
            t = time.monotonic() - start
            height = 0.2 * np.sin(2 * np.pi * t / 0.9)  # a racket of 0.2 m at 0.9 s
            height_px = page.evaluate("window.innerHeight")  # as the page maps it now
            page.move_pointer(400, height_px * (1 - (height - low) / (high - low)))
            time.sleep(0.01)
        process.wait(30.0)
    finally:
        process.kill()
    assert process.returncode == 0, "".join(lines)
    recording = pd.read_csv(out / "recordings" / "s1_virtual_t1.csv")
    racket = recording["racket_x_m"].to_numpy()
    assert len(racket) > 60  # the page's frames over 3 s
    assert np.all(np.abs(racket) < 0.2 + 0.01)  # the pointer's heights, within a pixel
    assert racket.max() > 0.1 and racket.min() < -0.1
    assert np.all(np.diff(recording["t_s"]) > 0)


def test_a_mouse_that_never_moves_is_a_racket_at_rest_and_a_closed_page_a_left_out_trial(
        browser, tmp_path):
    """The page sends the pointer's height from the start (the racket's rest, height 0) even
    before the mouse moves; a trial during which no page is open has no racket samples: it is
    left out with a warning and the session goes on."""
    out = tmp_path / "r"
    # the rest lets the page close before trial 2 starts (its backlog is dropped then)
    process, url, lines = start_session(out, "racket=mouse", "trials=2", "trial_s=2",
                                        "rest_s=3", "display.countdown_s=0")
    page = browser(url, width=800, height=600)
    deadline = time.monotonic() + 30.0
    while not any("trial 1 of 2 done" in line for line in lines):
        assert time.monotonic() < deadline, "".join(lines)
        time.sleep(0.05)
    page.close()  # trial 2 runs with no page
    try:
        process.wait(30.0)
    finally:
        process.kill()
    process.reader.join(10.0)
    text = "".join(lines)
    assert process.returncode == 0, text
    assert "trial 2: fewer than 4 racket samples came" in text
    # run.json says so too, beside "completed" (a script reading it saw a complete session)
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "completed" and record["trials_left_out"] == [2]
    recordings = sorted(p.name for p in (out / "recordings").iterdir())
    assert recordings == ["s1_virtual_t1.csv"]
    racket = pd.read_csv(out / "recordings" / recordings[0])["racket_x_m"].to_numpy()
    assert len(racket) > 60 and np.all(np.abs(racket) < 0.02)  # at rest, within a pixel


#: what the page shows when it has lost its server (page.html's overlay)
LOST = "connection to bounce lost"


def shown_text(page) -> str:
    """The page's text as it is shown (innerText leaves out what is hidden)."""
    return page.evaluate("document.body.innerText") or ""


def within(seconds: float, condition, what: str) -> float:
    """Wait until ``condition()`` holds, at most ``seconds``; how long it took (s)."""
    start = time.monotonic()
    while not condition():
        if time.monotonic() - start > seconds:
            raise AssertionError(f"{what}: not within {seconds} s")
        time.sleep(0.05)
    return time.monotonic() - start


def test_the_page_says_its_server_is_gone_and_clears_when_it_is_back(browser, tmp_path):
    """A page whose server stalls or stops says so within about a second (it showed the last
    frame, ball and all, as if the session were live) and draws no ball; when the server
    answers again, or is back on the same port, the notice goes and the page is live again."""
    from bounce_cli.virtual.display import Display, View

    display = Display(View(low_m=-0.2, high_m=1.5), port=0)
    display.start()
    again = None
    try:
        display.show_status(phase="trial", trial=1, trials=2, score=3, duration_s=60.0)
        display.publish(1, 0, 0.0, 0.0, 0.8, time.perf_counter())
        page = browser(display.url)
        within(10.0, lambda: page.evaluate("frame !== null && offset !== null"), "a frame")
        live = page.screenshot(tmp_path / "live.png")
        assert colour_share(live, BALL_RGB) > 1e-4 and LOST not in shown_text(page)
        # a stall: the server's event loop blocked (the connection open, nothing comes)
        display._loop.call_soon_threadsafe(time.sleep, 2.5)
        took = within(2.0, lambda: LOST in shown_text(page), "the stall shown")
        assert took > 0.5, took  # not at once: a second of silence is the sign
        within(3.0, lambda: LOST not in shown_text(page), "the notice gone after the stall")
        # the server stops (the session over or its process killed: the socket closes)
        display.stop()
        within(2.0, lambda: LOST in shown_text(page), "the lost connection shown")
        text = shown_text(page)
        assert "reconnecting" in text and "bounces 3" not in text, text
        lost = page.screenshot(tmp_path / "lost.png")
        # no ball, no racket (a drawn racket covers 1e-3 of the screen; the notice's light
        # text has a few pixels of its colour)
        assert colour_share(lost, BALL_RGB) < 1e-5 and colour_share(lost, RACKET_RGB) < 5e-4
        # a server back on the same port: the page reconnects by itself, the notice goes
        again = Display(View(low_m=-0.2, high_m=1.5), port=display.port)
        again.start()
        again.show_status(phase="waiting", trials=1, message="waiting for the set-up")
        within(3.0, lambda: LOST not in shown_text(page)
               and "waiting for the set-up" in shown_text(page), "the page live again")
    finally:
        display.stop()
        if again is not None:
            again.stop()


def test_a_killed_session_does_not_leave_a_live_looking_page(browser, tmp_path):
    """``bounce virtual`` killed in a countdown: the page stops counting down and says that
    the connection is lost (it froze on 'get ready')."""
    process, url, lines = start_session(tmp_path / "k", "trials=1", "trial_s=30",
                                        "display.countdown_s=30")
    try:
        page = browser(url)
        within(10.0, lambda: "get ready" in shown_text(page), "the countdown")
        process.kill()
        within(2.0, lambda: LOST in shown_text(page), "the lost connection shown")
        assert "get ready" not in shown_text(page)
    finally:
        process.kill()
        process.wait(10.0)
