"""Periodic orbits of the ball bouncing map (eqs. 5, 6) followed in one parameter by
pseudo-arclength continuation, with their bifurcations located by test functions.

A periodic orbit of period p impacts over m racket cycles is a zero of

    R(x, lambda) = F^p(x) - x - (0, 2 pi m),      x = (v, theta) in eq. 9's order,

where F is the map of eqs. 5, 6 and lambda one parameter (Gamma = a_r w^2 / g, a_r, tau or
alpha). Its x-derivative is M - I with M = J_{p-1} ... J_0, the product of the map's
Jacobians along the orbit (the implicit-function derivatives of section 4 at every impact,
``analysis.lyapunov.map_jacobian``; eq. 9 at the period-1 orbit). Its lambda-derivative follows
the orbit too: dx_{k+1}/dlambda = J_k dx_k/dlambda + dF/dlambda(x_k), with dF/dlambda from
the same implicit differentiation of eq. 6 in the racket's amplitude, angular frequency, g
and alpha (:func:`parameter_derivative`).

Each flight's hop is the root of the gap (``model.impact.gap``) continued from the previous
point of the branch (Newton on G(s) = 0), not the first root: a branch can then be followed
up to and past the point where a flight touches the racket tangentially (grazing), and the
physical orbit is the part of the branch where every flight stays above the racket.

Test functions at every point of a branch, whose sign changes are located by Newton on the
augmented system (R(x, lambda) = 0 and the test function = 0; three equations in
(v, theta, lambda)):

* flip (an eigenvalue of M at -1): det(M + I) = 1 + tr M + det M;
* fold (an eigenvalue at +1): det(M - I) = 1 - tr M + det M;
* Neimark-Sacker (a complex pair on the unit circle): det M - 1 where the pair is complex.
  The impact law contracts area by alpha per impact on the way out and the flight restores it
  on the way in, so det M = alpha^(2p) on every periodic orbit (checked in the tests): for
  alpha < 1 this test function never vanishes, and the map has no Neimark-Sacker bifurcation;
* grazing: the smallest interior local minimum of the gap over the orbit's flights (the ball's
  height above the racket, m); it crosses 0 where a flight touches the racket with zero
  relative velocity, the border collision that impact maps have and smooth maps do not.

At a flip the branch of the doubled orbit (period 2p over 2m cycles) leaves the located point
along the eigenvector of -1 with lambda stationary (a pitchfork of F^(2p) - x); it is reached
by Newton on R_2p with the projection on that eigenvector fixed, and continued in turn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .bifurcation import detect_period, parameter_point, period1_thresholds
from ..model.impact import gap, gap_slope
from ..model.linear import is_stable
from .lyapunov import map_jacobian
from ..model.maps import iterate_orbit, velocity_after_impact
from ..model.params import MIN_HOP_S, ModelError, ModelParams, phase_difference

TWO_PI = 2.0 * math.pi
#: Newton on one flight's gap: iterations and relative tolerance of the hop
HOP_NEWTON_STEPS = 50
#: relative size of the residual (in the scaled coordinates) that counts as converged
RESIDUAL_TOLERANCE = 1e-11
#: Newton stops after a step below this (scaled coordinates): the systems' condition numbers
#: reach 1e4-1e5 near a flip, so steps at the rounding level are ~1e-12, not 1e-16
NEWTON_STEP_TOLERANCE = 1e-10
#: samples per radian of flight when looking for the gap's interior minima
GAP_SAMPLES_PER_RAD = 16
#: a continuation step is retried shorter when the tangent turns by more than this (cosine)
#: or the corrector moves farther than MAX_CORRECTION steps from the predictor: either is how
#: a jump onto a neighbouring branch shows
MAX_TURN_COSINE = math.cos(0.2)
MAX_CORRECTION = 0.2
#: two located bifurcations of one kind and orbit within this (relative) are the same point
#: (located to ~1e-14; distinct ones of one orbit family are 1e-4 apart at period 32)
SAME_BIFURCATION_RTOL = 1e-9
#: the shortest step along a flip's eigenvector tried when switching onto the doubled orbit
SMALLEST_SWITCH_STEP = 1e-9


def signed_phase(theta) -> float:
    """theta wrapped to [-pi, pi) (rad): the two branches of eq. 8, theta = +-arccos, meet at
    0 at their fold, so this form keeps a fold's phase away from the wrap."""
    return float(phase_difference(theta, 0.0))


# -- one flight, continued ----------------------------------------------------------------------
def continued_hop(theta: float, v: float, params: ModelParams, guess: float) -> float:
    """The root s of the gap G(s) (eq. 6 as ball minus racket height) continued from ``guess``
    by Newton's method: the flight's hop as the branch follows it (module docstring). NaN when
    Newton does not converge or runs to s <= 0."""
    s = float(guess)
    close = False
    for _ in range(HOP_NEWTON_STEPS):
        slope = float(gap_slope(s, theta, v, params))
        if slope == 0.0 or not math.isfinite(slope):
            return math.nan
        step = float(gap(s, theta, v, params)) / slope
        s -= step
        if not s > 0.0:
            return math.nan
        if close:  # one step after a step of 1e-12: converged to rounding (quadratically)
            return s
        close = abs(step) <= 1e-12 * s
    return math.nan


def parameter_derivative(theta, v, hop, params: ModelParams, parameter: str) -> np.ndarray:
    """d(v_{k+1}, theta_{k+1}) / d(parameter) at fixed (v_k, theta_k), by implicit
    differentiation of eqs. 5, 6 (section 4's route, in the parameter instead of the state).

    With s the hop and G the gap, dtheta_{k+1}/dp = -(dG/dp) / (dG/dtheta_{k+1}), and the
    velocity map (eq. 5) gives dv_{k+1}/dp = K dtheta_{k+1}/dp + (dv_{k+1}/dp at fixed
    theta_{k+1}), K = -(1+alpha) a w sin theta_{k+1} + g alpha / w. The partial derivatives in
    a = a_r, w = omega_r, g and alpha are

        dG/da = sin theta - sin theta_{k+1},  dG/dw = -v s / w^2 + g s^2 / w^3,
        dG/dg = -s^2 / (2 w^2),                dG/dalpha = 0,
        dv/da = (1+alpha) w cos theta_{k+1},  dv/dw = (1+alpha) a cos theta_{k+1} - g alpha s / w^2,
        dv/dg = alpha s / w,                   dv/dalpha = a w cos theta_{k+1} - v + g s / w,

    and the parameters of a sweep act through them: Gamma sets a = Gamma g / w^2 (g and w
    fixed), tau sets w = 2 pi / tau (dw/dtau = -w / tau).

    Parameters
    ----------
    theta, v, hop : float
        The impact (rad, m/s) and the phase elapsed to the next one.
    params : ModelParams
        The parameter point.
    parameter : str
        ``gamma``, ``racket_amplitude``, ``racket_period`` or ``alpha``.

    Returns
    -------
    numpy.ndarray
        (dv_{k+1}/dp, dtheta_{k+1}/dp).
    """
    a, w, g, alpha = params.racket_amplitude, params.omega, params.g, params.alpha
    s = hop
    theta_next = theta + s
    cos_next, sin_next = math.cos(theta_next), math.sin(theta_next)
    v_before = v - g * s / w
    dgap_dnext = (v_before - a * w * cos_next) / w
    k = -(1.0 + alpha) * a * w * sin_next + g * alpha / w

    def along(dgap, dvel):
        dnext = -dgap / dgap_dnext
        return np.array([k * dnext + dvel, dnext])

    by_amplitude = along(math.sin(theta) - sin_next, (1.0 + alpha) * w * cos_next)
    if parameter == "racket_amplitude":
        return by_amplitude
    if parameter == "gamma":
        return by_amplitude * g / w**2
    if parameter == "racket_period":
        by_omega = along(-v * s / w**2 + g * s**2 / w**3,
                         (1.0 + alpha) * a * cos_next - g * alpha * s / w**2)
        return by_omega * (-w / params.racket_period)
    if parameter == "alpha":
        return along(0.0, a * w * cos_next - v + g * s / w)
    raise ModelError(f"cannot continue in {parameter!r}")


# -- the periodic-orbit residual ----------------------------------------------------------------
@dataclass(frozen=True)
class OrbitEvaluation:
    """F^p from one point: the impacts along the orbit (k = 0..p), the hops, the monodromy
    matrix M = dF^p/dx, dF^p/dlambda and the residual R = F^p(x) - x - (0, 2 pi m)."""

    theta: np.ndarray
    v: np.ndarray
    hops: np.ndarray
    monodromy: np.ndarray
    parameter_derivative: np.ndarray
    residual: np.ndarray

    @property
    def finite(self) -> bool:
        return bool(np.all(np.isfinite(self.residual)) and np.all(np.isfinite(self.monodromy)))


def evaluate_orbit(x, params: ModelParams, parameter: str, cycles: int,
                   hops_guess) -> OrbitEvaluation:
    """Iterate eqs. 5, 6 p = len(hops_guess) times from x = (v, theta), each hop continued
    from its guess (:func:`continued_hop`), with the monodromy matrix (products of
    ``map_jacobian``) and the parameter derivative (:func:`parameter_derivative`)."""
    p = len(hops_guess)
    v = np.empty(p + 1)
    theta = np.empty(p + 1)
    hops = np.empty(p)
    v[0], theta[0] = float(x[0]), float(x[1])
    mono = np.eye(2)
    dpar = np.zeros(2)
    for k in range(p):
        s = continued_hop(theta[k], v[k], params, hops_guess[k])
        hops[k] = s
        theta[k + 1] = theta[k] + s
        v[k + 1] = velocity_after_impact(theta[k + 1], v[k], s, params)
        jac = map_jacobian(theta[k], v[k], s, params)
        mono = jac @ mono
        dpar = jac @ dpar + parameter_derivative(theta[k], v[k], s, params, parameter)
    residual = np.array([v[p] - v[0], theta[p] - theta[0] - TWO_PI * cycles])
    return OrbitEvaluation(theta, v, hops, mono, dpar, residual)


# -- test functions -----------------------------------------------------------------------------
def flip_test(monodromy: np.ndarray) -> float:
    """det(M + I): zero where M has the eigenvalue -1 (flip, period doubling)."""
    return float(1.0 + np.trace(monodromy) + np.linalg.det(monodromy))


def fold_test(monodromy: np.ndarray) -> float:
    """det(M - I): zero where M has the eigenvalue +1 (fold, saddle-node)."""
    return float(1.0 - np.trace(monodromy) + np.linalg.det(monodromy))


def neimark_sacker_test(monodromy: np.ndarray) -> float:
    """det M - 1 where M's eigenvalues are a complex pair (their modulus squared is det M),
    NaN where they are real."""
    tr, det = float(np.trace(monodromy)), float(np.linalg.det(monodromy))
    return det - 1.0 if tr * tr < 4.0 * det else math.nan


def flight_minimum_gap(theta: float, v: float, hop: float, params: ModelParams) -> float:
    """The smallest interior local minimum of the gap G(s) over 0 < s < hop (m): the flight's
    closest approach to the racket; +inf when G has no interior minimum. Local minima are
    bracketed on a grid (``GAP_SAMPLES_PER_RAD`` per radian) by a sign change of G' from - to
    + and refined by Newton on G'(s) = 0 with G''(s) = -g / w^2 + a sin(theta + s)."""
    n = max(8, int(math.ceil(hop * GAP_SAMPLES_PER_RAD)))
    s = np.linspace(0.0, hop, n + 1)
    slope = gap_slope(s, theta, v, params)
    found = np.flatnonzero((slope[:-1] < 0.0) & (slope[1:] >= 0.0))
    best = math.inf
    curvature_const = -params.g / params.omega**2
    for i in found:
        lo, hi = float(s[i]), float(s[i + 1])
        x = 0.5 * (lo + hi)
        for _ in range(50):
            d2 = curvature_const + params.racket_amplitude * math.sin(theta + x)
            d1 = float(gap_slope(x, theta, v, params))
            nxt = x - d1 / d2 if d2 > 0.0 else math.nan
            if not lo <= nxt <= hi:  # bisection keeps it in the bracket
                if d1 < 0.0:
                    lo = x
                else:
                    hi = x
                nxt = 0.5 * (lo + hi)
            if abs(nxt - x) <= 1e-15 * max(1.0, x):
                x = nxt
                break
            x = nxt
        if 0.0 < x < hop:
            best = min(best, float(gap(x, theta, v, params)))
    return best


def grazing_test(ev: OrbitEvaluation, params: ModelParams) -> float:
    """The smallest interior minimum of the gap over the orbit's flights (m), see
    :func:`flight_minimum_gap`: negative where a flight passes below the racket (the branch
    is not a physical orbit there), zero at a grazing."""
    return min(flight_minimum_gap(float(ev.theta[k]), float(ev.v[k]), float(ev.hops[k]), params)
               for k in range(ev.hops.size))


TEST_FUNCTIONS: dict[str, Callable[[OrbitEvaluation, ModelParams], float]] = {
    "flip": lambda ev, params: flip_test(ev.monodromy),
    "fold": lambda ev, params: fold_test(ev.monodromy),
    "neimark_sacker": lambda ev, params: neimark_sacker_test(ev.monodromy),
    "grazing": grazing_test,
}


# -- branches -----------------------------------------------------------------------------------
@dataclass
class BranchPoint:
    """One converged point of a branch: the parameter value, the orbit's first impact
    (v m/s, theta rad in [-pi, pi)), its hops, the monodromy matrix, the test values, whether
    every flight stays above the racket, and all p impacts."""

    value: float
    v: float
    theta: float
    hops: np.ndarray
    monodromy: np.ndarray
    tests: dict[str, float]
    physical: bool
    impact_v: np.ndarray  # v after each of the p impacts (m/s)
    impact_theta: np.ndarray  # their phases (rad, wrapped to [-pi, pi))

    @property
    def eigenvalues(self) -> np.ndarray:
        """M's eigenvalues, the larger modulus first (complex)."""
        lam = np.linalg.eigvals(self.monodromy).astype(complex)
        return lam[np.argsort(-np.abs(lam), kind="stable")]

    @property
    def stable(self) -> bool:
        return is_stable(float(np.max(np.abs(self.eigenvalues))))


@dataclass(frozen=True)
class Bifurcation:
    """A located bifurcation: ``kind`` (flip, fold, neimark_sacker, grazing) of the orbit of
    ``period`` impacts over ``cycles`` racket cycles, at the parameter ``value`` and the
    orbit's first impact (v m/s, theta rad in [-pi, pi)); ``residual``: |test function| there."""

    kind: str
    period: int
    cycles: int
    value: float
    v: float
    theta: float
    residual: float


@dataclass
class Branch:
    """The points of one branch in the order followed (several runs: ``segment`` counts
    them: 0 toward the end of the range the continuation started to, 1 the other way)."""

    period: int
    cycles: int
    points: list[BranchPoint] = field(default_factory=list)
    segments: list[int] = field(default_factory=list)
    parent: int = -1  # index of the branch it was switched from at a flip


@dataclass(frozen=True)
class ContinuationSettings:
    """Step control and limits of the pseudo-arclength continuation.

    ``initial_step``, ``min_step``, ``max_step``: arclength in the scaled coordinates
    (v / v_scale, theta rad, parameter / its start value). ``max_points`` per branch segment.
    ``max_period``: doubled branches are switched onto up to this period (its own flips are
    still located). ``switch_step``: distance along the flip's eigenvector at which the
    doubled branch is first computed (scaled coordinates)."""

    initial_step: float = 1e-3
    min_step: float = 1e-7
    max_step: float = 2e-2
    max_points: int = 2000
    max_period: int = 32
    switch_step: float = 1e-4
    newton_steps: int = 12

    def __post_init__(self) -> None:
        if not 0.0 < self.min_step <= self.initial_step <= self.max_step:
            raise ModelError("continuation steps must satisfy 0 < min_step <= initial_step "
                             "<= max_step")


class Continuation:
    """Pseudo-arclength continuation of periodic orbits of the map at ``base`` in
    ``parameter`` over [low, high] (module docstring)."""

    def __init__(self, base: ModelParams, parameter: str, low: float, high: float,
                 settings: ContinuationSettings = ContinuationSettings()):
        self.base, self.parameter, self.settings = base, parameter, settings
        self.low, self.high = min(low, high), max(low, high)
        self.branches: list[Branch] = []
        self.bifurcations: list[Bifurcation] = []
        self._scale = np.ones(3)
        #: located flips whose doubled branch is still to be switched onto
        self._pending: list[tuple[np.ndarray, OrbitEvaluation, Branch]] = []

    # -- evaluation in y = (v, theta, lambda) ---------------------------------------------------
    def params_at(self, value: float) -> ModelParams:
        return parameter_point(self.base, self.parameter, float(value))

    def evaluate(self, y, cycles: int, hops) -> OrbitEvaluation | None:
        try:
            params = self.params_at(y[2])
        except ModelError:
            return None
        ev = evaluate_orbit(y[:2], params, self.parameter, cycles, hops)
        return ev if ev.finite else None

    def _jacobian(self, ev: OrbitEvaluation) -> np.ndarray:
        """dR/dy (2 x 3) in the scaled coordinates."""
        raw = np.hstack([ev.monodromy - np.eye(2), ev.parameter_derivative[:, None]])
        return raw * self._scale[None, :]

    def _tangent(self, ev: OrbitEvaluation, previous: np.ndarray | None) -> np.ndarray:
        jac = self._jacobian(ev)
        t = np.cross(jac[0], jac[1])
        t /= np.linalg.norm(t)
        if previous is not None and float(t @ previous) < 0.0:
            t = -t
        return t

    def _residual_scaled(self, ev: OrbitEvaluation) -> float:
        return float(np.max(np.abs(ev.residual / np.array([self._scale[0], 1.0]))))

    def correct(self, y_pred, cycles: int, hops, row: np.ndarray, target: float,
                extra: Callable[[np.ndarray], tuple[float, np.ndarray]] | None = None):
        """Newton on (R(y) = 0, row . (y / scale) = target), or with ``extra`` (a function of
        y giving a third equation's value and its gradient in scaled coordinates) instead of
        the row. Returns (y, evaluation) or None."""
        y = np.array(y_pred, dtype=float)
        for _ in range(self.settings.newton_steps):
            ev = self.evaluate(y, cycles, hops)
            if ev is None:
                return None
            hops = ev.hops
            jac = self._jacobian(ev)
            if extra is None:
                third, grad = float(row @ (y / self._scale)) - target, row
            else:
                third, grad = extra(y)
            system = np.vstack([jac, grad])
            rhs = -np.concatenate([ev.residual, [third]])
            try:
                delta = np.linalg.solve(system, rhs)
            except np.linalg.LinAlgError:
                return None
            y = y + delta * self._scale
            if np.max(np.abs(delta)) < NEWTON_STEP_TOLERANCE:
                ev = self.evaluate(y, cycles, hops)
                if ev is None or self._residual_scaled(ev) > RESIDUAL_TOLERANCE:
                    return None
                return y, ev
        return None

    def point(self, y, ev: OrbitEvaluation) -> BranchPoint:
        params = self.params_at(y[2])
        tests = {name: float(f(ev, params)) for name, f in TEST_FUNCTIONS.items()}
        return BranchPoint(float(y[2]), float(y[0]), signed_phase(y[1]), ev.hops.copy(),
                           ev.monodromy.copy(), tests, physical=tests["grazing"] > 0.0,
                           impact_v=ev.v[:-1].copy(),
                           impact_theta=phase_difference(ev.theta[:-1], 0.0))

    # -- following a branch ---------------------------------------------------------------------
    def follow(self, y0, cycles: int, hops, direction: float | np.ndarray,
               branch: Branch, segment: int) -> None:
        """Continue from the converged y0 (its evaluation is redone) until the parameter leaves
        [low, high], the step falls below ``min_step``, the branch stops being physical
        (after its grazing is located) or ``max_points``. ``direction``: the sign of the
        parameter's change at the start, or a scaled vector the first tangent must follow."""
        s = self.settings
        y = np.array(y0, dtype=float)
        ev = self.evaluate(y, cycles, hops)
        if ev is None:
            return
        if np.ndim(direction) == 0:
            previous = np.array([0.0, 0.0, float(direction)])
        else:
            previous = np.asarray(direction, dtype=float)
        tangent = self._tangent(ev, previous)
        current = self.point(y, ev)
        if not branch.points or segment > 0:
            branch.points.append(current)
            branch.segments.append(segment)
        step = s.initial_step
        for _ in range(s.max_points):
            pred = y + step * tangent * self._scale
            row = tangent
            target = float(tangent @ (pred / self._scale))
            out = self.correct(pred, cycles, ev.hops, row, target)
            if out is None:
                step /= 2.0
                if step < s.min_step:
                    return
                continue
            y_new, ev_new = out
            new_tangent = self._tangent(ev_new, tangent)
            moved = float(np.linalg.norm((y_new - pred) / self._scale))
            if (float(new_tangent @ tangent) < MAX_TURN_COSINE
                    or moved > MAX_CORRECTION * step):
                # the corrector went far from the predictor or the branch turned sharply:
                # it may have jumped onto another branch; retry with a shorter step
                step /= 2.0
                if step < s.min_step:
                    return
                continue
            new = self.point(y_new, ev_new)
            located = self._detect(branch, current, new, y, y_new, ev, ev_new, cycles)
            branch.points.append(new)
            branch.segments.append(segment)
            if located and located.kind == "grazing":
                return  # the rest of the branch passes through the racket
            y, ev, current = y_new, ev_new, new
            tangent = new_tangent
            if not self.low <= y[2] <= self.high:
                return
            step = min(step * 1.5, s.max_step)

    def _detect(self, branch: Branch, a: BranchPoint, b: BranchPoint, ya, yb,
                eva: OrbitEvaluation, evb: OrbitEvaluation, cycles: int) -> Bifurcation | None:
        """Locate every test function that changes sign between a and b (grazing last: the
        flips and folds of a branch that grazes in the same step come first)."""
        last = None
        for kind in ("flip", "fold", "neimark_sacker", "grazing"):
            fa, fb = a.tests[kind], b.tests[kind]
            if not (math.isfinite(fa) and math.isfinite(fb)) or fa * fb > 0.0 or fa == fb:
                continue
            if kind != "grazing" and not (a.physical or b.physical):
                continue
            found = self.locate(kind, ya, yb, fa, fb, cycles, eva.hops)
            if found is None:
                continue
            bif, y_star, ev_star = found
            if self._known(bif):
                continue
            self.bifurcations.append(bif)
            last = bif
            if kind == "flip" and 2 * branch.period <= self.settings.max_period:
                self._pending.append((y_star, ev_star, branch))
        return last

    def _known(self, bif: Bifurcation) -> bool:
        """Whether ``bif`` was located already: a branch can pass a bifurcation twice, with
        its first impact at another of the orbit's impacts (the doubled orbit's branch, once
        through its birth at the flip, follows the same orbit from its other impact)."""
        return any(b.kind == bif.kind and b.period == bif.period and b.cycles == bif.cycles
                   and abs(b.value - bif.value) <= SAME_BIFURCATION_RTOL * abs(bif.value)
                   for b in self.bifurcations)

    def locate(self, kind: str, ya, yb, fa: float, fb: float, cycles: int, hops):
        """Newton on the augmented system (R = 0, test function = 0) from the secant point
        between two branch points whose test values have opposite signs; the test function's
        gradient by central differences in the scaled coordinates (the function itself uses
        the analytic monodromy matrix). Returns (Bifurcation, y, evaluation) or None."""
        y_guess = ya + (yb - ya) * (fa / (fa - fb))
        hop_state = {"hops": hops}

        def value(y) -> float:
            ev = self.evaluate(y, cycles, hop_state["hops"])
            if ev is None:
                return math.nan
            return float(TEST_FUNCTIONS[kind](ev, self.params_at(y[2])))

        def extra(y):
            h = 1e-6
            grad = np.empty(3)
            for i in range(3):
                e = np.zeros(3)
                e[i] = h * self._scale[i]
                grad[i] = (value(y + e) - value(y - e)) / (2.0 * h)
            return value(y), grad

        # onto the branch first, on the plane through the secant point normal to the chord
        # (regular at a fold, where fixing the parameter is not; a long orbit's single
        # shooting needs a start close to the branch), then the augmented system
        chord = (yb - ya) / self._scale
        chord /= np.linalg.norm(chord)
        on_branch = self.correct(y_guess, cycles, hops, chord,
                                 float(chord @ (y_guess / self._scale)))
        if on_branch is None:
            return None
        hop_state["hops"] = on_branch[1].hops
        out = self.correct(on_branch[0], cycles, on_branch[1].hops, np.zeros(3), 0.0,
                           extra=extra)
        if out is None:
            return None
        y, ev = out
        # between the two points along the branch (in the scaled coordinates: a fold's
        # parameter lies outside the two points' parameters)
        chord_length = float(np.linalg.norm((yb - ya) / self._scale))
        if max(float(np.linalg.norm((y - end) / self._scale)) for end in (ya, yb)) > (
                2.0 * chord_length):
            return None  # converged to another zero
        residual = abs(value(y))
        bif = Bifurcation(kind, len(hops), cycles, float(y[2]), float(y[0]), signed_phase(y[1]),
                          residual)
        return bif, y, ev

    # -- the whole computation ------------------------------------------------------------------
    def run(self, start_value: float, v0: float, theta0: float, cycles: int, hops,
            on_branch: Callable[[Branch], None] | None = None) -> list[Branch]:
        """Converge the orbit from (v0, theta0) with the given hops at ``start_value``, follow
        it both ways, then every doubled branch born at a located flip (up to
        ``max_period``), and return all branches (also kept in ``self.branches``)."""
        self._pending = []
        p_fixed = self.params_at(start_value)
        self._scale = np.array([math.pi * p_fixed.g / p_fixed.omega, 1.0,
                                abs(start_value) if start_value != 0.0 else 1.0])
        y0 = np.array([v0, theta0, start_value], dtype=float)
        out = self.correct(y0, cycles, list(hops), np.array([0.0, 0.0, 1.0]),
                           float(start_value / self._scale[2]))
        if out is None:
            raise ModelError(f"no periodic orbit of period {len(hops)} over {cycles} racket "
                             f"cycle(s) converged near v = {v0:.6g} m/s, theta = "
                             f"{math.degrees(theta0):.6g} deg at {self.parameter} = "
                             f"{start_value:.6g}")
        y, ev = out
        first = Branch(len(hops), cycles)
        self.branches.append(first)
        self.follow(y, cycles, ev.hops, +1.0, first, 0)
        self.follow(y, cycles, ev.hops, -1.0, first, 1)
        if on_branch:
            on_branch(first)
        while self._pending:
            y_star, ev_star, parent = self._pending.pop(0)
            doubled = self.switch(y_star, ev_star, parent)
            if doubled is not None and on_branch:
                on_branch(doubled)
        return self.branches

    def switch(self, y_star, ev_star: OrbitEvaluation, parent: Branch) -> Branch | None:
        """The doubled orbit born at the flip (y_star): Newton on R_2p with the projection on
        the eigenvector of -1 fixed at ``switch_step``, then followed away from the flip."""
        lam, vecs = np.linalg.eig(ev_star.monodromy)
        e = np.real(vecs[:, int(np.argmin(np.abs(lam + 1.0)))])
        e_scaled = e / self._scale[:2]
        e_scaled /= np.linalg.norm(e_scaled)
        row = np.array([e_scaled[0], e_scaled[1], 0.0])
        cycles, hops = 2 * parent.cycles, np.concatenate([ev_star.hops, ev_star.hops])
        base = float(row @ (y_star / self._scale))
        # the doubled orbit's features shrink along the cascade (by Feigenbaum's 2.5 per
        # doubling): a step that single shooting over 2p impacts cannot take is shortened
        h = self.settings.switch_step
        while h >= SMALLEST_SWITCH_STEP:
            pred = y_star + h * row * self._scale
            out = self.correct(pred, cycles, hops, row, base + h)
            if out is not None:
                y, ev = out
                if abs(ev.v[parent.period] - ev.v[0]) / self._scale[0] > 0.1 * h:
                    break  # else it converged back onto the period-p orbit
            h /= 4.0
        else:
            return None
        branch = Branch(2 * parent.period, cycles, parent=self.branches.index(parent))
        self.branches.append(branch)
        away = (y - y_star) / self._scale
        away[:2] = 0.0  # follow the side of the parameter the doubled orbit lives on
        direction = float(np.sign(away[2])) if away[2] != 0.0 else 1.0
        self.follow(y, cycles, ev.hops, direction, branch, 0)
        return branch


# -- starts -------------------------------------------------------------------------------------
def eq8_orbit(params: ModelParams, cycles: int = 1) -> tuple[float, float]:
    """(v, theta) of the period-1 orbit hopping ``cycles`` racket cycles (eqs. 7, 8 with
    2 pi -> 2 pi m: v = m pi g / w, cos theta = m pi (1-alpha)/(1+alpha) g / (w^2 a_r)), on
    the stable branch theta = +arccos. Raises ModelError where it does not exist."""
    cos_theta = cycles * params.cos_theta_fixed()
    if cos_theta > 1.0:
        raise ModelError(f"the period-1 orbit hopping {cycles} racket cycle(s) does not exist "
                         f"here (eq. 8 gives cos theta = {cos_theta:.4g} > 1)")
    return cycles * math.pi * params.g / params.omega, math.acos(cos_theta)


@dataclass(frozen=True)
class IteratedOrbit:
    """A periodic orbit found by iterating the map: its first impact, period and cycles and
    its hops (the first roots)."""

    v: float
    theta: float
    period: int
    cycles: int
    hops: np.ndarray


def orbit_by_iteration(theta0: float, v0: float, params: ModelParams, *, transient: int,
                       max_period: int, tolerance: float,
                       min_hop_s: float = MIN_HOP_S) -> IteratedOrbit:
    """Iterate eqs. 5, 6 (first roots, ``maps.iterate_orbit``) ``transient`` impacts from
    (theta0, v0), then read the smallest period p <= max_period whose v and wrapped theta
    repeat within ``tolerance`` (m/s, rad) over the next 2 max_period impacts
    (``bifurcation.detect_period``); cycles from the phase it advanced. Raises ModelError when
    the ball sticks (a hop under ``min_hop_s``, section 3), cannot fly or has no period."""
    orbit = iterate_orbit(theta0, v0, params, transient + 2 * max_period, min_hop_s)
    if orbit.stop_reason:
        raise ModelError(f"the orbit from the initial condition ends ({orbit.stop_reason}) "
                         "before it settles")
    theta, v, hop = (x[transient:] for x in (orbit.theta, orbit.v, orbit.hop_phase))
    period = int(detect_period(v[None, :], theta[None, :], max_period, tolerance)[0])
    if period == 0:
        raise ModelError(f"no period up to {max_period} found after {transient} impacts from "
                         "the initial condition")
    cycles = int(round((theta[period] - theta[0]) / TWO_PI))
    return IteratedOrbit(float(v[0]), signed_phase(theta[0]), period, cycles,
                         np.array(hop[1:period + 1]))


def period1_branch(base: ModelParams, parameter: str, low: float, high: float, start: float,
                   cycles: int = 1,
                   settings: ContinuationSettings = ContinuationSettings(max_period=1)
                   ) -> Continuation:
    """The branch of eq. 8's period-1 orbit hopping ``cycles`` racket cycles, converged at
    ``start`` (where it must exist) and followed both ways within [low, high], with its
    bifurcations located (no doubled branches by default).

    Parameters
    ----------
    base : ModelParams
        The parameters not continued.
    parameter : str
        ``gamma``, ``racket_amplitude``, ``racket_period`` or ``alpha``.
    low, high : float
        The range the branch is followed in.
    start : float
        Where the orbit is first converged.
    cycles : int
        Racket cycles per hop.
    settings : ContinuationSettings
        Step control.

    Returns
    -------
    Continuation
        Its ``branches`` and ``bifurcations``.
    """
    cont = Continuation(base, parameter, low, high, settings)
    v, theta = eq8_orbit(cont.params_at(start), cycles)
    cont.run(start, v, theta, cycles, [TWO_PI * cycles])
    return cont


def first_bifurcation(cont: Continuation, kind: str, period: int = 1) -> Bifurcation | None:
    """The first located bifurcation of ``kind`` of the orbits of ``period``, or None."""
    found = [b for b in cont.bifurcations if b.kind == kind and b.period == period]
    return found[0] if found else None


def period1_flip(base: ModelParams, parameter: str, low: float, high: float, start: float,
                 cycles: int = 1) -> Bifurcation | None:
    """The flip of eq. 8's orbit hopping ``cycles`` racket cycles located by continuation
    from ``start`` within [low, high] (:func:`period1_branch`); None when it does not flip
    there.

    Parameters
    ----------
    base, parameter, low, high, start, cycles
        As for :func:`period1_branch`.

    Returns
    -------
    Bifurcation or None
        The first flip of that orbit located on its branch.
    """
    return first_bifurcation(period1_branch(base, parameter, low, high, start, cycles), "flip")


def continued_period1_thresholds(base: ModelParams, parameter: str,
                                 cycles: int = 1) -> tuple[float, float]:
    """(existence, flip) of eq. 8's orbit hopping ``cycles`` racket cycles, located by
    continuation: the fold where the orbit is born (eq. 8: cos theta~ = 1) and its flip
    (eq. 14). The closed forms only seed it: the branch is converged midway between them and
    followed over their span widened by a tenth each side. NaN where a closed form is (the
    threshold lies outside the parameter's valid range) or nothing is located.

    Parameters
    ----------
    base, parameter, cycles
        As for :func:`period1_branch`.

    Returns
    -------
    tuple of float
        The parameter's values at the fold and at the flip.
    """
    closed = period1_thresholds(base, parameter, cycles)
    if not (math.isfinite(closed.existence) and math.isfinite(closed.flip)):
        return math.nan, math.nan
    low, high = sorted((closed.existence, closed.flip))
    margin = 0.1 * (high - low)
    cont = period1_branch(base, parameter, low - margin, high + margin,
                          0.5 * (closed.existence + closed.flip), cycles)
    fold, flip = (first_bifurcation(cont, kind) for kind in ("fold", "flip"))
    return (fold.value if fold is not None else math.nan,
            flip.value if flip is not None else math.nan)


def feigenbaum_ratios(flips) -> np.ndarray:
    """delta_n = (lambda_n - lambda_{n-1}) / (lambda_{n+1} - lambda_n) of successive flips of
    a period-doubling cascade (the flips of the orbits of period 2^(n-1) p in order); tends to
    Feigenbaum's 4.6692 for a cascade of a map with a quadratic maximum.

    Parameters
    ----------
    flips : sequence of float
        The parameter values of the flips, in the order of the cascade.

    Returns
    -------
    numpy.ndarray
        len(flips) - 2 ratios (delta_1 uses flips 0, 1, 2).
    """
    x = np.asarray(flips, dtype=float)
    gaps = np.diff(x)
    return gaps[:-1] / gaps[1:]
