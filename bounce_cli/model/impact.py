"""The contact solver: the FIRST root of a gap, for the map (eq. 6) and the controlled map,
vectorised over many flights.

After a flight starts (an impact, a release, the racket's mid-position crossing), the height
of the ball above the racket is a gap G(s) of the elapsed phase (or time) s, and the next
contact is its FIRST root: G has several, and a root finder handed a bracket may return a
later landing. ``first_contact`` takes only steps that a lower bound of G proves root-free:
from a point with G >= 0 and G' = d, a bound M >= |G''| on the segment ahead gives

    G(s + h) >= G + d h - M h^2 / 2 > 0   for h < (d + sqrt(d^2 + 2 M G)) / M   (``safe_step``),

so the iteration can never jump over a root; it approaches the first root from the safe side
(like Newton, quadratically near a simple root). A gap describes itself through ``Gap``: at s
its value, slope and the magnitude of its terms (its rounding level), the bound M and where
M stops holding (a racket whose motion changes from cycle to cycle: steps stop there). The
caller gives the start, a point up to which G > 0 is already proved (the gaps' starts below).

The stopping rule, stated once (``ROUNDING_LEVEL``, ``STEP_FLOOR``, ``LAST_STEP_LEVEL``,
``POLISH_LIMIT``; ``model.compiled`` uses the same constants):

* converged at s: G <= 8 eps (sum of |G's terms|), i.e. G is at the rounding level of its own
  evaluation, or the next step is below 4 eps s; a Newton polish -G/G' gives the root, only
  where the crossing is transversal (G' < 0) and the correction below 1e-6 max(s, |G'| / M),
  so that it cannot move to another root (from a root with slope G', |G''| <= M keeps G
  away from 0 for 2 |G'| / M). After an impact (G(0) = 0) |G'| <= M s at the root (G' has a
  zero in (0, s)), so that is 1e-6 s; a gap that starts above the racket (G(0) > 0) can
  meet it after a tiny s at a large slope, where the safe step's rounding, about
  eps |G'| / M, is far above eps s and the polish corrects it;
* after a last step h taken without evaluating G again: from s + h on, G' <= d + M h, so with
  delta = -(d + M h) > 0, G(s + h) <= M h^2 and the first root lies in
  [s + h, s + h + 2 M h^2 / delta]; when 2 M h^2 <= eps (s + h) delta, and the step's own
  rounding (about eps |d| / M) is as small (|d| <= M (s + h), which holds after an impact),
  s + h is the root to about an ulp and the evaluation that would only confirm it is saved
  (about one of the 5.6 evaluations an impact of the Fig. 4 grid takes).

The gaps:

* ``SinusoidGap``, the map's (eq. 1 minus eq. 4; eq. 6 is G = 0 times w^2): after an impact at
  phase theta with ball velocity v (just after it),

      G(s) = h + v s / w - g s^2 / (2 w^2) + a sin(theta) - a sin(theta + s),

  h = 0, |G''| <= g/w^2 + a =: M everywhere. sin(theta) - sin(theta + s) is evaluated as
  -2 cos(theta + s/2) sin(s/2), which keeps full relative precision for the very short hops
  near sticking (the plain difference loses it for hops below ~1e-6 rad). With G(0) = 0 and
  G'(0) = d > 0 the safe step from s = 0 is zero, so ``first_impact_phase`` starts at:

  - after an impact, Taylor to third order with |G'''| <= a:
    G(h) >= h (d + c h / 2 - a h^2 / 6), c = G''(0), positive up to the smallest positive
    root of d + c h/2 - a h^2/6. Where c < 0 and d is tiny, (c/2 + sqrt(c^2/4 + 2ad/3)) / (a/3)
    cancels to an absolute error of about eps |c| / (a/3); the polish corrects it unless that
    exceeds 1e-6 s (hops below ~1e-7 rad, deep in sticking, when |c| / a is large), where
    the hop keeps that error (kept: the map's bits are the reference);
  - after a release (exact sticking, ``model.chatter``: the ball leaves the racket where the
    racket's acceleration reaches -g, sin theta = 1/Gamma, with the racket's velocity), where
    G = G' = G'' = 0 and that bound has no positive step: one order further,
    G'''(0) = a cos theta > 0 and |G''''| <= a give G(h) >= h^3 (a cos theta / 6 - a h / 24),
    positive for h < 4 cos theta; the start is half that.

  The controlled map's racket that changes its period at its upward mid-position crossing
  (``model.control.contact_after_crossing``) is the same gap with theta = 0 and h >= 0 the
  ball's height there, started at s = 0.
* (not yet moved here: ``data.simulated_lab.next_contact``, the simulated lab's racket, still
  has its own loop; ``GapAt.segment_end`` and the horizon are for it: M per racket cycle.)

Each evaluation of ``SinusoidGap`` takes two transcendental functions, sin and cos of s/2:
sin and cos of theta + s/2 follow from them and the launch's sin theta, cos theta by the
angle-addition formulas. Which sine and cosine is the caller's choice (``trig``): numpy's by
default, ``trig.sincos`` in the basin's classifier (the same bits as its compiled kernel and
on every machine). Against a long-double reference on 2 x 10^5 random flights (Fig. 4's
racket, and a = 0.6 m), the mean error is 0.8-0.9 ulp, the error of the root finder this
replaced (three transcendental functions, no last-step rule) 1.0-1.3 ulp; larger errors (up to
a few hundred ulp) only where G' at the root is small (|G'| < 0.01: the root is
ill-conditioned). With ``trig.sincos`` the errors are the same (4000 flights against a 40-digit
root: mean 0.78 and 1.00 ulp at a = 0.3 and 0.6 m where |G'| >= 0.01, numpy's 0.77 and 0.99).
"""

from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple, Protocol

import numpy as np

from .params import ModelParams, NoFixedPointError
from .trig import numpy_sincos

#: steps after which a state still not converged is reported as NaN (never seen in tests:
#: typical flights converge in 10-30 steps)
MAX_SAFE_STEPS = 2000

_EPS = float(np.finfo(float).eps)
#: a sine-and-cosine function: x -> (sin x, cos x) (``trig.numpy_sincos``, ``trig.sincos``)
Trig = Callable[[Any], tuple[np.ndarray, np.ndarray]]
#: the stopping rule (module docstring): converged where G <= ROUNDING_LEVEL * (sum of |G's
#: terms|), or where the next safe step is below STEP_FLOOR * s
ROUNDING_LEVEL = 8.0 * _EPS
STEP_FLOOR = 4.0 * _EPS
#: a last step needs no confirming evaluation when it brackets the root within this * s
LAST_STEP_LEVEL = _EPS
#: a converged root's Newton polish moves it by less than POLISH_LIMIT * max(s, |G'| / M), or
#: not at all (module docstring)
POLISH_LIMIT = 1e-6


class GapAt(NamedTuple):
    """A gap and what the solver needs of it at the points s of a batch of flights.

    value: G(s); slope: G'(s); terms: the sum of the absolute values of the terms G is
    computed from (its rounding level is ``ROUNDING_LEVEL`` times that); bound: M >= |G''| on
    [s, segment_end); segment_end: where that bound stops holding (None: nowhere)."""

    value: Any
    slope: Any
    terms: Any
    bound: Any
    segment_end: Any = None


class Gap(Protocol):
    """The gap between ball and racket of a batch of flights, for ``first_contact``."""

    def at(self, s: np.ndarray) -> GapAt:
        """The gap's value, slope, terms and curvature bound at s (one point per flight)."""
        ...

    def select(self, keep: np.ndarray) -> "Gap":
        """The same gap for the flights where ``keep`` is True (the batch compacted)."""
        ...


def safe_step(value, slope, bound):
    """The longest step from a point where the gap is ``value`` (>= 0) and its slope ``slope``
    that the bound ``bound`` >= |G''| proves root-free: (d + sqrt(d^2 + 2 M G)) / M (module
    docstring; arrays broadcast; a negative value counts as 0)."""
    step = np.maximum(value, 0.0)
    step *= 2.0 * bound
    step += slope * slope
    step = np.sqrt(step)
    step += slope
    step /= bound
    return step


def first_contact(gap: Gap, start, *, max_steps: int = MAX_SAFE_STEPS,
                  horizon: float = math.inf) -> np.ndarray:
    """The first root of each flight's gap at or after ``start``: the next contact.

    Parameters
    ----------
    gap : Gap
        The flights' gaps (one flight per element of ``start``).
    start : numpy.ndarray
        1-D: for each flight, a phase (or time) s0 >= 0 up to which G > 0 is proved (G(s0)
        may be 0: a contact at s0).
    max_steps : int
        Evaluations after which a flight still not converged is reported as NaN.
    horizon : float
        A flight that reaches it without contact is reported as +inf (``inf``: none).

    Returns
    -------
    numpy.ndarray
        s with G(s) = 0 and G > 0 on (0, s), to the stopping rule's accuracy (module
        docstring); NaN where the iteration did not converge in ``max_steps``.

    Notes
    -----
    Finished flights are dropped from the batch only when at least an eighth of it is
    finished (until then they are carried along, their results already stored), which saves
    copying every array at nearly every step. Neither that nor the batch a flight shares
    changes a bit of its result: each flight's arithmetic is its own.
    """
    s = np.asarray(start, dtype=float)
    result = np.full(s.shape, np.nan)
    idx = np.arange(s.size)
    live = np.ones(s.size, dtype=bool)  # not yet finished (finished ones may be carried)
    n_live = s.size
    for _ in range(max_steps):
        if n_live == 0:
            break
        at = gap.at(s)
        G, d, bound = at.value, at.slope, at.bound
        two_bound = 2.0 * bound
        step = np.maximum(G, 0.0)  # safe_step, in place
        step *= two_bound
        step += d * d
        np.sqrt(step, out=step)
        step += d
        step /= bound
        scale = at.terms
        scale *= ROUNDING_LEVEL
        done = G <= scale
        done |= step <= STEP_FLOOR * s
        done &= live
        s_next = s + step
        last = live & ~done  # candidates for the last-step rule
        limit = at.segment_end
        if not math.isinf(horizon):
            limit = horizon if limit is None else np.minimum(limit, horizon)
        beyond = None
        if limit is not None:  # steps stop where the bound stops holding (or at the horizon)
            clipped = s_next >= limit
            s_next = np.where(clipped, limit, s_next)
            last &= ~clipped
            if not math.isinf(horizon):  # no contact before the horizon: +inf
                beyond = live & ~done & (s_next >= horizon)
                result[idx[beyond]] = math.inf
        # the last step, taken without an evaluation to confirm it: the root lies in
        # [s + h, s + h + 2 M h^2 / delta] when delta = -(d + M h) > 0 (module docstring);
        # when that is within eps (s + h), s + h is the root to about an ulp
        delta = np.multiply(bound, step)
        delta += d
        np.negative(delta, out=delta)
        closes = np.multiply(two_bound, step)
        closes *= step
        closes = closes <= LAST_STEP_LEVEL * s_next * delta
        closes &= delta > 0.0
        closes &= last
        if closes.any():
            # ... provided the step's own rounding, about eps |G'| / M, is within eps (s + h)
            # (after an impact it is: module docstring)
            (at_,) = np.nonzero(closes)
            closes[at_] = -d[at_] <= (bound if np.ndim(bound) == 0 else bound[at_]) * s_next[at_]
            result[idx[closes]] = s_next[closes]
        finished = done | closes
        if beyond is not None:
            finished |= beyond
        if finished.any():
            if done.any():
                # Newton polish of the converged ones, only where the crossing is transversal
                # and the correction tiny, so that a polish can never move to another root
                sd, Gd, dd = s[done], G[done], d[done]
                with np.errstate(divide="ignore", invalid="ignore"):
                    corr = np.where(dd < 0.0, Gd / dd, 0.0)
                    reach = np.maximum(sd, -dd / (bound if np.ndim(bound) == 0 else bound[done]))
                corr = np.where(np.abs(corr) < POLISH_LIMIT * reach, corr, 0.0)
                result[idx[done]] = sd - corr
            live &= ~finished
            n_live = int(np.count_nonzero(live))
            if n_live == 0:
                break
            if n_live <= live.size - live.size // 8:  # compact: drop the finished ones
                idx, s_next = idx[live], s_next[live]
                gap = gap.select(live)
                live = np.ones(n_live, dtype=bool)
        s = s_next
    return result


def _per_flight(x: np.ndarray) -> Any:
    """A racket parameter as a plain float when it is one value (the fast path, the same
    arithmetic as an array of that value), else the flat array."""
    return float(x.flat[0]) if x.size and np.all(x == x.flat[0]) else x.ravel()


class SinusoidGap:
    """The map's gap (module docstring) for a batch of flights launched at phases theta with
    cos theta, sin theta given, ball velocities v, G'(0) = ``slope0`` and racket amplitude a,
    angular frequency w and g (each a float or one value per flight), and optionally a height
    h above the racket at s = 0 (None: 0, the arithmetic of an impact)."""

    def __init__(self, cos_theta, sin_theta, v, slope0, amplitude, omega, g, height=None,
                 trig: Trig = numpy_sincos):
        self.cos_th, self.sin_th, self.v, self.d0 = cos_theta, sin_theta, v, slope0
        self.a, self.w, self.g, self.height = amplitude, omega, g, height
        self.trig = trig
        self.bound: Any = g / (omega * omega) + amplitude  # M >= |G''|
        # scalars of the evaluation, computed once (the values the array expressions give)
        self.w_sq: Any = omega * omega
        self.two_w_sq: Any = 2.0 * omega * omega
        self.two_a: Any = 2.0 * amplitude

    def select(self, keep: np.ndarray) -> "SinusoidGap":
        def part(x):
            return x if x is None or isinstance(x, float) else x[keep]

        cos_th, sin_th, v, d0, a, w, g, height = (part(x) for x in (
            self.cos_th, self.sin_th, self.v, self.d0, self.a, self.w, self.g, self.height))
        return SinusoidGap(cos_th, sin_th, v, d0, a, w, g, height, trig=self.trig)

    def at(self, s: np.ndarray) -> GapAt:
        """G, G' and the terms at s, written to compute each subexpression once
        (``model.compiled`` repeats these expressions in the same order)."""
        cos_th, sin_th, two_a = self.cos_th, self.sin_th, self.two_a
        tmp = np.empty_like(s)
        sin_half, cos_half = self.trig(s / 2.0)
        # cos and sin of theta + s/2 by the angle-addition formulas: two transcendental
        # functions per step instead of three (the same expressions as model.compiled)
        cos_mid = cos_th * cos_half
        cos_mid -= np.multiply(sin_th, sin_half, out=tmp)
        sin_mid = np.multiply(sin_th, cos_half, out=cos_half)
        sin_mid += np.multiply(cos_th, sin_half, out=tmp)
        racket_rise = np.multiply(two_a, cos_mid, out=cos_mid)
        racket_rise *= sin_half  # a (sin(th + s) - sin(th)) = 2 a cos(th + s/2) sin(s/2)
        ball = self.v * s
        ball /= self.w
        g_s = self.g * s
        drop = g_s * s
        drop /= self.two_w_sq
        G = ball - drop
        G -= racket_rise
        # d = d0 - g s / w^2 + 2 a sin(th + s/2) sin(s/2)
        d = np.divide(g_s, self.w_sq, out=g_s)
        np.subtract(self.d0, d, out=d)
        rate = np.multiply(two_a, sin_mid, out=sin_mid)
        rate *= sin_half
        d += rate
        # terms = |v s / w| + g s^2 / (2 w^2) + |racket rise| (+ |h|)
        terms = np.abs(ball, out=ball)
        terms += drop
        terms += np.abs(racket_rise, out=racket_rise)
        if self.height is not None:
            G += self.height
            terms += np.abs(self.height)
        return GapAt(G, d, terms, self.bound)


def gap(s, theta, v, params: ModelParams):
    """Ball height minus racket height (m) at elapsed phase s after an impact at theta.

    sin(theta) - sin(theta + s) is evaluated as -2 cos(theta + s/2) sin(s/2), which keeps
    full relative precision for the very short hops near sticking.
    """
    w, a, g = params.omega, params.racket_amplitude, params.g
    return v * s / w - g * s * s / (2.0 * w * w) - 2.0 * a * np.cos(theta + s / 2) * np.sin(s / 2)


def gap_slope(s, theta, v, params: ModelParams):
    """dG/ds: relative velocity of ball and racket divided by omega_r (m/rad)."""
    w, a, g = params.omega, params.racket_amplitude, params.g
    return (
        launch_slope(theta, v, params)
        - g * s / (w * w)
        + 2.0 * a * np.sin(theta + s / 2) * np.sin(s / 2)
    )


def launch_slope(theta, v, params: ModelParams):
    """G'(0) = (v - v_r(theta)) / omega_r: positive when the ball leaves the racket upwards."""
    return (np.asarray(v, dtype=float) - params.racket_velocity(theta)) / params.omega


def can_fly(theta, v, params: ModelParams):
    """True where a ball launched at (theta, v) rises above the racket.

    Either it leaves faster than the racket (G'(0) > 0), or it leaves with the racket's
    velocity while the racket decelerates faster than gravity (G'(0) = 0, G''(0) > 0).
    """
    return can_fly_at(theta, v, params.racket_amplitude, params.omega, params.g)


def can_fly_at(theta, v, amplitude, omega, g):
    """``can_fly`` with the racket's amplitude (m), angular frequency (rad/s) and g given
    directly (arrays broadcast): a racket whose period changes from flight to flight (the
    controlled map) is at the frequency it has at the launch."""
    theta = np.asarray(theta, dtype=float)
    slope = (np.asarray(v, dtype=float) - amplitude * omega * np.cos(theta)) / omega  # G'(0)
    curvature = -g / omega**2 + amplitude * np.sin(theta)  # G''(0)
    return (slope > 0.0) | ((slope == 0.0) & (curvature > 0.0))


def next_impact_phase(theta, v, params: ModelParams, *, max_steps: int = MAX_SAFE_STEPS,
                      released=None):
    """Phase elapsed until the FIRST impact after leaving the racket at (theta, v).

    theta: phase of the current impact (rad, wrapped or not); v: ball velocity just after it
    (m/s). Arrays broadcast. Returns s > 0 with G(s) = 0 and G > 0 on (0, s); NaN where the
    ball cannot fly (see ``can_fly``) or, never observed, where the iteration did not converge.

    ``params`` is a ``ModelParams``, or any object with the same attributes holding arrays that
    broadcast to the states' shape: one parameter point per state (bifurcation sweeps).
    ``released``: as for ``first_impact_phase``.
    """
    return first_impact_phase(theta, v, params.racket_amplitude, params.omega, params.g,
                              max_steps=max_steps, released=released)


#: how far from one racket cycle (relative) the fixed point's hop may come out numerically
PERIOD1_HOP_TOLERANCE = 1e-6


def check_period1_orbit(params: ModelParams) -> None:
    """Raise unless eq. 8's fixed point is an orbit of the map (eqs. 5, 6): leaving the racket
    at (theta~, v~) of eqs. 7, 8, the FIRST impact must come one racket cycle later.

    Eq. 8 asks only that an impact one cycle later exists. Where the racket decelerates slower
    than gravity (AC > -1 g) and the impact is nearly dead (alpha near 0), the racket meets
    the ball again at once (alpha 0.01 at the least amplitude: after 0.025 of a cycle), or the
    ball cannot leave it at all (alpha 0, where it leaves with the racket's velocity and
    separates only where AC < -1 g: decided by AC, not by the rounding of a zero relative
    velocity): no period-1 orbit, whatever eq. 10 says of it.

    Raises
    ------
    NoFixedPointError
        Where eq. 8 has no solution, or its point is no orbit of the map.
    """
    fp = params.fixed_point()
    ac = params.racket_acceleration_g(fp.theta_rad)
    where = (f"eq. 8's fixed point (theta~ = {fp.theta_deg:.4g} deg) is no orbit of the map at "
             f"alpha={params.alpha:g}, a_r={params.racket_amplitude:g} m: ")
    v = fp.v_m_s
    if params.alpha == 0.0:
        # the ball leaves with the racket's own velocity: whether it separates is the sign of
        # the relative acceleration, -g (1 + AC), not the last bit of a zero relative velocity
        if not ac < -1.0:
            raise NoFixedPointError(
                f"no period-1 fixed point: {where}the ball cannot leave the racket there: at "
                f"alpha 0 it leaves with the racket's velocity, and the racket decelerates "
                f"slower than gravity (AC = {ac:.3g} g > -1 g; a larger model.alpha or "
                "model.racket_amplitude gives the ball its flight)")
        v = v * (1.0 + 1e-9)  # separating: its flight checked from just above the racket's
    cycles = float(next_impact_phase(fp.theta_rad, v, params)) / (2.0 * math.pi)
    if abs(cycles - 1.0) <= PERIOD1_HOP_TOLERANCE:
        return
    what = ("the ball cannot leave the racket there" if math.isnan(cycles) else
            f"leaving the racket there, the ball meets the racket again after {cycles:.3g} "
            "of a racket cycle, not one")
    raise NoFixedPointError(
        f"no period-1 fixed point: {where}{what} (AC = {ac:.3g} g; a larger model.alpha or "
        "model.racket_amplitude gives the ball its flight)")


def first_impact_phase(theta, v, amplitude, omega, g, *, max_steps: int = MAX_SAFE_STEPS,
                       cos_theta=None, sin_theta=None, released=None,
                       trig: Trig = numpy_sincos):
    """``next_impact_phase`` with the racket's amplitude a (m), angular frequency w (rad/s)
    and gravity g (m/s^2) given directly, each a scalar or an array broadcasting with theta
    and v: one call serves states at different parameters (a sweep of the map, or a racket
    whose period changes from one flight to the next under period control). Scalars take the
    same arithmetic as arrays of one value, so results do not depend on the form.

    ``trig``: the sine and cosine the solve takes (of theta and of s/2 at each evaluation):
    numpy's (``trig.numpy_sincos``), or the basin classifier's ``trig.sincos``, which the
    compiled kernel repeats bit for bit. ``cos_theta`` and ``sin_theta``, when given, are
    ``trig`` of theta wrapped to [0, 2 pi) (a caller that has them, the basin's classifier,
    saves their evaluation); the result is the same to the last bit.

    ``released``: None, or a boolean (array broadcasting with theta) marking states that
    leave the racket at a release point of exact sticking (``model.chatter``): there the
    ball moves with the racket and the racket's acceleration is -g, so G'(0) and G''(0) are
    zero by construction (whatever their rounded values: they are set to 0) and the first
    step is the module docstring's fourth-order one (needs cos theta > 0, i.e. the release
    of sin theta = 1/Gamma in the first quadrant; elsewhere NaN). With None (or all False)
    the arithmetic is the one without the argument, bit for bit.

    The flights are ``SinusoidGap``'s, solved by ``first_contact`` from the module
    docstring's first step (``model.compiled`` repeats these expressions in the same order).
    """
    theta, v, *given = np.broadcast_arrays(*(np.asarray(x, dtype=float)
                                             for x in (theta, v, amplitude, omega, g)))
    shape = theta.shape
    release = (None if released is None or not np.any(released)
               else np.broadcast_to(np.asarray(released, dtype=bool), shape).ravel())
    theta = np.mod(theta.ravel(), 2.0 * np.pi)  # sin/cos periodic: keep arguments small
    v = v.ravel()
    # racket parameters: plain floats when they are one value (the fast path), else arrays
    # that are compacted with the states
    a, w, g = (_per_flight(x) for x in given)
    if cos_theta is None or sin_theta is None:
        sin_th, cos_th = trig(theta)
    if cos_theta is not None:
        cos_th = np.broadcast_to(cos_theta, shape).ravel()
    if sin_theta is not None:
        sin_th = np.broadcast_to(sin_theta, shape).ravel()

    result = np.full(theta.shape, np.nan)
    slope = (v - a * w * cos_th) / w
    curvature = -g / w**2 + a * sin_th
    flies = (slope > 0.0) | ((slope == 0.0) & (curvature > 0.0))  # can_fly
    if release is not None:  # a release point flies when G''' = a cos theta > 0
        flies = np.where(release, cos_th > 0.0, flies)
    idx = np.flatnonzero(flies)
    vv = v[idx]
    a, w, g = (x if isinstance(x, float) else x[idx] for x in (a, w, g))

    # first step from s = 0 (G = 0): smallest positive root of d + c h/2 - a h^2/6
    cos_th, sin_th = cos_th[idx], sin_th[idx]
    d0 = vv / w - a * cos_th
    c0 = -g / (w * w) + a * sin_th
    s = (c0 / 2.0 + np.sqrt(c0 * c0 / 4.0 + 2.0 * a * np.maximum(d0, 0.0) / 3.0)) / (a / 3.0)
    if release is not None:  # G' = G'' = 0 at a release: the fourth-order first step
        at_release = release[idx]
        d0 = np.where(at_release, 0.0, d0)
        s = np.where(at_release, 2.0 * cos_th, s)
    result[idx] = first_contact(SinusoidGap(cos_th, sin_th, vv, d0, a, w, g, trig=trig), s,
                                max_steps=max_steps)
    return result.reshape(shape)
