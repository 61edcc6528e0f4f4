"""The basin kernel's constants: the scalars its loops read, in one float array.

Numba-free, so that both ways of running the compiled kernel share it: numba's dispatcher
(``model.compiled``) and its machine code loaded without numba (``model.native``). Each
scalar is the numpy code's own expression (``impact.first_impact_phase``,
``PassiveMap.step``, eqs. 5-6) computed once in Python, so that the kernel gives the numpy
route's bits.
"""

from __future__ import annotations

import numpy as np

from .params import FixedPoint, ModelParams

# indices into the constants array (see solver_constants)
(_A, _W, _G, _AW, _NEG_G_W2, _NEG_G_WW, _BOUND, _W_SQ, _TWO_W_SQ, _TWO_A, _TWO_BOUND,
 _A_3, _V_COEF, _ALPHA, _G_ALPHA_W, _V_FP, _TH_FP, _TOL, _MIN_HOP, _N_CONSTANTS) = range(20)


def flight_constants(a, w, g, c):
    """The solver's constants at angular frequency w into ``c``, each by the numpy code's
    expression (for an array of frequencies: w**2 is w * w; ``solver_constants`` puts
    Python's pow back). Plain Python, compiled by ``model.compiled`` for its loops."""
    c[_A], c[_W], c[_G] = a, w, g
    c[_AW] = a * w  # can_fly, racket_velocity: a * w * cos
    c[_NEG_G_W2] = -g / (w * w)  # can_fly's curvature
    c[_NEG_G_WW] = -g / (w * w)  # first step's curvature
    c[_BOUND] = g / (w * w) + a
    c[_W_SQ] = w * w
    c[_TWO_W_SQ] = 2.0 * w * w
    c[_TWO_A] = 2.0 * a
    c[_TWO_BOUND] = 2.0 * (g / (w * w) + a)
    c[_A_3] = a / 3.0


def solver_constants(params: ModelParams, fp: FixedPoint, tolerance: float,
                     min_hop: float) -> np.ndarray:
    """The scalars of the numpy code, each by the numpy code's own expression (Python floats:
    ``-g / w**2`` is Python's pow, ``a * w * cos`` is ``(a * w) * cos``).

    Parameters
    ----------
    params : ModelParams
        The model (racket amplitude and frequency, g, alpha).
    fp : FixedPoint
        The classification's target (eqs. 7-8); NaN where only the solver runs.
    tolerance : float
        The distance to the fixed point that counts as converged.
    min_hop : float
        The shortest hop (s) that is not sticking.

    Returns
    -------
    numpy.ndarray
        The constants, indexed by this module's ``_A`` ... ``_MIN_HOP``.
    """
    a, w, g, alpha = params.racket_amplitude, params.omega, params.g, params.alpha
    c = np.empty(_N_CONSTANTS)
    flight_constants(a, w, g, c)
    c[_NEG_G_W2] = -g / w**2  # can_fly's curvature: Python's pow, as the numpy code's scalar
    c[_V_COEF] = (1.0 + alpha) * a * w  # eq. 5
    c[_ALPHA] = alpha
    c[_G_ALPHA_W] = g * alpha / w
    c[_V_FP], c[_TH_FP] = fp.v_m_s, fp.theta_rad
    c[_TOL], c[_MIN_HOP] = tolerance, min_hop
    return c


def classify_scratch(n: int) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
    """``compiled._classify``'s outputs and scratch for n points: outcome (int8), iterations
    (int16), and (the queue of flying points, int64; the states and the solver's scratch,
    12 rows of float64; the solver's positions, int64). Untouched pages cost nothing: the
    rows beyond the points that fly are never written."""
    return (np.empty(n, np.int8), np.empty(n, np.int16),
            (np.empty(n, np.int64), np.empty((12, n)), np.empty(n, np.int64)))


def kernel_inputs(theta0, v0, params: ModelParams, fp: FixedPoint, tolerance: float,
                  min_hop: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``compiled._classify``'s inputs: the starts as contiguous float64 arrays and the
    constants (``solver_constants``)."""
    return (np.ascontiguousarray(theta0, dtype=float), np.ascontiguousarray(v0, dtype=float),
            solver_constants(params, fp, tolerance, min_hop))
