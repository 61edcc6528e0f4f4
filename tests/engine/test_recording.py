"""The simulated lab session (engine.recording, ``bounce simulate-recording``): its truth must
be the model's own motion, so that extraction can be held against it."""


import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from bounce_cli.cli import app
from bounce_cli.engine import FlightSettings, ModelError, ModelParams, simulate
from bounce_cli.engine.recording import (
    SessionSettings,
    next_contact,
    simulate_session,
    truth_rows,
)
from bounce_cli.impacts import EVENT_COLUMNS, REQUIRED_COLUMNS

PAPER = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)
VARIED = SessionSettings(n_trials=2, duration_s=20.0, velocity_noise_m_s=0.03,
                         period_sd_s=0.005, amplitude_sd_m=0.003, drift_amplitude_m=0.03,
                         drift_period_s=15.0, perturb_every=10, perturb_alphas=(0.4, 0.6),
                         seed=5)


def test_without_variation_the_impacts_are_those_of_the_engines_flight_simulation():
    """Independent route: engine.flight.simulate (exact integrator, first-impact solver in
    phase) from the same launch gives the same impacts as the time-stepping safe search."""
    session = SessionSettings(n_trials=1, duration_s=30.0, velocity_noise_m_s=0.0)
    # launched at the fixed point: period-1 from the start
    (truth, _), = simulate_session(ModelParams(0.5, 9.81, 0.30, 0.92), session)
    start = truth.racket.starts[0]
    fp = PAPER.fixed_point()
    traj = simulate(fp.theta_rad, fp.v_m_s, PAPER, 32.0, FlightSettings())
    t_engine = np.array([im.t_s for im in traj.impacts]) + start
    v_engine = np.array([im.v_after_m_s for im in traj.impacts])
    keep = t_engine >= 0.0
    n = len(truth.impact_t)
    np.testing.assert_allclose(truth.impact_t, t_engine[keep][:n], atol=1e-9)
    np.testing.assert_allclose(truth.impact_v, v_engine[keep][:n], atol=1e-9)
    # and a transient (launch off the fixed point) through a perturbation agrees too
    perturbed = SessionSettings(n_trials=1, duration_s=12.0, perturb_every=100, perturb_first=2,
                                perturb_alphas=(0.6,))
    (truth, _), = simulate_session(PAPER, perturbed)
    rows = truth_rows(truth)
    k = 2
    traj = simulate(rows["theta_rad"][k], rows["v_m_s"][k], PAPER, 8.0, FlightSettings())
    t_next = np.array([im.t_s for im in traj.impacts]) - traj.t0 + rows["t_s"][k]
    m = min(len(t_next), len(rows["t_s"]) - k - 1)
    np.testing.assert_allclose(rows["t_s"][k + 1:k + 1 + m], t_next[:m], atol=1e-9)
    np.testing.assert_allclose(rows["v_m_s"][k + 1:k + 1 + m],
                               [im.v_after_m_s for im in traj.impacts][:m], atol=1e-9)


def test_the_next_contact_is_the_first_one():
    """Between consecutive impacts the ball stays above the racket (dense check), on a
    racket whose cycles vary and whose mid-position drifts."""
    for truth, _ in simulate_session(PAPER, VARIED):
        t = np.linspace(truth.impact_t[0], truth.impact_t[-1], 400_001)
        gap = truth.ball_position(t) - truth.racket.position(t)
        assert gap.min() > -1e-9
        # and at each impact the ball is on the racket
        at = truth.ball_position(truth.impact_t) - truth.racket.position(truth.impact_t)
        assert np.max(np.abs(at)) < 1e-9


def test_next_contact_near_grazing_finds_the_first_touch():
    """A flight that barely clears the racket's peak must not skip a grazing contact."""
    session = SessionSettings(n_trials=1, duration_s=10.0)
    (truth, _), = simulate_session(PAPER, session)
    racket = truth.racket
    c = 3
    t_peak = racket.starts[c] + racket.periods[c] / 4.0
    # a ball falling onto the racket's peak from 1 mm above at rest: touches near the peak
    t0 = t_peak - 0.05
    x_peak = float(racket.position(t_peak))
    x0 = x_peak + 0.001 + 0.5 * 9.81 * 0.05**2
    hit = next_contact(t0, x0, 0.0, 9.81, racket, t0 + 1.0)
    t = np.linspace(t0, hit, 20001)
    gap = x0 - 0.5 * 9.81 * (t - t0) ** 2 - racket.position(t)
    assert gap[:-1].min() > -1e-12 and abs(gap[-1]) < 1e-9


def test_truth_is_the_models_impact_law_and_phase():
    """Eq. 3 at every impact (without noise), theta linear in each racket cycle, AC the
    racket's acceleration, period and amplitude those of the cycle."""
    session = SessionSettings(n_trials=1, duration_s=20.0, period_sd_s=0.01,
                              amplitude_sd_m=0.004, perturb_every=5, perturb_alphas=(0.4, 0.6))
    (truth, _), = simulate_session(PAPER, session)
    r, rows = truth.racket, truth_rows(truth)
    t = rows["t_s"]
    c = r.cycle_index(t)
    theta = 2 * np.pi * (t - r.starts[c]) / r.periods[c]
    np.testing.assert_allclose(rows["theta_rad"], theta, atol=1e-12)
    np.testing.assert_allclose(rows["theta_deg"], np.degrees(theta), atol=1e-10)
    assert np.all((rows["theta_deg"] >= 0) & (rows["theta_deg"] < 360))
    w = 2 * np.pi / r.periods[c]
    np.testing.assert_allclose(rows["racket_acc_g"] * 9.81, -r.amplitudes[c] * w**2 * np.sin(theta),
                               atol=1e-12)
    np.testing.assert_allclose(rows["racket_period_s"], r.periods[c])
    # eq. 3: v+ = v_r - alpha (v- - v_r), v- from the previous flight (eq. 2)
    v_before = rows["v_m_s"][:-1] - 9.81 * rows["hop_s"][:-1]
    v_r = r.amplitudes[c] * w * np.cos(theta)
    expected = v_r[1:] - rows["alpha"][1:] * (v_before - v_r[1:])
    np.testing.assert_allclose(rows["v_m_s"][1:], expected, atol=1e-9)
    # apex: v^2 / 2g above the impact point, relative to the (undrifted) mid-position 0
    np.testing.assert_allclose(rows["ball_apex_m"][:-1],
                               r.position(t[:-1]) + rows["v_m_s"][:-1] ** 2 / (2 * 9.81))


def test_perturbations_follow_the_configured_pattern():
    session = SessionSettings(n_trials=1, duration_s=30.0, perturb_every=8, perturb_first=4,
                              perturb_alphas=(0.4, 0.6))
    (truth, _), = simulate_session(PAPER, session)
    rows = truth_rows(truth)
    k = rows["k"]
    expected = (k >= 4) & ((k - 4) % 8 == 0)
    np.testing.assert_array_equal(rows["perturbed"], expected)
    np.testing.assert_array_equal(rows["alpha"][expected],
                                  [0.4, 0.6, 0.4, 0.6][:expected.sum()])
    assert np.all(rows["alpha"][~expected] == 0.5)
    # a perturbed alpha changes the velocity after impact as eq. 3 says: down for 0.4
    first = np.flatnonzero(expected)[0]
    assert rows["v_m_s"][first] < rows["v_m_s"][first - 1] - 0.3


def test_trials_have_their_own_streams_and_runs_are_reproducible():
    two = simulate_session(PAPER, VARIED)
    again = simulate_session(PAPER, VARIED)
    three = simulate_session(PAPER, SessionSettings(**{**VARIED.__dict__, "n_trials": 3}))
    for (a, sa), (b, _sb), (c, sc) in zip(two, again, three):
        np.testing.assert_array_equal(a.impact_t, b.impact_t)
        np.testing.assert_array_equal(a.impact_t, c.impact_t)
        np.testing.assert_array_equal(sa[2], sc[2])
    assert not np.array_equal(two[0][0].impact_v[:5], two[1][0].impact_v[:5])


def test_sampling_and_measurement_noise():
    session = SessionSettings(n_trials=1, duration_s=10.0, sample_rate_hz=250.0,
                              position_noise_m=0.002, ball_marker_offset_m=0.02)
    (truth, (t, racket, ball)), = simulate_session(PAPER, session)
    assert len(t) == 2501 and t[1] == pytest.approx(0.004) and t[-1] == pytest.approx(10.0)
    resid_r = racket - truth.racket.position(t)
    resid_b = ball - 0.02 - truth.ball_position(t)
    assert np.std(resid_r) == pytest.approx(0.002, rel=0.06)
    assert np.std(resid_b) == pytest.approx(0.002, rel=0.06)
    assert abs(np.corrcoef(resid_r, resid_b)[0, 1]) < 0.06


def test_a_resting_start_launches_at_the_fixed_point():
    session = SessionSettings(n_trials=1, duration_s=12.0, rest_s=3.0)
    (truth, (t, racket, ball)), = simulate_session(PAPER, session)
    rows = truth_rows(truth)
    fp = PAPER.fixed_point()
    assert rows["t_s"][0] == pytest.approx(3.0 + fp.theta_rad / PAPER.omega)
    assert rows["v_m_s"][0] == pytest.approx(fp.v_m_s)
    before = t < rows["t_s"][0]
    np.testing.assert_allclose(ball[before], racket[before])  # resting on the racket
    assert np.ptp(racket[t < 3.0]) == 0.0  # the racket is still


def test_a_session_falling_into_sticking_is_a_clear_error():
    wild = SessionSettings(n_trials=1, duration_s=40.0, perturb_every=3,
                           perturb_alphas=(0.3, 0.7))
    with pytest.raises(ModelError, match="sticking"):
        simulate_session(PAPER, wild)


runner = CliRunner()


def test_simulate_recording_command_writes_recording_events_and_truth(tmp_path):
    out = tmp_path / "sim"
    result = runner.invoke(app, ["simulate-recording", "--out", str(out), "--set", "trials=2",
                                 "--set", "duration_s=8", "--quiet"])
    assert result.exit_code == 0, result.output
    recording = pd.read_csv(out / "recording.csv")
    events = pd.read_csv(out / "events.csv")
    truth = pd.read_csv(out / "truth.csv")
    assert list(recording.columns) == ["trial", "t_s", "racket_x_m", "ball_x_m"]
    assert list(events.columns) == ["trial", "t_s", "alpha"]
    assert list(truth.columns) == [*REQUIRED_COLUMNS, *EVENT_COLUMNS]
    assert sorted(recording["trial"].unique()) == [1, 2]
    assert len(recording) == 2 * (8 * 200 + 1)
    np.testing.assert_array_equal(events["t_s"], truth["t_s"])
    assert (out / "recording.png").stat().st_size > 10_000
    bad = runner.invoke(app, ["simulate-recording", "--out", str(tmp_path / "bad"), "--set",
                              "racket.period_sd_s=0.5"])
    assert bad.exit_code == 2 and "period_sd_s" in bad.stderr
    assert not (tmp_path / "bad").exists()
