"""Statistics over a study's units (subjects x conditions): the paper's single-subject
analyses (Figs. 6-9, 11; eqs. 10, 15) turned into group tests.

* :func:`mixed_trend`: a learning trend (Fig. 6) over subjects, a linear mixed-effects model
  with a random intercept and slope per subject (statsmodels ``MixedLM``).
* :func:`paired_difference`: the data's spectral radius minus the model's (eq. 10) per unit,
  its mean with a t interval: section 7's "the model is too slow" tested across subjects.
* :func:`eq15_prediction`: eq. 15's slope for trials of differing alpha, g and phase.
* :func:`across_units`: curves (correlation functions, impulse responses) averaged over units,
  with their SD across units.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from ..errors import TooFewObservationsError
from .regression import eq15_slope


@dataclass(frozen=True)
class Trend:
    """A fixed-effect slope with its t interval on ``df`` degrees of freedom: ``method``
    says which model gave it (``mixed: random intercept and slope``, ``mixed: random
    intercept``, ``two-stage``, ``ols``); ``mixed`` is False where no mixed model could be
    fitted."""

    slope: float
    intercept: float
    se: float
    ci_low: float
    ci_high: float
    p_value: float
    groups: int
    observations: int
    method: str
    mixed: bool
    df: int


def mixed_trend(frame: pd.DataFrame, y: str, x: str = "trial_number", group: str = "subject",
                confidence: float = 0.95) -> Trend:
    """The fixed-effect slope of ``y`` on ``x`` with a random intercept and slope per
    ``group`` (the learning trend of Fig. 6 over subjects).

    Parameters
    ----------
    frame : pandas.DataFrame
        One row per trial, with columns ``y``, ``x`` and ``group``.
    y, x, group : str
        Response, trial number, and the grouping (subject) column.
    confidence : float
        Level of the slope's interval.

    Returns
    -------
    Trend
        The slope with SE, interval and p-value. Where the random-slope model does not
        converge, a random intercept only; where neither does, the two-stage estimate (the
        mean of each subject's own OLS slope, t interval across subjects); with one subject,
        ordinary least squares. ``method`` names which.

    Notes
    -----
    The mixed model's interval and p-value take Student's t, not the normal (the Wald
    statistic's reference with as many subjects as a lab has: with 3 subjects the normal
    interval covered the population slope in 85 % of simulated studies, the t interval in
    97.5 %), on the containment degrees of freedom: subjects - 1 for the slope of the
    random-slope model (it varies between subjects), trials - subjects - 1 for the random
    intercept model's (a within-subject effect).
    """
    data = frame[[y, x, group]].dropna()
    data = data.assign(**{group: data[group].astype(str)})
    n_groups = int(data[group].nunique())
    n_obs = len(data)
    if n_obs < 3:
        raise TooFewObservationsError(f"a trend of {y} needs at least 3 trials (got {n_obs})")
    if n_groups >= 2:
        import statsmodels.formula.api as smf

        # the containment degrees of freedom of the fixed slope (Notes)
        for re_formula, method, df in (
                (f"~{x}", "mixed: random intercept and slope", n_groups - 1),
                ("~1", "mixed: random intercept", n_obs - n_groups - 1)):
            if df < 1:
                continue
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                try:
                    model = smf.mixedlm(f"{y} ~ {x}", data, groups=data[group],
                                        re_formula=re_formula)
                    fit = model.fit(reml=True, method=["lbfgs", "powell"])
                except (np.linalg.LinAlgError, ValueError):
                    continue
                # inside: a covariance with a negative diagonal warns in its sqrt (the SE is
                # NaN and the next model is tried; the warning is no user's business)
                slope, se = float(fit.fe_params[x]), float(fit.bse_fe[x])
            if not (bool(getattr(fit, "converged", True)) and math.isfinite(slope)
                    and math.isfinite(se) and se > 0.0):
                continue
            # a random-effects variance estimated at 0 is a valid fit of the fixed effects
            # (the data show no spread of that effect across subjects): said, not refused
            if any("boundary" in str(w.message).lower() or "singular" in str(w.message).lower()
                   for w in caught):
                method += "; a random-effects variance estimated at 0"
            t = stats.t.ppf(0.5 + confidence / 2.0, df)
            p = 2.0 * stats.t.sf(abs(slope / se), df)
            return Trend(slope, float(fit.fe_params["Intercept"]), se, slope - t * se,
                         slope + t * se, float(p), n_groups, n_obs, method, True, df)
        slopes, intercepts = [], []
        for _, part in data.groupby(group, sort=True):
            if part[x].nunique() >= 2:
                res = stats.linregress(part[x].to_numpy(float), part[y].to_numpy(float))
                slopes.append(res.slope)
                intercepts.append(res.intercept)
        if len(slopes) >= 2:
            # two-stage: each subject's own slope, their mean with a t interval across subjects
            m, sd, k = float(np.mean(slopes)), float(np.std(slopes, ddof=1)), len(slopes)
            se = sd / math.sqrt(k)
            t = stats.t.ppf(0.5 + confidence / 2.0, k - 1)
            p = float(2.0 * stats.t.sf(abs(m / se), k - 1)) if se > 0 else math.nan
            return Trend(m, float(np.mean(intercepts)), se, m - t * se, m + t * se, p, n_groups,
                         n_obs, "two-stage: mean of the subjects' own slopes (mixed model not "
                         "estimable)", False, k - 1)
    res = stats.linregress(data[x].to_numpy(float), data[y].to_numpy(float))
    t = stats.t.ppf(0.5 + confidence / 2.0, n_obs - 2)
    return Trend(float(res.slope), float(res.intercept), float(res.stderr),
                 float(res.slope - t * res.stderr), float(res.slope + t * res.stderr),
                 float(res.pvalue), n_groups, n_obs, "ols (one subject)", False, n_obs - 2)


@dataclass(frozen=True)
class PairedDifference:
    """Mean of ``a - b`` over pairs, its SD, n, t interval and two-sided p-value."""

    mean: float
    sd: float
    n: int
    ci_low: float
    ci_high: float
    p_value: float


def paired_difference(a, b, confidence: float = 0.95) -> PairedDifference:
    """The paired difference ``a - b`` (e.g. the data's spectral radius minus the model's, per
    unit) with a t interval of its mean; pairs with a NaN are left out.

    Parameters
    ----------
    a, b : array_like
        Paired values.
    confidence : float
        Level of the interval.

    Returns
    -------
    PairedDifference
        NaN interval and p-value with fewer than 2 pairs.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = (a - b)[np.isfinite(a) & np.isfinite(b)]
    n = int(d.size)
    if n == 0:
        return PairedDifference(math.nan, math.nan, 0, math.nan, math.nan, math.nan)
    mean = float(d.mean())
    if n < 2:
        return PairedDifference(mean, math.nan, 1, math.nan, math.nan, math.nan)
    sd = float(d.std(ddof=1))
    se = sd / math.sqrt(n)
    t = stats.t.ppf(0.5 + confidence / 2.0, n - 1)
    p = float(2.0 * stats.t.sf(abs(mean / se), n - 1)) if se > 0 else (0.0 if mean else 1.0)
    return PairedDifference(mean, sd, n, mean - t * se, mean + t * se, p)


def eq15_prediction(tau_s, theta_rad, alpha, g) -> float:
    """Eq. 15's slope for trials whose alpha, g and mean phase differ: the least-squares line
    through the origin of each trial's predicted amplitude ``s_i tau_i^2`` on ``tau_i^2``,
    i.e. ``sum s_i tau_i^4 / sum tau_i^4`` (equal to eq. 15's slope when they agree).

    Parameters
    ----------
    tau_s, theta_rad, alpha, g : array_like
        Per trial: mean racket period (s), mean impact phase (rad), alpha, gravity (m/s^2).

    Returns
    -------
    float
        The predicted slope, m/s^2 (NaN when no trial has all four).
    """
    tau = np.asarray(tau_s, float)
    s = eq15_slope(np.asarray(theta_rad, float), np.asarray(alpha, float), np.asarray(g, float))
    ok = np.isfinite(tau) & np.isfinite(s)
    if not ok.any():
        return math.nan
    w = tau[ok] ** 4
    return float(np.sum(s[ok] * w) / np.sum(w))


def across_units(frame: pd.DataFrame, keys: list[str], value: str) -> pd.DataFrame:
    """Mean and SD across units of a curve given per unit (e.g. each unit's mean correlation
    at each lag), by ``keys``.

    Parameters
    ----------
    frame : pandas.DataFrame
        One row per unit and curve point: the ``keys`` and ``value``.
    keys : list of str
        What identifies a point of the curve (e.g. ``["condition", "pair", "lag"]``).
    value : str
        The column averaged.

    Returns
    -------
    pandas.DataFrame
        ``keys`` + ``mean``, ``sd`` (ddof 1; NaN for one unit) and ``units``.
    """
    grouped = frame.dropna(subset=[value]).groupby(keys, sort=True)[value]
    out = grouped.agg(mean="mean", sd="std", units="count").reset_index()
    return out
