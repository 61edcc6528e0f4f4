"""Bifurcation sweeps of the ball bouncing map: one parameter over a range, many initial
conditions per value, all iterated together (eqs. 5, 6), with the attractor found and its
largest Lyapunov exponent.

The map depends on its four parameters only through alpha and Gamma = a_r w^2 / g (with the
velocity in units of g / w): eqs. 8 and 14 put the period-1 orbit's existence at
Gamma = pi (1-alpha)/(1+alpha) (cos theta~ = 1) and its flip (period doubling, lambda_- = -1)
where AC reaches -2 (1+alpha^2)/(1+alpha)^2, i.e.
Gamma^2 = AC_flip^2 + pi^2 ((1-alpha)/(1+alpha))^2.

Every state carries its own parameter point (:class:`ParameterArrays`), so all values and
initial conditions advance in one vectorised first-impact solve per impact; nothing here needs
the period-1 orbit to exist. The attractor of an orbit is read from the impacts recorded after
a transient, in the wrapped phase (phases compared modulo 2 pi):

* ``below_racket``: the initial velocity is not above the racket's (the ball cannot leave);
* ``sticking``: some hop lasted less than the sticking interval (section 3's criterion; the
  map cannot continue a ball that rests on the racket);
* ``period<p>``: the smallest p <= max_period with |v_{k+p} - v_k| and |theta_{k+p} - theta_k|
  (mod 2 pi) below the tolerance at every recorded impact;
* ``chaotic``: no such p and a positive largest Lyapunov exponent (above a threshold);
* ``unresolved``: no such p and a non-positive exponent (a longer period, or an orbit that has
  not settled within the transient, as happens right at a bifurcation).

With ``min_hop_s`` 0 (exact sticking, ``model.chatter``) an orbit is not stopped where it
sticks: it rides to the release and flies on from there (the release state is the same every
time). ``locked``: it was released at least twice during the measured impacts (periodic from
its first release; ``SweepOrbits.locked_cycles`` racket cycles per period; the recorded
impacts are the resolved ones of a period); its exponent is -inf (a stick forgets every
perturbation), as for any orbit that stuck while measured. ``resting``: stuck with Gamma <= 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from scipy.optimize import brentq

from ..model.impact import can_fly
from ..model.linear import ac_explicit_g, flip_boundary_g, spectral_radius, with_parameters
from .lyapunov import advance_tangent, initial_tangent, map_jacobian
from ..model.maps import map_step
from ..model.params import MIN_HOP_S, ModelError, ModelParams, gamma, phase_difference

TWO_PI = 2.0 * math.pi

#: parameters a sweep can vary, with the CSV column (unit in the name) and the axis label
SWEEPABLE: dict[str, tuple[str, str]] = {
    "gamma": ("gamma", r"$\Gamma = a_r \omega_r^2 / g$"),
    "racket_amplitude": ("racket_amplitude_m", r"racket amplitude $a_r$ (m)"),
    "racket_period": ("racket_period_s", r"racket period $\tau$ (s)"),
    "alpha": ("alpha", r"coefficient of restitution $\alpha$"),
}


def parameter_column(parameter: str) -> str:
    """The table column of a swept parameter, with its unit (``racket_amplitude_m``)."""
    return SWEEPABLE[parameter][0]


def column_parameter(column: str) -> str | None:
    """The swept parameter a table column holds (``parameter_column``'s inverse), or None."""
    return next((name for name, (col, _) in SWEEPABLE.items() if col == column), None)


@dataclass(frozen=True)
class ParameterArrays:
    """Model parameters per state: the attributes of ``ModelParams`` as arrays of the states'
    shape, accepted wherever the engine's map functions take ``params``."""

    alpha: np.ndarray
    g: np.ndarray
    racket_amplitude: np.ndarray
    racket_period: np.ndarray

    @property
    def omega(self) -> np.ndarray:
        return 2.0 * np.pi / self.racket_period

    @property
    def gamma(self) -> np.ndarray:
        """Gamma = a_r w^2 / g: the racket's peak acceleration in units of g."""
        return gamma(self.racket_amplitude, self.omega, self.g)

    def racket_velocity(self, phase):
        return self.racket_amplitude * self.omega * np.cos(phase)

    def duck(self) -> Any:
        """This object where a ``ModelParams`` is expected: the engine's map functions read
        only the attributes, which broadcast per state."""
        return self

    def take(self, index) -> "ParameterArrays":
        return ParameterArrays(
            self.alpha[index], self.g[index], self.racket_amplitude[index],
            self.racket_period[index],
        )


def gamma_of(params: ModelParams) -> float:
    """Gamma = a_r w^2 / g of one parameter point."""
    return params.gamma


def parameter_point(base: ModelParams, parameter: str, value: float) -> ModelParams:
    """``base`` with ``parameter`` set to ``value``; Gamma sets a_r = Gamma g / w^2 (g and
    the racket period stay). Raises ModelError for invalid parameters."""
    if parameter not in SWEEPABLE:
        raise ModelError(f"cannot sweep {parameter!r}: choose one of {', '.join(SWEEPABLE)}")
    return with_parameters(base, {parameter: value})


def sweep_parameters(base: ModelParams, parameter: str, values) -> ParameterArrays:
    """One parameter point per value (each validated as a ``ModelParams``)."""
    points = [parameter_point(base, parameter, float(x)) for x in np.ravel(values)]
    return ParameterArrays(
        *(np.array([getattr(p, f) for p in points], dtype=float)
          for f in ("alpha", "g", "racket_amplitude", "racket_period"))
    )


# -- closed forms: where the period-1 orbit exists (eq. 8) and where it flips (eq. 14) -------
@dataclass(frozen=True)
class Period1Thresholds:
    """Values of the swept parameter at which the period-1 orbit appears (eq. 8: cos theta~
    = 1, AC = 0) and loses stability by a flip (eq. 14: AC = -2(1+alpha^2)/(1+alpha)^2,
    lambda_- = -1). NaN where the threshold lies outside the parameter's valid range."""

    existence: float
    flip: float


def threshold_gamma(alpha, ac_g, cycles: int = 1):
    """Gamma at which the period-1 orbit hopping ``cycles`` racket cycles has racket
    acceleration ``ac_g`` at impact (g): the explicit AC formula of section 4,
    Gamma^2 = AC^2 + (n pi (1-alpha)/(1+alpha))^2 (n = 1 in the paper; for n cycles eqs. 7, 8
    read v~ = n pi g / w, cos theta~ = n pi (1-alpha)/(1+alpha) / Gamma, and eq. 9, hence
    eq. 14, is unchanged)."""
    ratio = (1.0 - np.asarray(alpha)) / (1.0 + np.asarray(alpha))
    return np.sqrt(np.square(ac_g) + np.square(cycles * np.pi * ratio))


def period1_thresholds(base: ModelParams, parameter: str, cycles: int = 1) -> Period1Thresholds:
    """Existence (eq. 8) and flip (eq. 14) thresholds of the period-1 orbit (hopping
    ``cycles`` racket cycles; the paper's orbit: 1) in units of the swept parameter, the other
    parameters as in ``base`` (for Gamma and a_r: g and tau fixed)."""
    alpha, g = base.alpha, base.g
    gammas = [float(threshold_gamma(alpha, ac, cycles))
              for ac in (0.0, float(flip_boundary_g(alpha)))]
    if parameter == "gamma":
        return Period1Thresholds(*gammas)
    if parameter == "racket_amplitude":  # a_r = Gamma g / w^2
        return Period1Thresholds(*(x * g / base.omega**2 for x in gammas))
    if parameter == "racket_period":  # Gamma = a_r (2 pi / tau)^2 / g
        return Period1Thresholds(*(TWO_PI * math.sqrt(base.racket_amplitude / (g * x))
                                   for x in gammas))
    if parameter == "alpha":
        # at fixed Gamma; both threshold Gammas decrease monotonically in alpha on [0, 1)
        gamma0 = gamma_of(base)

        def solve(ac_of_alpha):
            f = lambda a: float(threshold_gamma(a, ac_of_alpha(a), cycles)) - gamma0  # noqa: E731
            lo, hi = 0.0, 1.0 - 1e-12
            if f(lo) * f(hi) > 0.0:
                return math.nan
            return brentq(f, lo, hi, xtol=1e-15, rtol=1e-14)

        return Period1Thresholds(solve(lambda a: 0.0), solve(lambda a: float(flip_boundary_g(a))))
    raise ModelError(f"cannot sweep {parameter!r}: choose one of {', '.join(SWEEPABLE)}")


def period1_log_radius(params: ParameterArrays) -> np.ndarray:
    """ln of the spectral radius of eq. 10 per parameter point (NaN where eq. 8 has no
    solution): the Lyapunov exponent of the period-1 orbit where it is stable."""
    ac = ac_explicit_g(params.alpha, params.g, params.racket_amplitude, params.racket_period)
    with np.errstate(invalid="ignore"):
        return np.log(spectral_radius(params.alpha, ac))


# -- iteration -------------------------------------------------------------------------------
@dataclass(frozen=True)
class SweepSettings:
    """How long to iterate and how to read the attractor.

    transient_impacts: discarded. measured_impacts: after the transient; the Lyapunov exponent
    is their mean log growth. recorded_impacts: the last ones of the measured impacts, kept
    (v, wrapped theta) for the diagram and the period (>= 2 max_period). period_tolerance:
    m/s and rad. min_hop_s: a shorter hop is sticking (section 3). chaos_threshold:
    an orbit without a period is chaotic when its exponent (per impact) exceeds this.
    """

    transient_impacts: int = 1000
    measured_impacts: int = 1000
    recorded_impacts: int = 64
    max_period: int = 32
    period_tolerance: float = 1e-6
    min_hop_s: float = MIN_HOP_S
    chaos_threshold: float = 0.0

    def __post_init__(self) -> None:
        if self.recorded_impacts > self.measured_impacts:
            raise ModelError("recorded_impacts must not exceed measured_impacts")
        if self.recorded_impacts < 2 * self.max_period:
            raise ModelError("recorded_impacts must be at least 2 max_period")


@dataclass(frozen=True)
class SweepOrbits:
    """Per state: the recorded impacts (n, recorded_impacts) of v (m/s) and wrapped theta
    (rad), NaN for states that stuck or could not leave; the largest Lyapunov exponent per
    impact (NaN likewise) and its standard error (``lyapunov_standard_error``); the impact at
    which the state stuck (-1: never); whether the ball could leave the racket at all."""

    v: np.ndarray
    theta: np.ndarray
    lyapunov: np.ndarray
    lyapunov_se: np.ndarray
    stuck_at: np.ndarray
    flies: np.ndarray
    first_recorded_impact: int
    #: exact sticking (min_hop_s 0): per state, the racket cycles between its last two
    #: releases when it stuck during the measured impacts (a locked orbit), else 0; None
    #: with the 1 ms rule
    locked_cycles: np.ndarray | None = None
    #: per state: the largest growth (ln) of a perturbation of its start over the orbit
    #: (the tangent vector's log growths summed since the start, at their maximum; 0 if it
    #: never grew). A last bit (relative 1.1e-16) has grown to 1.1e-16 exp(peak_stretch) at
    #: most: where that reaches the scale of a decision, the orbit's outcome is one of the
    #: last bits' (a chaotic transient, a chatter at the edge of the sticking rule)
    peak_stretch: np.ndarray | None = None


def iterate_sweep(
    theta0,
    v0,
    params: ParameterArrays,
    settings: SweepSettings = SweepSettings(),
    on_impact: Callable[[int], None] | None = None,
) -> SweepOrbits:
    """Iterate every state (theta0[i], v0[i]) at its own parameters ``params.take(i)``.

    All states advance together, one vectorised first-impact solve per impact; a state that
    sticks is dropped. The tangent vector of each state is propagated with the Jacobian of
    eqs. 5, 6 at every impact (``map_jacobian``) and renormalised, through the transient too,
    so that it points along the most expanding direction when the measurement starts.
    ``on_impact(1)`` is called after each impact (progress).
    """
    theta0 = np.asarray(theta0, dtype=float).ravel()
    v0 = np.asarray(v0, dtype=float).ravel()
    n = theta0.size
    total = settings.transient_impacts + settings.measured_impacts
    first_recorded = total - settings.recorded_impacts + 1
    v_rec = np.full((n, settings.recorded_impacts), np.nan)
    theta_rec = np.full_like(v_rec, np.nan)
    log_growth = np.zeros(n)
    # the log growth of a perturbation of the start, summed since the start, and its largest
    # value (what a last bit can have grown to)
    stretch, peak_stretch = np.zeros(n), np.zeros(n)
    batches = min(LYAPUNOV_BATCHES, settings.measured_impacts)
    batch_growth = np.zeros((n, batches))  # the same, summed per batch (standard error)
    stuck_at = np.full(n, -1, dtype=np.int64)

    per_state: Any = params  # duck-typed ModelParams: one parameter point per state
    flies: np.ndarray = np.asarray(can_fly(np.mod(theta0, TWO_PI), v0, per_state), dtype=bool)
    idx = np.flatnonzero(flies)
    th, vv, pars = np.mod(theta0[idx], TWO_PI), v0[idx], params.take(idx)
    tangent = initial_tangent(idx.size)
    exact = settings.min_hop_s == 0.0  # exact sticking (model.chatter)
    chatter = _ExactSticking(n, idx.size) if exact else None
    for k in range(1, total + 1):
        if idx.size:
            step = map_step(th, vv, pars.duck(),
                            released=None if chatter is None else chatter.released)
            hop = step.hop_phase
            jac = map_jacobian(th, vv, hop, pars)
            tangent, growth = advance_tangent(tangent, jac, pars)
            stretch[idx] += growth
            peak_stretch[idx] = np.fmax(peak_stretch[idx], stretch[idx])
            if k > settings.transient_impacts:
                log_growth[idx] += growth
                measured = k - settings.transient_impacts - 1
                batch_growth[idx, measured * batches // settings.measured_impacts] += growth
            th, vv = np.mod(step.theta, TWO_PI), step.v
            if k >= first_recorded:
                v_rec[idx, k - first_recorded] = vv
                theta_rec[idx, k - first_recorded] = th
            # a NaN hop (the ball cannot leave after the impact: alpha = 0) is sticking too
            stuck = ~(hop / pars.omega >= settings.min_hop_s)
            if chatter is not None:  # complete chatters: stick, ride, release (or rest)
                th, vv, tangent, stuck = chatter.after_impact(
                    k, k > settings.transient_impacts, idx, th, vv, hop, tangent, pars, stuck)
            if stuck.any():
                stuck_at[idx[stuck]] = k
                keep = ~stuck
                idx, th, vv, tangent = idx[keep], th[keep], vv[keep], tangent[keep]
                pars = pars.take(keep)
                if chatter is not None:
                    chatter.keep(keep)
        if on_impact is not None:
            on_impact(1)

    settled = flies & (stuck_at < 0)
    v_rec[~settled] = np.nan
    theta_rec[~settled] = np.nan
    lyapunov = np.where(settled, log_growth / settings.measured_impacts, np.nan)
    se = np.where(settled, lyapunov_standard_error(batch_growth, settings.measured_impacts),
                  np.nan)
    if chatter is None:
        return SweepOrbits(v_rec, theta_rec, lyapunov, se, stuck_at, flies, first_recorded,
                           peak_stretch=peak_stretch)
    locked = settled & chatter.locked
    lyapunov[locked] = -np.inf  # superstable: a stick forgets the state
    se[locked] = np.nan
    return SweepOrbits(v_rec, theta_rec, lyapunov, se, stuck_at, flies, first_recorded,
                       np.where(locked, chatter.cycles, 0), peak_stretch)


#: batches of the measured impacts for the exponent's standard error (batch means)
LYAPUNOV_BATCHES = 10


def lyapunov_standard_error(batch_growth: np.ndarray, measured_impacts: int) -> np.ndarray:
    """Standard error of finite-time Lyapunov exponents by batch means.

    The exponent is the mean log growth per impact over the measured impacts; the log growths
    of successive impacts are correlated, so their own scatter understates the error. Split
    into ``B`` consecutive batches (``LYAPUNOV_BATCHES``), each batch's mean log growth is an
    estimate of its own, nearly independent of the others when a batch is longer than the
    correlation time, and the standard error of their mean is SD(batch means) / sqrt(B)
    (Flegal & Jones 2010). It measures the scatter a finite measurement leaves within the
    run (the statistics of a chaotic orbit, a tangent vector still turning), not what the run
    is too short to see (an intermittency longer than the run). Two machines whose last bits
    differ follow a chaotic orbit apart and agree on its exponent within a few such errors,
    not digit for digit (``bounce_cli.reproduction.chaotic_tables``).

    Parameters
    ----------
    batch_growth : ndarray, shape (n, B)
        Log growth summed over each batch: batch j holds the measured impacts i (0-based)
        with i * B // measured_impacts == j.
    measured_impacts : int
        The number of measured impacts.

    Returns
    -------
    ndarray, shape (n,)
        The standard error per impact; NaN with fewer than two batches.
    """
    batches = batch_growth.shape[1]
    if batches < 2:
        return np.full(batch_growth.shape[0], np.nan)
    lengths = np.bincount(np.arange(measured_impacts) * batches // measured_impacts,
                          minlength=batches)
    with np.errstate(invalid="ignore"):
        means = batch_growth / lengths
        return means.std(axis=1, ddof=1) / math.sqrt(batches)


class _ExactSticking:
    """``iterate_sweep``'s bookkeeping of exact sticking (``model.chatter``), per state: the
    unwrapped phase since the start (to count racket cycles between releases), the phase of
    the last release, whether the next flight starts at a release, and whether the state
    stuck during the measured impacts (locked)."""

    def __init__(self, n: int, active: int) -> None:
        self.clock = np.zeros(active)  # phase flown since the start, rad (active states)
        self.released = np.zeros(active, dtype=bool)
        self.last_release = np.full(n, np.nan)
        self.cycles = np.zeros(n, dtype=np.int64)
        self.locked = np.zeros(n, dtype=bool)

    def keep(self, keep: np.ndarray) -> None:
        self.clock, self.released = self.clock[keep], self.released[keep]

    def after_impact(self, k, measuring, idx, th, vv, hop, tangent, pars, stuck):
        """States whose chatter's tail is summable stick at its accumulation point and are
        released (state: the release phase, wrapped, and the racket's velocity; tangent
        reset); Gamma <= 1 rests (returned in ``stuck``, as the 1 ms rule's sticking is)."""
        from ..model.chatter import TAIL_TOLERANCE_S, chatter_tail, release_phases

        self.clock += hop
        tail, bound = chatter_tail(th, vv - pars.racket_velocity(th), pars)
        sticks = bound <= TAIL_TOLERANCE_S
        self.released = np.zeros(th.size, dtype=bool)
        if not sticks.any():
            return th, vv, tangent, stuck
        s = np.flatnonzero(sticks)
        at = pars.take(s)
        release = release_phases(th[s] + tail[s], at)
        rests = ~np.isfinite(release)
        stuck = stuck.copy()
        stuck[s[rests]] = True
        s, release = s[~rests], release[~rests]
        if s.size == 0:
            return th, vv, tangent, stuck
        at = pars.take(s)
        self.clock[s] += release - th[s]
        states = idx[s]
        seen = np.isfinite(self.last_release[states])
        self.cycles[states[seen]] = np.rint(
            (self.clock[s][seen] - self.last_release[states[seen]]) / TWO_PI).astype(np.int64)
        self.last_release[states] = self.clock[s]
        if measuring:
            self.locked[states] = True
        th, vv, tangent = th.copy(), vv.copy(), tangent.copy()
        th[s] = np.mod(release, TWO_PI)
        vv[s] = at.racket_velocity(release)
        tangent[s] = initial_tangent(s.size)
        self.released[s] = True
        return th, vv, tangent, stuck


def detect_period(v, theta, max_period: int, tolerance: float) -> np.ndarray:
    """Smallest p <= max_period with |v_{k+p} - v_k| < tolerance (m/s) and
    |theta_{k+p} - theta_k| < tolerance (rad, compared modulo 2 pi) at every recorded k;
    0 where there is none (or the row holds NaN). ``v``, ``theta``: (n, recorded)."""
    v, theta = np.atleast_2d(v), np.atleast_2d(theta)
    period = np.zeros(v.shape[0], dtype=np.int64)
    open_ = np.isfinite(v).all(axis=1) & np.isfinite(theta).all(axis=1)
    for p in range(1, max_period + 1):
        if not open_.any() or p >= v.shape[1]:
            break
        # a row repeats after p impacts only if its last point does: the whole row is
        # compared only there (a chaotic orbit's rows rarely pass; the attractors' discovery
        # spent 5 s of a 20 s point comparing them in full at every p)
        rows = np.flatnonzero(open_ & (np.abs(v[:, -1] - v[:, -1 - p]) < tolerance)
                              & (np.abs(phase_difference(theta[:, -1], theta[:, -1 - p]))
                                 < tolerance))
        dv = np.abs(v[rows, p:] - v[rows, :-p]).max(axis=1)
        dth = np.abs(phase_difference(theta[rows, p:], theta[rows, :-p])).max(axis=1)
        hit = rows[(dv < tolerance) & (dth < tolerance)]
        period[hit] = p
        open_[hit] = False
    return period


def attractor_names(orbits: SweepOrbits, settings: SweepSettings) -> tuple[np.ndarray, np.ndarray]:
    """(attractor name, period) per state; period 0 unless periodic. See the module doc."""
    period = detect_period(orbits.v, orbits.theta, settings.max_period, settings.period_tolerance)
    names = np.where(period > 0, np.char.add("period", period.astype(str)), "unresolved")
    names = names.astype(object)
    chaotic = (period == 0) & (orbits.lyapunov > settings.chaos_threshold)
    names[chaotic] = "chaotic"
    names[orbits.stuck_at >= 0] = "sticking" if orbits.locked_cycles is None else "resting"
    if orbits.locked_cycles is not None:  # exact sticking: released twice while measured
        names[orbits.locked_cycles > 0] = "locked"
    names[~orbits.flies] = "below_racket"
    return names, period


def stopped_flying(orbits: SweepOrbits) -> np.ndarray:
    """Per state: the ball stuck to the racket, rests or is locked to it, or starts below it
    (``attractor_names``' sticking, resting, locked and below_racket): no period of flight."""
    stopped = (orbits.stuck_at >= 0) | ~orbits.flies
    if orbits.locked_cycles is not None:
        stopped |= orbits.locked_cycles > 0
    return stopped


# -- the flip, located on the map itself ------------------------------------------------------
def period_doubling_candidates(
    periods: np.ndarray, max_gap: int = 2
) -> list[tuple[int, int, int]]:
    """In a (values, initial conditions) array of detected periods in sweep order, the places
    where an initial condition's period goes from 1 to 2 or from 2 to 1: (i, j, ic) with
    period 1 or 2 at value i, the other at value j, and at most ``max_gap`` values between
    them without a period (right at a flip an orbit has not settled: no period is read).
    One per i, the first initial condition, in sweep order. A change can also be a jump to a
    coexisting orbit; ``locate_period_doubling`` tells them apart (with a longer transient
    its ends must keep periods 1 and 2)."""
    p = np.asarray(periods)
    found: dict[int, tuple[int, int, int]] = {}
    for step in range(1, max_gap + 2):
        a, b = p[:-step], p[step:]
        change = ((a == 1) & (b == 2)) | ((a == 2) & (b == 1))
        for k in range(1, step):  # nothing settled in between
            change &= p[k:len(p) - step + k] == 0
        for i in np.flatnonzero(change.any(axis=1)):
            found.setdefault(int(i), (int(i), int(i) + step, int(np.argmax(change[i]))))
    return [found[i] for i in sorted(found)]


def hop_cycles(v, params: ModelParams) -> int:
    """Racket cycles per flight of a period-1 orbit with velocity ``v`` after impact: eqs. 5, 6
    with theta_{k+1} = theta_k + 2 pi n give v = n pi g / w (eq. 7 for n = 1)."""
    return int(round(float(v) * params.omega / (math.pi * params.g)))


def continues_period1(v1: float, params1: ModelParams, v2_pair, params2: ModelParams) -> bool:
    """Whether the period-2 orbit with velocities ``v2_pair`` (two successive impacts, at
    ``params2``) can have been born in a flip of the period-1 orbit with velocity ``v1`` (at
    ``params1``, close by): it hops the same racket cycles on average (the two flights of a
    period-2 orbit last 2n racket periods together, as two of the period-1 orbit's) and its
    velocities lie either side of the period-1 one (the flip's eigenvector, eigenvalue -1,
    alternates the sign of the deviation). A period-2 orbit of another family, reached by a
    jump between coexisting orbits, fails one or both."""
    v2 = np.asarray(v2_pair, dtype=float)
    if not (np.all(np.isfinite(v2)) and np.isfinite(v1)):
        return False
    same_cycles = hop_cycles(float(v2.mean()), params2) == hop_cycles(v1, params1)
    return bool(same_cycles and v2.min() <= v1 <= v2.max())


@dataclass(frozen=True)
class FlipLocation:
    """The swept-parameter interval between ``period1_end`` (period 1 detected) and
    ``period2_end`` (the first value beyond it without period 1: period 2 at a supercritical
    flip), found on the map's own orbits (no closed form used); ``cycles``: racket cycles per
    flight of the period-1 orbit that flips."""

    period1_end: float
    period2_end: float
    cycles: int

    @property
    def value(self) -> float:
        return 0.5 * (self.period1_end + self.period2_end)

    @property
    def width(self) -> float:
        return abs(self.period2_end - self.period1_end)


@dataclass(frozen=True)
class FlipBracket:
    """A candidate flip: period 1 detected at ``period1_end``, period 2 at ``period2_end``
    (either may be the larger number), for the orbit from (theta0 rad, v0 m/s)."""

    period1_end: float
    period2_end: float
    theta0: float
    v0: float


def flip_multiplier_floor(settings: SweepSettings) -> float:
    """The least modulus of the period-1 orbit's multiplier at the period-1 end of a narrowed
    flip bracket. At a flip the multiplier is -1; the end is where the orbit still settled,
    within ``period_tolerance`` in ``transient_impacts``, which an orbit with multiplier
    1 - eps does once eps > ln(1 / tolerance) / transient: so the end's multiplier is above
    1 - ln(1 / tolerance) / transient, and the floor allows four times that, at most 0.95
    (a narrowed bracket is 1/256 of a sweep step wide: a true flip's end is at 0.999)."""
    eps = math.log(1.0 / settings.period_tolerance) / max(settings.transient_impacts, 1)
    return max(0.0, min(0.95, 1.0 - 4.0 * eps))


#: how much wider than (its first width) / (probes + 1)^rounds a narrowed flip bracket may be
#: and still be located: each round may lose the probes next to it to starts that stopped
#: flying (a factor 2 per round at two rounds: 4)
NARROWING_SLACK = 4.0


def locate_period_doublings(
    base: ModelParams,
    parameter: str,
    brackets: list[FlipBracket],
    *,
    settings: SweepSettings,
    probes: int = 15,
    rounds: int = 2,
    on_impact: Callable[[int], None] | None = None,
) -> list[FlipLocation | None]:
    """Narrow each bracket by multisection, all brackets in one batch: first both ends are
    iterated again with ``settings``; a bracket whose ends no longer show periods 1 and 2, or
    whose period-2 orbit does not continue the period-1 one (``continues_period1``), was a
    jump to a coexisting orbit, not a flip: None. Then each round iterates ``probes`` values
    inside every interval at once and keeps the sub-interval between the last value of the
    run of period 1 and the next value, skipping probes whose ball stopped flying (sticking:
    no evidence of either period); the final ends are checked again the same way, and a
    bracket the rounds could not narrow (wider than ``NARROWING_SLACK`` times its share) is
    not located.

    A finite transient biases the result toward the period-1 side: just below the flip the
    period-1 orbit attracts like (1 - eps)^k with eps proportional to the distance, so an orbit
    that has not settled within the tolerance looks like period 2.
    """
    n = len(brackets)
    if n == 0:
        return []
    low = np.array([b.period1_end for b in brackets], dtype=float)
    high = np.array([b.period2_end for b in brackets], dtype=float)
    theta0 = np.array([b.theta0 for b in brackets], dtype=float)
    v0 = np.array([b.v0 for b in brackets], dtype=float)

    def run(values, th, v):
        """Periods of flight (0: none settled; -1: the ball stopped flying) and the orbits."""
        orbits = iterate_sweep(th, v, sweep_parameters(base, parameter, values), settings,
                               on_impact)
        period = attractor_names(orbits, settings)[1]
        return np.where(stopped_flying(orbits), -1, period), orbits

    def confirm(which: np.ndarray, settled: bool,
                least_multiplier: float = 0.0) -> tuple[np.ndarray, list[int]]:
        """Which brackets of ``which`` show a flip at their ends (low: period 1, high: a
        period 2 continuing it; with ``settled`` False, right at the flip, the high end may
        also not have settled), and the period-1 orbit's racket cycles per hop. With
        ``least_multiplier``, the period-1 orbit at the low end must also be about to flip:
        its largest multiplier in modulus (the Lyapunov exponent's, the tangent's growth per
        impact) at least that."""
        ends, orbits = run(np.concatenate([low[which], high[which]]), np.tile(theta0[which], 2),
                           np.tile(v0[which], 2))
        m = which.size
        ok, cycles = np.zeros(m, dtype=bool), [0] * m
        for i, k in enumerate(which):
            if ends[i] != 1:
                continue
            if least_multiplier > 0.0 and not (
                    orbits.lyapunov[i] >= math.log(least_multiplier)):
                continue  # a stable period-1 orbit beside a period-2 one: a jump
            at_low = parameter_point(base, parameter, low[k])
            cycles[i] = hop_cycles(orbits.v[i, -1], at_low)
            if ends[m + i] == 2:
                ok[i] = continues_period1(orbits.v[i, -1], at_low, orbits.v[m + i, -2:],
                                          parameter_point(base, parameter, high[k]))
            else:
                ok[i] = not settled and ends[m + i] == 0
        return ok, cycles

    confirmed, cycles = confirm(np.arange(n), settled=True)
    active = np.flatnonzero(confirmed)
    # a bracket left wider than its share of the rounds (a few skipped probes each round
    # allowed): the starts stopped flying across the flip, which is not located
    widest = NARROWING_SLACK * np.abs(high - low) / (probes + 1) ** rounds
    for _ in range(rounds if active.size else 0):
        inner = np.linspace(low[active], high[active], probes + 2)[1:-1]  # (probes, active)
        p, _ = run(inner.T.ravel(), np.repeat(theta0[active], probes),
                   np.repeat(v0[active], probes))
        for row, k in enumerate(active):
            seq = np.concatenate([[1], p[row * probes:(row + 1) * probes], [2]])
            values = np.concatenate([[low[k]], inner[:, row], [high[k]]])
            # a start that stops flying tells neither period: beside a sticking band the
            # bracket would close on the band's edge (a review: -0.46 % from eq. 14)
            flew = seq != -1
            seq, values = seq[flew], values[flew]
            first_other = int(np.argmax(seq != 1))  # seq[-1] = 2: there is one
            low[k], high[k] = values[first_other - 1], values[first_other]
    if active.size:  # the narrowed ends: a jump can hide inside a flip's bracket too, and a
        # period-2 orbit that coexists with a stable period-1 one passes the tests above (g 1.62
        # m/s^2: a 'flip' at Gamma 1.4928 where the period-1 multiplier is 0.85)
        least = flip_multiplier_floor(settings) if rounds > 0 else 0.0
        confirmed[active] = confirm(active, settled=False, least_multiplier=least)[0]
        confirmed &= np.abs(high - low) <= widest
    return [FlipLocation(float(low[k]), float(high[k]), cycles[k]) if confirmed[k] else None
            for k in range(n)]


def locate_period_doubling(
    base: ModelParams,
    parameter: str,
    period1_end: float,
    period2_end: float,
    *,
    theta0: float,
    v0: float,
    settings: SweepSettings,
    probes: int = 15,
    rounds: int = 2,
) -> FlipLocation:
    """``locate_period_doublings`` for one bracket; raises ModelError when its ends do not
    show periods 1 and 2 at these settings."""
    (loc,) = locate_period_doublings(
        base, parameter, [FlipBracket(period1_end, period2_end, theta0, v0)],
        settings=settings, probes=probes, rounds=rounds)
    if loc is None:
        raise ModelError(
            f"cannot bracket the flip: no periods 1 and 2 at {period1_end:g} and "
            f"{period2_end:g} from theta0 = {theta0:g} rad, v0 = {v0:g} m/s")
    return loc
