"""The amplitude-period relation (eq. 15) and its test by ordinary least squares (section 5).

Eq. 15, from eq. 8: a_r = (1 / 4 pi) (1 - alpha)/(1 + alpha) g / cos(theta~) tau^2, a line
through the origin in tau^2 whose slope is fixed by alpha, g and the impact phase theta~.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import stdtrit

from ..errors import TooFewObservationsError
from ..model.params import ModelParams, wrap_phase
from .stochastic import simulate_stochastic_map


def eq15_slope(theta_rad, alpha, g):
    """Slope of a_r against tau^2 (m/s^2): (1 / 4 pi) (1-alpha)/(1+alpha) g / cos(theta)."""
    return (1.0 - alpha) / (1.0 + alpha) * g / (4.0 * np.pi * np.cos(theta_rad))


def eq15_amplitude(tau_s, theta_rad, alpha, g):
    """Racket amplitude a_r (m) of eq. 15 for period tau (s) and impact phase theta (rad)."""
    return eq15_slope(theta_rad, alpha, g) * np.square(tau_s)


def phase_from_slope(slope, alpha, g):
    """The impact phase (rad) that eq. 15 implies for a given slope (NaN if none)."""
    with np.errstate(divide="ignore"):  # slope 0: no phase (NaN below)
        cos_t = (1.0 - alpha) / (1.0 + alpha) * g / (4.0 * np.pi * np.asarray(slope, float))
    return np.where(np.abs(cos_t) <= 1.0, np.arccos(np.clip(cos_t, -1.0, 1.0)), np.nan)


def period_for_height(height_m, g):
    """Racket period (s) of the period-1 orbit whose ball rises height_m above the impact:
    v~ = g tau / 2 (eq. 7) and h = v~^2 / (2 g), so tau = sqrt(8 h / g)."""
    return np.sqrt(8.0 * np.asarray(height_m, float) / g)


@dataclass(frozen=True)
class LineFit:
    """OLS fit y = intercept + slope x with t-based confidence intervals (arrays broadcast
    over leading axes when fitting many data sets at once)."""

    n: np.ndarray
    slope: np.ndarray
    slope_ci_low: np.ndarray
    slope_ci_high: np.ndarray
    intercept: np.ndarray
    intercept_ci_low: np.ndarray
    intercept_ci_high: np.ndarray
    r2: np.ndarray


#: tau^2 spanning less than this fraction of its mean determines no slope of eq. 15 worth
#: reporting (the paper's Fig. 7 spans about a factor 2)
NARROW_TAU2 = 0.01


def narrow_periods(tau_s) -> str:
    """Why eq. 15's slope is not determined by trials at these racket periods (s): their
    squared periods span less than ``NARROW_TAU2`` of their mean (one racket period, as a
    virtual set-up's sine session); '' where they span enough."""
    tau2 = np.square(np.asarray(tau_s, dtype=float))
    spread = float(np.ptp(tau2) / np.mean(tau2)) if tau2.size else 0.0
    if spread >= NARROW_TAU2:
        return ""
    return (f"the trials' squared racket periods span only {spread:.2%} of their mean, so "
            "eq. 15's slope is not determined (fit trials at different racket periods, e.g. "
            "different target heights)")


def ols_line(x, y, confidence: float = 0.95) -> LineFit:
    """Ordinary least squares of y on x along the last axis, closed form.

    Standard errors from the residual variance SSE / (n - 2); intervals estimate +- t_{n-2}
    quantile x SE. Needs n >= 3 and x not constant.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    n = x.shape[-1]
    if n < 3:
        raise TooFewObservationsError(
            f"a line fit with confidence intervals needs at least 3 points (got {n})")
    xm = x.mean(axis=-1, keepdims=True)
    ym = y.mean(axis=-1, keepdims=True)
    sxx = np.sum((x - xm) ** 2, axis=-1)
    # x values equal to within rounding (means of the same numbers summed in another order)
    if np.any(sxx <= n * (1e-12 * np.max(np.abs(x), axis=-1)) ** 2):
        # the design cannot answer it (every trial at the same racket period: a sine racket)
        raise TooFewObservationsError("a line fit needs at least two different x values")
    sxy = np.sum((x - xm) * (y - ym), axis=-1)
    syy = np.sum((y - ym) ** 2, axis=-1)
    slope = sxy / sxx
    intercept = ym[..., 0] - slope * xm[..., 0]
    sse = np.maximum(syy - slope * sxy, 0.0)
    s2 = sse / (n - 2)
    se_slope = np.sqrt(s2 / sxx)
    se_int = np.sqrt(s2 * (1.0 / n + xm[..., 0] ** 2 / sxx))
    t = stdtrit(n - 2, 0.5 + confidence / 2.0)  # Student's t quantile (stats.t.ppf)
    r2 = np.where(syy > 0, 1.0 - sse / np.where(syy > 0, syy, 1.0), 1.0)
    return LineFit(
        n=np.full(np.shape(slope), n), slope=slope,
        slope_ci_low=slope - t * se_slope, slope_ci_high=slope + t * se_slope,
        intercept=intercept,
        intercept_ci_low=intercept - t * se_int, intercept_ci_high=intercept + t * se_int,
        r2=r2,
    )


@dataclass(frozen=True)
class TrialMeans:
    """Means over the simulated bounces of one trial."""

    tau_s: float  # mean time between impacts, s
    theta_rad: float  # mean impact phase (wrapped), rad
    bounces: int
    lost: bool  # the ball stuck to the racket (trial unusable)


def simulate_trial(params: ModelParams, q_v: float, q_theta: float, duration_s: float,
                   seed: np.random.SeedSequence, burn_in: int = 0,
                   velocity_phase: str = "theta") -> TrialMeans:
    """Run one trial of eqs. 16-18 for ``duration_s`` (round(duration / tau) bounces) from the
    trial's fixed point and average what an experimenter measures: the time between impacts
    and the impact phase."""
    fp = params.fixed_point()
    n = max(int(round(duration_s / params.racket_period)), 2)
    runs = simulate_stochastic_map(params, q_v, q_theta, n, [seed], burn_in=burn_in,
                                   velocity_phase=velocity_phase)
    dtheta = runs.dtheta[0]
    # the phase advances by 2 pi + (theta_{k+1} - theta_k) between impacts
    hop = 2.0 * np.pi + np.diff(dtheta)
    return TrialMeans(
        tau_s=float(np.mean(hop) / params.omega) if n > 1 else params.racket_period,
        theta_rad=float(wrap_phase(fp.theta_rad + np.mean(dtheta))),
        bounces=n,
        lost=bool(runs.lost[0]),
    )


__all__ = [
    "LineFit", "TrialMeans", "eq15_amplitude", "eq15_slope", "ols_line", "period_for_height",
    "phase_from_slope", "simulate_trial",
]
