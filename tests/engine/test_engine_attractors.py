"""Attractors by recurrence (``analysis.attractors``): checked against the basin's classifier,
continuation, the Lyapunov routine and the basin measures' known values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bounce_cli.analysis.attractors import (
    BELOW_RACKET,
    STICKING,
    UNDECIDED,
    AttractorFinder,
    RecurrenceSettings,
    basin_fractions,
    find_attractors,
)
from bounce_cli.analysis.basin_measures import basin_entropy, uncertainty_exponent
from bounce_cli.analysis.bifurcation import SweepSettings, iterate_sweep, parameter_point, \
    sweep_parameters
from bounce_cli.analysis.classify import BELOW_RACKET as C_BELOW
from bounce_cli.analysis.classify import LOCKED as C_LOCKED
from bounce_cli.analysis.classify import PERIOD1 as C_PERIOD1
from bounce_cli.analysis.classify import STICKING as C_STICKING
from bounce_cli.analysis.classify import classify_batch
from bounce_cli.analysis.continuation import Continuation, eq8_orbit
from bounce_cli.model.maps import ClassifySettings
from bounce_cli.model.params import phase_difference

QUICK = RecurrenceSettings(transient=500, window=128, max_period=32, sample=200)


def grid(theta_deg, v, n):
    th, vv = np.meshgrid(np.radians(np.linspace(*theta_deg, n)), np.linspace(*v, n))
    return th, vv


def test_at_fig4_every_decided_start_is_today_s_class(paper_params):
    th, vv = grid((0, 360), (0, 10), 80)
    found = find_attractors(th, vv, paper_params, QUICK)
    today = classify_batch(th, vv, paper_params).outcome
    (p1,) = [a.index for a in found.attractors if a.kind == "periodic" and a.period == 1]
    assert found.attractors[p1].v[0] == pytest.approx(paper_params.fixed_point().v_m_s, abs=1e-12)
    assert np.allclose(np.abs(found.attractors[p1].multipliers), 0.5, atol=1e-12)
    assert np.array_equal(found.labels == p1, today == C_PERIOD1)
    assert np.array_equal(found.labels == STICKING, today == C_STICKING)
    assert np.array_equal(found.labels == BELOW_RACKET, today == C_BELOW)
    shares = basin_fractions(found.labels)
    assert sum(f.fraction for f in shares) == pytest.approx(1.0, abs=1e-12)
    assert all(f.low <= f.fraction <= f.high for f in shares)


@pytest.mark.slow
def test_exact_sticking_s_locked_orbit_owns_what_sticks(paper_params):
    """With exact sticking every orbit that sticks is released in one state: where that
    state's orbit sticks again (a locked orbit), the starts that stick are its basin, as the
    classifier's exact mode says."""
    params = parameter_point(paper_params, "racket_amplitude", 0.55)
    th, vv = grid((0, 360), (0, 10), 50)
    found = find_attractors(th, vv, params, RecurrenceSettings(
        transient=500, window=128, max_period=32, sample=200, min_hop_s=0.0))
    today = classify_batch(th, vv, params, ClassifySettings(min_hop_s=0.0),
                           require_fixed_point=False).outcome
    (locked,) = [a.index for a in found.attractors if a.kind == "locked"]
    assert np.array_equal(found.labels == BELOW_RACKET, today == C_BELOW)
    assert np.all(found.labels[today == C_LOCKED] == locked)
    # what today's rules leave undecided (100 impacts) or call period-1 (a pass within 1e-3
    # of eq. 8's orbit, unstable here: AC = -2.4 g) ends on the locked orbit as well
    rest = ~np.isin(today, (C_LOCKED, C_BELOW))
    assert rest.sum() >= 5 and np.all(found.labels[rest] == locked)
    assert not np.any(found.labels == UNDECIDED)


@pytest.mark.slow
def test_the_period_2_orbit_past_the_flip_is_continuation_s(paper_params):
    cont = Continuation(paper_params, "gamma", 1.3, 1.62)
    v0, theta0 = eq8_orbit(parameter_point(paper_params, "gamma", 1.3))
    cont.run(1.3, v0, theta0, 1, [2 * math.pi])
    branch = next(b for b in cont.branches if b.period == 2)
    point = min(branch.points, key=lambda p: abs(p.value - 1.6))
    params = parameter_point(paper_params, "gamma", point.value)
    th, vv = grid((0, 360), (0, 10), 40)
    found = find_attractors(th, vv, params, QUICK)
    (p2,) = [a for a in found.attractors if a.kind == "periodic" and a.period == 2
             and a.cycles == 2]
    assert p2.refined and np.all(np.abs(p2.multipliers) < 1.0)
    closest = np.argmin(np.abs(phase_difference(p2.theta, point.theta)))
    assert p2.v[closest] == pytest.approx(point.v, abs=1e-9)
    assert abs(float(phase_difference(p2.theta[closest], point.theta))) < 1e-9
    assert np.sort(p2.v) == pytest.approx(np.sort(point.impact_v), abs=1e-9)


@pytest.mark.slow
def test_the_chaotic_attractor_s_exponent_is_the_lyapunov_routine_s(paper_params):
    params = parameter_point(paper_params, "gamma", 1.72)
    th, vv = grid((0, 360), (0, 10), 30)
    found = find_attractors(th, vv, params, QUICK)
    (chaos,) = [a for a in found.attractors if a.kind == "chaotic"]
    assert chaos.lyapunov > 0.05
    # the routine from another start in the same basin, run longer
    start = np.flatnonzero(found.labels.ravel() == chaos.index)[0]
    orbits = iterate_sweep([th.ravel()[start]], [vv.ravel()[start]],
                           sweep_parameters(params, "gamma", [1.72]),
                           SweepSettings(transient_impacts=1000, measured_impacts=8000))
    assert chaos.lyapunov == pytest.approx(float(orbits.lyapunov[0]),
                                           abs=4 * float(orbits.lyapunov_se[0]) + 0.02)


def test_a_region_of_one_attractor_has_no_basin_entropy(paper_params):
    th, vv = grid((30, 50), (4.3, 4.7), 25)
    labels = find_attractors(th, vv, paper_params, QUICK).labels
    assert np.unique(labels).size == 1 and labels.ravel()[0] >= 0
    measured = basin_entropy(labels, 5)
    assert measured.basin_entropy == 0.0 and measured.boundary_basin_entropy == 0.0


@pytest.mark.slow
def test_a_smooth_boundary_has_uncertainty_exponent_one(paper_params):
    """Below 1.8 m/s at 30-80 deg the only boundary is the racket's velocity curve v0 =
    a_r w cos(theta0) (below it the ball cannot leave): smooth, so alpha = 1."""
    finder = AttractorFinder(paper_params, QUICK)
    fit = uncertainty_exponent(lambda x, y: finder.label(x, y)[0],
                               (math.radians(30), math.radians(80)), (0.0, 1.8),
                               np.array([0.002, 0.004, 0.008, 0.016, 0.032]), 4000,
                               np.random.default_rng(1))
    assert abs(fit.alpha - 1.0) < max(3 * fit.alpha_se, 0.05)


@pytest.mark.slow
@pytest.mark.parametrize("kernel", ["auto", "numpy"])
def test_an_orbit_that_sticks_while_its_recurrence_is_followed_is_sticking(monkeypatch, kernel):
    """A chaotic transient that sticks after 4446 impacts (alpha 0.85, a_r 0.2945 m): past
    the discovery's 1256 impacts, while its recurrence is followed, it sticks; it is
    'sticking', as a start that sticks sooner is (it was left 'undecided')."""
    from bounce_cli.analysis.attractors import STICKING, RecurrenceSettings, find_attractors
    from bounce_cli.model.maps import iterate_orbit
    from bounce_cli.model.params import MIN_HOP_S, ModelParams

    monkeypatch.setenv("BOUNCE_KERNEL", kernel)
    params = ModelParams(alpha=0.85, g=9.81, racket_amplitude=0.2944509508080423,
                         racket_period=0.92)
    theta0, v0 = np.radians(86.89655172413794), 3.103448275862069
    orbit = iterate_orbit(theta0, v0, params, 6000, MIN_HOP_S)
    assert orbit.stop_reason == "sticking" and 1256 < orbit.v.size - 1 < 6000
    found = find_attractors(np.array([theta0]), np.array([v0]), params, RecurrenceSettings())
    assert found.labels.tolist() == [STICKING]


def test_a_periodic_orbit_s_exponent_is_its_largest_multiplier_s_log_per_impact():
    """A periodic attractor's lyapunov_per_impact was NaN while its multipliers were given:
    ln max |mu| / p (period-3 with |mu| 0.92, 0.13: ln 0.92 / 3), -inf for a superstable
    orbit, NaN without multipliers."""
    from bounce_cli.analysis.attractors import periodic_lyapunov

    assert periodic_lyapunov(np.array([0.920417, -0.127821]), 3) == pytest.approx(
        math.log(0.920417) / 3, rel=1e-12)
    assert periodic_lyapunov(np.array([0.7 + 0.1j, 0.7 - 0.1j]), 1) == pytest.approx(
        math.log(abs(0.7 + 0.1j)), rel=1e-12)
    assert periodic_lyapunov(np.array([0.0, 0.0]), 2) == -math.inf
    assert math.isnan(periodic_lyapunov(np.array([], complex), 2))
    assert math.isnan(periodic_lyapunov(np.array([np.nan, 0.5]), 2))


def test_the_boundary_entropy_is_read_against_ln_2_by_two_standard_errors():
    """measures.csv said '> ln 2 = 0.693: a fractal boundary' beside 0.693167 over 91 boxes
    (a margin of 2e-5, within any error): the verdict now takes the entropy's standard error
    (the boundary boxes' spread), and says when it decides nothing."""
    from bounce_cli.experiments.attractors import ln2_verdict

    assert "undecided" in ln2_verdict(0.693167, 0.028)
    assert "fractal boundary" in ln2_verdict(0.80, 0.02)
    assert "silent" in ln2_verdict(0.40, 0.02)
    assert "not tested" in ln2_verdict(0.75, math.nan)
    # the standard error is the boundary boxes' entropies' spread over sqrt(their number)
    grid = np.zeros((10, 10), int)
    grid[:, 3:] = 1  # the two left boxes hold two outcomes
    grid[0, 7] = 2  # a right box two others
    measured = basin_entropy(grid, box=5)
    assert measured.boundary_boxes == 3 and measured.boundary_basin_entropy_se > 0.0
