"""The simulated lab session (engine.recording, ``bounce simulate-recording``): its truth must
be the model's own motion, so that extraction can be held against it."""


import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from bounce_cli.cli.commands import app
from bounce_cli.model.flight import FlightSettings, simulate
from bounce_cli.model.params import ModelError, ModelParams
from bounce_cli.data.simulated_lab import (
    CycleRacket,
    SessionSettings,
    compliant_contact,
    next_contact,
    simulate_session,
    truth_rows,
)
from bounce_cli.data.impacts import EVENT_COLUMNS, MEASURED_COLUMNS, REQUIRED_COLUMNS

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
    assert list(truth.columns) == [*REQUIRED_COLUMNS, *EVENT_COLUMNS, *MEASURED_COLUMNS]
    assert sorted(recording["trial"].unique()) == [1, 2]
    assert len(recording) == 2 * (8 * 200 + 1)
    np.testing.assert_array_equal(events["t_s"], truth["t_s"])
    assert (out / "recording.png").stat().st_size > 10_000
    bad = runner.invoke(app, ["simulate-recording", "--out", str(tmp_path / "bad"), "--set",
                              "racket.period_sd_s=0.5"])
    assert bad.exit_code == 2 and "period_sd_s" in bad.stderr
    assert not (tmp_path / "bad").exists()


# -- a physical set-up (issue 24) -------------------------------------------------------------
BOOM = ModelParams(alpha=0.42, g=5.8, racket_amplitude=0.065, racket_period=0.55)
STILL = CycleRacket(np.array([1e9]), np.array([1.0]), np.array([0.1]))  # never moves


@pytest.mark.parametrize("alpha, contact_s", [(0.42, 0.01), (0.8, 0.03), (0.1, 0.005)])
def test_the_spring_damper_contact_has_its_duration_and_restitution(alpha, contact_s):
    """Without gravity, on a still racket, the integrated contact (DOP853, event at the
    release) gives the closed form's duration pi / omega_d and restitution exactly."""
    release, dy, solution = compliant_contact(2.0, -3.0, 0.0, STILL, alpha, contact_s)
    assert release - 2.0 == pytest.approx(contact_s, rel=1e-7)
    assert dy / 3.0 == pytest.approx(alpha, rel=1e-7)
    assert solution(2.0 + 0.5 * contact_s)[0] < -0.01 * 3.0 * contact_s  # compressed


def test_a_compliant_contact_tends_to_the_instant_impact():
    """Equivalent impacts of ever shorter contacts converge to the instantaneous ones (eq. 3)
    of the same session (no noise: the flights are the same up to the contacts' effect)."""
    base = dict(n_trials=1, duration_s=6.0, velocity_noise_m_s=0.0)
    (instant, _), = simulate_session(BOOM, SessionSettings(**base))
    (short, _), = simulate_session(BOOM, SessionSettings(contact_s=1e-4, **base))
    (finite, _), = simulate_session(BOOM, SessionSettings(contact_s=0.01, **base))
    n = min(len(instant.impact_t), len(short.impact_t))
    assert n >= 9
    np.testing.assert_allclose(short.impact_t[:n], instant.impact_t[:n], atol=5e-5)
    np.testing.assert_allclose(short.impact_v[:n], instant.impact_v[:n], atol=2e-3)
    rows = truth_rows(short)
    np.testing.assert_allclose(rows["alpha_measured"], 0.42, atol=2e-3)
    # a 10 ms contact: the same g on both flights, so they meet once, inside the contact
    touches = np.array([touch for touch, _, _ in finite.contacts])
    for t_k in finite.impact_t:
        touch, release, _ = finite.contacts[int(np.searchsorted(touches, t_k)) - 1]
        assert touch < t_k < release and release - touch == pytest.approx(0.01, abs=5e-4)
    rows = truth_rows(finite)
    assert np.all(rows["v_in_m_s"] < 0) and np.all(rows["contact_s"] > 0.009)
    assert abs(np.mean(rows["alpha_measured"]) - 0.42) < 0.03


def test_the_ball_follows_its_free_flights_outside_the_contacts_and_stays_above():
    """Samples away from each contact lie on the parabolas through the equivalent impact
    (position of the incoming flight there, v_k and v_in); within the contacts the ball is
    below its free flights and never more than a few mm into the racket."""
    (truth, _), = simulate_session(BOOM, SessionSettings(n_trials=1, duration_s=6.0,
                                                         contact_s=0.01, alpha_sd=0.03,
                                                         seed=2))
    rows = truth_rows(truth)
    touches = np.array([touch for touch, _, _ in truth.contacts])
    for j in range(1, len(rows["t_s"]) - 1):
        t_k = rows["t_s"][j]
        touch, release, _ = truth.contacts[int(np.searchsorted(touches, t_k)) - 1]
        after = np.linspace(release + 1e-4, release + 0.1, 50)
        before = np.linspace(touch - 0.1, touch - 1e-4, 50)
        x_eq = float(truth.ball_position(np.array([touch]))[0]) + (
            rows["v_in_m_s"][j] * (t_k - touch) + 0.5 * 5.8 * (t_k - touch) ** 2)
        out = x_eq + rows["v_m_s"][j] * (after - t_k) - 2.9 * (after - t_k) ** 2
        inc = x_eq + rows["v_in_m_s"][j] * (before - t_k) - 2.9 * (before - t_k) ** 2
        np.testing.assert_allclose(truth.ball_position(after), out, atol=1e-8)
        np.testing.assert_allclose(truth.ball_position(before), inc, atol=1e-8)
        inside = np.linspace(touch, release, 30)[1:-1]
        depth = truth.ball_position(inside) - truth.racket.position(inside)
        assert depth.max() < 0.0 and depth.min() > -0.02
    assert np.std(rows["alpha"][1:]) == pytest.approx(0.03, rel=0.5)


def test_the_second_harmonic_keeps_the_crossing_and_has_its_amplitude():
    """b sin(2 theta) is odd about the mid-position crossing: the racket is at its mid-position
    at each cycle start, rising; (peak - trough) / 2 is the closed form's (dense check)."""
    session = SessionSettings(n_trials=1, duration_s=10.0, harmonic2_m=0.012, seed=1,
                              amplitude_sd_m=0.003)
    (truth, _), = simulate_session(PAPER, session)
    r = truth.racket
    assert np.max(np.abs(r.position(r.starts[1:10]))) < 1e-12
    assert np.all(r.velocity(r.starts[1:10] + 1e-9) > 0)
    rows = truth_rows(truth)
    for j in range(3):
        c = int(r.cycle_index(rows["t_s"][j]))
        t = np.linspace(r.starts[c], r.ends[c], 200_001)[:-1]
        x = r.position(t)
        assert rows["racket_amplitude_m"][j] == pytest.approx(0.5 * np.ptp(x), abs=1e-9)
        assert rows["racket_amplitude_m"][j] > r.amplitudes[c] + 1e-4
    h = 1e-5  # AC by finite differences of the position
    t = rows["t_s"][:5]
    fd = (r.position(t + h) - 2 * r.position(t) + r.position(t - h)) / h**2
    np.testing.assert_allclose(rows["racket_acc_g"][:5] * 9.81, fd, atol=1e-3)


@pytest.mark.slow
def test_the_racket_disturbance_starts_at_each_release_and_is_gone_after_its_duration():
    session = SessionSettings(n_trials=1, duration_s=8.0, disturbance_m=0.003,
                              disturbance_s=0.1, contact_s=0.01)
    (truth, _), = simulate_session(BOOM, session)
    r = truth.racket
    smooth = CycleRacket(r.starts, r.periods, r.amplitudes)
    releases = np.array([release for _, release, _ in truth.contacts])
    np.testing.assert_allclose(r.disturbance_starts, releases)
    t = np.linspace(1.0, 7.0, 600_001)
    d = r.position(t) - smooth.position(t)
    since = t - releases[np.maximum(np.searchsorted(releases, t) - 1, 0)]
    assert np.max(np.abs(d[since > 0.1])) < 1e-15  # exactly gone after 100 ms
    assert np.max(np.abs(d[since < 0.1])) > 0.5 * 0.003  # the shape peaks at 0.61 A
    assert np.max(np.abs(np.diff(d))) < 1e-4  # continuous
    # the ball stays above the disturbed racket between contacts (the first contact is found)
    free = np.ones(t.shape, dtype=bool)
    for touch, release, _ in truth.contacts:
        free &= ~((t >= touch) & (t <= release))
    assert (truth.ball_position(t) - r.position(t))[free].min() > -1e-9


def test_the_racket_draws_do_not_hinge_on_the_last_bit_of_the_period():
    """The data side simulates sessions lasting a whole number of quarter racket periods at the
    period measured from the data: the number of cycles drawn (and so where the amplitudes'
    draws start) must not change when that period moves by an ulp."""
    import math

    from bounce_cli.data.simulated_lab import racket_cycles_drawn

    flips_before = 0
    for i in range(400):
        tau = 0.5 + i * 0.00037
        quarters = 2 * (40 + i % 60)  # even: (duration + 3 tau) / (tau / 2) is an integer
        counts, old_counts = set(), set()
        for t in (np.nextafter(tau, 0.0), tau, np.nextafter(tau, 1.0)):
            params = ModelParams(alpha=0.5, g=9.81, racket_period=t, racket_amplitude=0.1)
            settings = SessionSettings(n_trials=1, duration_s=quarters * t * 1.25)
            counts.add(racket_cycles_drawn(params, settings))
            ratio = (settings.duration_s + 3 * t) / (0.5 * t)
            old_counts.add(int(math.ceil(ratio)) + 4)
        assert len(counts) == 1, tau
        flips_before += len(old_counts) > 1
    assert flips_before > 0  # the plain ceil did hinge on them: this test can fail


def test_an_ulp_in_the_racket_period_moves_a_simulated_session_by_rounding_only():
    from bounce_cli.data.simulated_runs import RacketSession, simulate_runs

    session = RacketSession(3e-4, 1.2e-4, 0.05)
    impacts = []
    for tau in (0.5754, np.nextafter(0.5754, 1.0)):
        params = ModelParams(alpha=0.5, g=9.81, racket_period=tau, racket_amplitude=0.1)
        runs, _ = simulate_runs(params, session, [60, 60], np.random.SeedSequence(5))
        impacts.append(np.concatenate([np.column_stack([r.v_m_s, r.theta_rad, r.racket_amplitude_m])
                                      for r in runs]))
    np.testing.assert_allclose(impacts[0], impacts[1], rtol=1e-9, atol=1e-12)
