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
equation has no noise of its own, so its SEs are small): :func:`simulate_runs` simulates a
session of the model at a racket's per-cycle SDs, for the model's own prediction of what such
a fit estimates (``experiments.data_side.varx_prediction``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.params import ModelError, ModelParams

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


def cycle_map_step(params: ModelParams, v_k: float, theta_k: float, this: tuple[float, float],
                   next_: tuple[float, float]) -> tuple[float, float]:
    """One impact of the cycle-wise racket by the simulated lab's own contact search (eqs. 1-3
    on ``engine.recording``'s racket, not eqs. 5-6): the ball leaves impact k at phase
    ``theta_k`` of a cycle with (period, amplitude) ``this`` with velocity ``v_k``, and meets
    the racket in the next cycle, of ``next_``. Returns (v_{k+1}, theta_{k+1}) with theta in
    that cycle's phase. The independent route of the tests' finite differences.

    Parameters
    ----------
    params : ModelParams
        alpha and g (the racket comes from ``this`` and ``next_``).
    v_k, theta_k : float
        Velocity after impact k (m/s) and its phase in its cycle (rad, [0, 2 pi)).
    this, next_ : tuple of float
        (period s, amplitude m) of impact k's cycle and of the next.

    Returns
    -------
    tuple of float
        (v_{k+1} m/s, theta_{k+1} rad).
    """
    from ..model.flight import impact_velocity
    from ..data.simulated_lab import CycleRacket, next_contact

    (t_c, a_c), (t_n, a_n) = this, next_
    racket = CycleRacket(starts=np.array([0.0, t_c, t_c + t_n]),
                         periods=np.array([t_c, t_n, t_n]),
                         amplitudes=np.array([a_c, a_n, a_n]))
    t0 = t_c * theta_k / (2.0 * math.pi)
    x0 = float(racket.position(t0))
    t1 = next_contact(t0, x0, v_k, params.g, racket, t_c + 2.0 * t_n)
    v_before = v_k - params.g * (t1 - t0)
    v_next = impact_velocity(v_before, float(racket.velocity(t1)), params.alpha)
    return v_next, 2.0 * math.pi * (t1 - t_c) / t_n


# -- the model's prediction for a VARX estimate (what the estimator converges to) -------------
#: impacts simulated and dropped before each run (the launch at the fixed point relaxes as
#: |lambda|^k: 20 impacts leave less than 1e-5 of it at the paper's radii)
SIMULATION_BURN_IN = 20
#: sessions that end in sticking are drawn again, at most this many times per session
MAX_SIMULATION_RETRIES = 5


@dataclass(frozen=True)
class RacketSession:
    """What a simulated session needs besides the map's parameters: the racket's per-cycle
    variability and eq. 16's velocity noise (SI units)."""

    period_sd_s: float
    amplitude_sd_m: float
    velocity_noise_m_s: float


@dataclass(frozen=True)
class SimulatedRun:
    """One simulated run of consecutive impacts, in the impacts table's variables: velocity
    after impact (m/s), phase in the impact's racket cycle (rad, [0, 2 pi)) and that cycle's
    period (s) and amplitude (m)."""

    v_m_s: np.ndarray
    theta_rad: np.ndarray
    racket_period_s: np.ndarray
    racket_amplitude_m: np.ndarray


def simulate_runs(params: ModelParams, session: RacketSession, lengths: list[int],
                  seed: np.random.SeedSequence) -> tuple[list[SimulatedRun], int]:
    """Runs of the given lengths from the simulated lab (``data.simulated_lab``: eqs. 1-4 on a
    racket whose cycles have their own period and amplitude, white around tau and a_r with
    the given SDs, eq. 3 at each contact and eq. 16's velocity noise), each launched at the
    fixed point (eqs. 7-8) and its first ``SIMULATION_BURN_IN`` impacts dropped. The exact
    impacts, no measurement noise. A run that falls into sticking is drawn again.

    Parameters
    ----------
    params : ModelParams
        alpha, g and the mean racket (tau, a_r).
    session : RacketSession
        Per-cycle racket SDs and q_v.
    lengths : list of int
        Impacts per run.
    seed : numpy.random.SeedSequence
        One spawned stream per run (and per retry).

    Returns
    -------
    tuple
        (runs, sessions that fell into sticking and were drawn again).
    """
    from ..data.simulated_lab import SessionSettings, simulate_trial, truth_rows

    runs, redrawn = [], 0
    for n, run_seed in zip(lengths, seed.spawn(len(lengths))):
        duration = (n + SIMULATION_BURN_IN + 4) * params.racket_period * 1.25
        settings = SessionSettings(n_trials=1, duration_s=duration,
                                   period_sd_s=session.period_sd_s,
                                   amplitude_sd_m=session.amplitude_sd_m,
                                   velocity_noise_m_s=session.velocity_noise_m_s)
        for attempt in run_seed.spawn(MAX_SIMULATION_RETRIES):
            racket_seq, velocity_seq, alpha_seq = attempt.spawn(3)
            try:
                truth = simulate_trial(params, settings, (np.random.default_rng(racket_seq),
                                                          np.random.default_rng(velocity_seq),
                                                          np.random.default_rng(alpha_seq)))
            except ModelError:
                redrawn += 1
                continue
            rows = truth_rows(truth)
            keep = slice(SIMULATION_BURN_IN, SIMULATION_BURN_IN + n)
            if len(rows["v_m_s"][keep]) < n:
                raise ModelError(f"a simulated run of {duration:.3g} s has fewer than "
                                 f"{n + SIMULATION_BURN_IN} impacts")
            runs.append(SimulatedRun(rows["v_m_s"][keep], rows["theta_rad"][keep],
                                     rows["racket_period_s"][keep],
                                     rows["racket_amplitude_m"][keep]))
            break
        else:
            raise ModelError(f"the model's simulated sessions fall into sticking at this "
                             f"racket variability ({1e3 * session.period_sd_s:.3g} ms, "
                             f"{1e3 * session.amplitude_sd_m:.3g} mm per cycle) and noise "
                             f"({session.velocity_noise_m_s:.3g} m/s)")
    return runs, redrawn
