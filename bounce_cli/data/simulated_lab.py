"""A simulated lab session with known truth: sampled racket and ball positions per trial.

The racket moves cycle by cycle (section 2, eq. 4): cycle c starts at an upward crossing of the
racket's mid-position at time t_c, lasts T_c and has amplitude a_c, so inside it

    x_r(t) = d(t) + a_c sin(theta),   theta = 2 pi (t - t_c) / T_c  in [0, 2 pi),

with a slow drift d(t) = D sin(2 pi t / P) of the mid-position. The phase advances by 2 pi per
cycle and is linear inside it: on this racket the data definition of the phase of impact (from
one upward mid-position crossing to the next, mapped linearly onto [0, 2 pi)) is exactly the
model's theta. Each cycle's T_c and a_c are drawn around the model's tau and a_r (per-cycle SDs;
0 gives the model's sinusoid, eq. 4). Between cycles the position and the acceleration are
continuous; the velocity jumps by 2 pi (a_{c+1}/T_{c+1} - a_c/T_c) where T or a change.

The ball flies ballistically (eqs. 1, 2) and bounces by the impact law eq. 3
(``flight.impact_velocity``), with velocity noise q_v xi_k added to every velocity after
impact as in eq. 16. Perturbation events replace alpha by alpha_p at chosen impacts (section 7).
The next impact is the FIRST contact after the current one, found by the safe-step iteration of
``model.impact`` (the gap's lower bound G + G' h - M h^2 / 2 with M >= |G''| proves each step
root-free), here in time and for the drifting, cycle-wise racket: steps never cross a cycle
boundary, where M changes. With zero SDs and no drift the impacts are those of
``flight.simulate`` (tested).

The ball is launched from the racket at the fixed point (eqs. 7, 8): phase theta~ of the
racket's first cycle, velocity v~. Without ``rest_s`` that happens before the recording starts
(t = 0 falls in the racket's second cycle); with ``rest_s`` the ball first rests on the still
racket, which starts its first cycle at ``rest_s``, and the launch is the trial's impact 0.

A physical set-up's imperfections (all off by default, when the above holds exactly):

* a racket that is not a pure sine: a second harmonic ``harmonic2_m`` sin(2 theta) in each
  cycle (odd about the cycle's mid-position crossing, so theta = 0 stays that crossing and the
  mid-position stays (peak + trough) / 2; the amplitude (peak - trough) / 2 grows to
  ``harmonic_amplitude``), and the short disturbance the impact gives the racket (section 2:
  it "dies out after approximately 100 ms"): -A (1 - u)^2 sin(2 pi u), u = (t - t_0) / D in
  (0, 1), from the ball's release t_0 (``disturbance_m`` A, ``disturbance_s`` D), exactly zero
  after D;
* restitution varying per impact: alpha_k + ``alpha_sd`` xi_k;
* a compliant contact of duration ``contact_s``: from the touch (the flight meets the racket)
  the ball's lowest point y below the racket obeys a linear spring-damper,
  y'' = -g - x_r'' - k y - c y', until y = 0 again (the release); k and c give the contact
  duration pi / omega_d = contact_s and the restitution exp(-zeta pi / sqrt(1 - zeta^2)) =
  alpha_k of a free spring-damper (``spring_damper``). The truth is the EQUIVALENT
  instantaneous impact: the time where the incoming and the outgoing free flights,
  extrapolated, meet (both have the same g: their difference is linear in t, one time), with
  the outgoing flight's velocity v_k and the incoming one's v_in there; eq. 3 at that time
  gives the alpha a recording shows (``alpha_measured``; with an instant contact it differs
  from alpha_k only by eq. 16's noise);
* the ball's marker ``ball_marker_offset_m`` above its lowest point (a marker at the ball's
  centre: its radius).

Randomness: one ``SeedSequence(seed).spawn(n_trials)`` stream per trial, each spawning four
(racket cycles, velocity noise, measurement noise, restitution), so a trial does not depend on
the others (the fourth is drawn from only with ``alpha_sd``: without it the session is the one
three streams gave).
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model.flight import impact_velocity, restitution_of
from ..model.params import ModelError, ModelParams
from .impacts import ball_apex
from ..model.perturbation import perturbed_impact
from .lab_contact import CONTACT_TOLERANCE_M, MAX_CONTACT_STEPS

#: a simulated session's sticking threshold, s: a hop shorter than this is an error (a lab's
#: ball does not chatter); ten times section 3's ``MIN_HOP_S``
LAB_MIN_HOP_S = 0.01

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class SessionSettings:
    """What varies in a simulated session beyond the model's parameters (SI units)."""

    n_trials: int = 2
    duration_s: float = 20.0
    sample_rate_hz: float = 200.0
    position_noise_m: float = 0.0
    period_sd_s: float = 0.0
    amplitude_sd_m: float = 0.0
    velocity_noise_m_s: float = 0.0
    drift_amplitude_m: float = 0.0
    drift_period_s: float = 20.0
    rest_s: float = 0.0
    ball_marker_offset_m: float = 0.0
    perturb_every: int = 0
    perturb_first: int = 4
    perturb_alphas: tuple[float, ...] = ()
    min_hop_s: float = LAB_MIN_HOP_S
    seed: int = 0
    #: a physical set-up (module docstring): compliant contact, restitution SD per impact,
    #: the racket's second harmonic and its disturbance after each impact
    contact_s: float = 0.0
    alpha_sd: float = 0.0
    harmonic2_m: float = 0.0
    disturbance_m: float = 0.0
    disturbance_s: float = 0.1
    #: racket period control (``model.control``): at each impact the controller sets the
    #: period of the racket's NEXT cycle (``switch = "cycle"``); None: the periods are drawn
    controller: Any = None


@dataclass(frozen=True)
class CycleRacket:
    """The racket of one trial: cycles starting at ``starts[c]`` with ``periods[c]`` and
    ``amplitudes[c]``, still (at the drifting mid-position) before ``starts[0]``."""

    starts: np.ndarray
    periods: np.ndarray
    amplitudes: np.ndarray
    drift_amplitude: float = 0.0
    drift_period: float = 20.0
    harmonic2: float = 0.0
    disturbance_m: float = 0.0
    disturbance_s: float = 0.1
    #: where each disturbance starts (the ball's releases), appended as the trial runs
    disturbance_starts: list = field(default_factory=list)

    @property
    def ends(self) -> np.ndarray:
        return self.starts + self.periods

    def harmonic_amplitude(self, amplitude):
        """(peak - trough) / 2 of a sin(theta) + b sin(2 theta), b = ``harmonic2`` (|b| <= a/4):
        the peak where a cos(theta) + 2 b cos(2 theta) = 0, i.e. 4 b c^2 + a c - 2 b = 0 for
        c = cos(theta); the function is odd, so the trough is minus the peak."""
        a = np.asarray(amplitude, dtype=float)
        b = abs(self.harmonic2)
        if b == 0.0:
            return a
        c = (-a + np.sqrt(a * a + 32.0 * b * b)) / (8.0 * b)
        return np.sqrt(1.0 - c * c) * (a + 2.0 * b * c)

    def _disturbance(self, t, derivative: int):
        """The sum of the live disturbances at t (their ``derivative``-th time derivative)."""
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape)
        if self.disturbance_m == 0.0:
            return out
        a, d = self.disturbance_m, self.disturbance_s
        for t0 in self.disturbance_starts:
            u = (t - t0) / d
            live = (u > 0.0) & (u < 1.0)
            if not np.any(live):
                continue
            w, s_, c_ = 1.0 - u, np.sin(TWO_PI * u), np.cos(TWO_PI * u)
            if derivative == 0:
                value = w * w * s_
            elif derivative == 1:
                value = (-2.0 * w * s_ + TWO_PI * w * w * c_) / d
            else:
                value = (2.0 * s_ - 4.0 * TWO_PI * w * c_ - TWO_PI**2 * w * w * s_) / (d * d)
            out = out - np.where(live, a * value, 0.0)
        return out

    def disturbance_acceleration_bound(self) -> float:
        """max |d''| of one disturbance: A / D^2 (2 + 4 (2 pi) + (2 pi)^2)."""
        return abs(self.disturbance_m) / self.disturbance_s**2 * (
            2.0 + 4.0 * TWO_PI + TWO_PI**2)

    def cycle_index(self, t):
        """Index of the cycle holding t (-1 before the first cycle)."""
        return np.searchsorted(self.starts, np.asarray(t, dtype=float), side="right") - 1

    def _cycle(self, t):
        t = np.asarray(t, dtype=float)
        c = self.cycle_index(t)
        moving = c >= 0
        cc = np.maximum(c, 0)
        omega = 2.0 * np.pi / self.periods[cc]
        theta = omega * (t - self.starts[cc])
        amp = np.where(moving, self.amplitudes[cc], 0.0)
        return t, amp, omega, theta

    def phase(self, t):
        """Phase of the racket in its cycle, [0, 2 pi) (NaN before the first cycle)."""
        t, amp, omega, theta = self._cycle(t)
        return np.where(self.cycle_index(t) >= 0, np.mod(theta, 2.0 * np.pi), np.nan)

    def drift(self, t, derivative: int = 0):
        k = 2.0 * np.pi / self.drift_period
        arg = k * np.asarray(t, dtype=float)
        return self.drift_amplitude * k**derivative * np.sin(arg + derivative * np.pi / 2.0)

    def _harmonic(self, amp):
        return np.where(amp != 0.0, self.harmonic2, 0.0)  # only while the racket moves

    def position(self, t):
        t, amp, omega, theta = self._cycle(t)
        return (self.drift(t) + amp * np.sin(theta)
                + self._harmonic(amp) * np.sin(2.0 * theta) + self._disturbance(t, 0))

    def velocity(self, t):
        t, amp, omega, theta = self._cycle(t)
        return (self.drift(t, 1) + amp * omega * np.cos(theta)
                + 2.0 * self._harmonic(amp) * omega * np.cos(2.0 * theta)
                + self._disturbance(t, 1))

    def acceleration(self, t):
        t, amp, omega, theta = self._cycle(t)
        return (self.drift(t, 2) - amp * omega**2 * np.sin(theta)
                - 4.0 * self._harmonic(amp) * omega**2 * np.sin(2.0 * theta)
                + self._disturbance(t, 2))

    def acceleration_bound(self, c: int) -> float:
        """max |x_r''| over cycle c (or before the first cycle, c = -1); disturbances do not
        overlap (each lasts less than a hop), so one's bound covers them."""
        k = 2.0 * np.pi / self.drift_period
        bound = abs(self.drift_amplitude) * k * k + self.disturbance_acceleration_bound()
        if c >= 0:
            bound += (self.amplitudes[c] + 4.0 * abs(self.harmonic2)) * (
                2.0 * np.pi / self.periods[c]) ** 2
        return float(bound)

    def segment_end(self, t: float) -> float:
        """The next cycle boundary after t (inf after the last cycle)."""
        i = int(np.searchsorted(self.starts, t, side="right"))
        if i < len(self.starts):
            return float(self.starts[i])
        return float(self.ends[-1]) if t < self.ends[-1] else math.inf


def next_contact(t0: float, x0: float, v0: float, g: float, racket: CycleRacket,
                 t_max: float) -> float:
    """First time t > t0 at which the ball, flying from (t0, x0, v0) with x0 >= x_r(t0),
    meets the racket; ``inf`` when it does not before ``t_max``.

    Safe steps on the gap G(t) = ball - racket: from a point with G >= 0 and G' = d, the bound
    |G''| <= M = g + max|x_r''| keeps G > 0 for h < (d + sqrt(d^2 + 2 M G)) / M, so no step
    jumps over a contact; the iteration approaches the first contact from above and ends with
    a Newton step. Steps stop at cycle boundaries (M is per cycle)."""
    t = t0
    steps = 0
    while t < t_max:
        c = int(racket.cycle_index(t))
        bound = g + racket.acceleration_bound(c)
        seg_end = min(racket.segment_end(t), t_max)
        while True:
            dt = t - t0
            gap = x0 + v0 * dt - 0.5 * g * dt * dt - float(racket.position(t))
            slope = v0 - g * dt - float(racket.velocity(t))
            if t > t0 and gap <= CONTACT_TOLERANCE_M:
                if slope < 0.0:
                    t -= gap / slope  # Newton polish from the safe side
                return t
            step = (slope + math.sqrt(slope * slope + 2.0 * bound * max(gap, 0.0))) / bound
            steps += 1
            if steps > MAX_CONTACT_STEPS:
                raise ModelError(f"no contact found after t = {t0:.6g} s (grazing flight)")
            if step <= 0.0:
                raise ModelError(f"the ball cannot leave the racket at t = {t0:.6g} s")
            if t + step >= seg_end:
                t = seg_end
                break
            t += step
    return math.inf


@dataclass
class TrialTruth:
    """One simulated trial: the racket, the ball's flights and the exact impacts."""

    racket: CycleRacket
    flight_starts: np.ndarray  # (t, x, v) where each free flight begins
    flight_x: np.ndarray
    flight_v: np.ndarray
    impact_t: np.ndarray
    impact_v: np.ndarray  # ball velocity just after each impact (with the eq. 16 noise)
    impact_alpha: np.ndarray
    impact_perturbed: np.ndarray
    duration_s: float
    g: float
    extra: dict = field(default_factory=dict)
    #: ball velocity just before each (equivalent) impact; None: v_k's flight's own, eq. 2
    impact_v_in: np.ndarray | None = None
    #: each impact's contact duration, touch to release (0: instantaneous)
    impact_contact_s: np.ndarray | None = None
    #: the compliant contacts: (touch, release, dense solution of (y, y')) each
    contacts: list = field(default_factory=list)

    def ball_position(self, t):
        """Ball position (its lowest point) at times t."""
        t = np.asarray(t, dtype=float)
        i = np.searchsorted(self.flight_starts, t, side="right") - 1
        flying = i >= 0
        ii = np.maximum(i, 0)
        dt = t - self.flight_starts[ii]
        x = self.flight_x[ii] + self.flight_v[ii] * dt - 0.5 * self.g * dt * dt
        x = np.where(flying, x, self.racket.position(t))
        for touch, release, solution in self.contacts:
            inside = (t > touch) & (t < release)
            if np.any(inside):
                x = x.copy()
                x[inside] = self.racket.position(t[inside]) + solution(t[inside])[0]
        return x


def racket_cycles_drawn(params: ModelParams, s: SessionSettings) -> int:
    """How many racket cycles a trial draws: enough to cover it twice over, plus margin.

    The count decides where the amplitudes' draws start in the generator's stream (after the
    periods'), so it must not hinge on a float's last bits: the data side's model sessions
    last a whole number of quarter periods, where the ratio below is an integer up to
    rounding, and a plain ``ceil`` gave one more cycle or not as the racket's mean period
    (measured from the data) moved by an ulp, and with it every amplitude of the session.
    A ratio within 1e-9 of an integer counts as that integer."""
    ratio = (s.duration_s + s.rest_s + 3 * params.racket_period) / (0.5 * params.racket_period)
    return int(math.ceil(ratio - 1e-9 * max(1.0, abs(ratio)))) + 4


def _draw_racket(params: ModelParams, s: SessionSettings, rng: np.random.Generator) -> CycleRacket:
    tau, a = params.racket_period, params.racket_amplitude
    n = racket_cycles_drawn(params, s)
    periods = tau + s.period_sd_s * rng.standard_normal(n)
    amplitudes = a + s.amplitude_sd_m * rng.standard_normal(n)
    if np.any(periods <= 0.2 * tau) or np.any(amplitudes <= 0.0):
        raise ModelError("per-cycle period or amplitude drawn <= 0: lower period_sd_s or "
                         "amplitude_sd_m")
    # the recording starts at t = 0: in the racket's second cycle (a trough) unless it rests
    first = s.rest_s if s.rest_s > 0.0 else -periods[0] - 0.75 * periods[1]
    starts = first + np.concatenate([[0.0], np.cumsum(periods[:-1])])
    # with control the periods change during the trial: keep every drawn cycle
    keep = (starts < s.duration_s + s.rest_s + tau) | (s.controller is not None)
    return CycleRacket(starts[keep], periods[keep], amplitudes[keep],
                       s.drift_amplitude_m, s.drift_period_s, s.harmonic2_m,
                       s.disturbance_m, s.disturbance_s)


def alpha_at(k: int, alpha: float, s: SessionSettings) -> tuple[float, bool]:
    """Coefficient of restitution of impact k: alpha_p at the perturbed impacts (every
    ``perturb_every``-th from ``perturb_first``, cycling through ``perturb_alphas``)."""
    if s.perturb_alphas and perturbed_impact(k, s.perturb_every, s.perturb_first):
        j = (k - s.perturb_first) // s.perturb_every
        return float(s.perturb_alphas[j % len(s.perturb_alphas)]), True
    return alpha, False


def spring_damper(alpha: float, contact_s: float) -> tuple[float, float]:
    """(k, c) per unit mass of the linear spring-damper whose free contact lasts ``contact_s``
    (half a damped period: omega_d = pi / contact_s) with restitution ``alpha`` =
    exp(-zeta pi / sqrt(1 - zeta^2)): zeta = -ln(alpha) / sqrt(pi^2 + ln(alpha)^2),
    omega_n = omega_d / sqrt(1 - zeta^2), k = omega_n^2, c = 2 zeta omega_n.

    Parameters
    ----------
    alpha : float
        Restitution of the free contact, in (0, 1).
    contact_s : float
        Duration of the free contact, s (> 0).

    Returns
    -------
    tuple of float
        Stiffness k (1/s^2) and damping c (1/s), both per unit mass.
    """
    if not 0.0 < alpha < 1.0:
        raise ModelError(f"a compliant contact needs a restitution in (0, 1), got {alpha:.3g} "
                         "(lower alpha_sd)")
    log = math.log(alpha)
    zeta = -log / math.sqrt(math.pi**2 + log * log)
    omega_n = math.pi / contact_s / math.sqrt(1.0 - zeta * zeta)
    return omega_n * omega_n, 2.0 * zeta * omega_n


def compliant_contact(t_touch: float, closing_v: float, g: float, racket: CycleRacket,
                      alpha: float, contact_s: float):
    """The spring-damper contact from the touch (the ball's lowest point at the racket,
    closing at ``closing_v`` = ball minus racket velocity < 0) to the release (y = 0 again):
    (release time, y' there, dense solution of (y, y')). y'' = -g - x_r'' - k y - c y'."""
    from scipy.integrate import solve_ivp  # (its import: a physical set-up's contacts only)

    k, c = spring_damper(alpha, contact_s)

    def rhs(t, state):
        y, dy = state
        return [dy, -g - float(racket.acceleration(t)) - k * y - c * dy]

    def released(t, state):
        return state[0]

    released.terminal, released.direction = True, 1.0  # type: ignore[attr-defined]
    sol = solve_ivp(rhs, (t_touch, t_touch + 20.0 * contact_s), [0.0, closing_v],
                    method="DOP853", rtol=1e-10, atol=1e-13, max_step=contact_s / 20.0,
                    events=released, dense_output=True)
    if sol.t_events[0].size == 0:
        raise ModelError(f"the ball fell into sticking at t = {t_touch:.3f} s (it stayed on "
                         "the racket through the contact): lower velocity_noise_m_s, the "
                         "racket's variation or the perturbations, or change the model "
                         "parameters")
    t_release = float(sol.t_events[0][0])
    return t_release, float(sol.y_events[0][0][1]), sol.sol


def equivalent_impact(t_in: float, x_in: float, v_in: float, t_out: float, x_out: float,
                      v_out: float, g: float) -> tuple[float, float, float]:
    """The equivalent instantaneous impact of a finite contact: where the incoming flight
    (from (t_in, x_in, v_in)) and the outgoing one (from (t_out, x_out, v_out)), both
    constant-g parabolas (eq. 1), meet. Their difference is linear in t: one time.

    Parameters
    ----------
    t_in, x_in, v_in : float
        A point of the incoming flight: time (s), position (m), velocity (m/s).
    t_out, x_out, v_out : float
        A point of the outgoing flight.
    g : float
        Gravitational acceleration, m/s^2.

    Returns
    -------
    tuple of float
        (time, incoming velocity, outgoing velocity) there.
    """
    def gap(t):
        a, b = t - t_in, t - t_out
        return (x_in + v_in * a - 0.5 * g * a * a) - (x_out + v_out * b - 0.5 * g * b * b)

    slope = (v_in - g * (t_out - t_in)) - v_out  # d gap / dt, constant
    t_eq = t_out - gap(t_out) / slope
    return t_eq, v_in - g * (t_eq - t_in), v_out - g * (t_eq - t_out)


def common_path(s: SessionSettings) -> bool:
    """True when a session has none of the physical set-up's imperfections, no perturbations
    and no controller: the path ``compiled_lab`` runs compiled."""
    return (s.contact_s == 0.0 and s.alpha_sd == 0.0 and s.harmonic2_m == 0.0
            and s.disturbance_m == 0.0 and s.drift_amplitude_m == 0.0 and s.controller is None
            and not s.perturb_alphas)


def compiled_lab_available() -> bool:
    """True when the compiled contact loop (``compiled_lab``, numba) can be used: the
    environment variable ``BOUNCE_LAB`` is not ``python`` and the module imports (numba
    installed and willing); otherwise the Python loop runs, with the same results."""
    if os.environ.get("BOUNCE_LAB", "auto").strip().lower() == "python":
        return False
    return _compiled_lab_imports()


@functools.lru_cache(maxsize=None)
def _compiled_lab_imports() -> bool:
    from ..model.native import numba_installed

    if not numba_installed():
        return False
    try:
        from . import compiled_lab  # noqa: F401
    except Exception:
        return False
    return True


def simulate_trial(params: ModelParams, s: SessionSettings, streams) -> TrialTruth:
    """One trial's continuous motion and impacts (see the module docstring)."""
    rng_racket, rng_velocity = streams[:2]
    rng_alpha = streams[2] if len(streams) > 2 else None
    g = params.g
    racket = _draw_racket(params, s, rng_racket)
    period_noise = racket.periods - params.racket_period  # each cycle's own deviation
    reference = None
    if s.controller is not None:
        from ..model.control import Reference

        reference = Reference.of(params)
    t_end = s.duration_s
    fp = params.fixed_point()
    t = float(racket.starts[0] + fp.theta_rad / params.omega)  # the launch
    x, v = float(racket.position(t)), fp.v_m_s
    starts, xs, vs = [t], [x], [v]
    times, v_after, alphas, perturbed, v_ins, contact_s = [], [], [], [], [], []
    contacts: list = []
    if t >= 0.0:  # a resting start: the launch is the trial's first impact
        times, v_after, alphas, perturbed = [t], [v], [params.alpha], [False]
        v_ins, contact_s = [math.nan], [0.0]  # no incoming flight: alpha_measured unknown
    if common_path(s) and compiled_lab_available():
        from .compiled_lab import contact_loop

        loop = contact_loop(racket, params, s, t, x, v, rng_velocity)
        if loop is not None:
            flights, impacts = loop
            n = impacts.shape[1]
            return TrialTruth(
                racket, flights[0], flights[1], flights[2],
                np.concatenate([times, impacts[0]]), np.concatenate([v_after, impacts[1]]),
                np.array(alphas + [params.alpha] * n),
                np.array(perturbed + [False] * n, dtype=bool), t_end, g,
                impact_v_in=np.concatenate([v_ins, impacts[2]]),
                impact_contact_s=np.array(contact_s + [0.0] * n), contacts=[])
    while True:
        t_hit = next_contact(t, x, v, g, racket, t_end)
        if not math.isfinite(t_hit):
            break
        v_before = v - g * (t_hit - t)
        racket_v = float(racket.velocity(t_hit))
        k = len(times)
        alpha_k, is_perturbed = alpha_at(k, params.alpha, s)
        if s.alpha_sd > 0.0 and rng_alpha is not None:
            alpha_k += s.alpha_sd * float(rng_alpha.standard_normal())
        hop = t_hit - t
        if s.contact_s > 0.0:
            t_release, dy, solution = compliant_contact(t_hit, v_before - racket_v, g, racket,
                                                        alpha_k, s.contact_s)
            release_v = float(racket.velocity(t_release))
            v_out = release_v + dy + s.velocity_noise_m_s * float(rng_velocity.standard_normal())
            x_release = float(racket.position(t_release))
            t_k, v_in, v_new = equivalent_impact(t, x, v, t_release, x_release, v_out, g)
            leaves = v_out > release_v
        else:
            v_new = impact_velocity(v_before, racket_v, alpha_k)
            v_new += s.velocity_noise_m_s * float(rng_velocity.standard_normal())
            t_release, x_release, v_out, t_k, v_in = (t_hit, float(racket.position(t_hit)),
                                                      v_new, t_hit, v_before)
            leaves = v_new > racket_v
        if t_hit >= 0.0 and (hop < s.min_hop_s or not leaves):
            why = (f"a hop of {hop:.3g} s" if hop < s.min_hop_s else
                   "it leaves the racket no faster than the racket moves")
            raise ModelError(
                f"the ball fell into sticking at t = {t_hit:.3f} s ({why}): lower "
                "velocity_noise_m_s, the racket's variation or the perturbations, or change "
                "the model parameters")
        if s.disturbance_m != 0.0:
            if racket.disturbance_starts and t_release - racket.disturbance_starts[-1] < (
                    s.disturbance_s):
                raise ModelError(f"a hop shorter than racket.disturbance_s at t = "
                                 f"{t_hit:.3f} s: shorten the disturbance")
            racket.disturbance_starts.append(t_release)
        if t_release > t_hit:
            contacts.append((t_hit, t_release, solution))
        if t_k >= 0.0:
            times.append(t_k)
            v_after.append(v_new)
            alphas.append(alpha_k)
            perturbed.append(is_perturbed)
            v_ins.append(v_in)
            contact_s.append(t_release - t_hit)
        if s.controller is not None:
            set_next_period(racket, t_k, v_new, s.controller, reference, period_noise,
                            params.racket_period)
        t, x, v = t_release, x_release, v_out
        starts.append(t)
        xs.append(x)
        vs.append(v)
    return TrialTruth(racket, np.array(starts), np.array(xs), np.array(vs),
                      np.array(times), np.array(v_after), np.array(alphas),
                      np.array(perturbed, dtype=bool), t_end, g,
                      impact_v_in=np.array(v_ins), impact_contact_s=np.array(contact_s),
                      contacts=contacts)


def set_next_period(racket: CycleRacket, t: float, v: float, controller, reference,
                    period_noise: np.ndarray, tau_bar: float) -> None:
    """Racket period control at an impact at time t with ball velocity v (after impact):
    the controller's tau_{k+1} from (v, the phase of the impact in its cycle, that cycle's
    period) becomes the period of every later cycle (plus each cycle's own drawn deviation
    ``period_noise``) until the next impact sets another; the later cycles' starts follow.
    The current cycle is not changed (the racket's position and velocity stay continuous
    up to the next crossing)."""
    c = int(racket.cycle_index(t))
    if c < 0 or c + 1 >= len(racket.periods):
        return
    tau_k = float(racket.periods[c])
    tau_next = float(controller.next_period(v, float(racket.phase(t)), tau_k, reference))
    periods = tau_next + period_noise[c + 1:]
    if not np.all(periods > 0.2 * tau_bar):
        raise ModelError(f"the controller asks for a racket period of {tau_next:.3g} s at "
                         f"t = {t:.3f} s (below 20 % of {tau_bar:g} s): lower the gain")
    racket.periods[c + 1:] = periods
    racket.starts[c + 2:] = racket.starts[c + 1] + np.cumsum(periods[:-1])


def impact_state(truth: TrialTruth) -> dict[str, np.ndarray]:
    """The exact impacts' state and racket cycle: velocity after impact (m/s), phase in the
    impact's racket cycle (rad) and that cycle's period (s) and amplitude (m) -- the columns
    of :func:`truth_rows` that a model session (``data.simulated_runs``) keeps."""
    r, t = truth.racket, truth.impact_t
    c = r.cycle_index(t)
    return {"v_m_s": truth.impact_v, "theta_rad": r.phase(t),
            "racket_period_s": r.periods[c],
            "racket_amplitude_m": r.harmonic_amplitude(r.amplitudes[c])}


def truth_rows(truth: TrialTruth) -> dict[str, np.ndarray]:
    """The exact impacts in the impacts table's variables (``bounce_cli.data.impacts``)."""
    r, g = truth.racket, truth.g
    t = truth.impact_t
    state = impact_state(truth)
    theta, v = state["theta_rad"], state["v_m_s"]
    hop = np.append(np.diff(t), np.nan)
    v_in = truth.impact_v_in
    racket_v = r.velocity(t)
    alpha_measured = restitution_of(v_in, v, racket_v)  # eq. 3 at the equivalent impact
    apex = ball_apex(t, v, r.position(t), np.append(t[1:], truth.duration_s), g, r.drift)
    return {
        "k": np.arange(len(t)),
        "t_s": t,
        "theta_rad": theta,
        "theta_deg": np.degrees(theta),
        "v_m_s": v,
        "racket_acc_g": r.acceleration(t) / g,
        "racket_period_s": state["racket_period_s"],
        "racket_amplitude_m": state["racket_amplitude_m"],
        "hop_s": hop,
        "ball_apex_m": apex,
        "alpha": truth.impact_alpha,
        "perturbed": truth.impact_perturbed,
        "v_in_m_s": v_in,
        "alpha_measured": alpha_measured,
        "contact_s": truth.impact_contact_s,
    }


def sample_trial(truth: TrialTruth, s: SessionSettings, rng: np.random.Generator):
    """(t, racket_x, ball_x) sampled at ``sample_rate_hz`` on [0, duration] with Gaussian
    measurement noise; the ball marker sits ``ball_marker_offset_m`` above the ball's lowest
    point (its radius for a marker at its centre)."""
    n = int(math.floor(s.duration_s * s.sample_rate_hz + 1e-9)) + 1
    t = np.arange(n) / s.sample_rate_hz
    racket = truth.racket.position(t)
    ball = truth.ball_position(t) + s.ball_marker_offset_m
    if s.position_noise_m > 0.0:
        racket = racket + s.position_noise_m * rng.standard_normal(n)
        ball = ball + s.position_noise_m * rng.standard_normal(n)
    return t, racket, ball


def simulate_session(params: ModelParams, s: SessionSettings):
    """Every trial: a list of (truth, (t, racket_x, ball_x)), one stream per trial."""
    trials = []
    for seq in np.random.SeedSequence(s.seed).spawn(s.n_trials):
        racket_seq, velocity_seq, noise_seq, alpha_seq = seq.spawn(4)
        truth = simulate_trial(params, s, (np.random.default_rng(racket_seq),
                                           np.random.default_rng(velocity_seq),
                                           np.random.default_rng(alpha_seq)))
        samples = sample_trial(truth, s, np.random.default_rng(noise_seq))
        trials.append((truth, samples))
    return trials
