"""Eq. 15 and the OLS line fit with t-based confidence intervals."""

import math

import numpy as np
import pytest
from scipy import stats

from bounce_cli.model.params import ModelError, ModelParams
from bounce_cli.analysis.regression import (
    eq15_amplitude,
    eq15_slope,
    ols_line,
    period_for_height,
    phase_from_slope,
)


@pytest.mark.parametrize("alpha, g, a, tau", [(0.5, 9.81, 0.30, 0.92), (0.42, 5.8, 0.065, 0.55),
                                              (0.7, 9.81, 0.12, 0.6)])
def test_eq15_is_eq8_rewritten(alpha, g, a, tau):
    theta = ModelParams(alpha, g, a, tau).fixed_point().theta_rad
    assert eq15_amplitude(tau, theta, alpha, g) == pytest.approx(a, rel=1e-12)
    assert phase_from_slope(eq15_slope(theta, alpha, g), alpha, g) == pytest.approx(theta)


def test_period_for_height_gives_that_height():
    tau = period_for_height(0.6, 9.81)
    v = ModelParams(0.5, 9.81, 0.3, float(tau)).fixed_point().v_m_s  # eq. 7
    assert v**2 / (2 * 9.81) == pytest.approx(0.6)


def test_ols_matches_scipy_linregress():
    rng = np.random.default_rng(3)
    x = rng.uniform(0.3, 0.7, 20)
    y = 0.3 * x + 0.01 + rng.normal(0, 0.01, 20)
    fit = ols_line(x, y, 0.9)
    ref = stats.linregress(x, y)
    t = stats.t.ppf(0.95, 18)
    assert fit.slope == pytest.approx(ref.slope)
    assert fit.intercept == pytest.approx(ref.intercept)
    assert fit.r2 == pytest.approx(ref.rvalue**2)
    assert fit.slope_ci_high - fit.slope == pytest.approx(t * ref.stderr)
    assert fit.intercept - fit.intercept_ci_low == pytest.approx(t * ref.intercept_stderr)


def test_noiseless_line_is_recovered_exactly():
    x = np.array([0.31, 0.33, 0.49, 0.5, 0.65, 0.66])
    fit = ols_line(x, 0.287 * x)
    assert fit.slope == pytest.approx(0.287, rel=1e-12)
    assert abs(fit.intercept) < 1e-14 and fit.r2 == pytest.approx(1.0)


@pytest.mark.parametrize("confidence", [0.95, 0.8])
def test_confidence_intervals_cover_at_nominal_rate(confidence):
    """Many small data sets from eq. 15 + amplitude noise: the t intervals cover the true slope
    and the zero intercept at the nominal rate (n = 6, where z intervals would undercover)."""
    sets, alpha, g, theta = 4000, 0.5, 9.81, math.radians(32)
    rng = np.random.default_rng(2024)
    tau = np.repeat(period_for_height(np.array([0.4, 0.6, 0.8]), g), 2)
    tau = tau + rng.normal(0, 0.01, (sets, tau.size))
    x = tau**2
    y = eq15_amplitude(tau, theta, alpha, g) + rng.normal(0, 0.004, x.shape)
    fit = ols_line(x, y, confidence)
    slope = eq15_slope(theta, alpha, g)
    cover_slope = np.mean((fit.slope_ci_low <= slope) & (slope <= fit.slope_ci_high))
    cover_zero = np.mean((fit.intercept_ci_low <= 0) & (0 <= fit.intercept_ci_high))
    tol = 4.5 * math.sqrt(confidence * (1 - confidence) / sets)
    assert cover_slope == pytest.approx(confidence, abs=tol)
    assert cover_zero == pytest.approx(confidence, abs=tol)


def test_ols_needs_three_points_and_spread():
    with pytest.raises(ModelError, match="at least 3"):
        ols_line([1.0, 2.0], [1.0, 2.0])
    with pytest.raises(ModelError, match="two different"):
        ols_line([1.0, 1.0, 1.0], [1.0, 2.0, 3.0])
