"""Continuation of periodic orbits (engine.continuation): the analytic derivatives against
finite differences, the located flips and folds against eqs. 8 and 14, the period-doubling
cascade and its Feigenbaum ratios, grazing, and the continued orbits against the map itself
(brute-force iteration and the bifurcation sweep's flip)."""

import math

import numpy as np
import pytest

from bounce_cli.analysis.bifurcation import (
    SweepSettings,
    locate_period_doubling,
    parameter_point,
    period1_thresholds,
    threshold_gamma,
)
from bounce_cli.analysis.continuation import (
    Continuation,
    ContinuationSettings,
    continued_period1_thresholds,
    eq8_orbit,
    evaluate_orbit,
    feigenbaum_ratios,
    flight_minimum_gap,
    orbit_by_iteration,
    parameter_derivative,
    period1_flip,
)
from bounce_cli.model.impact import gap, next_impact_phase
from bounce_cli.model.linear import flip_boundary_g
from bounce_cli.model.maps import map_step
from bounce_cli.model.params import ModelError, ModelParams

BASE = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)
PARAMETERS = ("gamma", "racket_amplitude", "racket_period", "alpha")


def value_of(params: ModelParams, parameter: str) -> float:
    if parameter == "gamma":
        return params.racket_amplitude * params.omega**2 / params.g
    return getattr(params, parameter)


@pytest.mark.parametrize("parameter", PARAMETERS)
def test_parameter_derivatives_match_central_differences_of_the_map(parameter):
    """dF/dp of eqs. 5, 6 (implicit differentiation) against the first-impact solver re-run at
    p +- h, at random states and parameters: a sign slip or a missing chain factor (Gamma
    acting through a_r, tau through w) would be off by O(1)."""
    rng = np.random.default_rng(7)
    for _ in range(40):
        params = ModelParams(alpha=rng.uniform(0.2, 0.9), g=9.81,
                             racket_amplitude=rng.uniform(0.1, 0.5),
                             racket_period=rng.uniform(0.6, 1.2))
        theta = rng.uniform(0.0, 2 * math.pi)
        v = float(params.racket_velocity(theta)) + rng.uniform(0.5, 8.0)
        step = map_step(theta, v, params)
        hop = float(step.hop_phase)
        if not math.isfinite(hop) or hop / params.omega < 0.05:
            continue
        p0 = value_of(params, parameter)
        h = 1e-6 * p0
        plus, minus = (map_step(theta, v, parameter_point(params, parameter, p0 + d))
                       for d in (h, -h))
        fd = np.array([(float(plus.v) - float(minus.v)) / (2 * h),
                       (float(plus.theta) - float(minus.theta)) / (2 * h)])
        analytic = parameter_derivative(theta, v, hop, params, parameter)
        # a flight ending near a tangency magnifies rounding in the differences: skip those
        if abs(float(plus.hop_phase) - float(minus.hop_phase)) > 1e-3:
            continue
        np.testing.assert_allclose(analytic, fd, rtol=2e-5, atol=1e-7 * np.abs(fd).max())


def test_orbit_monodromy_and_parameter_derivative_match_finite_differences():
    """M = dF^p/dx and dF^p/dGamma along a 3-impact piece of orbit against central
    differences of the whole piece (continued hops), in all three directions."""
    params = parameter_point(BASE, "gamma", 1.6)
    x = np.array([5.0, 0.7])
    hops = list(map_step(x[1], x[0], params).hop_phase.reshape(1))
    for _ in range(2):
        ev = evaluate_orbit(x, params, "gamma", 0, hops)
        hops = list(ev.hops) + [float(map_step(ev.theta[-1], ev.v[-1], params).hop_phase)]
    ev = evaluate_orbit(x, params, "gamma", 0, hops)

    def end(xx, gamma):
        e = evaluate_orbit(xx, parameter_point(BASE, "gamma", gamma), "gamma", 0, hops)
        return np.array([e.v[-1], e.theta[-1]])

    fd = np.empty((2, 3))
    for i, h in enumerate((1e-6, 1e-7)):
        d = np.zeros(2)
        d[i] = h
        fd[:, i] = (end(x + d, 1.6) - end(x - d, 1.6)) / (2 * h)
    fd[:, 2] = (end(x, 1.6 + 1e-7) - end(x, 1.6 - 1e-7)) / 2e-7
    np.testing.assert_allclose(ev.monodromy, fd[:, :2], rtol=1e-5)
    np.testing.assert_allclose(ev.parameter_derivative, fd[:, 2], rtol=1e-5)


@pytest.mark.parametrize("alpha", [0.05, 0.3, 0.5, 0.7, 0.9])
def test_period1_flip_equals_eq14_to_1e10(alpha):
    """The located flip of eq. 8's orbit within 1e-10 (relative) of eq. 14's closed form,
    Gamma^2 = AC_flip^2 + (pi (1-alpha)/(1+alpha))^2, at any alpha."""
    exact = float(threshold_gamma(alpha, float(flip_boundary_g(alpha))))
    existence = float(threshold_gamma(alpha, 0.0))
    base = BASE.with_alpha(alpha)
    flip = period1_flip(base, "gamma", existence, 1.2 * exact, 0.5 * (existence + exact))
    assert flip is not None
    assert flip.value == pytest.approx(exact, rel=1e-10)
    assert flip.residual < 1e-12


@pytest.mark.parametrize("parameter", ["racket_amplitude", "racket_period", "alpha"])
def test_period1_thresholds_in_other_parameters_equal_eqs_8_and_14(parameter):
    """The fold and the flip found by continuing in a_r, tau or alpha (their parameter
    derivatives drive the predictor and the augmented Newton) at eqs. 8 and 14's closed
    forms in that parameter (bounce bifurcation's thresholds, which it draws)."""
    closed = period1_thresholds(BASE, parameter, 1)
    existence, flip = continued_period1_thresholds(BASE, parameter, 1)
    assert existence == pytest.approx(closed.existence, rel=1e-10)
    assert flip == pytest.approx(closed.flip, rel=1e-10)


@pytest.mark.parametrize("cycles", [1, 2])
def test_m_cycle_orbit_exists_from_gamma_m_and_flips_at_eq14(cycles):
    """Eq. 8 with 2 pi m per hop: the orbit is a zero of F(x) - x - (0, 2 pi m) (residual at
    rounding), its Jacobian is eq. 9's with that orbit's theta, its fold (where it is born)
    is at Gamma_m = m pi (1-alpha)/(1+alpha) and its flip at eq. 14's AC."""
    alpha = BASE.alpha
    gamma_m = cycles * math.pi * (1 - alpha) / (1 + alpha)
    flip_m = float(threshold_gamma(alpha, float(flip_boundary_g(alpha)), cycles))
    start = 0.5 * (gamma_m + flip_m)
    params = parameter_point(BASE, "gamma", start)
    v, theta = eq8_orbit(params, cycles)
    ev = evaluate_orbit((v, theta), params, "gamma", cycles, [2 * math.pi * cycles])
    assert np.abs(ev.residual).max() < 1e-13
    a, w, g = params.racket_amplitude, params.omega, params.g
    eq9 = np.array([[alpha**2 - (1 + alpha) ** 2 * a * w**2 * math.sin(theta) / g,
                     -(1 + alpha) * a * w * math.sin(theta)],
                    [(1 + alpha) * w / g, 1.0]])
    np.testing.assert_allclose(ev.monodromy, eq9, rtol=1e-12, atol=1e-12)

    cont = Continuation(BASE, "gamma", 0.9 * gamma_m, 1.05 * flip_m,
                        ContinuationSettings(max_period=1))
    cont.run(start, v, theta, cycles, [2 * math.pi * cycles])
    kinds = {b.kind: b for b in cont.bifurcations if b.period == 1}
    assert kinds["fold"].value == pytest.approx(gamma_m, rel=1e-10)
    assert abs(kinds["fold"].theta) < 1e-6  # the branches theta = +-arccos meet at 0
    assert kinds["flip"].value == pytest.approx(flip_m, rel=1e-10)


def test_no_neimark_sacker_point_and_det_m_is_alpha_to_the_2p():
    """det M = alpha^(2p) on every periodic orbit (the impact law's area contraction, an
    independent check of the monodromy product), so the complex pair never reaches the unit
    circle: no Neimark-Sacker point is reported along the whole cascade."""
    cont = Continuation(BASE, "gamma", 1.0, 1.8, ContinuationSettings(max_period=4))
    v, theta = eq8_orbit(cont.params_at(1.3))
    cont.run(1.3, v, theta, 1, [2 * math.pi])
    assert {b.period for b in cont.branches} == {1, 2, 4}
    for branch in cont.branches:
        for pt in branch.points:
            assert np.linalg.det(pt.monodromy) == pytest.approx(
                BASE.alpha ** (2 * branch.period), rel=1e-8)
    assert not [b for b in cont.bifurcations if b.kind == "neimark_sacker"]


@pytest.fixture(scope="module")
def cascade():
    cont = Continuation(BASE, "gamma", 1.0, 1.75, ContinuationSettings(max_period=32))
    v, theta = eq8_orbit(cont.params_at(1.3))
    cont.run(1.3, v, theta, 1, [2 * math.pi])
    return cont


@pytest.mark.slow
def test_cascade_to_period_32_and_feigenbaum_ratios(cascade):
    """alpha 0.5: the flips of the orbits of period 1, 2, ..., 32 located in order, and the
    ratios of their successive distances approach Feigenbaum's 4.6692 (each closer than the
    one before; the last within 0.01). Measured: 4.7321, 4.6330, 4.6512, 4.6643."""
    flips = sorted((b for b in cascade.bifurcations if b.kind == "flip"), key=lambda b: b.period)
    assert [b.period for b in flips] == [1, 2, 4, 8, 16, 32]
    assert [b.cycles for b in flips] == [1, 2, 4, 8, 16, 32]
    values = np.array([b.value for b in flips])
    assert np.all(np.diff(values) > 0)
    deltas = feigenbaum_ratios(values)
    distance = np.abs(deltas - 4.669201609)
    assert np.all(np.diff(distance) < 0), deltas
    assert distance[-1] < 0.01, deltas
    assert values[0] == pytest.approx(float(threshold_gamma(0.5, float(flip_boundary_g(0.5)))),
                                      rel=1e-10)


@pytest.mark.slow
def test_continued_period2_orbit_is_the_attractor_the_map_iterates_to(cascade):
    """Simulated truth: between the first two flips the map, iterated from the paper's
    initial condition, settles on the period-2 orbit the continuation followed (same two
    velocities to 1e-9 m/s); the continuation's branch point nearest Gamma 1.6 corrected at
    exactly 1.6."""
    (branch,) = [b for b in cascade.branches if b.period == 2]
    near = min(branch.points, key=lambda p: abs(p.value - 1.6))
    y = np.array([near.v, near.theta, 1.6])
    out = cascade.correct(y, 2, near.hops, np.array([0.0, 0.0, 1.0]),
                          1.6 / cascade._scale[2])
    assert out is not None
    velocities = np.sort(out[1].v[:2])
    found = orbit_by_iteration(math.radians(45.0), 4.8, parameter_point(BASE, "gamma", 1.6),
                               transient=3000, max_period=8, tolerance=1e-11)
    assert (found.period, found.cycles) == (2, 2)
    iterated = np.sort([found.v, evaluate_orbit((found.v, found.theta),
                                                parameter_point(BASE, "gamma", 1.6), "gamma",
                                                2, found.hops).v[1]])
    np.testing.assert_allclose(velocities, iterated, atol=1e-9)


@pytest.mark.slow
def test_located_flip_agrees_with_the_bifurcation_sweeps_brute_force_flip():
    """The flip located on the map by iterating (bounce bifurcation's multisection on the
    detected period) within its resolution (1e-3 relative) of the continuation's, and on the
    period-1 side of it (critical slowing down biases the brute force that way)."""
    settings = SweepSettings(transient_impacts=3000, measured_impacts=64, recorded_impacts=64)
    brute = locate_period_doubling(BASE, "gamma", 1.52, 1.532, theta0=math.radians(45.0),
                                   v0=5.0, settings=settings, probes=7)
    flip = period1_flip(BASE, "gamma", 1.0, 1.6, 1.3)
    assert flip is not None
    assert brute.value == pytest.approx(flip.value, rel=1e-3)
    assert brute.period1_end < flip.value


def test_grazing_is_a_tangency_of_the_flight_with_the_racket():
    """The unstable period-1 branch (theta < 0, racket accelerating upward) stops being a
    physical orbit where its flight touches the racket: there the gap's interior minimum is
    0 (to 1e-9 m, dense sampling) with zero slope; just past it the first-impact solver finds
    an impact before the continued hop."""
    cont = Continuation(BASE, "gamma", 1.0, 2.6, ContinuationSettings(max_period=1))
    v, theta = eq8_orbit(cont.params_at(1.3))
    cont.run(1.3, v, theta, 1, [2 * math.pi])
    (graze,) = [b for b in cont.bifurcations if b.kind == "grazing"]
    assert graze.theta < 0.0
    params = cont.params_at(graze.value)
    s = np.linspace(1e-3, 2 * math.pi - 1e-3, 400_001)
    heights = gap(s, graze.theta, graze.v, params)
    assert abs(heights.min()) < 1e-9
    assert flight_minimum_gap(graze.theta, graze.v, 2 * math.pi, params) == pytest.approx(
        0.0, abs=1e-12)
    past = cont.params_at(graze.value * (1 + 1e-4))
    fixed_v, fixed_theta = v, -math.acos(past.cos_theta_fixed())
    assert next_impact_phase(fixed_theta, fixed_v, past) < 2 * math.pi - 0.1
    before = cont.params_at(graze.value * (1 - 1e-4))
    assert next_impact_phase(-math.acos(before.cos_theta_fixed()), fixed_v, before) == (
        pytest.approx(2 * math.pi, rel=1e-12))


def test_feigenbaum_ratios_of_a_geometric_sequence():
    """lambda_n = L - c q^n gives delta_n = 1/q exactly."""
    n = np.arange(6)
    np.testing.assert_allclose(feigenbaum_ratios(2.0 - 0.3 * 0.25**n), 4.0, rtol=1e-12)


def test_starts_that_do_not_exist_are_model_errors():
    with pytest.raises(ModelError, match="does not exist"):
        eq8_orbit(parameter_point(BASE, "gamma", 1.0))
    with pytest.raises(ModelError, match="no period|sticks"):
        orbit_by_iteration(math.radians(45.0), 5.0, parameter_point(BASE, "gamma", 1.75),
                           transient=100, max_period=8, tolerance=1e-9)
