"""The deterministic map (eqs. 5, 6)."""

import math

import numpy as np
import pytest

from bounce_cli.model.impact import gap
from bounce_cli.model.maps import iterate_map, iterate_orbit, map_step
from bounce_cli.model.params import ModelParams, phase_difference

FIG3_THETA0 = math.asin(0.205 / 0.30)  # section 3: x_b(0) = 0.205 m on the racket


def test_fixed_point_is_fixed(paper_params):
    fp = paper_params.fixed_point()
    step = map_step(fp.theta_rad, fp.v_m_s, paper_params)
    assert float(step.theta) == pytest.approx(fp.theta_rad + 2 * math.pi, rel=1e-13)
    assert float(step.v) == pytest.approx(fp.v_m_s, rel=1e-12)


def test_velocity_map_obeys_impact_law_eq3():
    """Independent route to eq. 5: ballistic arrival velocity (eq. 2) and the impact law
    (eq. 3) with the racket velocity at the new impact."""
    rng = np.random.default_rng(11)
    for _ in range(200):
        p = ModelParams(rng.uniform(0, 0.95), 9.81, rng.uniform(0.1, 0.5), rng.uniform(0.4, 1.5))
        theta = rng.uniform(0, 2 * np.pi)
        v = float(p.racket_velocity(theta)) + rng.uniform(0.01, 8)
        step = map_step(theta, v, p)
        dt = float(step.hop_phase) / p.omega
        v_before = v - p.g * dt  # eq. 2
        v_racket = float(p.racket_velocity(step.theta))
        v_after = v_racket - p.alpha * (v_before - v_racket)  # eq. 3 solved for v_b^+
        assert float(step.v) == pytest.approx(v_after, rel=1e-10, abs=1e-10)
        # and the ball lands on the racket (eq. 6): ball height = racket height
        x_ball = float(p.racket_position(theta)) + v * dt - p.g * dt**2 / 2
        assert x_ball == pytest.approx(float(p.racket_position(step.theta)), abs=1e-10)


def test_fig3_period1_initial_condition_settles(paper_params):
    """Fig. 3 top: leaving at asin(0.205/0.30) with 4.8 m/s reaches the period-1 attractor."""
    fp = paper_params.fixed_point()
    orbit = iterate_orbit(FIG3_THETA0, 4.8, paper_params, 40, 1e-3)
    assert orbit.stop_reason == ""
    assert abs(orbit.v[-1] - fp.v_m_s) < 1e-6
    assert abs(phase_difference(orbit.theta[-1], fp.theta_rad)) < 1e-6


def test_fig3_sticking_initial_condition_sticks(paper_params):
    """Fig. 3 bottom: 5.7 m/s ends in the sticking solution (hops shrink below 1 ms)."""
    orbit = iterate_orbit(FIG3_THETA0, 5.7, paper_params, 40, 1e-3)
    assert orbit.stop_reason == "sticking"
    hops = orbit.hop_phase[1:] / paper_params.omega
    assert hops[-1] < 1e-3
    assert np.all(hops[-6:] < hops[-7])  # a chattering sequence of shrinking hops


def test_below_racket_stops_at_once(paper_params):
    orbit = iterate_orbit(0.3, 0.0, paper_params, 10, 1e-3)
    assert orbit.stop_reason == "below_racket"
    assert len(orbit.theta) == 1


def test_iterate_map_matches_repeated_steps_and_keeps_phase_unwrapped(paper_params):
    theta0 = np.array([0.2, 1.0, 3.0])
    v0 = np.array([5.0, 4.0, 6.0])
    theta, v, hop = iterate_map(theta0, v0, paper_params, 5)
    assert theta.shape == (6, 3)
    t, vv = theta0, v0
    for k in range(1, 6):
        step = map_step(t, vv, paper_params)
        t, vv = step.theta, step.v
        np.testing.assert_allclose(theta[k], t)
        np.testing.assert_allclose(v[k], vv)
    assert np.all(np.diff(theta, axis=0) > 0)  # unwrapped phase always increases
    np.testing.assert_allclose(np.diff(theta, axis=0), hop[1:], rtol=1e-12)


def test_each_impact_is_the_first_contact(paper_params):
    theta, v, hop = iterate_map(np.array([0.5, 2.0]), np.array([6.0, 7.5]), paper_params, 20)
    for k in range(20):
        for j in range(2):
            s = np.linspace(0, hop[k + 1, j], 3000)[1:-1]
            assert np.all(gap(s, theta[k, j], v[k, j], paper_params) > -1e-12)


def test_an_unstable_fixed_point_is_no_start_s_period1(paper_params):
    """A start ON the period-1 fixed point stays one impact at the stable point (period1 at
    once); where it is linearly unstable (eq. 10: alpha 0.7, a_r 0.3 m, spectral radius 2.07)
    a start within the tolerance of it has not reached an attractor: it leaves, and no start
    is period1 (the target is NaN)."""
    from bounce_cli.analysis.classify import OUTCOMES, classify_batch, passive_map
    from bounce_cli.model.linear import stability

    for params, stable in ((paper_params, True),
                           (paper_params.with_alpha(0.7), False)):
        assert stability(params).stable is stable
        fp = params.fixed_point()
        result = classify_batch(np.array([fp.theta_rad]), np.array([fp.v_m_s]), params)
        if stable:
            assert OUTCOMES[result.outcome[0]] == "period1" and result.iterations[0] == 1
            assert passive_map(params).target == fp
        else:
            assert OUTCOMES[result.outcome[0]] != "period1"
            assert math.isnan(passive_map(params).target.v_m_s)
