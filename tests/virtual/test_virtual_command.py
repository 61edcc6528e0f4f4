"""``bounce virtual`` headless: the protocol's perturbations, files bounce reads, replay."""

from __future__ import annotations

import json
import math
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import bounce_cli

PROTOCOL = Path(__file__).resolve().parents[2] / "configs" / "virtual" / "perturbation.yaml"
STEADY = PROTOCOL.with_name("steady.yaml")

#: the tests run without a page (--headless); the page has a test of its own
HEADLESS = {"display.headless": True}
SHORT = {**HEADLESS, "trials": 2, "trial_s": 12.0, "perturbations.every": 5, "seed": 3}


@pytest.mark.slow
def test_perturbation_protocol_every_fifth_impact_in_the_ranges(tmp_path):
    result = bounce_cli.run("virtual", config=PROTOCOL, set=SHORT,
                            out=tmp_path / "v")
    impacts = result.frames["impacts.csv"]
    for _, trial in impacts.groupby("trial"):
        k = trial["k"].to_numpy()
        expected = (k >= 4) & ((k - 4) % 5 == 0)
        assert np.array_equal(trial["perturbed"].to_numpy(), expected)
        alpha = trial["alpha"].to_numpy()
        low = (alpha >= 0.3) & (alpha <= 0.4)
        high = (alpha >= 0.6) & (alpha <= 0.7)
        assert np.all((low | high)[expected]) and np.all(alpha[~expected] == 0.5)
    # the two trials draw from streams of their own
    a1 = impacts.loc[(impacts["trial"] == 1) & impacts["perturbed"], "alpha"].to_numpy()
    a2 = impacts.loc[(impacts["trial"] == 2) & impacts["perturbed"], "alpha"].to_numpy()
    assert not np.array_equal(a1[:2], a2[:2])
    # alpha_measured by eq. 3 from the exact velocities is the alpha applied
    assert np.allclose(impacts["alpha_measured"], impacts["alpha"], atol=1e-9)
    manifest = pd.read_csv(tmp_path / "v" / "study.csv")
    assert list(manifest.columns) == ["file", "events", "subject", "condition", "trial"]
    for row in manifest.itertuples():
        assert (tmp_path / "v" / row.file).is_file() and (tmp_path / "v" / row.events).is_file()
    assert (tmp_path / "v" / "virtual.png").is_file()


@pytest.mark.slow
def test_extract_with_the_events_recovers_the_exact_impacts(tmp_path):
    """The recording and events are what ``bounce extract`` reads with no --set."""
    out = tmp_path / "v"
    run = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 10.0}, out=out)
    exact = run.frames["impacts.csv"]
    extracted = bounce_cli.run(
        "extract", set={"events": str(out / "events" / "s1_virtual_t1.csv")},
        data=out / "recordings" / "s1_virtual_t1.csv").frames["impacts.csv"]
    both = exact.merge(extracted, on="k", suffixes=("", "_x"))
    assert len(both) >= 8
    assert np.allclose(both["t_s"], both["t_s_x"], atol=1e-9)
    assert np.allclose(both["v_m_s"], both["v_m_s_x"], atol=2e-3)


def test_replay_of_a_sine_recording_gives_the_sine_source_s_impacts(tmp_path):
    sine = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 8.0})
    recording = sine.frames["recordings/s1_virtual_t1.csv"]
    path = tmp_path / "racket.csv"
    recording.to_csv(path, index=False)
    replay = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 8.0,
                                            "racket": f"replay:{path}"})
    a, b = sine.frames["impacts.csv"], replay.frames["impacts.csv"]
    assert len(a) == len(b) and np.allclose(a["t_s"], b["t_s"], atol=1e-9)
    assert np.allclose(a["v_m_s"], b["v_m_s"], atol=1e-9)


def test_samples_stamped_when_sent_are_left_out_not_flown_through(tmp_path):
    # every third sample of a 500 Hz racket stamped 10 us after the one before (a sender's
    # clock at sending, in bursts): the cubic through it moved at hundreds of m/s and threw
    # the ball kilometres up, without a word
    sine = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 8.0})
    recording = sine.frames["recordings/s1_virtual_t1.csv"].copy()
    t = recording["t_s"].to_numpy().copy()
    burst = np.arange(len(t)) % 3 == 2
    t[burst] = t[np.flatnonzero(burst) - 1] + 1e-5
    recording["t_s"] = t
    path = tmp_path / "racket.csv"
    recording.to_csv(path, index=False)
    with pytest.warns(UserWarning, match=r"racket sample\(s\) stamped less than 0.25 of a "
                                         r"sample interval .* left out"):
        replay = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 8.0,
                                                "racket": f"replay:{path}"})
    a, b = sine.frames["impacts.csv"], replay.frames["impacts.csv"]
    ball = replay.frames["recordings/s1_virtual_t1.csv"]["ball_x_m"]
    assert ball.max() < 2.0 and b["v_m_s"].abs().max() < 10.0
    # the racket sampled at 500 Hz with every third sample missing: the same bounces
    assert len(b) == len(a) and np.allclose(a["t_s"], b["t_s"], atol=1e-4)
    assert np.allclose(a["v_m_s"], b["v_m_s"], atol=1e-2)


def test_the_spacing_guard_judges_by_the_nominal_interval_or_the_recent_median():
    from bounce_cli.virtual.sources import SpacingGuard

    nominal = SpacingGuard(0.002)
    assert [nominal.accept(t) for t in (0.0, 0.002, 0.0021, 0.0026, 0.004)] == \
        [True, True, False, True, True]
    learned = SpacingGuard()  # no nominal rate: three spacings seen first
    kept = [learned.accept(t) for t in (0.0, 1e-5, 0.01, 0.02, 0.03, 0.03001, 0.04)]
    assert kept == [True, True, True, True, True, False, True] and learned.dropped == 1


def test_a_racket_sampled_at_60_hz_still_gives_the_impacts_their_phase():
    # a mouse's 60 Hz (or a slow stream): the racket's cycles were found with the default
    # 10 ms windows, none was, and impacts.csv held no row while the events held them all
    slow = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 8.0,
                                          "sample_rate_hz": 60.0})
    impacts = slow.frames["impacts.csv"]
    events = slow.frames["events/s1_virtual_t1.csv"]
    assert len(impacts) >= len(events) - 3 and len(impacts) >= 4
    # the phase of a 0.92 s racket's period-1 bounce (about 42 deg), within what 60 Hz allows
    assert np.all(np.abs(impacts["racket_period_s"] - 0.92) < 0.01)
    assert abs(float(impacts["theta_deg"].iloc[-1]) - 42.0) < 8.0


def test_a_drop_from_below_the_racket_is_one_line(cli, user_error, tmp_path):
    user_error(cli("virtual", "--headless", "--set", "launch.mode=drop", "--set",
                   "launch.height_m=-1", "--out", tmp_path / "x"),
               "--set: launch.height_m", "greater than 0")
    assert not (tmp_path / "x").exists()


def test_an_unknown_racket_source_is_one_line(cli, user_error, tmp_path):
    user_error(cli("virtual", "--headless", "--racket", "lsl", "--out", tmp_path / "x"),
               "unknown source")
    assert not (tmp_path / "x").exists()
    user_error(cli("virtual", "--headless", "--racket", "replay:nope.csv", "--out",
                   tmp_path / "y"),
               "no such file")
    user_error(cli("virtual", "--headless", "--racket", "replay:", "--out", tmp_path / "y"),
               "replay: names no recording")
    user_error(cli("virtual", "--headless", "--racket", f"replay:{tmp_path}", "--out",
                   tmp_path / "y"),
               "a folder, not a recording")
    assert not (tmp_path / "y").exists()


@pytest.mark.slow
def test_study_analyses_the_virtual_session_with_no_step_between(tmp_path, cli):
    out = tmp_path / "v"
    assert cli("virtual", "--headless", "--config", PROTOCOL, "--set",
               "trials=4", "--quiet", "--out", out).exit_code == 0
    result = cli("study", "--manifest", out / "study.csv", "--quiet", "--out",
                 tmp_path / "study")
    assert result.exit_code in (0, 1)  # 1: an analysis the data cannot support, in failures.csv
    impulse = pd.read_csv(tmp_path / "study" / "group_impulse.csv")
    assert set(impulse["direction"]) == {"decrease", "increase"}
    # the passive sine racket: Fig. 11's period modulation is flat
    period = impulse[impulse["quantity"] == "racket_period_s"]
    assert np.all(np.abs(period["mean"]) < 1e-9)


@pytest.mark.slow
def test_extract_at_a_restitution_below_the_contact_factor_s_zero(tmp_path):
    """alpha 0.25: K(alpha) of the contact's area is negative there; the impacts are still
    extracted (alpha measured by eq. 3), the contact duration is not measured (NaN)."""
    out = tmp_path / "v"
    bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 20.0, "model.alpha": 0.25,
                                   "model.racket_amplitude": 0.5}, out=out)
    impacts = bounce_cli.run("extract", data=out / "recordings" / "s1_virtual_t1.csv"
                             ).frames["impacts.csv"]
    assert len(impacts) >= 15
    measured = impacts["alpha_measured"].dropna()  # the first impact has no flight before it
    assert len(measured) >= len(impacts) - 1 and np.allclose(measured, 0.25, atol=2e-3)
    assert impacts["contact_s"].isna().all()


@pytest.mark.slow
def test_fig9_from_the_virtual_session_is_the_model_s_impulse_response(tmp_path):
    """Section 7's protocol on the passive sine racket with one size of perturbation each way
    (0.4, 0.6: inside the basin) and 40 impacts between them (relaxed to 0.5^35): the data
    side's Fig. 9 (``impulse --data`` on the session's impacts) is the full map's response at
    the data's parameters. What is left is the data side's reading of the sampled racket (its
    phase from the cycles' crossings, its amplitude and period measured): 7e-6 m/s and
    2.6e-4 deg at 1 kHz; the set-up's impacts themselves equal the map to 2e-7 m/s
    (test_physics)."""
    out = tmp_path / "v"
    bounce_cli.run("virtual", config=PROTOCOL, out=out, set={
        **HEADLESS, "trials": 10, "perturbations.every": 40, "perturbations.first": 5,
        "perturbations.ranges": [[0.6, 0.6], [0.4, 0.4]]})
    result = bounce_cli.run("impulse", data=out / "impacts.csv",
                            set={"data_analysis.settle_after_perturbation": 30})
    aligned, model = result.frames["aligned.csv"], result.frames["model_response.csv"]
    for side, alpha_p in (("decrease", 0.4), ("increase", 0.6)):
        curve = model[model["direction"] == side].sort_values("k")
        assert curve["alpha_p"].iloc[0] == pytest.approx(alpha_p, abs=1e-12)
        for quantity, column, tolerance in (("v_m_s", "dv_m_s", 2e-5),
                                            ("theta_deg", "dtheta_deg", 1e-3)):
            data = aligned[(aligned["quantity"] == quantity)
                           & (aligned["direction"] == side)].sort_values("k")
            assert len(data) == len(curve) >= 10 and data["n"].min() >= 4
            assert np.max(np.abs(data["mean"].to_numpy() - curve[column].to_numpy())) < tolerance


def _simulated_session(tmp_path, rounded: bool):
    """A simulate-recording session at 1 kHz without noise, its racket varied cycle by cycle
    (period and amplitude SD 1 cm / 10 ms), alpha 0.6 at every 8th impact: the recording's
    file (positions at full precision, or rounded to 0.1 micrometre as simulate-recording
    writes them) and the truth's impacts."""
    from bounce_cli.data.simulated_lab import simulate_session, truth_rows
    from bounce_cli.experiments.simulate_recording import POSITION_DECIMALS, RecordingConfig

    config = RecordingConfig.model_validate({
        "sample_rate_hz": 1000.0, "position_noise_m": 0.0, "velocity_noise_m_s": 0.0,
        "racket": {"period_sd_s": 0.01, "amplitude_sd_m": 0.01}, "trials": 1,
        "duration_s": 20.0, "perturbations": {"every": 8, "first": 4, "alphas": [0.6]}})
    (truth, (t, racket, ball)), = simulate_session(config.params, config.session())
    if rounded:
        racket, ball = np.round(racket, POSITION_DECIMALS), np.round(ball, POSITION_DECIMALS)
    path = tmp_path / ("rounded.csv" if rounded else "full.csv")
    pd.DataFrame({"trial": 1, "t_s": t, "racket_x_m": racket, "ball_x_m": ball}).to_csv(
        path, index=False, float_format="%.17g")
    return path, pd.DataFrame(truth_rows(truth))


@pytest.mark.parametrize("rounded, t_tol, v_tol", [
    (False, 1e-6, 1e-6),
    # 0.1 micrometre steps in the racket: its interpolated velocity is uncertain by about
    # 7 q / h = 7e-4 m/s at 1 kHz, and the impacts with it
    (True, 2e-4, 2e-3)])
@pytest.mark.slow
def test_replay_of_a_simulated_recording_gives_its_truth(tmp_path, rounded, t_tol, v_tol):
    path, truth = _simulated_session(tmp_path, rounded)
    launch = truth.iloc[0]  # the ball leaves the racket at the truth's first impact
    replay = bounce_cli.run("virtual", set={
        **HEADLESS, "racket": f"replay:{path}", "trials": 1, "trial_s": 20.0,
        "launch.mode": "state", "launch.t_s": float(launch["t_s"]),
        "launch.v_m_s": float(launch["v_m_s"]), "perturbations.every": 8,
        "perturbations.first": 3, "perturbations.ranges": [[0.6, 0.6]]}).frames["impacts.csv"]
    later = truth.iloc[1:].reset_index(drop=True)  # replay's impact k is the truth's k + 1
    both = later.assign(k=later["k"] - 1).merge(replay, on="k", suffixes=("", "_virtual"))
    assert len(both) >= len(later) - 1 >= 18
    assert np.all(both["alpha"] == both["alpha_virtual"]) and both["perturbed"].sum() >= 2
    assert np.max(np.abs(both["t_s"] - both["t_s_virtual"])) < t_tol
    assert np.max(np.abs(both["v_m_s"] - both["v_m_s_virtual"])) < v_tol


@pytest.mark.slow
def test_realtime_paces_a_headless_sine_and_leaves_the_physics_alone():
    settings = {**HEADLESS, "trials": 1, "trial_s": 2.5}
    start = time.monotonic()
    paced = bounce_cli.run("virtual", set={**settings, "display.realtime": True})
    assert time.monotonic() - start >= 2.5
    fast = bounce_cli.run("virtual", set=settings)
    a, b = fast.frames["impacts.csv"], paced.frames["impacts.csv"]
    assert len(a) == len(b) >= 1 and np.array_equal(a["t_s"], b["t_s"])


@pytest.mark.slow
@pytest.mark.parametrize("signum, how", [(signal.SIGINT, "Ctrl-C"), (signal.SIGTERM, "SIGTERM"),
                                         (signal.SIGHUP, "SIGHUP")])
def test_a_stop_signal_keeps_the_finished_trials(tmp_path, signum, how):
    """SIGINT (or kill, or a closed terminal) in trial 2 of a paced session: trial 1 is
    written whole, trial 2 left out (SIGTERM and SIGHUP once threw the session away)."""
    out = tmp_path / "v"
    process = subprocess.Popen(
        [sys.executable, "-m", "bounce_cli", "virtual", "--headless", "--realtime", "--set",
         "trials=3", "--set", "trial_s=2", "--out", str(out)],
        stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    seen = ""
    while "trial 1 of 3 done" not in seen:  # what a live session tells its operator
        line = process.stderr.readline()
        assert line, seen
        seen += line
    time.sleep(0.5)
    process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signum, stderr  # written, and said to be interrupted
    assert f"stopped by {how} in trial 2" in stdout + stderr
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "interrupted" and "trial 2" in record["interrupted"]
    assert sorted(p.name for p in (out / "recordings").iterdir()) == ["s1_virtual_t1.csv"]
    manifest = pd.read_csv(out / "study.csv")
    assert list(manifest["trial"]) == [1]
    recording = pd.read_csv(out / "recordings" / "s1_virtual_t1.csv")
    assert recording["t_s"].iloc[-1] == pytest.approx(2.0)


def test_a_session_recorded_live_is_not_replaced_without_force(tmp_path, cli, user_error):
    """A person's session (the page's mouse, an LSL stream: run.json's recorded_live) cannot
    be made again: a rerun into its folder needs --force (it was replaced silently)."""
    out = tmp_path / "v"
    args = ("virtual", "--headless", "--set", "trials=1", "--set", "trial_s=2", "--out", out)
    assert cli(*args).exit_code == 0
    assert "recorded_live" not in json.loads((out / "run.json").read_text())  # a sine racket
    assert cli(*args).exit_code == 0  # a simulated session is made again: replaced
    record = json.loads((out / "run.json").read_text())
    record["recorded_live"] = True
    (out / "run.json").write_text(json.dumps(record, indent=2) + "\n")
    before = (out / "impacts.csv").read_bytes()
    user_error(cli(*args), "holds a session recorded live", "--force")
    assert (out / "impacts.csv").read_bytes() == before
    assert cli(*args, "--force").exit_code == 0


def test_a_steady_session_s_study_skips_what_two_trials_cannot_answer(tmp_path, cli):
    # section 6's steady protocol (2 trials) studied as its summary says: learning (a trend
    # over trials) and regression (a line through the trials) need 3 trials; they are not
    # run, with the reason, and the study exits 0 (it exited 1 with two failure rows). With
    # the sine racket the ball does not vary beyond rounding: acf is not run either, with its
    # reason (it reported the correlations of rounding)
    out = tmp_path / "steady session"
    made = cli("virtual", "--headless", "--config", STEADY, "--set", "trial_s=25",
               "--out", out)
    assert made.exit_code == 0, made.output
    suggested = re.search(r"run `(bounce study [^`]+)`", made.stderr).group(1)
    words = shlex.split(suggested)
    result = cli(*words[1:], "--quiet")
    assert result.exit_code == 0, result.output
    said = " ".join(result.stderr.split())
    assert "learning: not run: " in said and "at least 3" in said
    assert "regression: not run: " in said
    study_dir = Path(words[words.index("--out") + 1])
    assert pd.read_csv(study_dir / "failures.csv").empty
    assert "acf: not run: the impacts barely vary" in said
    assert not (study_dir / "s1" / "virtual" / "acf" / "stability_data.csv").exists()


@pytest.mark.slow
def test_a_sine_racket_s_study_skips_the_line_through_equal_periods(tmp_path, cli):
    # three trials of the perturbation protocol with the sine racket: every trial at the
    # same racket period, so Fig. 7's line has one x; the study exited 1 with a failure row
    # where the docs promise "not run, with a warning" (as with two trials)
    out = tmp_path / "sine"
    made = cli("virtual", "--headless", "--config", PROTOCOL, "--set", "trials=3",
               "--set", "trial_s=15", "--out", out)
    assert made.exit_code == 0, made.output
    result = cli("study", "--manifest", out / "study.csv", "--out", tmp_path / "st",
                 "--quiet")
    assert result.exit_code == 0, result.output
    said = " ".join(result.stderr.split())
    assert "regression: not run: " in said and "eq. 15's slope is not determined" in said
    assert pd.read_csv(tmp_path / "st" / "failures.csv").empty
    # the pooled Fig. 7 neither: it printed a 'line' of R^2 0.98 through one period (a review)
    pooled = pd.read_csv(tmp_path / "st" / "group_regression.csv").iloc[0]
    assert "slope" not in pooled or np.isnan(pooled["slope"])
    assert pooled["note"].startswith("not fitted: the trials' squared racket periods span only")
    # group.csv's radii are NaN (acf did not run: perturbations every fifth impact), and
    # their notes say why (they were empty, the reason only in the warnings)
    group = pd.read_csv(tmp_path / "st" / "group.csv")
    for method in ("ols", "lag2", "varx_ols", "varx_lag2"):
        assert group[f"radius_{method}"].isna().all()
        assert group[f"radius_{method}_note"].str.startswith(
            "acf --data not run: the perturbations leave no run").all()


def test_a_lab_s_recording_is_replayed_by_its_own_column_names_and_units(tmp_path, cli,
                                                                          user_error):
    # replay.columns / replay.units, as bounce extract reads the file; a missing column names
    # the key as this command takes it (it named extract's 'columns.time', which virtual
    # refused as an unknown key)
    sine = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 8.0})
    recording = sine.frames["recordings/s1_virtual_t1.csv"]
    lab = tmp_path / "lab.csv"
    pd.DataFrame({"time_s": recording["t_s"], "paddle_mm": recording["racket_x_m"] * 1000.0}
                 ).to_csv(lab, index=False)
    user_error(cli("virtual", "--headless", "--racket", f"replay:{lab}", "--out",
                   tmp_path / "x"),
               "no column 't_s'", "set replay.columns.time")
    assert not (tmp_path / "x").exists()
    replay = bounce_cli.run("virtual", set={
        **HEADLESS, "trials": 1, "trial_s": 8.0, "racket": f"replay:{lab}",
        "replay.columns.time": "time_s", "replay.columns.racket": "paddle_mm",
        "replay.columns.trial": None, "replay.columns.ball": None,
        "replay.units.length": "mm"})
    a, b = sine.frames["impacts.csv"], replay.frames["impacts.csv"]
    assert len(a) == len(b) >= 5
    assert np.allclose(a["t_s"], b["t_s"], atol=1e-9)
    assert np.allclose(a["v_m_s"], b["v_m_s"], atol=1e-9)


def test_trials_the_source_or_the_launch_cut_short_are_said(tmp_path):
    # a replayed trial shorter than trial_s, and trials without an impact, ran without a word
    sine = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 8.0})
    path = tmp_path / "racket.csv"
    sine.frames["recordings/s1_virtual_t1.csv"].to_csv(path, index=False)
    with pytest.warns(UserWarning, match=r"trial_s = 12 s, but 2 trial\(s\) ended with their "
                      r"racket .* trial 1 after 8\.0 s, trial 2 after 8\.0 s"):
        cut = bounce_cli.run("virtual", set={**HEADLESS, "trials": 2, "trial_s": 12.0,
                                             "racket": f"replay:{path}"})
    # the summary and the figures' caption say how long the trials were, not trial_s alone
    # (a review: "2 trial(s) x 40 s" beside the warning that both ended at 20 s)
    assert cut.summary[0].startswith("2 trial(s) of 8.0 s (trial_s 12 s; the racket's "
                                     "recording ended) ("), cut.summary[0]
    with pytest.warns(UserWarning, match=r"no impact in trial\(s\) 1, 2 within trial_s = 1\.01"):
        empty = bounce_cli.run("virtual", set={**HEADLESS, "trials": 2, "trial_s": 1.01})
    assert empty.frames["impacts.csv"].empty


@pytest.mark.parametrize("key", ["subject", "condition"])
@pytest.mark.parametrize("value", [".", ".."])
def test_a_name_the_study_would_refuse_is_one_line(cli, user_error, tmp_path, key, value):
    user_error(cli("virtual", "--headless", "--set", f"{key}={value}", "--out",
                   tmp_path / "x"),
               f"--set: {key}", "folder")
    assert not (tmp_path / "x").exists()


def test_a_visual_gain_s_session_starts_on_the_gained_racket_s_fixed_point():
    # the ball meets the virtual racket (a_r x visual_gain): fixed_point launches on its
    # period-1 orbit (eqs. 7, 8 at 0.45 m), where it started on the source's (0.3 m) and
    # bounced far from it
    import dataclasses

    from bounce_cli.model.params import ModelParams

    result = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 6.0,
                                            "visual_gain": 1.5, "model.racket_amplitude": 0.3})
    gained = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.45, racket_period=0.92)
    fixed = gained.fixed_point()
    first = result.frames["impacts.csv"].iloc[:3]
    assert np.allclose(first["theta_deg"], fixed.theta_deg, atol=1e-3)
    assert np.allclose(first["v_m_s"], fixed.v_m_s, atol=1e-4)
    assert "visual gain 1.5" in result.summary[0]
    assert dataclasses.replace(gained, racket_amplitude=0.3).fixed_point().theta_deg < 45.0


def test_a_noisy_racket_stream_is_said_to_shake_the_ball(tmp_path, cli):
    """A motion-capture racket with 0.2 mm of noise: the ball leaves each impact with the
    velocity of a cubic through the 4 latest samples, which turns that noise into ~0.1 m/s of
    noise in the ball's velocity after impact at 200 Hz (a review: an effective alpha SD of 1
    at 1 kHz), three times the paper's subjects' map noise, without a word. Said now, with the
    figure and what to do; a clean racket says nothing."""
    sine = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 8.0})
    recording = sine.frames["recordings/s1_virtual_t1.csv"].iloc[::5]  # 200 Hz
    clean = tmp_path / "clean.csv"
    recording.to_csv(clean, index=False)
    noisy = recording.assign(racket_x_m=recording["racket_x_m"] + np.random.default_rng(
        1).normal(0.0, 2e-4, len(recording)))
    noisy.to_csv(tmp_path / "noisy.csv", index=False)
    said = {}
    for name in ("clean", "noisy"):
        result = cli("virtual", "--headless", "--racket", f"replay:{tmp_path / name}.csv",
                     "--set", "trials=1", "--set", "trial_s=8", "--out", tmp_path / name,
                     "--quiet")
        assert result.exit_code == 0, result.output
        said[name] = " ".join(result.stderr.split())
    assert "noise" not in said["clean"]
    assert "the racket's samples carry about 0.2 mm of noise" in said["noisy"], said["noisy"]
    assert "of noise in the ball's velocity after each impact" in said["noisy"]
    assert "filter" in said["noisy"]


@pytest.mark.parametrize("scale, needle", [
    (0.0, "the racket moved by only 0 mm in trial 1: the wrong channel "
          "(replay.columns.racket)"),  # a constant channel
    (1000.0, "millimetres (0.3 m) typed for metres? (set replay.units.length)"),  # mm as m
])
def test_a_racket_that_cannot_be_a_person_s_is_said_after_its_trial(tmp_path, cli, scale,
                                                                   needle):
    """A stream's wrong channel (a constant) or positions in mm read as m: the session ran
    on without a word (a review). After each trial the racket's range is checked against what
    a person can do, once per session."""
    sine = bounce_cli.run("virtual", set={**HEADLESS, "trials": 1, "trial_s": 8.0})
    recording = sine.frames["recordings/s1_virtual_t1.csv"]
    racket = recording["racket_x_m"]
    recording = recording.assign(racket_x_m=racket.mean() + scale * (racket - racket.mean()))
    recording.to_csv(tmp_path / "racket.csv", index=False)
    result = cli("virtual", "--headless", "--racket", f"replay:{tmp_path / 'racket.csv'}",
                 "--set", "trials=3", "--set", "trial_s=2.5", "--out", tmp_path / "o",
                 "--quiet")
    said = " ".join(result.stderr.split())
    assert needle in said, said
    assert said.count("what a person can do") + said.count("moved by only") == 1


def test_the_score_counts_bounces_not_a_chatter_s_micro_hops():
    """A chatter's hops of 10-50 ms counted one point each on the page and in 'trial n done:
    N bounces', where bounce extract sees one contact (a review). Counted: impacts that left
    the ball off the racket after a flight of at least sticking_hop_s (the first one too)."""
    from bounce_cli.experiments.virtual import bounces
    from bounce_cli.virtual.physics import Impact

    def impact(hop_s: float, stuck: bool = False) -> Impact:
        return Impact(0, 0.0, -4.0, 4.0, 0.0, 1.0, -9.0, 0.5, False, hop_s, stuck)

    chatter = [impact(math.nan), impact(0.9), impact(0.03), impact(0.012), impact(0.011, True)]
    assert bounces(chatter) == 2
    assert bounces([impact(0.05), impact(0.049)]) == 1
