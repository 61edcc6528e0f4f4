"""Section 7's perturbation of the fixed point, shared by the passive and the controlled map:
the velocity after the perturbed impact, and the impact from which a response stays relaxed."""

from __future__ import annotations

import numpy as np

from .params import ModelParams


def perturbed_velocity(params: ModelParams, alpha_p: float) -> float:
    """v_0 = (1 + 2 alpha_p - alpha_0) / (1 + alpha_0) v~ (section 7), alpha_0 = params.alpha.

    It is eq. 5 with alpha_p at the fixed point (theta_{k+1} = theta~ + 2 pi, v_k = v~):
    (1 + alpha_p) a_r w cos(theta~) - alpha_p v~ + g alpha_p 2 pi / w.
    """
    alpha_0 = params.alpha
    return (1.0 + 2.0 * alpha_p - alpha_0) / (1.0 + alpha_0) * params.fixed_point().v_m_s


def relaxation_impacts(dv, dtheta, tol_v: float, tol_theta: float) -> int:
    """First impact k from which |dv| <= tol_v and |dtheta| <= tol_theta at every later impact
    of the series; -1 when the series does not end inside the tolerance (or holds NaN there)."""
    inside = (np.abs(dv) <= tol_v) & (np.abs(dtheta) <= tol_theta)
    if not inside[-1]:
        return -1
    outside = np.flatnonzero(~inside)
    return int(outside[-1] + 1) if len(outside) else 0
