"""Iteration of the ball bouncing map (eqs. 5, 6) and its stochastic version (eqs. 16-18).

The state is (theta_k, v_k): phase of the k-th impact (rad, unwrapped: theta = omega_r t_k)
and ball velocity just after it (m/s).

The one step protocol (``ImpactMap``): a map is its states and its step, nothing more (as
emcee's moves implement only ``get_proposal`` and scipy's ``OdeSolver`` only ``_step_impl``).
``PassiveMap`` (eqs. 5, 6) implements it here, ``model.control.ControlledMap`` (the racket
period as a third state) there; everything that iterates a map is written once over it:
the orbit and the batch iteration here (``iterate_states``, ``iterate_map_orbit``), the basin's
classification and its tiles in ``analysis.classify``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from .chatter import tail_is_summable
from .impact import MAX_SAFE_STEPS, can_fly, first_impact_phase, next_impact_phase
from .params import MIN_HOP_S, FixedPoint, ModelParams, phase_difference
from .trig import sincos

TWO_PI = 2.0 * math.pi


def velocity_after_impact(theta_next, v, hop_phase, params: ModelParams, alpha=None, *,
                          cos_theta_next=None):
    """Velocity map, eq. 5:
    v_{k+1} = (1+alpha) a_r w cos(theta_{k+1}) - alpha v_k + (g alpha / w)(theta_{k+1} - theta_k).

    ``hop_phase`` is theta_{k+1} - theta_k (in eq. 16 the noiseless phi_{k+1} - theta_k).
    ``alpha`` overrides the model's coefficient of restitution for this impact (section 7).
    ``cos_theta_next``: ``np.cos(theta_next)`` if the caller has it already.
    """
    alpha = params.alpha if alpha is None else alpha
    return velocity_map(theta_next, v, hop_phase, alpha, params.racket_amplitude,
                        params.omega, params.g, cos_theta_next=cos_theta_next)


def velocity_map(theta_next, v, hop_phase, alpha, amplitude, omega, g, *,
                 cos_theta_next=None):
    """Eq. 5 with the racket's amplitude (m), the angular frequency of the flight that just
    ended (rad/s) and g given directly (arrays broadcast: the controlled map's flights each
    have their own frequency); ``velocity_after_impact`` at one parameter point."""
    cos_next = np.cos(theta_next) if cos_theta_next is None else cos_theta_next
    return ((1.0 + alpha) * amplitude * omega * cos_next - alpha * v
            + g * alpha / omega * hop_phase)


@dataclass(frozen=True)
class MapStep:
    """One application of the map to an array of states."""

    theta: np.ndarray  # theta_{k+1}, rad (unwrapped continuation of the input phase)
    v: np.ndarray  # v_{k+1}, m/s
    hop_phase: np.ndarray  # phi_{k+1} - theta_k: phase elapsed in flight (NaN: no flight)


def map_step(theta, v, params: ModelParams, velocity_noise=0.0, phase_noise=0.0, *,
             released=None) -> MapStep:
    """Advance states (theta_k, v_k) by one impact.

    Deterministic map: eqs. 5 and 6. With noise terms (already scaled: q_v xi and q_theta xi'
    with independent xi, xi'), the stochastic map of eqs. 16-18: the noiseless next phase
    phi_{k+1} solves eq. 17, theta_{k+1} = phi_{k+1} + phase_noise (eq. 18), and
    v_{k+1} follows eq. 16 with cos(theta_{k+1}) and (phi_{k+1} - theta_k).
    States whose ball cannot leave the racket give NaN. ``released``: states that leave from
    a release point of exact sticking (``model.chatter``; ``next_impact_phase``).
    """
    theta = np.asarray(theta, dtype=float)
    v = np.asarray(v, dtype=float)
    hop = next_impact_phase(theta, v, params, released=released)
    theta_next = theta + hop + phase_noise
    v_next = velocity_after_impact(theta_next, v, hop, params) + velocity_noise
    return MapStep(theta=theta_next, v=v_next, hop_phase=hop)


@dataclass(frozen=True)
class ClassifySettings:
    """Stopping conditions of section 3, the paper's values by default (the one place these
    defaults live: the config's ``classify`` block, the reference classifier and the
    continuous motion's sticking criterion take them from here; ``analysis.classify`` runs
    them over the step protocol).

    max_iterations: impacts at most (section 3: 100).
    tolerance: period-1 when |v - v~| < tolerance (m/s) and the wrapped |theta - theta~| <
    tolerance (rad) (section 3: 1e-3).
    min_hop_s: sticking when a hop lasts less than this, s (section 3: 1e-3 s).
    """

    max_iterations: int = 100
    tolerance: float = 1e-3
    min_hop_s: float = MIN_HOP_S


# -- the one step protocol ---------------------------------------------------------------------
@dataclass(frozen=True)
class State:
    """States of a map just after impact k (arrays of one shape).

    theta: phase of the impact (rad; wrapped to [0, 2 pi) or unwrapped, as the caller asked);
    v: ball velocity just after it (m/s); extra: the map's own further arrays (the controlled
    map's racket period; the passive map's cos and sin of a wrapped state's theta, a cache),
    which the algorithms carry along without reading them."""

    theta: np.ndarray
    v: np.ndarray
    extra: tuple[np.ndarray, ...] = ()

    def take(self, which) -> "State":
        """The states at ``which`` (an index array or a boolean mask)."""
        return State(self.theta[which], self.v[which], tuple(x[which] for x in self.extra))


@dataclass(frozen=True)
class Step:
    """One impact of a map: the states after it, the phase elapsed in the flight (rad of the
    racket's phase; NaN: the ball could not fly) and the flight's duration (s)."""

    state: State
    hop_phase: np.ndarray
    hop_s: np.ndarray


class ImpactMap(Protocol):
    """The one step protocol: what a map implements so that orbits, batch iteration,
    classification and tiling (written once, over this) run it.

    ``start``: the states (theta0, v0) of a ball leaving the racket (``wrap``: phase wrapped
    to [0, 2 pi), as the classification keeps it); ``launches``: where such a ball rises
    above the racket (section 3's "below the racket" where not); ``step``: one impact (eqs.
    5, 6, or the map's own version; ``wrap`` as for ``start``); ``near_fixed_point``: within
    ``tolerance`` of the period-1 fixed point (eqs. 7, 8) in every state variable (section
    3's period-1 test). ``period_s``: the racket period of each state (s), for a flight's
    time. A map object must pickle (tiles of a grid run in worker processes)."""

    def start(self, theta0, v0, *, wrap: bool = False) -> State: ...

    def launches(self, state: State) -> np.ndarray: ...

    def step(self, state: State, *, wrap: bool = False) -> Step: ...

    def near_fixed_point(self, state: State, tolerance: float) -> np.ndarray: ...


@dataclass(frozen=True)
class PassiveMap:
    """The ball bouncing map (eqs. 5, 6) at ``params`` behind the step protocol.

    ``target``: the fixed point the period-1 test compares with (default eqs. 7, 8; NaN: no
    state is near it, for parameter sweeps where eq. 8 has no solution). The arithmetic is
    ``map_step``'s (unwrapped) and the basin classifier's (wrapped: cos and sin of theta by
    ``trig.sincos`` once per impact, shared by eq. 5 and the solver's start, the values
    ``first_impact_phase`` would compute), which ``model.compiled`` repeats bit for bit.
    ``compiled_hops``: a wrapped step's first-impact solve by that compiled kernel
    (``compiled.first_impact_phase_of``, needs numba), the same bits at a fraction of the
    cost on a few hundred states (numpy's cost there is its calls, not its arithmetic)."""

    params: ModelParams
    target: FixedPoint = field(default=FixedPoint(math.nan, math.nan))
    compiled_hops: bool = False

    @classmethod
    def of(cls, params: ModelParams, *, require_fixed_point: bool = True) -> "PassiveMap":
        """The map with eqs. 7, 8's fixed point as target (NoFixedPointError where there is
        none, unless ``require_fixed_point`` is False: then a NaN target). The classifier
        takes it only where it attracts (``analysis.classify.passive_map``)."""
        if require_fixed_point or params.cos_theta_fixed() <= 1.0:
            return cls(params, params.fixed_point())
        return cls(params)

    def start(self, theta0, v0, *, wrap: bool = False) -> State:
        theta0, v0 = np.asarray(theta0, dtype=float), np.asarray(v0, dtype=float)
        if not wrap:
            return State(theta0, v0)
        theta = np.mod(theta0, TWO_PI)
        sin_th, cos_th = sincos(theta)
        return State(theta, v0, (cos_th, sin_th))

    def launches(self, state: State) -> np.ndarray:
        return can_fly(state.theta, state.v, self.params)

    def step(self, state: State, *, wrap: bool = False) -> Step:
        p = self.params
        if not wrap:
            out = map_step(state.theta, state.v, p)
            return Step(State(out.theta, out.v), out.hop_phase, out.hop_phase / p.omega)
        th, (cos_th, sin_th) = state.theta, state.extra
        if self.compiled_hops:
            from .compiled import first_impact_phase_of

            hop = first_impact_phase_of(state.v, cos_th, sin_th, p, max_steps=MAX_SAFE_STEPS)
        else:
            hop = first_impact_phase(th, state.v, p.racket_amplitude, p.omega, p.g,
                                     cos_theta=cos_th, sin_theta=sin_th, trig=sincos)
        th = np.mod(th + hop, TWO_PI)
        sin_th, cos_th = sincos(th)
        v = velocity_after_impact(th, state.v, hop, p, cos_theta_next=cos_th)
        return Step(State(th, v, (cos_th, sin_th)), hop, hop / p.omega)

    def near_fixed_point(self, state: State, tolerance: float) -> np.ndarray:
        return ((np.abs(state.v - self.target.v_m_s) < tolerance)
                & (np.abs(phase_difference(state.theta, self.target.theta_rad)) < tolerance))

    #: the compiled kernel (``model.compiled``) implements this map
    compiled_kernel = True

    def compiled_classification(self, theta0, v0, settings, max_steps: int):
        """(outcome, iterations) of flat arrays by the compiled kernel (``model.compiled``,
        loaded without numba where it can be: ``model.native``), the classification's
        arithmetic bit for bit."""
        from .native import classify_arrays

        return classify_arrays(theta0, v0, self.params, self.target, settings.max_iterations,
                               settings.tolerance, settings.min_hop_s, max_steps)

    def summable_chatter(self, state: State) -> np.ndarray:
        """Exact sticking (``model.chatter``): where the chatter after the impacts of a
        wrapped ``state`` is complete (its tail summable)."""
        p = self.params
        return tail_is_summable(state.theta,
                                state.v - p.racket_amplitude * p.omega * state.extra[0], p)


@dataclass(frozen=True)
class MapOrbit:
    """An orbit of any ``ImpactMap`` (``iterate_map_orbit``): the states after impacts
    k = 0..K (k = 0: the initial condition), the phase elapsed in the flight ending at each
    (NaN at k = 0), and why it stopped: "" (all impacts done) | "below_racket" (the ball
    cannot leave at the start) | "sticking" (a hop shorter than ``min_hop_s``, or a ball that
    cannot leave after an impact)."""

    states: list[State]
    hop_phase: np.ndarray
    stop_reason: str

    def column(self, name: str) -> np.ndarray:
        """theta or v over the impacts, as floats."""
        return np.array([float(getattr(s, name)) for s in self.states])

    def extra(self, i: int) -> np.ndarray:
        """The map's i-th further state variable over the impacts."""
        return np.array([float(s.extra[i]) for s in self.states])


def iterate_map_orbit(impact_map: ImpactMap, theta0: float, v0: float, n_impacts: int,
                      min_hop_s: float) -> MapOrbit:
    """Iterate any map (``ImpactMap``) from one initial condition for up to ``n_impacts``
    impacts, unwrapped phases; stops after the first hop shorter than ``min_hop_s``
    (section 3's sticking criterion; also a NaN hop: the ball could not fly) or when the
    ball cannot leave the racket after an impact (alpha = 0 only), and at once when it cannot
    leave at the start (v_0 <= racket velocity)."""
    state = impact_map.start(float(theta0), float(v0))
    states, hops = [state], [math.nan]
    if not impact_map.launches(state):
        return MapOrbit(states, np.array(hops), "below_racket")
    for _ in range(n_impacts):
        step = impact_map.step(state)
        state = step.state
        states.append(state)
        hops.append(float(step.hop_phase))
        if not float(step.hop_s) >= min_hop_s or not impact_map.launches(state):
            return MapOrbit(states, np.array(hops), "sticking")
    return MapOrbit(states, np.array(hops), "")


@dataclass(frozen=True)
class History:
    """States of a batch over impacts k = 0..n (``iterate_states``): theta (rad, unwrapped),
    v (m/s), the map's further state variables (``State.extra``) and the hop phases (NaN at
    k = 0), each of shape (n + 1, *batch shape)."""

    theta: np.ndarray
    v: np.ndarray
    extra: tuple[np.ndarray, ...]
    hop_phase: np.ndarray


def iterate_states(impact_map: ImpactMap, theta0, v0, n_impacts: int, *,
                   start: State | None = None) -> History:
    """Iterate any map (``ImpactMap``) n_impacts times from arrays of initial conditions
    (broadcast; unwrapped phases), or from the states ``start`` (the map's further
    variables set by the caller). Once a state cannot fly, it stays NaN."""
    theta0, v0 = np.broadcast_arrays(np.asarray(theta0, float), np.asarray(v0, float))
    state = impact_map.start(theta0, v0) if start is None else start
    states, hops = [state], [np.full(theta0.shape, np.nan)]
    for _ in range(n_impacts):
        step = impact_map.step(state)
        state = step.state
        states.append(state)
        hops.append(step.hop_phase)

    def stacked(values) -> np.ndarray:
        return np.stack([np.broadcast_to(x, theta0.shape) for x in values])

    return History(stacked(s.theta for s in states), stacked(s.v for s in states),
                   tuple(stacked(s.extra[i] for s in states)
                         for i in range(len(state.extra))),
                   stacked(hops))


def iterate_map(theta0, v0, params: ModelParams, n_impacts: int):
    """Iterate the deterministic map n_impacts times from arrays of initial conditions.

    Returns (theta, v, hop_phase) with shapes (n_impacts + 1, *shape): row 0 is the
    initial condition (hop_phase NaN there). Once a state cannot fly, it stays NaN.
    ``iterate_states`` of the ``PassiveMap``.
    """
    history = iterate_states(PassiveMap(params), theta0, v0, n_impacts)
    return history.theta, history.v, history.hop_phase


@dataclass(frozen=True)
class Orbit:
    """A single orbit of the deterministic map, stopped early when it can go no further.

    Arrays run over impacts k = 0..K (row 0: the initial condition, hop NaN there).
    stop_reason: "" (all impacts done) | "below_racket" (v_0 not above the racket's
    velocity: the ball cannot leave) | "sticking" (the last hop was shorter than
    ``min_hop_s``).
    """

    theta: np.ndarray
    v: np.ndarray
    hop_phase: np.ndarray
    stop_reason: str


def iterate_orbit(
    theta0: float, v0: float, params: ModelParams, n_impacts: int, min_hop_s: float
) -> Orbit:
    """Iterate eqs. 5, 6 from one initial condition for up to ``n_impacts`` impacts.

    Stops after the first hop lasting less than ``min_hop_s`` (section 3's sticking
    criterion), or at once when the ball cannot leave the racket (v_0 <= racket velocity).
    ``iterate_map_orbit`` of the ``PassiveMap``.
    """
    orbit = iterate_map_orbit(PassiveMap(params), theta0, v0, n_impacts, min_hop_s)
    return Orbit(orbit.column("theta"), orbit.column("v"), orbit.hop_phase, orbit.stop_reason)
