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
map of ``engine.maps`` (same arithmetic, same bits). The fixed point is the passive one,
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
from typing import Any, Callable, Protocol, Sequence

import numpy as np

from ..analysis.classify import BELOW_RACKET, PERIOD1, STICKING, UNDECIDED, Classification
from ..analysis.classify import ClassifySettings, tile_slices
from .impact import MAX_SAFE_STEPS, SinusoidGap, first_contact, first_impact_phase
from .perturbation import perturbed_impact, perturbed_velocity, relaxation_impacts
from .linear import iterate_linear, jacobian, racket_acceleration_at_impact_g
from .params import ModelError, ModelParams, phase_difference

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
    #: ``engine.recording`` moves it; see ``controlled_step``)
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
def can_fly_at(theta, v, amplitude, omega, g):
    """``engine.can_fly`` with the racket's amplitude, angular frequency and g given directly
    (arrays broadcast): the ball rises above a racket moving at that frequency."""
    theta = np.asarray(theta, dtype=float)
    slope = (np.asarray(v, dtype=float) - amplitude * omega * np.cos(theta)) / omega
    curvature = -g / omega**2 + amplitude * np.sin(theta)
    return (slope > 0.0) | ((slope == 0.0) & (curvature > 0.0))


def velocity_map(theta_next, v, hop_phase, alpha, amplitude, omega, g):
    """Eq. 5 with the racket's angular frequency of the flight that just ended (arrays
    broadcast); the same arithmetic as ``engine.maps.velocity_after_impact``."""
    return ((1.0 + alpha) * amplitude * omega * np.cos(theta_next) - alpha * v
            + g * alpha / omega * hop_phase)


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
    section 7); noise terms as in ``engine.maps.map_step`` (eqs. 16-18), and ``period_noise``
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
    hop = first_impact_phase(theta, v, params.racket_amplitude, omega, params.g)
    theta_next = theta + hop + phase_noise
    if wrap:
        theta_next = np.mod(theta_next, TWO_PI)
    alpha = params.alpha if alpha is None else alpha
    v_next = velocity_map(theta_next, v, hop, alpha, params.racket_amplitude, omega,
                          params.g) + velocity_noise
    return ControlledStep(theta=theta_next, v=v_next, tau=np.broadcast_to(tau_next, hop.shape),
                          hop_phase=hop, omega=np.broadcast_to(omega, hop.shape))


def contact_after_crossing(height, v, amplitude, omega, g, *,
                           max_steps: int = MAX_SAFE_STEPS):
    """Phase s >= 0 of the first contact after the racket's upward mid-position crossing.

    The racket moves as a sin(s) at angular frequency omega from the crossing s = 0; the
    ball is ``height`` (>= 0) above it there with velocity v. This is the map's gap with
    theta = 0 and a height (``engine.impact.SinusoidGap``; |G''| <= g / w^2 + a), solved by
    ``engine.impact.first_contact`` from s = 0 with its stopping rule.

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


def iterate_controlled(theta0, v0, tau0, params: ModelParams, controller: Controller,
                       n_impacts: int):
    """Iterate the controlled map n_impacts times: (theta, v, tau, hop_phase), each of shape
    (n_impacts + 1, *broadcast shape), row 0 the initial condition (hop NaN there), as
    ``engine.maps.iterate_map``. Once a state cannot fly, it stays NaN."""
    theta0, v0, tau0 = np.broadcast_arrays(*(np.asarray(x, float) for x in (theta0, v0, tau0)))
    reference = Reference.of(params)
    out = {name: np.full((n_impacts + 1,) + theta0.shape, np.nan)
           for name in ("theta", "v", "tau", "hop")}
    out["theta"][0], out["v"][0], out["tau"][0] = theta0, v0, tau0
    for k in range(n_impacts):
        step = controlled_step(out["theta"][k], out["v"][k], out["tau"][k], params, controller,
                               reference=reference)
        out["theta"][k + 1], out["v"][k + 1] = step.theta, step.v
        out["tau"][k + 1], out["hop"][k + 1] = step.tau, step.hop_phase
    return out["theta"], out["v"], out["tau"], out["hop"]


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


def period_control_radius(params: ModelParams, gain, rate) -> np.ndarray:
    """Spectral radius of the period controller's 3 x 3 Jacobian for arrays of K and c."""
    gain, rate = np.broadcast_arrays(np.asarray(gain, float), np.asarray(rate, float))
    gradient = PeriodController(gain, rate).gradient(Reference.of(params))
    return spectral_radius_3x3(jacobian_from_gradient(params, gradient))


# -- impulse responses (section 7 with control) -----------------------------------------------
@dataclass(frozen=True)
class ControlledResponse:
    """Impacts k = 0..n after the perturbed impact k = 0: v (m/s), wrapped theta (rad), the
    racket period of the flight ending at impact k (s; tau_0 = tau_bar: the perturbation is
    not foreseen) and deviations from (v~, theta~, tau_bar) (dtheta wrapped to [-pi, pi))."""

    v: np.ndarray
    theta: np.ndarray
    tau: np.ndarray
    dv: np.ndarray
    dtheta: np.ndarray
    dtau: np.ndarray

    def relaxation_impacts(self, tol_v: float, tol_theta: float) -> int:
        """``engine.relaxation_impacts`` of this response (v and theta, as for Fig. 9)."""
        return relaxation_impacts(self.dv, self.dtheta, tol_v, tol_theta)


def controlled_impulse_response(params: ModelParams, controller: Controller, alpha_p: float,
                                n_impacts: int) -> ControlledResponse:
    """Section 7's impulse response with control: at the fixed point one impact has alpha_p,
    so the ball leaves at theta~ with v_0 = (1 + 2 alpha_p - alpha_0)/(1 + alpha_0) v~ while the
    racket still has tau_bar; from there the controlled map runs (alpha_0)."""
    v_fp, theta_fp, tau_bar = controlled_fixed_point(params, controller)
    theta, v, tau, _ = iterate_controlled(theta_fp, perturbed_velocity(params, alpha_p), tau_bar,
                                          params, controller, n_impacts)
    dtheta = phase_difference(theta, theta_fp)
    return ControlledResponse(v=v, theta=np.mod(theta_fp + dtheta, TWO_PI), tau=tau,
                              dv=v - v_fp, dtheta=dtheta, dtau=tau - tau_bar)


# -- classification (section 3's criteria, with the period as third state) ---------------------
def classify_controlled(theta0, v0, params: ModelParams, controller: Controller,
                        settings: ClassifySettings = ClassifySettings(), *, tau0=None,
                        period_tolerance_s: float | None = None) -> Classification:
    """Section 3's classification (see ``engine.classify``) of initial conditions for the
    controlled map, vectorised over the arrays (broadcast); the racket starts with tau0
    (default tau_bar) and the controller sets the first flight's period from (v0, theta0).

    * below_racket: v0 not above the racket's velocity at theta0 with the period tau0 the
      racket had (section 3's criterion, the same region as the passive basin's);
    * sticking: a hop shorter than ``min_hop_s``; also a ball that cannot leave
      (including at impact 0, when the controller's new period makes the racket faster than
      the ball at once) and a controller asking for a racket period <= 0 (the racket stops);
    * period1: |v - v~| < tol, |wrap(theta) - theta~| < tol and |tau - tau_bar| <
      ``period_tolerance_s`` (default: the same number as tol, in s);
    * undecided: none within ``max_iterations``.

    The arithmetic is ``classify_batch``'s (phases wrapped every impact), so a controller that
    keeps the period (K = 0) gives the passive classification exactly.
    """
    theta0, v0 = np.broadcast_arrays(np.asarray(theta0, dtype=float), np.asarray(v0, dtype=float))
    shape = theta0.shape
    theta0, v0 = theta0.ravel(), v0.ravel()
    fp = params.fixed_point()
    reference = Reference.of(params)
    tau_bar = params.racket_period
    tau0 = np.broadcast_to(np.asarray(tau_bar if tau0 is None else tau0, float), shape).ravel()
    tol = settings.tolerance
    tol_tau = tol if period_tolerance_s is None else period_tolerance_s

    outcome = np.full(theta0.shape, UNDECIDED, dtype=np.int8)
    iterations = np.full(theta0.shape, settings.max_iterations, dtype=np.int16)
    omega0 = 2.0 * np.pi / tau0
    flies = can_fly_at(theta0, v0, params.racket_amplitude, omega0, params.g)
    outcome[~flies] = BELOW_RACKET
    iterations[~flies] = 0
    idx = np.flatnonzero(flies)
    th, vv, tt = np.mod(theta0[idx], TWO_PI), v0[idx], tau0[idx]
    for k in range(1, settings.max_iterations + 1):
        if idx.size == 0:
            break
        step = controlled_step(th, vv, tt, params, controller, reference=reference, wrap=True)
        hop, tt, th, vv = step.hop_phase, step.tau, step.theta, step.v
        # NaN hop (cannot leave the racket, or no valid period) compares False: sticking
        sticking = ~(hop / step.omega >= settings.min_hop_s)
        period1 = (
            (np.abs(vv - fp.v_m_s) < tol)
            & (np.abs(phase_difference(th, fp.theta_rad)) < tol)
            & (np.abs(tt - tau_bar) < tol_tau)
            & ~sticking
        )
        settled = sticking | period1
        if settled.any():
            done = idx[settled]
            outcome[done] = np.where(sticking[settled], STICKING, PERIOD1)
            iterations[done] = k
            keep = ~settled
            idx, th, vv, tt = idx[keep], th[keep], vv[keep], tt[keep]
    return Classification(outcome.reshape(shape), iterations.reshape(shape))


# -- basin exit threshold of alpha_p (section 7) ----------------------------------------------
# -- perturbation trials: simulation, alignment and the fit of K and c ------------------------
def simulate_perturbation_trials(params: ModelParams, controller: Controller, *, n_trials: int,
                                 impacts_per_trial: int, perturb_every: int = 5,
                                 alpha_p_low: tuple[float, float] = (0.3, 0.4),
                                 alpha_p_high: tuple[float, float] = (0.6, 0.7),
                                 velocity_noise_sd: float = 0.0, phase_noise_sd: float = 0.0,
                                 period_noise_sd: float = 0.0, seed: int = 0) -> dict:
    """Trials of the controlled stochastic map with section 7's perturbations: every
    ``perturb_every``-th impact has alpha_p drawn uniformly from ``alpha_p_low`` or
    ``alpha_p_high`` (each with probability 1/2), the others alpha_0. Noise per impact:
    velocity and phase as eqs. 16-18 (independent standard normals times the sd) and the
    racket period's own (sd in s, added to the controller's tau_{k+1}). Each trial starts at
    (theta~, v~, tau_bar) and draws from its own stream (``SeedSequence(seed).spawn``).

    Returns the impacts table's columns as arrays, one entry per impact k = 0..
    impacts_per_trial - 1 of each trial (a trial whose ball stops is cut there): trial, k,
    theta_rad (wrapped), v_m_s, racket_period_s (period of the flight ending at the impact),
    alpha, perturbed."""
    v_fp, theta_fp, tau_bar = controlled_fixed_point(params, controller)
    reference = Reference.of(params)
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n_trials)]
    n = impacts_per_trial
    draws = np.stack([rng.standard_normal((n, 3)) for rng in streams])  # (trial, k, 3)
    ups = np.stack([rng.random(n) < 0.5 for rng in streams])
    fracs = np.stack([rng.random(n) for rng in streams])
    k_all = np.arange(n)
    perturbed = np.broadcast_to(perturbed_impact(k_all, perturb_every), (n_trials, n))
    lo = alpha_p_low[0] + fracs * (alpha_p_low[1] - alpha_p_low[0])
    hi = alpha_p_high[0] + fracs * (alpha_p_high[1] - alpha_p_high[0])
    alpha = np.where(perturbed, np.where(ups, hi, lo), params.alpha)

    theta = np.full((n_trials, n), np.nan)
    v, tau = np.full_like(theta, np.nan), np.full_like(theta, np.nan)
    theta[:, 0], v[:, 0], tau[:, 0] = theta_fp, v_fp, tau_bar
    for k in range(1, n):
        step = controlled_step(theta[:, k - 1], v[:, k - 1], tau[:, k - 1], params, controller,
                               reference=reference, alpha=alpha[:, k],
                               velocity_noise=velocity_noise_sd * draws[:, k, 0],
                               phase_noise=phase_noise_sd * draws[:, k, 1],
                               period_noise=period_noise_sd * draws[:, k, 2])
        theta[:, k], v[:, k], tau[:, k] = step.theta, step.v, step.tau
    alive = np.cumprod(np.isfinite(v) & np.isfinite(theta), axis=1).astype(bool)
    trial = np.broadcast_to(np.arange(n_trials)[:, None], (n_trials, n))
    return {
        "trial": trial[alive], "k": np.broadcast_to(k_all, (n_trials, n))[alive],
        "theta_rad": np.mod(theta[alive], TWO_PI), "v_m_s": v[alive],
        "racket_period_s": tau[alive], "alpha": alpha[alive], "perturbed": perturbed[alive],
    }


@dataclass(frozen=True)
class MeanResponse:
    """Mean deviations at impacts j = 0..n after the perturbed impact (j = 0) of one direction
    of perturbation, with the standard errors of the means: v (m/s), theta (rad), racket
    period (s). ``n_events``: perturbations averaged. ``initial``: each event's own deviation
    at j = 0, (n_events, 3) in (m/s, rad, s), or None when only the means are known."""

    direction: str
    dv_m_s: np.ndarray
    dtheta_rad: np.ndarray
    dtau_s: np.ndarray
    se_v_m_s: np.ndarray
    se_theta_rad: np.ndarray
    se_tau_s: np.ndarray
    n_events: int
    initial: np.ndarray | None = None


def align_perturbations(trial, k, v, theta, tau, perturbed, *, alpha=None, alpha_0=None,
                        n_after: int = 4, settle: int = 0) -> dict[str, MeanResponse]:
    """Mean responses to perturbations, by direction ("decrease" / "increase"), with the data
    side's alignment (``engine.data_stats.align``, the one ``bounce impulse --data`` uses).

    One window per perturbed impact: impacts j = 0..n_after of the same trial with
    consecutive k; only complete windows are kept (one cut by a trial's end, a gap in k or
    another perturbation at j >= 1 is dropped: the fit compares whole responses).
    Deviations are from each trial's baseline: the mean of its unperturbed impacts at least
    ``settle`` impacts after a perturbation (v, tau; the circular mean for theta). The
    direction is alpha > alpha_0 when alpha is given, else the sign of dv at j = 0.
    """
    from ..analysis.data_stats import align

    trial, k = np.asarray(trial), np.asarray(k)
    v, theta, tau = (np.asarray(x, float) for x in (v, theta, tau))
    perturbed = np.asarray(perturbed, bool)
    alpha_all = np.zeros_like(v) if alpha is None else np.asarray(alpha, float)
    order = np.lexsort((k, trial))
    labels = list(dict.fromkeys(trial[order]))
    groups = [order[trial[order] == t] for t in labels]
    try:
        aligned = [align([x[g] for g in groups], [perturbed[g] for g in groups],
                         [alpha_all[g] for g in groups], n_after, settle, phase=is_phase,
                         k_trials=[k[g] for g in groups], labels=labels)
                   for x, is_phase in ((v, False), (theta, True), (tau, False))]
    except ModelError as exc:
        if "no perturbed impact" in str(exc):
            return {}
        raise
    values = np.stack([w.values for w in aligned], axis=1)  # (windows, 3, n_after + 1)
    complete = np.all(np.isfinite(values), axis=(1, 2))
    if alpha is not None and alpha_0 is not None:
        up = aligned[0].alpha_p > alpha_0
    else:
        up = values[:, 0, 0] > 0.0
    out = {}
    for direction, sel in (("decrease", ~up & complete), ("increase", up & complete)):
        if not sel.any():
            continue
        arr = values[sel]
        mean = arr.mean(axis=0)
        n = arr.shape[0]
        se = arr.std(axis=0, ddof=1) / math.sqrt(n) if n > 1 else np.full_like(mean, np.nan)
        out[direction] = MeanResponse(direction, mean[0], mean[1], mean[2], se[0], se[1], se[2],
                                      n_events=n, initial=arr[:, :, 0])
    return out


@dataclass(frozen=True)
class ControlFit:
    """Least-squares fit of a period controller (K, c) to mean perturbation responses.

    gain, rate: estimates; *_ci: (low, high) confidence intervals (Wald, t quantile, the
    covariance scaled by the residual variance); offsets: fitted baselines of (v m/s,
    theta rad, tau s) common to both directions (the trial means are not the fixed point);
    eigenvalues: the fitted model's 3 x 3 Jacobian's, by decreasing modulus;
    reduced_chi2: weighted residual sum of squares per degree of freedom (about 1 when the
    standard errors describe the scatter)."""

    gain: float
    rate: float
    gain_ci: tuple[float, float]
    rate_ci: tuple[float, float]
    offsets: tuple[float, float, float]
    eigenvalues: np.ndarray
    spectral_radius: float
    reduced_chi2: float
    n_residuals: int
    success: bool


def predicted_deviations(params: ModelParams, controller: Controller, y0, n_impacts: int):
    """The controlled map's deviations (dv, dtheta, dtau) at impacts 0..n from the fixed point
    (v~, theta~, tau_bar) + y0, y0 = (dv_0 m/s, dtheta_0 rad, dtau_0 s); shape (3, n + 1) or,
    for y0 of shape (3, E) (several starts), (3, n + 1, E)."""
    v_fp, theta_fp, tau_bar = controlled_fixed_point(params, controller)
    theta, v, tau, _ = iterate_controlled(theta_fp + y0[1], v_fp + y0[0], tau_bar + y0[2],
                                          params, controller, n_impacts)
    return np.stack([v - v_fp, phase_difference(theta, theta_fp), tau - tau_bar])


def fit_period_control(params: ModelParams, responses: Sequence[MeanResponse], *,
                       initial: tuple[float, float] = (0.5, 0.5),
                       gain_bounds: tuple[float, float] = (-2.0, 2.0),
                       rate_bounds: tuple[float, float] = (0.0, 2.0),
                       confidence: float = 0.95,
                       controller_of: Callable[[float, float], Controller] = PeriodController,
                       starts_from_grid: int = 3) -> ControlFit:
    """Fit K and c of the period controller to mean responses (``align_perturbations``).

    The model's mean response of a direction is the mean of the controlled map's responses
    (full, not linearised: section 7's perturbations are not small) started from each event's
    own deviation at j = 0 (``MeanResponse.initial``; from the mean deviation when only means
    are known), minus the fitted offsets, at the model's fixed point. Residuals:
    (model + offset - data) / standard error for v, theta and tau at j = 1..n of every
    direction, minimised with ``scipy.optimize.least_squares`` over (K, c, three offsets),
    from ``initial`` and the ``starts_from_grid`` best points of a coarse (K, c) grid (the cost
    has local minima); the lowest minimum wins.

    Measured on trials simulated with K = 0.6, c = 0.7 and section 7's protocol (24 trials
    of 60 impacts, noise 0.05 m/s, 0.02 rad, 5 ms; seeds 100-129, the shared alignment): K is
    biased by about -0.003 (c by +0.002), the 95 % interval's half width is 0.020; the
    intervals held the truth in 29 (K) and 30 (c) of 30 data sets. The bias comes from the
    noise after the perturbed impact (it vanishes without noise): the mean of noisy
    nonlinear responses is not the noiseless response. Starting every model response from
    the mean deviation instead of each event's own adds -0.004 (measured before).
    """
    from scipy import optimize, stats

    data = [(np.stack([r.dv_m_s, r.dtheta_rad, r.dtau_s]),
             np.stack([r.se_v_m_s, r.se_theta_rad, r.se_tau_s]),
             None if r.initial is None else np.asarray(r.initial, float).T)
            for r in responses]
    scales = np.array([np.nanmax(np.abs(d[0][i])) for d in data for i in range(3)]).reshape(
        len(data), 3).max(axis=0)
    floor = 1e-6 * np.where(scales > 0, scales, 1.0)

    def residuals(x):
        controller = controller_of(x[0], x[1])
        offsets = x[2:]
        out = []
        for mean, se, initial in data:
            n = mean.shape[1] - 1
            if initial is None:
                model = predicted_deviations(params, controller, mean[:, 0] - offsets, n)
            else:
                model = np.nanmean(predicted_deviations(
                    params, controller, initial - offsets[:, None], n), axis=-1)
            r = (model[:, 1:] + offsets[:, None] - mean[:, 1:]) / np.maximum(se[:, 1:],
                                                                            floor[:, None])
            out.append(np.where(np.isfinite(r), r, 1e3).ravel())
        return np.concatenate(out)

    lower = [gain_bounds[0], rate_bounds[0], -np.inf, -np.inf, -np.inf]
    upper = [gain_bounds[1], rate_bounds[1], np.inf, np.inf, np.inf]
    # the cost has local minima: start from ``initial`` and the best points of a coarse grid
    grid = [(k, c) for k in np.linspace(-0.25, 1.25, 7) for c in (0.25, 0.5, 0.75, 1.0, 1.25, 1.5)
            if gain_bounds[0] <= k <= gain_bounds[1] and rate_bounds[0] <= c <= rate_bounds[1]]
    cost = [float(np.sum(residuals(np.array([k, c, 0.0, 0.0, 0.0])) ** 2)) for k, c in grid]
    starts = [tuple(initial)] + [grid[i] for i in np.argsort(cost)[:starts_from_grid]]
    sol = min((optimize.least_squares(residuals, np.array([k, c, 0.0, 0.0, 0.0]),
                                      bounds=(lower, upper), x_scale="jac") for k, c in starts),
              key=lambda res: res.cost)
    m, p = sol.fun.size, sol.x.size
    dof = max(m - p, 1)
    chi2 = float(sol.fun @ sol.fun) / dof
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * chi2
        half = stats.t.ppf(0.5 + confidence / 2.0, dof) * np.sqrt(np.diag(cov))
    except np.linalg.LinAlgError:
        half = np.full(p, np.nan)
    gain, rate = float(sol.x[0]), float(sol.x[1])
    controller = controller_of(gain, rate)
    eig = np.linalg.eigvals(controlled_jacobian(params, controller))
    eig = eig[np.argsort(-np.abs(eig))]
    return ControlFit(
        gain=gain, rate=rate,
        gain_ci=(gain - half[0], gain + half[0]), rate_ci=(rate - half[1], rate + half[1]),
        offsets=(float(sol.x[2]), float(sol.x[3]), float(sol.x[4])), eigenvalues=eig,
        spectral_radius=float(np.abs(eig).max()), reduced_chi2=chi2, n_residuals=m,
        success=bool(sol.success),
    )


# -- the fastest period controller ------------------------------------------------------------
@dataclass(frozen=True)
class FastestController:
    """A (K, c) where the spectral radius of the controlled map is smallest, and that radius."""

    gain: float
    rate: float
    spectral_radius: float


def fastest_immediate_controller(params: ModelParams) -> FastestController:
    """Smallest spectral radius along K at c = 1, in closed form.

    With c = 1 one eigenvalue is 0 and the others solve lambda^2 - T lambda + D = 0 with
    D = alpha^2 - K A, T = 1 + alpha^2 + B - K (A + B), A = (1 - alpha)^2, B = (1+alpha)^2 AC.
    While they are complex |lambda| = sqrt(D) falls with K; the minimum is where the pair
    becomes real (T^2 = 4 D), at the larger root K of
    (A + B)^2 K^2 + (4 A - 2 (1 + alpha^2 + B)(A + B)) K + (1 + alpha^2 + B)^2 - 4 alpha^2 = 0.
    Where the pair is never complex (with D >= 0) the minimum of a fine grid of K in [-2, 2]."""
    alpha = params.alpha
    ac = racket_acceleration_at_impact_g(params)
    A, B = (1.0 - alpha) ** 2, (1.0 + alpha) ** 2 * ac
    t0, s = 1.0 + alpha**2 + B, A + B
    roots = np.roots([s * s, 4.0 * A - 2.0 * t0 * s, t0 * t0 - 4.0 * alpha**2])
    roots = roots[np.isreal(roots)].real
    roots = roots[alpha**2 - roots * A >= 0.0]
    if len(roots):
        gain = float(roots.max())
        return FastestController(gain, 1.0, math.sqrt(alpha**2 - gain * A))
    # the pair never turns complex (the passive map is in eq. 14's real regime): a fine grid
    gains = np.linspace(-2.0, 2.0, 40001)
    radius = period_control_radius(params, gains, 1.0)
    i = int(np.argmin(radius))
    return FastestController(float(gains[i]), 1.0, float(radius[i]))


def fastest_controller(params: ModelParams, guess: tuple[float, float]) -> FastestController:
    """Smallest spectral radius over (K, c): where all three eigenvalues coincide (a triple
    real root: the characteristic polynomial is (lambda - r)^3), found from ``guess`` (the
    best point of a grid) by solving trace = 3 r, sum of principal 2 x 2 minors = 3 r^2,
    det = r^3 for (K, c, r). The radius has a cusp there, which grid or simplex searches
    resolve poorly. Falls back to the guess when the solve fails."""
    from scipy import optimize

    def radius_at(k, c):
        return float(spectral_radius_3x3(controlled_jacobian(params, PeriodController(k, c))))

    def equations(x):
        k, c, r = x
        poly = np.poly(controlled_jacobian(params, PeriodController(k, c)))
        return [poly[1] + 3 * r, poly[2] - 3 * r * r, poly[3] + r**3]

    k0, c0 = guess
    r0 = radius_at(k0, c0)
    sol, _, ok, _ = optimize.fsolve(equations, [k0, c0, r0], full_output=True, xtol=1e-13)
    if ok == 1 and abs(sol[0] - k0) < 0.2 and abs(sol[1] - c0) < 0.2:
        found = radius_at(sol[0], sol[1])
        if found <= r0:
            return FastestController(float(sol[0]), float(sol[1]), found)
    return FastestController(float(k0), float(c0), r0)


# -- one orbit (``bounce orbit`` with control) ---------------------------------------------------
@dataclass(frozen=True)
class ControlledOrbit:
    """One orbit of the controlled map, stopped as ``engine.maps.Orbit`` is (stop_reason ""
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
    """``engine.maps.iterate_orbit`` for the controlled map from (theta0, v0, tau0 = tau_bar):
    stops after a hop shorter than ``min_hop_s`` or when the ball cannot fly (also
    when the controller asks for a period <= 0), at once when v0 is not above the racket's
    velocity (with tau0)."""
    reference = Reference.of(params)
    tau0 = params.racket_period if tau0 is None else float(tau0)
    theta, v, tau, hop = [float(theta0)], [float(v0)], [tau0], [math.nan]
    reason = ""
    if not can_fly_at(theta0, v0, params.racket_amplitude, TWO_PI / tau0, params.g):
        reason = "below_racket"
    else:
        for _ in range(n_impacts):
            step = controlled_step(theta[-1], v[-1], tau[-1], params, controller,
                                   reference=reference)
            theta.append(float(step.theta))
            v.append(float(step.v))
            tau.append(float(step.tau))
            hop.append(float(step.hop_phase))
            if not float(step.hop_seconds()) >= min_hop_s:  # NaN: cannot fly
                reason = "sticking"
                break
    return ControlledOrbit(np.array(theta), np.array(v), np.array(tau), np.array(hop), reason)


def classify_controlled_grid(theta0, v0, params: ModelParams, controller: Controller,
                             settings: ClassifySettings = ClassifySettings(), *,
                             tile_points: int = 1 << 15, on_tile_done=None,
                             period_tolerance_s: float | None = None) -> Classification:
    """``classify_controlled`` over large arrays in tiles of at most ``tile_points`` (in this
    process; ``on_tile_done(n)`` after each, for a progress bar). A point's result does not
    depend on the tiling."""
    theta0, v0 = np.broadcast_arrays(np.asarray(theta0, dtype=float), np.asarray(v0, dtype=float))
    shape = theta0.shape
    theta0, v0 = theta0.ravel(), v0.ravel()
    outcome = np.empty(theta0.shape, dtype=np.int8)
    iterations = np.empty(theta0.shape, dtype=np.int16)
    for tile in tile_slices(theta0.size, tile_points):
        res = classify_controlled(theta0[tile], v0[tile], params, controller, settings,
                                  period_tolerance_s=period_tolerance_s)
        outcome[tile], iterations[tile] = res.outcome, res.iterations
        if on_tile_done is not None:
            on_tile_done(res.outcome.size)
    return Classification(outcome.reshape(shape), iterations.reshape(shape))


def controlled_impulse_response_linear(params: ModelParams, controller: Controller,
                                       alpha_p: float, n_impacts: int) -> ControlledResponse:
    """The linearised controlled map y_{k+1} = M y_k (M: the 3 x 3 Jacobian) from
    y_0 = (v_0 - v~, 0, 0), as ``engine.impulse_response_linear`` is for eq. 9's J."""
    v_fp, theta_fp, tau_bar = controlled_fixed_point(params, controller)
    y = iterate_linear(controlled_jacobian(params, controller),
                       [perturbed_velocity(params, alpha_p) - v_fp, 0.0, 0.0], n_impacts)
    v = v_fp + y[:, 0]  # dv = v - v~ as ``engine.impulse`` computes it (same bits at K = 0)
    return ControlledResponse(v=v, theta=np.mod(theta_fp + y[:, 1], TWO_PI),
                              tau=tau_bar + y[:, 2], dv=v - v_fp, dtheta=y[:, 1], dtau=y[:, 2])


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


def simulate_controlled_motion(theta0: float, v0: float, params: ModelParams,
                               controller: Controller, duration_s: float, settings):
    """``engine.flight.simulate`` (exact integrator) with racket period control: the ball
    leaves the racket at phase theta0 (t0 = theta0 / w_bar) with v0; at the launch and at
    every impact the controller sets the racket's period from then on (``switch: impact``,
    the map of this module: the phase stays continuous, the racket's velocity jumps). Sticking
    as in ``engine.flight`` (a hop shorter than ``settings.min_hop_s``, or a ball that leaves no
    faster than the racket then moves): the ball rides on the racket, which keeps its period,
    until the racket's downward acceleration exceeds g. Returns (Trajectory, RacketClock,
    periods): the racket's period during the flight that ended at each impact (s), as
    ``iterate_controlled_orbit``'s tau."""
    from .flight import LEAVE_NUDGE_PHASE, Impact, Segment, Trajectory, impact_velocity

    a, g = params.racket_amplitude, params.g
    reference = Reference.of(params)
    tau = params.racket_period
    t = theta0 * tau / TWO_PI
    t0, t_end = t, t + duration_s
    phase = float(theta0)
    tau = float(controller.next_period(v0, theta0, tau, reference))
    if not tau > 0.0:
        raise ModelError("the controller asks for a racket period <= 0 at the launch")
    starts, phases, omegas = [t], [phase], [TWO_PI / tau]
    segments: list = []
    impacts: list = []
    periods: list[float] = []
    v = float(v0)
    omega = omegas[-1]

    def racket(time):
        ph = phases[-1] + omega * (time - starts[-1])
        return ph, a * math.sin(ph), a * omega * math.cos(ph)

    stuck = not bool(can_fly_at(phase, v, a, omega, g))
    while t < t_end:
        ph, x_r, v_r = racket(t)
        if stuck:
            ratio = g / (a * omega**2)
            if ratio >= 1.0:
                leave = math.inf
            elif math.sin(ph) > ratio:
                leave = ph
            else:
                leave = ph + float(np.mod(math.asin(ratio) - ph, TWO_PI))
            t_leave = t + (leave - ph) / omega
            segments.append(Segment("stuck", t, min(t_leave, t_end), x_r, v_r))
            t = t_leave
            if math.isfinite(t):
                v = racket(t)[2]
            stuck = False
            continue
        launch_ph, launch_v = ph, v
        if v - v_r <= 0.0:  # leaving with the racket's velocity: hand over just after
            launch_ph, launch_v = ph + LEAVE_NUDGE_PHASE, v - g * LEAVE_NUDGE_PHASE / omega
        hop = float(first_impact_phase(launch_ph, launch_v, a, omega, g))
        if not math.isfinite(hop):
            raise ModelError(f"no next impact found after t = {t:.6g} s")
        t_hit = t + (launch_ph - ph + hop) / omega
        segments.append(Segment("flight", t, min(t_hit, t_end), x_r, v))
        if t_hit > t_end:
            break
        ph_hit, _, racket_v = racket(t_hit)
        v_before = v - g * (t_hit - t)
        v_after = impact_velocity(v_before, racket_v, params.alpha)
        impacts.append(Impact(t_hit, ph_hit, v_before, v_after, racket_v, t_hit - t))
        periods.append(tau)  # the period of the flight that ended at this impact
        tau_next = float(controller.next_period(v_after, ph_hit, tau, reference))
        if not tau_next > 0.0:
            raise ModelError(f"the controller asks for a racket period <= 0 at t = {t_hit:.4g} s")
        tau, omega = tau_next, TWO_PI / tau_next
        starts.append(t_hit)
        phases.append(ph_hit)
        omegas.append(omega)
        t, v = t_hit, v_after
        stuck = (t_hit - segments[-1].t_start < settings.min_hop_s
                 or v - a * omega * math.cos(ph_hit) <= settings.min_relative_velocity_m_s
                 or not bool(can_fly_at(ph_hit, v, a, omega, g)))
    clock = RacketClock(np.array(starts), np.array(phases), np.array(omegas))
    trajectory = Trajectory(params, t0, t_end, tuple(segments), tuple(impacts))
    return trajectory, clock, np.array(periods)
