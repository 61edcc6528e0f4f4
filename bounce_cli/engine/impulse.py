"""Impulse response after a one-impact change of the coefficient of restitution (section 7).

At the period-1 fixed point (v~, theta~) of a model with alpha_0, one impact happens with
alpha_p instead: the ball leaves the racket at theta~ with v_0 (the velocity map, eq. 5, with
alpha_p), and from then on the map with alpha_0 runs, either in full (eqs. 5, 6) or linearised
about the fixed point, y_{k+1} = J y_k with the Jacobian of eq. 9 and y = (v - v~, theta - theta~).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .linear import iterate_linear, jacobian
from .maps import iterate_map
from .params import ModelParams, phase_difference


def perturbed_velocity(params: ModelParams, alpha_p: float) -> float:
    """v_0 = (1 + 2 alpha_p - alpha_0) / (1 + alpha_0) v~ (section 7), alpha_0 = params.alpha.

    It is eq. 5 with alpha_p at the fixed point (theta_{k+1} = theta~ + 2 pi, v_k = v~):
    (1 + alpha_p) a_r w cos(theta~) - alpha_p v~ + g alpha_p 2 pi / w.
    """
    alpha_0 = params.alpha
    return (1.0 + 2.0 * alpha_p - alpha_0) / (1.0 + alpha_0) * params.fixed_point().v_m_s


@dataclass(frozen=True)
class ImpulseResponse:
    """Impacts k = 0..n after the perturbed impact (k = 0): velocity after impact (m/s),
    wrapped phase (rad, in [0, 2 pi)) and deviations from the fixed point (dtheta wrapped to
    [-pi, pi))."""

    v: np.ndarray
    theta: np.ndarray
    dv: np.ndarray
    dtheta: np.ndarray


def _response(params: ModelParams, v: np.ndarray, dtheta: np.ndarray) -> ImpulseResponse:
    fp = params.fixed_point()
    return ImpulseResponse(
        v=v, theta=np.mod(fp.theta_rad + dtheta, 2.0 * math.pi), dv=v - fp.v_m_s, dtheta=dtheta
    )


def impulse_response_full(params: ModelParams, alpha_p: float, n_impacts: int) -> ImpulseResponse:
    """The full map (eqs. 5, 6) from (theta~, v_0). NaN once the ball cannot leave the racket."""
    fp = params.fixed_point()
    theta, v, _ = iterate_map(fp.theta_rad, perturbed_velocity(params, alpha_p), params, n_impacts)
    return _response(params, v, phase_difference(theta, fp.theta_rad))


def impulse_response_linear(
    params: ModelParams, alpha_p: float, n_impacts: int
) -> ImpulseResponse:
    """The linearised map y_{k+1} = J y_k (J of eq. 9) from y_0 = (v_0 - v~, 0)."""
    fp = params.fixed_point()
    y = iterate_linear(jacobian(params), [perturbed_velocity(params, alpha_p) - fp.v_m_s, 0.0],
                       n_impacts)
    return _response(params, fp.v_m_s + y[:, 0], y[:, 1])


def relaxation_impacts(dv, dtheta, tol_v: float, tol_theta: float) -> int:
    """First impact k from which |dv| <= tol_v and |dtheta| <= tol_theta at every later impact
    of the series; -1 when the series does not end inside the tolerance (or holds NaN there)."""
    inside = (np.abs(dv) <= tol_v) & (np.abs(dtheta) <= tol_theta)
    if not inside[-1]:
        return -1
    outside = np.flatnonzero(~inside)
    return int(outside[-1] + 1) if len(outside) else 0
