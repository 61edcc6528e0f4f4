"""Extraction (engine.extraction, ``bounce extract``) held against known truth: simulated
sessions (engine.recording) and ``bounce trajectory``'s own motion, degraded as lab files are.

Accuracy targets (issue 13; stated in the README):
(a) 1 kHz, no measurement noise: every theta within 0.05 deg, v within 2 mm/s, AC within 0.01 g;
(b) 200 Hz, 0.5 mm position noise: RMS errors theta <= 1 deg, v <= 0.03 m/s, AC <= 0.1 g;
(c) as (b) without the ball (impact times from the events, v_k from eq. 1).
"""

import functools
import math

import numpy as np
import pandas as pd
import pytest
from scipy.signal import savgol_filter
from typer.testing import CliRunner

from bounce_cli.cli.commands import app
from bounce_cli.model.params import ModelParams
from bounce_cli.data.extraction import (
    ExtractionSettings,
    contact_shape_factor,
    extract_trial,
    local_derivatives,
    local_fit,
    match_impacts,
    pooled_gravity,
)
from bounce_cli.data.simulated_lab import SessionSettings, simulate_session, truth_rows
from bounce_cli.data.impacts import EVENT_COLUMNS, MEASURED_COLUMNS, REQUIRED_COLUMNS

PAPER = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)
BASE = dict(n_trials=2, duration_s=20.0, velocity_noise_m_s=0.04, perturb_every=8,
            perturb_alphas=(0.4, 0.6))
CASE_A = SessionSettings(sample_rate_hz=1000.0, **BASE)
CASE_B = SessionSettings(sample_rate_hz=200.0, position_noise_m=0.0005, period_sd_s=0.005,
                         amplitude_sd_m=0.002, seed=3, **BASE)
QUANTITIES = ("theta_deg", "v_m_s", "racket_acc_g", "racket_period_s", "racket_amplitude_m",
              "hop_s", "ball_apex_m")
runner = CliRunner()


@functools.lru_cache(maxsize=None)
def session(settings: SessionSettings):
    return simulate_session(PAPER, settings)


def errors_against_truth(trials, *, ball=True, events=False, settings=None, transform=None):
    """Extraction errors of every matched impact, and (found, true) impact counts."""
    settings = ExtractionSettings() if settings is None else settings
    errors = {q: [] for q in QUANTITIES}
    found = total = 0
    for truth, (t, racket, b) in trials:
        rows = truth_rows(truth)
        if transform is not None:
            t, racket, b = transform(t, racket, b)
        result = extract_trial(t, racket, b if ball else None,
                               truth.impact_t if events else None, None, settings)
        idx = match_impacts(rows["t_s"], result.impacts["t_s"])
        assert np.all(idx >= 0), "an extracted impact matches no true impact"
        found += len(idx)
        total += len(rows["t_s"])
        for q in QUANTITIES:
            d = result.impacts[q] - rows[q][idx]
            if q == "theta_deg":
                d = (d + 180.0) % 360.0 - 180.0
            errors[q].append(d[np.isfinite(d)])
    return {q: np.concatenate(v) for q, v in errors.items()}, found, total


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


# -- building blocks --------------------------------------------------------------------------
def test_local_polynomial_is_savitzky_golay_at_the_samples():
    rng = np.random.default_rng(0)
    t = np.arange(400) * 0.005
    x = 0.3 * np.sin(2 * np.pi * t / 0.92) + 0.001 * rng.standard_normal(t.size)
    for window, degree in ((21, 4), (11, 2), (31, 3)):
        half = (window // 2) * 0.005
        expected = savgol_filter(x, window, degree, deriv=2, delta=0.005)
        for i in (50, 123, 300):
            assert local_derivatives(t, x, t[i], half, degree)[2] == pytest.approx(
                expected[i], rel=1e-9, abs=1e-9)


def test_one_local_fit_serves_value_slope_and_curvature():
    """The racket's fits at an impact are done once (``local_fit``) for its position, velocity
    and AC: the same numbers, bit for bit, as ``local_derivatives``; a line has no curvature."""
    rng = np.random.default_rng(3)
    t = np.arange(300) * 0.004
    x = 0.2 * np.sin(2 * np.pi * t / 0.8) + 0.0005 * rng.standard_normal(t.size)
    for t0, half, degree in ((0.5013, 0.02, 3), (0.7, 0.04, 4), (0.31, 0.02, 1)):
        fit = local_fit(t, x, t0, half, degree)
        assert (fit.x, fit.v, fit.acc) == local_derivatives(t, x, t0, half, degree)
    assert local_fit(t, x, 0.5, 0.02, 1).acc == 0.0


def test_second_derivative_of_a_sine_between_samples():
    """At any time (not only at samples) on a pure sine: -a w^2 sin(w t) to 1e-4 relative."""
    t = np.arange(0.0, 3.0, 0.005)
    w = 2 * np.pi / 0.92
    for t0 in (1.0, 1.0021, 1.4567):
        acc = local_derivatives(t, 0.3 * np.sin(w * t), t0, 0.1, 4)[2]
        assert acc == pytest.approx(-0.3 * w**2 * np.sin(w * t0), rel=1e-3, abs=1e-3)


def test_match_impacts_by_nearest_time():
    truth = np.array([0.3, 1.2, 2.1, 3.0])
    np.testing.assert_array_equal(match_impacts(truth, [1.21, 2.05, 2.6, 3.0]), [1, 2, -1, 3])


# -- accuracy (a), (b), (c) -------------------------------------------------------------------
def test_accuracy_a_1khz_without_noise():
    errors, found, total = errors_against_truth(session(CASE_A))
    assert found >= total - 2 * CASE_A.n_trials  # at most the impact in each trial's last,
    assert np.max(np.abs(errors["theta_deg"])) <= 0.05  # incomplete racket cycle is missing
    assert np.max(np.abs(errors["v_m_s"])) <= 0.002
    assert np.max(np.abs(errors["racket_acc_g"])) <= 0.01
    assert np.max(np.abs(errors["racket_period_s"])) <= 1e-5
    assert np.max(np.abs(errors["hop_s"])) <= 1e-6


def test_accuracy_b_200hz_half_a_millimetre_noise():
    errors, found, total = errors_against_truth(session(CASE_B))
    assert found >= total - 2 * CASE_B.n_trials
    assert rms(errors["theta_deg"]) <= 1.0
    assert rms(errors["v_m_s"]) <= 0.03
    assert rms(errors["racket_acc_g"]) <= 0.1
    # what we measure (README): a tenth of the targets or better
    assert rms(errors["theta_deg"]) <= 0.15 and rms(errors["v_m_s"]) <= 0.001
    assert rms(errors["racket_acc_g"]) <= 0.04
    assert rms(errors["racket_amplitude_m"]) <= 0.001
    assert rms(errors["ball_apex_m"]) <= 0.002


def test_accuracy_c_events_without_the_ball():
    errors, found, total = errors_against_truth(session(CASE_B), ball=False, events=True)
    assert found >= total - 2 * CASE_B.n_trials
    assert rms(errors["theta_deg"]) <= 1.0
    assert rms(errors["v_m_s"]) <= 0.03
    assert rms(errors["racket_acc_g"]) <= 0.1
    assert rms(errors["v_m_s"]) <= 0.002 and np.max(np.abs(errors["hop_s"])) == 0.0


def test_events_with_the_ball_give_the_logged_times():
    errors, _, _ = errors_against_truth(session(CASE_B), events=True)
    assert rms(errors["v_m_s"]) <= 0.001 and np.max(np.abs(errors["hop_s"])) == 0.0


# -- messy recordings -------------------------------------------------------------------------
def test_racket_drift_and_cycle_variation_are_followed():
    drifting = SessionSettings(sample_rate_hz=200.0, position_noise_m=0.0005,
                               drift_amplitude_m=0.03, drift_period_s=15.0, seed=7, **BASE)
    errors, found, total = errors_against_truth(session(drifting))
    assert found >= total - 2 * drifting.n_trials
    assert rms(errors["theta_deg"]) <= 0.3
    assert rms(errors["ball_apex_m"]) <= 0.003
    # the same without handling the drift (mid-position from one window over the whole
    # trial) is visibly worse: the test would catch a lost drift correction
    flat, _, _ = errors_against_truth(session(drifting),
                                      settings=ExtractionSettings(mid_window_s=1e3))
    assert rms(flat["theta_deg"]) > 3 * rms(errors["theta_deg"])


def test_short_gaps_are_bridged_and_impacts_in_long_gaps_dropped():
    trials = session(CASE_B)
    truth, (t, racket, ball) = trials[0]
    rng = np.random.default_rng(1)
    ball_g, racket_g = ball.copy(), racket.copy()
    for start in rng.choice(np.arange(100, len(t) - 100), 25, replace=False):
        ball_g[start:start + 4] = np.nan  # 20 ms gaps: bridged
    for start in rng.choice(np.arange(100, len(t) - 100), 10, replace=False):
        racket_g[start:start + 3] = np.nan
    rows = truth_rows(truth)
    lost = rows["t_s"][5]
    i = np.searchsorted(t, lost)
    ball_g[i - 20:i + 20] = np.nan  # 0.2 s without the ball around impact 5: dropped
    result = extract_trial(t, racket_g, ball_g, s=ExtractionSettings())
    idx = match_impacts(rows["t_s"], result.impacts["t_s"])
    assert 5 not in idx and np.all(idx >= 0)
    assert len(idx) >= len(rows["t_s"]) - 3
    assert any(reason.startswith("gap") and abs(tt - lost) < 0.5 for tt, reason in result.excluded)
    assert rms(result.impacts["v_m_s"] - rows["v_m_s"][idx]) <= 0.03
    theta_err = (result.impacts["theta_deg"] - rows["theta_deg"][idx] + 180) % 360 - 180
    assert rms(theta_err) <= 1.0
    # the impact before the long gap has no known hop (the next contact is in the gap)
    before = np.flatnonzero(idx == 4)
    assert before.size == 1 and math.isnan(result.impacts["hop_s"][before[0]])
    assert np.array_equal(result.impacts["k"], idx)  # k counts the lost impact
    # with events the impact in the gap is known and dropped, the others keep their times
    logged = extract_trial(t, racket_g, ball_g, rows["t_s"], None, ExtractionSettings())
    assert 5 not in logged.impacts["k"]
    assert any(reason.startswith("gap") and tt == lost for tt, reason in logged.excluded)


def test_a_resting_start_is_skipped_until_bouncing_begins():
    # the still racket drifts: its crossings of the mid-position are not racket cycles
    resting = SessionSettings(n_trials=1, duration_s=15.0, rest_s=4.0, sample_rate_hz=200.0,
                              position_noise_m=0.0005, velocity_noise_m_s=0.04, seed=2,
                              drift_amplitude_m=0.03, drift_period_s=10.0)
    errors, found, total = errors_against_truth(session(resting))
    truth, (t, racket, ball) = session(resting)[0]
    result = extract_trial(t, racket, ball, s=ExtractionSettings())
    assert result.impacts["t_s"].min() > 4.0  # nothing while the ball rests
    assert found >= total - 2  # the launch (no racket cycle before it) and the last one
    assert rms(errors["v_m_s"]) <= 0.03 and rms(errors["theta_deg"]) <= 1.0


def test_the_launch_from_rest_is_timed_like_every_other_bounce():
    """Target (a) at a resting start (1 kHz, no noise): the racket stands still, then moves
    from its mid-position with its full velocity. The first cycle's start was fitted across
    that kink (a cubic over +-20 ms: 5 ms early), so the launch contact's phase was 1.7 deg off
    and its cycle's period 5 ms long; the crossing is now fitted on the moving side only."""
    resting = SessionSettings(sample_rate_hz=1000.0, rest_s=1.0, **BASE)
    errors, found, total = errors_against_truth(session(resting))
    assert found >= total - 2
    assert np.abs(errors["theta_deg"]).max() <= 0.05  # measured 6e-5 (was 1.7)
    assert np.abs(errors["racket_period_s"]).max() <= 1e-4
    # and at 200 Hz with 0.5 mm noise, where the still racket dithers about its mid-position
    # (the crossing is fitted from its last still sample): measured max 0.14 deg (was 6.8)
    noisy = SessionSettings(sample_rate_hz=200.0, position_noise_m=0.0005, rest_s=1.0, **BASE)
    errors, found, total = errors_against_truth(session(noisy))
    assert found >= total - 2
    assert np.abs(errors["theta_deg"]).max() <= 0.5


@pytest.mark.parametrize("ulps", [-4, -1, 1, 4])
def test_a_racket_resting_at_its_mid_position_starts_its_cycle_whatever_the_last_bits(ulps):
    """The racket rests exactly at its mid-position before the launch; whether it is below
    the least-squares mid-position (so that its start is an upward crossing) was decided by
    the last bits of that fit, which differ between BLAS kernels (OPENBLAS_CORETYPE Zen and
    Haswell found the cycle, Prescott and SkylakeX lost it and the launch impact with it).
    Moving the still samples by a few ulps of the racket's scale, either way, must not change
    the decision: the first cycle starts at the launch (1.0 s) and every impact is found."""
    resting = SessionSettings(sample_rate_hz=1000.0, rest_s=1.0, **BASE)
    truth, (t, racket, ball) = session(resting)[0]
    still = t <= 1.0
    shift = ulps * np.spacing(0.3)  # the racket's amplitude: its positions' scale
    racket, ball = racket.copy(), ball.copy()
    racket[still] += shift
    ball[still] += shift
    result = extract_trial(t, racket, ball, s=ExtractionSettings())
    assert result.cycles.crossings[0] == pytest.approx(1.0, abs=1e-6)
    idx = match_impacts(truth_rows(truth)["t_s"], result.impacts["t_s"])
    assert len(idx) == len(truth.impact_t) - 1  # all but the last (no complete cycle after)
    assert [reason for _, reason in result.excluded][:1] == [
        "sticking: the ball rested on the racket for 0.087 s"]  # the racket's start, not a bounce


@pytest.mark.parametrize("params, rate, noise, rms_theta", [
    (PAPER, 1000.0, 0.0005, 0.05),  # measured 0.019 deg (was: 175 contacts not reported)
    (PAPER, 500.0, 0.0005, 0.05),   # measured 0.023 (was RMS 1.44, worst 9.2 deg)
    (PAPER, 250.0, 0.002, 0.3),     # measured 0.17 (was 92 of 168 found)
    (ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.103, racket_period=0.57),
     1000.0, 0.001, 0.2),           # measured 0.11; a short racket period: slow separation
], ids=["1kHz-0.5mm", "500Hz-0.5mm", "250Hz-2mm", "short-racket-1kHz-1mm"])
@pytest.mark.slow
def test_noise_at_high_sampling_rates_makes_no_spurious_contacts(params, rate, noise, rms_theta):
    """The ball's velocity jump over one sample: 0.5 mm of noise at 1 kHz is 1.2 m/s (SD),
    above the 1 m/s threshold near the racket, and the spurious contacts split the flights
    (wrong impacts, k skipping numbers, `bounce acf` then finding no run of consecutive
    impacts). Now the jump is taken over 10 ms with a threshold of 4 robust SDs, and 10 ms
    are kept away from each contact: every impact found (but each trial's first and last),
    k consecutive, errors growing with the noise as at 200 Hz."""
    settings = SessionSettings(n_trials=2, duration_s=30.0, sample_rate_hz=rate,
                               position_noise_m=noise, velocity_noise_m_s=0.04, seed=5)
    trials = simulate_session(params, settings)
    errors, found, total = errors_against_truth(trials)
    assert found >= total - 2 * len(trials)
    assert rms(errors["theta_deg"]) <= rms_theta
    for _truth, (t, racket, ball) in trials:
        result = extract_trial(t, racket, ball, s=ExtractionSettings())
        assert np.all(np.diff(result.impacts["k"]) == 1)
        assert not result.excluded or all(
            reason == "outside a complete racket cycle" for _, reason in result.excluded)


@pytest.mark.slow
def test_a_recording_ending_before_the_last_peak_keeps_the_cycle_before():
    """40 s at 1 kHz: the racket's last upward crossing (39.79 s) comes less than a quarter
    cycle before the end, so no peak follows it; it still closes the cycle before it, whose
    impact was lost as "outside a complete racket cycle" (a new-user review). Only the impact
    after it, in the incomplete cycle, has no phase."""
    forty = SessionSettings(n_trials=2, duration_s=40.0, sample_rate_hz=1000.0,
                            velocity_noise_m_s=0.04, perturb_every=8, perturb_alphas=(0.4, 0.6))
    trials = session(forty)
    errors, found, total = errors_against_truth(trials)
    assert found == total - len(trials)
    for _truth, (t, racket, ball) in trials:
        result = extract_trial(t, racket, ball, s=ExtractionSettings())
        last_start = result.cycles.crossings[-1]
        assert t[-1] - (last_start + result.cycles.periods[-1]) < 0.25 * 0.92
        assert [reason for _, reason in result.excluded] == ["outside a complete racket cycle"]


def test_marker_offset_is_measured_and_only_shifts_the_apex():
    offset = SessionSettings(sample_rate_hz=200.0, position_noise_m=0.0005,
                             ball_marker_offset_m=0.03, seed=4, **BASE)
    truth, (t, racket, ball) = session(offset)[0]
    rows = truth_rows(truth)
    plain = extract_trial(t, racket, ball, s=ExtractionSettings())
    assert plain.measured_offset_m == pytest.approx(0.03, abs=0.001)
    told = extract_trial(t, racket, ball, s=ExtractionSettings(ball_offset_m=0.03))
    idx = match_impacts(rows["t_s"], told.impacts["t_s"])
    assert rms(told.impacts["ball_apex_m"] - rows["ball_apex_m"][idx]) <= 0.002
    np.testing.assert_allclose(plain.impacts["v_m_s"], told.impacts["v_m_s"], atol=1e-3)


def test_passes_sharing_the_racket_cycles_give_the_same_impacts():
    """extract_all's passes at another g and marker offset reuse the first pass's racket
    cycles (``cache``): each pass's impacts equal, bit for bit, a fresh extraction's."""
    offset = SessionSettings(sample_rate_hz=200.0, position_noise_m=0.0005,
                             ball_marker_offset_m=0.03, seed=4, **BASE)
    truth, (t, racket, ball) = session(offset)[0]
    cache: dict = {}
    for settings in (ExtractionSettings(), ExtractionSettings(g=9.79),
                     ExtractionSettings(g=9.79, ball_offset_m=0.03)):
        shared = extract_trial(t, racket, ball, s=settings, cache=cache)
        fresh = extract_trial(t, racket, ball, s=settings)
        assert shared.impacts.keys() == fresh.impacts.keys()
        for name, column in fresh.impacts.items():
            np.testing.assert_array_equal(shared.impacts[name], column, err_msg=name)
        np.testing.assert_array_equal(shared.se_theta_rad, fresh.se_theta_rad)
    assert cache["racket"] is not None


def test_chatter_is_flagged_not_reported():
    """A double contact 2 ms apart: the 2 ms hop is not a bounce."""
    truth, (t, racket, ball) = session(CASE_A)[0]
    rows = truth_rows(truth)
    events = np.sort(np.append(rows["t_s"], rows["t_s"][6] + 0.002))
    result = extract_trial(t, racket, None, events, None, ExtractionSettings())
    assert np.all(result.impacts["hop_s"][np.isfinite(result.impacts["hop_s"])] >= 0.05)
    assert any(reason.startswith("chatter") for _, reason in result.excluded)
    assert not np.any(np.isclose(result.impacts["t_s"], rows["t_s"][6]))
    # events outside the recording are listed, and k stays the event's index in the log
    logged = np.concatenate([[-0.4], rows["t_s"], [t[-1] + 0.3]])
    shifted = extract_trial(t, racket, None, logged, None, ExtractionSettings())
    assert sum("outside the recording" in reason for _, reason in shifted.excluded) == 2
    idx = match_impacts(rows["t_s"], shifted.impacts["t_s"])
    np.testing.assert_array_equal(shifted.impacts["k"], idx + 1)


# -- round trip with bounce trajectory --------------------------------------------------------
@pytest.mark.slow
def test_round_trip_with_bounce_trajectorys_csv(tmp_path):
    out = tmp_path / "traj"
    made = runner.invoke(app, ["trajectory", "--out", str(out), "--quiet"])
    assert made.exit_code == 0, made.output
    extracted = tmp_path / "ex"
    result = runner.invoke(app, [
        "extract", "--data", str(out / "trajectory.csv"), "--out", str(extracted), "--quiet",
        "--set", "columns.trial=case"])
    assert result.exit_code == 0, result.output
    ours = pd.read_csv(extracted / "impacts.csv")
    theirs = pd.read_csv(out / "impacts.csv")
    track = pd.read_csv(out / "trajectory.csv")
    for case in ("period-1", "sticking"):
        mine, ref = ours[ours.trial == case], theirs[theirs.case == case]
        idx = match_impacts(ref["t_s"].to_numpy(), mine["t_s"].to_numpy(), 0.01)
        assert np.all(idx >= 0)
        for q, tol in (("theta_deg", 1e-5), ("v_m_s", 1e-9), ("racket_acc_g", 2e-3)):
            np.testing.assert_allclose(mine[q], ref[q].to_numpy()[idx], atol=tol, err_msg=q)
    p1 = ours[ours.trial == "period-1"]
    assert len(p1) == len(theirs[theirs.case == "period-1"]) - 2  # launch, last cycle
    # the sticking case: every stuck phase of the trajectory is flagged, no short hop reported
    excluded = pd.read_csv(extracted / "excluded.csv")
    stuck = (track[track.case == "sticking"]["state"] == "stuck").astype(int).to_numpy()
    stuck_phases = int(np.sum(np.diff(stuck) == 1))
    flagged = excluded[(excluded.trial == "sticking")
                       & excluded.reason.str.startswith(("sticking", "chatter"))]
    assert stuck_phases >= 5 and len(flagged) == stuck_phases
    assert ours[ours.trial == "sticking"]["hop_s"].min() >= 0.05


# -- the command: files, units, columns, events, C3D, errors ----------------------------------
@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "sim"
    result = runner.invoke(app, ["simulate-recording", "--out", str(out), "--quiet",
                                 "--set", "trials=3", "--set", "duration_s=12"])
    assert result.exit_code == 0, result.output
    return out


def extract_cli(tmp_path, *args):
    out = tmp_path / "ex"
    result = runner.invoke(app, ["extract", "--out", str(out), "--quiet", *args])
    return result, out


@pytest.mark.slow
def test_researcher_workflow_mm_ms_other_names_and_events(simulated, tmp_path):
    """`bounce extract --data my_lab.csv --events my_events.csv --set units.length=mm`."""
    rec = pd.read_csv(simulated / "recording.csv")
    lab = pd.DataFrame({"Subject trial": rec["trial"].map({1: "A", 2: "B", 3: "C"}),
                        "time [ms]": rec["t_s"] * 1000, "paddle_z": rec["racket_x_m"] * 1000,
                        "ball_z": rec["ball_x_m"] * 1000})
    lab.to_csv(tmp_path / "my_lab.csv", index=False)
    events = pd.read_csv(simulated / "events.csv")
    events["trial"] = events["trial"].map({1: "A", 2: "B", 3: "C"})
    events["t_s"] *= 1000
    events.to_csv(tmp_path / "my_events.csv", index=False)
    result, out = extract_cli(
        tmp_path, "--data", str(tmp_path / "my_lab.csv"), "--events",
        str(tmp_path / "my_events.csv"), "--set", "units.length=mm", "--set", "units.time=ms",
        "--set", "columns.trial=Subject trial", "--set", "columns.time=time [ms]",
        "--set", "columns.racket=paddle_z", "--set", "columns.ball=ball_z")
    assert result.exit_code == 0, result.output
    impacts = pd.read_csv(out / "impacts.csv")
    assert list(impacts.columns) == [*REQUIRED_COLUMNS, *EVENT_COLUMNS, *MEASURED_COLUMNS]
    assert list(impacts["trial"].unique()) == ["A", "B", "C"]
    truth = pd.read_csv(simulated / "truth.csv")
    for label, number in (("A", 1), ("B", 2), ("C", 3)):
        mine, ref = impacts[impacts.trial == label], truth[truth.trial == number]
        idx = match_impacts(ref["t_s"].to_numpy(), mine["t_s"].to_numpy())
        assert np.all(idx >= 0) and len(idx) >= len(ref) - 2
        np.testing.assert_array_equal(mine["perturbed"], ref["perturbed"].to_numpy()[idx])
        np.testing.assert_allclose(mine["alpha"], ref["alpha"].to_numpy()[idx])
        np.testing.assert_allclose(mine["k"], ref["k"].to_numpy()[idx])
        assert rms(mine["v_m_s"] - ref["v_m_s"].to_numpy()[idx]) < 0.01
    assert impacts["theta_deg"].between(0, 360, inclusive="left").all()
    assert (out / "fig2.png").stat().st_size > 10_000


@pytest.mark.slow
def test_truth_gives_accuracy_csv(simulated, tmp_path):
    result, out = extract_cli(tmp_path, "--data", str(simulated / "recording.csv"),
                              "--set", f"truth={simulated / 'truth.csv'}",
                              "--set", "figure.trial=2", "--set", "figure.bounces=4")
    assert result.exit_code == 0, result.output
    acc = pd.read_csv(out / "accuracy.csv").set_index("quantity")
    assert acc.loc["theta_deg", "rms_error"] <= 1.0 and acc.loc["v_m_s", "rms_error"] <= 0.03
    assert acc.loc["racket_acc_g", "rms_error"] <= 0.1
    shown = pd.read_csv(out / "fig2_samples.csv")
    assert set(shown["trial"]) == {2} and shown["t_s"].max() - shown["t_s"].min() < 5 * 0.92


@pytest.mark.filterwarnings("ignore:No analog data")
def test_c3d_recording_in_millimetres(simulated, tmp_path):
    c3d = pytest.importorskip("c3d")
    rec = pd.read_csv(simulated / "recording.csv")
    one = rec[rec.trial == 2]
    writer = c3d.Writer(point_rate=200.0, point_units="mm  ")
    writer.set_point_labels(["Racket1", "Ball"])
    frames = []
    for racket, ball in zip(one["racket_x_m"], one["ball_x_m"]):
        points = np.zeros((2, 5), dtype=np.float32)
        points[:, 1] = [racket * 1000.0, ball * 1000.0]  # vertical axis: y
        frames.append((points, np.zeros((0, 0), dtype=np.float32)))
    writer.add_frames(frames)
    path = tmp_path / "session_2.c3d"
    with open(path, "wb") as handle:
        writer.write(handle)
    result, out = extract_cli(tmp_path, "--data", str(path), "--set", "markers.racket=Racket1",
                              "--set", "markers.ball=Ball", "--set", "markers.vertical_axis=y")
    assert result.exit_code == 0, result.output
    impacts = pd.read_csv(out / "impacts.csv")
    assert set(impacts["trial"]) == {"session_2"}
    truth = pd.read_csv(simulated / "truth.csv")
    ref = truth[truth.trial == 2]
    idx = match_impacts(ref["t_s"].to_numpy() - one["t_s"].iloc[0], impacts["t_s"].to_numpy())
    assert np.all(idx >= 0) and len(idx) >= len(ref) - 2
    assert rms(impacts["v_m_s"] - ref["v_m_s"].to_numpy()[idx]) < 0.01
    missing, _ = extract_cli(tmp_path / "m", "--data", str(path))
    assert missing.exit_code == 2 and "no marker 'racket'" in missing.stderr
    assert str(path) in missing.stderr and "Racket1" in missing.stderr


def one_line_error(result, *needles):
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bounce: error: "), result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


def test_bad_recordings_are_one_line_errors_and_write_nothing(simulated, tmp_path):
    rec = pd.read_csv(simulated / "recording.csv")
    cases = {}
    cases["missing"] = (rec.drop(columns="ball_x_m"), ["ball_x_m", "columns.ball"])
    backwards = rec.copy()
    backwards.loc[500, "t_s"] = backwards.loc[498, "t_s"]
    cases["backwards"] = (backwards, ["trial 1", "t_s", "runs backwards"])
    cases["few"] = (rec[rec.trial == 1].head(20), ["trial 1", "only 20 samples"])
    resting = rec[rec.trial == 2].copy()
    resting["ball_x_m"] = resting["racket_x_m"]
    cases["no_bounce"] = (pd.concat([rec[rec.trial == 1], resting]),
                          ["trial 2", "no bounce", "check units.length", "vertical axis"])
    text = rec.copy().astype({"racket_x_m": object})
    text.loc[7, "racket_x_m"] = "n/a?"
    cases["text"] = (text, ["racket_x_m", "row 9"])
    cases["header_only"] = (rec.head(0), ["no samples"])
    no_racket = rec.copy()
    no_racket.loc[no_racket.trial == 2, "racket_x_m"] = np.nan
    cases["no_racket"] = (no_racket, ["trial 2", "no racket positions"])
    for name, (frame, needles) in cases.items():
        path = tmp_path / f"{name}.csv"
        frame.to_csv(path, index=False)
        out = tmp_path / f"out_{name}"
        result = runner.invoke(app, ["extract", "--data", str(path), "--out", str(out)])
        one_line_error(result, str(path), *needles)
        assert not out.exists() or not any(out.iterdir()), name  # nothing written
    result = runner.invoke(app, ["extract", "--data", str(tmp_path / "nope.csv"), "--out",
                                 str(tmp_path / "o")])
    one_line_error(result, "nope.csv", "not found")
    events = pd.DataFrame({"trial": [9], "t_s": [1.0]})
    events.to_csv(tmp_path / "ev.csv", index=False)
    result = runner.invoke(app, ["extract", "--data", str(simulated / "recording.csv"),
                                 "--events", str(tmp_path / "ev.csv"), "--out",
                                 str(tmp_path / "o")])
    one_line_error(result, "ev.csv", "trial 9")
    no_ball = runner.invoke(app, ["extract", "--data", str(simulated / "recording.csv"),
                                  "--set", "columns.ball=null", "--out", str(tmp_path / "o")])
    one_line_error(no_ball, "--events")
    assert not (tmp_path / "o").exists()  # the folder the failed runs created is removed


def test_extract_help_declares_data_and_events():
    text = runner.invoke(app, ["extract", "--help"]).stdout
    assert "--data" in text and "--events" in text
    assert "--events" not in runner.invoke(app, ["simulate-recording", "--help"]).stdout


def test_one_trial_file_without_a_trial_column_in_centimetres(simulated, tmp_path):
    rec = pd.read_csv(simulated / "recording.csv")
    one = rec[rec.trial == 3].drop(columns="trial")
    one[["racket_x_m", "ball_x_m"]] *= 100.0
    one.to_csv(tmp_path / "one.csv", index=False)
    result, out = extract_cli(tmp_path, "--data", str(tmp_path / "one.csv"),
                              "--set", "columns.trial=null", "--set", "units.length=cm")
    assert result.exit_code == 0, result.output
    impacts = pd.read_csv(out / "impacts.csv")
    truth = pd.read_csv(simulated / "truth.csv")
    ref = truth[truth.trial == 3]
    idx = match_impacts(ref["t_s"].to_numpy(), impacts["t_s"].to_numpy())
    assert set(impacts["trial"]) == {1} and np.all(idx >= 0)
    assert rms(impacts["v_m_s"] - ref["v_m_s"].to_numpy()[idx]) < 0.01
    assert rms(impacts["racket_amplitude_m"] - ref["racket_amplitude_m"].to_numpy()[idx]) < 0.002


def test_coarse_sampling_widens_the_fits_and_still_finds_every_bounce():
    """30 Hz: the local fits widen to hold enough samples, contacts are still found."""
    coarse = SessionSettings(sample_rate_hz=30.0, position_noise_m=0.0005, seed=6, **BASE)
    errors, found, total = errors_against_truth(session(coarse))
    assert found >= total - 2 * coarse.n_trials
    assert rms(errors["theta_deg"]) <= 1.0 and rms(errors["v_m_s"]) <= 0.03
    assert rms(errors["racket_acc_g"]) <= 0.1


@pytest.mark.parametrize("content", [b"", b"trial,t_s\n1,0.0\n" * 20, bytes(range(256)) * 4])
def test_damaged_or_foreign_c3d_is_one_line_error(tmp_path, content):
    """The c3d reader asserts on its header and unpacks with struct: an empty, truncated or
    renamed non-C3D file must still be one line naming the file, exit 2, nothing written."""
    path = tmp_path / "take.c3d"
    path.write_bytes(content)
    result = runner.invoke(app, ["extract", "--data", str(path), "--out", str(tmp_path / "o")])
    one_line_error(result, "take.c3d", "cannot read as C3D")
    assert not (tmp_path / "o").exists()


def test_a_truth_on_another_time_base_is_an_error_not_nan_accuracy(simulated, tmp_path):
    """The recording shifted by 100 s against its truth: no impact matches; the accuracy would
    be NaN with n = 0 (a new-user review saw exit 0): one line instead, nothing written."""
    rec = pd.read_csv(simulated / "recording.csv")
    rec["t_s"] += 100.0
    rec.to_csv(tmp_path / "shifted.csv", index=False)
    result, out = extract_cli(tmp_path, "--data", str(tmp_path / "shifted.csv"),
                              "--set", f"truth={simulated / 'truth.csv'}")
    one_line_error(result, "truth", "none of its", "time base")
    assert not out.exists()


@pytest.mark.slow
def test_an_impact_lost_to_a_racket_gap_says_gap(simulated, tmp_path):
    """A 60 ms hole in the racket column alone (longer than max_gap_s) removes its cycle: the
    impact in it was listed as "outside a complete racket cycle" (a new-user review)."""
    rec = pd.read_csv(simulated / "recording.csv")
    hole = (rec.trial == 1) & (rec.t_s > 5.50) & (rec.t_s < 5.56)
    rec.loc[hole, "racket_x_m"] = np.nan
    rec.to_csv(tmp_path / "hole.csv", index=False)
    result, out = extract_cli(tmp_path, "--data", str(tmp_path / "hole.csv"))
    assert result.exit_code == 0, result.output
    excluded = pd.read_csv(out / "excluded.csv")
    middle = excluded[(excluded.trial == 1) & excluded.t_s.between(4.0, 7.0)]
    assert len(middle) == 1 and middle.reason.iloc[0].startswith("gap: racket data missing")


@pytest.mark.parametrize("write, settings", [
    (dict(sep=";", decimal=","), ["csv.separator=semicolon", "csv.decimal=comma"]),
    (dict(sep="\t"), ["csv.separator=tab"]),
    (dict(sep=" "), ["csv.separator=space"]),
    (dict(units_row=True), ["csv.skip_rows=1"]),
], ids=["semicolon-decimal-comma", "tab", "spaces", "units-row"])
@pytest.mark.slow
def test_other_csv_dialects_give_the_same_impacts(simulated, tmp_path, write, settings):
    """A European spreadsheet's export (; and a decimal comma), tabs, spaces, a row of units
    under the header: the same impacts as the plain file (new-user review: no way to read
    them)."""
    rec = pd.read_csv(simulated / "recording.csv")
    path = tmp_path / "dialect.csv"
    if write.pop("units_row", False):
        with open(path, "w") as handle:
            handle.write(",".join(rec.columns) + "\n-,s,m,m\n")
            rec.to_csv(handle, header=False, index=False)
    else:
        rec.to_csv(path, index=False, **write)
    plain, plain_out = extract_cli(tmp_path / "plain", "--data", str(simulated / "recording.csv"))
    result, out = extract_cli(tmp_path, "--data", str(path),
                              *[a for s in settings for a in ("--set", s)])
    assert plain.exit_code == 0 and result.exit_code == 0, result.output
    pd.testing.assert_frame_equal(pd.read_csv(out / "impacts.csv"),
                                  pd.read_csv(plain_out / "impacts.csv"))
    # without the settings: one line that says which key to set
    bare, _ = extract_cli(tmp_path / "bare", "--data", str(path))
    one_line_error(bare, "csv.")


def test_the_errors_of_a_decimal_comma_and_a_lone_mark_say_what_to_set(tmp_path):
    """A decimal-comma export read with only its separator set said "a row of units? set
    csv.skip_rows"; --set csv.decimal=, said only that ',' is no YAML (a review met both)."""
    t = np.arange(50) * 0.005
    frame = pd.DataFrame({"t_s": t, "racket_x_m": 0.1 * np.sin(t), "ball_x_m": 0.5 + t})
    frame.to_csv(tmp_path / "eu.csv", sep=";", decimal=",", index=False)
    comma, _ = extract_cli(tmp_path / "a", "--data", str(tmp_path / "eu.csv"),
                           "--set", "csv.separator=semicolon")
    one_line_error(comma, "a decimal comma? set csv.decimal=comma")
    mark, _ = extract_cli(tmp_path / "b", "--data", str(tmp_path / "eu.csv"),
                          "--set", "csv.decimal=,")
    one_line_error(mark, "--set \"csv.decimal=','\") or give a mark's name (comma")


def test_a_dropout_written_as_zero_is_warned_of_and_read_as_a_gap_where_declared(
        simulated, tmp_path):
    """Some systems write a marker they did not see as 0. Read as heights, three 60 ms
    zeros in the ball column made phantom contacts (a ball at height 0: six "sticking" and
    "contact not located" rows in excluded.csv) and hop_s errors of 0.7 s against the
    truth, without a word. Now a run of zeros is warned of, naming the key; with
    csv.missing_heights=[0] the zeros are gaps, and the impacts are those of the file with
    empty cells there."""
    rec = pd.read_csv(simulated / "recording.csv")
    holes = np.zeros(len(rec), dtype=bool)
    for start in (3.3, 6.1, 9.4):
        holes |= ((rec.trial == 1) & (rec.t_s > start) & (rec.t_s < start + 0.06)).to_numpy()
    zeros, empty = rec.copy(), rec.copy()
    zeros.loc[holes, "ball_x_m"] = 0.0
    empty.loc[holes, "ball_x_m"] = np.nan
    zeros.to_csv(tmp_path / "zeros.csv", index=False)
    empty.to_csv(tmp_path / "empty.csv", index=False)
    as_heights, heights_out = extract_cli(tmp_path / "h", "--data", str(tmp_path / "zeros.csv"))
    assert as_heights.exit_code == 0, as_heights.output
    assert "column 'ball_x_m' is exactly 0 in 3 run(s)" in as_heights.output
    assert "csv.missing_heights=[0]" in as_heights.output
    phantom = pd.read_csv(heights_out / "excluded.csv")
    assert phantom.reason.str.startswith("sticking").sum() == 3  # what a reader would meet
    as_gaps, gaps_out = extract_cli(tmp_path / "g", "--data", str(tmp_path / "zeros.csv"),
                                    "--set", "csv.missing_heights=[0]")
    with_empty, empty_out = extract_cli(tmp_path / "e", "--data", str(tmp_path / "empty.csv"))
    assert as_gaps.exit_code == 0 and with_empty.exit_code == 0, as_gaps.output
    assert "exactly 0" not in as_gaps.output
    pd.testing.assert_frame_equal(pd.read_csv(gaps_out / "impacts.csv"),
                                  pd.read_csv(empty_out / "impacts.csv"))
    assert not pd.read_csv(gaps_out / "excluded.csv").reason.str.startswith("sticking").any()


def test_two_zeros_in_a_row_are_heights_without_a_warning(tmp_path):
    """A racket whose origin is its mid-position passes through 0: two samples written as 0
    in a row are heights, and nothing is said; three are a run (``ZERO_RUN_SAMPLES``)."""
    from types import SimpleNamespace

    from bounce_cli.data.recordings import read_csv_recording

    t = np.arange(60) * 0.005
    racket = 0.3 * np.sin(2 * np.pi * t / 0.92)
    racket[10:12] = 0.0
    ball = 0.5 + 0.0 * t
    pd.DataFrame({"t_s": t, "racket_x_m": racket, "ball_x_m": ball}).to_csv(
        tmp_path / "r.csv", index=False)
    columns = SimpleNamespace(time="t_s", racket="racket_x_m", ball="ball_x_m", trial=None)
    units = SimpleNamespace(length="m", time="s")
    heard: list[str] = []
    (trial,) = read_csv_recording(tmp_path / "r.csv", columns, units, None, heard.append)
    assert heard == [] and np.all(trial.racket[10:12] == 0.0)
    racket[30:33] = 0.0
    pd.DataFrame({"t_s": t, "racket_x_m": racket, "ball_x_m": ball}).to_csv(
        tmp_path / "r.csv", index=False)
    (trial,) = read_csv_recording(tmp_path / "r.csv", columns, units, None, heard.append)
    assert len(heard) == 1 and "'racket_x_m' is exactly 0 in 1 run(s)" in heard[0]
    assert "t_s = 0.15" in heard[0]
    missing = SimpleNamespace(separator=",", decimal=".", skip_rows=0, missing_heights=[0.0])
    (trial,) = read_csv_recording(tmp_path / "r.csv", columns, units, missing, heard.append)
    assert len(heard) == 1 and np.isnan(trial.racket[[10, 11, 30, 31, 32]]).all()


@pytest.fixture(scope="module")
def finite_contacts(tmp_path_factory):
    """A simulated session whose contacts last 6 ms, its events at the equivalent impacts."""
    out = tmp_path_factory.mktemp("contacts") / "sim"
    result = runner.invoke(app, ["simulate-recording", "--out", str(out), "--quiet",
                                 "--set", "trials=1", "--set", "duration_s=12",
                                 "--set", "sample_rate_hz=500",
                                 "--set", "contact.duration_s=0.006"])
    assert result.exit_code == 0, result.output
    return out


def extract_with_events_shifted(session_dir, tmp_path, shift_s):
    """``bounce extract`` of a simulated session's recording with its events shifted by
    ``shift_s`` (an event log on a clock of its own): (result, out)."""
    events = pd.read_csv(session_dir / "events.csv")
    events["t_s"] += shift_s
    events.to_csv(tmp_path / "shifted_events.csv", index=False)
    return extract_cli(tmp_path, "--data", str(session_dir / "recording.csv"),
                       "--events", str(tmp_path / "shifted_events.csv"))


@pytest.mark.parametrize("shift_ms, warned", [(0.0, False), (-3.0, False), (5.0, True),
                                               (-5.0, True)])
def test_events_off_the_recording_s_clock_are_measured_and_warned_of(
        finite_contacts, tmp_path, shift_ms, warned):
    """Events 5 ms late or early against the recording (a logger on its own clock) gave every
    phase 2 deg off and v_k 0.05 m/s off without a word. setup.csv's event_lag_s measures the
    lag where the ball's flights meet (to 0.2 ms here), and a lag beyond half the contact's
    duration and 1 ms (6 ms contacts: 4 ms; an onset log is early by about half) is warned
    of."""
    result, out = extract_with_events_shifted(finite_contacts, tmp_path, shift_ms / 1000.0)
    assert result.exit_code == 0, result.output
    setup = pd.read_csv(out / "setup.csv").set_index("quantity")
    assert setup.loc["event_lag_s", "estimate"] == pytest.approx(shift_ms / 1000.0, abs=2e-4)
    assert ("on the recording's clock" in result.output) == warned, result.output


def test_the_shift_the_warning_names_puts_the_events_on_the_recording_s_clock(
        finite_contacts, tmp_path):
    """The warning names the setting that undoes the lag (events_shift_s, recorded in
    run.json); with it the lag is gone and nothing is said."""
    late, _ = extract_with_events_shifted(finite_contacts, tmp_path, 0.005)
    warned = next(line for line in late.output.splitlines() if "recording's clock" in line)
    setting = warned.split("--set ")[1].split(" ")[0]
    assert setting.startswith("events_shift_s=-0.00")
    fixed, out = extract_cli(tmp_path / "fixed", "--data",
                             str(finite_contacts / "recording.csv"), "--events",
                             str(tmp_path / "shifted_events.csv"), "--set", setting)
    assert fixed.exit_code == 0 and "recording's clock" not in fixed.output, fixed.output
    lag = pd.read_csv(out / "setup.csv").set_index("quantity").loc["event_lag_s", "estimate"]
    assert abs(lag) < 2e-4


def test_events_that_cut_the_flights_are_still_warned_of(tmp_path):
    """Events 11 ms late at 200 Hz cut most flights in the wrong place: a third of the
    impacts lost and the rest biased, and the lag where the flights meet rests on a few
    impacts or none (a review found no warning from 9.5 to 12.5 ms). The events against the
    contacts detected in the ball's samples measure the lag to about a sample: warned."""
    sim = tmp_path / "sim"
    made = runner.invoke(app, ["simulate-recording", "--out", str(sim), "--quiet",
                               "--set", "trials=1", "--set", "duration_s=15",
                               "--set", "sample_rate_hz=200"])
    assert made.exit_code == 0, made.output
    result, _ = extract_with_events_shifted(sim, tmp_path, 0.011)
    assert result.exit_code == 0, result.output
    warned = [line for line in result.output.splitlines() if "recording's clock" in line]
    assert len(warned) == 1 and "contacts detected in its samples" in warned[0], result.output
    said = float(warned[0].split("the events are ")[1].split(" ms")[0])
    assert said == pytest.approx(11.0, abs=2.5)  # to about half a 5 ms sample


def test_events_far_off_the_clock_say_so_where_no_bounce_is_found(finite_contacts, tmp_path):
    """Events 10 ms late cut every flight in the wrong place: the one-line error names the
    events' clock beside the units and axes it asked about."""
    result, _ = extract_with_events_shifted(finite_contacts, tmp_path, 0.010)
    assert result.exit_code == 2, result.output
    assert "events' times are on the recording's clock" in result.output


def _upward_crossings(racket):
    """Indices i where the racket passes its mean upwards between samples i and i + 1."""
    mid = np.nanmean(racket)
    return np.flatnonzero((racket[:-1] <= mid) & (racket[1:] > mid))


def _holes_at_crossings(offset_s, length_s, rows, every=2):
    """A transform for ``errors_against_truth``: every ``every``-th upward crossing of the
    racket gets a hole of ``length_s`` starting ``offset_s`` after it, as missing cells (NaN racket)
    or as missing rows (a logger's dropout: no sample at all)."""
    def transform(t, racket, ball):
        hole = np.zeros(t.size, dtype=bool)
        for i in _upward_crossings(racket)[::every]:
            start = t[i] + offset_s
            hole |= (t > start) & (t < start + length_s)
        if rows:
            return t[~hole], racket[~hole], ball[~hole]
        return t, np.where(hole, np.nan, racket), ball
    return transform


@pytest.mark.parametrize("offset_s, rows", [(-0.0175, False), (-0.0175, True), (0.004, True)],
                         ids=["cells-about", "rows-about", "rows-after"])
def test_a_gap_at_the_racket_s_crossing_keeps_its_cycles(offset_s, rows):
    """A 35 ms gap at every other upward crossing of the racket (200 Hz, 0.5 mm noise): about
    the crossing, missing cells or rows left too few samples for its +-20 ms fit, and the two
    cycles it bounds were lost (their impacts listed as "outside a complete racket cycle");
    just after it, the fit extrapolated from one side (cycles 6 ms long or short). Now the fit
    spans the gap: every impact of the gap-free recording is found, its phase within 0.5 deg
    of the truth, its racket period within 2 ms."""
    clean, found_clean, _ = errors_against_truth(session(CASE_B))
    errors, found, total = errors_against_truth(
        session(CASE_B), transform=_holes_at_crossings(offset_s, 0.035, rows))
    assert found == found_clean, (found, found_clean, total)
    assert np.max(np.abs(errors["theta_deg"])) < 0.5
    assert rms(errors["theta_deg"]) < 1.5 * rms(clean["theta_deg"])
    assert np.max(np.abs(errors["racket_period_s"])) < 0.002


def test_rows_missing_are_said(tmp_path):
    """35 ms of rows missing at every other racket crossing (no empty cell shows them): the
    extraction copes (above) but the impacts near such stretches rest on fewer samples, and
    nothing said so (a review). A warning counts them and names the longest; the same
    recording with every row says nothing."""
    (truth, (t, racket, ball)), *_ = session(CASE_B)
    for name, (tt, rr, bb) in (("whole", (t, racket, ball)),
                               ("holes", _holes_at_crossings(-0.0175, 0.035, rows=True)(
                                   t, racket, ball))):
        pd.DataFrame({"trial": 1, "t_s": tt, "racket_x_m": rr, "ball_x_m": bb}).to_csv(
            tmp_path / f"{name}.csv", index=False)
    whole, _ = extract_cli(tmp_path / "w", "--data", str(tmp_path / "whole.csv"))
    holes, _ = extract_cli(tmp_path / "h", "--data", str(tmp_path / "holes.csv"))
    assert whole.exit_code == 0 and holes.exit_code == 0, holes.output
    assert "without samples" not in whole.output
    said = [line for line in holes.output.splitlines() if "without samples" in line]
    expected = _upward_crossings(racket)[::2].size
    assert len(said) == 1 and f"{expected} stretch(es) without samples" in said[0], said
    assert "the longest 40 ms" in said[0]  # 35 ms of rows less one 5 ms sample interval: 40


def test_a_long_dropout_of_rows_at_a_crossing_is_named_as_a_gap():
    """Rows missing for 80 ms about a crossing (longer than max_gap_s): the cycles it bounds
    are lost, and their impacts say it is a gap of the racket's data (they said "outside a
    complete racket cycle", as if the recording had ended)."""
    (truth, (t, racket, ball)), *_ = session(CASE_B)
    t, racket, ball = _holes_at_crossings(-0.04, 0.08, rows=True, every=4)(t, racket, ball)
    result = extract_trial(t, racket, ball, None, None, ExtractionSettings())
    reasons = [reason for _, reason in result.excluded]
    assert "gap: racket data missing in the impact's racket cycle" in reasons
    inside = [(at, reason) for at, reason in result.excluded if t[0] + 1.0 < at < t[-1] - 1.0]
    assert all(reason != "outside a complete racket cycle" for _, reason in inside), inside


def test_a_dropout_written_as_minus_9999_is_read_as_a_gap_and_said_so(tmp_path):
    """Some systems write a lost marker as -9999 (or another code), not 0: 8 samples of it in
    the ball column were read as heights without a word (a review found the two phantom
    contacts shift every later impact's k by 2), then with a warning only (a later review: the
    tool knows the value is a code, yet the run went on with it). A value that far outside
    the column's heights is read as a gap, and the warning says so and names the setting;
    with the setting given, nothing is said."""
    from types import SimpleNamespace

    from bounce_cli.data.recordings import read_csv_recording

    t = np.arange(400) * 0.005
    ball = 0.4 + 2.0 * t - 4.905 * t**2 % 0.3  # any moving height
    ball[100:108] = -9999.0
    pd.DataFrame({"t_s": t, "racket_x_m": 0.1 * np.sin(2 * np.pi * t / 0.92),
                  "ball_x_m": ball}).to_csv(tmp_path / "r.csv", index=False)
    columns = SimpleNamespace(time="t_s", racket="racket_x_m", ball="ball_x_m", trial=None)
    units = SimpleNamespace(length="m", time="s")
    heard: list[str] = []
    (trial,) = read_csv_recording(tmp_path / "r.csv", columns, units, None, heard.append)
    assert len(heard) == 1 and "'ball_x_m' is exactly -9999 in 1 run(s)" in heard[0]
    assert "read as gaps" in heard[0] and "--set 'csv.missing_heights=[-9999]'" in heard[0]
    assert np.isnan(trial.ball[100:108]).all()
    assert np.isfinite(np.delete(trial.ball, np.arange(100, 108))).all()
    coded = SimpleNamespace(separator=",", decimal=".", skip_rows=0, missing_heights=[-9999])
    (same,) = read_csv_recording(tmp_path / "r.csv", columns, units, coded, heard.append)
    assert len(heard) == 1 and np.array_equal(same.ball, trial.ball, equal_nan=True)


def test_a_racket_resting_at_0_is_no_dropout(tmp_path):
    """The virtual set-up's mouse racket rests at exactly 0 until the subject moves the
    pointer, and then moves in the pointer's steps: no warning (it said "a marker dropout
    written as 0?"). A dropout in the same column, a jump to 0 and back, still is one."""
    from types import SimpleNamespace

    from bounce_cli.data.recordings import read_csv_recording

    t = np.arange(1000) * 0.001
    pointer = np.floor(t * 60.0) / 60.0  # the page's 60 Hz pointer updates, held
    racket = np.where(t < 0.2, 0.0, 0.05 * np.sin(2 * np.pi * (pointer - 0.2) / 0.5))
    ball = 0.5 + 0.0 * t
    columns = SimpleNamespace(time="t_s", racket="racket_x_m", ball="ball_x_m", trial=None)
    units = SimpleNamespace(length="m", time="s")
    heard: list[str] = []
    pd.DataFrame({"t_s": t, "racket_x_m": racket, "ball_x_m": ball}).to_csv(
        tmp_path / "r.csv", index=False)
    read_csv_recording(tmp_path / "r.csv", columns, units, None, heard.append)
    assert heard == []
    racket[600:610] = 0.0  # the racket near its top, lost for 10 ms
    pd.DataFrame({"t_s": t, "racket_x_m": racket, "ball_x_m": ball}).to_csv(
        tmp_path / "r.csv", index=False)
    read_csv_recording(tmp_path / "r.csv", columns, units, None, heard.append)
    assert len(heard) == 1 and "'racket_x_m' is exactly 0 in 1 run(s)" in heard[0]
    assert "t_s = 0.6" in heard[0]


# -- extraction faults (issue 24) ------------------------------------------------------------
FAULT_SESSION = SessionSettings(n_trials=1, duration_s=20.0, sample_rate_hz=200.0,
                                position_noise_m=0.0005, velocity_noise_m_s=0.04, seed=3)


@pytest.mark.slow
def test_a_40ms_ball_gap_at_an_impact_keeps_the_impact_and_its_k():
    """A gap shorter than max_gap_s is bridged by a spline for detection; across a contact
    the spline smeared the velocity jump into a spurious contact at the gap's edge (listed as
    "no free flight after the impact") and k skipped a number at a real impact: a false lag
    pair for acf/VAR. Now the jump is taken across the gap from the measured samples either
    side; the impact is found, timed from the flights, with its own k."""
    truth, (t, racket, ball) = session(FAULT_SESSION)[0]
    rows = truth_rows(truth)
    for j in (2, 5, 8):
        i = int(np.searchsorted(t, rows["t_s"][j]))
        for shift in (-6, -4, -3, -2, 0):  # 7 samples missing: 40 ms between measured ones
            gapped = ball.copy()
            gapped[i + shift:i + shift + 7] = np.nan
            result = extract_trial(t, racket, gapped, s=ExtractionSettings())
            idx = match_impacts(rows["t_s"], result.impacts["t_s"])
            assert j in idx, (j, shift)
            np.testing.assert_array_equal(result.impacts["k"], idx)
            assert [r for _, r in result.excluded] == ["outside a complete racket cycle"]
            at = np.flatnonzero(idx == j)[0]
            assert abs(result.impacts["v_m_s"][at] - rows["v_m_s"][j]) <= 0.03
            theta_err = (result.impacts["theta_deg"][at] - rows["theta_deg"][j] + 180) % 360 - 180
            assert abs(theta_err) <= 1.0


def test_a_contact_that_cannot_be_located_is_listed_at_its_time_and_k_skips_it():
    """The ball lost for 1.2 s before impact 6 (no flight before it) and the racket for 40 ms
    at it (no racket fit to meet): its contact cannot be located. Its time was NaN: the
    median hop of the lost-impacts count became NaN, so the impact lost in the long gap was
    not counted ("about 0 impact(s) lost"), k did not skip it (a false lag pair) and
    excluded.csv had a row at t = NaN."""
    truth, (t, racket, ball) = session(FAULT_SESSION)[0]
    rows = truth_rows(truth)
    t6 = rows["t_s"][6]
    gapped_ball, gapped_racket = ball.copy(), racket.copy()
    gapped_ball[(t > t6 - 1.2) & (t < t6 - 0.03)] = np.nan
    gapped_racket[(t > t6 - 0.02) & (t < t6 + 0.02)] = np.nan
    result = extract_trial(t, gapped_racket, gapped_ball, s=ExtractionSettings())
    idx = match_impacts(rows["t_s"], result.impacts["t_s"])
    assert np.all(idx >= 0) and 6 not in idx
    np.testing.assert_array_equal(result.impacts["k"], idx)
    times = dict((reason.split(":")[0], tt) for tt, reason in result.excluded)
    assert abs(times["contact not located"] - t6) <= 0.01
    assert any("about 1 impact(s) lost" in reason for _, reason in result.excluded)
    assert all(math.isfinite(tt) for tt, _ in result.excluded)


def test_a_long_ball_gap_within_one_flight_says_no_impact_was_lost():
    """A 0.15 s gap of the ball data in the middle of one flight (longer than max_gap_s, so
    the hop after the impact before it is unknown) hides no impact: excluded.csv says so, as
    the estimate it is (it said "about 0 impact(s) lost in it"), and k does not skip."""
    truth, (t, racket, ball) = session(FAULT_SESSION)[0]
    rows = truth_rows(truth)
    mid = 0.5 * (rows["t_s"][4] + rows["t_s"][5])
    gapped = ball.copy()
    gapped[(t > mid - 0.075) & (t < mid + 0.075)] = np.nan
    result = extract_trial(t, racket, gapped, s=ExtractionSettings())
    gaps = [(tt, r) for tt, r in result.excluded if r.startswith("gap:")]
    assert len(gaps) == 1 and abs(gaps[0][0] - mid) < 0.02, result.excluded
    assert gaps[0][1].endswith("probably no impact lost in it (the time across it is about "
                               "one typical hop)"), gaps
    idx = match_impacts(rows["t_s"], result.impacts["t_s"])
    np.testing.assert_array_equal(result.impacts["k"], idx)


# -- the set-up measured from the data (issue 24) -------------------------------------------
def test_pooled_gravity_is_the_curvature_of_the_flights():
    """Flights of known g with their own positions and velocities and 0.5 mm noise: the pooled
    fit recovers g within 3 of its SE, the SE matches the scatter of per-flight quadratic
    fits (an independent route: np.polyfit per flight, inverse-variance mean), and the
    residual SD is the noise."""
    rng = np.random.default_rng(4)
    flights, single = [], []
    for _ in range(30):
        t = np.arange(0.0, rng.uniform(0.3, 0.6), 0.005) + rng.uniform(0, 100)
        s = t - t[0]
        x = rng.uniform(0, 0.1) + rng.uniform(1.0, 2.0) * s - 0.5 * 5.8 * s * s
        x = x + 0.0005 * rng.standard_normal(t.size)
        flights.append((t, x))
        c, cov = np.polyfit(s, x, 2, cov=True)
        single.append((-2 * c[0], 4 * cov[0, 0]))
    fit = pooled_gravity(flights)
    assert fit.n_flights == 30 and abs(fit.g - 5.8) <= 3 * fit.se
    g_i, var_i = np.array(single).T
    weighted = np.sum(g_i / var_i) / np.sum(1 / var_i)
    assert fit.g == pytest.approx(weighted, abs=2 * fit.se)
    assert fit.se == pytest.approx(np.sqrt(1 / np.sum(1 / var_i)), rel=0.2)
    assert fit.residual_sd == pytest.approx(0.0005, rel=0.05)


@pytest.mark.parametrize("alpha", [0.3, 0.42, 0.7])
def test_the_contact_shape_factor_is_the_area_between_the_path_and_its_flights(alpha):
    """Independent route: the simulator's integrated spring-damper contact (no gravity, a still
    racket), the V of its two straight flights meeting at the equivalent impact, the area
    between them by the trapezoid rule: K |u| T^2."""
    from bounce_cli.data.simulated_lab import compliant_contact, CycleRacket

    still = CycleRacket(np.array([1e9]), np.array([1.0]), np.array([0.1]))
    u, duration = -2.0, 0.01
    release, dy, solution = compliant_contact(0.0, u, 0.0, still, alpha, duration)
    s = np.linspace(0.0, release, 20001)
    v_shape = np.maximum(u * s, dy * (s - release))
    area = np.trapezoid(solution(s)[0] - v_shape, s)
    assert area == pytest.approx(contact_shape_factor(alpha) * abs(u) * duration**2, rel=1e-4)


BOOM_SET_UP = {"model": {"alpha": 0.42, "g": 5.8, "racket_amplitude": 0.065,
                         "racket_period": 0.55},
               "seed": 11, "trials": 2, "duration_s": 30.0, "sample_rate_hz": 200.0,
               "position_noise_m": 0.0005, "velocity_noise_m_s": 0.04,
               "perturbations": {"every": 0}, "ball_marker_offset_m": 0.02,
               "contact": {"duration_s": 0.01, "alpha_sd": 0.03}}


@functools.lru_cache(maxsize=None)
def boom_session():
    from bounce_cli.experiments.simulate_recording import RecordingConfig, session_frames

    recording, _, truth = session_frames(RecordingConfig.model_validate(BOOM_SET_UP))
    return recording, truth


def boom_errors(extraction, truth):
    impacts = extraction.impacts
    errors = {q: [] for q in ("theta_deg", "v_m_s", "alpha_measured")}
    for label, tr in truth.groupby("trial"):
        ex = impacts[impacts["trial"] == label]
        idx = match_impacts(tr["t_s"].to_numpy(), ex["t_s"].to_numpy())
        assert np.all(idx >= 0)
        for q in errors:
            d = ex[q].to_numpy() - tr[q].to_numpy()[idx]
            errors[q].append((d + 180) % 360 - 180 if q == "theta_deg" else d)
    return {q: np.concatenate(v) for q, v in errors.items()}


@pytest.mark.slow
def test_a_boom_set_up_is_extracted_without_being_told_its_set_up():
    """Issue 24's done-when: g 5.8 m/s^2 (a boom), 10 ms spring-damper contacts with alpha
    0.42 +- 0.03 per impact, the marker at the ball's centre (20 mm), 200 Hz, 0.5 mm noise,
    extracted with nothing set: RMS theta <= 1 deg, v <= 0.03 m/s, g within 0.1 m/s^2, mean
    alpha within 0.02, per-impact alpha RMS <= 0.05 (measured: 0.22 deg, 0.3 mm/s, 5e-5 m/s^2,
    0.002, 0.0025 on another seed). At the default g (the old behaviour) v was 1 m/s off."""
    from bounce_cli.experiments.extract import ExtractionBlock, extract_all, trials_from_frame

    recording, truth = boom_session()
    trials = trials_from_frame(recording)
    block = ExtractionBlock()
    measured = extract_all(trials, None, block.settings(9.81), "boom", measure_g=True,
                           measure_offset=True)
    setup = {q.quantity: q for q in measured.setup}
    errors = boom_errors(measured, truth)
    assert len(errors["v_m_s"]) >= len(truth) - 2 * 2
    assert rms(errors["theta_deg"]) <= 1.0 and rms(errors["v_m_s"]) <= 0.03
    assert abs(setup["g_m_s2"].estimate - 5.8) <= 0.1
    assert abs(setup["g_m_s2"].estimate - 5.8) <= 4 * setup["g_m_s2"].se
    assert measured.settings.g == setup["g_m_s2"].estimate  # the flights were fitted at it
    assert abs(setup["alpha"].estimate - truth["alpha_measured"].mean()) <= 0.02
    assert rms(errors["alpha_measured"]) <= 0.05
    assert setup["alpha_sd"].estimate == pytest.approx(truth["alpha_measured"].std(), abs=0.01)
    # the contact: 10 ms (measured 11 ms), the marker above the racket's at the equivalent
    # impact: the radius less the compression there
    assert setup["contact_s"].estimate == pytest.approx(0.01, abs=0.003)
    assert 0.005 < setup["ball_offset_m"].estimate < 0.02
    assert measured.settings.ball_offset_m == setup["ball_offset_m"].estimate
    # the measurement SDs are the errors' size (another analysis uses them as noise)
    assert setup["measurement_sd_v_m_s"].estimate == pytest.approx(rms(errors["v_m_s"]),
                                                                   rel=0.5)
    assert setup["measurement_sd_theta_rad"].estimate == pytest.approx(
        np.radians(rms(errors["theta_deg"])), rel=0.5)
    assert setup["position_noise_m"].estimate == pytest.approx(0.0005, rel=0.05)
    assert setup["racket_noise_m"].estimate == pytest.approx(0.0005, rel=0.1)
    # told the wrong g: the old result (v 1 m/s off), and a warning that the flights disagree
    told = extract_all(trials, None, block.settings(9.81), "boom")
    assert rms(boom_errors(told, truth)["v_m_s"]) > 0.3
    assert any("5.8" in w and "SE off" in w for w in told.warnings)


@pytest.mark.slow
def test_extract_writes_the_measured_set_up_and_names_a_unit_slip(simulated, tmp_path,
                                                                  user_error):
    """setup.csv beside impacts.csv (read back by the analyses' reader) and the summary line;
    millimetres read as centimetres: the flights show 98 m/s^2, an error naming the slip
    (issue 22), nothing written."""
    from bounce_cli.data.setup_table import read_setup

    result, out = extract_cli(tmp_path, "--data", str(simulated / "recording.csv"))
    assert result.exit_code == 0, result.output
    setup = read_setup(out / "impacts.csv")
    assert setup["g_m_s2"].estimate == pytest.approx(9.81, abs=0.01)
    assert {"alpha", "alpha_sd", "contact_s", "ball_offset_m", "position_noise_m",
            "racket_noise_m", "measurement_sd_v_m_s", "measurement_sd_theta_rad"} <= set(setup)
    assert abs(setup["ball_offset_m"].estimate) < 0.001
    impacts = pd.read_csv(out / "impacts.csv")
    assert list(impacts.columns) == [*REQUIRED_COLUMNS, *MEASURED_COLUMNS]
    rec = pd.read_csv(simulated / "recording.csv")
    rec = rec[rec["trial"] == 1].copy()
    rec[["racket_x_m", "ball_x_m"]] *= 1000.0
    rec.to_csv(tmp_path / "mm.csv", index=False)
    slip, slip_out = extract_cli(tmp_path / "slip", "--data", str(tmp_path / "mm.csv"),
                                 "--set", "units.length=cm")
    user_error(slip, "98", "millimetres read as centimetres", "units.length")
    assert not slip_out.exists()


def _mid_position_one_by_one(cycles, times):
    """The definition of ``RacketCycles.mid_position``: one least-squares fit per time."""
    from bounce_cli.data.extraction import least_squares

    out = []
    for ti in times:
        sel = np.abs(cycles.mid_times - ti) <= cycles.mid_window_s
        n = int(np.count_nonzero(sel))
        if n == 0:
            out.append(math.nan)
            continue
        s = (cycles.mid_times[sel] - ti) / cycles.mid_window_s
        coef, _ = least_squares(np.vander(s, 3 if n >= 3 else 1, increasing=True),
                                cycles.mid_values[sel])
        out.append(coef[0])
    return np.array(out)


@pytest.mark.parametrize("seed", range(5))
def test_the_stacked_mid_position_is_the_fit_at_each_time(seed):
    """All times' windows in one stacked solve give each window's own quadratic (a mean below
    3 midpoints, NaN with none), a degenerate window (repeated midpoint times) included."""
    from bounce_cli.data.extraction import RacketCycles

    rng = np.random.default_rng(seed)
    mid_times = np.sort(np.concatenate([rng.uniform(0.0, 10.0, 40), [12.0, 12.0, 12.0],
                                        [15.0, 15.2]]))
    mid_values = 0.01 * np.sin(mid_times) + 1e-3 * rng.standard_normal(mid_times.size)
    empty = np.array([])
    cycles = RacketCycles(empty, empty, empty, empty, mid_times, mid_values, 0.6)
    times = np.concatenate([rng.uniform(-1.0, 17.0, 200), mid_times[:5] + 0.6, [12.0, 20.0]])
    stacked = cycles.mid_position(times)
    reference = _mid_position_one_by_one(cycles, times)
    assert np.array_equal(np.isnan(stacked), np.isnan(reference))
    assert np.isnan(stacked[-1]) and np.isfinite(stacked[-2])
    np.testing.assert_allclose(stacked, reference, rtol=1e-11, atol=1e-14)
    one = int(np.flatnonzero(np.isfinite(reference))[0])
    assert float(cycles.mid_position(times[one])[0]) == pytest.approx(reference[one], rel=1e-12)
    grid = times[:204].reshape(6, -1)
    np.testing.assert_allclose(cycles.mid_position(grid), stacked[:204].reshape(6, -1),
                               rtol=1e-13)


def test_events_without_ball_data_say_which_g_the_flights_are_computed_at(simulated, tmp_path):
    """Without ball data v_k comes from the events' flight times at a g that nothing
    measured: model.g's default 9.81 was used without a word (on a g = 7.5 set-up v_k was
    0.81 m/s off and AC -0.32 g for -0.42 g). A warning now names the g and the setting."""
    events = simulated / "events.csv"
    assert events.is_file()
    result, out = extract_cli(tmp_path, "--data", str(simulated / "recording.csv"),
                              "--events", str(events), "--set", "columns.ball=null")
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    assert "no ball data" in said and "g = 9.81 m/s^2" in said and "model.g" in said
    result, out = extract_cli(tmp_path, "--data", str(simulated / "recording.csv"),
                              "--events", str(events), "--set", "columns.ball=null",
                              "--set", "model.g=9.81", "--force")
    assert result.exit_code == 0, result.output
    assert "no ball data" not in " ".join(result.output.split())


def test_no_bounce_in_noisy_markers_names_the_contact_tolerance(tmp_path):
    """At 3 mm of noise on both markers (200 Hz; a review's set-up: small, quick bounces)
    the ball's height above the racket dips within the 5 mm contact tolerance between
    bounces, the ball 'rests', and the error blamed units only. It now names the measured
    noise and the setting; at the setting it names, the recording extracts."""
    import re

    sim = tmp_path / "sim"
    result = runner.invoke(app, [
        "simulate-recording", "--out", str(sim), "--quiet", "--set", "trials=1", "--set",
        "duration_s=20", "--set", "model.alpha=0.7", "--set", "model.racket_period=0.7",
        "--set", "model.racket_amplitude=0.065", "--set", "model.g=7.5", "--set",
        "velocity_noise_m_s=0.03", "--set", "perturbations.every=0", "--set", "seed=5"])
    assert result.exit_code == 0, result.output
    rec = pd.read_csv(sim / "recording.csv")
    rng = np.random.default_rng(42)
    for column in ("racket_x_m", "ball_x_m"):
        rec[column] += rng.normal(0.0, 0.003, len(rec))
    noisy = tmp_path / "noisy.csv"
    rec.to_csv(noisy, index=False)
    result, out = extract_cli(tmp_path, "--data", str(noisy))
    said = " ".join(result.output.split())
    assert result.exit_code == 2 and "no bounce found" in said, said
    found = re.search(r"SD about ([0-9.]+) mm.*--set extraction\.contact_tolerance_m=([0-9.]+)",
                      said)
    assert found, said
    assert 3.5 < float(found.group(1)) < 5.0  # both markers' 3 mm: 4.2 mm
    result, out = extract_cli(tmp_path, "--data", str(noisy),
                              "--set", f"extraction.contact_tolerance_m={found.group(2)}")
    assert result.exit_code == 0, result.output
    assert len(pd.read_csv(out / "impacts.csv")) >= 20


def test_the_separation_noise_is_the_markers_noise_beside_a_moving_racket():
    """The robust SD of second differences over sqrt(6) is the white noise's SD; a racket's
    own 0.3 m sine at 0.92 s and 200 Hz adds little, and a bounce's jumps nothing."""
    from bounce_cli.experiments.extract import separation_noise_m

    t = np.arange(0.0, 30.0, 0.005)
    racket = 0.3 * np.sin(2 * np.pi * t / 0.92)
    ball = racket + 0.5 * np.abs(np.sin(np.pi * t / 0.92))  # flights of 0.92 s, with kinks
    rng = np.random.default_rng(1)
    for sd in (0.0005, 0.003):
        noisy = (ball + rng.normal(0, sd, t.size), racket + rng.normal(0, sd, t.size))
        assert separation_noise_m(noisy[1], noisy[0]) == pytest.approx(np.sqrt(2) * sd,
                                                                      rel=0.15)
    assert separation_noise_m(racket, ball) < 2e-4


def test_jittering_sample_times_are_warned_about(simulated, tmp_path):
    """1 ms of jitter in a 200 Hz recording's time stamps (a PC's clock) found contacts where
    there were none, without a word. The capture system's own clock, with rows missing here
    and there or every third row missing, is not jitter."""
    rec = pd.read_csv(simulated / "recording.csv")
    jittered = rec.assign(t_s=rec["t_s"] + np.random.default_rng(7).uniform(
        -0.001, 0.001, len(rec)))
    holes = rec.drop(index=rec.index[100:2000:97])  # a few rows missing, regular clock
    # every third row missing (a capture that drops frames regularly): the intervals are
    # 5 and 10 ms in turn, multiples of one clock's step, not jitter (the first version
    # said they jittered by 3.7 ms around 7.5 ms)
    thirds = rec.drop(index=rec.index[2::3])
    jittered_thirds = jittered.drop(index=jittered.index[2::3])
    for name, frame, warned in (("jittered", jittered, True), ("holes", holes, False),
                                ("thirds", thirds, False),
                                ("jittered_thirds", jittered_thirds, True)):
        path = tmp_path / f"{name}.csv"
        frame.to_csv(path, index=False)
        result, out = extract_cli(tmp_path, "--data", str(path), "--force")
        said = " ".join(result.output.split())
        assert ("sample times jitter" in said) is warned, (name, said)


def test_the_clock_step_is_found_under_rows_missing_and_jitter():
    """``clock_step``: the capture's step whatever share of rows is missing (every third row:
    intervals of 1 and 2 steps in equal numbers, whose median is neither; three rows in five
    at random), and about the mean interval under jitter."""
    from bounce_cli.experiments.extract import clock_step

    t = 0.1 + np.arange(4000) * 0.005  # time stamps as a file gives them, with rounding
    rng = np.random.default_rng(3)
    for kept in (t, np.delete(t, np.arange(2, t.size, 3)),
                 np.sort(rng.choice(t, size=1600, replace=False))):
        assert clock_step(np.diff(kept)) == pytest.approx(0.005, rel=1e-9)
    # under jitter (and with rows missing too) the step is the clock's, not the median of
    # the short intervals: a review's 5 ms clock with 1 ms of jitter was named "4.94 ms"
    for size in (0.0005, 0.001):
        jittered = t + rng.uniform(-size, size, t.size)
        assert clock_step(np.diff(jittered)) == pytest.approx(0.005, rel=2e-3)
        gappy = np.delete(jittered, np.arange(2, t.size, 3))
        assert clock_step(np.diff(gappy)) == pytest.approx(0.005, rel=2e-3)


def test_flights_too_long_for_their_launch_say_a_bounce_was_missed(tmp_path):
    """8 mm of marker noise at 200 Hz lost bounces without a word (a review: 10 impacts found
    of 16, hops of 1.8-2.7 s beside 0.92 s, k consecutive across them). A flight 1.5 times
    longer than 2 v_k / g is warned of; the clean recording's flights are not."""
    sim = tmp_path / "sim"
    result = runner.invoke(app, ["simulate-recording", "--out", str(sim), "--quiet",
                                 "--set", "trials=1", "--set", "duration_s=15",
                                 "--set", "seed=3", "--set", "position_noise_m=0.008"])
    assert result.exit_code == 0, result.output
    result, out = extract_cli(tmp_path, "--data", str(sim / "recording.csv"))
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    assert "flight(s) last 1.5 times or more what their launch gives" in said, said
    assert "trial 1 at t =" in said
    clean = tmp_path / "clean"
    result = runner.invoke(app, ["simulate-recording", "--out", str(clean), "--quiet",
                                 "--set", "trials=1", "--set", "duration_s=15", "--set", "seed=3"])
    result, out = extract_cli(tmp_path, "--data", str(clean / "recording.csv"), "--force")
    assert result.exit_code == 0 and "launch gives" not in result.output, result.output


def test_a_low_hop_over_a_falling_racket_is_not_taken_for_a_missed_bounce():
    """Chatter's low hops last far longer than 2 v_k / g (the racket falls away under the
    ball: 0.33 s where 2 v_k / g gave 0.08 s in a virtual session), and the first version
    warned of missed bounces there. The flight is the model's, at the impact's racket."""
    from bounce_cli.experiments.extract import missed_bounce_warnings
    from bounce_cli.model.impact import first_impact_phase

    theta = np.radians(np.array([100.0, 120.0, 150.0, 30.0]))  # the racket past its top
    v = np.array([0.3, 0.4, 0.4, 4.5])
    omega = 2 * np.pi / 0.92
    hop = first_impact_phase(theta, v, 0.3, omega, 9.81) / omega
    assert np.all(hop[:3] > 4 * 2 * v[:3] / 9.81)  # far longer than a ballistic flight
    frame = pd.DataFrame({"trial": 1, "t_s": np.arange(4.0), "theta_rad": theta, "v_m_s": v,
                          "hop_s": hop, "racket_period_s": 0.92, "racket_amplitude_m": 0.3})
    assert missed_bounce_warnings(frame, 9.81, "x") == []
    frame.loc[3, "hop_s"] = 2 * hop[3]  # a bounce missed in the last flight
    assert len(missed_bounce_warnings(frame, 9.81, "x")) == 1


def test_a_pause_of_the_clock_is_no_flight(simulated, tmp_path):
    """The virtual set-up stops its world while the racket's stream is silent: 300 ms without
    rows, the ball where it was on both sides. Fitted across the hole as one free flight, that
    flight's curvature pulled the measured g to 9.06 m/s^2, the marker offset measured at it
    to 55 mm, and with events trial 1 had 'no bounce found'. A stretch without rows longer
    than max_gap_s now ends a flight's fit as a gap of cells does."""
    rec = pd.read_csv(simulated / "recording.csv")
    events = pd.read_csv(simulated / "events.csv")
    for frame in (rec, events):
        frame.loc[(frame.trial == 1) & (frame.t_s > 5.0), "t_s"] += 0.3
    rec.to_csv(tmp_path / "paused.csv", index=False)
    events.to_csv(tmp_path / "paused_events.csv", index=False)
    result, out = extract_cli(tmp_path, "--data", tmp_path / "paused.csv",
                              "--events", tmp_path / "paused_events.csv")
    assert result.exit_code == 0, result.output
    setup = pd.read_csv(out / "setup.csv").set_index("quantity")["estimate"]
    assert setup["g_m_s2"] == pytest.approx(9.81, rel=1e-3)
    assert abs(setup["ball_offset_m"]) < 1e-3
    impacts = pd.read_csv(out / "impacts.csv")
    assert (impacts.trial == 1).sum() >= 10  # 12 without the pause, 1-2 beside it lost


def test_a_long_racket_gap_over_a_contact_is_no_flight(simulated, tmp_path):
    """150 ms of the racket's column empty around a contact in every trial: no contact is seen
    there, and the ball's way down and up again was fitted as one free flight, whose curvature
    measured g 6.88 m/s^2 (truth 9.81), the marker offset 64 mm, and then the whole file had
    'no bounce found (sticking ...)' (a data review). Where the racket is not measured, a
    flight's fit ends; the impact there is lost, not the file."""
    rec = pd.read_csv(simulated / "recording.csv")
    truth = pd.read_csv(simulated / "truth.csv")
    lost = 0
    for trial, impacts in truth.groupby("trial"):
        at = float(impacts.t_s.iloc[len(impacts) // 2])
        rec.loc[(rec.trial == trial) & rec.t_s.between(at - 0.075, at + 0.075),
                "racket_x_m"] = np.nan
        lost += 1
    rec.to_csv(tmp_path / "racket_gaps.csv", index=False)
    result, out = extract_cli(tmp_path, "--data", tmp_path / "racket_gaps.csv")
    assert result.exit_code == 0, result.output
    setup = pd.read_csv(out / "setup.csv").set_index("quantity")["estimate"]
    assert setup["g_m_s2"] == pytest.approx(9.81, rel=1e-3)
    assert abs(setup["ball_offset_m"]) < 1e-3
    impacts = pd.read_csv(out / "impacts.csv")
    assert len(impacts) >= len(truth) - lost - 4  # 4: edges, cycles
    # the hidden bounce is listed and counted in k (a new-user review: lost without a word,
    # the hop before it spanning two and k running on as if they were consecutive)
    excluded = pd.read_csv(out / "excluded.csv")
    hidden = excluded[excluded.reason.str.match(
        r"gap: 0\.1[45]\d* s without racket data; about 1 impact\(s\) lost in it")]
    assert len(hidden) == lost, excluded
    both = impacts.merge(truth, on=["trial", "k"], suffixes=("", "_truth"))
    assert len(both) == len(impacts)
    assert np.abs(both.t_s - both.t_s_truth).max() < 1e-3  # every k is the truth's k
    assert (impacts.hop_s.dropna() < 1.2 * truth.hop_s.median()).all()


@pytest.mark.parametrize("racket_above_m", [0.03, 0.05, 0.08])
def test_a_racket_marker_above_the_face_is_measured_not_taken_for_resting(
        simulated, tmp_path, racket_above_m):
    """The racket's marker 30 to 80 mm above its face: at every bounce the ball's marker goes
    that far below it, read as resting at offset 0, and a lab's file had 'no bounce found
    (sticking ...)' with advice on units only (a data review). The first pass now starts
    from the depth of the ball's lowest points; the offset is then measured at the impacts
    as always, and the impacts are the plain file's."""
    rec = pd.read_csv(simulated / "recording.csv")
    plain, plain_out = extract_cli(tmp_path / "plain", "--data", simulated / "recording.csv")
    assert plain.exit_code == 0, plain.output
    rec["racket_x_m"] += racket_above_m
    rec.to_csv(tmp_path / "marker.csv", index=False)
    result, out = extract_cli(tmp_path, "--data", tmp_path / "marker.csv")
    assert result.exit_code == 0, result.output
    setup = pd.read_csv(out / "setup.csv").set_index("quantity")["estimate"]
    plain_setup = pd.read_csv(plain_out / "setup.csv").set_index("quantity")["estimate"]
    assert setup["ball_offset_m"] == pytest.approx(
        plain_setup["ball_offset_m"] - racket_above_m, abs=1e-4)
    ours, theirs = (pd.read_csv(o / "impacts.csv") for o in (out, plain_out))
    assert len(ours) == len(theirs)
    assert np.allclose(ours.t_s, theirs.t_s, atol=1e-9) and np.allclose(ours.v_m_s, theirs.v_m_s)


@pytest.mark.parametrize("period_s", [0.92, 0.6, 0.5])
def test_alpha_measured_is_unbiased_at_short_racket_periods(period_s):
    """Eq. 3's alpha at each impact takes the racket's velocity there from a local fit. Over
    +-0.1 s a quartic's slope is biased by the racket's fifth derivative, a_r w^5: without
    noise alpha_measured came out +1.6e-4 too high at tau 0.92 s, +8e-4 at 0.6 s and +1.7e-3
    at 0.5 s (a review: +0.0008 to +0.0022, enough to move a model radius near the real
    regime by 0.09). The slope now comes from a degree-6 fit over the same window: within
    1e-4 at every period (measured: 2e-5 at 0.5 s)."""
    amplitude = 1.43 * 9.81 / (2.0 * math.pi / period_s) ** 2  # Gamma 1.43, as Fig. 4's
    params = ModelParams(alpha=0.5, g=9.81, racket_amplitude=amplitude, racket_period=period_s)
    settings = SessionSettings(n_trials=2, duration_s=20.0, sample_rate_hz=200.0)
    bias = []
    for truth, (t, racket, ball) in simulate_session(params, settings):
        rows = truth_rows(truth)
        found = extract_trial(t, racket, ball, None, None, ExtractionSettings()).impacts
        index = match_impacts(rows["t_s"], found["t_s"])
        bias.append(found["alpha_measured"] - rows["alpha_measured"][index])
    bias = np.concatenate(bias)
    assert abs(float(np.mean(bias))) < 1e-4, float(np.mean(bias))


def test_millimetres_read_as_metres_are_named_before_any_noise_advice(simulated, tmp_path):
    """A recording in mm read as m: 'no bounce found', then advice to raise
    contact_tolerance_m to 2.2 m for a 'noise' of 733 mm, and the units last (a data review).
    A racket moving more than a person can is a unit slip: said first, no noise advice."""
    rec = pd.read_csv(simulated / "recording.csv")
    rec[["racket_x_m", "ball_x_m"]] *= 1000.0
    rec.to_csv(tmp_path / "mm.csv", index=False)
    result, _ = extract_cli(tmp_path, "--data", tmp_path / "mm.csv")
    one_line_error(result, "is outside what a person can do (0.002-1 m)",
                   "millimetres (0.3009 m) typed for metres?")
    assert "contact_tolerance_m" not in result.stderr
    assert result.stderr.index("typed for metres") < result.stderr.index("check units.length")
