"""Sessions of the simulated lab for the data side's own predictions: the cycle-wise racket's
impact (the independent route of ``analysis.racket_inputs``' derivatives) and runs of the
model at a racket's per-cycle SDs, for the model's prediction of what a VARX fitted to such
data estimates (``experiments.data_side.varx_prediction``). They stand on the simulated lab
(``simulated_lab``: eqs. 1-4 on a racket whose cycles have their own period and amplitude).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.flight import impact_velocity
from ..model.params import ModelError, ModelParams
from .simulated_lab import (CycleRacket, SessionSettings, impact_state, next_contact,
                            simulate_trial)


def cycle_map_step(params: ModelParams, v_k: float, theta_k: float, this: tuple[float, float],
                   next_: tuple[float, float]) -> tuple[float, float]:
    """One impact of the cycle-wise racket by the simulated lab's own contact search (eqs. 1-3
    on ``simulated_lab``'s racket, not eqs. 5-6): the ball leaves impact k at phase
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
    runs, redrawn = [], 0
    for n, run_seed in zip(lengths, seed.spawn(len(lengths))):
        duration = (n + SIMULATION_BURN_IN + 4) * params.racket_period * 1.25
        settings = SessionSettings(n_trials=1, duration_s=duration,
                                   period_sd_s=session.period_sd_s,
                                   amplitude_sd_m=session.amplitude_sd_m,
                                   velocity_noise_m_s=session.velocity_noise_m_s)
        for _ in range(MAX_SIMULATION_RETRIES):
            # spawned one retry at a time: the same streams as spawn(MAX_SIMULATION_RETRIES)
            # (a child's key is its parent's and its index), without the unused ones
            attempt = run_seed.spawn(1)[0]
            racket_seq, velocity_seq, alpha_seq = attempt.spawn(3)
            try:
                truth = simulate_trial(params, settings, (np.random.default_rng(racket_seq),
                                                          np.random.default_rng(velocity_seq),
                                                          np.random.default_rng(alpha_seq)))
            except ModelError:
                redrawn += 1
                continue
            rows = impact_state(truth)  # (the full truth_rows: a third of the time)
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
