"""The VAR(1) fits of :mod:`bounce_cli.analysis.var_fit` on many data sets at once.

A trust study (``experiments.data_side.trust_frame``) fits hundreds of simulated data sets of
the same trial structure; fitted one by one, the Python overhead of each small fit is most of
the time. :func:`stacked_fit` fits R panels (R data sets of the same trial lengths, each the
trials one after the other) in one stacked solve: the same estimator as ``var_fit.fit_var1``
(each trial's mean removed, no pair across a trial boundary, OLS or lag 2, the split-panel
jackknife, inputs), the normal equations of all R panels formed by batched matrix products
and solved by one batched ``np.linalg.solve``; it agrees with ``fit_var1`` to rounding
(``tests/engine/test_data_var_stacked.py``). :func:`simulate_panels` draws such panels from
eq. 19, each trial started in the stationary distribution.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..model.linear import spectral_radii_2x2
from ..model.params import ModelError
from .var_fit import (
    MAX_PLAUSIBLE_RADIUS,
    MIN_INSTRUMENT_DET,
)

#: the condition numbers above which a fit is not identified (as ``var_fit._fit``)
CONDITION_LIMIT = {"ols": 1e12, "lag2": 1e10}


@dataclass(frozen=True)
class Segments:
    """Where the trials (or half-trials) lie in a panel's rows: ``starts`` and ``lengths``."""

    starts: tuple[int, ...]
    lengths: tuple[int, ...]

    def halves(self) -> tuple[Segments, Segments]:
        """The first and second half of each segment (``var_fit.split_jackknife``'s split:
        the first len // 2 rows, then the rest)."""
        first = Segments(self.starts, tuple(n // 2 for n in self.lengths))
        second = Segments(tuple(s + n // 2 for s, n in zip(self.starts, self.lengths)),
                          tuple(n - n // 2 for n in self.lengths))
        return first, second


def whole_trials(lengths: Sequence[int]) -> Segments:
    """The segments of a panel made of trials of ``lengths`` one after the other."""
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(int)
    return Segments(tuple(int(s) for s in starts), tuple(int(n) for n in lengths))


@dataclass(frozen=True)
class StackedFit:
    """One estimator fitted to R panels at once.

    Attributes
    ----------
    jacobian : (R, 2, 2) array
        The estimates of J (jackknifed where asked).
    cov_vec : (R, 4, 4) array
        Cov(vec J) of each fit (row-major, as ``Var1Fit.cov_vec``; the full data's).
    identified : (R,) bool array
        False where ``fit_var1`` raises (Z'X nearly singular in the full or a half fit).
    valid : (R,) bool array
        ``identified`` and not withheld on data (``Var1Fit.radius_problem``: a lag-2
        instrument too weak, a radius not finite or above 1.5).
    """

    jacobian: np.ndarray
    cov_vec: np.ndarray
    identified: np.ndarray
    valid: np.ndarray


def _cross(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The cross-products left_r' right_r of each of R stacked (R, n, i) and (R, n, j)
    arrays, (R, i, j): a batched matrix product (BLAS), about ten times einsum's loop."""
    return left.transpose(0, 2, 1) @ right


def _demeaned(panels: np.ndarray, segments: Segments) -> np.ndarray:
    """(R, T, w) panels with each segment's mean removed (rows outside a segment: 0)."""
    out = np.zeros_like(panels)
    for start, n in zip(segments.starts, segments.lengths):
        part = panels[:, start:start + n]
        out[:, start:start + n] = part - part.mean(axis=1, keepdims=True)
    return out


def _rows(segments: Segments, lags: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Row indices of (y_k, ..., y_{k+lags}) within each segment and each row's segment."""
    parts: list[list[np.ndarray]] = [[] for _ in range(lags + 1)]
    segment_of = []
    for i, (start, n) in enumerate(zip(segments.starts, segments.lengths)):
        m = n - lags
        if m <= 0:
            continue
        for lag in range(lags + 1):
            parts[lag].append(start + lag + np.arange(m))
        segment_of.append(np.full(m, i))
    if not segment_of:
        raise ModelError(f"no trial has more than {lags} bounces")
    return [np.concatenate(p) for p in parts], np.concatenate(segment_of)


def _solve_segments(method: str, panels: np.ndarray, inputs: np.ndarray | None,
                    segments: Segments, with_cov: bool = True
                    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    """``var_fit._fit`` on R panels at once: J (R, 2, 2), Cov(vec J) (R, 4, 4; None unless
    ``with_cov``: a jackknife's half fits need J alone), identified (R,) and valid (R,:
    identified with a strong enough lag-2 instrument)."""
    lags = 1 if method == "ols" else 2
    y = _demeaned(panels, segments)
    index, segment_of = _rows(segments, lags)
    x, x_next = y[:, index[-2]], y[:, index[-1]]
    instruments = x if method == "ols" else y[:, index[0]]
    r, n = x.shape[0], x.shape[1]
    if inputs is not None:  # (T, m): the same for every panel, or (R, T, m): each its own
        u = _demeaned(inputs if inputs.ndim == 3 else inputs[None], segments)
        u_rows = np.concatenate([u[:, index[-1]], u[:, index[-2]]], axis=2)
        stacked = np.broadcast_to(u_rows, (r,) + u_rows.shape[1:])
        regressors = np.concatenate([x, stacked], axis=2)
        z = np.concatenate([instruments, stacked], axis=2)
    else:
        regressors, z = x, instruments
    p = regressors.shape[2]
    dof = n - p - len(segments.lengths)
    if dof < 2:
        what = "pairs" if method == "ols" else "triples"
        raise ModelError(f"too few bounces for the {'VAR(1)' if method == 'ols' else 'lag-2'}"
                         f" fit ({n} {what} in {len(segments.lengths)} trials)")
    a = _cross(z, regressors)
    identified = np.linalg.cond(a) <= CONDITION_LIMIT[method]
    valid = identified.copy()
    if method == "lag2":
        sign, log_a = np.linalg.slogdet(a)
        sign_z, log_z = np.linalg.slogdet(_cross(z, z))
        sign_x, log_x = np.linalg.slogdet(_cross(regressors, regressors))
        ok = (sign != 0) & (sign_z > 0) & (sign_x > 0)
        with np.errstate(over="ignore", invalid="ignore"):
            strength = np.where(ok, np.minimum(1.0, np.exp(log_a - 0.5 * (log_z + log_x))),
                                0.0)
        valid &= strength >= MIN_INSTRUMENT_DET
    a = np.where(identified[:, None, None], a, np.eye(p))  # a failed fit solves something harmless
    b = np.linalg.solve(a, _cross(z, x_next))  # (R, p, 2) = [J, B]^T
    if not with_cov:
        return b[:, :2, :].transpose(0, 2, 1), None, identified, valid
    resid = x_next - regressors @ b
    a_inv = np.linalg.inv(a)
    if method == "ols":
        sigma = _cross(resid, resid) / dof
        cov = sigma[:, :, None, :, None] * a_inv[:, None, :2, None, :2]
        cov = cov.reshape(r, 4, 4)
    else:
        g = (resid[:, :, :, None] * z[:, :, None, :]).reshape(r, n, 2 * p)
        s = _cross(g, g)
        same = segment_of[1:] == segment_of[:-1]
        g1 = _cross(g[:, 1:][:, same], g[:, :-1][:, same])
        s = s + g1 + g1.transpose(0, 2, 1)
        bread = np.zeros((r, 2 * p, 2 * p))
        bread[:, :p, :p] = a_inv
        bread[:, p:, p:] = a_inv
        full = bread @ s @ bread.transpose(0, 2, 1)
        w, v = np.linalg.eigh((full + full.transpose(0, 2, 1)) / 2)
        full = (v * np.clip(w, 0.0, None)[:, None, :]) @ v.transpose(0, 2, 1)
        j_index = [0, 1, p, p + 1]
        cov = full[:, j_index][:, :, j_index]
    return b[:, :2, :].transpose(0, 2, 1), cov, identified, valid


def stacked_fit(panels: np.ndarray, lengths: Sequence[int], method: str,
                jackknife: bool, inputs: np.ndarray | None = None) -> StackedFit:
    """``var_fit.fit_var1`` on R panels of the same trial structure, in one stacked solve.

    Parameters
    ----------
    panels : (R, T, 2) array
        R data sets of (v, theta), each the trials of ``lengths`` one after the other.
    lengths : sequence of int
        The trials' numbers of impacts (sum T).
    method : {"ols", "lag2"}
        The estimator (``var_fit`` module docstring).
    jackknife : bool
        The split-panel jackknife (``var_fit.split_jackknife``).
    inputs : (T, m) or (R, T, m) array, optional
        Exogenous inputs (a VARX): the same for every panel, or each panel's own.

    Returns
    -------
    StackedFit
        J, Cov(vec J) and validity of each panel's fit, as ``fit_var1`` gives them to
        rounding (``tests/engine/test_data_var_stacked.py``).
    """
    if method not in CONDITION_LIMIT:
        raise ModelError(f"unknown VAR(1) estimator {method!r}")
    panels = np.asarray(panels, float)
    if inputs is not None:
        inputs = np.asarray(inputs, float)
    whole = whole_trials(lengths)
    jac, cov, identified, valid = _solve_segments(method, panels, inputs, whole)
    assert cov is not None
    if jackknife:
        if min(lengths) < 8:
            raise ModelError(f"a trial has only {min(lengths)} bounces: the split-panel "
                             "jackknife needs at least 8 per trial (4 per half)")
        first, second = whole.halves()
        j1, _, id1, ok1 = _solve_segments(method, panels, inputs, first, with_cov=False)
        j2, _, id2, ok2 = _solve_segments(method, panels, inputs, second, with_cov=False)
        identified = identified & id1 & id2
        jac = 2.0 * jac - 0.5 * (j1 + j2)
        valid = valid & ok1 & ok2
    radius = spectral_radii_2x2(jac)
    valid = valid & np.isfinite(radius) & (radius <= MAX_PLAUSIBLE_RADIUS)
    return StackedFit(jac, cov, identified, valid & identified)


def log_radius_se(jac: np.ndarray, cov_vec: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """SE(log r) = SE(r) / r of each fit by the delta method (``Var1Fit.eigen_summary``'s
    central-difference gradient with respect to vec J)."""
    grad = np.empty(jac.shape[:-2] + (4,))
    for i in range(4):
        d = np.zeros(4)
        d[i] = step
        grad[..., i] = (spectral_radii_2x2(jac + d.reshape(2, 2))
                        - spectral_radii_2x2(jac - d.reshape(2, 2))) / (2 * step)
    var = np.einsum("...i,...ij,...j->...", grad, cov_vec, grad)
    return np.sqrt(np.clip(var, 0.0, None)) / spectral_radii_2x2(jac)


def simulate_panels(jac: np.ndarray, noise_cov: np.ndarray, lengths: Sequence[int],
                    replicates: int, rng: np.random.Generator,
                    inputs: np.ndarray | None = None,
                    input_coef: np.ndarray | None = None,
                    measurement_sd: np.ndarray | None = None) -> np.ndarray:
    """R panels of eq. 19 (with inputs: y_{k+1} = J y_k + B_next u_{k+1} + B_this u_k +
    eps_k), each trial started in (J, Sigma)'s stationary distribution, observed with white
    measurement noise of SDs ``measurement_sd`` where given.

    Parameters
    ----------
    jac : (2, 2) array
        J, spectral radius below 1.
    noise_cov : (2, 2) array
        Sigma, the covariance of eps_k.
    lengths : sequence of int
        The trials' numbers of impacts.
    replicates : int
        R.
    rng : numpy.random.Generator
        The draws.
    inputs : (T, m) array, optional
        The inputs u_k of all trials one after the other (each trial's mean removed here).
    input_coef : (2, 2 m) array, optional
        [B_next, B_this] (``Var1Fit.exog_coef``).
    measurement_sd : (2,) array, optional
        SDs of white noise added to the observed (v, theta) (not to the state).

    Returns
    -------
    (R, T, 2) array
    """
    from .stochastic import stationary_covariance

    chol = np.linalg.cholesky(_positive(noise_cov))
    start = np.linalg.cholesky(_positive(stationary_covariance(jac, noise_cov)))
    segments = whole_trials(lengths)
    u = None if inputs is None else _demeaned(np.asarray(inputs, float)[None], segments)[0]
    out = np.empty((replicates, sum(lengths), 2))
    for first, n in zip(segments.starts, segments.lengths):
        y = rng.standard_normal((replicates, 2)) @ start.T
        out[:, first] = y
        for k in range(first, first + n - 1):
            y = y @ jac.T + rng.standard_normal((replicates, 2)) @ chol.T
            if u is not None and input_coef is not None:
                y = y + input_coef @ np.concatenate([u[k + 1], u[k]])
            out[:, k + 1] = y
    if measurement_sd is not None:
        out += rng.standard_normal(out.shape) * np.asarray(measurement_sd, float)
    return out


def _positive(cov: np.ndarray) -> np.ndarray:
    """A covariance made safely positive definite for its Cholesky factor."""
    cov = (np.asarray(cov, float) + np.asarray(cov, float).T) / 2
    scale = max(float(np.trace(cov)), 1e-300)
    return cov + 1e-12 * scale * np.eye(len(cov))
