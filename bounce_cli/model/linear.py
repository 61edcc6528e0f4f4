"""Linear stability of the period-1 fixed point (section 4: eqs. 9-14).

Stability depends only on alpha and AC, the racket acceleration at impact in units of g:
AC = -a_r w^2 sin(theta~) / g. Functions of (alpha, ac) accept numpy arrays.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .maps import map_step
from .params import ModelError, ModelParams, gamma


def racket_acceleration_at_impact_g(params: ModelParams) -> float:
    """AC = -a_r w^2 sin(theta~) / g (section 4), negative on the stable branch.

    Equals -sqrt((a_r w^2/g)^2 - pi^2 ((1-alpha)/(1+alpha))^2).
    """
    return params.racket_acceleration_g(params.fixed_point().theta_rad)


def jacobian(params: ModelParams) -> np.ndarray:
    """Jacobian of the map at the fixed point, eq. 9, for the state (v, theta):

        [[alpha^2 - (1+alpha)^2 a_r w^2 sin(theta~)/g,  -(1+alpha) a_r w sin(theta~)],
         [(1+alpha) w / g,                                1                          ]]
    """
    fp = params.fixed_point()
    a, w, g, alpha = params.racket_amplitude, params.omega, params.g, params.alpha
    sin_t = math.sin(fp.theta_rad)
    return np.array(
        [
            [alpha**2 - (1 + alpha) ** 2 * a * w**2 * sin_t / g, -(1 + alpha) * a * w * sin_t],
            [(1 + alpha) * w / g, 1.0],
        ]
    )


def characteristic_c(alpha, ac):
    """c = ((1 + alpha^2) + (1 + alpha)^2 AC) / 2, half the trace of J (before eq. 10)."""
    return ((1.0 + np.square(alpha)) + np.square(1.0 + np.asarray(alpha)) * ac) / 2.0


def eigenvalues_from_trace(c, det):
    """The eigenvalues of a 2 x 2 matrix from half its trace and its determinant:
    ``lambda_+- = c +- sqrt(c^2 - det)`` (eq. 10, where eq. 9's J has det J = alpha^2).

    The one definition of the 2 x 2 eigenvalues: :func:`eigenvalues` (the model's, from
    alpha and AC) and :func:`eigenvalues_2x2` (any matrix: a VAR(1) fitted to data) call it.

    Parameters
    ----------
    c : float or array_like
        Half the trace, tr J / 2.
    det : float or array_like
        The determinant, det J.

    Returns
    -------
    tuple of numpy.ndarray
        (lambda_+, lambda_-), complex; a complex pair where c^2 < det.
    """
    disc = c * c - det
    root = np.where(disc >= 0.0, np.sqrt(np.abs(disc)) + 0j, 1j * np.sqrt(np.abs(disc)))
    return c + root, c - root


def eigenvalues(alpha, ac):
    """lambda_+- = c +- sqrt(c^2 - alpha^2) (eq. 10) as complex arrays (lambda_+, lambda_-)."""
    c = np.asarray(characteristic_c(alpha, ac), dtype=float)
    return eigenvalues_from_trace(c, np.square(alpha))


def eigenvalues_2x2(jac) -> tuple[complex, complex]:
    """(lambda_+, lambda_-) of a 2 x 2 matrix: :func:`eigenvalues_from_trace` with
    c = tr J / 2 and det J (eq. 10 for eq. 9's J, where det J = alpha^2).

    Parameters
    ----------
    jac : array_like, shape (2, 2)
        The matrix (eq. 9's Jacobian, or a VAR(1) coefficient matrix fitted to data).

    Returns
    -------
    tuple of complex

    Examples
    --------
    >>> eigenvalues_2x2(np.array([[0.0, -0.25], [1.0, 0.0]]))
    (0.5j, -0.5j)
    """
    plus, minus = eigenvalues_from_trace(*half_trace_and_det(np.asarray(jac)))
    return complex(plus), complex(minus)


def half_trace_and_det(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(tr J / 2, det J) of each 2 x 2 matrix of a (..., 2, 2) stack."""
    c = 0.5 * (jac[..., 0, 0] + jac[..., 1, 1])
    det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
    return c, det


def spectral_radii_2x2(jac: np.ndarray) -> np.ndarray:
    """max |lambda| of each 2 x 2 matrix of a stack, by :func:`eigenvalues_from_trace`
    (eq. 10); a complex pair's modulus is sqrt(det J) (eq. 12: alpha for eq. 9's J).

    Parameters
    ----------
    jac : numpy.ndarray, shape (..., 2, 2)
        The matrices (VAR(1) coefficient matrices fitted to many data sets at once).

    Returns
    -------
    numpy.ndarray, shape (...)
        The spectral radii.
    """
    c, det = half_trace_and_det(jac)
    plus, minus = eigenvalues_from_trace(c, det)
    real_pair = c * c - det >= 0.0
    return np.where(real_pair, np.maximum(np.abs(plus), np.abs(minus)), np.sqrt(np.abs(det)))


def spectral_radius(alpha, ac):
    """max(|lambda_+|, |lambda_-|)."""
    lp, lm = eigenvalues(alpha, ac)
    return np.maximum(np.abs(lp), np.abs(lm))


#: relative margin by which a computed spectral radius must lie below a level to count as
#: below it (``radius_below``, ``is_stable``); see ``radius_below`` for why 1e-12
ROUNDING_MARGIN = 1e-12


def radius_below(radius, level=1.0) -> np.ndarray:
    """Where a computed spectral radius lies below ``level`` by more than rounding:
    ``radius < level (1 - ROUNDING_MARGIN)``, elementwise (NaN: not below).

    On a stability boundary an eigenvalue lies on the circle exactly: at AC = 0,
    lambda_+ = 1 (eq. 10 with c = (1 + alpha^2) / 2), at the flip boundary (eq. 14)
    lambda_- = -1, with racket period control at gain K = 1 an eigenvalue 1. The computed
    radius is then 1 +- a few ulp (2.2e-16 each), its sign decided by the last bits of the
    machine's arithmetic, so a plain ``radius < 1`` would call such points stable on one
    machine and unstable on another. The margin, 1e-12 relative (thousands of ulp, far
    below any radius a grid or a fit resolves), puts them on the boundary, not inside.

    Parameters
    ----------
    radius : float or array_like
        Spectral radii (max |lambda| of eq. 10, or of any Jacobian).
    level : float or array_like, default 1.0
        The level (1: linear stability; a target radius of a control design).

    Returns
    -------
    numpy.ndarray of bool
        ``radius``'s shape.

    Examples
    --------
    >>> radius_below([0.5, 1.0 - 2.2e-16, 1.0, 1.0 + 2.2e-16]).tolist()
    [True, False, False, False]
    """
    level = np.asarray(level, dtype=float)
    return np.asarray(radius, dtype=float) < level * (1.0 - ROUNDING_MARGIN)


def is_stable(radius: float) -> bool:
    """Whether a period-1 fixed point with this spectral radius is linearly stable: both
    eigenvalues of eq. 10 inside the unit circle (section 4's condition), by more than
    rounding (``radius_below``: a radius of 1 +- a few ulp is on the boundary, not stable).

    Parameters
    ----------
    radius : float
        The spectral radius, max |lambda| (eq. 10, or of the 3 x 3 Jacobian with control).

    Returns
    -------
    bool

    Examples
    --------
    >>> is_stable(0.5), is_stable(1.0 - 2.2e-16), is_stable(float("nan"))
    (True, False, False)
    """
    return bool(radius_below(radius))


def is_complex_regime(alpha, ac):
    """True where c^2 < alpha^2: a complex pair with |lambda| = |alpha| (eqs. 11, 12)."""
    c = characteristic_c(alpha, ac)
    return c * c < np.square(alpha)


def flip_boundary_g(alpha):
    """Lower stability boundary AC = -2 (1 + alpha^2) / (1 + alpha)^2 (eq. 14)."""
    return -2.0 * (1.0 + np.square(alpha)) / np.square(1.0 + np.asarray(alpha))


def complex_boundaries_g(alpha):
    """Boundaries of the complex regime (eq. 11): (-1, -((1-alpha)/(1+alpha))^2).

    The regime is the AC between the two. The paper prints eq. 11 as
    -((1-alpha)/(1+alpha))^2 < AC < -1, the order that holds only for alpha < 0; for the
    physical 0 <= alpha < 1 it reads -1 < AC < -((1-alpha)/(1+alpha))^2 (c^2 = alpha^2 at
    both, c^2 < alpha^2 between them). Returned as (low, high) at every alpha: the
    stability diagram's grid runs into alpha < 0 (pure algebra), where the order turns.
    """
    alpha = np.asarray(alpha, dtype=float)
    other = -np.square((1.0 - alpha) / (1.0 + alpha))
    return np.minimum(-1.0, other), np.maximum(-1.0, other)


@dataclass(frozen=True)
class Stability:
    ac_g: float
    eigenvalues: tuple[complex, complex]
    spectral_radius: float
    regime: str  # "real" | "complex"
    stable: bool


def stability(params: ModelParams) -> Stability:
    """Eigenvalues (eq. 10) at the fixed point, their regime and linear stability."""
    ac = racket_acceleration_at_impact_g(params)
    lp, lm = eigenvalues(params.alpha, ac)
    radius = float(max(abs(lp), abs(lm)))
    return Stability(
        ac_g=ac,
        eigenvalues=(complex(lp), complex(lm)),
        spectral_radius=radius,
        regime="complex" if bool(is_complex_regime(params.alpha, ac)) else "real",
        stable=is_stable(radius),
    )


def finite_difference_jacobian(params: ModelParams, rel_step: float = 1e-6) -> np.ndarray:
    """Jacobian of the implicit map (eqs. 5, 6) at the fixed point by central differences.

    Independent of eq. 9: it perturbs (v, theta) and re-solves eq. 6 for the next impact.
    Rows/columns ordered (v, theta) as in eq. 9; the 2 pi phase advance is removed.
    """
    fp = params.fixed_point()
    h_v = rel_step * fp.v_m_s
    h_t = rel_step
    base_v = np.array([fp.v_m_s + h_v, fp.v_m_s - h_v, fp.v_m_s, fp.v_m_s])
    base_t = np.array([fp.theta_rad, fp.theta_rad, fp.theta_rad + h_t, fp.theta_rad - h_t])
    step = map_step(base_t, base_v, params)
    dv_dv = (step.v[0] - step.v[1]) / (2 * h_v)
    dv_dt = (step.v[2] - step.v[3]) / (2 * h_t)
    dt_dv = (step.theta[0] - step.theta[1]) / (2 * h_v)
    dt_dt = (step.theta[2] - step.theta[3]) / (2 * h_t)
    return np.array([[dv_dv, dv_dt], [dt_dv, dt_dt]])


def ac_explicit_g(alpha, g, racket_amplitude, racket_period):
    """AC in explicit form (section 4, after the characteristic equation):

        AC = -sqrt((a_r w^2 / g)^2 - pi^2 ((1-alpha)/(1+alpha))^2),   w = 2 pi / tau.

    NaN where the radicand is negative (no fixed point).
    """
    w = 2.0 * np.pi / np.asarray(racket_period, dtype=float)
    radicand = np.square(gamma(racket_amplitude, w, g)) - np.pi**2 * np.square(
        (1.0 - np.asarray(alpha)) / (1.0 + np.asarray(alpha))
    )
    with np.errstate(invalid="ignore"):
        return -np.sqrt(radicand)


def racket_amplitude_for_ac(alpha, ac_g, g, racket_period):
    """The a_r (m) that puts the fixed point at racket acceleration ``ac_g`` (<= 0, units of g):
    the explicit AC formula solved for a_r,  a_r = (g/w^2) sqrt(AC^2 + pi^2 ((1-a)/(1+a))^2)."""
    w = 2.0 * np.pi / np.asarray(racket_period, dtype=float)
    ratio = (1.0 - np.asarray(alpha)) / (1.0 + np.asarray(alpha))
    return g / w**2 * np.sqrt(np.square(ac_g) + np.pi**2 * np.square(ratio))


#: the four parameters of ``ModelParams``
MODEL_FIELDS = ("alpha", "g", "racket_amplitude", "racket_period")


def with_parameters(base: ModelParams, values: Mapping[str, float]) -> ModelParams:
    """``base`` with some parameters replaced: the point of a parameter sweep.

    Parameters
    ----------
    base : ModelParams
        The parameters not replaced.
    values : mapping
        New values of any of ``alpha``, ``g``, ``racket_amplitude``, ``racket_period``, and
        at most one of the two that set the racket amplitude instead: ``gamma``
        (Gamma = a_r w^2 / g > 0, at the point's g and racket period) or ``ac_g`` (the
        fixed point's racket acceleration at impact AC in units of g, <= 0: section 4's
        explicit form solved for a_r, ``racket_amplitude_for_ac``, at the point's alpha, g
        and racket period).

    Returns
    -------
    ModelParams

    Raises
    ------
    ModelError
        An unknown name, two values for the racket amplitude, or an invalid point (the other
        parameters are checked first, so that the error names them).
    """
    unknown = set(values) - set(MODEL_FIELDS) - {"gamma", "ac_g"}
    if unknown:
        raise ModelError(f"cannot set {sorted(unknown)}: choose from "
                         f"{', '.join(MODEL_FIELDS + ('gamma', 'ac_g'))}")
    amplitude = [k for k in ("racket_amplitude", "gamma", "ac_g") if k in values]
    if len(amplitude) > 1:
        raise ModelError(f"{' and '.join(amplitude)} cannot both be swept (each sets a_r)")
    fields = {f: getattr(base, f) for f in MODEL_FIELDS}
    fields.update({k: float(v) for k, v in values.items() if k in MODEL_FIELDS})
    if "gamma" in values:
        gamma_value = float(values["gamma"])
        if not gamma_value > 0.0:
            raise ModelError(f"gamma must be > 0 (got {values['gamma']!r})")
        point = ModelParams(**fields)
        fields["racket_amplitude"] = gamma_value * point.g / point.omega**2
    if "ac_g" in values:
        ac = float(values["ac_g"])
        if not ac <= 0.0:
            raise ModelError(f"ac_g must be <= 0 (the fixed point's racket acceleration, "
                             f"section 4; got {values['ac_g']!r})")
        ModelParams(**fields)
        fields["racket_amplitude"] = float(racket_amplitude_for_ac(
            fields["alpha"], ac, fields["g"], fields["racket_period"]))
    return ModelParams(**fields)


def stable_ac_range_g(alpha):
    """(lower, upper) AC of linear stability for |alpha| < 1: eq. 14, (flip boundary, 0)."""
    flip = flip_boundary_g(alpha)
    return flip, np.zeros_like(flip)


@dataclass(frozen=True)
class MinimumRadius:
    """Minimum over the stable AC range of the spectral radius (section 4) on a grid."""

    spectral_radius: float
    ac_low_g: float  # the smallest and largest grid AC where the minimum is attained
    ac_high_g: float


def min_stable_spectral_radius(alpha: float, n_ac: int = 4001, rtol: float = 1e-9):
    """min over AC in the stable range of max(|lambda+|, |lambda-|), found on a grid of ``n_ac``
    points strictly inside eq. 14's interval, with the AC interval where it is attained (to
    ``rtol``). Section 4 proves the minimum equals |alpha|, attained on the complex regime."""
    low, high = stable_ac_range_g(alpha)
    ac = np.linspace(float(low), float(high), n_ac + 2)[1:-1]
    radius = spectral_radius(alpha, ac)
    best = float(radius.min())
    at = ac[radius <= best * (1.0 + rtol)]
    return MinimumRadius(best, float(at.min()), float(at.max()))


@dataclass(frozen=True)
class ContractionFit:
    """Empirical contraction (or growth) rate of the full map near the fixed point.

    rate: exp of the least-squares slope of log ||deviation_k|| over the fitted impacts.
    norms: ||deviation_k|| for k = 0..len-1 (deviation (dv / v~, dtheta in rad)).
    fitted_from: first impact used in the fit (earlier ones are transient).
    left_at: impact at which the deviation first exceeded ``ceiling`` (it left the linear
        neighbourhood: growth), or None.
    """

    rate: float
    norms: np.ndarray
    fitted_from: int
    left_at: int | None

    @property
    def n_fitted(self) -> int:
        return len(self.norms) - self.fitted_from


def empirical_contraction_rate(
    params: ModelParams,
    *,
    perturbation: float = 1e-5,
    max_impacts: int = 600,
    floor: float = 1e-13,
    ceiling: float = 1e-2,
    skip: int = 2,
) -> ContractionFit:
    """Iterate the full map (eqs. 5, 6) from the fixed point with v_0 = v~ (1 + perturbation)
    and fit the per-impact decay (or growth) of the deviation norm.

    The norm is sqrt((dv/v~)^2 + dtheta^2); the phase is reduced by 2 pi each impact (the map
    depends on the phase only modulo 2 pi), so rounding stays at the 1e-16 level. Iteration
    stops when the norm falls below ``floor`` (rounding), rises above ``ceiling`` (it leaves
    the neighbourhood where the linearisation holds), the ball cannot fly, or after
    ``max_impacts``. Where stable the rate tends to the spectral radius; where unstable it is
    the growth per impact while the deviation was still small.
    """
    fp = params.fixed_point()
    theta, v = fp.theta_rad, fp.v_m_s * (1.0 + perturbation)
    norms: list[float] = []
    left_at = None
    for k in range(max_impacts + 1):
        norm = math.hypot((v - fp.v_m_s) / fp.v_m_s, theta - fp.theta_rad)
        if not math.isfinite(norm):
            break
        norms.append(norm)
        if norm > ceiling:
            left_at = k
            break
        if norm < floor or k == max_impacts:
            break
        step = map_step(theta, v, params)
        theta, v = float(step.theta) - 2.0 * math.pi, float(step.v)
    arr = np.array(norms)
    start = min(skip, max(len(arr) - 2, 0))
    ks = np.arange(start, len(arr))
    if len(ks) < 2 or np.any(arr[ks] <= 0.0):
        return ContractionFit(float("nan"), arr, start, left_at)
    slope = np.polyfit(ks, np.log(arr[ks]), 1)[0]
    return ContractionFit(float(math.exp(slope)), arr, start, left_at)


def iterate_linear(matrix: np.ndarray, y0, n_impacts: int) -> np.ndarray:
    """The linearised map y_{k+1} = J y_k: rows k = 0..n_impacts of the deviation y_k."""
    matrix = np.asarray(matrix, dtype=float)
    out = np.empty((n_impacts + 1, matrix.shape[0]))
    out[0] = np.asarray(y0, dtype=float)
    for k in range(n_impacts):
        out[k + 1] = matrix @ out[k]
    return out
