"""Linear stability of the period-1 fixed point (section 4: eqs. 9-14).

Stability depends only on alpha and AC, the racket acceleration at impact in units of g:
AC = -a_r w^2 sin(theta~) / g. Functions of (alpha, ac) accept numpy arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .maps import map_step
from .params import ModelParams


def racket_acceleration_at_impact_g(params: ModelParams) -> float:
    """AC = -a_r w^2 sin(theta~) / g (section 4), negative on the stable branch.

    Equals -sqrt((a_r w^2/g)^2 - pi^2 ((1-alpha)/(1+alpha))^2).
    """
    fp = params.fixed_point()
    return -params.racket_amplitude * params.omega**2 * math.sin(fp.theta_rad) / params.g


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


def eigenvalues(alpha, ac):
    """lambda_+- = c +- sqrt(c^2 - alpha^2) (eq. 10) as complex arrays (lambda_+, lambda_-)."""
    c = np.asarray(characteristic_c(alpha, ac), dtype=float)
    disc = c * c - np.square(alpha)
    root = np.where(disc >= 0.0, np.sqrt(np.abs(disc)) + 0j, 1j * np.sqrt(np.abs(disc)))
    return c + root, c - root


def spectral_radius(alpha, ac):
    """max(|lambda_+|, |lambda_-|)."""
    lp, lm = eigenvalues(alpha, ac)
    return np.maximum(np.abs(lp), np.abs(lm))


def is_complex_regime(alpha, ac):
    """True where c^2 < alpha^2: a complex pair with |lambda| = |alpha| (eqs. 11, 12)."""
    c = characteristic_c(alpha, ac)
    return c * c < np.square(alpha)


def flip_boundary_g(alpha):
    """Lower stability boundary AC = -2 (1 + alpha^2) / (1 + alpha)^2 (eq. 14)."""
    return -2.0 * (1.0 + np.square(alpha)) / np.square(1.0 + np.asarray(alpha))


def complex_boundaries_g(alpha):
    """Boundaries of the complex regime (eq. 11): (-1, -((1-alpha)/(1+alpha))^2)."""
    alpha = np.asarray(alpha, dtype=float)
    return np.full_like(alpha, -1.0), -np.square((1.0 - alpha) / (1.0 + alpha))


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
        stable=radius < 1.0,
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
