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
four entries of J, times Cov(vec J). Intervals are estimate +- z SE (normal).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy import stats

from .params import ModelError

#: the entries of J in the order of vec(J) (row-major): (v, theta) as in eq. 9
J_ENTRIES = ("J_vv", "J_vtheta", "J_thetav", "J_thetatheta")
ESTIMATORS = ("ols", "lag2")


@dataclass(frozen=True)
class Var1Fit:
    """A fitted J with its covariance and what follows from it."""

    method: str  # "ols" | "lag2", with "+jackknife" when split_jackknife was applied
    jacobian: np.ndarray  # (2, 2)
    cov_vec: np.ndarray  # (4, 4) covariance of vec(J) (row-major: J_ENTRIES)
    noise_cov: np.ndarray  # (2, 2) residual covariance (for lag2: of the MA(1) residual)
    n_pairs: int  # (y_k, y_{k+1}) pairs used
    n_trials: int

    @property
    def jacobian_se(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov_vec), 0.0, None)).reshape(2, 2)

    def eigen_summary(
        self, confidence: float = 0.95
    ) -> dict[str, tuple[float, float, float, float]]:
        """quantity -> (estimate, SE, CI low, CI high) for the spectral radius and the real and
        imaginary parts of lambda_+ and lambda_- (eq. 10's labels: lambda_+- = c +- sqrt(c^2 -
        det J), c = tr J / 2), by the delta method."""
        z = stats.norm.ppf(0.5 + confidence / 2.0)
        values = _eigen_quantities(self.jacobian)
        grad = _numerical_gradient(_eigen_quantities, self.jacobian)  # (q, 4)
        var = np.einsum("qi,ij,qj->q", grad, self.cov_vec, grad)
        out = {}
        for name, value, v in zip(EIGEN_QUANTITIES, values, var):
            se = math.sqrt(max(v, 0.0))
            out[name] = (float(value), se, float(value) - z * se, float(value) + z * se)
        return out


EIGEN_QUANTITIES = ("spectral_radius", "lambda_plus_re", "lambda_plus_im", "lambda_minus_re",
                    "lambda_minus_im")


def eigenvalues_2x2(jac: np.ndarray) -> tuple[complex, complex]:
    """(lambda_+, lambda_-) = c +- sqrt(c^2 - det J), c = tr J / 2 (eq. 10 for eq. 9's J,
    where det J = alpha^2)."""
    c = 0.5 * (jac[0, 0] + jac[1, 1])
    det = jac[0, 0] * jac[1, 1] - jac[0, 1] * jac[1, 0]
    disc = c * c - det
    root = math.sqrt(disc) if disc >= 0 else 1j * math.sqrt(-disc)
    return complex(c + root), complex(c - root)


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
def demeaned(trials: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Each trial (N_i, 2) minus its own mean; trials must have no NaN."""
    out = []
    for i, y in enumerate(trials):
        y = np.asarray(y, float)
        if y.ndim != 2 or y.shape[1] != 2:
            raise ModelError(f"trial {i}: expected an (N, 2) array of (v, theta)")
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


# -- estimators ------------------------------------------------------------------------------
def fit_var1_ols(trials: Sequence[np.ndarray]) -> Var1Fit:
    """OLS of y_{k+1} on y_k pooled over trials (each trial's mean removed). See the module
    docstring for the standard errors."""
    y = demeaned(trials)
    (x, x_next), _ = _lagged_rows(y, 1)
    n = len(x)
    dof = n - 2 - len(y)  # 2 slopes per equation, and one mean per trial removed
    if dof < 2:
        raise ModelError(f"too few bounces for a VAR(1) fit ({n} pairs in {len(y)} trials)")
    xtx = x.T @ x
    if np.linalg.cond(xtx) > 1e12:
        raise ModelError("the data's v and theta are (nearly) collinear: J is not identified")
    b = np.linalg.solve(xtx, x.T @ x_next)  # b = J^T
    resid = x_next - x @ b
    sigma = resid.T @ resid / dof
    cov = np.kron(sigma, np.linalg.inv(xtx))
    return Var1Fit("ols", b.T, cov, sigma, n, len(y))


def fit_var1_lag2(trials: Sequence[np.ndarray]) -> Var1Fit:
    """J = C(2) C(1)^-1 pooled over trials: instrument y_{k-1} for y_k (module docstring)."""
    y = demeaned(trials)
    (z, x, x_next), trial_of = _lagged_rows(y, 2)
    n = len(z)
    if n - 2 - len(y) < 2:
        raise ModelError(f"too few bounces for the lag-2 estimate ({n} triples in {len(y)} trials)")
    a = z.T @ x  # = C(1)^T
    if np.linalg.cond(a) > 1e10:
        raise ModelError("the lag-1 covariance C(1) is (nearly) singular: the lag-2 estimate "
                         "of J is not identified (too few bounces, or no serial correlation)")
    b = np.linalg.solve(a, z.T @ x_next)  # b = J^T
    resid = x_next - x @ b
    sigma = resid.T @ resid / (n - 2 - len(y))
    a_inv = np.linalg.inv(a)
    # S = Var(sum_k u_k (x) z_k): lag-0 and lag-1 autocovariances, within trials only
    g = (resid[:, :, None] * z[:, None, :]).reshape(n, 4)
    s = g.T @ g
    same = trial_of[1:] == trial_of[:-1]
    g1 = g[1:][same].T @ g[:-1][same]
    s = s + g1 + g1.T
    bread = np.kron(np.eye(2), a_inv)
    cov = bread @ s @ bread.T
    w, v = np.linalg.eigh((cov + cov.T) / 2)
    cov = (v * np.clip(w, 0.0, None)) @ v.T
    return Var1Fit("lag2", b.T, cov, sigma, n, len(y))


FITTERS: dict[str, Callable[[Sequence[np.ndarray]], Var1Fit]] = {
    "ols": fit_var1_ols, "lag2": fit_var1_lag2,
}


def split_jackknife(fitter: Callable[[Sequence[np.ndarray]], Var1Fit],
                    trials: Sequence[np.ndarray]) -> Var1Fit:
    """Half-panel jackknife (Dhaene & Jochmans 2015) against the O(1/N_i) bias of removing
    each trial's mean: J = 2 J(all) - (J(first halves) + J(second halves)) / 2. The covariance
    is the full-data fit's (the correction changes J at order 1/N, its variance at higher
    order)."""
    full = fitter(trials)
    first = fitter([np.asarray(y)[: len(y) // 2] for y in trials])
    second = fitter([np.asarray(y)[len(y) // 2:] for y in trials])
    jac = 2.0 * full.jacobian - 0.5 * (first.jacobian + second.jacobian)
    return Var1Fit(full.method + "+jackknife", jac, full.cov_vec, full.noise_cov,
                   full.n_pairs, full.n_trials)


def fit_var1(trials: Sequence[np.ndarray], method: str = "ols",
             jackknife: bool = True) -> Var1Fit:
    """Fit J by ``method`` ("ols" or "lag2"), with the split-panel jackknife when asked."""
    if method not in FITTERS:
        raise ModelError(f"unknown VAR(1) estimator {method!r} (one of {', '.join(FITTERS)})")
    fitter = FITTERS[method]
    if jackknife:
        short = min(len(y) for y in trials)
        if short < 8:
            raise ModelError(f"a trial has only {short} bounces: the split-panel jackknife "
                             "needs at least 8 per trial (4 per half)")
        return split_jackknife(fitter, trials)
    return fitter(trials)


def jacobian_coverage(fit: Var1Fit, truth: np.ndarray, confidence: float = 0.95) -> np.ndarray:
    """Per entry of J: is the true value inside estimate +- z SE? (shape (2, 2), bool)."""
    z = stats.norm.ppf(0.5 + confidence / 2.0)
    return np.abs(fit.jacobian - truth) <= z * fit.jacobian_se
