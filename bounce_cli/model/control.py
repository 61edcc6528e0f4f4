"""Active period control: the racket period as a third state (the future work of sections 7-8).

The state after impact k is (v_k, theta_k, tau_k): ball velocity just after the impact (m/s),
racket phase of the impact (rad, unwrapped) and the racket period during the flight that ENDED
at impact k (s; the period of the racket cycle in which impact k falls, as a lab measures it).
At impact k a controller sets the period of the next flight from what it perceives then,

    tau_{k+1} = controller(v_k, theta_k, tau_k),

and during that flight the racket moves as x_r = a_r sin(phi) with its phase phi advancing
2 pi per tau_{k+1}, i.e. at w_{k+1} = 2 pi / tau_{k+1}, continuing from theta_k (the racket's
position never jumps). The next impact then follows eqs. 5 and 6 with w_{k+1} in place of w_r:

    0 = a_r w_{k+1}^2 (sin theta_k - sin theta_{k+1}) + v_k w_{k+1} s - g s^2 / 2,    (eq. 6)
    v_{k+1} = (1+alpha) a_r w_{k+1} cos(theta_{k+1}) - alpha v_k + (g alpha / w_{k+1}) s,  (eq. 5)

s = theta_{k+1} - theta_k. Eq. 5 holds unchanged because the racket's velocity at impact k+1
is a_r w_{k+1} cos(theta_{k+1}) and the flight lasted s / w_{k+1}. The racket's VELOCITY jumps
at impact k by a_r (w_{k+1} - w_k) cos(theta_k) (its position is continuous, its speed
changes with the frequency): the impact law at k used the racket velocity just before, and the
ball must leave faster than the racket moves just after (else it cannot fly: NaN).

The default controller (after de Rugy et al. 2003, "period"): a ball leaving faster than v~
flies longer by about 2 (v_k - v~) / g, so the target period is
tau_bar + K 2 (v_k - v~) / g, approached at rate c:

    tau_{k+1} = tau_k + c (tau_bar + K 2 (v_k - v~) / g - tau_k).

With K = 0 and tau_0 = tau_bar the period stays tau_bar bit for bit and the map IS the passive
map of ``model.maps`` (same arithmetic, same bits). The fixed point is the passive one,
(v~, theta~, tau_bar) (eqs. 7, 8), for every K != 1 (at K = 1 every period has one: a line
of fixed points, one eigenvalue 1).

Linearisation (the 3 x 3 Jacobian at the fixed point, state order (v, theta, tau)): the
passive block is eq. 9's J; the new flight's period enters through

    d theta_{k+1} / d tau_{k+1} = -(1 + alpha) w / 2,
    d v_{k+1} / d tau_{k+1}     = -(g / 2) ((1 - alpha)^2 + (1 + alpha)^2 AC),

(implicit function theorem on eq. 6 and eq. 5, as in section 4), and the controller's gradient
row r = (d tau'/d v, d tau'/d theta, d tau'/d tau) = (2 c K / g, 0, 1 - c):

    M = [[J + b r_(v,theta),  b r_tau],
         [r_(v,theta),        r_tau  ]],   b = (d v'/d tau', d theta'/d tau').

With K = 0 M is block triangular: eq. 10's eigenvalues plus the period's own 1 - c.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from .chatter import release_phase
from .flight import simulate_with_racket
from .impact import MAX_SAFE_STEPS, SinusoidGap, can_fly_at, first_contact, first_impact_phase
from .trig import numpy_sincos, sincos
from .linear import jacobian, racket_acceleration_at_impact_g
from .maps import ClassifySettings, State, Step, iterate_map_orbit, iterate_states, velocity_map
from .params import FixedPoint, ModelError, ModelParams, phase_difference

TWO_PI = 2.0 * math.pi


# -- controllers ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Reference:
    """What a controller regulates towards: the passive fixed point at the mean period.

    racket_period_s: tau_bar (s); v_m_s: v~ = pi g / w_bar (eq. 7); theta_rad: theta~ (eq. 8;
    NaN where eq. 8 has no solution: the map is still defined there); g (m/s^2)."""

    racket_period_s: float
    v_m_s: float
    theta_rad: float
    g: float

    @classmethod
    def of(cls, params: ModelParams) -> "Reference":
        cos_t = params.cos_theta_fixed()
        theta = math.acos(cos_t) if cos_t <= 1.0 else math.nan
        return cls(params.racket_period, math.pi * params.g / params.omega, theta, params.g)


class Controller(Protocol):
    """A racket period controller: ``next_period`` gives tau_{k+1} from the state after
    impact k (arrays broadcast); ``gradient`` its partial derivatives
    (d tau'/d v, d tau'/d theta, d tau'/d tau) at the fixed point (v~, theta~, tau_bar),
    for the analytic 3 x 3 Jacobian. A controller must leave tau_bar unchanged at the fixed
    point (``next_period(v~, theta~, tau_bar) = tau_bar``) so that the fixed point is eqs. 7, 8.
    """

    @property
    def kind(self) -> str: ...

    def next_period(self, v, theta, tau, reference: Reference): ...

    def gradient(self, reference: Reference) -> tuple: ...


@dataclass(frozen=True)
class PeriodController:
    """The expected-flight-time controller (after de Rugy et al. 2003; ``kind: period``):
    tau_{k+1} = tau_k + c (tau_bar + K 2 (v_k - v~) / g - tau_k).

    gain K (dimensionless: 1 = the period follows the change of the ballistic flight time in
    full), rate c (per impact: 1 = immediate adaptation, 0 = the period never changes).
    Gain and rate may be arrays (a grid of controllers) for ``gradient``."""

    gain: Any  # float, or an array of gains (a grid of controllers)
    rate: Any = 1.0
    kind: str = "period"
    #: when the new period starts: "impact" (the flight after impact k runs at tau_{k+1}; the
    #: model of this module) or "cycle" (at the racket's next upward mid-position crossing:
    #: the rest of the current cycle keeps tau_k, a racket moved cycle by cycle as
    #: ``data.simulated_lab`` moves it; see ``controlled_step``)
    switch: str = "impact"

    def target(self, v, reference: Reference):
        """tau_bar + K * 2 (v - v~) / g: the period that matches the ball's flight time."""
        return reference.racket_period_s + self.gain * (2.0 * (v - reference.v_m_s) / reference.g)

    def next_period(self, v, theta, tau, reference: Reference):
        return tau + self.rate * (self.target(v, reference) - tau)

    def gradient(self, reference: Reference) -> tuple:
        gain, rate = np.asarray(self.gain, float), np.asarray(self.rate, float)
        return 2.0 * rate * gain / reference.g, np.zeros_like(gain * rate), 1.0 - rate


#: the passive map as a controller: the racket keeps its period tau_bar (a parameter, not a
#: state: a period set off tau_bar returns to it at once, eigenvalue 1 - c = 0)
PASSIVE = PeriodController(gain=0.0, rate=1.0)

def is_passive(controller: Controller | None) -> bool:
    """No controller, or one that leaves the period at tau_bar (gain 0: the passive map bit for
    bit, whatever the rate), so that the paper's statements about the passive map apply."""
    return controller is None or bool(np.all(np.asarray(getattr(controller, "gain", 1.0)) == 0))


#: controller kinds a config may name (``control: {kind: ...}``) -> class
CONTROLLERS: dict[str, type] = {"period": PeriodController}


# -- the controlled map -----------------------------------------------------------------------
@dataclass(frozen=True)
class ControlledStep:
    """One impact of the controlled map: theta_{k+1} (rad, unwrapped continuation), v_{k+1}
    (m/s), tau_{k+1} (s, the period of the flight just flown) and the phase elapsed in it
    (NaN: the ball could not fly, or the controller asked for a period <= 0)."""

    theta: np.ndarray
    v: np.ndarray
    tau: np.ndarray
    hop_phase: np.ndarray
    omega: np.ndarray  # 2 pi / tau_{k+1}, rad/s

    def hop_seconds(self) -> np.ndarray:
        return self.hop_phase / self.omega


def controlled_step(theta, v, tau, params: ModelParams, controller: Controller, *,
                    reference: Reference | None = None, alpha=None, velocity_noise=0.0,
                    phase_noise=0.0, period_noise=0.0, wrap: bool = False) -> ControlledStep:
    """Advance states (theta_k, v_k, tau_k) by one impact (see the module docstring).

    ``alpha`` overrides the coefficient of restitution of the impact k+1 (a perturbation,
    section 7); noise terms as in ``model.maps.map_step`` (eqs. 16-18), and ``period_noise``
    (s) added to the period the controller sets (a racket not timed exactly). ``wrap``: return
    theta_{k+1} wrapped to [0, 2 pi) and evaluate eq. 5 with it (``classify_batch``'s
    arithmetic). With a controller that keeps tau_k = tau_bar this is ``map_step`` (or
    ``classify_batch``'s step, wrapped) bit for bit.
    """
    reference = Reference.of(params) if reference is None else reference
    theta, v, tau = (np.asarray(x, dtype=float) for x in (theta, v, tau))
    tau_next = np.asarray(controller.next_period(v, theta, tau, reference), dtype=float)
    tau_next = tau_next + period_noise
    tau_next = np.where(tau_next > 0.0, tau_next, np.nan)  # no racket has a period <= 0
    if getattr(controller, "switch", "impact") == "cycle":
        return _step_switching_at_crossing(theta, v, tau, tau_next, params, alpha,
                                           velocity_noise, phase_noise, wrap)
    omega = 2.0 * np.pi / tau_next
    # wrapped: the classifier's step, whose sine and cosine the compiled kernel repeats
    hop = first_impact_phase(theta, v, params.racket_amplitude, omega, params.g,
                             trig=sincos if wrap else numpy_sincos)
    theta_next = theta + hop + phase_noise
    if wrap:
        theta_next = np.mod(theta_next, TWO_PI)
    alpha = params.alpha if alpha is None else alpha
    # wrapped, eq. 5 takes the classifier's cosine too (``PassiveMap.step``'s)
    cos_next = sincos(theta_next)[1] if wrap else None
    v_next = velocity_map(theta_next, v, hop, alpha, params.racket_amplitude, omega,
                          params.g, cos_theta_next=cos_next) + velocity_noise
    return ControlledStep(theta=theta_next, v=v_next, tau=np.broadcast_to(tau_next, hop.shape),
                          hop_phase=hop, omega=np.broadcast_to(omega, hop.shape))


def contact_after_crossing(height, v, amplitude, omega, g, *,
                           max_steps: int = MAX_SAFE_STEPS):
    """Phase s >= 0 of the first contact after the racket's upward mid-position crossing.

    The racket moves as a sin(s) at angular frequency omega from the crossing s = 0; the
    ball is ``height`` (>= 0) above it there with velocity v. This is the map's gap with
    theta = 0 and a height (``model.impact.SinusoidGap``; |G''| <= g / w^2 + a), solved by
    ``model.impact.first_contact`` from s = 0 with its stopping rule.

    Parameters
    ----------
    height : array_like
        Ball above the racket at the crossing, m (NaN: no flight to solve).
    v : array_like
        Ball velocity there, m/s.
    amplitude, omega, g : array_like
        The racket's amplitude (m) and angular frequency (rad/s) after the crossing, and
        gravity (m/s^2). All five broadcast.
    max_steps : int
        Safe steps after which a flight still not converged is NaN.

    Returns
    -------
    numpy.ndarray
        s (rad of the racket's phase after the crossing), NaN where none is found.
    """
    height, v, amplitude, omega, g = np.broadcast_arrays(
        *(np.asarray(x, float) for x in (height, v, amplitude, omega, g)))
    result = np.full(height.shape, np.nan)
    idx = np.flatnonzero(np.isfinite(height) & np.isfinite(v) & np.isfinite(omega)
                         & (height >= 0.0))
    a, w, gg = (np.ravel(x)[idx] for x in (amplitude, omega, g))
    vv = np.ravel(v)[idx]
    ones = np.ones(idx.size)
    gap = SinusoidGap(ones, np.zeros(idx.size), vv, vv / w - a * ones, a, w, gg,
                      height=np.ravel(height)[idx])
    result.flat[idx] = first_contact(gap, np.zeros(idx.size), max_steps=max_steps)
    return result


def _step_switching_at_crossing(theta, v, tau, tau_next, params: ModelParams, alpha,
                                velocity_noise, phase_noise, wrap: bool) -> ControlledStep:
    """``controlled_step`` for ``switch = "cycle"``: the racket finishes its current cycle
    with tau_k (its velocity does not jump at the impact) and runs with tau_{k+1} from the
    next upward crossing of its mid-position. The next impact is then the first contact
    with the old racket before the crossing (the impact falls in the same cycle, which keeps
    tau_k) or the first contact after it (``contact_after_crossing``); eq. 3 with the
    racket's velocity at that contact. ``hop_phase`` is the flight time times the angular
    frequency at the contact, so ``hop_seconds`` is the flight time."""
    a, g = params.racket_amplitude, params.g
    omega_now, omega_next = TWO_PI / tau, TWO_PI / tau_next
    phase = np.mod(theta, TWO_PI)
    hop_before = first_impact_phase(theta, v, a, omega_now, g)
    flies = np.isfinite(hop_before)
    same_cycle = flies & (phase + hop_before < TWO_PI)
    to_crossing = TWO_PI - phase
    dt = to_crossing / omega_now
    height = a * np.sin(phase) + v * dt - 0.5 * g * dt * dt
    after = contact_after_crossing(np.where(same_cycle | ~flies, np.nan, height),
                                   v - g * dt, a, omega_next, g)
    advance = np.where(same_cycle, hop_before, to_crossing + after)
    flight = np.where(same_cycle, hop_before / omega_now, dt + after / omega_next)
    omega_at = np.where(same_cycle, omega_now, omega_next)
    tau_at = np.where(same_cycle, tau, tau_next)
    advance = np.where(flies, advance, np.nan)
    theta_next = theta + advance + phase_noise
    if wrap:
        theta_next = np.mod(theta_next, TWO_PI)
    alpha = params.alpha if alpha is None else alpha
    v_next = ((1.0 + alpha) * a * omega_at * np.cos(theta_next) - alpha * v
              + alpha * g * flight + velocity_noise)
    return ControlledStep(theta=theta_next, v=v_next, tau=tau_at, hop_phase=flight * omega_at,
                          omega=omega_at)


@dataclass(frozen=True)
class ControlledMap:
    """The controlled map behind the step protocol (``model.maps.ImpactMap``): states
    (theta, v) with the racket period tau of the flight that ended at the impact as their one
    further variable (``State.extra = (tau,)``); ``controlled_step`` is its step. Orbits,
    batch iteration, classification and tiles (``model.maps``, ``analysis.classify``) run it
    as they run the passive map.

    ``target``: the fixed point (eqs. 7, 8) of the period-1 test (NaN: none), with tau_bar;
    ``period_tolerance_s``: the period-1 test's tolerance on tau (None: the same number as
    the one on v and theta, in s); ``initial_period_s``: tau_0 of a start (None: tau_bar).
    """

    params: ModelParams
    controller: Controller
    reference: Reference
    target: FixedPoint = FixedPoint(math.nan, math.nan)
    period_tolerance_s: float | None = None
    initial_period_s: float | None = None

    @classmethod
    def of(cls, params: ModelParams, controller: Controller, *,
           require_fixed_point: bool = False, period_tolerance_s: float | None = None,
           initial_period_s: float | None = None) -> "ControlledMap":
        """The map at ``params`` with ``controller``; ``require_fixed_point``: the target is
        eqs. 7, 8's fixed point (NoFixedPointError where there is none), else NaN."""
        target = params.fixed_point() if require_fixed_point else FixedPoint(math.nan, math.nan)
        return cls(params, controller, Reference.of(params), target, period_tolerance_s,
                   initial_period_s)

    def start(self, theta0, v0, *, wrap: bool = False) -> State:
        theta0, v0 = np.asarray(theta0, dtype=float), np.asarray(v0, dtype=float)
        tau0 = self.params.racket_period if self.initial_period_s is None else \
            float(self.initial_period_s)
        return State(np.mod(theta0, TWO_PI) if wrap else theta0, v0,
                     (np.full(np.shape(theta0), tau0),))

    def launches(self, state: State) -> np.ndarray:
        """The ball rises above the racket moving with the period it had (state's tau)."""
        return can_fly_at(state.theta, state.v, self.params.racket_amplitude,
                          2.0 * np.pi / state.extra[0], self.params.g)

    def step(self, state: State, *, wrap: bool = False) -> Step:
        out = controlled_step(state.theta, state.v, state.extra[0], self.params,
                              self.controller, reference=self.reference, wrap=wrap)
        return Step(State(out.theta, out.v, (out.tau,)), out.hop_phase, out.hop_seconds())

    @property
    def compiled_kernel(self) -> bool:
        """The compiled kernel implements this map: the period controller with one gain and
        rate (``switch: impact``)."""
        c = self.controller
        return (isinstance(c, PeriodController) and c.switch == "impact"
                and np.ndim(c.gain) == 0 and np.ndim(c.rate) == 0)

    def compiled_classification(self, theta0, v0, settings: ClassifySettings, max_steps: int):
        """(outcome, iterations) of flat arrays by the compiled kernel
        (``model.compiled.classify_controlled_arrays``), the numpy loop's bit for bit."""
        from .compiled import classify_controlled_arrays

        c = self.controller
        assert isinstance(c, PeriodController)
        tau0 = self.start(theta0, v0).extra[0]
        return classify_controlled_arrays(
            theta0, v0, tau0, self.params, self.target, tau_bar=self.reference.racket_period_s,
            v_reference=self.reference.v_m_s, gain=float(c.gain), rate=float(c.rate),
            max_iterations=settings.max_iterations, tolerance=settings.tolerance,
            period_tolerance_s=self._period_tolerance(settings.tolerance),
            min_hop_s=settings.min_hop_s, max_steps=max_steps)

    def _period_tolerance(self, tolerance: float) -> float:
        return tolerance if self.period_tolerance_s is None else self.period_tolerance_s

    def near_fixed_point(self, state: State, tolerance: float) -> np.ndarray:
        tol_tau = self._period_tolerance(tolerance)
        return ((np.abs(state.v - self.target.v_m_s) < tolerance)
                & (np.abs(phase_difference(state.theta, self.target.theta_rad)) < tolerance)
                & (np.abs(state.extra[0] - self.params.racket_period) < tol_tau))


def iterate_controlled(theta0, v0, tau0, params: ModelParams, controller: Controller,
                       n_impacts: int):
    """Iterate the controlled map n_impacts times: (theta, v, tau, hop_phase), each of shape
    (n_impacts + 1, *broadcast shape), row 0 the initial condition (hop NaN there), as
    ``model.maps.iterate_map`` (``iterate_states`` of the ``ControlledMap``). Once a state
    cannot fly, it stays NaN."""
    theta0, v0, tau0 = np.broadcast_arrays(*(np.asarray(x, float) for x in (theta0, v0, tau0)))
    impact_map = ControlledMap.of(params, controller)
    history = iterate_states(impact_map, theta0, v0, n_impacts,
                             start=State(theta0, v0, (tau0,)))
    return history.theta, history.v, history.extra[0], history.hop_phase


# -- fixed point and linearisation ------------------------------------------------------------
def controlled_fixed_point(
    params: ModelParams, controller: Controller
) -> tuple[float, float, float]:
    """(v~, theta~, tau_bar): the passive fixed point (eqs. 7, 8) at the mean period, which a
    controller keeps (it asks for tau_bar there). Raises NoFixedPointError as eq. 8 does."""
    fp = params.fixed_point()
    reference = Reference.of(params)
    tau = float(np.asarray(controller.next_period(fp.v_m_s, fp.theta_rad, params.racket_period,
                                                  reference)))
    if not math.isclose(tau, params.racket_period, rel_tol=1e-12):
        raise ValueError(f"controller {controller!r} moves the period away from tau_bar at the "
                         "fixed point")
    return fp.v_m_s, fp.theta_rad, params.racket_period


def period_sensitivity(params: ModelParams) -> tuple[float, float]:
    """(d v_{k+1}/d tau_{k+1}, d theta_{k+1}/d tau_{k+1}) of eqs. 5, 6 at the fixed point:
    (-(g/2)((1-alpha)^2 + (1+alpha)^2 AC)  [m/s per s],  -(1+alpha) w / 2  [rad per s])."""
    alpha, g, w = params.alpha, params.g, params.omega
    ac = racket_acceleration_at_impact_g(params)
    return (-0.5 * g * ((1.0 - alpha) ** 2 + (1.0 + alpha) ** 2 * ac),
            -0.5 * (1.0 + alpha) * w)


def jacobian_from_gradient(params: ModelParams, gradient) -> np.ndarray:
    """The 3 x 3 Jacobian (state order v, theta, tau) for a controller gradient row
    (d tau'/d v, d tau'/d theta, d tau'/d tau); arrays in the row broadcast, giving a stack of
    matrices of shape (*broadcast, 3, 3)."""
    r_v, r_theta, r_tau = np.broadcast_arrays(*(np.asarray(x, float) for x in gradient))
    J = jacobian(params)
    b = period_sensitivity(params)
    M = np.empty(r_v.shape + (3, 3))
    for i in range(2):
        M[..., i, 0] = J[i, 0] + b[i] * r_v
        M[..., i, 1] = J[i, 1] + b[i] * r_theta
        M[..., i, 2] = b[i] * r_tau
    M[..., 2, 0], M[..., 2, 1], M[..., 2, 2] = r_v, r_theta, r_tau
    return M


def controlled_jacobian(params: ModelParams, controller: Controller) -> np.ndarray:
    """The analytic 3 x 3 Jacobian of the controlled map at (v~, theta~, tau_bar); for a
    controller whose period starts at the next cycle (``switch = "cycle"``) the central
    differences of ``finite_difference_controlled_jacobian``."""
    params.fixed_point()  # NoFixedPointError where eq. 8 has no solution
    if getattr(controller, "switch", "impact") == "cycle":
        return finite_difference_controlled_jacobian(params, controller)
    return jacobian_from_gradient(params, controller.gradient(Reference.of(params)))


def finite_difference_controlled_jacobian(params: ModelParams, controller: Controller,
                                          rel_step: float = 1e-6) -> np.ndarray:
    """The 3 x 3 Jacobian by central differences of the full controlled map (re-solving eq. 6
    for each perturbed state): independent of the analytic route. Rows/columns (v, theta,
    tau); the 2 pi phase advance is removed."""
    v, theta, tau = controlled_fixed_point(params, controller)
    steps = np.array([rel_step * v, rel_step, rel_step * tau])
    base = np.array([v, theta, tau])
    states = np.repeat(base[None, :], 6, axis=0)
    for j in range(3):
        states[2 * j, j] += steps[j]
        states[2 * j + 1, j] -= steps[j]
    out = controlled_step(states[:, 1], states[:, 0], states[:, 2], params, controller)
    after = np.stack([out.v, out.theta, out.tau], axis=1)
    return np.stack([(after[2 * j] - after[2 * j + 1]) / (2 * steps[j]) for j in range(3)],
                    axis=1)


def spectral_radius_3x3(matrices) -> np.ndarray:
    """max |eigenvalue| of each matrix of a stack (..., 3, 3)."""
    return np.abs(np.linalg.eigvals(matrices)).max(axis=-1)


# -- one orbit (``bounce orbit`` with control) ---------------------------------------------------
@dataclass(frozen=True)
class ControlledOrbit:
    """One orbit of the controlled map, stopped as ``model.maps.Orbit`` is (stop_reason ""
    | "below_racket" | "sticking"). Arrays over impacts k = 0..n: theta (rad, unwrapped), v
    (m/s), tau (s, the period of the flight ending at k; tau_0 the initial one), hop_phase
    (NaN at k = 0), t_s (time of impact k: t_0 = theta_0 / w_0, then + each flight's duration)
    and flight_s (duration of the flight ending at k)."""

    theta: np.ndarray
    v: np.ndarray
    tau: np.ndarray
    hop_phase: np.ndarray
    stop_reason: str

    @property
    def flight_s(self) -> np.ndarray:
        return self.hop_phase / (2.0 * np.pi / self.tau)

    @property
    def t_s(self) -> np.ndarray:
        start = self.theta[0] / (2.0 * np.pi / self.tau[0])
        return start + np.concatenate([[0.0], np.cumsum(self.flight_s[1:])])


def iterate_controlled_orbit(theta0: float, v0: float, params: ModelParams,
                             controller: Controller, n_impacts: int, min_hop_s: float,
                             tau0: float | None = None) -> ControlledOrbit:
    """``model.maps.iterate_orbit`` for the controlled map from (theta0, v0, tau0 = tau_bar)
    (``iterate_map_orbit`` of the ``ControlledMap``): stops after a hop shorter than
    ``min_hop_s`` or when the ball cannot fly (also when the controller asks for a period
    <= 0), at once when v0 is not above the racket's velocity (with tau0)."""
    impact_map = ControlledMap.of(params, controller, initial_period_s=tau0)
    orbit = iterate_map_orbit(impact_map, theta0, v0, n_impacts, min_hop_s)
    return ControlledOrbit(orbit.column("theta"), orbit.column("v"), orbit.extra(0),
                           orbit.hop_phase, orbit.stop_reason)


# -- continuous-time motion with control (``bounce trajectory`` with ``model.control``) ----------
@dataclass(frozen=True)
class RacketClock:
    """The controlled racket's phase in time: from ``t_start[i]`` on it is
    ``phase_start[i] + omega[i] (t - t_start[i])`` (continuous; the rate changes at impacts)."""

    t_start: np.ndarray
    phase_start: np.ndarray
    omega: np.ndarray

    def phase(self, t):
        """(phase, angular frequency) at times t."""
        t = np.asarray(t, dtype=float)
        i = np.clip(np.searchsorted(self.t_start, t, side="right") - 1, 0, len(self.t_start) - 1)
        return self.phase_start[i] + self.omega[i] * (t - self.t_start[i]), self.omega[i]


class ControlledRacket:
    """The racket of the continuous motion with period control (``model.flight.Racket``):
    at the launch and at every impact the controller sets its period from then on
    (``switch: impact``, the map of this module): the phase stays continuous, the racket's
    velocity jumps. ``clock()``: its phase in time; ``periods``: the period of the flight
    that ended at each impact (s), as ``iterate_controlled_orbit``'s tau."""

    def __init__(self, params: ModelParams, controller: Controller) -> None:
        self.params = params
        self.controller = controller
        self.reference = Reference.of(params)
        self.tau = params.racket_period
        self.omega = TWO_PI / self.tau
        self.starts: list[float] = []
        self.phases: list[float] = []
        self.omegas: list[float] = []
        self.periods: list[float] = []

    def start_time(self, theta0: float) -> float:
        self.starts, self.phases = [theta0 * self.tau / TWO_PI], [float(theta0)]
        return self.starts[0]

    def phase(self, t: float) -> float:
        return self.phases[-1] + self.omega * (t - self.starts[-1])

    def position(self, t: float) -> float:
        return self.params.racket_amplitude * math.sin(self.phase(t))

    def velocity(self, t: float) -> float:
        return self.params.racket_amplitude * self.omega * math.cos(self.phase(t))

    def can_fly(self, phase: float, v: float) -> bool:
        return bool(can_fly_at(phase, v, self.params.racket_amplitude, self.omega,
                               self.params.g))

    def leave_time(self, t: float) -> float:
        """When a ball riding from t leaves: the racket keeps its period meanwhile."""
        ph = self.phase(t)
        at_period = ModelParams(self.params.alpha, self.params.g,
                                self.params.racket_amplitude, self.tau)
        return t + (release_phase(ph, at_period) - ph) / self.omega

    def hit_time(self, t: float, phase: float, launch_phase: float, hop: float) -> float:
        return t + (launch_phase - phase + hop) / self.omega

    def launch(self, t: float, v: float) -> None:
        self._set_period(t, v, "at the launch")

    def impact(self, t: float, v_after: float) -> None:
        self.periods.append(self.tau)  # the period of the flight that ended at this impact
        phase = self.phase(t)
        self._set_period(t, v_after, f"at t = {t:.4g} s")
        self.starts.append(t)
        self.phases.append(phase)

    def _set_period(self, t: float, v: float, where: str) -> None:
        phase = self.phase(t)
        tau = float(self.controller.next_period(v, phase, self.tau, self.reference))
        if not tau > 0.0:
            raise ModelError(f"the controller asks for a racket period <= 0 {where}")
        self.tau, self.omega = tau, TWO_PI / tau
        self.omegas.append(self.omega)

    def clock(self) -> RacketClock:
        return RacketClock(np.array(self.starts), np.array(self.phases), np.array(self.omegas))


def simulate_controlled_motion(theta0: float, v0: float, params: ModelParams,
                               controller: Controller, duration_s: float, settings):
    """``model.flight.simulate`` (exact integrator) with racket period control: the ball
    leaves the racket at phase theta0 (t0 = theta0 / w_bar) with v0 against a
    ``ControlledRacket`` (the one event loop, ``model.flight.simulate_with_racket``).
    Sticking as in ``model.flight`` (a hop shorter than ``settings.min_hop_s``, or a ball that
    leaves no faster than the racket then moves): the ball rides on the racket, which keeps
    its period, until the racket's downward acceleration exceeds g. Returns (Trajectory,
    RacketClock, periods): the racket's period during the flight that ended at each impact
    (s), as ``iterate_controlled_orbit``'s tau."""
    racket = ControlledRacket(params, controller)
    trajectory = simulate_with_racket(racket, float(theta0), float(v0), duration_s, settings)
    return trajectory, racket.clock(), np.array(racket.periods)
