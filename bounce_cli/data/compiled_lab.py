"""The simulated lab's common path compiled with numba: ``simulated_lab.simulate_trial``'s
contact loop, bit for bit.

The common path is the model's own session: a cycle-wise racket (each cycle its own period
and amplitude) with no drift, harmonic or disturbance, instantaneous contacts, no restitution
SD, no perturbations, no controller and no rest before the first cycle; it is what
``data.simulated_runs.simulate_runs`` simulates for the data side's VARX calibration (about
a hundred sessions a unit). There ``simulate_trial`` spends almost all of its time in
``next_contact``'s safe steps, each a handful of numpy calls on 0-d arrays (about 10 us a
step); here the same steps take well under a microsecond.

Bit-for-bit: every expression is the Python code's in the same order (IEEE double, no
fast-math, so no fused multiply-adds), the per-cycle bounds M are computed in Python by
``CycleRacket.acceleration_bound`` itself, sin/cos/sqrt are the C library's as numpy's are,
and the velocity noise is the same stream: drawn ahead as one array (a Generator's array of
standard normals is its scalar draws in turn), the generator then put back and advanced by
exactly the draws used, so that it ends where the Python loop leaves it. Where the drawn
array would not suffice (more impacts than twice the cycles), the Python loop runs instead.
``tests/engine/test_compiled_lab.py`` compares the two routes on fixed seeds.

Environment variable ``BOUNCE_LAB=python`` turns this route off (the reference route of
``benchmarks/study.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .lab_contact import CONTACT_TOLERANCE_M, MAX_CONTACT_STEPS

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")

TWO_PI = 2.0 * np.pi  # CycleRacket._cycle's 2.0 * np.pi

#: status codes of the loop
OK, STICKING_HOP, STICKING_SLOW, GRAZING, CANNOT_LEAVE, OUT_OF_DRAWS = range(6)


@_jit
def _bisect_right(a, x):
    """np.searchsorted(a, x, side="right") for a sorted array."""
    lo, hi = 0, a.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@_jit
def _cycle(starts, periods, amplitudes, t):
    """CycleRacket._cycle: (amplitude, omega, theta) at t (amplitude 0 before the first)."""
    c = _bisect_right(starts, t) - 1
    cc = c if c >= 0 else 0
    omega = TWO_PI / periods[cc]
    theta = omega * (t - starts[cc])
    return (amplitudes[cc] if c >= 0 else 0.0), omega, theta


@_jit
def _position(starts, periods, amplitudes, t):
    """CycleRacket.position without drift, harmonic or disturbance (their terms are zeros)."""
    amp, omega, theta = _cycle(starts, periods, amplitudes, t)
    return amp * math.sin(theta)


@_jit
def _velocity(starts, periods, amplitudes, t):
    """CycleRacket.velocity likewise: (amp * omega) * cos(theta)."""
    amp, omega, theta = _cycle(starts, periods, amplitudes, t)
    return amp * omega * math.cos(theta)


@_jit
def _next_contact(t0, x0, v0, g, starts, periods, amplitudes, bounds, end_last, t_max):
    """simulated_lab.next_contact: (time, status); ``bounds[c + 1]`` is g + M of cycle c."""
    t = t0
    steps = 0
    n = starts.shape[0]
    while t < t_max:
        c = _bisect_right(starts, t) - 1
        bound = bounds[c + 1]
        i = c + 1  # segment_end
        if i < n:
            seg = starts[i]
        elif t < end_last:
            seg = end_last
        else:
            seg = np.inf
        seg_end = t_max if t_max < seg else seg  # Python's min(seg, t_max)
        while True:
            dt = t - t0
            gap = x0 + v0 * dt - 0.5 * g * dt * dt - _position(starts, periods, amplitudes, t)
            slope = v0 - g * dt - _velocity(starts, periods, amplitudes, t)
            if t > t0 and gap <= CONTACT_TOLERANCE_M:
                if slope < 0.0:
                    t -= gap / slope
                return t, OK
            gap_pos = 0.0 if 0.0 > gap else gap  # Python's max(gap, 0.0)
            step = (slope + math.sqrt(slope * slope + 2.0 * bound * gap_pos)) / bound
            steps += 1
            if steps > MAX_CONTACT_STEPS:
                return t0, GRAZING
            if step <= 0.0:
                return t0, CANNOT_LEAVE
            if t + step >= seg_end:
                t = seg_end
                break
            t += step
    return np.inf, OK


@_jit
def _contact_loop(starts, periods, amplitudes, bounds, end_last, t, x, v, g, alpha, q,
                  draws, t_end, min_hop, flights, impacts):
    """simulate_trial's loop on the common path. ``flights`` (rows t, x, v) and ``impacts``
    (rows t, v after, v before) are filled; returns (flights, impacts, draws used, status,
    the time and hop the status refers to)."""
    n_flights, n_impacts, used = 0, 0, 0
    flights[0, 0], flights[1, 0], flights[2, 0] = t, x, v
    n_flights = 1
    while True:
        t_hit, status = _next_contact(t, x, v, g, starts, periods, amplitudes, bounds,
                                      end_last, t_end)
        if status != OK:
            return n_flights, n_impacts, used, status, t_hit, 0.0
        if not math.isfinite(t_hit):
            return n_flights, n_impacts, used, OK, t_hit, 0.0
        v_before = v - g * (t_hit - t)
        racket_v = _velocity(starts, periods, amplitudes, t_hit)
        hop = t_hit - t
        v_new = racket_v - alpha * (v_before - racket_v)
        if used >= draws.shape[0] or n_flights >= flights.shape[1]:
            return n_flights, n_impacts, used, OUT_OF_DRAWS, t_hit, hop
        v_new += q * draws[used]
        used += 1
        x_release = _position(starts, periods, amplitudes, t_hit)
        leaves = v_new > racket_v
        if t_hit >= 0.0 and hop < min_hop:
            return n_flights, n_impacts, used, STICKING_HOP, t_hit, hop
        if t_hit >= 0.0 and not leaves:
            return n_flights, n_impacts, used, STICKING_SLOW, t_hit, hop
        if t_hit >= 0.0:
            impacts[0, n_impacts], impacts[1, n_impacts] = t_hit, v_new
            impacts[2, n_impacts] = v_before
            n_impacts += 1
        t, x, v = t_hit, x_release, v_new
        flights[0, n_flights], flights[1, n_flights], flights[2, n_flights] = t, x, v
        n_flights += 1


def _bounds(racket, g: float) -> np.ndarray:
    """g + ``racket.acceleration_bound(c)`` for c = -1, 0, ..., by its own expressions on the
    common path (its drift and disturbance terms are 0.0), the cycles' at once: only the
    square is taken per cycle, by the C library's pow as numpy's scalar ``**`` takes it (an
    array's ``**2`` multiplies, which differs in the last bit about once in a thousand)."""
    omega = 2.0 * np.pi / racket.periods
    squares = np.array([w**2 for w in omega.tolist()])
    moving = (racket.amplitudes + 4.0 * abs(racket.harmonic2)) * squares
    return g + np.concatenate([[0.0], 0.0 + moving])


def contact_loop(racket, params, settings, t, x, v, rng_velocity):
    """Run the compiled loop for ``simulate_trial`` (the racket drawn, the launch (t, x, v)
    computed there). Returns (flights (3, F), impacts (3, N)) or raises the Python loop's
    ModelError; None where the drawn noise did not suffice (the generator is then as it was
    given: the caller runs the Python loop)."""
    from ..model.params import ModelError

    n_cycles = len(racket.starts)
    bounds = _bounds(racket, params.g)
    state = rng_velocity.bit_generator.state
    capacity = 2 * n_cycles + 16
    draws = rng_velocity.standard_normal(capacity)
    flights = np.empty((3, capacity + 1))
    impacts = np.empty((3, capacity))
    n_flights, n_impacts, used, status, t_at, hop = _contact_loop(
        racket.starts, racket.periods, racket.amplitudes, bounds, float(racket.ends[-1]),
        t, x, v, params.g, params.alpha, settings.velocity_noise_m_s, draws,
        settings.duration_s, settings.min_hop_s, flights, impacts)
    rng_velocity.bit_generator.state = state
    if status == OUT_OF_DRAWS:
        return None
    rng_velocity.standard_normal(used)  # the generator where the Python loop leaves it
    if status in (STICKING_HOP, STICKING_SLOW):
        why = (f"a hop of {hop:.3g} s" if status == STICKING_HOP else
               "it leaves the racket no faster than the racket moves")
        raise ModelError(
            f"the ball fell into sticking at t = {t_at:.3f} s ({why}): lower "
            "velocity_noise_m_s, the racket's variation or the perturbations, or change "
            "the model parameters")
    if status == GRAZING:
        raise ModelError(f"no contact found after t = {t_at:.6g} s (grazing flight)")
    if status == CANNOT_LEAVE:
        raise ModelError(f"the ball cannot leave the racket at t = {t_at:.6g} s")
    return flights[:, :n_flights].copy(), impacts[:, :n_impacts].copy()
