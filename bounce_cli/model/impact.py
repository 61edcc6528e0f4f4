"""The first-impact solver for the implicit phase map (eq. 6), vectorised over many states.

After an impact at phase theta with ball velocity v (just after impact), the height of the
ball above the racket at elapsed phase s = omega_r (t - t_k) is the gap (eq. 1 minus eq. 4)

    G(s) = v s / w - g s^2 / (2 w^2) + a sin(theta) - a sin(theta + s),

and eq. 6 is G(s) = 0 (multiplied by w^2). G has several roots; the next impact is the FIRST
positive one. With G(0) = 0 and G'(0) = (v - a w cos theta)/w > 0 the ball starts above the
racket. Every step taken here is one that a lower bound of G proves root-free:

* first step, from s = 0: Taylor to third order with |G'''| <= a gives
  G(h) >= h (d + c h / 2 - a h^2 / 6), d = G'(0), c = G''(0);
* first step after a release (exact sticking, ``engine.chatter``: the ball leaves the racket
  where the racket's acceleration reaches -g, sin theta = 1/Gamma, with the racket's
  velocity), where G = G' = G'' = 0 and that bound has no positive step: one order further,
  G''' (0) = a cos theta > 0 and |G''''| <= a give G(h) >= h^3 (a cos theta / 6 - a h / 24),
  positive for h < 4 cos theta; the first step is half that;
* later steps, from a point with G > 0: |G''| <= g/w^2 + a =: M gives
  G(s + h) >= G + d h - M h^2 / 2 > 0 for h < (d + sqrt(d^2 + 2 M G)) / M.

So the iteration can never jump over a root; it approaches the first root from the safe
side (like Newton, quadratically near a simple root). It stops in one of two ways:

* converged at s: G is at the rounding level of its terms or the next step is below
  4 eps s; a Newton polish (only where the crossing is transversal and the correction tiny)
  gives the root;
* after a last step h taken without evaluating G again: from s + h on, G' <= d + M h, so with
  delta = -(d + M h) > 0, G(s + h) <= M h^2 and the first root lies in
  [s + h, s + h + 2 M h^2 / delta]; when 2 M h^2 <= eps (s + h) delta, s + h is the root to
  about an ulp and the evaluation that would only confirm it is saved (about one of the
  5.6 evaluations an impact of the Fig. 4 grid takes).

Each evaluation takes two transcendental functions, sin and cos of s/2: sin and cos of
theta + s/2 follow from them and the launch's sin theta, cos theta by the angle-addition
formulas. Against a long-double reference on 2 x 10^5 random flights (Fig. 4's racket, and
a = 0.6 m), the mean error is 0.8-0.9 ulp, the error of the root finder this replaced (three
transcendental functions, no last-step rule) 1.0-1.3 ulp; larger errors (up to a few hundred
ulp) only where G' at the root is small (|G'| < 0.01: the root is ill-conditioned).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .params import ModelParams

#: steps after which a state still not converged is reported as NaN (never seen in tests:
#: typical flights converge in 10-30 steps)
MAX_SAFE_STEPS = 2000


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
    theta = np.asarray(theta, dtype=float)
    slope = launch_slope(theta, v, params)
    curvature = -params.g / params.omega**2 + params.racket_amplitude * np.sin(theta)
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


def first_impact_phase(theta, v, amplitude, omega, g, *, max_steps: int = MAX_SAFE_STEPS,
                       cos_theta=None, sin_theta=None, released=None):
    """``next_impact_phase`` with the racket's amplitude a (m), angular frequency w (rad/s)
    and gravity g (m/s^2) given directly, each a scalar or an array broadcasting with theta
    and v: one call serves states at different parameters (a sweep of the map, or a racket
    whose period changes from one flight to the next under period control). Scalars take the
    same arithmetic as arrays of one value, so results do not depend on the form.

    ``cos_theta`` and ``sin_theta``, when given, are ``np.cos`` and ``np.sin`` of theta
    wrapped to [0, 2 pi) (a caller that has them, the basin's classifier, saves two
    transcendental functions per state); the result is the same to the last bit.

    ``released``: None, or a boolean (array broadcasting with theta) marking states that
    leave the racket at a release point of exact sticking (``engine.chatter``): there the
    ball moves with the racket and the racket's acceleration is -g, so G'(0) and G''(0) are
    zero by construction (whatever their rounded values: they are set to 0) and the first
    step is the module docstring's fourth-order one (needs cos theta > 0, i.e. the release
    of sin theta = 1/Gamma in the first quadrant; elsewhere NaN). With None (or all False)
    the arithmetic is the one without the argument, bit for bit.

    The work per step is that of the module docstring's safe step, written to compute each
    subexpression once (``engine.compiled`` repeats these expressions in the same order);
    finished states are dropped from the arrays only when at least an eighth of them are
    finished (until then they are carried along, their results already stored), which saves
    copying every array at nearly every step. Neither changes a bit of the result, nor does
    the batch a state shares: each state's arithmetic is its own.
    """
    theta, v, *given = np.broadcast_arrays(*(np.asarray(x, dtype=float)
                                             for x in (theta, v, amplitude, omega, g)))
    shape = theta.shape
    release = (None if released is None or not np.any(released)
               else np.broadcast_to(np.asarray(released, dtype=bool), shape).ravel())
    theta = np.mod(theta.ravel(), 2.0 * np.pi)  # sin/cos periodic: keep arguments small
    v = v.ravel()
    # racket parameters: plain floats when they are one value (the fast path), else arrays
    # that are compacted with the states below
    racket: list[Any] = [float(x.flat[0]) if x.size and np.all(x == x.flat[0]) else x.ravel()
                         for x in given]
    a, w, g = racket
    bound: Any = g / (w * w) + a  # M >= |G''|
    cos_th = np.cos(theta) if cos_theta is None else np.broadcast_to(cos_theta, shape).ravel()
    sin_th = np.sin(theta) if sin_theta is None else np.broadcast_to(sin_theta, shape).ravel()

    result = np.full(theta.shape, np.nan)
    slope = (v - a * w * cos_th) / w
    curvature = -g / w**2 + a * sin_th
    flies = (slope > 0.0) | ((slope == 0.0) & (curvature > 0.0))  # can_fly
    if release is not None:  # a release point flies when G''' = a cos theta > 0
        flies = np.where(release, cos_th > 0.0, flies)
    idx = np.flatnonzero(flies)
    vv = v[idx]
    a, w, g, bound = (x if isinstance(x, float) else x[idx] for x in (a, w, g, bound))

    # first step from s = 0 (G = 0): smallest positive root of d + c h/2 - a h^2/6
    cos_th, sin_th = cos_th[idx], sin_th[idx]
    d0 = vv / w - a * cos_th
    c0 = -g / (w * w) + a * sin_th
    s = (c0 / 2.0 + np.sqrt(c0 * c0 / 4.0 + 2.0 * a * np.maximum(d0, 0.0) / 3.0)) / (a / 3.0)
    if release is not None:  # G' = G'' = 0 at a release: the fourth-order first step
        at_release = release[idx]
        d0 = np.where(at_release, 0.0, d0)
        s = np.where(at_release, 2.0 * cos_th, s)
    tmp = np.empty_like(s)
    del slope, curvature, c0

    eps = np.finfo(float).eps
    # scalars of the step, computed once (the same values the array expressions would use)
    w_sq: Any = w * w
    two_w_sq: Any = 2.0 * w * w
    two_a: Any = 2.0 * a
    two_bound: Any = 2.0 * bound
    live = np.ones(idx.size, dtype=bool)  # not yet finished (finished ones may be carried)
    n_live = idx.size
    for _ in range(max_steps):
        if n_live == 0:
            break
        half = s / 2.0
        sin_half = np.sin(half)
        cos_half = np.cos(half, out=half)
        # cos and sin of theta + s/2 by the angle-addition formulas: two transcendental
        # functions per step instead of three (the same expressions as engine.compiled)
        cos_mid = cos_th * cos_half
        cos_mid -= np.multiply(sin_th, sin_half, out=tmp)
        sin_mid = np.multiply(sin_th, cos_half, out=cos_half)
        sin_mid += np.multiply(cos_th, sin_half, out=tmp)
        racket_rise = np.multiply(two_a, cos_mid, out=cos_mid)
        racket_rise *= sin_half  # a (sin(th + s) - sin(th)) = 2 a cos(th + s/2) sin(s/2)
        ball = vv * s
        ball /= w
        g_s = g * s
        drop = g_s * s
        drop /= two_w_sq
        G = ball - drop
        G -= racket_rise
        # d = d0 - g s / w^2 + 2 a sin(th + s/2) sin(s/2)
        d = np.divide(g_s, w_sq, out=g_s)
        np.subtract(d0, d, out=d)
        rate = np.multiply(two_a, sin_mid, out=sin_mid)
        rate *= sin_half
        d += rate
        # scale = |v s / w| + g s^2 / (2 w^2) + |racket rise|
        scale = np.abs(ball, out=ball)
        scale += drop
        scale += np.abs(racket_rise, out=racket_rise)
        # step = (d + sqrt(d^2 + 2 M max(G, 0))) / M
        step = np.maximum(G, 0.0, out=drop)
        step *= two_bound
        step += np.multiply(d, d, out=sin_half)
        np.sqrt(step, out=step)
        step += d
        step /= bound
        scale *= 8.0 * eps
        done = G <= scale
        done |= step <= 4.0 * eps * s
        done &= live
        s_next = s + step
        # the last step, taken without an evaluation to confirm it: the root lies in
        # [s + h, s + h + 2 M h^2 / delta] when delta = -(d + M h) > 0 (module docstring);
        # when that is within eps (s + h), s + h is the root to about an ulp
        delta = np.multiply(bound, step)
        delta += d
        np.negative(delta, out=delta)
        last = np.multiply(two_bound, step)
        last *= step
        last = last <= eps * s_next * delta
        last &= delta > 0.0
        last &= live
        last &= ~done
        if last.any():
            result[idx[last]] = s_next[last]
        finished = done | last
        if finished.any():
            if done.any():
                # Newton polish of the converged ones, only where the crossing is transversal
                # and the correction tiny, so that a polish can never move to another root
                sd, Gd, dd = s[done], G[done], d[done]
                with np.errstate(divide="ignore", invalid="ignore"):
                    corr = np.where(dd < 0.0, Gd / dd, 0.0)
                corr = np.where(np.abs(corr) < 1e-6 * sd, corr, 0.0)
                result[idx[done]] = sd - corr
            live &= ~finished
            n_live = int(np.count_nonzero(live))
            if n_live <= live.size - live.size // 8:  # compact: drop the finished ones
                idx, vv, d0, s_next, cos_th, sin_th = (
                    x[live] for x in (idx, vv, d0, s_next, cos_th, sin_th)
                )
                tmp = np.empty_like(s_next)
                a, w, g, bound = (x if isinstance(x, float) else x[live]
                                  for x in (a, w, g, bound))
                w_sq, two_w_sq, two_a, two_bound = w * w, 2.0 * w * w, 2.0 * a, 2.0 * bound
                live = np.ones(n_live, dtype=bool)
        s = s_next
    return result.reshape(shape)
