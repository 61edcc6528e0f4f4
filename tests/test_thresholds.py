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


def test_the_linear_modules_examples_run():
    outcome = doctest.testmod(linear, verbose=False)
    assert outcome.attempted >= 2 and outcome.failed == 0


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
    from bounce_cli.api import warn_if_unstable
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
