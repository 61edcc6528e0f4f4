"""engine/control.py: the map with the racket period as third state (sections 7-8's future work).

Cross-checks: K = 0 against the passive engine bit for bit; the analytic 3 x 3 Jacobian against
finite differences of the full map, against eq. 10 (K = 0), against the closed-form
characteristic polynomial at c = 1, and against the decay rate of a long simulation; the
controlled step against ballistics and the impact law; the fit against trials simulated with
known K and c.
"""

import importlib.util
import math

import numpy as np
import pytest

from bounce_cli.analysis.classify import ClassifySettings, classify_batch
from bounce_cli.analysis.impulse import find_threshold, impulse_response_full
from bounce_cli.model.linear import eigenvalues, jacobian, racket_acceleration_at_impact_g
from bounce_cli.model.maps import PassiveMap, iterate_map, map_step
from bounce_cli.model.params import ModelParams
from bounce_cli.model.control import (
    PASSIVE,
    PeriodController,
    Reference,
    controlled_fixed_point,
    controlled_jacobian,
    controlled_step,
    finite_difference_controlled_jacobian,
    iterate_controlled,
)
from bounce_cli.analysis.control_design import (
    align_perturbations,
    classify_controlled,
    controlled_impulse_response,
    fit_period_control,
    period_control_radius,
    simulate_perturbation_trials,
)

OTHER = ModelParams(alpha=0.7, g=9.81, racket_amplitude=0.12, racket_period=0.5)


# -- K = 0 is the passive map, bit for bit --------------------------------------------------------
@pytest.mark.parametrize("rate", [0.0, 0.3, 1.0, 1.7])
def test_zero_gain_iterates_the_passive_map_bit_for_bit(paper_params, rate):
    rng = np.random.default_rng(5)
    theta0, v0 = rng.uniform(0, 2 * np.pi, 3000), rng.uniform(0, 10, 3000)
    passive = iterate_map(theta0, v0, paper_params, 25)
    theta, v, tau, hop = iterate_controlled(theta0, v0, paper_params.racket_period, paper_params,
                                            PeriodController(0.0, rate), 25)
    for a, b in zip(passive, (theta, v, hop)):
        assert np.array_equal(a, b, equal_nan=True)
    assert np.all((tau == paper_params.racket_period) | np.isnan(v))


def test_zero_gain_step_with_noise_and_alpha_is_map_step(paper_params):
    rng = np.random.default_rng(2)
    fp = paper_params.fixed_point()
    theta = fp.theta_rad + rng.normal(0, 0.1, 500)
    v = fp.v_m_s + rng.normal(0, 0.3, 500)
    nv, nt = rng.normal(0, 0.05, 500), rng.normal(0, 0.02, 500)
    a = map_step(theta, v, paper_params, velocity_noise=nv, phase_noise=nt)
    b = controlled_step(theta, v, paper_params.racket_period, paper_params, PASSIVE,
                        velocity_noise=nv, phase_noise=nt)
    assert np.array_equal(a.theta, b.theta) and np.array_equal(a.v, b.v)
    assert np.array_equal(a.hop_phase, b.hop_phase)


def test_zero_gain_classification_is_the_passive_basin(paper_params):
    theta, v = np.meshgrid(np.linspace(0, 2 * np.pi, 90), np.linspace(0, 10, 90))
    passive = classify_batch(theta, v, paper_params)
    controlled = classify_controlled(theta, v, paper_params, PeriodController(0.0, 1.0))
    assert np.array_equal(passive.outcome, controlled.outcome)
    assert np.array_equal(passive.iterations, controlled.iterations)


@pytest.mark.parametrize("params", [
    ModelParams(alpha=0.8, g=9.81, racket_amplitude=0.6, racket_period=0.92),
    ModelParams(alpha=0.765, g=10.66, racket_amplitude=0.37, racket_period=0.643),
])
def test_zero_gain_classifier_step_is_the_passive_one_bit_for_bit(params):
    """The wrapped step (the classifier's: ``trig.sincos`` for the solve and for eq. 5) of a
    controller with K = 0 is the passive map's to the last bit, and so are the basins, with
    either kernel, where chaotic orbits would show any last-bit difference (eq. 5 once took
    numpy's cosine here and sincos there: 269 of 6400 points differed)."""
    rng = np.random.default_rng(9)
    theta, v = rng.uniform(0, 2 * np.pi, 4000), rng.uniform(0, 10, 4000)
    passive = PassiveMap.of(params, require_fixed_point=False)
    state = passive.start(theta, v, wrap=True)
    a = passive.step(state, wrap=True)
    b = controlled_step(state.theta, state.v, params.racket_period, params,
                        PeriodController(0.0, 1.0), wrap=True)
    assert np.array_equal(a.state.theta, b.theta, equal_nan=True)
    assert np.array_equal(a.state.v, b.v, equal_nan=True)
    th, vv = np.meshgrid(np.linspace(0, 2 * np.pi, 50), np.linspace(0, 10, 50))
    kernels = ["numpy"] + (["compiled"] if importlib.util.find_spec("numba") else [])
    for kernel in kernels:
        one = classify_batch(th, vv, params, kernel=kernel)
        other = classify_controlled(th, vv, params, PeriodController(0.0, 1.0), kernel=kernel)
        assert np.array_equal(one.outcome, other.outcome), kernel
        assert np.array_equal(one.iterations, other.iterations), kernel


def test_zero_gain_impulse_response_is_the_passive_one(paper_params):
    for alpha_p in (0.35, 0.6, 0.65):
        passive = impulse_response_full(paper_params, alpha_p, 12)
        controlled = controlled_impulse_response(paper_params, PeriodController(0.0, 1.0),
                                                 alpha_p, 12)
        assert np.array_equal(passive.v, controlled.v, equal_nan=True)
        assert np.array_equal(passive.dtheta, controlled.dtheta, equal_nan=True)
        assert np.all(controlled.dtau[np.isfinite(controlled.v)] == 0.0)


# -- the controlled step is physics: ballistics, the impact law, the first root ----------------
def test_controlled_step_obeys_ballistics_and_the_impact_law():
    """Independent of eqs. 5, 6 as coded: the ball starts on the racket (x = a sin theta_k) and
    flies ballistically; the racket continues from the same phase at the new frequency; at
    the impact both heights agree, the ball was above the racket before, and the velocity
    after obeys eq. 3 with the racket velocity a w_{k+1} cos(theta_{k+1})."""
    rng = np.random.default_rng(8)
    controller = PeriodController(0.8, 0.6)
    for p in (ModelParams(0.5, 9.81, 0.3, 0.92), OTHER):
        ref = Reference.of(p)
        for _ in range(60):
            theta = rng.uniform(0, 2 * np.pi)
            tau = p.racket_period * rng.uniform(0.8, 1.2)
            v = ref.v_m_s * rng.uniform(0.6, 1.4)
            step = controlled_step(theta, v, tau, p, controller)
            if not np.isfinite(step.v):
                continue
            tau_new = float(controller.next_period(v, theta, tau, ref))
            assert float(step.tau) == pytest.approx(tau_new, rel=1e-15)
            w = 2 * np.pi / tau_new
            T = float(step.hop_phase) / w
            ball = p.racket_amplitude * np.sin(theta) + v * T - p.g * T**2 / 2
            assert ball == pytest.approx(p.racket_amplitude * np.sin(float(step.theta)), abs=1e-9)
            t = np.linspace(0, T, 2001)[1:-1]
            above = (p.racket_amplitude * np.sin(theta) + v * t - p.g * t**2 / 2
                     - p.racket_amplitude * np.sin(theta + w * t))
            assert np.all(above > -1e-12)  # the FIRST impact
            v_racket = p.racket_amplitude * w * np.cos(float(step.theta))
            v_after = v_racket - p.alpha * ((v - p.g * T) - v_racket)
            assert float(step.v) == pytest.approx(v_after, rel=1e-10, abs=1e-10)


def test_controller_equation_and_fixed_point(paper_params):
    ref = Reference.of(paper_params)
    fp = paper_params.fixed_point()
    assert ref.v_m_s == pytest.approx(fp.v_m_s, rel=1e-15)
    assert ref.v_m_s == pytest.approx(paper_params.g * paper_params.racket_period / 2, rel=1e-14)
    c = PeriodController(gain=0.6, rate=0.25)
    # ball 0.981 m/s too fast: flight 0.2 s longer; target 0.92 + 0.6 * 0.2 = 1.04 s;
    # from tau_k = 1.0 s a quarter of the way: 1.01 s
    assert float(c.next_period(ref.v_m_s + 0.981, 0.3, 1.0, ref)) == pytest.approx(1.01)
    v, theta, tau = controlled_fixed_point(paper_params, c)
    step = controlled_step(theta, v, tau, paper_params, c)
    assert float(step.v) == pytest.approx(v, rel=1e-12)
    assert float(step.theta) == pytest.approx(theta + 2 * np.pi, rel=1e-13)
    assert float(step.tau) == tau


def test_a_period_at_or_below_zero_stops_the_ball(paper_params):
    # K = 3 and a slow ball ask for a negative period
    step = controlled_step(1.0, 0.5, paper_params.racket_period, paper_params,
                           PeriodController(3.0, 1.0))
    assert np.isnan(step.tau) and np.isnan(step.v) and np.isnan(step.hop_phase)
    res = classify_controlled(1.0, 3.0, paper_params, PeriodController(3.0, 1.0))
    assert np.atleast_1d(res.names())[0] == "sticking" and res.iterations[()] == 1


# -- the 3 x 3 Jacobian ------------------------------------------------------------------------
CONTROLLERS = [(0.0, 1.0), (0.0, 0.4), (0.5, 1.0), (0.7, 0.8), (1.0, 1.0), (-0.4, 1.5),
               (1.3, 0.2)]


@pytest.mark.parametrize("params", [ModelParams(0.5, 9.81, 0.3, 0.92), OTHER],
                         ids=["paper", "other"])
@pytest.mark.parametrize("gain,rate", CONTROLLERS)
def test_analytic_jacobian_matches_finite_differences(params, gain, rate):
    c = PeriodController(gain, rate)
    analytic = controlled_jacobian(params, c)
    numeric = finite_difference_controlled_jacobian(params, c)
    scale = np.abs(analytic).max()
    np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-7 * scale)


@pytest.mark.parametrize("rate", [0.0, 0.25, 1.0, 1.6])
def test_zero_gain_eigenvalues_are_eq10_plus_one_minus_c(paper_params, rate):
    M = controlled_jacobian(paper_params, PeriodController(0.0, rate))
    np.testing.assert_allclose(M[:2, :2], jacobian(paper_params), rtol=1e-15)
    lp, lm = eigenvalues(paper_params.alpha, racket_acceleration_at_impact_g(paper_params))
    expected = np.sort_complex(np.array([complex(lp), complex(lm), 1.0 - rate]))
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(M)), expected, atol=1e-12)


@pytest.mark.parametrize("params", [ModelParams(0.5, 9.81, 0.3, 0.92), OTHER],
                         ids=["paper", "other"])
def test_immediate_adaptation_closed_form(params):
    """c = 1: the period depends on v_k only, so one eigenvalue is 0 and the others solve
    lambda^2 - T lambda + D = 0 with D = alpha^2 - K (1-alpha)^2 and
    T = 1 + alpha^2 - K (1-alpha)^2 + (1+alpha)^2 AC (1 - K) (derived by hand from eqs. 5, 6)."""
    alpha, ac = params.alpha, racket_acceleration_at_impact_g(params)
    for gain in (-0.3, 0.2, 0.5, 0.74, 0.9):
        D = alpha**2 - gain * (1 - alpha) ** 2
        T = 1 + alpha**2 - gain * (1 - alpha) ** 2 + (1 + alpha) ** 2 * ac * (1 - gain)
        expected = np.sort_complex(np.concatenate([[0.0], np.roots([1.0, -T, D])]))
        got = np.sort_complex(np.linalg.eigvals(controlled_jacobian(params,
                                                                    PeriodController(gain, 1.0))))
        np.testing.assert_allclose(got, expected, atol=1e-12)


def test_gain_one_has_a_line_of_fixed_points(paper_params):
    """K = 1: the period follows the flight time exactly, so every period has its period-1
    orbit (v = g tau / 2, eq. 8 at tau): the map keeps it, and the Jacobian has eigenvalue 1."""
    c = PeriodController(1.0, 0.5)
    assert np.abs(np.linalg.eigvals(controlled_jacobian(paper_params, c))).max() == pytest.approx(
        1.0, abs=1e-12)
    tau = 0.95
    shifted = ModelParams(0.5, 9.81, 0.3, tau)
    fp = shifted.fixed_point()
    step = controlled_step(fp.theta_rad, fp.v_m_s, tau, paper_params, c)
    assert float(step.tau) == pytest.approx(tau, rel=1e-13)
    assert float(step.v) == pytest.approx(fp.v_m_s, rel=1e-10)
    assert float(step.theta) == pytest.approx(fp.theta_rad + 2 * np.pi, rel=1e-12)


@pytest.mark.parametrize("gain,rate", [(0.0, 1.0), (0.5, 1.0), (0.7, 0.8), (0.3, 0.4)])
def test_long_simulation_decays_at_the_spectral_radius(paper_params, gain, rate):
    """Closed form vs long simulation: a tiny deviation of the full map shrinks per impact by
    the Jacobian's spectral radius."""
    c = PeriodController(gain, rate)
    radius = float(period_control_radius(paper_params, gain, rate))
    v, theta, tau = controlled_fixed_point(paper_params, c)
    th, vv, tt = theta, v * (1 + 1e-4), tau * (1 + 1e-4)
    norms = []
    while not norms or norms[-1] > 1e-11:
        step = controlled_step(th, vv, tt, paper_params, c)
        th, vv, tt = float(step.theta) - 2 * np.pi, float(step.v), float(step.tau)
        norms.append(math.sqrt(((vv - v) / v) ** 2 + (th - theta) ** 2 + ((tt - tau) / tau) ** 2))
    k = np.arange(3, len(norms))
    rate_fit = math.exp(np.polyfit(k, np.log(np.array(norms)[k]), 1)[0])
    assert rate_fit == pytest.approx(radius, rel=0.05)


def test_radius_grid_equals_the_single_jacobians(paper_params):
    K, c = np.meshgrid([0.0, 0.5, 0.9], [0.2, 1.0])
    grid = period_control_radius(paper_params, K, c)
    for i in np.ndindex(K.shape):
        M = controlled_jacobian(paper_params, PeriodController(float(K[i]), float(c[i])))
        assert grid[i] == pytest.approx(np.abs(np.linalg.eigvals(M)).max(), rel=1e-12)


# -- impulse responses, basin, threshold -----------------------------------------------------
def test_controlled_response_modulates_the_period_with_the_ball(paper_params):
    """Fig. 11's sign: a faster ball (alpha_p > alpha_0) lengthens the next racket period."""
    c = PeriodController(0.7, 1.0)
    up = controlled_impulse_response(paper_params, c, 0.6, 6)
    down = controlled_impulse_response(paper_params, c, 0.4, 6)
    assert up.dtau[0] == 0.0 == down.dtau[0]  # the perturbed impact is not foreseen
    assert up.dtau[1] == pytest.approx(0.7 * 2 * up.dv[0] / paper_params.g, rel=1e-12)
    assert up.dtau[1] > 0 > down.dtau[1]
    tol = (0.05, math.radians(1.0))
    passive = [impulse_response_full(paper_params, a, 100) for a in (0.4, 0.6)]
    from bounce_cli.model.perturbation import relaxation_impacts
    slow = [relaxation_impacts(r.dv, r.dtheta, *tol) for r in passive]
    fast = [controlled_impulse_response(paper_params, c, a, 100).relaxation_impacts(*tol)
            for a in (0.4, 0.6)]
    assert all(f < s for f, s in zip(fast, slow))


def test_zero_gain_threshold_is_bounce_impulse_threshold(paper_params):
    from bounce_cli.runtime.config import bundled_config_path, load_config
    from bounce_cli.experiments import impulse as exp

    cfg = load_config(exp.ImpulseConfig, bundled_config_path("impulse"),
                      ["threshold.scan_step=0.02", "threshold.bisection_tolerance=1e-3"])
    passive = exp.threshold_row(paper_params, +1, cfg)
    ours = find_threshold(paper_params, +1, cfg.classify.settings(), scan_step=0.02,
                          bisection_tolerance=1e-3, alpha_p_max=0.99, controller=PASSIVE)
    assert ours.alpha_p_threshold == passive["alpha_p_threshold"]
    assert ours.outcome_outside == passive["outcome_outside"]
    assert ours.alpha_p_threshold == pytest.approx(0.63, abs=0.01)  # section 7: about 0.65


def test_period_one_needs_the_period_back_too(paper_params):
    """With the period as state, a point is period-1 only when tau is back at tau_bar too:
    a stricter period tolerance takes longer (v, theta alone would be back sooner)."""
    fp = paper_params.fixed_point()
    c = PeriodController(0.0, 0.3)  # the period relaxes by 0.7 per impact
    settings = ClassifySettings(max_iterations=200)

    def iterations(tol):
        res = classify_controlled(fp.theta_rad, fp.v_m_s, paper_params, c, settings,
                                  tau0=paper_params.racket_period + 0.01,
                                  period_tolerance_s=tol)
        assert np.atleast_1d(res.names())[0] == "period1"
        return int(res.iterations)

    strict, default, ignored = iterations(1e-9), iterations(None), iterations(1e9)
    assert strict > default >= ignored
    # 0.01 s * 0.7^n < 1e-9 s needs n >= 46
    assert strict >= math.ceil(math.log(1e-7) / math.log(0.7))


# -- perturbation trials: alignment and fit --------------------------------------------------------
def test_alignment_keeps_windows_inside_trials_and_without_gaps():
    #            trial 0: k 0..7, perturbed at 2 and 6 (6 is too close to the end)
    #            trial 1: k 0..6 with k = 4 missing, perturbed at 1 (gap) and 5 (end)
    trial = [0] * 8 + [1] * 6
    k = list(range(8)) + [0, 1, 2, 3, 5, 6]
    perturbed = [False, False, True, False, False, False, True, False,
                 False, True, False, False, True, False]
    v = np.arange(14, dtype=float)
    theta = np.full(14, 0.5)
    tau = np.full(14, 0.9)
    out = align_perturbations(trial, k, v, theta, tau, perturbed, n_after=3)
    assert list(out) == ["increase"] or list(out) == ["decrease"]
    (resp,) = out.values()
    assert resp.n_events == 1
    # the baseline: the trial's unperturbed impacts (the data side's alignment, settle 0)
    np.testing.assert_allclose(resp.dv_m_s, np.arange(2, 6) - np.mean([0, 1, 3, 4, 5, 7]))


@pytest.fixture(scope="module")
def simulated_fit():
    params = ModelParams(0.5, 9.81, 0.3, 0.92)
    truth = PeriodController(0.7, 0.8)
    data = simulate_perturbation_trials(
        params, truth, n_trials=24, impacts_per_trial=60, velocity_noise_sd=0.05,
        phase_noise_sd=0.02, period_noise_sd=0.005, seed=11,
        alpha_p_low=(0.3, 0.4), alpha_p_high=(0.6, 0.7))
    responses = align_perturbations(data["trial"], data["k"], data["v_m_s"], data["theta_rad"],
                                    data["racket_period_s"], data["perturbed"],
                                    alpha=data["alpha"], alpha_0=0.5)
    return params, truth, data, responses, fit_period_control(params, list(responses.values()))


def test_simulated_trials_follow_the_paper_protocol(simulated_fit):
    _, _, data, responses, _ = simulated_fit
    assert np.all(data["perturbed"] == ((data["k"] % 5 == 0) & (data["k"] > 0)))
    hit = data["alpha"][data["perturbed"]]
    assert np.all(((hit >= 0.3) & (hit <= 0.4)) | ((hit >= 0.6) & (hit <= 0.7)))
    assert len(data["k"]) == 24 * 60  # no trial lost its ball
    assert responses["increase"].dv_m_s[0] > 0 > responses["decrease"].dv_m_s[0]
    assert responses["increase"].dtau_s[1] > 0 > responses["decrease"].dtau_s[1]  # Fig. 11


def test_fit_recovers_known_gain_and_rate(simulated_fit):
    params, truth, _, _, fit = simulated_fit
    assert fit.success
    assert fit.gain_ci[0] <= truth.gain <= fit.gain_ci[1]
    assert fit.rate_ci[0] <= truth.rate <= fit.rate_ci[1]
    assert fit.gain_ci[1] - fit.gain_ci[0] < 0.1 and fit.rate_ci[1] - fit.rate_ci[0] < 0.1
    # the known small bias of fitting noisy means (fit_period_control's docstring)
    assert abs(fit.gain - truth.gain) < 0.025 and abs(fit.rate - truth.rate) < 0.025
    assert 0.3 < fit.reduced_chi2 < 3.0
    true_radius = float(period_control_radius(params, truth.gain, truth.rate))
    assert fit.spectral_radius == pytest.approx(true_radius, abs=0.05)


@pytest.mark.slow
def test_fit_of_passive_trials_finds_no_period_control():
    """Passive trials (K = 0): the period never answers the ball, so the fitted immediate
    period response 2 c K / g is nil and K's interval holds 0 (with c -> 0 K is not
    identifiable at all: its interval is wide)."""
    params = ModelParams(0.5, 9.81, 0.3, 0.92)
    data = simulate_perturbation_trials(
        params, PeriodController(0.0, 0.5), n_trials=16, impacts_per_trial=60,
        velocity_noise_sd=0.05, phase_noise_sd=0.02, period_noise_sd=0.005, seed=4,
        alpha_p_low=(0.4, 0.45), alpha_p_high=(0.55, 0.6))
    responses = align_perturbations(data["trial"], data["k"], data["v_m_s"], data["theta_rad"],
                                    data["racket_period_s"], data["perturbed"],
                                    alpha=data["alpha"], alpha_0=0.5)
    fit = fit_period_control(params, list(responses.values()))
    assert fit.gain_ci[0] <= 0.0 <= fit.gain_ci[1]
    assert abs(fit.gain * fit.rate) < 0.02


def test_flight_time_matching_returns_the_phase_in_one_impact(paper_params):
    """K = 1, c = 1: the racket period becomes the ball's flight time 2 v_0 / g (since
    tau_bar = 2 v~ / g, eq. 7), so a ball kicked at theta~ lands at theta~ again, exactly
    (nonlinear, any size): section 7's subject, back after one impact. Its spectral radius
    is 1 nonetheless (a line of fixed points): the slowest mode is not what this
    perturbation excites."""
    c = PeriodController(1.0, 1.0)
    for alpha_p in (0.35, 0.6, 0.65):
        r = controlled_impulse_response(paper_params, c, alpha_p, 20)
        v0 = r.v[0]
        assert r.tau[1] == pytest.approx(2 * v0 / paper_params.g, rel=1e-14)
        assert abs(r.dtheta[1]) < 1e-9
        assert r.relaxation_impacts(0.05, math.radians(1.0)) <= 2
    assert float(period_control_radius(paper_params, 1.0, 1.0)) == pytest.approx(1.0, abs=1e-12)


def test_grid_tiles_and_orbit_agree_with_the_batch(paper_params):
    from bounce_cli.analysis.classify import classify_grid
    from bounce_cli.model.control import ControlledMap, iterate_controlled_orbit

    c = PeriodController(0.6, 0.9)
    theta, v = np.meshgrid(np.linspace(0, 2 * np.pi, 50), np.linspace(0, 10, 50))
    whole = classify_controlled(theta, v, paper_params, c)
    tiled = classify_grid(theta, v, ControlledMap.of(paper_params, c, require_fixed_point=True),
                          tile_points=77)
    assert np.array_equal(whole.outcome, tiled.outcome)
    assert np.array_equal(whole.iterations, tiled.iterations)
    orbit = iterate_controlled_orbit(0.8, 5.3, paper_params, c, 15, 1e-3)
    batch = iterate_controlled(0.8, 5.3, paper_params.racket_period, paper_params, c, 15)
    for a, b in zip((orbit.theta, orbit.v, orbit.tau), batch[:3]):
        assert np.array_equal(a, b)


@pytest.mark.slow
def test_fit_survives_a_labs_degradations():
    """Trials as a lab's table comes: rows missing (tracking gaps), a calibration offset on v,
    a constant phase offset (another zero of the racket cycle), the period measured with
    2 ms jitter, rows shuffled. The fit still contains the truth."""
    params = ModelParams(0.5, 9.81, 0.3, 0.92)
    truth = PeriodController(0.6, 0.7)
    d = simulate_perturbation_trials(params, truth, n_trials=24, impacts_per_trial=60,
                                     velocity_noise_sd=0.05, phase_noise_sd=0.02,
                                     period_noise_sd=0.005, seed=21)
    rng = np.random.default_rng(0)
    keep = rng.random(len(d["k"])) > 0.05
    order = rng.permutation(np.flatnonzero(keep))
    trial, k, perturbed, alpha = (d[c][order] for c in ("trial", "k", "perturbed", "alpha"))
    v = d["v_m_s"][order] + 0.12
    theta = np.mod(d["theta_rad"][order] + 0.3, 2 * np.pi)
    tau = d["racket_period_s"][order] + rng.normal(0, 0.002, order.size)
    responses = align_perturbations(trial, k, v, theta, tau, perturbed, alpha=alpha,
                                    alpha_0=0.5)
    assert all(r.n_events < 24 * 11 / 2 for r in responses.values())  # gapped windows dropped
    fit = fit_period_control(params, list(responses.values()))
    assert fit.gain_ci[0] <= truth.gain <= fit.gain_ci[1]
    assert fit.rate_ci[0] <= truth.rate <= fit.rate_ci[1]


@pytest.mark.slow
def test_fit_is_not_caught_in_a_local_minimum():
    """At a_r = 0.5 m a start at (K, c) = (0.5, 0.5) alone ends at K = 0.31, c = 1.55 (reduced
    chi2 ~ 4000); the grid of starts finds the truth."""
    params = ModelParams(0.5, 9.81, 0.5, 0.92)
    truth = PeriodController(0.7, 1.0)
    d = simulate_perturbation_trials(params, truth, n_trials=20, impacts_per_trial=60,
                                     velocity_noise_sd=0.05, phase_noise_sd=0.02,
                                     period_noise_sd=0.005, seed=1)
    responses = align_perturbations(d["trial"], d["k"], d["v_m_s"], d["theta_rad"],
                                    d["racket_period_s"], d["perturbed"], alpha=d["alpha"],
                                    alpha_0=0.5)
    single = fit_period_control(params, list(responses.values()), starts_from_grid=0)
    assert single.reduced_chi2 > 100  # the trap exists
    fit = fit_period_control(params, list(responses.values()))
    assert fit.gain_ci[0] <= truth.gain <= fit.gain_ci[1]
    assert fit.rate_ci[0] <= truth.rate <= fit.rate_ci[1]
    assert fit.reduced_chi2 < 3


def test_alignment_without_a_perturbed_impact_is_empty_by_the_errors_class():
    """No perturbed impact: no responses (decided by ``NoPerturbedImpactError``, not by the
    message's text)."""
    trial, k = np.zeros(20, int), np.arange(20)
    v, theta, tau = np.full(20, 4.5), np.full(20, 0.4), np.full(20, 0.92)
    assert align_perturbations(trial, k, v, theta, tau, np.zeros(20, bool), n_after=3) == {}
