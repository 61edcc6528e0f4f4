"""One source for each threshold and protocol (issue 23): "stable" with its rounding margin
(``engine.linear.is_stable``, ``radius_below``), decided the same way wherever it is asked."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

from bounce_cli.model import linear
from bounce_cli.model.linear import ROUNDING_MARGIN, is_stable, radius_below
from bounce_cli.model.params import ModelParams

PAPER = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.92)


def ulps_from_one(n: int) -> float:
    """The float ``n`` representable steps above (n > 0) or below (n < 0) 1.0."""
    x = 1.0
    for _ in range(abs(n)):
        x = float(np.nextafter(x, np.inf if n > 0 else -np.inf))
    return x


# -- is_stable and its margin ----------------------------------------------------------------
@pytest.mark.parametrize("n", [-8, -2, -1, 0, 1, 2, 8])
def test_a_radius_of_one_to_a_few_ulps_is_not_stable(n):
    assert not is_stable(ulps_from_one(n))
    assert not radius_below(ulps_from_one(n))


@pytest.mark.parametrize("radius, stable", [
    (0.0, True), (0.5, True), (1.0 - 10 * ROUNDING_MARGIN, True),
    (1.0 - ROUNDING_MARGIN / 2, False), (1.5, False), (float("nan"), False), (float("inf"), False),
])
def test_is_stable_inside_the_unit_circle_by_more_than_rounding(radius, stable):
    assert is_stable(radius) is stable


def test_radius_below_is_elementwise_and_takes_any_level():
    radius = np.array([[0.2, 0.3 * (1 - 1e-15)], [0.3, np.nan]])
    assert radius_below(radius, 0.3).tolist() == [[True, False], [False, False]]
    assert radius_below(radius, np.array([1.0, 0.25])).tolist() == [[True, False], [True, False]]


@pytest.mark.parametrize("module", ["linear", "params", "perturbation"])
def test_the_examples_of_the_modules_holding_the_rules_run(module):
    import importlib

    outcome = doctest.testmod(importlib.import_module(f"bounce_cli.model.{module}"),
                              verbose=False)
    assert outcome.attempted >= 1 and outcome.failed == 0


# -- the neutral points decided by the margin, not by the last bits --------------------------
def test_the_fold_and_flip_boundaries_of_eq_14_are_not_stable_on_the_stability_grid():
    from bounce_cli.experiments.stability import eigen_frame

    alpha = np.linspace(-0.2, 0.9, 111)
    frame = eigen_frame(alpha, np.array([0.0]))  # AC = 0: lambda_+ = 1 (eq. 10)
    assert np.allclose(frame.spectral_radius, 1.0, rtol=0, atol=1e-14)
    assert not frame.stable.any()
    flip = np.concatenate([eigen_frame(np.array([a]), np.array([linear.flip_boundary_g(a)]))
                           .stable.to_numpy() for a in alpha])  # lambda_- = -1
    assert not flip.any()
    inside = eigen_frame(alpha, np.array([-1e-6]))
    assert inside.stable.all()


def test_stability_of_a_fixed_point_agrees_with_is_stable():
    st = linear.stability(PAPER)
    assert st.stable is is_stable(st.spectral_radius) is True
    unstable = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.30, racket_period=0.5)
    assert linear.stability(unstable).stable is False


@pytest.mark.parametrize("rate", np.linspace(0.05, 1.0, 20))
def test_the_cli_warns_at_gain_one_whatever_the_last_bits(rate):
    """Racket period control with K = 1 has an eigenvalue 1 (a neutral direction): its radius
    is 1 +- 1 ulp depending on the rate; the warning must not depend on which."""
    from bounce_cli.experiments.runner import warn_if_unstable
    from bounce_cli.model.control import PeriodController

    heard: list[str] = []
    warn_if_unstable(PAPER, PeriodController(gain=1.0, rate=float(rate)), warn=heard.append)
    assert len(heard) == 1 and "linearly unstable" in heard[0]
    heard.clear()
    warn_if_unstable(PAPER, PeriodController(gain=0.5, rate=float(rate)), warn=heard.append)
    assert heard == []


def test_no_stationary_covariance_on_the_boundary():
    from bounce_cli.analysis.stochastic import stationary_covariance
    from bounce_cli.errors import NotStableError

    with pytest.raises(NotStableError):
        stationary_covariance(np.diag([ulps_from_one(-1), 0.5]), np.eye(2))


# -- the sticking threshold: one constant ------------------------------------------------------
def test_every_default_sticking_threshold_is_section_3s_one_constant():
    import inspect

    from bounce_cli.analysis.bifurcation import SweepSettings
    from bounce_cli.model.maps import ClassifySettings
    from bounce_cli.analysis.continuation import orbit_by_iteration
    from bounce_cli.analysis.data_stats import simulate_impacts
    from bounce_cli.data.simulated_lab import LAB_MIN_HOP_S, SessionSettings
    from bounce_cli.experiments.bifurcation import IterateBlock
    from bounce_cli.experiments.continuation import DiagramBlock
    from bounce_cli.experiments.lab import LabBlock
    from bounce_cli.experiments.simulate_recording import RecordingConfig
    from bounce_cli.model.params import MIN_HOP_S

    assert MIN_HOP_S == 1e-3  # section 3: "the time between bounces was less than 1e-3 s"
    assert ClassifySettings().min_hop_s == SweepSettings().min_hop_s == MIN_HOP_S
    from bounce_cli.cli import commands

    assert commands.MIN_HOP_S == MIN_HOP_S  # bounce orbit --min-hop-s, written beside the CLI
    assert IterateBlock().min_hop_s == DiagramBlock().min_hop_s == MIN_HOP_S
    for fn in (orbit_by_iteration, simulate_impacts):
        assert inspect.signature(fn).parameters["min_hop_s"].default == MIN_HOP_S
    assert SessionSettings().min_hop_s == LAB_MIN_HOP_S
    assert LabBlock.model_fields["min_hop_s"].default == LAB_MIN_HOP_S
    assert RecordingConfig.model_fields["min_hop_s"].default == LAB_MIN_HOP_S


# -- the circular mean --------------------------------------------------------------------------
@pytest.mark.parametrize("degrees, mean", [
    ([350.0, 10.0], 0.0), ([359.0, 1.0, 3.0], 1.0), ([-10.0, 10.0, 30.0], 10.0),
    ([170.0, -170.0], 180.0), ([90.0], 90.0), ([0.5 + 360.0 * 3, 359.5], 0.0),
])
def test_the_circular_mean_of_phases_around_zero_is_near_zero(degrees, mean):
    from bounce_cli.model.params import circular_mean, phase_difference

    got = circular_mean(np.radians(degrees))
    assert 0.0 <= got < 2 * np.pi
    assert abs(float(phase_difference(got, np.radians(mean)))) < 1e-12


def test_the_circular_mean_has_one_home():
    from bounce_cli.data import impacts
    from bounce_cli.model.params import circular_mean

    assert not hasattr(impacts, "circular_mean")  # its former home re-exports it no more
    assert np.isnan(circular_mean([]))


# -- section 7's perturbation schedule: one rule ----------------------------------------------
def test_every_fifth_bounce_first_and_last():
    from bounce_cli.model.perturbation import perturbed_impact

    mask = perturbed_impact(np.arange(21), 5)
    assert np.flatnonzero(mask).tolist() == [5, 10, 15, 20]  # not 0: a trial starts unperturbed
    assert np.flatnonzero(perturbed_impact(np.arange(20), 5)).tolist() == [5, 10, 15]
    assert np.flatnonzero(perturbed_impact(np.arange(12), 5, first=0)).tolist() == [0, 5, 10]
    assert perturbed_impact(4, 5, first=4) is True and perturbed_impact(3, 5, first=4) is False
    assert not perturbed_impact(np.arange(30), 0).any()  # no perturbations


def test_the_three_simulations_perturb_the_same_impacts():
    from bounce_cli.analysis.data_stats import perturbation_schedule
    from bounce_cli.data.simulated_lab import SessionSettings, alpha_at
    from bounce_cli.analysis.control_design import simulate_perturbation_trials
    from bounce_cli.model.control import PeriodController

    n = 23
    alpha = perturbation_schedule(2, n, 5, 0.5, [(0.3, 0.4), (0.6, 0.7)], seed=1)
    assert (np.flatnonzero(alpha[0] != 0.5) == [5, 10, 15, 20]).all()
    trials = simulate_perturbation_trials(PAPER, PeriodController(gain=0.5, rate=0.5), n_trials=1,
                                          impacts_per_trial=n, seed=1)
    perturbed = np.asarray(trials["perturbed"], bool)
    assert np.flatnonzero(perturbed).tolist() == [5, 10, 15, 20]
    lab = SessionSettings(perturb_every=5, perturb_first=5, perturb_alphas=(0.4, 0.6))
    assert [k for k in range(n) if alpha_at(k, 0.5, lab)[1]] == [5, 10, 15, 20]
    assert [alpha_at(k, 0.5, lab)[0] for k in (5, 10, 15)] == [0.4, 0.6, 0.4]


# -- the relaxation rule ------------------------------------------------------------------------
def test_relaxation_at_the_boundaries_of_the_series():
    from bounce_cli.model.perturbation import relaxation_impacts, relaxed_from

    assert relaxed_from([True, True, True]) == 0  # relaxed from the perturbed impact on
    assert relaxed_from([False, False, True]) == 2  # only the last impact inside
    assert relaxed_from([True, True, False]) == -1  # leaves at the end: not relaxed
    assert relaxed_from([False, True, False, True]) == 3  # a return inside is not relaxed
    dv = np.array([0.3, 0.02, 0.01, 0.01])
    assert relaxation_impacts(dv, np.zeros(4), 0.01, 0.01) == 2  # |dv| <= tol is inside
    assert relaxation_impacts(dv, np.array([0, 0, 0, np.nan]), 0.01, 0.01) == -1


def test_data_and_model_relax_by_the_same_rule():
    from bounce_cli.analysis.data_stats import relaxation_impact
    from bounce_cli.model.perturbation import relaxation_impacts

    rng = np.random.default_rng(3)
    for _ in range(50):
        dv, dtheta = rng.normal(0, 0.02, 8), rng.normal(0, 0.02, 8)
        model = relaxation_impacts(dv, dtheta, 0.02, 0.02)
        data = relaxation_impact([dv, dtheta], [np.zeros(8), np.zeros(8)], [0.02, 0.02])
        assert model == data
    # the data's SE widens the tolerance: a mean within 2 SE of 0 counts as relaxed
    assert relaxation_impact([[0.5, 0.05]], [[0.01, 0.03]], [0.01]) == 1
