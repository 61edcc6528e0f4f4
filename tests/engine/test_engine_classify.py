"""The basin classifier (section 3): point-by-point against an independent scalar brentq
reference, the paper's statements about Figs. 3 and 4, and independence of the tiling."""

import math

import numpy as np
import pytest

from bounce_cli.analysis.classify import (
    BELOW_RACKET,
    OUTCOMES,
    PERIOD1,
    STICKING,
    UNDECIDED,
    classify_batch,
    classify_grid,
    ClassifySettings,
)
from bounce_cli.model.maps import iterate_orbit, map_step
from bounce_cli.model.reference import classify_point_brentq, first_impact_brentq

FIG3_THETA0 = math.asin(0.205 / 0.30)  # section 3: x_b(0) = 0.205 m, ball on the racket


def paper_grid(n_theta=400, n_v=400):
    th = np.deg2rad(np.linspace(0, 360, n_theta))
    v = np.linspace(0, 10, n_v)
    return np.meshgrid(th, v)


@pytest.mark.slow
def test_matches_scalar_brentq_reference_point_by_point(paper_params):
    """Random points of the paper's 400 x 400 grid: same outcome AND same impact count."""
    rng = np.random.default_rng(2024)
    th = np.deg2rad(np.linspace(0, 360, 400))[rng.integers(0, 400, 300)]
    v = np.linspace(0, 10, 400)[rng.integers(0, 400, 300)]
    fast = classify_batch(th, v, paper_params)
    names = fast.names()
    ref = [classify_point_brentq(a, b, paper_params) for a, b in zip(th, v)]
    mismatches = [
        (math.degrees(a), b, r, (names[i], int(fast.iterations[i])))
        for i, (a, b, r) in enumerate(zip(th, v, ref))
        if r != (names[i], int(fast.iterations[i]))
    ]
    assert mismatches == []
    # the sample covers every reachable outcome
    assert {r[0] for r in ref} == {"period1", "sticking", "below_racket"}


def test_reference_first_root_agrees_with_map_step(paper_params):
    rng = np.random.default_rng(5)
    theta = rng.uniform(0, 2 * np.pi, 40)
    v = paper_params.racket_velocity(theta) + rng.uniform(0.01, 8, 40)
    hops = map_step(theta, v, paper_params).hop_phase
    ref = [first_impact_brentq(a, b, paper_params) for a, b in zip(theta, v)]
    np.testing.assert_allclose(hops, ref, rtol=1e-12, atol=1e-14)


def test_fig3_initial_conditions(paper_params):
    """Fig. 3 / Fig. 4 crosses: v0 = 4.8 m/s ends at the period-1 attractor, 5.7 m/s sticks."""
    res = classify_batch([FIG3_THETA0, FIG3_THETA0], [4.8, 5.7], paper_params)
    assert list(res.names()) == ["period1", "sticking"]
    # the impact count is where iterate_orbit (an independent loop) stops sticking
    orbit = iterate_orbit(FIG3_THETA0, 5.7, paper_params, 100, 1e-3)
    assert orbit.stop_reason == "sticking" and res.iterations[1] == len(orbit.theta) - 1


def test_fixed_point_itself_is_period1_after_one_impact(paper_params):
    fp = paper_params.fixed_point()
    res = classify_batch(fp.theta_rad, fp.v_m_s, paper_params)
    assert res.outcome == PERIOD1 and res.iterations == 1  # the initial state is not checked
    # also from the unwrapped phase theta~ + 2 pi (phases are compared wrapped)
    res = classify_batch(fp.theta_rad + 2 * np.pi, fp.v_m_s, paper_params)
    assert res.outcome == PERIOD1 and res.iterations == 1
    # just outside the tolerance in velocity: not settled at impact 0 by construction, the
    # contraction (spectral radius 0.5) brings it in within a few impacts
    res = classify_batch(fp.theta_rad, fp.v_m_s + 0.01, paper_params)
    assert res.outcome == PERIOD1 and 1 < res.iterations < 20


def test_below_racket_is_exactly_v0_not_above_racket_velocity(paper_params):
    theta, v = paper_grid(90, 60)
    res = classify_batch(theta, v, paper_params)
    v_racket = paper_params.racket_velocity(theta)
    np.testing.assert_array_equal(res.outcome == BELOW_RACKET, v <= v_racket)
    assert np.all(res.iterations[res.outcome == BELOW_RACKET] == 0)
    assert np.all(res.iterations[res.outcome != BELOW_RACKET] >= 1)


def test_low_velocity_band_sticks(paper_params):
    """Section 3: above the black region a region of sticking initial conditions (the initial
    velocity is too low), with the band of period-1 conditions higher up."""
    theta = np.deg2rad(np.linspace(0, 360, 73))
    v_racket = paper_params.racket_velocity(theta)
    just_above = np.maximum(v_racket, 0.0) + 0.05
    res = classify_batch(theta, just_above, paper_params)
    assert np.all(res.outcome == STICKING)
    # and the period-1 band around the fixed point at its phase
    fp = paper_params.fixed_point()
    v = np.linspace(3.9, 5.2, 14)
    assert np.all(classify_batch(fp.theta_rad, v, paper_params).outcome == PERIOD1)


def test_paper_grid_has_no_undecided_point(paper_params):
    """Section 3: "The simulation never ran to the maximum of 100 iterations"."""
    theta, v = paper_grid()
    res = classify_batch(theta, v, paper_params)
    assert not np.any(res.outcome == UNDECIDED)
    assert res.iterations.max() < 100
    counts = np.bincount(res.outcome.ravel(), minlength=4)
    assert counts[PERIOD1] > 0 and counts[STICKING] > 0 and counts[BELOW_RACKET] > 0


def test_undecided_after_max_iterations_and_consistent_truncation(paper_params):
    theta, v = paper_grid(50, 50)
    full = classify_batch(theta, v, paper_params)
    short = classify_batch(theta, v, paper_params, ClassifySettings(max_iterations=5))
    early = full.iterations <= 5
    np.testing.assert_array_equal(short.outcome[early], full.outcome[early])
    np.testing.assert_array_equal(short.iterations[early], full.iterations[early])
    assert np.all(short.outcome[~early] == UNDECIDED)
    assert np.all(short.iterations[~early] == 5)
    assert np.any(~early)


def test_tolerance_and_sticking_interval_are_used(paper_params):
    theta, v = paper_grid(30, 30)
    base = classify_batch(theta, v, paper_params)
    loose = classify_batch(theta, v, paper_params, ClassifySettings(tolerance=1e-1))
    fly = base.outcome == PERIOD1
    assert np.all(loose.iterations[fly] <= base.iterations[fly])
    assert np.any(loose.iterations[fly] < base.iterations[fly])
    never_stick = classify_batch(theta, v, paper_params,
                           ClassifySettings(max_iterations=30, min_hop_s=0.0))
    assert not np.any(never_stick.outcome[base.outcome == STICKING] == STICKING)


@pytest.mark.slow
@pytest.mark.parametrize("jobs, tile_points", [(1, 7), (1, 333), (2, 250), (2, 10_000)])
def test_grid_results_independent_of_tiles_and_jobs(paper_params, jobs, tile_points):
    from bounce_cli.runtime import parallel

    theta, v = paper_grid(40, 25)
    direct = classify_batch(theta, v, paper_params)
    done = []
    with parallel.executor(jobs) as executor:
        tiled = classify_grid(theta, v, paper_params, map=executor.map,
                              workers=executor.workers, tile_points=tile_points,
                              on_tile_done=done.append)
    np.testing.assert_array_equal(tiled.outcome, direct.outcome)
    np.testing.assert_array_equal(tiled.iterations, direct.iterations)
    assert sum(done) == theta.size and max(done) <= tile_points


def test_outcome_codes_name_what_happened(paper_params):
    """Each code and its name on a point whose fate is known independently: the fixed point,
    Fig. 3's sticking start, a ball slower than the racket, and one impact from far away."""
    fp = paper_params.fixed_point()
    theta = np.array([fp.theta_rad, FIG3_THETA0, 0.0, FIG3_THETA0])
    v = np.array([fp.v_m_s, 5.7, 0.5 * float(paper_params.racket_velocity(0.0)), 9.0])
    first = classify_batch(theta[:3], v[:3], paper_params)
    last = classify_batch(theta[3:], v[3:], paper_params, ClassifySettings(max_iterations=1))
    codes = np.concatenate([first.outcome, last.outcome])
    assert codes.tolist() == [PERIOD1, STICKING, BELOW_RACKET, UNDECIDED]
    assert [*first.names(), *last.names()] == [OUTCOMES[c] for c in codes]
    assert [*first.names(), *last.names()] == ["period1", "sticking", "below_racket",
                                               "undecided"]
