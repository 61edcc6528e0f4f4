"""Continuous-time motion of ball and racket (eqs. 1-4), with sticking (section 3, Fig. 3).

The ball flies ballistically (eqs. 1, 2) above the sinusoidal racket (eq. 4) and bounces off
it by the impact law eq. 3 with the racket much heavier than the ball:

    v_b+ = v_r - alpha (v_b- - v_r),   v_r = a_r w cos(w t).

Sticking: when impacts accumulate (a hop shorter than ``min_hop_s``, or a relative velocity
after impact of at most ``min_relative_velocity_m_s``), the ball rides on the racket until the
racket decelerates faster than gravity, a_r w^2 sin(w t) > g, where it leaves with the
racket's velocity. The leave phase is found analytically: the next phase >= the sticking
phase where sin(theta) = g / (a_r w^2) while sin is increasing (arcsin, first quadrant), or at
once when sin(theta) already exceeds it. When a_r w^2 <= g the racket never outruns gravity
and the ball stays stuck to the end.

Two integrators:

* ``exact``: analytic flight, impacts from the first-impact solver ``next_impact_phase``;
* ``rk4``: the paper's method, a fixed-step fourth-order Runge-Kutta integration of the
  ball's ODE (x' = v, v' = -g), an impact located inside the step where the gap (ball minus
  racket height, with the ball from the cubic Hermite interpolant of the step) changes sign.
  Hops shorter than a sixteenth of a step are not resolved and count as sticking.

All times in s, positions in m, velocities in m/s, phases in rad (theta = w t, unwrapped).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .chatter import IMPACT, RELEASE, STICK, iterate_exact_orbit, release_phase
from .maps import ClassifySettings
from .impact import can_fly, first_impact_phase
from .params import ModelError, ModelParams

INTEGRATORS = ("exact", "rk4")

#: phase (rad) after the leave point from which the exact integrator hands the flight to the
#: first-impact solver: at the leave point G' = G'' = 0 (the solver needs G'' > 0); the ball is
#: then a_r cos(theta) d^3 / 6 ~ 4e-14 m above the racket, which is neglected (the flight
#: itself is kept exact from the leave point).
LEAVE_NUDGE_PHASE = 1e-4

#: sub-intervals sampled per RK4 step to find the first sign change of the gap
RK4_SUBSAMPLES = 16



class FlightEnd(enum.Enum):
    """How a flight ends when it does not end in an impact."""

    #: the flight lasts beyond the end of the run
    BEYOND_END = "beyond_end"
    #: rk4: the ball is below the racket after one step with no crossing resolved inside it
    #: (a hop shorter than a sub-step); treated as sticking
    UNRESOLVED = "unresolved"


@dataclass(frozen=True)
class FlightSettings:
    """How the continuous motion is integrated and when the ball counts as stuck."""

    integrator: str = "exact"
    rk4_step_s: float = 1e-3  # the paper's RK4 step (section 3)
    #: section 3's sticking criterion; 0: exact sticking (``model.chatter``, integrator
    #: exact only; ``min_relative_velocity_m_s`` is then not used)
    min_hop_s: float = ClassifySettings().min_hop_s
    min_relative_velocity_m_s: float = 1e-3

    def __post_init__(self) -> None:
        if self.integrator not in INTEGRATORS:
            raise ModelError(f"integrator must be one of {INTEGRATORS} (got {self.integrator!r})")
        for name in ("rk4_step_s", "min_hop_s", "min_relative_velocity_m_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ModelError(f"{name} must be a finite number >= 0 (got {value!r})")
        if self.rk4_step_s <= 0.0:
            raise ModelError(f"rk4_step_s must be > 0 (got {self.rk4_step_s!r})")
        if self.min_hop_s == 0.0 and self.integrator != "exact":
            raise ModelError("min_hop_s 0 (exact sticking) needs integrator exact: a fixed "
                             "step cannot resolve a complete chatter's shrinking hops")


@dataclass(frozen=True)
class Segment:
    """A piece of the ball's motion on [t_start, t_end].

    kind "flight": x(t) = x_start + v_start (t - t_start) - g (t - t_start)^2 / 2 (eqs. 1, 2);
    kind "stuck": the ball moves with the racket (x_start, v_start are the racket's);
    kind "chatter" (exact sticking): the tail of a complete chatter, infinitely many hops
    from the last resolved impact to the accumulation point, all within u^2 / (2 g_eff) (about
    1e-11 m) of the racket: sampled as the racket.
    """

    kind: str
    t_start: float
    t_end: float
    x_start: float
    v_start: float


@dataclass(frozen=True)
class Impact:
    """One impact (eq. 3) at time t_s, phase theta_rad (unwrapped)."""

    t_s: float
    theta_rad: float
    v_before_m_s: float
    v_after_m_s: float
    racket_v_m_s: float
    hop_s: float  # flight time since the ball last left the racket


@dataclass(frozen=True)
class Trajectory:
    """Result of ``simulate``: pieces of motion and the impacts between them."""

    params: ModelParams
    t0: float
    t_end: float
    segments: tuple[Segment, ...]
    impacts: tuple[Impact, ...]
    #: exact sticking: times (s) of the accumulation points of complete chatters
    accumulations: tuple[float, ...] = ()

    @property
    def stuck_phases(self) -> list[tuple[float, float]]:
        """(start, end) times of the stuck phases."""
        return [(s.t_start, s.t_end) for s in self.segments if s.kind == "stuck"]

    def sample(self, t):
        """Ball position, velocity and stuck flag at times t (inside [t0, t_end]).

        At a time shared by two segments (an impact, a leave) the later segment is used.
        """
        t = np.asarray(t, dtype=float)
        starts = np.array([s.t_start for s in self.segments])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
        x = np.empty_like(t)
        v = np.empty_like(t)
        stuck = np.zeros(t.shape, dtype=bool)
        p = self.params
        for i, seg in enumerate(self.segments):
            m = idx == i
            if not np.any(m):
                continue
            if seg.kind == "flight":
                dt = t[m] - seg.t_start
                x[m] = seg.x_start + seg.v_start * dt - 0.5 * p.g * dt * dt
                v[m] = seg.v_start - p.g * dt
            else:
                x[m] = p.racket_position(p.omega * t[m])
                v[m] = p.racket_velocity(p.omega * t[m])
                stuck[m] = seg.kind == "stuck"
        return x, v, stuck


def leave_phase(theta, params: ModelParams) -> float:
    """First phase >= theta at which a ball resting on the racket leaves it: where the
    racket's downward acceleration reaches g (a_r w^2 sin = g, sin increasing), or theta
    itself when it already exceeds g there. ``inf`` when a_r w^2 <= g (never). The release
    of exact sticking, ``model.chatter.release_phase``."""
    return release_phase(theta, params)


def impact_velocity(v_before: float, racket_v: float, alpha: float) -> float:
    """Eq. 3 with v_r- = v_r+: v_b+ = v_r - alpha (v_b- - v_r)."""
    return racket_v - alpha * (v_before - racket_v)


def apex_height(params: ModelParams, theta, v):
    """Ball apex above the racket's mid-position after an impact (eqs. 1, 4).

    Parameters
    ----------
    params : ModelParams
        a_r and g.
    theta, v : float or array
        Phase of the impact (rad) and the ball's velocity after it (m/s).

    Returns
    -------
    float or array
        x_r(theta) + v^2 / (2 g), m.
    """
    return params.racket_amplitude * np.sin(theta) + np.square(v) / (2.0 * params.g)


def restitution_of(v_before, v_after, racket_v):
    """Eq. 3 solved for alpha: ``-(v_b+ - v_r) / (v_b- - v_r)`` (arrays broadcast; NaN or inf
    where the ball does not approach the racket, without a warning)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return -(v_after - racket_v) / (v_before - racket_v)


def simulate(
    theta0: float,
    v0: float,
    params: ModelParams,
    duration_s: float,
    settings: FlightSettings = FlightSettings(),
) -> Trajectory:
    """Motion of a ball that leaves the racket at phase theta0 (t0 = theta0 / w) with
    velocity v0, for ``duration_s`` seconds. A ball that cannot leave (v0 not above the
    racket's velocity and the racket not decelerating faster than g) starts stuck."""
    if not (math.isfinite(theta0) and math.isfinite(v0)):
        raise ModelError("initial phase and velocity must be finite")
    if not (math.isfinite(duration_s) and duration_s > 0.0):
        raise ModelError(f"duration must be > 0 (got {duration_s!r})")
    if settings.min_hop_s == 0.0:
        return _exact_sticking_trajectory(float(theta0), float(v0), params, duration_s)
    return simulate_with_racket(PassiveRacket(params), float(theta0), float(v0), duration_s,
                                settings)


class Racket(Protocol):
    """The racket as the continuous motion sees it (eq. 4, or a racket whose period a
    controller sets at each impact: ``model.control.ControlledRacket``): its phase,
    position and velocity at a time, the time a flight launched at a phase ends, and
    ``launch`` / ``impact``, where a controller may change the period. ``omega``: the angular
    frequency now (rad/s); ``params``: the model (g, alpha, the amplitude)."""

    @property
    def params(self) -> ModelParams: ...

    @property
    def omega(self) -> float: ...

    def start_time(self, theta0: float) -> float: ...

    def phase(self, t: float) -> float: ...

    def position(self, t: float) -> float: ...

    def velocity(self, t: float) -> float: ...

    def can_fly(self, phase: float, v: float) -> bool: ...

    def leave_time(self, t: float) -> float: ...

    def hit_time(self, t: float, phase: float, launch_phase: float, hop: float) -> float: ...

    def launch(self, t: float, v: float) -> None: ...

    def impact(self, t: float, v_after: float) -> None: ...


@dataclass(frozen=True)
class PassiveRacket:
    """The racket of eq. 4: phase w t, the period never changes."""

    params: ModelParams

    @property
    def omega(self) -> float:
        return self.params.omega

    def start_time(self, theta0: float) -> float:
        return theta0 / self.params.omega

    def phase(self, t: float) -> float:
        return self.params.omega * t

    def position(self, t: float) -> float:
        return float(self.params.racket_position(self.params.omega * t))

    def velocity(self, t: float) -> float:
        return float(self.params.racket_velocity(self.params.omega * t))

    def can_fly(self, phase: float, v: float) -> bool:
        return bool(can_fly(phase, v, self.params))

    def leave_time(self, t: float) -> float:
        return leave_phase(self.params.omega * t, self.params) / self.params.omega

    def hit_time(self, t: float, phase: float, launch_phase: float, hop: float) -> float:
        return (launch_phase + hop) / self.params.omega

    def launch(self, t: float, v: float) -> None:
        pass

    def impact(self, t: float, v_after: float) -> None:
        pass


def simulate_with_racket(racket: Racket, theta0: float, v0: float, duration_s: float,
                         settings: FlightSettings = FlightSettings()) -> Trajectory:
    """``simulate`` (with ``min_hop_s`` > 0) against any ``Racket``: the one event loop of
    the continuous motion (fly, impact, maybe stick, leave, fly...) for the passive racket
    and the one whose period a controller sets (``model.control``). The ball leaves at
    phase theta0 (at ``racket.start_time(theta0)``) with v0."""
    sim = _Simulation(racket, settings, racket.start_time(theta0), duration_s)
    sim.run(theta0, v0)
    return Trajectory(racket.params, sim.t0, sim.t_end, tuple(sim.segments),
                      tuple(sim.impacts))


def _exact_sticking_trajectory(theta0: float, v0: float, params: ModelParams,
                               duration_s: float) -> Trajectory:
    """``simulate`` with exact sticking (``min_hop_s`` 0): the events of
    ``chatter.iterate_exact_orbit`` (impacts, accumulation points, releases) laid out as
    segments. A ball that cannot leave at the start rides until its release first."""
    w = params.omega
    t0, t_end = theta0 / w, theta0 / w + duration_s
    segments: list[Segment] = []
    start_released = not bool(can_fly(theta0, v0, params))
    if start_released:  # rides from the start until the racket's acceleration reaches -g
        theta_r = release_phase(theta0, params)
        segments.append(Segment("stuck", t0, min(theta_r / w, t_end),
                                float(params.racket_position(theta0)),
                                float(params.racket_velocity(theta0))))
        if theta_r / w >= t_end:
            return Trajectory(params, t0, t_end, tuple(segments), ())
        theta0, v0 = theta_r, float(params.racket_velocity(theta_r))
    orbit = iterate_exact_orbit(theta0, v0, params, n_impacts=2**62,
                                start_released=start_released, until_theta=w * t_end)
    impacts: list[Impact] = []
    accumulations: list[float] = []
    for i in range(1, len(orbit.event)):
        kind, t_prev, t_i = orbit.event[i], orbit.theta[i - 1] / w, orbit.theta[i] / w
        if t_prev >= t_end:
            break
        if kind == IMPACT:
            segments.append(Segment("flight", t_prev, min(t_i, t_end),
                                    float(params.racket_position(orbit.theta[i - 1])),
                                    float(orbit.v[i - 1])))
            if t_i <= t_end:
                v_before = float(orbit.v[i - 1]) - params.g * (t_i - t_prev)
                impacts.append(Impact(t_i, float(orbit.theta[i]), v_before, float(orbit.v[i]),
                                      float(params.racket_velocity(orbit.theta[i])),
                                      t_i - t_prev))
        elif kind == STICK:
            segments.append(Segment("chatter", t_prev, min(t_i, t_end),
                                    float(params.racket_position(orbit.theta[i - 1])),
                                    float(params.racket_velocity(orbit.theta[i - 1]))))
            if t_i <= t_end:
                accumulations.append(t_i)
                # released at the next event; resting (or the run's end): rides to the end
                ride_end = (orbit.theta[i + 1] / w if i + 1 < len(orbit.event)
                            and orbit.event[i + 1] == RELEASE else math.inf)
                segments.append(Segment("stuck", t_i, min(ride_end, t_end),
                                        float(params.racket_position(orbit.theta[i])),
                                        float(orbit.v[i])))
    return Trajectory(params, t0, t_end, tuple(segments), tuple(impacts), tuple(accumulations))


class _Simulation:
    """The event loop shared by both integrators and every racket: fly, impact, maybe
    stick, leave, fly..."""

    def __init__(self, racket: Racket, settings: FlightSettings, t0: float, duration: float):
        self.racket = racket
        self.p = racket.params
        self.s = settings
        self.t0 = t0
        self.t_end = t0 + duration
        self.segments: list[Segment] = []
        self.impacts: list[Impact] = []
        if settings.integrator != "exact" and not isinstance(racket, PassiveRacket):
            raise ModelError("a racket whose period changes needs integrator exact")

    def run(self, theta: float, v: float) -> None:
        racket = self.racket
        t = self.t0
        racket.launch(t, v)
        stuck = not racket.can_fly(theta, v)
        while t < self.t_end:
            if stuck:
                t_leave = racket.leave_time(t)
                self.segments.append(Segment(
                    "stuck", t, min(t_leave, self.t_end), racket.position(t), racket.velocity(t),
                ))
                t = t_leave
                v = racket.velocity(t) if math.isfinite(t) else math.nan
                stuck = False
                continue
            impact = self.fly(t, v)
            if impact is FlightEnd.BEYOND_END:
                return
            if impact is FlightEnd.UNRESOLVED:
                stuck = True
                continue
            self.impacts.append(impact)
            t, v = impact.t_s, impact.v_after_m_s
            racket.impact(t, v)  # a controller may set the next flight's period here
            stuck = (
                impact.hop_s < self.s.min_hop_s
                or v - racket.velocity(t) <= self.s.min_relative_velocity_m_s
                or not racket.can_fly(impact.theta_rad, v)
            )

    # -- one flight: from the racket at time t with velocity v to the next impact ---------------
    def fly(self, t: float, v: float) -> Impact | FlightEnd:
        """The impact ending the flight from the racket at time t with velocity v, or how
        the flight ends otherwise (beyond the run's end; a hop rk4 cannot resolve)."""
        p, racket = self.p, self.racket
        x = racket.position(t)
        if self.s.integrator == "exact":
            t_hit = self._exact_hit(t, v)
        else:
            rk4_hit = self._rk4_hit(t, x, v)
            if rk4_hit is None:
                return FlightEnd.UNRESOLVED
            t_hit = rk4_hit
        self.segments.append(Segment("flight", t, min(t_hit, self.t_end), x, v))
        if t_hit > self.t_end:
            return FlightEnd.BEYOND_END
        hop = t_hit - t
        v_before = v - p.g * hop
        racket_v = racket.velocity(t_hit)
        return Impact(t_hit, racket.phase(t_hit), v_before,
                      impact_velocity(v_before, racket_v, p.alpha), racket_v, hop)

    def _exact_hit(self, t: float, v: float) -> float:
        p, racket = self.p, self.racket
        w = racket.omega
        theta = racket.phase(t)
        launch_v, launch_theta = v, theta
        if v - racket.velocity(t) <= 0.0:
            # leaving with the racket's velocity (G' = 0): hand over just after the leave
            launch_theta = theta + LEAVE_NUDGE_PHASE
            launch_v = v - p.g * LEAVE_NUDGE_PHASE / w
        hop = float(first_impact_phase(launch_theta, launch_v, p.racket_amplitude, w, p.g))
        if not math.isfinite(hop):
            raise ModelError(f"no next impact found after t = {t:.6g} s")
        return racket.hit_time(t, theta, launch_theta, hop)

    def _rk4_hit(self, t: float, x: float, v: float) -> float | None:
        p, w, h, g = self.p, self.p.omega, self.s.rk4_step_s, self.p.g

        def f(state):
            return np.array([state[1], -g])

        state = np.array([x, v])
        first = True
        while t < self.t_end + h:
            k1 = f(state)
            k2 = f(state + 0.5 * h * k1)
            k3 = f(state + 0.5 * h * k2)
            k4 = f(state + h * k3)
            new = state + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
            if new[0] < float(p.racket_position(w * (t + h))) or first:
                root = _first_crossing(t, h, state, new, p, skip_start=first)
                if root is not None:
                    return root
                if first and new[0] < float(p.racket_position(w * (t + h))):
                    return None  # below the racket without a resolved crossing: too short a hop
            first = False
            t, state = t + h, new
        return t


def _hermite(tau, h, x0, v0, x1, v1):
    """Cubic Hermite interpolant of the ball position inside one step (tau in [0, h])."""
    s = tau / h
    h00 = 2 * s**3 - 3 * s**2 + 1
    h10 = s**3 - 2 * s**2 + s
    h01 = -2 * s**3 + 3 * s**2
    h11 = s**3 - s**2
    return h00 * x0 + h10 * h * v0 + h01 * x1 + h11 * h * v1


def _first_crossing(t, h, state, new, p: ModelParams, skip_start: bool):
    """First time in (t, t + h] where the interpolated ball goes below the racket, or None."""
    w = p.omega

    def gap(tau):
        return _hermite(tau, h, state[0], state[1], new[0], new[1]) - p.racket_position(
            w * (t + tau)
        )

    taus = np.linspace(0.0, h, RK4_SUBSAMPLES + 1)
    gaps = gap(taus)
    start = 1 if skip_start else 0
    for i in range(start, RK4_SUBSAMPLES):
        if gaps[i] > 0.0 and gaps[i + 1] <= 0.0:
            from scipy.optimize import brentq  # (a fifth of a second's import: here only)

            return t + brentq(gap, taus[i], taus[i + 1], xtol=1e-14, rtol=1e-14)
    return None
