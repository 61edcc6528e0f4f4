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


def _range_sums(values: np.ndarray, starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """Sums of ``values`` (..., T + 1; its last entry zero, so that a range may end at T)
    over the entries [start, stop) of each range (start < stop): (..., ranges), by one
    ``np.add.reduceat`` over the interleaved bounds."""
    bounds = np.empty(2 * len(starts), dtype=np.intp)
    bounds[0::2], bounds[1::2] = starts, stops
    return np.add.reduceat(values, bounds, axis=-1)[..., 0::2]


def _demeaned(panels: np.ndarray, segments: Segments) -> np.ndarray:
    """(R, T, w) panels with each segment's mean removed (rows outside a segment: 0)."""
    out = np.zeros_like(panels)
    for start, n in zip(segments.starts, segments.lengths):
        part = panels[:, start:start + n]
        out[:, start:start + n] = part - part.mean(axis=1, keepdims=True)
    return out


def _lag_layout(method: str, width: int) -> tuple[int, list[int], list[int], list[int]]:
    """The lags of ``method`` and where its instruments, regressors and target lie in the
    stacked row s_k = (w_k, ..., w_{k+lags}) of w = (v, theta, inputs...) of ``width``:
    OLS regresses y_{k+1} on (y_k, u_{k+1}, u_k); lag 2 regresses y_{k+2} on (y_{k+1},
    u_{k+2}, u_{k+1}) with instruments (y_k, u_{k+2}, u_{k+1}) (``var_fit._prepared``)."""
    y, u = [0, 1], list(range(2, width))

    def at(lag: int, columns: list[int]) -> list[int]:
        return [lag * width + c for c in columns]

    if method == "ols":
        regressors = at(0, y) + at(1, u) + at(0, u)
        return 1, regressors, regressors, at(1, y)
    return 2, at(0, y) + at(2, u) + at(1, u), at(1, y) + at(2, u) + at(1, u), at(2, y)


@dataclass(frozen=True)
class _Moments:
    """A stack of R panels as the fits read it: w = (v, theta, inputs...) with each whole
    trial's mean removed, its series along the last axis (R, w, T), and its lagged products
    w_k w_{k+l}' (R, w, w, T - l); each padded with a zero entry for :func:`_range_sums`."""

    centred: np.ndarray  # (R, w, T + 1)
    products: list[np.ndarray]  # lag l: (R, w, w, T - l + 1)

    @classmethod
    def of(cls, panels: np.ndarray, inputs: np.ndarray | None, whole: Segments,
           lags: int) -> _Moments:
        r, t = panels.shape[:2]
        if inputs is not None:  # (T, m): the same for every panel, or (R, T, m): each its own
            u = inputs if inputs.ndim == 3 else inputs[None]
            panels = np.concatenate([panels, np.broadcast_to(u, (r,) + u.shape[1:])], axis=2)
        width = panels.shape[2]
        centred = np.zeros((r, width, t + 1))
        centred[:, :, :t] = panels.transpose(0, 2, 1)
        starts = np.asarray(whole.starts, dtype=np.intp)
        lengths = np.asarray(whole.lengths, dtype=np.intp)
        means = _range_sums(centred, starts, starts + lengths) / lengths  # (R, w, trials)
        centred[:, :, :t] -= np.repeat(means, lengths, axis=-1)
        products = []
        for lag in range(lags + 1):
            out = np.zeros((r, width, width, t - lag + 1))
            np.multiply(centred[:, :, None, :t - lag], centred[:, None, :, lag:t],
                        out=out[..., :-1])
            products.append(out)
        return cls(centred, products)

    def gram(self, segments: Segments, lags: int) -> tuple[np.ndarray, int]:
        """The Gram matrix sum_k (s_k - m)(s_k - m)' of the stacked rows s_k = (w_k, ...,
        w_{k+lags}) over k in [start, start + n - lags) of each segment, m the segment's own
        mean (over its n rows), summed over segments: (R, (lags + 1) w, (lags + 1) w), and
        the number of rows. Each block is a sum of lagged products over a range (one
        reduceat) less the segment mean's share: the halves of a split-panel jackknife
        downdate the whole data's products instead of refitting."""
        kept = [(s, n) for s, n in zip(segments.starts, segments.lengths) if n - lags > 0]
        if not kept:
            raise ModelError(f"no trial has more than {lags} bounces")
        starts = np.array([s for s, _ in kept], dtype=np.intp)
        lengths = np.array([n for _, n in kept], dtype=np.intp)
        count = lengths - lags  # rows k of each segment
        r, width = self.centred.shape[:2]
        mean = _range_sums(self.centred, starts, starts + lengths) / lengths  # (R, w, segs)
        first = [_range_sums(self.centred, starts + i, starts + i + count)
                 for i in range(lags + 1)]
        size = (lags + 1) * width
        gram = np.empty((r, size, size))
        for lag in range(lags + 1):
            for i in range(lags + 1 - lag):
                j = i + lag
                raw = _range_sums(self.products[lag], starts + i, starts + i + count)
                block = (raw - first[i][:, :, None] * mean[:, None, :, :]
                         - mean[:, :, None] * first[j][:, None, :, :]
                         + count * mean[:, :, None] * mean[:, None, :, :]).sum(axis=-1)
                gram[:, i * width:(i + 1) * width, j * width:(j + 1) * width] = block
                if lag:
                    gram[:, j * width:(j + 1) * width, i * width:(i + 1) * width] = \
                        block.transpose(0, 2, 1)
        return gram, int(count.sum())


def _solve_segments(method: str, moments: _Moments, segments: Segments, with_cov: bool = True
                    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    """``var_fit._fit`` on R panels at once: J (R, 2, 2), Cov(vec J) (R, 4, 4; None unless
    ``with_cov``: a jackknife's half fits need J alone), identified (R,) and valid (R,:
    identified with a strong enough lag-2 instrument). ``segments``: the whole trials (by
    which ``moments`` were centred) or parts of them."""
    width = moments.centred.shape[1]
    lags, inst, reg, target = _lag_layout(method, width)
    gram, n = moments.gram(segments, lags)
    r, p = gram.shape[0], len(reg)
    dof = n - p - len(segments.lengths)
    if dof < 2:
        what = "pairs" if method == "ols" else "triples"
        raise ModelError(f"too few bounces for the {'VAR(1)' if method == 'ols' else 'lag-2'}"
                         f" fit ({n} {what} in {len(segments.lengths)} trials)")
    a = gram[:, inst][:, :, reg]
    identified = np.linalg.cond(a) <= CONDITION_LIMIT[method]
    valid = identified.copy()
    if method == "lag2":
        sign, log_a = np.linalg.slogdet(a)
        sign_z, log_z = np.linalg.slogdet(gram[:, inst][:, :, inst])
        sign_x, log_x = np.linalg.slogdet(gram[:, reg][:, :, reg])
        ok = (sign != 0) & (sign_z > 0) & (sign_x > 0)
        with np.errstate(over="ignore", invalid="ignore"):
            strength = np.where(ok, np.minimum(1.0, np.exp(log_a - 0.5 * (log_z + log_x))),
                                0.0)
        valid &= strength >= MIN_INSTRUMENT_DET
    a = np.where(identified[:, None, None], a, np.eye(p))  # a failed fit solves something harmless
    b = np.linalg.solve(a, gram[:, inst][:, :, target])  # (R, p, 2) = [J, B]^T
    jac = b[:, :2, :].transpose(0, 2, 1)
    if not with_cov:
        return jac, None, identified, valid
    a_inv = np.linalg.inv(a)
    if method == "ols":
        # the residuals' cross-products from the Gram: e_k = y_{k+1} - b' x_k
        cross = gram[:, target][:, :, reg] @ b
        sse = (gram[:, target][:, :, target] - cross - cross.transpose(0, 2, 1)
               + b.transpose(0, 2, 1) @ gram[:, reg][:, :, reg] @ b)
        cov = (sse / dof)[:, :, None, :, None] * a_inv[:, None, :2, None, :2]
        return jac, cov.reshape(r, 4, 4), identified, valid
    # the lag-2 sandwich needs each row's residual times its instruments: the rows k of
    # (w_k, w_{k+1}, w_{k+2}), weighted 0 where they run past their segment's end
    t = moments.centred.shape[2] - 1
    row = [moments.centred[:, :, lag:t - lags + lag] for lag in range(lags + 1)]

    def series(index: int) -> np.ndarray:
        return row[index // width][:, index % width]

    inside = np.zeros(t - lags)
    for start, length in zip(segments.starts, segments.lengths):
        inside[start:start + max(length - lags, 0)] = 1.0
    regressors = [series(i) for i in reg]
    g = np.empty((r, 2, p, t - lags))
    for e, column in enumerate(target):
        resid = series(column) - sum(b[:, c, e, None] * x for c, x in enumerate(regressors))
        resid *= inside
        for c, i in enumerate(inst):
            g[:, e, c] = resid * series(i)
    g = g.reshape(r, 2 * p, t - lags)
    s = g @ g.transpose(0, 2, 1)
    g1 = g[:, :, 1:] @ g[:, :, :-1].transpose(0, 2, 1)  # consecutive rows: one segment's
    s = s + g1 + g1.transpose(0, 2, 1)
    bread = np.zeros((r, 2 * p, 2 * p))
    bread[:, :p, :p] = a_inv
    bread[:, p:, p:] = a_inv
    full = bread @ s @ bread.transpose(0, 2, 1)
    w, v = np.linalg.eigh((full + full.transpose(0, 2, 1)) / 2)
    full = (v * np.clip(w, 0.0, None)[:, None, :]) @ v.transpose(0, 2, 1)
    j_index = [0, 1, p, p + 1]
    return jac, full[:, j_index][:, :, j_index], identified, valid


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
    moments = _Moments.of(panels, inputs, whole, 1 if method == "ols" else 2)
    jac, cov, identified, valid = _solve_segments(method, moments, whole)
    assert cov is not None
    if jackknife:
        if min(lengths) < 8:
            raise ModelError(f"a trial has only {min(lengths)} bounces: the split-panel "
                             "jackknife needs at least 8 per trial (4 per half)")
        first, second = whole.halves()
        j1, _, id1, ok1 = _solve_segments(method, moments, first, with_cov=False)
        j2, _, id2, ok2 = _solve_segments(method, moments, second, with_cov=False)
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
