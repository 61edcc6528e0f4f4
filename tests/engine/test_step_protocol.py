"""The one step protocol (``model.maps.ImpactMap``): the passive map, the controlled map and
the cycle-switching racket run through the same orbit, batch and classification code, so
the controlled basin gets the worker pool (and every executor) with identical results, and
gain 0 is the passive map bit for bit on orbits and grids."""

import numpy as np
import pytest

from bounce_cli.runtime import parallel
from bounce_cli.analysis.classify import ClassifySettings, classify_batch, classify_grid
from bounce_cli.model.control import ControlledMap, PeriodController, iterate_controlled_orbit
from bounce_cli.analysis.control_design import classify_controlled
from bounce_cli.model.maps import PassiveMap, iterate_map_orbit, iterate_orbit


def grid(n=60):
    theta, v = np.meshgrid(np.linspace(0, 2 * np.pi, n), np.linspace(0, 10, n))
    return theta.ravel(), v.ravel()


def assert_same_classification(a, b):
    assert np.array_equal(a.outcome, b.outcome)
    assert np.array_equal(a.iterations, b.iterations)


@pytest.mark.slow
@pytest.mark.parametrize("rate", [0.0, 0.5, 1.0])
def test_zero_gain_orbits_are_the_passive_ones_bit_for_bit(paper_params, rate):
    rng = np.random.default_rng(11)
    reasons = set()
    for theta0, v0 in zip(rng.uniform(0, 2 * np.pi, 40), rng.uniform(0, 10, 40)):
        passive = iterate_orbit(theta0, v0, paper_params, 60, 1e-3)
        controlled = iterate_controlled_orbit(theta0, v0, paper_params,
                                              PeriodController(0.0, rate), 60, 1e-3)
        assert controlled.stop_reason == passive.stop_reason
        for a, b in ((passive.theta, controlled.theta), (passive.v, controlled.v),
                     (passive.hop_phase, controlled.hop_phase)):
            assert np.array_equal(a, b, equal_nan=True)
        assert np.all(controlled.tau == paper_params.racket_period)
        reasons.add(passive.stop_reason)
    assert reasons == {"", "below_racket", "sticking"}  # every way an orbit ends was run


@pytest.mark.slow
def test_zero_gain_grid_on_the_pool_is_the_passive_basin(paper_params):
    theta, v = grid()
    passive = classify_batch(theta, v, paper_params, kernel="numpy")
    impact_map = ControlledMap.of(paper_params, PeriodController(0.0, 0.7),
                                  require_fixed_point=True)
    with parallel.LocalPool(2) as pool:
        pooled = classify_grid(theta, v, impact_map, map=pool.map, workers=pool.workers,
                               tile_points=500)
    assert_same_classification(passive, pooled)


@pytest.mark.slow
@pytest.mark.parametrize("switch", ["impact", "cycle"])
def test_controlled_basin_is_the_same_on_any_executor(paper_params, switch):
    """The controlled map (and the racket that switches period at its next cycle) on the
    worker pool, in threads and in this process: the same codes and counts."""
    theta, v = grid(50)
    controller = PeriodController(0.6, 0.8, switch=switch)
    whole = classify_controlled(theta, v, paper_params, controller)
    impact_map = ControlledMap.of(paper_params, controller, require_fixed_point=True)
    with parallel.LocalPool(2) as pool:
        pooled = classify_grid(theta, v, impact_map, map=pool.map, workers=pool.workers,
                               tile_points=300)
    with parallel.Threads(2) as threads:
        threaded = classify_grid(theta, v, impact_map, map=threads.map, workers=2,
                                 tile_points=97)
    assert_same_classification(whole, pooled)
    assert_same_classification(whole, threaded)
    counts = np.bincount(whole.outcome, minlength=4)
    assert counts[1] > 0 and counts[2] > 0  # sticking and below the racket: not trivial
    assert counts[0] > 0 or switch == "cycle"  # period1 (with the impact switch)


def test_a_map_with_only_the_protocol_gets_orbits_and_classification(paper_params):
    """A map written from the protocol alone (the passive map's step behind a wrapper that
    has no compiled kernel and no exact sticking) classifies as the passive map."""

    class OnlyTheProtocol:
        def __init__(self, inner):
            self.inner = inner

        def start(self, theta0, v0, *, wrap=False):
            return self.inner.start(theta0, v0, wrap=wrap)

        def launches(self, state):
            return self.inner.launches(state)

        def step(self, state, *, wrap=False):
            return self.inner.step(state, wrap=wrap)

        def near_fixed_point(self, state, tolerance):
            return self.inner.near_fixed_point(state, tolerance)

    minimal = OnlyTheProtocol(PassiveMap.of(paper_params))
    theta, v = grid(40)
    assert_same_classification(classify_grid(theta, v, minimal, tile_points=333),
                               classify_batch(theta, v, paper_params))
    orbit = iterate_map_orbit(minimal, 0.9, 4.8, 30, 1e-3)
    passive = iterate_orbit(0.9, 4.8, paper_params, 30, 1e-3)
    assert np.array_equal(orbit.column("v"), passive.v)
    with pytest.raises(Exception, match="exact sticking"):
        classify_grid(theta[:5], v[:5], minimal, ClassifySettings(min_hop_s=0.0))
