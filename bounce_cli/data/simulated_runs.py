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
from .lab_contact import CONTACT_TOLERANCE_M, MAX_CONTACT_STEPS
from .simulated_lab import (CycleRacket, SessionSettings, TrialTruth, _draw_racket,
                            impact_state, next_contact, simulate_trial)


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
    return simulate_sessions(params, session, lengths, [seed])[0]


def simulate_sessions(params: ModelParams, session: RacketSession, lengths: list[int],
                      seeds: list[np.random.SeedSequence]
                      ) -> list[tuple[list[SimulatedRun], int]]:
    """:func:`simulate_runs` for each of ``seeds``, every run of every session simulated at
    once (:func:`_contacts_at_once`): the same draws and the same arithmetic as
    ``simulated_lab.simulate_trial``'s loop, one run after another, so the same impacts bit
    for bit (``tests/engine/test_simulated_sessions.py``), without a Python loop per contact
    or numba's start-up (half a second per process).

    Parameters
    ----------
    params, session, lengths
        As :func:`simulate_runs`.
    seeds : list of numpy.random.SeedSequence
        One per session.

    Returns
    -------
    list of tuple
        Per session, what :func:`simulate_runs` returns.
    """
    settings = [SessionSettings(n_trials=1, duration_s=run_duration(params, n),
                                period_sd_s=session.period_sd_s,
                                amplitude_sd_m=session.amplitude_sd_m,
                                velocity_noise_m_s=session.velocity_noise_m_s)
                for n in lengths]
    runs: list[list[SimulatedRun | None]] = [[None] * len(lengths) for _ in seeds]
    redrawn = [0] * len(seeds)
    run_seeds = [seed.spawn(len(lengths)) for seed in seeds]
    todo = [(i, j) for i in range(len(seeds)) for j in range(len(lengths))]
    for _ in range(MAX_SIMULATION_RETRIES):
        drawn, failed = [], []
        for i, j in todo:
            # spawned one retry at a time: the same streams as spawn(MAX_SIMULATION_RETRIES)
            # (a child's key is its parent's and its index), without the unused ones
            attempt = run_seeds[i][j].spawn(1)[0]
            try:
                drawn.append((i, j, _drawn_run(params, settings[j], attempt)))
            except ModelError:  # a period or amplitude drawn <= 0
                failed.append((i, j))
        outcomes = _contacts_at_once(params, [d for _, _, d in drawn],
                                     [settings[j] for _, j, _ in drawn])
        for (i, j, run), outcome in zip(drawn, outcomes):
            if isinstance(outcome, ModelError):
                failed.append((i, j))
                continue
            if outcome is None:  # more impacts than drawn noise: simulate_trial's own loop
                try:
                    truth = simulate_trial(params, settings[j], run.streams())
                except ModelError:
                    failed.append((i, j))
                    continue
                rows = impact_state(truth)
                outcome = (rows["v_m_s"], rows["theta_rad"], rows["racket_period_s"],
                           rows["racket_amplitude_m"])
            runs[i][j] = _kept(outcome, lengths[j], settings[j].duration_s)
        for i, _ in failed:
            redrawn[i] += 1
        todo = sorted(failed)
        if not todo:
            break
    if todo:
        raise ModelError(f"the model's simulated sessions fall into sticking at this "
                         f"racket variability ({1e3 * session.period_sd_s:.3g} ms, "
                         f"{1e3 * session.amplitude_sd_m:.3g} mm per cycle) and noise "
                         f"({session.velocity_noise_m_s:.3g} m/s)")
    return [([r for r in session_runs if r is not None], again)
            for session_runs, again in zip(runs, redrawn)]


def run_duration(params: ModelParams, n: int) -> float:
    """The duration of a simulated run of ``n`` impacts: its burn-in and a margin included."""
    return (n + SIMULATION_BURN_IN + 4) * params.racket_period * 1.25


def _kept(state, n: int, duration: float) -> SimulatedRun:
    """The run's impacts after the burn-in, ``n`` of them."""
    keep = slice(SIMULATION_BURN_IN, SIMULATION_BURN_IN + n)
    v, theta, period, amplitude = state
    if len(v[keep]) < n:
        raise ModelError(f"a simulated run of {duration:.3g} s has fewer than "
                         f"{n + SIMULATION_BURN_IN} impacts")
    return SimulatedRun(v[keep], theta[keep], period[keep], amplitude[keep])


@dataclass
class _DrawnRun:
    """A run's racket and velocity noise drawn from its attempt's streams, as
    ``simulate_trial`` draws them (the racket's periods then amplitudes; the noise of each
    impact in turn, drawn ahead)."""

    attempt: np.random.SeedSequence
    racket: CycleRacket
    bounds: np.ndarray  # g + max |x_r''| before the first cycle, then per cycle
    draws: np.ndarray

    def streams(self):
        racket_seq, velocity_seq, alpha_seq = self.attempt.spawn(3)
        return (np.random.default_rng(racket_seq), np.random.default_rng(velocity_seq),
                np.random.default_rng(alpha_seq))


def _drawn_run(params: ModelParams, settings: SessionSettings,
               attempt: np.random.SeedSequence) -> _DrawnRun:
    racket_seq, velocity_seq, _ = attempt.spawn(3)
    racket = _draw_racket(params, settings, np.random.default_rng(racket_seq))
    omega = 2.0 * np.pi / racket.periods
    # CycleRacket.acceleration_bound's square, by the C library's pow as Python's ** takes
    # it (an array's **2 multiplies, which differs in the last bit about once in a thousand)
    squares = np.array([w**2 for w in omega.tolist()])
    bounds = params.g + np.concatenate([[0.0], 0.0 + racket.amplitudes * squares])
    capacity = 2 * len(racket.starts) + 16
    draws = np.random.default_rng(velocity_seq).standard_normal(capacity)
    return _DrawnRun(attempt, racket, bounds, draws)


def _contacts_at_once(params: ModelParams, runs: list[_DrawnRun],
                      settings: list[SessionSettings]) -> list:
    """``simulate_trial``'s contact loop on the common path (``simulated_lab.next_contact``'s
    safe steps, eq. 3 and eq. 16's noise at each contact, the sticking checks), every run at
    once: each pass takes one safe step of every run still flying, in the same expressions
    and order as the scalar loop (numpy's elementwise arithmetic, sin and cos are the scalar
    ones, so the impacts are the same bits). Per run: (v, theta, period, amplitude) of its
    impacts at t >= 0, a ModelError (sticking, a grazing flight) or None (more impacts than
    its drawn noise)."""
    count = len(runs)
    if count == 0:
        return []
    g, alpha = params.g, params.alpha
    cycles = np.array([len(r.racket.starts) for r in runs])
    width = int(cycles.max())
    starts = np.full((count, width + 1), np.inf)
    omegas = np.ones((count, width))
    amplitudes = np.zeros((count, width))
    bounds = np.ones((count, width + 1))
    capacity = np.array([len(r.draws) for r in runs])
    draws = np.zeros((count, int(capacity.max())))
    for i, run in enumerate(runs):
        n = cycles[i]
        starts[i, :n] = run.racket.starts
        omegas[i, :n] = 2.0 * np.pi / run.racket.periods
        amplitudes[i, :n] = run.racket.amplitudes
        bounds[i, :n + 1] = run.bounds
        draws[i, :capacity[i]] = run.draws
    end_last = np.array([r.racket.ends[-1] for r in runs])
    t_max = np.array([s.duration_s for s in settings])
    min_hop = np.array([s.min_hop_s for s in settings])
    q = np.array([s.velocity_noise_m_s for s in settings])
    fp = params.fixed_point()
    rows = np.arange(count)

    def position(i, c, t):
        return amplitudes[i, c] * np.sin(omegas[i, c] * (t - starts[i, c]))

    def velocity(i, c, t):
        return amplitudes[i, c] * omegas[i, c] * np.cos(omegas[i, c] * (t - starts[i, c]))

    # the launch at the fixed point, in the first cycle (simulate_trial's)
    t = starts[:, 0] + fp.theta_rad / params.omega
    cycle = np.count_nonzero(starts <= t[:, None], axis=1) - 1
    x = position(rows, cycle, t)
    t0, x0, v0 = t.copy(), x, np.full(count, fp.v_m_s)
    steps = np.zeros(count, dtype=np.int64)
    used = np.zeros(count, dtype=np.intp)
    hits_t = np.empty(draws.shape)  # an impact uses a draw: at most as many as drawn
    hits_v = np.empty(draws.shape)
    n_hits = np.zeros(count, dtype=np.intp)
    outcome: list = [True] * count  # the run's end (True: it ran to t_max)
    flying = np.ones(count, dtype=bool)

    def ends(which, why) -> None:
        for run in which:
            if flying[run]:
                outcome[run] = why(run)
                flying[run] = False

    bound = np.empty(count)
    seg_end = np.empty(count)
    entering = np.ones(count, dtype=bool)  # next_contact's outer loop: a new segment
    live = rows.copy()
    while live.size:
        # next_contact's outer loop: the cycle holding t, its bound and the segment's end
        enter = live[entering[live]]
        if enter.size:
            over = t[enter] >= t_max[enter]
            flying[enter[over]] = False  # no contact before t_max: the trial is over
            enter = enter[~over]
            c = cycle[enter]
            bound[enter] = bounds[enter, c + 1]
            after = c + 1 < cycles[enter]
            seg = np.where(after, starts[enter, np.minimum(c + 1, width)],
                           np.where(t[enter] < end_last[enter], end_last[enter], np.inf))
            seg_end[enter] = np.where(t_max[enter] < seg, t_max[enter], seg)
            entering[enter] = False
            live = live[flying[live]]
            if not live.size:
                break
        i = live
        c = cycle[i]
        dt = t[i] - t0[i]
        gap = x0[i] + v0[i] * dt - 0.5 * g * dt * dt - position(i, c, t[i])
        slope = v0[i] - g * dt - velocity(i, c, t[i])
        hit = (t[i] > t0[i]) & (gap <= CONTACT_TOLERANCE_M)
        # the flights that meet the racket: Newton's polish, eq. 3, the noise, the checks
        k = i[hit]
        if k.size:
            t_hit = t[k].copy()
            down = slope[hit] < 0.0
            t_hit[down] -= gap[hit][down] / slope[hit][down]
            c_hit = cycle[k] - (t_hit < starts[k, cycle[k]])  # the polish may step back
            v_before = v0[k] - g * (t_hit - t0[k])
            racket_v = velocity(k, c_hit, t_hit)
            hop = t_hit - t0[k]
            v_new = racket_v - alpha * (v_before - racket_v)
            short = used[k] >= capacity[k]
            v_new = v_new + q[k] * draws[k, np.minimum(used[k], draws.shape[1] - 1)]
            x_release = position(k, c_hit, t_hit)
            leaves = v_new > racket_v
            ends(k[short], lambda run: None)
            counted = t_hit >= 0.0
            sticks = counted & ~short & ((hop < min_hop[k]) | ~leaves)
            ends(k[sticks], lambda run: ModelError(
                f"the ball fell into sticking at t = {t[run]:.3f} s"))
            record = counted & ~short & ~sticks
            rec = k[record]
            hits_t[rec, n_hits[rec]] = t_hit[record]
            hits_v[rec, n_hits[rec]] = v_new[record]
            n_hits[rec] += 1
            used[k] += 1
            t[k], t0[k], x0[k], v0[k] = t_hit, t_hit, x_release, v_new
            cycle[k] = c_hit
            steps[k] = 0
            entering[k] = True
        # the others take their safe step
        m = ~hit
        j = i[m]
        if j.size:
            gap_m, slope_m, bound_m = gap[m], slope[m], bound[j]
            step = (slope_m + np.sqrt(slope_m * slope_m + 2.0 * bound_m
                                      * np.maximum(gap_m, 0.0))) / bound_m
            steps[j] += 1
            ends(j[steps[j] > MAX_CONTACT_STEPS], lambda run: ModelError(
                f"no contact found after t = {t0[run]:.6g} s (grazing flight)"))
            ends(j[step <= 0.0], lambda run: ModelError(
                f"the ball cannot leave the racket at t = {t0[run]:.6g} s"))
            cross = t[j] + step >= seg_end[j]
            onto = j[cross]
            t[onto] = seg_end[onto]
            cycle[onto] = np.where(seg_end[onto] >= starts[onto, np.minimum(cycle[onto] + 1,
                                                                             width)],
                                   cycle[onto] + 1, cycle[onto])
            entering[onto] = True
            ahead = j[~cross]
            t[ahead] = t[ahead] + step[~cross]
        live = live[flying[live]]
    results: list = []
    for i, run in enumerate(runs):
        if outcome[i] is not True:
            results.append(outcome[i])
            continue
        hits = slice(0, n_hits[i])
        state = impact_state(TrialTruth(run.racket, np.zeros(0), np.zeros(0), np.zeros(0),
                                        hits_t[i, hits], hits_v[i, hits], np.zeros(0),
                                        np.zeros(0), settings[i].duration_s, g))
        results.append((state["v_m_s"], state["theta_rad"], state["racket_period_s"],
                        state["racket_amplitude_m"]))
    return results
