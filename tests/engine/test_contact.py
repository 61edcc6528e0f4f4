"""The one contact solver (``engine.impact.first_contact``) over each kind of gap: the root it
returns is the FIRST (G > 0 strictly between, on a dense grid and at every local minimum),
on random and near-grazing flights, and as accurate as the stopping rule states
(|s - s*| <= 8 eps (sum of |G's terms| / |G'(s*)| + s), s* the root to 40 digits)."""

from __future__ import annotations

import math

import mpmath
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize_scalar

from bounce_cli.model.control import contact_after_crossing
from bounce_cli.model.impact import (
    POLISH_LIMIT,
    ROUNDING_LEVEL,
    STEP_FLOOR,
    SinusoidGap,
    first_contact,
    first_impact_phase,
)

EPS = float(np.finfo(float).eps)

AMPLITUDE = st.floats(0.01, 1.0)
OMEGA = st.floats(0.2, 2.0).map(lambda period: 2.0 * math.pi / period)
GRAVITY = st.floats(1.0, 20.0)


def assert_first_root(gap, s: float, rounding: float, n_grid: int = 4000) -> None:
    """G > 0 strictly on (0, s) up to the rounding of its evaluation: on a dense grid and at
    every interior local minimum of it, refined with a bounded minimiser."""
    grid = np.linspace(0.0, s, n_grid + 2)[1:-1]
    values = gap(grid)
    inner = (grid > 1e-6 * s) & (grid < s * (1.0 - 1e-6))
    assert np.all(values[inner] > rounding), (s, values[inner].min())
    minima = np.flatnonzero((values[1:-1] <= values[:-2]) & (values[1:-1] <= values[2:])) + 1
    for i in minima:
        found = minimize_scalar(lambda x: float(gap(np.array([x]))[0]),
                                bounds=(grid[i - 1], grid[i + 1]), method="bounded",
                                options={"xatol": 1e-14})
        if 1e-6 * s < found.x < s * (1.0 - 1e-6):
            assert found.fun > rounding, (s, found.x, found.fun)


def assert_accurate(gap_mp, slope_mp, s: float, terms: float, start_rounding=0.0) -> None:
    """The root to 40 digits (Newton from s) is within the stopping rule's accuracy of s;
    ``start_rounding``: the rounding of a start the polish may not correct (its limit)."""
    with mpmath.workdps(40):
        root = mpmath.mpf(s)
        for _ in range(10):
            root -= gap_mp(root) / slope_mp(root)
        assert abs(gap_mp(root)) < mpmath.mpf(10) ** -35 * (1 + terms)
        slope = abs(float(slope_mp(root)))
        error = abs(float(root - mpmath.mpf(s)))
    allowance = start_rounding if start_rounding > POLISH_LIMIT * s else 0.0
    assert error <= 8.0 * EPS * (terms / slope + s) + allowance, (s, error, terms, slope)


def sinusoid_gap(theta, v, a, w, g, height=0.0):
    """G(s) = h + v s / w - g s^2 / (2 w^2) + a sin(theta) - a sin(theta + s), in floats (the
    product form of the difference of sines) and in mpmath; and the sum of |its terms|."""
    def floats(s):
        return (height + v * s / w - g * s * s / (2.0 * w * w)
                - 2.0 * a * np.cos(theta + s / 2.0) * np.sin(s / 2.0))

    A, W, G, V, T, H = (mpmath.mpf(x) for x in (a, w, g, v, theta, height))

    def exact(s):
        return H + V * s / W - G * s * s / (2 * W * W) + A * mpmath.sin(T) - A * mpmath.sin(T + s)

    def exact_slope(s):
        return V / W - G * s / (W * W) - A * mpmath.cos(T + s)

    def terms(s):
        return (abs(height) + abs(v * s / w) + g * s * s / (2.0 * w * w)
                + abs(2.0 * a * math.cos(theta + s / 2.0) * math.sin(s / 2.0)))

    return floats, exact, exact_slope, terms


def taylor_start_rounding(theta, v, a, w, g) -> float:
    """The rounding of the map's first step (c/2 + sqrt(c^2/4 + 2 a d/3)) / (a/3): where
    c < 0 and d is tiny the sum cancels, to an absolute error of about eps |c| / (a/3)."""
    d, c = v / w - a * math.cos(theta), -g / w**2 + a * math.sin(theta)
    return 4.0 * EPS * (abs(c) / 2.0 + math.sqrt(c * c / 4.0 + 2.0 * a * max(d, 0.0) / 3.0)) / (
        a / 3.0)


def check_sinusoid_root(s, theta, v, a, w, g, height=0.0, start_rounding=0.0):
    floats, exact, exact_slope, terms = sinusoid_gap(theta, v, a, w, g, height)
    assert math.isfinite(s) and s >= 0.0
    scale = terms(s) + 2.0 * a
    assert_first_root(floats, s, -4.0 * ROUNDING_LEVEL * scale)
    assert_accurate(exact, exact_slope, s, terms(s), start_rounding)


# -- the passive map's gap (eq. 6), from an impact -------------------------------------------
def test_the_maps_start_rounding_is_the_one_allowance():
    """The case hypothesis found: a = 0.01 m, theta = 0, 1e-8 m/s faster than the racket. The
    first step (cancelling) lands 1.2e-6 s beyond the root, just over the polish's limit."""
    a, w, g, theta = 0.01, 3.655671451449941, 12.0, 0.0
    v = a * w + 1e-8
    s = float(first_impact_phase(theta, v, a, w, g))
    check_sinusoid_root(s, theta, v, a, w, g,
                        start_rounding=taylor_start_rounding(theta, v, a, w, g))


@settings(max_examples=250, deadline=None)
@given(a=AMPLITUDE, w=OMEGA, g=GRAVITY, theta=st.floats(0.0, 2.0 * math.pi),
       log_excess=st.floats(-12.0, 1.2))
def test_passive_gap_first_root_random_and_near_grazing(a, w, g, theta, log_excess):
    """From barely faster than the racket (hops of 1e-12 rad: near sticking) to fast balls
    whose gap comes near 0 and rises again before the landing. The map's first step keeps
    its rounding where that exceeds the polish's limit, 1e-6 s (hops below ~1e-7 rad, deep
    in sticking; the map's bits are the reference and stay as they are)."""
    v = a * w * math.cos(theta) + 10.0**log_excess
    s = float(first_impact_phase(theta, v, a, w, g))
    assert s > 0.0
    check_sinusoid_root(s, theta, v, a, w, g,
                        start_rounding=taylor_start_rounding(theta, v, a, w, g))


# -- the controlled map's racket, switching its period at its mid-position crossing ----------
@settings(max_examples=250, deadline=None)
@given(a=AMPLITUDE, w=OMEGA, g=GRAVITY, v=st.floats(-6.0, 6.0),
       log_height=st.floats(-13.0, 0.3))
def test_crossing_gap_first_root_random_and_near_grazing(a, w, g, v, log_height):
    """A ball 1e-13 m to 2 m above the racket at its crossing, rising or falling: contacts
    after a tiny phase at a large slope (where the safe step's rounding is far above eps s)
    and after flights over the racket's peak."""
    height = 10.0**log_height
    s = float(contact_after_crossing(height, v, a, w, g))
    check_sinusoid_root(s, 0.0, v, a, w, g, height)


@settings(max_examples=250, deadline=None)
@given(a=AMPLITUDE, w=OMEGA, g=GRAVITY, log_relative=st.floats(-8.0, 0.0),
       falling=st.booleans(), log_height=st.floats(-13.0, -2.0))
def test_crossing_gap_first_root_near_the_racket_velocity(a, w, g, log_relative, falling,
                                                           log_height):
    """Just above the racket and nearly at its velocity a w at the crossing: the contact is
    ill-conditioned (|G'| small) and the stopping rule's accuracy is the tightest."""
    height = 10.0**log_height
    v = a * w + (-1.0 if falling else 1.0) * 10.0**log_relative
    s = float(contact_after_crossing(height, v, a, w, g))
    check_sinusoid_root(s, 0.0, v, a, w, g, height)


def test_crossing_contact_at_the_crossing_and_no_flight():
    """A ball on the racket at the crossing, falling onto it, meets it there (s = 0); NaN
    heights (no flight after the crossing) and heights below the racket give NaN."""
    got = contact_after_crossing(np.array([0.0, np.nan, -1e-3, 0.2]), -0.5, 0.3, 6.8, 9.81)
    assert got[0] == 0.0 and np.isnan(got[1]) and np.isnan(got[2]) and got[3] > 0.0


def test_one_solver_serves_every_batch_shape():
    """The crossing's contacts are the SinusoidGap at theta = 0 solved from s = 0; a state's
    result does not depend on the batch it shares (compaction keeps each state's bits)."""
    rng = np.random.default_rng(4)
    n = 2000
    height, v = 10.0 ** rng.uniform(-12, 0, n), rng.uniform(-5, 5, n)
    w = 2 * np.pi / rng.uniform(0.5, 1.5, n)
    together = contact_after_crossing(height, v, 0.3, w, 9.81)
    alone = [float(contact_after_crossing(height[i], v[i], 0.3, w[i], 9.81))
             for i in range(0, n, 41)]
    np.testing.assert_array_equal(together[::41], alone)
    ones = np.ones(n)
    gap = SinusoidGap(ones, np.zeros(n), v, v / w - 0.3 * ones, 0.3 * ones, w, 9.81 * ones,
                      height=height)
    np.testing.assert_array_equal(first_contact(gap, np.zeros(n)), together)


def test_the_stopping_rule_is_the_one_stated():
    """The constants of the rule: G at 8 eps of its terms, steps below 4 eps s."""
    assert ROUNDING_LEVEL == 8.0 * EPS and STEP_FLOOR == 4.0 * EPS
