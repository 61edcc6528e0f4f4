"""The first-impact solver for the implicit phase map (eq. 6), vectorised over many states.

After an impact at phase theta with ball velocity v (just after impact), the height of the
ball above the racket at elapsed phase s = omega_r (t - t_k) is the gap (eq. 1 minus eq. 4)

    G(s) = v s / w - g s^2 / (2 w^2) + a sin(theta) - a sin(theta + s),

and eq. 6 is G(s) = 0 (multiplied by w^2). G has several roots; the next impact is the FIRST
positive one. With G(0) = 0 and G'(0) = (v - a w cos theta)/w > 0 the ball starts above the
racket. Every step taken here is one that a lower bound of G proves root-free:

* first step, from s = 0: Taylor to third order with |G'''| <= a gives
  G(h) >= h (d + c h / 2 - a h^2 / 6), d = G'(0), c = G''(0);
* later steps, from a point with G > 0: |G''| <= g/w^2 + a =: M gives
  G(s + h) >= G + d h - M h^2 / 2 > 0 for h < (d + sqrt(d^2 + 2 M G)) / M.

So the iteration can never jump over a root; it approaches the first root from the safe
side (like Newton, quadratically near a simple root) and is finished with a Newton polish.
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


def next_impact_phase(theta, v, params: ModelParams, *, max_steps: int = MAX_SAFE_STEPS):
    """Phase elapsed until the FIRST impact after leaving the racket at (theta, v).

    theta: phase of the current impact (rad, wrapped or not); v: ball velocity just after it
    (m/s). Arrays broadcast. Returns s > 0 with G(s) = 0 and G > 0 on (0, s); NaN where the
    ball cannot fly (see ``can_fly``) or, never observed, where the iteration did not converge.

    ``params`` is a ``ModelParams``, or any object with the same attributes holding arrays that
    broadcast to the states' shape: one parameter point per state (bifurcation sweeps).
    """
    return first_impact_phase(theta, v, params.racket_amplitude, params.omega, params.g,
                              max_steps=max_steps)


def first_impact_phase(theta, v, amplitude, omega, g, *, max_steps: int = MAX_SAFE_STEPS):
    """``next_impact_phase`` with the racket's amplitude a (m), angular frequency w (rad/s)
    and gravity g (m/s^2) given directly, each a scalar or an array broadcasting with theta
    and v: one call serves states at different parameters (a sweep of the map, or a racket
    whose period changes from one flight to the next under period control). Scalars take the
    same arithmetic as arrays of one value, so results do not depend on the form."""
    theta, v, *given = np.broadcast_arrays(*(np.asarray(x, dtype=float)
                                             for x in (theta, v, amplitude, omega, g)))
    shape = theta.shape
    theta = np.mod(theta.ravel(), 2.0 * np.pi)  # sin/cos periodic: keep arguments small
    v = v.ravel()
    # racket parameters: plain floats when they are one value (the fast path), else arrays
    # that are compacted with the states below
    racket: list[Any] = [float(x.flat[0]) if x.size and np.all(x == x.flat[0]) else x.ravel()
                         for x in given]
    a, w, g = racket
    bound: Any = g / (w * w) + a  # M >= |G''|

    result = np.full(theta.shape, np.nan)
    slope = (v - a * w * np.cos(theta)) / w
    curvature = -g / w**2 + a * np.sin(theta)
    idx = np.flatnonzero((slope > 0.0) | ((slope == 0.0) & (curvature > 0.0)))  # can_fly
    th, vv = theta[idx], v[idx]
    a, w, g, bound = (x if isinstance(x, float) else x[idx] for x in (a, w, g, bound))

    # first step from s = 0 (G = 0): smallest positive root of d + c h/2 - a h^2/6
    d0 = vv / w - a * np.cos(th)
    c0 = -g / (w * w) + a * np.sin(th)
    s = (c0 / 2.0 + np.sqrt(c0 * c0 / 4.0 + 2.0 * a * np.maximum(d0, 0.0) / 3.0)) / (a / 3.0)

    eps = np.finfo(float).eps
    for _ in range(max_steps):
        if idx.size == 0:
            break
        half = s / 2.0
        sin_half, mid = np.sin(half), th + half
        racket_rise = 2.0 * a * np.cos(mid) * sin_half  # a (sin(th + s) - sin(th))
        G = vv * s / w - g * s * s / (2.0 * w * w) - racket_rise
        d = d0 - g * s / (w * w) + 2.0 * a * np.sin(mid) * sin_half
        scale = np.abs(vv * s / w) + g * s * s / (2.0 * w * w) + np.abs(racket_rise)
        step = (d + np.sqrt(d * d + 2.0 * bound * np.maximum(G, 0.0))) / bound
        done = (G <= 8.0 * eps * scale) | (step <= 4.0 * eps * s)
        if np.any(done):
            # Newton polish of the converged ones, only where the crossing is transversal and
            # the correction tiny, so that a polish can never move to another root
            sd, Gd, dd = s[done], G[done], d[done]
            with np.errstate(divide="ignore", invalid="ignore"):
                corr = np.where(dd < 0.0, Gd / dd, 0.0)
            corr = np.where(np.abs(corr) < 1e-6 * sd, corr, 0.0)
            result[idx[done]] = sd - corr
            keep = ~done
            idx, th, vv, d0, s, step = (
                idx[keep], th[keep], vv[keep], d0[keep], s[keep], step[keep]
            )
            a, w, g, bound = (x if isinstance(x, float) else x[keep] for x in (a, w, g, bound))
        s = s + step
    return result.reshape(shape)
