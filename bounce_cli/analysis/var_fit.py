"""The VAR(1) model of eq. 19, y_{k+1} = J y_k + eps_k, fitted to data (section 6).

Data are several trials of y_k = (v_k, theta_k), one array of shape (N_i, 2) per trial. Each
trial's mean is removed (the deviation from the trial's own stationary state: the fixed point
is not known from data) and no pair (y_k, y_{k+1}) spans two trials.

Two estimators of J, both pooled over trials:

``ols``
    Least squares of y_{k+1} on y_k: J = C(1) C(0)^-1 with C(l) = sum_k y_{k+l} y_k^T. Standard
    errors: Cov(vec J) = Sigma (x) (X^T X)^-1 with Sigma the residual covariance (the textbook
    formula for a VAR, e.g. Luetkepohl 2005, section 3.2). When y is measured with white noise
    w (observed z = y + w), C(0) grows by Cov(w) while C(1) does not: OLS is biased toward zero
    (errors in variables), i.e. toward a faster, MORE stable system.
``lag2``
    J = C(2) C(1)^-1 (C(2) = J C(1) for eq. 19): white measurement noise leaves C(1) and C(2)
    untouched, so this estimate is not biased by it. It is the instrumental-variable estimator
    with instrument y_{k-1} for y_k; its residual u_k = eps_k + w_{k+1} - J w_k is MA(1), so
    Cov(vec J) is the IV sandwich with the residual autocovariance truncated at lag 1 (exact for
    MA(1)). It needs C(1) well away from singular: more bounces than OLS (measured in the tests
    and the README).

Both are also biased at order 1/N_i by removing each trial's mean (the incidental-parameter or
"Nickell" bias of panel autoregressions: about -(1 + lambda)/N_i). ``split_jackknife`` removes
that O(1/N) term by the half-panel jackknife of Dhaene & Jochmans (2015):
J = 2 J(all) - (J(first halves) + J(second halves)) / 2, each half with its own mean removed.

Eigenvalues and spectral radius: delta method, numerical gradient of each with respect to the
four entries of J, times Cov(vec J). Intervals are estimate +- z SE (normal), except the
spectral radius's: a modulus lives in [0, inf), so its interval is the delta method on the log
scale, r exp(+- z SE / r) (SE(log r) = SE(r) / r), which never leaves (0, inf) and is
asymmetric where the estimate is uncertain. A data set of fewer pairs than
``MIN_PAIRS_FOR_INTERVAL`` (per estimator) gets no interval by default (NaN): whether the
first-order delta method holds its coverage there depends on J, the noise and above all on
measurement noise (which biases OLS), so it is measured, not assumed: ``acf --data``'s trust
study simulates data of the data's own run lengths at the model's J, the data's noise and the
set-up's measurement noise, and where the delta interval covers the truth there (at least the
level less ``trust_coverage_slack``, median bias within a quarter of the spread) the fit gets
its intervals (``Var1Fit.calibration_trusted``, ``experiments.data_side.calibrated``). The
fixed minimum (200 pairs for OLS, 1200 triples for lag2, whose ratio of covariances is
heavy-tailed on short data) is where the interval covered at least 90 % on linear VAR(1) data
at the acf and impulse configs' J and the assumed measurement noise, 400 data sets per size.

A spectral radius estimate that is not finite, above ``MAX_PLAUSIBLE_RADIUS`` (1.5: a ball
that kept bouncing cannot have it) or from an ill-conditioned fit (lag 2's instrument nearly
uncorrelated with the regressors: ``Var1Fit.instrument_det`` below ``MIN_INSTRUMENT_DET``) is
no estimate: :meth:`Var1Fit.radius_problem` says why, and the tables write it as NaN with that
reason (``experiments.data_side``, ``experiments.study``).

Exogenous inputs (VARX): with ``exog`` (each trial's (N_i, m) inputs u_k, e.g. the racket
period and amplitude of impact k's cycle), both estimators fit

    y_{k+1} = J y_k + B_next u_{k+1} + B_this u_k + eps_k

(each trial's mean of u removed too): impact k+1's flight starts in impact k's racket cycle and
ends in the next one, so both cycles enter (:mod:`bounce_cli.analysis.racket_inputs` gives the
model's B from eqs. 5-6). The inputs are their own instruments in ``lag2`` (they are measured
with the racket's precision, not the ball's). Without them, a racket that varies from cycle to
cycle biases J: u_k moves y_k and y_{k+1} alike. With them, on the nonlinear map, both
estimators converge to its best linear predictor at the data's spread, not to eq. 9's J
(``experiments.data_side.varx_prediction`` gives the model's prediction for the estimate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy.special import ndtri

from ..model.linear import eigenvalues_2x2
from ..model.params import ModelError

#: the entries of J in the order of vec(J) (row-major): (v, theta) as in eq. 9
J_ENTRIES = ("J_vv", "J_vtheta", "J_thetav", "J_thetatheta")
ESTIMATORS = ("ols", "lag2")
#: per estimator, fewer (y_k, y_{k+1}) pairs than this: no intervals (module docstring: the
#: delta method's 95 % interval covers at least 90 % from there on)
MIN_PAIRS_FOR_INTERVAL = {"ols": 200, "lag2": 1200}
#: a spectral radius estimate above this is no estimate: a ball that kept bouncing for the
#: recording cannot have it (its impacts diverge by this factor per bounce)
MAX_PLAUSIBLE_RADIUS = 1.5
#: a lag-2 fit whose instrument strength (``Var1Fit.instrument_det``) is below this is
#: ill-conditioned: on linear VAR(1) data at a study's J (radius 0.5, 1500 data sets per
#: size), the jackknifed lag-2 fits below it had a radius above 1.5 in 6 of 6 with 5 trials
#: of 35 impacts, in 22 of 25 with 3 trials of 35; none fell below it with 10 trials of 60
MIN_INSTRUMENT_DET = 0.01


@dataclass(frozen=True)
class Var1Fit:
    """A fitted J with its covariance and what follows from it."""

    method: str  # "ols" | "lag2", with "+jackknife" when split_jackknife was applied
    jacobian: np.ndarray  # (2, 2)
    cov_vec: np.ndarray  # (4, 4) covariance of vec(J) (row-major: J_ENTRIES)
    noise_cov: np.ndarray  # (2, 2) residual covariance (for lag2: of the MA(1) residual)
    n_pairs: int  # (y_k, y_{k+1}) pairs used
    n_trials: int
    #: (2, 2 m) coefficients of (u_{k+1}, u_k) in a VARX (empty without inputs) and their SEs
    exog_coef: np.ndarray = field(default_factory=lambda: np.zeros((2, 0)))
    exog_se: np.ndarray = field(default_factory=lambda: np.zeros((2, 0)))
    #: residuals per trial (rows k = 0.. of that trial's design), for diagnostics
    residuals: tuple[np.ndarray, ...] = ()
    #: |det Z'X| / sqrt(det Z'Z det X'X) of the instruments Z and regressors X (the product of
    #: their canonical correlations, in [0, 1]): 1 for OLS, near 0 where lag 2's C(1) is
    #: nearly singular; with the jackknife the least of the three fits'
    instrument_det: float = 1.0
    #: below ``MIN_PAIRS_FOR_INTERVAL``: the delta method's coverage measured on simulated data
    #: of this fit's own size (``experiments.data_side.calibrated``; NaN: not measured), and
    #: whether it is trusted there (then the fit has its intervals)
    calibrated_coverage: float = math.nan
    calibration_trusted: bool = False
    calibration_note: str = ""  # why it is not trusted there

    @property
    def jacobian_se(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov_vec), 0.0, None)).reshape(2, 2)

    @property
    def min_pairs_for_interval(self) -> int:
        """The fewest pairs for which this estimator gets intervals."""
        return MIN_PAIRS_FOR_INTERVAL[self.method.split("+")[0]]

    @property
    def has_interval(self) -> bool:
        """Enough pairs for the intervals (``MIN_PAIRS_FOR_INTERVAL``), or fewer where the
        delta method's coverage was measured and trusted at this size."""
        return self.n_pairs >= self.min_pairs_for_interval or self.calibration_trusted

    def radius_problem(self) -> str:
        """Why this fit's spectral radius is no estimate, or '' when it is one: the radius is
        not finite or above ``MAX_PLAUSIBLE_RADIUS`` (:func:`radius_problem`), or the fit is
        ill-conditioned (``instrument_det`` below ``MIN_INSTRUMENT_DET``).

        Returns
        -------
        str
            A reason that reads after "spectral radius withheld: ", or ''.
        """
        if not self.instrument_det >= MIN_INSTRUMENT_DET:
            return (f"the lag-2 fit is ill-conditioned (its instrument's normalised "
                    f"determinant is {self.instrument_det:.2g}, below {MIN_INSTRUMENT_DET:g}: "
                    "C(1) nearly singular; too few bounces)")
        return radius_problem(float(_eigen_quantities(self.jacobian)[0]))

    def eigen_summary(
        self, confidence: float = 0.95
    ) -> dict[str, tuple[float, float, float, float]]:
        """quantity -> (estimate, SE, CI low, CI high) for the spectral radius and the real and
        imaginary parts of lambda_+ and lambda_- (eq. 10's labels: lambda_+- = c +- sqrt(c^2 -
        det J), c = tr J / 2), by the delta method; the spectral radius's interval on the log
        scale (module docstring), so inside (0, inf). Intervals NaN below
        ``MIN_PAIRS_FOR_INTERVAL`` pairs."""
        z = ndtri(0.5 + confidence / 2.0)  # the normal quantile (scipy.stats.norm.ppf)
        values = _eigen_quantities(self.jacobian)
        grad = _numerical_gradient(_eigen_quantities, self.jacobian)  # (q, 4)
        var = np.einsum("qi,ij,qj->q", grad, self.cov_vec, grad)
        out = {}
        for name, value, v in zip(EIGEN_QUANTITIES, values, var):
            se = math.sqrt(max(v, 0.0))
            value = float(value)
            if not self.has_interval:
                low, high = math.nan, math.nan
            elif name == "spectral_radius":
                low, high = log_scale_interval(value, se, z)
            else:
                low, high = value - z * se, value + z * se
            out[name] = (value, se, low, high)
        return out


def radius_problem(value: float) -> str:
    """Why a spectral radius estimate is none, or '' when it is one.

    Parameters
    ----------
    value : float
        A spectral radius estimated from data (any estimator).

    Returns
    -------
    str
        ``not finite`` or ``<value> above 1.5 ...`` (``MAX_PLAUSIBLE_RADIUS``), or ''.
    """
    if not math.isfinite(value):
        return "the estimate is not finite"
    if value > MAX_PLAUSIBLE_RADIUS:
        return (f"the estimate {value:.4g} is above {MAX_PLAUSIBLE_RADIUS:g}, which a ball that "
                "kept bouncing cannot have")
    return ""


def log_scale_interval(value: float, se: float, z: float) -> tuple[float, float]:
    """Delta-method interval of a positive quantity on the log scale: value exp(-+ z se /
    value), inside (0, inf) for any se.

    Parameters
    ----------
    value : float
        The estimate (> 0; 0 or less gives (nan, nan)).
    se : float
        Its standard error (delta method, on the natural scale).
    z : float
        The normal quantile of the interval's level.

    Returns
    -------
    tuple of float
        (low, high).
    """
    if not value > 0.0:
        return math.nan, math.nan
    half = min(z * se / value, 700.0)  # exp(700) is still a float: a finite, huge interval
    return value * math.exp(-half), value * math.exp(half)


EIGEN_QUANTITIES = ("spectral_radius", "lambda_plus_re", "lambda_plus_im", "lambda_minus_re",
                    "lambda_minus_im")


def _eigen_quantities(jac: np.ndarray) -> np.ndarray:
    lp, lm = eigenvalues_2x2(jac)
    return np.array([max(abs(lp), abs(lm)), lp.real, lp.imag, lm.real, lm.imag])


def _numerical_gradient(f: Callable[[np.ndarray], np.ndarray], jac: np.ndarray,
                        step: float = 1e-6) -> np.ndarray:
    base = np.asarray(jac, float)
    cols = []
    for i in range(4):
        d = np.zeros(4)
        d[i] = step
        plus = f(base + d.reshape(2, 2))
        minus = f(base - d.reshape(2, 2))
        cols.append((plus - minus) / (2 * step))
    return np.stack(cols, axis=1)


# -- data handling ---------------------------------------------------------------------------
def demeaned(trials: Sequence[np.ndarray], width: int = 2, what: str = "(v, theta)"
             ) -> list[np.ndarray]:
    """Each trial (N_i, width) minus its own mean; trials must have no NaN."""
    out = []
    for i, y in enumerate(trials):
        y = np.asarray(y, float)
        if y.ndim != 2 or y.shape[1] != width:
            raise ModelError(f"trial {i}: expected an (N, {width}) array of {what}")
        if not np.all(np.isfinite(y)):
            raise ModelError(f"trial {i}: contains NaN or inf")
        out.append(y - y.mean(axis=0))
    return out


def _lagged_rows(trials: Sequence[np.ndarray], lags: int):
    """Stack (y_k, y_{k+1}, ..., y_{k+lags}) rows within each trial: list of (n, 2) arrays,
    index 0 the earliest; ``trial_of`` gives each row's trial."""
    parts: list[list[np.ndarray]] = [[] for _ in range(lags + 1)]
    trial_of = []
    for i, y in enumerate(trials):
        n = len(y) - lags
        if n <= 0:
            continue
        for lag in range(lags + 1):
            parts[lag].append(y[lag:lag + n])
        trial_of.append(np.full(n, i))
    if not trial_of:
        raise ModelError(f"no trial has more than {lags} bounces")
    return [np.concatenate(p) for p in parts], np.concatenate(trial_of)


def _prepared(trials: Sequence[np.ndarray], exog: Sequence[np.ndarray] | None, lags: int):
    """Demeaned y and, with inputs, the rows (u_{k+1}, u_k) beside y's lagged rows (``lags``
    as in :func:`_lagged_rows`; the last two of them are y_k and y_{k+1})."""
    y = demeaned(trials)
    rows, trial_of = _lagged_rows(y, lags)
    if exog is None:
        return y, rows, np.zeros((len(trial_of), 0)), trial_of
    if len(exog) != len(y) or any(len(u) != len(t) for u, t in zip(exog, y)):
        raise ModelError("the exogenous inputs must have one row per impact of each trial")
    width = np.asarray(exog[0]).shape[1] if np.ndim(exog[0]) == 2 else -1
    u = demeaned(exog, width, "inputs")
    spread = np.sqrt(np.mean(np.concatenate(u) ** 2, axis=0))
    scale = np.abs(np.concatenate([np.asarray(e, float) for e in exog])).max(axis=0)
    if np.any(spread <= 1e-9 * np.maximum(scale, 1e-300)):
        raise ModelError("an input does not vary within the trials: the VARX is not "
                         "identified (a steady racket: the VAR(1) needs no inputs)")
    u_rows, _ = _lagged_rows(u, lags)
    return y, rows, np.hstack([u_rows[-1], u_rows[-2]]), trial_of


def _fit(method: str, y, x, x_next, instruments, inputs, trial_of) -> Var1Fit:
    """The one linear solve of both estimators: x_next on [x, inputs] with instruments
    [instruments, inputs] (``instruments`` is x for OLS). Standard errors: OLS's Sigma (x)
    (X'X)^-1, the IV sandwich with lag-1 autocovariance within trials for lag2."""
    n, n_trials = len(x), len(y)
    regressors = np.hstack([x, inputs])
    z = np.hstack([instruments, inputs])
    p = regressors.shape[1]
    dof = n - p - n_trials  # p slopes per equation, and one mean per trial removed
    if dof < 2:
        what = "pairs" if method == "ols" else "triples"
        raise ModelError(f"too few bounces for the {'VAR(1)' if method == 'ols' else 'lag-2'}"
                         f" fit ({n} {what} in {n_trials} trials)")
    a = z.T @ regressors
    limit = 1e12 if method == "ols" else 1e10
    if np.linalg.cond(a) > limit:
        raise ModelError(
            "the data's v and theta are (nearly) collinear: J is not identified"
            if method == "ols" else
            "the lag-1 covariance C(1) is (nearly) singular: the lag-2 estimate of J is not "
            "identified (too few bounces, or no serial correlation)")
    strength = 1.0 if method == "ols" else instrument_strength(z, regressors, a)
    b = np.linalg.solve(a, z.T @ x_next)  # b = [J, B]^T
    resid = x_next - regressors @ b
    sigma = resid.T @ resid / dof
    a_inv = np.linalg.inv(a)
    if method == "ols":
        cov = np.kron(sigma, a_inv)
    else:
        # S = Var(sum_k u_k (x) z_k): lag-0 and lag-1 autocovariances, within trials only
        g = (resid[:, :, None] * z[:, None, :]).reshape(n, 2 * p)
        s = g.T @ g
        same = trial_of[1:] == trial_of[:-1]
        g1 = g[1:][same].T @ g[:-1][same]
        s = s + g1 + g1.T
        bread = np.kron(np.eye(2), a_inv)
        cov = bread @ s @ bread.T
        w, v = np.linalg.eigh((cov + cov.T) / 2)
        cov = (v * np.clip(w, 0.0, None)) @ v.T
    j_index = [0, 1, p, p + 1]
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None)).reshape(2, p)
    per_trial = tuple(resid[trial_of == i] for i in range(n_trials))
    return Var1Fit(method, b[:2].T, cov[np.ix_(j_index, j_index)], sigma, n, n_trials,
                   exog_coef=b[2:].T, exog_se=se[:, 2:], residuals=per_trial,
                   instrument_det=strength)


def instrument_strength(z: np.ndarray, x: np.ndarray, a: np.ndarray | None = None) -> float:
    """|det Z'X| / sqrt(det Z'Z det X'X): the product of the canonical correlations of the
    instruments ``z`` and the regressors ``x`` (same shape), in [0, 1]; scale-free, so that
    "near zero" means the same at any units and sample size.

    Parameters
    ----------
    z, x : (n, p) arrays
        Instruments and regressors.
    a : (p, p) array, optional
        ``z.T @ x``, if already computed.

    Returns
    -------
    float
        0 where Z'X is singular.
    """
    sign, log_a = np.linalg.slogdet(z.T @ x if a is None else a)
    sign_z, log_z = np.linalg.slogdet(z.T @ z)
    sign_x, log_x = np.linalg.slogdet(x.T @ x)
    if sign == 0 or sign_z <= 0 or sign_x <= 0:
        return 0.0
    return float(min(1.0, math.exp(log_a - 0.5 * (log_z + log_x))))


# -- estimators ------------------------------------------------------------------------------
def fit_var1_ols(trials: Sequence[np.ndarray],
                 exog: Sequence[np.ndarray] | None = None) -> Var1Fit:
    """OLS of y_{k+1} on y_k (and, given ``exog``, on u_{k+1} and u_k: a VARX) pooled over
    trials, each trial's mean removed. See the module docstring for the standard errors.

    Parameters
    ----------
    trials : sequence of (N_i, 2) arrays
        (v, theta) of each trial's consecutive impacts.
    exog : sequence of (N_i, m) arrays, optional
        Exogenous inputs of the same impacts (e.g. racket period and amplitude).

    Returns
    -------
    Var1Fit
        J, Cov(vec J), the residual covariance and, with ``exog``, the inputs' coefficients.
    """
    y, (x, x_next), inputs, trial_of = _prepared(trials, exog, 1)
    return _fit("ols", y, x, x_next, x, inputs, trial_of)


def fit_var1_lag2(trials: Sequence[np.ndarray],
                  exog: Sequence[np.ndarray] | None = None) -> Var1Fit:
    """J = C(2) C(1)^-1 pooled over trials: instrument y_{k-1} for y_k (module docstring);
    ``exog`` as in :func:`fit_var1_ols` (the inputs instrument themselves).

    Parameters
    ----------
    trials : sequence of (N_i, 2) arrays
        (v, theta) of each trial's consecutive impacts.
    exog : sequence of (N_i, m) arrays, optional
        Exogenous inputs of the same impacts.

    Returns
    -------
    Var1Fit
        As :func:`fit_var1_ols`, with the IV sandwich covariance.
    """
    y, (z, x, x_next), inputs, trial_of = _prepared(trials, exog, 2)
    return _fit("lag2", y, x, x_next, z, inputs, trial_of)


Fitter = Callable[..., Var1Fit]
FITTERS: dict[str, Fitter] = {"ols": fit_var1_ols, "lag2": fit_var1_lag2}


def split_jackknife(fitter: Fitter, trials: Sequence[np.ndarray],
                    exog: Sequence[np.ndarray] | None = None) -> Var1Fit:
    """Half-panel jackknife (Dhaene & Jochmans 2015) against the O(1/N_i) bias of removing
    each trial's mean: J = 2 J(all) - (J(first halves) + J(second halves)) / 2 (the inputs'
    coefficients likewise). The covariance is the full-data fit's (the correction changes J
    at order 1/N, its variance at higher order)."""
    def halves(arrays, first: bool):
        if arrays is None:
            return None
        return [np.asarray(a)[: len(a) // 2] if first else np.asarray(a)[len(a) // 2:]
                for a in arrays]

    full = fitter(trials, exog)
    first = fitter(halves(trials, True), halves(exog, True))
    second = fitter(halves(trials, False), halves(exog, False))
    jac = 2.0 * full.jacobian - 0.5 * (first.jacobian + second.jacobian)
    coef = 2.0 * full.exog_coef - 0.5 * (first.exog_coef + second.exog_coef)
    return Var1Fit(full.method + "+jackknife", jac, full.cov_vec, full.noise_cov,
                   full.n_pairs, full.n_trials, exog_coef=coef, exog_se=full.exog_se,
                   residuals=full.residuals,
                   instrument_det=min(full.instrument_det, first.instrument_det,
                                      second.instrument_det))


def fit_var1(trials: Sequence[np.ndarray], method: str = "ols", jackknife: bool = True,
             exog: Sequence[np.ndarray] | None = None) -> Var1Fit:
    """Fit J by ``method`` ("ols" or "lag2"), with the split-panel jackknife when asked, and
    with exogenous inputs ``exog`` (a VARX) when given."""
    if method not in FITTERS:
        raise ModelError(f"unknown VAR(1) estimator {method!r} (one of {', '.join(FITTERS)})")
    fitter = FITTERS[method]
    if jackknife:
        short = min(len(y) for y in trials)
        if short < 8:
            raise ModelError(f"a trial has only {short} bounces: the split-panel jackknife "
                             "needs at least 8 per trial (4 per half)")
        return split_jackknife(fitter, trials, exog)
    return fitter(trials, exog)


def jacobian_coverage(fit: Var1Fit, truth: np.ndarray, confidence: float = 0.95) -> np.ndarray:
    """Per entry of J: is the true value inside estimate +- z SE? (shape (2, 2), bool)."""
    z = ndtri(0.5 + confidence / 2.0)  # the normal quantile (scipy.stats.norm.ppf)
    return np.abs(fit.jacobian - truth) <= z * fit.jacobian_se


# -- residual diagnostics ------------------------------------------------------------------
@dataclass(frozen=True)
class LjungBox:
    """The Ljung-Box test of one residual component, pooled over trials."""

    component: str  # "v" or "theta"
    lags: int
    statistic: float  # sum over trials of each trial's Q(lags)
    df: int  # n_trials * lags - the fitted slopes of the equation
    p_value: float


def ljung_box_q(x: np.ndarray, lags: int) -> float:
    """The Ljung-Box statistic Q = n (n + 2) sum_{k=1..lags} r_k^2 / (n - k) of a series, r_k
    its sample autocorrelations (mean removed, each lag's sum divided by the lag-0 sum):
    statsmodels' ``acorr_ljungbox(x, lags=[lags])["lb_stat"]`` (the tests hold the two to
    1e-12), without statsmodels' import (half a second in every process of a study) or its
    table per call.

    Parameters
    ----------
    x : (n,) array
        The series (one trial's residuals of one component).
    lags : int
        The largest lag entering Q (< n).

    Returns
    -------
    float
    """
    x = np.asarray(x, float)
    n = len(x)
    centred = x - x.mean()
    denominator = float(centred @ centred)
    ks = np.arange(1, lags + 1)
    r = np.array([centred[:n - k] @ centred[k:] for k in ks]) / denominator
    return float(n * (n + 2) * np.sum(r * r / (n - ks)))


def ljung_box(fit: Var1Fit, lags: int) -> list[LjungBox]:
    """Whiteness of the residuals of ``fit``, per component (v, theta): the Ljung-Box Q
    (:func:`ljung_box_q`) of each trial's own residuals (never a lag across a trial
    boundary), the trials' Q statistics summed (independent trials: chi^2 with the summed
    degrees of freedom), minus the equation's fitted slopes once (they are pooled over
    trials).

    Parameters
    ----------
    fit : Var1Fit
        A fit with per-trial residuals (``fit_var1`` and the estimators keep them).
    lags : int
        Autocorrelations 1..lags enter Q; trials with fewer than lags + 2 residuals are left
        out.

    Returns
    -------
    list of LjungBox
        One per component.
    """
    from scipy.special import chdtrc

    slopes = 2 + fit.exog_coef.shape[1]
    out = []
    for index, component in enumerate(("v", "theta")):
        total, used = 0.0, 0
        for resid in fit.residuals:
            if len(resid) < lags + 2:
                continue
            total += ljung_box_q(resid[:, index], lags)
            used += 1
        df = used * lags - slopes
        p_value = float(chdtrc(df, total)) if used and df > 0 else math.nan  # chi^2's sf
        out.append(LjungBox(component, lags, total if used else math.nan, max(df, 0), p_value))
    return out


@dataclass(frozen=True)
class LagOrder:
    """Information criteria of a VAR(p) fitted by OLS on the same impacts for every p."""

    order: int
    aic: float
    bic: float
    n_rows: int


#: impacts per coefficient of an equation a VAR(p) beyond p = 1 needs to enter the lag-order
#: comparison (a review's 15 impacts "preferred" a VAR(5): 10 slopes an equation)
ROWS_PER_COEFFICIENT = 10


def lag_order_criteria(trials: Sequence[np.ndarray], max_order: int) -> list[LagOrder]:
    """AIC and BIC of VAR(p), p = 1..max_order, fitted by least squares pooled over trials
    (each trial's mean removed, no lag across a trial boundary; statsmodels' VAR knows no
    trial boundaries): ln det Sigma_p + 2 K^2 p / T and ln det Sigma_p + ln(T) K^2 p / T with
    K = 2, Sigma_p the maximum-likelihood residual covariance and T the rows used, the same
    rows for every p (each trial from its impact max_order on). Orders beyond 1 are compared
    while the rows number at least ``ROWS_PER_COEFFICIENT`` per coefficient of an equation.

    Parameters
    ----------
    trials : sequence of (N_i, 2) arrays
        (v, theta) of each trial's consecutive impacts.
    max_order : int
        The largest lag order compared (>= 1).

    Returns
    -------
    list of LagOrder
        One per order, 1..max_order.
    """
    y = demeaned(trials)
    parts, _ = _lagged_rows(y, max_order)  # parts[max_order] is the target y_{k+max_order}
    target = parts[max_order]
    n = len(target)
    out = []
    for order in range(1, max_order + 1):
        x = np.hstack([parts[max_order - lag] for lag in range(1, order + 1)])
        if n <= x.shape[1] + len(y) or (order > 1 and n < ROWS_PER_COEFFICIENT * x.shape[1]):
            break
        coef, *_ = np.linalg.lstsq(x, target, rcond=None)
        resid = target - x @ coef
        sign, logdet = np.linalg.slogdet(resid.T @ resid / n)
        if sign <= 0:
            break
        k2p = 4 * order
        out.append(LagOrder(order, logdet + 2.0 * k2p / n, logdet + math.log(n) * k2p / n, n))
    return out

