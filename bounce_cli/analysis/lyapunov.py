"""The Jacobian of the ball bouncing map at ANY state, and the largest Lyapunov exponent.

Section 4 differentiates the implicit phase map (eq. 6) with the implicit function theorem at
the fixed point only (eq. 9). The same differentiation holds at every impact. With the hop
s = theta_{k+1} - theta_k, the ball's velocity just before the next impact (eq. 2)

    v^- = v_k - g s / w,

and the racket velocities v_r(theta) = a_r w cos(theta) at the two impacts, the partial
derivatives of F (the right-hand side of eq. 6 divided by w^2, as in section 4) are

    dF/dtheta_{k+1} = (v^- - v_r(theta_{k+1})) / w      (< 0: the ball lands from above)
    dF/dtheta_k     = (v_r(theta_k) - v^-) / w
    dF/dv_k         = s / w

so that

    dtheta_{k+1}/dtheta_k = (v_r(theta_k) - v^-) / (v_r(theta_{k+1}) - v^-)
    dtheta_{k+1}/dv_k     = s / (v_r(theta_{k+1}) - v^-)

and from the explicit velocity map (eq. 5), with
K = dv_{k+1}/dtheta_{k+1} (at fixed hop) = -(1+alpha) a_r w sin(theta_{k+1}) + g alpha / w,

    dv_{k+1}/dv_k     = K dtheta_{k+1}/dv_k - alpha
    dv_{k+1}/dtheta_k = K dtheta_{k+1}/dtheta_k - g alpha / w.

At the fixed point (s = 2 pi, v^- = -v~, v_r equal at both impacts) this is eq. 9.

The largest Lyapunov exponent (per impact) is the mean of log ||J_k u_k|| over an orbit, with
the tangent vector u renormalised to unit length after every impact. Tangent vectors are kept
in the dimensionless coordinates (v w / g, theta), so the norm mixes no units; the exponent
itself does not depend on that choice.
"""

from __future__ import annotations

import numpy as np


def map_jacobian(theta, v, hop_phase, params) -> np.ndarray:
    """Jacobian d(v_{k+1}, theta_{k+1}) / d(v_k, theta_k) of eqs. 5, 6 at the impact
    (theta_k, v_k) whose next impact is ``hop_phase`` later, by implicit differentiation.

    Rows and columns in eq. 9's order (v, theta). Arrays broadcast; ``params`` is a
    ``ModelParams`` or per-state parameter arrays. Returns shape (..., 2, 2). The phase may
    be wrapped or not (the map depends on it modulo 2 pi).
    """
    theta, v, s = np.broadcast_arrays(
        np.asarray(theta, float), np.asarray(v, float), np.asarray(hop_phase, float)
    )
    w, a, g, alpha = params.omega, params.racket_amplitude, params.g, params.alpha
    theta_next = theta + s
    v_before = v - g * s / w  # eq. 2 at the next impact
    racket_now = a * w * np.cos(theta)
    approach = a * w * np.cos(theta_next) - v_before  # racket minus ball velocity, > 0
    # a grazing impact (approach 0: alpha 0 lets the ball land with the racket's velocity)
    # has no derivative: inf or NaN entries, which the callers take as such, without warning
    with np.errstate(divide="ignore", invalid="ignore"):
        dtheta_dtheta = (racket_now - v_before) / approach
        dtheta_dv = s / approach
        k = -(1.0 + alpha) * a * w * np.sin(theta_next) + g * alpha / w
        jac = np.empty(theta.shape + (2, 2))
        jac[..., 0, 0] = k * dtheta_dv - alpha
        jac[..., 0, 1] = k * dtheta_dtheta - g * alpha / w
        jac[..., 1, 0] = dtheta_dv
        jac[..., 1, 1] = dtheta_dtheta
    return jac


def initial_tangent(n: int) -> np.ndarray:
    """Unit tangent vectors (n, 2) in the scaled coordinates (v w / g, theta). A fixed
    direction that is generic (not an eigenvector of eq. 9 at any parameters we know of);
    after a transient every start converges to the most expanding direction."""
    return np.tile(np.array([0.6, 0.8]), (n, 1))


def advance_tangent(tangent: np.ndarray, jac: np.ndarray, params) -> tuple[np.ndarray, np.ndarray]:
    """One impact of the tangent dynamics: u' = D J D^-1 u with D = diag(w/g, 1) (scaled
    coordinates), renormalised. Returns (unit u', log ||D J D^-1 u||) per state."""
    scale = params.omega / params.g  # m/s -> dimensionless velocity
    du_v = tangent[:, 0] / scale  # back to (m/s, rad)
    du_t = tangent[:, 1]
    # a grazing impact's infinite derivatives (``map_jacobian``) give inf - inf here: NaN,
    # the growth of a state that has no tangent, taken as such by the callers
    with np.errstate(invalid="ignore", divide="ignore"):
        new_v = (jac[:, 0, 0] * du_v + jac[:, 0, 1] * du_t) * scale
        new_t = jac[:, 1, 0] * du_v + jac[:, 1, 1] * du_t
        norm = np.hypot(new_v, new_t)
        unit = np.stack([new_v / norm, new_t / norm], axis=1)
        return unit, np.log(norm)
