"""Exact sticking (engine.chatter): complete chatters summed to their accumulation point,
riding, release at sin(theta) = 1/Gamma, and the locked orbits this gives, checked against an
independent 40-digit iteration of the map (eqs. 5, 6) written here with mpmath."""

import math

import mpmath as mp
import numpy as np
import pytest

from bounce_cli.model.chatter import (
    RELEASE,
    STICK,
    chatter_tail,
    effective_gravity,
    iterate_exact_orbit,
    locked_period,
    release_fate,
    release_phase,
)
from bounce_cli.analysis.classify import OUTCOMES, ClassifySettings, classify_batch, outcome_names
from bounce_cli.model.impact import first_impact_phase
from bounce_cli.model.params import ModelParams

DIGITS = 40


# -- the reference: the map iterated with 40 digits, roots by scanning G(s)/s -----------------
def _gap_over_s(s, th, v, a, w, g):
    """G(s)/s (eq. 6 divided by s, so that the root s = 0 is gone)."""
    if s == 0:
        return v / w - a * mp.cos(th)
    return v / w - g * s / (2 * w * w) - a * (mp.sin(th + s) - mp.sin(th)) / s


def _reference_hop(th, v, a, w, g):
    """First root of G(s)/s: a scan for its first sign change (on the scale of the hop
    2 u / g_eff when that is short), refined by Illinois in the bracket."""
    u = v - a * w * mp.cos(th)
    g_eff = g - a * w * w * mp.sin(th)
    guess = 2 * u * w / g_eff if g_eff > 0 else mp.mpf(1)
    if g_eff > 0 and guess < 0.05:
        grid = [guess * k / 200 for k in range(1, 801)]
    else:
        grid = [mp.mpf(k) * mp.mpf("0.004") for k in range(1, 20001)]
    prev = _gap_over_s(grid[0], th, v, a, w, g)
    for lo, hi in zip(grid[:-1], grid[1:]):
        val = _gap_over_s(hi, th, v, a, w, g)
        if val <= 0 < prev:
            return mp.findroot(lambda s: _gap_over_s(s, th, v, a, w, g), (lo, hi),
                               solver="illinois", verify=False)
        prev = val
    raise AssertionError("no root in the scan")


def reference_accumulation(theta, v, params: ModelParams, u_stop="1e-24", max_impacts=500):
    """Phase of the first accumulation point from a ball leaving the racket at (theta, v):
    every impact iterated (40 digits) until the relative velocity after one is below
    ``u_stop`` m/s (the rest of the chatter then lasts < 1e-23 s)."""
    with mp.workdps(DIGITS):
        th, vv = mp.mpf(theta), mp.mpf(v)
        a, w, g = (mp.mpf(params.racket_amplitude), 2 * mp.pi / mp.mpf(params.racket_period),
                   mp.mpf(params.g))
        alpha = mp.mpf(params.alpha)
        for _ in range(max_impacts):
            s = _reference_hop(th, vv, a, w, g)
            th = th + s
            vv = (1 + alpha) * a * w * mp.cos(th) - alpha * vv + g * alpha / w * s
            if vv - a * w * mp.cos(th) < mp.mpf(u_stop):
                return th, w
        raise AssertionError("no accumulation")


# -- tests ------------------------------------------------------------------------------------
@pytest.mark.slow
def test_fig3_accumulation_time_agrees_with_a_40_digit_iteration_to_1e_9_s(paper_params):
    """Fig. 3's sticking solution (theta0 = 43.1 deg, v0 = 5.7 m/s): the first accumulation
    point, and the one after the first release (whose flight starts with G = G' = G'' = 0)."""
    p = paper_params
    theta0 = math.radians(43.1)
    orbit = iterate_exact_orbit(theta0, 5.7, p, 60)
    sticks, releases = orbit.rows(STICK), orbit.rows(RELEASE)
    ref_theta, w = reference_accumulation(theta0, 5.7, p)
    assert abs(orbit.theta[sticks[0]] / p.omega - float(ref_theta / w)) < 1e-9
    assert orbit.tail_error_s[sticks[0]] < 1e-12
    # from the release: its phase is asin(1/Gamma), its velocity the racket's
    th_r = orbit.theta[releases[0]]
    with mp.workdps(DIGITS):
        a, g = mp.mpf(p.racket_amplitude), mp.mpf(p.g)
        w_mp = 2 * mp.pi / mp.mpf(p.racket_period)
        exact_release = mp.asin(g / (a * w_mp**2)) + 2 * mp.pi * 3  # the racket's 4th cycle
        assert abs(th_r - float(exact_release)) < 1e-12
        ref2, _ = reference_accumulation(exact_release, a * w_mp * mp.cos(exact_release), p)
    assert abs(orbit.theta[sticks[1]] / p.omega - float(ref2 / w)) < 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("alpha", [0.1, 0.5, 0.85])
@pytest.mark.parametrize("theta_deg", [-60.0, 20.0, 170.0])
def test_tail_closed_form_is_within_its_bound_and_needs_the_drift_of_g_eff(alpha, theta_deg):
    """The tail from u = 1e-3 m/s: the closed form is within its stated bound of the
    40-digit sum; the leading term 2u / (g_eff (1 - alpha)) alone (g_eff held fixed) is not."""
    p = ModelParams(alpha, 9.81, 0.30, 0.92)
    theta, u = math.radians(theta_deg), 1e-3
    v = u + float(p.racket_velocity(theta))
    ref_theta, w = reference_accumulation(theta, v, p)
    ref_s = float((ref_theta - mp.mpf(theta)) / w)
    tail_phase, bound = (float(x) for x in chatter_tail(theta, u, p))
    assert abs(tail_phase / p.omega - ref_s) <= bound
    leading = 2 * u / (float(effective_gravity(theta, p)) * (1 - alpha))
    assert abs(leading - ref_s) > 10 * bound


def test_a_release_flight_starts_with_zero_slope_and_curvature(paper_params):
    """At sin(theta) = 1/Gamma with the racket's velocity, G = G' = G'' = 0: the ordinary
    third-order start has no positive step (NaN or no flight); ``released`` finds the first
    root, equal to the 40-digit one; ``released`` False everywhere changes no bit."""
    p = paper_params
    th = release_phase(0.0, p)
    v = float(p.racket_velocity(th))
    a, w, g = p.racket_amplitude, p.omega, p.g
    hop = float(first_impact_phase(th, v, a, w, g, released=True))
    with mp.workdps(DIGITS):
        am, gm = mp.mpf(a), mp.mpf(g)
        wm = 2 * mp.pi / mp.mpf(p.racket_period)
        th_m = mp.asin(gm / (am * wm**2))
        ref = _reference_hop(th_m, am * wm * mp.cos(th_m), am, wm, gm)
    assert hop == pytest.approx(float(ref), rel=1e-12)
    plain = float(first_impact_phase(th, v, a, w, g))
    assert not plain == pytest.approx(hop, rel=1e-6)  # NaN or a wrong root without the flag
    rng = np.random.default_rng(4)
    thetas, vs = rng.uniform(0, 2 * np.pi, 500), rng.uniform(0, 8, 500)
    np.testing.assert_array_equal(
        first_impact_phase(thetas, vs, a, w, g),
        first_impact_phase(thetas, vs, a, w, g, released=np.zeros(500, dtype=bool)))


def test_fig3_sticking_solution_is_locked_with_period_one_racket_cycle(paper_params):
    """Every stick is followed by a release at asin(1/Gamma) (mod 2 pi), releases one racket
    cycle apart, the same state each time; the shared fate of all sticking orbits says so."""
    p = paper_params
    orbit = iterate_exact_orbit(math.radians(43.1), 5.7, p, 200)
    releases = orbit.rows(RELEASE)
    assert releases.size >= 10
    gamma = p.racket_amplitude * p.omega**2 / p.g
    assert np.allclose(np.mod(orbit.theta[releases], 2 * np.pi), math.asin(1 / gamma),
                       atol=1e-12)
    assert np.allclose(np.diff(orbit.theta[releases]), 2 * np.pi, atol=1e-9)
    sticks = orbit.rows(STICK)
    assert np.ptp(np.mod(orbit.theta[sticks[1:]], 2 * np.pi)) < 1e-9  # locked: the same stick
    assert np.allclose(orbit.v[releases], p.racket_velocity(orbit.theta[releases]))
    assert locked_period(orbit) == 1
    fate = release_fate(p, 100, 1e-3, p.fixed_point())
    assert (fate.kind, fate.cycles) == ("locked", 1)
    assert fate.impacts == np.count_nonzero(
        np.asarray(orbit.event[releases[1]:releases[2]]) == "impact")


def test_gamma_below_one_rests_on_the_racket():
    """Gamma = 0.9: the racket never accelerates downward as fast as g; after the chatter the
    ball rests (no release)."""
    p = ModelParams(0.5, 9.81, 0.9 * 9.81 / (2 * math.pi / 0.92) ** 2, 0.92)
    orbit = iterate_exact_orbit(0.0, 2.0, p, 200)
    assert orbit.stop_reason == "resting"
    assert orbit.event[-2:] == ("stick", "resting")
    assert math.isinf(release_phase(1.0, p))
    assert release_fate(p, 100, 1e-3).kind == "resting"


def test_alpha_zero_sticks_at_every_impact(paper_params):
    """alpha = 0: the ball leaves every impact with the racket's velocity, a chatter of one
    impact whose tail is empty."""
    p = paper_params.with_alpha(0.0)
    orbit = iterate_exact_orbit(math.radians(43.1), 4.8, p, 10)
    sticks = orbit.rows(STICK)
    assert sticks.size >= 3
    np.testing.assert_array_equal(orbit.flight[sticks], 0.0)
    assert (orbit.chatter_impacts[sticks] == 1).all()


def test_exact_basin_locks_where_the_1ms_rule_sticks_on_fig4(paper_params):
    """Fig. 4's basin with min_hop_s 0: every point the 1 ms rule calls sticking is locked on
    the period-1-cycle sticking solution, every other outcome is the same point for point; the
    compiled kernel falls back to this numpy code (same result)."""
    theta, v = np.meshgrid(np.radians(np.linspace(0, 360, 41)), np.linspace(0, 10, 41))
    exact = classify_batch(theta, v, paper_params, ClassifySettings(min_hop_s=0.0),
                           kernel="numpy")
    cut = classify_batch(theta, v, paper_params, ClassifySettings(), kernel="numpy")
    assert exact.locked_cycles == 1
    names, cut_names = exact.names(), cut.names()
    assert (names == "locked").sum() > 500
    np.testing.assert_array_equal(names == "locked", cut_names == "sticking")
    np.testing.assert_array_equal(names[names != "locked"], cut_names[names != "locked"])
    compiled = classify_batch(theta, v, paper_params, ClassifySettings(min_hop_s=0.0),
                              kernel="compiled")
    np.testing.assert_array_equal(compiled.outcome, exact.outcome)
    assert outcome_names(ClassifySettings(min_hop_s=0.0))[-2:] == ("locked", "resting")
    assert outcome_names(ClassifySettings()) == OUTCOMES


def test_exact_basin_rests_below_gamma_one():
    """Gamma = 0.9 (no period-1 orbit either): every ball that can leave ends resting."""
    p = ModelParams(0.5, 9.81, 0.9 * 9.81 / (2 * math.pi / 0.92) ** 2, 0.92)
    theta, v = np.radians([10.0, 100.0, 200.0]), np.array([2.0, 2.5, 3.0])
    result = classify_batch(theta, v, p, ClassifySettings(min_hop_s=0.0),
                            require_fixed_point=False)
    assert list(result.names()) == ["resting"] * 3
