"""The LSL source over loopback: a real outlet in the test publishing a sine racket (the
sender's timestamps), ``bounce virtual --racket lsl:<name>`` consuming it, bounded in time."""

from __future__ import annotations

import json
import math
import threading
import time
import uuid

import numpy as np
import pytest

import bounce_cli
from bounce_cli.paper.values import FIG3_MODEL as P

pylsl = pytest.importorskip("pylsl", reason="pylsl (the virtual extra) is not installed")

RATE = 1000.0


def publish(name: str, pieces, unit_scale: float = 1.0):
    """An outlet named ``name`` that, once a consumer is there, pushes each piece
    ``(t_from, t_to, pause_after_s)`` of the sine racket (times in s from a base stamp)."""
    info = pylsl.StreamInfo(name, "Mocap", 2, RATE, "float32", str(uuid.uuid4()))
    outlet = pylsl.StreamOutlet(info)

    def run():
        deadline = time.monotonic() + 20.0
        while not outlet.wait_for_consumers(0.1):
            if time.monotonic() > deadline:
                return
        base = pylsl.local_clock()
        w = P.omega
        for t_from, t_to, pause in pieces:
            for i in range(int(round(t_from * RATE)), int(round(t_to * RATE))):
                t = i / RATE
                # channel 1 is the racket height (channel 0 another marker)
                outlet.push_sample([0.0, P.racket_amplitude * math.sin(w * t) / unit_scale],
                                   base + t)
            time.sleep(pause)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return outlet, thread


def test_an_lsl_racket_gives_the_sine_source_s_impacts_and_a_stall_is_a_logged_gap():
    name = f"bounce-test-{uuid.uuid4().hex[:8]}"
    # 6 s, a 1.5 s stall (stream time and wall clock), then 4 s more: one trial of 10 s
    outlet, thread = publish(name, [(0.0, 3.0, 0.2), (4.5, 10.5, 0.0)], unit_scale=0.001)
    settings = {"display.headless": True, "trials": 1, "trial_s": 10.0, "lsl.channel": 1,
                "lsl.units": "mm",
                "lsl.give_up_s": 3.0}
    start = time.monotonic()
    live = bounce_cli.run("virtual", set={**settings, "racket": f"lsl:{name}"})
    assert time.monotonic() - start < 30.0
    thread.join(5.0)
    gaps = live.frames["gaps.csv"]
    assert len(gaps) == 1
    assert gaps["t_end_s"].iloc[0] - gaps["t_start_s"].iloc[0] == pytest.approx(1.5, abs=2e-3)
    sine = bounce_cli.run("virtual", set={"display.headless": True, "trials": 1, "trial_s": 10.0})
    a, b = sine.frames["impacts.csv"], live.frames["impacts.csv"]
    # before the stall the two are the same racket, sample for sample (impacts in a racket
    # cycle the stall cut short have no phase and are left out of impacts.csv: match on k)
    both = a[a["t_s"] < 2.9].merge(b, on="k", suffixes=("", "_live"))
    assert len(both) >= 2
    assert np.allclose(both["t_s"], both["t_s_live"], atol=1e-6)
    assert np.allclose(both["v_m_s"], both["v_m_s_live"], atol=1e-5)  # float32 samples in mm
    events = live.frames["events/s1_virtual_t1.csv"]  # every impact, the cut cycle's too
    assert np.allclose(events["t_s"][:3], a["t_s"][:3], atol=1e-6)
    del outlet


def test_no_such_stream_is_one_line(cli, user_error, tmp_path):
    user_error(cli("virtual", "--headless", "--racket", "lsl:no-such-stream-here", "--set",
                   "lsl.resolve_timeout_s=0.5", "--out", tmp_path / "x"), "no stream")
    assert not (tmp_path / "x").exists()


def test_a_stream_that_dies_ends_its_trial_and_run_json_says_how_long_it_was(tmp_path):
    """A stream silent for lsl.give_up_s ends the trial with a warning; the summary and
    run.json say how long the trial was (a review: run.json said "completed" and nothing
    else, the summary "1 trial(s) x 8 s")."""
    name = f"bounce-test-{uuid.uuid4().hex[:8]}"
    outlet, thread = publish(name, [(0.0, 3.0, 0.0)])  # 3 s, then silence
    out = tmp_path / "died"
    start = time.monotonic()
    with pytest.warns(UserWarning, match=r"no samples for 1 s: trial 1 ends there"):
        run = bounce_cli.run("virtual", set={
            "display.headless": True, "trials": 1, "trial_s": 8.0, "lsl.channel": 1,
            "lsl.give_up_s": 1.0, "racket": f"lsl:{name}"}, out=out)
    assert time.monotonic() - start < 30.0
    thread.join(5.0)
    assert run.summary[0].startswith("1 trial(s) of 3.0 s (trial_s 8 s; the racket's samples "
                                     "stopped)"), run.summary[0]
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "completed"
    assert record["trials_shorter"] == [{"trial": 1, "recorded_s": pytest.approx(3.0, abs=0.01)}]
    del outlet
