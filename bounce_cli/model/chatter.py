"""Exact sticking: complete chatter, the accumulation point, riding and release (eqs. 1-6
without section 3's 1 ms cut).

Relative to the racket the ball moves with the effective gravity (eq. 1 minus eq. 4)

    g_eff(theta) = g + racket acceleration = g - a_r w^2 sin(theta)          (m/s^2),

and after an impact at theta with relative velocity u = v - v_r(theta) > 0 it hops for about
2 u / g_eff and comes back with about u, leaving with alpha u (eq. 3). When g_eff > 0 the hops
shrink geometrically and infinitely many impacts accumulate at a finite time: a *complete
chatter*. The accumulation point is computed, not cut:

* the exact map (eqs. 5, 6) is iterated while the hops are resolvable, i.e. until the closed
  form below sums the rest to within ``TAIL_TOLERANCE_S``;
* the tail, from an impact at t_0 with relative velocity u_0, sums the remaining hops to
  first order in the variation of g_eff over the tail (g_1 = d g_eff / dt at t_0,
  kappa = g_1 u_0 / g_eff^2):

      T = 2 u_0 / (g_eff (1 - alpha)) [1 - 2 kappa / (3 (1 - alpha))]

  (each hop is tau = 2u/g_eff - (4/3) g_1 u^2 / g_eff^3 and the next u is
  alpha (u + (2/3) g_1 u^2 / g_eff^2), g_eff taken at the hop's start; summing the geometric
  series with the drift of g_eff along them gives the bracket). The neglected terms are of
  second order, T_0 (kappa^2 + u_0^2 |d^2 g_eff/dt^2| / g_eff^3) with T_0 = 2 u_0 / (g_eff
  (1 - alpha)) and |d^2 g_eff / dt^2| <= a_r w^4; ``tail_error_bound_s`` is that with the
  factor ``TAIL_ERROR_FACTOR`` (the tests check it against a 40-digit iteration of the map).

After the accumulation point the ball rides with the racket while the racket's acceleration is
above -g (g_eff > 0) and is released where it reaches -g, sin(theta) = 1 / Gamma with
Gamma = a_r w^2 / g and sin increasing (``release_phase``), with the racket's velocity; the
flight after a release starts with G = G' = G'' = 0 (``first_impact_phase(released=...)``).
When Gamma <= 1 no release comes: the ball rests on the racket.

Every orbit that sticks is released at the same phase modulo 2 pi, in the same state, so an
orbit that sticks twice is periodic from its first release: a *locked* orbit, whose period is
the number of racket cycles between two releases. At one parameter point all orbits that
stick share one release and hence one fate (``release_fate``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .impact import can_fly, first_impact_phase
from .params import ModelParams

TWO_PI = 2.0 * math.pi

#: the tail is summed in closed form once its error bound is below this, s
TAIL_TOLERANCE_S = 1e-12

#: factor on the first neglected order of the tail's closed form (measured against a 40-digit
#: iteration of the map at alpha 0.05-0.95 and phases all round the cycle: the actual error is
#: at most 0.72 times the order estimate for u <= 1e-3 m/s, 1.06 times at u = 1e-2 m/s; the
#: tail is used from u ~ 1e-5 m/s on, where the factor leaves a margin of about 3)
TAIL_ERROR_FACTOR = 2.0

#: event names of an exact orbit (``ExactOrbit.event``)
START, IMPACT, STICK, RELEASE, RESTING = "start", "impact", "stick", "release", "resting"


def effective_gravity(theta, params: ModelParams):
    """g_eff = g + racket acceleration = g - a_r w^2 sin(theta), m/s^2: the ball's
    acceleration toward the racket relative to it."""
    return params.g - params.racket_amplitude * params.omega**2 * np.sin(theta)


def release_phase(theta: float, params: ModelParams) -> float:
    """First phase >= theta at which a ball riding on the racket is released: where the
    racket's acceleration reaches -g (sin = 1/Gamma, sin increasing), or theta itself when
    the racket already accelerates downward faster than g there. ``inf`` when Gamma <= 1
    (the ball rests on the racket for ever).

    Parameters
    ----------
    theta : float
        Phase at which the ball starts riding, rad (unwrapped).
    params : ModelParams
        The model.

    Returns
    -------
    float
        The release phase, rad (unwrapped, >= theta), or ``inf``.
    """
    ratio = params.g / (params.racket_amplitude * params.omega**2)
    if ratio >= 1.0:
        return math.inf
    if math.sin(theta) > ratio:
        return float(theta)
    crossing = math.asin(ratio)
    return float(theta + np.mod(crossing - theta, TWO_PI))


def release_phases(theta, params):
    """``release_phase`` for arrays, with one parameter point per state (``params`` may be a
    ``bifurcation.ParameterArrays``): the first phase >= theta where sin = 1/Gamma with sin
    increasing, theta where the racket already accelerates downward faster than g, ``inf``
    where Gamma <= 1.

    Parameters
    ----------
    theta : array_like
        Phases at which the balls start riding, rad.
    params : ModelParams or ParameterArrays
        The model (per state).

    Returns
    -------
    ndarray
        Release phases, rad (unwrapped, >= theta), ``inf`` where never.
    """
    theta = np.asarray(theta, dtype=float)
    ratio = params.g / (params.racket_amplitude * params.omega**2)
    crossing = np.arcsin(np.minimum(ratio, 1.0))
    release = np.where(np.sin(theta) > ratio, theta, theta + np.mod(crossing - theta, TWO_PI))
    return np.where(ratio >= 1.0, np.inf, release)


def chatter_tail(theta, u, params: ModelParams):
    """Phase from an impact to the accumulation point of the chatter that follows it, and the
    error bound of that time (module docstring's closed form).

    Parameters
    ----------
    theta : array_like
        Phase of the impact, rad.
    u : array_like
        Relative velocity ball minus racket just after it, m/s (>= 0).
    params : ModelParams
        The model.

    Returns
    -------
    tail_phase : ndarray
        w T, rad; 0 where u <= 0; NaN where g_eff <= 0 (the hops do not shrink).
    error_bound_s : ndarray
        Bound on the error of T, s (inf where g_eff <= 0).
    """
    theta, u = np.broadcast_arrays(np.asarray(theta, dtype=float), np.asarray(u, dtype=float))
    alpha, a, w = params.alpha, params.racket_amplitude, params.omega
    g_eff = effective_gravity(theta, params)
    g_rate = -a * w**3 * np.cos(theta)  # d g_eff / dt
    u = np.maximum(u, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        leading = 2.0 * u / (g_eff * (1.0 - alpha))
        kappa = g_rate * u / (g_eff * g_eff)
        factor = 1.0 / (1.0 - alpha)
        tail_s = leading * (1.0 - 2.0 / 3.0 * kappa * factor)
        second_order = kappa * kappa + u * u * a * w**4 / g_eff**3
        bound = TAIL_ERROR_FACTOR * leading * second_order * factor * factor
    shrinking = g_eff > 0.0
    tail_phase = np.where(shrinking, w * tail_s, np.nan)
    bound = np.where(shrinking, bound, np.inf)
    return tail_phase, bound


def tail_is_summable(theta, u, params: ModelParams, tolerance_s: float = TAIL_TOLERANCE_S):
    """True where the chatter after an impact (phase theta, relative velocity u) is complete
    and its tail's closed form is within ``tolerance_s``: the accumulation point is then
    theta + ``chatter_tail``."""
    _, bound = chatter_tail(theta, u, params)
    return bound <= tolerance_s


@dataclass(frozen=True)
class ExactOrbit:
    """The hybrid orbit: one row per event, in time order.

    ``event``: "start" (row 0: the initial condition), "impact" (an impact resolved by the
    map), "stick" (the accumulation point of a complete chatter: the ball moves with the
    racket from here), "release" (the racket's acceleration reached -g: the ball leaves with
    the racket's velocity), "resting" (stuck with Gamma <= 1: no release ever). ``theta``
    (rad, unwrapped), ``v`` (m/s: after the impact; the racket's at stick and release),
    ``flight`` (phase since the previous event, rad, NaN at row 0 and at a release),
    ``chatter_impacts`` (at a stick: the resolved impacts of the chatter, i.e. of the run of
    shrinking hops that accumulates; else 0), ``tail_error_s`` (at a stick: the bound on its
    time; else 0). ``stop_reason``: "" | "below_racket" | "resting".
    """

    event: tuple[str, ...]
    theta: np.ndarray
    v: np.ndarray
    flight: np.ndarray
    chatter_impacts: np.ndarray
    tail_error_s: np.ndarray
    stop_reason: str

    def rows(self, kind: str) -> np.ndarray:
        """Indices of the events of one kind."""
        return np.flatnonzero(np.asarray(self.event, dtype=object) == kind)


def iterate_exact_orbit(theta0: float, v0: float, params: ModelParams, n_impacts: int,
                        *, max_events: int | None = None,
                        start_released: bool = False,
                        until_theta: float = math.inf) -> ExactOrbit:
    """The hybrid motion from a ball leaving the racket at (theta0 rad, v0 m/s): the map
    (eqs. 5, 6) while hops are resolvable, complete chatters summed to their accumulation
    points, riding and release (module docstring).

    Parameters
    ----------
    theta0, v0 : float
        Phase (rad) and velocity (m/s) with which the ball leaves the racket.
    params : ModelParams
        The model.
    n_impacts : int
        Resolved impacts to compute at most.
    max_events : int, optional
        Events at most (default: no limit beyond ``n_impacts``).
    start_released : bool
        The start is a release point (v0 the racket's velocity, the racket's acceleration
        -g): row 0 is then a "release" event and the first flight starts with G = G' = G''
        = 0.
    until_theta : float
        Stop after the first event at or beyond this phase, rad (a simulated duration).

    Returns
    -------
    ExactOrbit
    """
    w = params.omega
    events = [RELEASE if start_released else START]
    theta, v, flight = [float(theta0)], [float(v0)], [math.nan]
    chatter, tail_error = [0], [0.0]
    released, impacts, run, last_hop = start_released, 0, 0, math.inf
    reason = "" if start_released or can_fly(theta0, v0, params) else "below_racket"
    while not reason and impacts < n_impacts and theta[-1] < until_theta and (
            max_events is None or len(events) < max_events):
        hop = float(first_impact_phase(theta[-1], v[-1], params.racket_amplitude, w, params.g,
                                       released=released))
        if not math.isfinite(hop):  # grazing departure that cannot fly (never seen)
            reason = "resting"
            break
        th = theta[-1] + hop
        vn = float((1.0 + params.alpha) * params.racket_amplitude * w * math.cos(th)
                   - params.alpha * v[-1] + params.g * params.alpha / w * hop)
        impacts += 1
        if effective_gravity(th, params) > 0.0:  # the run of shrinking hops it may end
            run = run + 1 if hop < last_hop else 1
        else:
            run = 0
        last_hop = hop
        events.append(IMPACT)
        theta.append(th)
        v.append(vn)
        flight.append(hop)
        chatter.append(0)
        tail_error.append(0.0)
        released = False
        u = vn - float(params.racket_velocity(th))
        tail, bound = (float(x) for x in chatter_tail(th, u, params))
        if not bound <= TAIL_TOLERANCE_S:
            continue
        th_stick = th + tail
        events.append(STICK)
        theta.append(th_stick)
        v.append(float(params.racket_velocity(th_stick)))
        flight.append(tail)
        chatter.append(run)
        tail_error.append(bound)
        th_release = release_phase(th_stick, params)
        if not math.isfinite(th_release):
            reason = "resting"
            events.append(RESTING)
            theta.append(th_stick)
            v.append(v[-1])
            flight.append(math.nan)
            chatter.append(0)
            tail_error.append(0.0)
            break
        events.append(RELEASE)
        theta.append(th_release)
        v.append(float(params.racket_velocity(th_release)))
        flight.append(math.nan)
        chatter.append(0)
        tail_error.append(0.0)
        released, run, last_hop = True, 0, math.inf
    return ExactOrbit(tuple(events), np.array(theta), np.array(v), np.array(flight),
                      np.array(chatter, dtype=np.int64), np.array(tail_error), reason)


def locked_period(orbit: ExactOrbit) -> int:
    """Racket cycles between the last two releases of an exact orbit (0: fewer than two).
    From its first release on an orbit is periodic with this period (module docstring)."""
    releases = orbit.rows(RELEASE)
    if releases.size < 2:
        return 0
    return int(round((orbit.theta[releases[-1]] - orbit.theta[releases[-2]]) / TWO_PI))


@dataclass(frozen=True)
class ReleaseFate:
    """Where the orbit from the release point goes, which every orbit that sticks shares.

    ``kind``: "locked" (it sticks again: periodic, ``cycles`` racket cycles between
    releases, ``impacts`` resolved impacts per period), "resting" (Gamma <= 1), "period1"
    (it reaches eq. 8's fixed point within ``tolerance``), "undecided" (neither within the
    impacts allowed).
    """

    kind: str
    cycles: int
    impacts: int


def release_fate(params: ModelParams, max_impacts: int, tolerance: float,
                 fixed_point=None) -> ReleaseFate:
    """The fate of the orbit from the release point (``ReleaseFate``).

    Parameters
    ----------
    params : ModelParams
        The model.
    max_impacts : int
        Resolved impacts to follow the released ball for at most.
    tolerance : float
        Period-1 when |v - v~| < tolerance (m/s) and the wrapped |theta - theta~| < tolerance
        (rad) after an impact (the basin's test, section 3).
    fixed_point : FixedPoint, optional
        The period-1 fixed point (eqs. 7, 8); None: none is looked for.

    Returns
    -------
    ReleaseFate
    """
    return _release_fate(params, int(max_impacts), float(tolerance),
                         None if fixed_point is None else (fixed_point.v_m_s,
                                                           fixed_point.theta_rad))


@functools.lru_cache(maxsize=256)
def _release_fate(params: ModelParams, max_impacts: int, tolerance: float,
                  fixed_point: tuple[float, float] | None) -> ReleaseFate:
    from .params import phase_difference

    start = release_phase(0.0, params)
    if not math.isfinite(start):
        return ReleaseFate("resting", 0, 0)
    orbit = iterate_exact_orbit(start, float(params.racket_velocity(start)), params,
                                max_impacts, start_released=True)
    # the first event is the release itself (row 0); the next release closes the period
    impacts = 0
    for k in range(1, len(orbit.event)):
        kind = orbit.event[k]
        if kind == IMPACT:
            impacts += 1
            if fixed_point is not None and (
                    abs(orbit.v[k] - fixed_point[0]) < tolerance
                    and abs(float(phase_difference(orbit.theta[k], fixed_point[1])))
                    < tolerance):
                return ReleaseFate("period1", 0, impacts)
        elif kind == RELEASE:
            cycles = int(round((orbit.theta[k] - start) / TWO_PI))
            return ReleaseFate("locked", cycles, impacts)
    return ReleaseFate("undecided", 0, impacts)
