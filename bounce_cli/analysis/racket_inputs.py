"""The map's response to a racket that varies from cycle to cycle: the model's prediction for a
VARX's input coefficients (section 4's implicit-function derivatives, extended to the racket).

A person's racket is not eq. 4's sine: each cycle c has its own period T_c and amplitude a_c
(the impacts table's ``racket_period_s`` and ``racket_amplitude_m`` of the impact's cycle). In
period-1 motion impact k falls in cycle c at phase theta_k (from the cycle's upward
mid-position crossing, in [0, 2 pi)) and impact k+1 in cycle c+1, so the flight lasts

    Delta = T_c (2 pi - theta_k) / (2 pi) + T_{c+1} theta_{k+1} / (2 pi)

and eqs. 5-6 read, with the racket of the two cycles,

    F = a_{c+1} sin theta_{k+1} - a_c sin theta_k - v_k Delta + g Delta^2 / 2 = 0      (eq. 6)
    v_{k+1} = -alpha (v_k - g Delta) + (1 + alpha) a_{c+1} (2 pi / T_{c+1}) cos theta_{k+1}
                                                                                        (eq. 5)

(with T_c = T_{c+1} = tau and a_c = a_{c+1} = a_r these are eqs. 5-6 times -1/omega^2 and as
printed). The implicit function theorem gives d theta_{k+1} / dp = -F_p / F_theta_{k+1} for p in
(T_c, a_c, T_{c+1}, a_{c+1}), and d v_{k+1} / dp = dv/dp + dv/d theta_{k+1} d theta_{k+1} / dp.
At the fixed point these are the B of

    y_{k+1} = J y_k + B_next u_{k+1} + B_this u_k,     u_k = (T_c - tau, a_c - a_r),

whose J is eq. 9 (the same derivatives with respect to (v_k, theta_k): tested).

These are derivatives at the fixed point. A VARX fitted to the map's own impacts estimates its
best linear predictor instead, which differs from them where the state spreads far enough for
the map's curvature to show (with a varying racket the phase's SD is several degrees; theta's
equation has no noise of its own, so its SEs are small): ``data.simulated_runs`` simulates
a session of the model at a racket's per-cycle SDs, for the model's own prediction of what
such a fit estimates (``experiments.data_side.varx_prediction``), and the cycle-wise
racket's impact by the simulated lab's contact search, the tests' independent route.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.params import ModelParams

#: the inputs' names in the order of u_k
RACKET_INPUTS = ("racket_period_s", "racket_amplitude_m")
#: names of the entries of the (2, 4) VARX input matrix [B_next, B_this], row-major
INPUT_COEFFICIENTS = tuple(f"B_{state}_{when}_{inp}" for state in ("v", "theta")
                           for when in ("next", "this") for inp in ("period", "amplitude"))


@dataclass(frozen=True)
class RacketInputJacobian:
    """d(v_{k+1}, theta_{k+1}) / d(period, amplitude) of impact k+1's cycle (``next``) and of
    impact k's (``this``), each (2, 2): rows (v, theta), columns (period in s, amplitude in m);
    ``state`` is d(v_{k+1}, theta_{k+1}) / d(v_k, theta_k) by the same route (eq. 9's J)."""

    next: np.ndarray
    this: np.ndarray
    state: np.ndarray

    def as_varx(self) -> np.ndarray:
        """(2, 4) coefficients of (u_{k+1}, u_k) in the VARX's column order."""
        return np.hstack([self.next, self.this])


def racket_input_jacobian(params: ModelParams) -> RacketInputJacobian:
    """The implicit-function derivatives of eqs. 5-6 with a cycle-wise racket (module
    docstring) at the period-1 fixed point of ``params``.

    Parameters
    ----------
    params : ModelParams
        alpha, g and the mean racket (tau, a_r) about which the cycles vary.

    Returns
    -------
    RacketInputJacobian
        B_next, B_this (rows v, theta; columns period s, amplitude m) and the state Jacobian.
    """
    fp = params.fixed_point()
    alpha, g = params.alpha, params.g
    tau, a = params.racket_period, params.racket_amplitude
    theta = fp.theta_rad % (2.0 * math.pi)  # the data's phase: from the upward crossing
    v = fp.v_m_s
    delta = tau  # period 1: one racket cycle per flight
    share_this, share_next = (2.0 * math.pi - theta) / (2.0 * math.pi), theta / (2.0 * math.pi)
    f_delta = -v + g * delta
    # dF / d(v_k, theta_k, T_c, a_c, T_{c+1}, a_{c+1}) and dF / d theta_{k+1}
    f_p = np.array([-delta, -a * math.cos(theta) - f_delta * tau / (2 * math.pi),
                    f_delta * share_this, -math.sin(theta), f_delta * share_next,
                    math.sin(theta)])
    f_theta_next = a * math.cos(theta) + f_delta * tau / (2.0 * math.pi)
    dtheta = -f_p / f_theta_next
    omega = 2.0 * math.pi / tau
    # partial derivatives of eq. 5 at fixed theta_{k+1}, same order, and d/d theta_{k+1}
    v_p = np.array([-alpha, -alpha * g * tau / (2 * math.pi), alpha * g * share_this, 0.0,
                    alpha * g * share_next - (1 + alpha) * a * omega / tau * math.cos(theta),
                    (1 + alpha) * omega * math.cos(theta)])
    v_theta_next = alpha * g * tau / (2 * math.pi) - (1 + alpha) * a * omega * math.sin(theta)
    dv = v_p + v_theta_next * dtheta
    total = np.vstack([dv, dtheta])  # (2, 6)
    return RacketInputJacobian(next=total[:, 4:6], this=total[:, 2:4], state=total[:, 0:2])
