"""Stochastic map (eqs. 16-18) and VAR(1) theory (eq. 19)."""

import math

import numpy as np
import pytest

from bounce_cli.paper import values as paper
from bounce_cli.model.linear import jacobian
from bounce_cli.model.maps import map_step
from bounce_cli.model.params import ModelError, ModelParams
from bounce_cli.analysis.stochastic import (
    PAIR_NAMES,
    map_noise_covariance,
    paper_noise_covariance,
    sample_correlations,
    simulate_stochastic_map,
    stationary_covariance,
    stochastic_step,
    var1_theory,
)

ACF_PARAMS = paper.FIG8_MODEL  # the paper's Fig. 8 parameters (section 6)


def covariance_by_summation(jac, noise_cov, terms=400):
    """Independent route: R(0) = sum_i J^i Q (J^i)^T."""
    total = np.zeros_like(noise_cov)
    power = np.eye(len(jac))
    for _ in range(terms):
        total += power @ noise_cov @ power.T
        power = jac @ power
    return total


def test_stationary_covariance_matches_summation_and_lyapunov_identity():
    jac = jacobian(ACF_PARAMS)
    for q in (paper_noise_covariance(0.04, 0.05), map_noise_covariance(ACF_PARAMS, 0.04, 0.05)):
        cov = stationary_covariance(jac, q)
        np.testing.assert_allclose(cov, covariance_by_summation(jac, q), rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(jac @ cov @ jac.T + q, cov, rtol=1e-12, atol=1e-15)


def test_lagged_correlations_follow_powers_of_j_and_paper_signs():
    jac = jacobian(ACF_PARAMS)
    th = var1_theory(jac, paper_noise_covariance(0.04, 0.05), max_lag=10)
    cov1 = jac @ th.cov0
    sd = np.sqrt(np.diag(th.cov0))
    # R(1)[1, 0] = E[theta_{k+1} v_k] is velocity -> phase
    assert th.correlations["v_to_theta"][1] == pytest.approx(cov1[1, 0] / (sd[0] * sd[1]))
    assert th.correlations["theta_to_v"][1] == pytest.approx(cov1[0, 1] / (sd[0] * sd[1]))
    # section 6: velocity -> phase has a negative lag-0 and a positive lag-1 correlation,
    # phase -> velocity only lag 0 is sizeable. Transposing the pairs breaks this.
    assert th.correlations["v_to_theta"][0] < -0.5
    assert th.correlations["v_to_theta"][1] > 0.5
    assert abs(th.correlations["theta_to_v"][1]) < 0.2
    assert th.correlations["v_to_theta"][0] == th.correlations["theta_to_v"][0]
    for name in ("v_v", "theta_theta"):
        assert th.correlations[name][0] == pytest.approx(1.0)
    # decay like |lambda|^l = alpha^l in the complex regime
    assert abs(th.correlations["v_v"][10]) < 5 * 0.42**10


def test_lag_convention_on_a_pure_delay():
    """theta_{k+1} = v_k: only v_to_theta at lag 1 is one, in theory and in the sample."""
    jac = np.array([[0.0, 0.0], [1.0, 0.0]])
    q = np.diag([1.0, 1e-12])
    th = var1_theory(jac, q, max_lag=2)
    assert th.correlations["v_to_theta"][1] == pytest.approx(1.0, abs=1e-6)
    assert th.correlations["theta_to_v"][1] == pytest.approx(0.0, abs=1e-6)
    v = np.random.default_rng(0).standard_normal(5000)
    theta = np.concatenate([[0.0], v[:-1]])
    s = sample_correlations(v, theta, max_lag=2)
    assert s["v_to_theta"][1] == pytest.approx(1.0, abs=1e-3)
    assert abs(s["theta_to_v"][1]) < 0.05


def test_sample_estimator_on_a_linear_var1_matches_theory():
    """The estimator against the closed form, on data generated directly from eq. 19."""
    jac = jacobian(ACF_PARAMS)
    q = map_noise_covariance(ACF_PARAMS, 0.04, 0.05)
    runs, n = 200, 2000
    rng = np.random.default_rng(1)
    chol = np.linalg.cholesky(q)
    y = np.zeros((runs, 2))
    out = np.empty((runs, 2, n))
    for k in range(n + 50):
        y = y @ jac.T + rng.standard_normal((runs, 2)) @ chol.T
        if k >= 50:
            out[:, :, k - 50] = y
    s = sample_correlations(out[:, 0], out[:, 1], max_lag=4)
    th = var1_theory(jac, q, max_lag=4)
    for name in PAIR_NAMES:
        se = s[name].std(axis=0) / math.sqrt(runs) + 1e-9
        bias = 5.0 / n  # the 1/N estimator's bias is O(l/N)
        assert np.all(np.abs(s[name].mean(axis=0) - th.correlations[name]) < 4 * se + bias), name


@pytest.mark.slow
@pytest.mark.parametrize("velocity_phase", ["theta", "phi"])
def test_stochastic_map_sample_matches_linear_theory_at_small_noise(velocity_phase):
    """Long runs of eqs. 16-18 agree with eq. 19 (with the noise covariance the map induces)
    within standard errors when the noise is small enough for the linearisation."""
    q_v, q_t = 0.008, 0.01
    runs, n = 60, 1500
    seeds = np.random.SeedSequence(7).spawn(runs)
    res = simulate_stochastic_map(ACF_PARAMS, q_v, q_t, n, seeds, burn_in=30,
                                  velocity_phase=velocity_phase)
    assert not res.lost.any()
    s = sample_correlations(res.dv, res.dtheta, max_lag=3)
    th = var1_theory(jacobian(ACF_PARAMS),
                     map_noise_covariance(ACF_PARAMS, q_v, q_t, velocity_phase), max_lag=3)
    for name in PAIR_NAMES:
        se = s[name].std(axis=0) / math.sqrt(runs) + 1e-9
        assert np.all(np.abs(s[name].mean(axis=0) - th.correlations[name]) < 4 * se + 3.0 / n), name
    assert np.std(res.dv) == pytest.approx(th.sd_v_m_s, rel=0.03)
    assert np.std(res.dtheta) == pytest.approx(th.sd_theta_rad, rel=0.03)


def test_printed_eq16_noise_is_not_diagonal_and_differs_from_phi_reading():
    q_map = map_noise_covariance(ACF_PARAMS, 0.04, 0.05, "theta")
    c = -(1.42) * 0.065 * ACF_PARAMS.omega * math.sin(ACF_PARAMS.fixed_point().theta_rad)
    assert q_map[0, 1] == pytest.approx(c * 0.05**2)
    assert q_map[0, 0] == pytest.approx(0.04**2 + c**2 * 0.05**2)
    np.testing.assert_array_equal(map_noise_covariance(ACF_PARAMS, 0.04, 0.05, "phi"),
                                  paper_noise_covariance(0.04, 0.05))


def test_stochastic_step_implements_eqs_16_to_18():
    fp = ACF_PARAMS.fixed_point()
    theta, v = np.array([fp.theta_rad + 0.03]), np.array([fp.v_m_s - 0.02])
    dv, dth = 0.011, -0.02
    det = map_step(theta, v, ACF_PARAMS)  # noiseless phi_{k+1} from eq. 17
    phi, hop = det.theta, det.hop_phase
    w, a, al, g = ACF_PARAMS.omega, 0.065, 0.42, 5.8
    # eq. 17 holds for phi
    eq17 = a * w**2 * (np.sin(theta) - np.sin(phi)) + v * w * hop - g / 2 * hop**2
    assert eq17 == pytest.approx(0, abs=1e-9)
    for vp, phase_in_cos in (("theta", phi + dth), ("phi", phi)):
        th1, v1, hop1 = stochastic_step(theta, v, ACF_PARAMS, dv, dth, vp)
        np.testing.assert_allclose(th1, phi + dth)  # eq. 18
        np.testing.assert_allclose(hop1, hop)
        # eq. 16
        expected = (1 + al) * a * w * np.cos(phase_in_cos) - al * v + g * al / w * hop + dv
        np.testing.assert_allclose(v1, expected, rtol=1e-13)


def test_runs_do_not_depend_on_batching_or_block_size():
    seeds = np.random.SeedSequence(11).spawn(6)
    kw = dict(burn_in=5)
    all_runs = simulate_stochastic_map(ACF_PARAMS, 0.04, 0.05, 300, seeds, block=64, **kw)
    again = simulate_stochastic_map(ACF_PARAMS, 0.04, 0.05, 300, seeds, block=64, **kw)
    np.testing.assert_array_equal(all_runs.dv, again.dv)
    part = simulate_stochastic_map(ACF_PARAMS, 0.04, 0.05, 300, seeds[2:4], block=50, **kw)
    np.testing.assert_allclose(part.dv, all_runs.dv[2:4], rtol=0, atol=1e-12)
    np.testing.assert_allclose(part.dtheta, all_runs.dtheta[2:4], rtol=0, atol=1e-12)
    other = simulate_stochastic_map(ACF_PARAMS, 0.04, 0.05, 300,
                                    np.random.SeedSequence(12).spawn(6), **kw)
    assert not np.allclose(other.dv, all_runs.dv)


def test_phase_is_kept_wrapped_in_long_runs():
    res = simulate_stochastic_map(ACF_PARAMS, 0.0, 0.0, 800, np.random.SeedSequence(0).spawn(2))
    # noiseless from the fixed point: stays there to rounding, not drifting with k
    assert np.max(np.abs(res.dtheta)) < 1e-9 and np.max(np.abs(res.dv)) < 1e-9


def test_unstable_fixed_point_has_no_stationary_covariance():
    # the paper's observed a_r = 0.076 m, tau = 0.53 s: a flip-unstable fixed point
    observed = ModelParams(alpha=0.42, g=5.8, racket_amplitude=0.076, racket_period=0.53)
    with pytest.raises(ModelError, match="spectral radius 1.3"):
        stationary_covariance(jacobian(observed), paper_noise_covariance(0.04, 0.05))


def test_lost_runs_are_flagged_and_blank_from_the_loss_on():
    """q_v = 0.08 m/s: one of 8 runs of 300 bounces (seed 1) loses the ball at bounce 290
    (a hop shorter than 1 ms); its row is NaN from there on, the other runs are untouched,
    and the lost run alone gives the same numbers (each run has its own stream)."""
    seeds = np.random.SeedSequence(1).spawn(8)
    runs = simulate_stochastic_map(ACF_PARAMS, 0.08, 0.05, 300, seeds)
    assert runs.lost.tolist() == [False] * 4 + [True] + [False] * 3
    blank = np.isnan(runs.dv[4])
    first = int(np.argmax(blank))
    assert 0 < first and blank[first:].all() and not blank[:first].any()
    assert (np.isnan(runs.dtheta[4]) == blank).all()
    assert np.isfinite(runs.dv[~runs.lost]).all()
    alone = simulate_stochastic_map(ACF_PARAMS, 0.08, 0.05, 300, seeds[4:5])
    assert alone.lost.tolist() == [True]
    np.testing.assert_array_equal(alone.dv[0], runs.dv[4])
    # a longer shortest hop loses it no later
    strict = simulate_stochastic_map(ACF_PARAMS, 0.08, 0.05, 300, seeds[4:5], min_hop_s=0.05)
    assert int(np.argmax(np.isnan(strict.dv[0]))) <= first
