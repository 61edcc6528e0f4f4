"""The first-impact solver (the next impact is the FIRST root of eq. 6)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq, minimize_scalar

from bounce_cli.model.impact import gap, gap_slope, next_impact_phase
from bounce_cli.model.params import ModelParams

PARAMS = st.builds(
    ModelParams,
    alpha=st.floats(0.0, 0.95),
    g=st.floats(1.0, 20.0),
    racket_amplitude=st.floats(0.01, 1.0),
    racket_period=st.floats(0.2, 2.0),
)


def assert_first_root(theta, v, s, params, n_grid=4000):
    """G(s) = 0, and G > 0 strictly on (0, s): on a dense grid and at every local minimum."""
    scale = (abs(v) * s / params.omega + params.g * s * s / params.omega**2
             + 2 * params.racket_amplitude)
    assert abs(gap(s, theta, v, params)) <= 1e-11 * scale
    assert gap_slope(s, theta, v, params) <= 1e-9 * scale  # the ball comes down onto the racket
    grid = np.linspace(0, s, n_grid + 2)[1:-1]
    g_vals = gap(grid, theta, v, params)
    # ignore the roundoff zone right next to the two roots
    near_ends = (grid < 1e-6 * s) | (grid > s * (1 - 1e-6))
    assert np.all(g_vals[~near_ends] > -1e-12 * scale)
    # refine every interior local minimum of the grid with a bounded minimiser
    mins = np.flatnonzero((g_vals[1:-1] <= g_vals[:-2]) & (g_vals[1:-1] <= g_vals[2:])) + 1
    for i in mins:
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        res = minimize_scalar(lambda x: gap(x, theta, v, params), bounds=(lo, hi),
                              method="bounded", options={"xatol": 1e-14})
        if 1e-6 * s < res.x < s * (1 - 1e-6):
            assert res.fun > -1e-12 * scale, (theta, v, s, res.x, res.fun)


@settings(max_examples=300, deadline=None)
@given(params=PARAMS, theta=st.floats(0, 2 * math.pi), excess=st.floats(1e-6, 15.0))
def test_first_root_random_states(params, theta, excess):
    v = float(params.racket_velocity(theta)) + excess
    s = float(next_impact_phase(theta, v, params))
    assert s > 0
    assert_first_root(theta, v, s, params)


@settings(max_examples=200, deadline=None)
@given(params=PARAMS, theta=st.floats(0, 2 * math.pi), log_excess=st.floats(-9, -3))
def test_first_root_very_short_hops(params, theta, log_excess):
    """Barely faster than the racket: hops can be tiny, and the first root must not be
    skipped in favour of the long flight after a near-touch."""
    v = float(params.racket_velocity(theta)) + 10.0**log_excess
    s = float(next_impact_phase(theta, v, params))
    assert s > 0
    assert_first_root(theta, v, s, params, n_grid=2000)


def test_thousands_of_states_vectorised():
    rng = np.random.default_rng(7)
    p = ModelParams(0.5, 9.81, 0.30, 0.92)
    n = 5000
    theta = rng.uniform(0, 2 * np.pi, n)
    v = p.racket_velocity(theta) + 10 ** rng.uniform(-8, 1.2, n)
    s = next_impact_phase(theta, v, p)
    assert np.all(np.isfinite(s)) and np.all(s > 0)
    # vectorised G on a (n, grid) mesh strictly inside (0, s)
    frac = np.linspace(0, 1, 1202)[1:-1]
    mesh = s[:, None] * frac[None, :]
    g_vals = gap(mesh, theta[:, None], v[:, None], p)
    inner = (frac > 1e-6) & (frac < 1 - 1e-6)
    assert np.all(g_vals[:, inner] > -1e-12)
    assert np.max(np.abs(gap(s, theta, v, p))) < 1e-12


@pytest.mark.slow
def test_takes_the_first_of_several_roots(paper_params):
    """Short hops at the paper's parameters where G crosses zero, comes back positive (the
    racket drops away) and crosses again: a bracket such as [0, 2 pi] handed to a root finder
    may return the later landing. The solver must return the first crossing."""
    p = paper_params
    rng = np.random.default_rng(0)
    grid = np.linspace(1e-9, 6 * np.pi, 30001)
    multi = 0
    for _ in range(3000):
        theta = rng.uniform(0, 2 * np.pi)
        v = float(p.racket_velocity(theta)) + 10 ** rng.uniform(-3, 1)
        g_vals = gap(grid, theta, v, p)
        crossings = np.flatnonzero(np.sign(g_vals[:-1]) != np.sign(g_vals[1:]))
        if len(crossings) < 3:
            continue
        multi += 1
        first = brentq(gap, grid[crossings[0]], grid[crossings[0] + 1], args=(theta, v, p),
                       xtol=1e-15)
        later = brentq(gap, grid[crossings[2]], grid[crossings[2] + 1], args=(theta, v, p))
        s = float(next_impact_phase(theta, v, p))
        assert s == pytest.approx(first, rel=1e-9, abs=1e-13)
        assert later > 10 * s or later - s > 0.1  # a genuinely different, later root
    assert multi > 50, "too few multi-root states: the test lost its teeth"


def test_no_flight_below_racket_is_nan(paper_params):
    theta = 1.0
    v_r = float(paper_params.racket_velocity(theta))
    assert np.isnan(next_impact_phase(theta, v_r - 0.1, paper_params))


def test_launch_at_racket_velocity_when_racket_falls_faster_than_gravity(paper_params):
    """The sticking ball leaves where the racket decelerates faster than g (G'(0)=0, G''>0)."""
    p = paper_params
    theta = math.pi / 2  # racket acceleration -a w^2 = -1.43 g
    v = float(p.racket_velocity(theta))
    s = float(next_impact_phase(theta, v, p))
    assert s > 0
    assert_first_root(theta, v, s, p)


def test_fixed_point_hop_is_one_cycle(paper_params):
    fp = paper_params.fixed_point()
    s = next_impact_phase(fp.theta_rad, fp.v_m_s, paper_params)
    assert float(s) == pytest.approx(2 * math.pi, rel=1e-13)


def test_result_independent_of_unwrapping(paper_params):
    theta = np.array([0.3, 2.0, 5.0])
    v = paper_params.racket_velocity(theta) + 2.0
    s0 = next_impact_phase(theta, v, paper_params)
    s1 = next_impact_phase(theta + 2 * np.pi * 37, v, paper_params)
    np.testing.assert_allclose(s0, s1, rtol=1e-11)


def test_array_parameters_give_each_state_its_own_racket():
    """first_impact_phase with arrays of (a, w, g) equals a scalar call per state, and a
    scalar given as an array of one value takes the same arithmetic (same bits)."""
    from bounce_cli.model.impact import first_impact_phase

    rng = np.random.default_rng(3)
    n = 200
    a = rng.uniform(0.05, 0.4, n)
    w = 2 * np.pi / rng.uniform(0.4, 1.2, n)
    g = rng.uniform(3.0, 12.0, n)
    theta = rng.uniform(0, 2 * np.pi, n)
    v = a * w * np.cos(theta) + rng.uniform(0.01, 6.0, n)
    together = first_impact_phase(theta, v, a, w, g)
    alone = np.array([first_impact_phase(theta[i], v[i], a[i], w[i], g[i]) for i in range(n)])
    np.testing.assert_array_equal(together, alone)
    assert np.all(np.isfinite(together))
    same = first_impact_phase(theta, v, np.full(n, 0.3), np.full(n, w[0]), 9.81)
    np.testing.assert_array_equal(same, first_impact_phase(theta, v, 0.3, w[0], 9.81))


def test_each_state_is_solved_alone_to_the_last_bit(paper_params):
    """The solver carries finished states along until an eighth of a batch has finished, and
    takes cos/sin of the phase from a caller that has them: neither may change a bit of any
    state's result, whatever batch it shares (the basin's results depend on it)."""
    from bounce_cli.model.impact import first_impact_phase
    from bounce_cli.model.trig import sincos

    rng = np.random.default_rng(11)
    n = 3000
    theta = rng.uniform(0.0, 2 * np.pi, n)
    v_racket = paper_params.racket_velocity(theta)
    # long flights, short hops near sticking, grazing launches: steps to converge differ
    v = v_racket + np.concatenate([rng.uniform(0, 8, n // 3), 10.0 ** rng.uniform(-9, -3, n // 3),
                                   10.0 ** rng.uniform(-15, -9, n - 2 * (n // 3))])
    a, w, g = paper_params.racket_amplitude, paper_params.omega, paper_params.g
    batch = first_impact_phase(theta, v, a, w, g)
    given = first_impact_phase(theta, v, a, w, g, cos_theta=np.cos(theta),
                               sin_theta=np.sin(theta))
    alone = np.array([first_impact_phase(t, x, a, w, g) for t, x in zip(theta[::37], v[::37])])
    np.testing.assert_array_equal(given, batch)
    np.testing.assert_array_equal(alone, batch[::37])
    # the basin classifier's sine and cosine (trig.sincos), given or not, batch or alone
    exact = first_impact_phase(theta, v, a, w, g, trig=sincos)
    sin_theta, cos_theta = sincos(theta)
    np.testing.assert_array_equal(
        first_impact_phase(theta, v, a, w, g, trig=sincos, cos_theta=cos_theta,
                           sin_theta=sin_theta), exact)
    np.testing.assert_array_equal(
        [first_impact_phase(t, x, a, w, g, trig=sincos) for t, x in zip(theta[::37], v[::37])],
        exact[::37])
    # the two sines differ in the last bit; hops near sticking keep their start's rounding
    np.testing.assert_allclose(exact, batch, rtol=1e-12, atol=1e-13)
    assert np.isfinite(batch).all()
    # one state per parameter point (arrays of a), carried and compacted alike
    amplitudes = rng.uniform(0.1, 0.4, n)
    swept = first_impact_phase(theta, v, amplitudes, w, g)
    np.testing.assert_array_equal(
        swept[::53], [first_impact_phase(t, x, am, w, g)
                      for t, x, am in zip(theta[::53], v[::53], amplitudes[::53])])
