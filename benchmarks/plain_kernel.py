"""The reference for the basin's speed: a plain single-thread vectorised numpy kernel of the map.

This is what a careful user would write in an afternoon (a script, not part of ``bounce``): the
Fig. 4 classification of section 3 with the straightforward vectorised safe-step iteration
(from quadratic lower bounds of the gap) and nothing else -- no tiles, no worker processes,
no third-order first step, no product form of sin(theta) - sin(theta + s), no Newton
polish, no files. All points of the grid advance together, one vectorised first-impact
solve per impact on the points still undecided; inside a solve every unconverged point
takes the safe step of the quadratic bound

    G(s + h) >= G + G' h - M h^2 / 2,  M = g / w^2 + a  (|G''| <= M),

i.e. h = (G' + sqrt(G'^2 + 2 M G)) / M, starting from s = 0 (where G = 0: h = 2 G'(0) / M),
until the step is below 1e-13 rad. Gap (eq. 6 divided by w^2):
G(s) = v s / w - g s^2 / (2 w^2) + a sin(theta) - a sin(theta + s); velocity map eq. 5.

``benchmarks/basin.py --plain`` times it against ``bounce basin`` and reports how many points
the two classify alike (all but a handful on the basin boundaries: the two root finders differ
in the last bits).

    python benchmarks/plain_kernel.py --size 1000
"""

from __future__ import annotations

import argparse
import time

import numpy as np

PERIOD1, STICKING, BELOW_RACKET, UNDECIDED = 0, 1, 2, 3

#: the paper's Fig. 4 model and section 3's stopping conditions
ALPHA, G_ACC, AMPLITUDE, PERIOD = 0.5, 9.81, 0.30, 0.92
MAX_ITERATIONS, TOLERANCE, MIN_HOP_S = 100, 1e-3, 1e-3
STEP_TOLERANCE = 1e-13


def plain_grid(n: int):
    """The flattened n x n grid (v0 outer, theta0 inner), theta0 0..360 deg, v0 0..10 m/s."""
    theta, v = np.meshgrid(np.deg2rad(np.linspace(0.0, 360.0, n)), np.linspace(0.0, 10.0, n))
    return theta.ravel(), v.ravel()


def fixed_point(alpha=ALPHA, g=G_ACC, a=AMPLITUDE, period=PERIOD):
    """Eqs. 7, 8: v~ = g tau / 2, cos theta~ = (1 - alpha) g tau / (2 (1 + alpha) a w)."""
    w = 2.0 * np.pi / period
    v_fp = g * period / 2.0
    theta_fp = np.arccos((1.0 - alpha) / (1.0 + alpha) * g * period / (2.0 * a * w))
    return theta_fp, v_fp


def classify_plain(theta0, v0, alpha=ALPHA, g=G_ACC, a=AMPLITUDE, period=PERIOD):
    """Outcome codes (0 period1, 1 sticking, 2 below racket, 3 undecided) and impact counts."""
    w = 2.0 * np.pi / period
    bound = g / w**2 + a
    theta_fp, v_fp = fixed_point(alpha, g, a, period)
    outcome = np.full(theta0.shape, UNDECIDED, dtype=np.int8)
    iterations = np.full(theta0.shape, MAX_ITERATIONS, dtype=np.int16)
    flies = v0 > a * w * np.cos(theta0)
    outcome[~flies] = BELOW_RACKET
    iterations[~flies] = 0

    idx = np.flatnonzero(flies)
    th, v = np.mod(theta0[idx], 2 * np.pi), v0[idx]
    for k in range(1, MAX_ITERATIONS + 1):
        if idx.size == 0:
            break
        # first impact: safe steps from s = 0 until converged (active points only)
        hop = np.empty(th.size)
        sin_th = np.sin(th)
        s = np.zeros(th.size)
        active = np.arange(th.size)
        a_th, a_v, a_sin, a_s = th, v, sin_th, s
        while active.size:
            gap = a_v * a_s / w - g * a_s**2 / (2 * w**2) + a * a_sin - a * np.sin(a_th + a_s)
            slope = a_v / w - g * a_s / w**2 - a * np.cos(a_th + a_s)
            step = (slope + np.sqrt(np.maximum(slope**2 + 2 * bound * gap, 0.0))) / bound
            a_s = a_s + step
            done = step < STEP_TOLERANCE
            hop[active[done]] = a_s[done]
            keep = ~done
            active, a_th, a_v, a_sin, a_s = (x[keep] for x in (active, a_th, a_v, a_sin, a_s))
        th = np.mod(th + hop, 2 * np.pi)
        v = (1 + alpha) * a * w * np.cos(th) - alpha * v + g * alpha / w * hop
        sticking = hop / w < MIN_HOP_S
        period1 = ~sticking & (np.abs(v - v_fp) < TOLERANCE) & (
            np.abs(np.mod(th - theta_fp + np.pi, 2 * np.pi) - np.pi) < TOLERANCE)
        settled = sticking | period1
        outcome[idx[settled]] = np.where(sticking[settled], STICKING, PERIOD1)
        iterations[idx[settled]] = k
        keep = ~settled
        idx, th, v = idx[keep], th[keep], v[keep]
    return outcome, iterations


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1000, help="grid side N (N x N points)")
    ap.add_argument("--repeat", type=int, default=3, help="runs; the minimum is reported")
    args = ap.parse_args()
    theta, v = plain_grid(args.size)
    times = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        outcome, iterations = classify_plain(theta, v)
        times.append(time.perf_counter() - t0)
    fractions = np.bincount(outcome, minlength=4) / outcome.size
    print(f"plain numpy kernel, {args.size} x {args.size}: min {min(times):.2f} s of "
          f"{args.repeat} ({', '.join(f'{t:.2f}' for t in times)}); fractions "
          + ", ".join(f"{f:.4f}" for f in fractions) + f"; max impacts {iterations.max()}")


if __name__ == "__main__":
    main()
