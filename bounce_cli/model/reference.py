"""A slow, independent, per-point classifier: the paper's method (section 3: a Brent zero
finder for each impact, Matlab's fzero) done right.

For each impact the FIRST root of eq. 6 is bracketed by scanning the gap for its first sign
change on a fine grid of elapsed phase, then refined with ``scipy.optimize.brentq``. Scalar
Python throughout (``math``), sharing no code with ``next_impact_phase`` or ``classify_batch``: it
exists to check the fast classifier point by point and as the baseline of
``benchmarks/basin.py``. It follows the same conventions as ``analysis.classify`` (see there).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from .maps import ClassifySettings
from .params import ModelParams

#: scan step of the bracket search (rad of racket phase; 1e-3 rad = 0.15 ms at tau = 0.92 s)
SCAN_STEP = 1e-3
#: phases scanned per vectorised chunk of the bracket search
_CHUNK = 256


def first_impact_brentq(theta: float, v: float, params: ModelParams, scan_step=SCAN_STEP):
    """Elapsed phase s of the first impact after leaving the racket at (theta, v), or None
    when the ball cannot leave (v not above the racket velocity).

    Works with H(s) = G(s) / s (G the gap of eq. 6): H(0+) = G'(0) > 0, so the scan starts
    at s = 0 with no spurious root there. The scan evaluates H in chunks with numpy (the
    only vectorisation), stops at the first chunk containing a non-positive value, and brentq
    refines inside [s_j-1, s_j].
    """
    w, a, g = params.omega, params.racket_amplitude, params.g
    d0 = v / w - a * math.cos(theta)
    if d0 <= 0.0:
        return None
    sin_t = math.sin(theta)

    def h(s: float) -> float:
        if s == 0.0:
            return d0
        return v / w - g * s / (2.0 * w * w) + a * (sin_t - math.sin(theta + s)) / s

    start = 0.0
    while True:
        s = start + scan_step * np.arange(1, _CHUNK + 1)
        values = v / w - g * s / (2.0 * w * w) + a * (sin_t - np.sin(theta + s)) / s
        below = np.flatnonzero(values <= 0.0)
        if below.size:
            j = below[0]
            hi = float(s[j])
            lo = float(s[j - 1]) if j > 0 else start
            if h(hi) == 0.0:
                return hi
            return brentq(h, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200)
        start = float(s[-1])


def classify_point_brentq(theta0: float, v0: float, params: ModelParams,
                          settings: ClassifySettings = ClassifySettings()) -> tuple[str, int]:
    """(outcome name, iterations) of one initial condition by the scalar reference method,
    with the stopping conditions of ``settings`` (section 3)."""
    max_iterations, tolerance = settings.max_iterations, settings.tolerance
    w, a, g, alpha = params.omega, params.racket_amplitude, params.g, params.alpha
    fp = params.fixed_point()
    theta, v = math.fmod(theta0, 2 * math.pi) % (2 * math.pi), float(v0)
    if not v > a * w * math.cos(theta):
        # can_fly also lets a ball leave with the racket's velocity when the racket
        # decelerates faster than gravity; on a grid that equality is never hit exactly
        return "below_racket", 0
    for k in range(1, max_iterations + 1):
        s = first_impact_brentq(theta, v, params)
        if s is None or s / w < settings.min_hop_s:
            return "sticking", k
        theta = (theta + s) % (2 * math.pi)
        v = (1 + alpha) * a * w * math.cos(theta) - alpha * v + g * alpha / w * s  # eq. 5
        dphase = (theta - fp.theta_rad + math.pi) % (2 * math.pi) - math.pi
        if abs(v - fp.v_m_s) < tolerance and abs(dphase) < tolerance:
            return "period1", k
    return "undecided", max_iterations
