"""The basin classifier compiled with numba: ``classify_batch``'s arithmetic, bit for bit.

Optional (``pip install 'bounce-cli[fast]'``): ``classify.classify_batch`` uses this kernel
when numba can be imported (``kernel="auto"``) and its own numpy code otherwise, with the same
outcome and impact count for every point (tests/engine/test_compiled.py compares the two on
grids, on random states and on the edge cases: grazing launches, balls that cannot fly,
unconverged solves). Environment variable ``BOUNCE_KERNEL=numpy`` turns the kernel off.

Why it is faster, measured on the 2-core machine the benchmarks run on (``benchmarks/``):
the Fig. 4 grid at 1000 x 1000 takes about 12.5 M impacts at about 5 evaluations of the gap
each (``impact.first_impact_phase``, eq. 6), each with a sine and a cosine (of s/2). numpy
evaluates them one array function after another plus some thirty array passes of
arithmetic: 4.5 s for the grid on one core. Here all points of a tile advance in lock step
as in numpy (an impact, then the safe steps of all points still flying), each step in two
tight loops: one evaluation and one safe step of every flight, without a branch and without
a call (the sine and cosine are ``trig.sincos``'s arithmetic, inlined; the stopping rule is
selects), which LLVM vectorises (AVX-512 here: about 4.5 ns a flight, where the C library's
``sin`` and ``cos`` alone took 24 ns), and the compaction of the flights still in the air
(2.3 ns, also without a branch). An impact's own work (the new phase, its sine and cosine,
eq. 5, the launch's first step) is split the same way into loops that vectorise and loops
that compact; the new phase is wrapped without fmod's call (``_wrap_near``). The grid takes
0.73 s on one thread (was 1.5 s with the C library's functions), 0.37 s on two, on the AMD
machine; on an Intel Xeon with AVX-512, whose full width LLVM uses only when asked
(``prefer_full_vector_width``), the wrap and the width took two threads from 0.79-0.89 s to
0.54-0.75 s (in a slow hour of that machine).

Bit-for-bit: every expression below is the numpy code's expression in the same order
(IEEE double arithmetic, no fast-math, so no contraction into fused multiply-adds;
vectorising changes no result, as each flight's arithmetic is its own), the scalars
derived from the parameters are computed once in Python by the numpy code's own
expressions (``_constants``), sqrt is correctly rounded everywhere, and sin and cos are
``trig.sincos`` (the numpy code's classifier takes the same function, ``trig=sincos``),
so the results do not depend on the C library either -- except the launch test on the
grid's theta0 (``_launch``: cos and sin of the unwrapped phase), where both routes call the
C library's functions, as numpy does for float64. The functions release the GIL:
tiles of a grid run in threads (``parallel.Threads``).
"""

from __future__ import annotations

import contextlib
import functools
import math
import sys
from typing import Any, Iterator

import numba
import numpy as np
from numba.core import codegen as numba_codegen, config as numba_config

from .kernel_arrays import (  # noqa: F401  (the indices: globals of the loops below)
    _A, _A_3, _ALPHA, _AW, _BOUND, _G, _G_ALPHA_W, _MIN_HOP, _N_CONSTANTS, _NEG_G_W2,
    _NEG_G_WW, _TH_FP, _TOL, _TWO_A, _TWO_BOUND, _TWO_W_SQ, _V_COEF, _V_FP, _W, _W_SQ,
    classify_scratch, flight_constants, kernel_inputs, solver_constants as _constants,
)
from .impact import LAST_STEP_LEVEL, POLISH_LIMIT, ROUNDING_LEVEL, STEP_FLOOR
from .params import FixedPoint, ModelParams
from .trig import sincos, sincos_of_float

TWO_PI = 2.0 * math.pi


def prefer_full_vector_width() -> bool:
    """Let LLVM vectorise with the CPU's widest vectors: on CPUs with AVX-512 it keeps to
    256-bit vectors by default (its tuning for Intel's server CPUs), and the kernel's loops
    ran about a tenth slower so (the Fig. 4 grid on two threads: 0.70-0.75 s against
    0.60-0.68 s on a 2-core Intel Xeon). Each flight's arithmetic is its own, so the width
    changes no bit (``tests/engine/test_compiled.py`` compares a run without vectors).

    Only where numba's own choice is in force: not when NUMBA_CPU_NAME or
    NUMBA_CPU_FEATURES are set (a cache shared by several machines) or AVX is disabled, and
    only before numba has compiled anything in this process (its target is made once);
    whatever numba compiles later in the process gets the same width. Returns whether it
    was set."""
    config: Any = numba_config  # its names are set from the environment at run time
    if config.CPU_NAME is not None or config.CPU_FEATURES is not None or not config.ENABLE_AVX:
        return False
    features = numba_codegen.get_host_cpu_features()
    if "+avx512f" not in features.split(","):
        return False
    config.CPU_FEATURES = features + ",-prefer-256-bit"
    return True


prefer_full_vector_width()

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
#: small functions inlined into the loops that call them (in the numba IR: the loop stays
#: one block of arithmetic that LLVM vectorises)
_inline = numba.njit(inline="always", error_model="numpy")

_flight_constants = _jit(flight_constants)


#: ``trig.sincos`` of one float, inlined into the loops that call it
_sincos = _inline(sincos_of_float)


@_jit
def _launch(i, slope, curvature, idx, m, outcome, iterations):
    """can_fly of initial condition i from G'(0) and G''(0): queue it (idx[m] = i, returns
    m + 1), or classify it below the racket (0 iterations, returns m)."""
    if slope > 0.0 or (slope == 0.0 and curvature > 0.0):
        idx[m] = i
        return m + 1
    outcome[i] = 2  # below_racket
    iterations[i] = 0
    return m


@_inline
def _wrap_near(x):
    """np.mod(x, 2 pi) for x in (-2 pi, 8 pi) without fmod's call, the same bits: on
    [2 pi, 8 pi) (with 2 pi the double TWO_PI) fmod's x - n TWO_PI, n = 1, ..., 3, is exact, and
    so is each subtraction here (Sterbenz: each takes a multiple of TWO_PI from a number
    within a factor 2 of it), and on (-2 pi, 0) np.mod's fmod is x itself and the result its
    rounded sum with TWO_PI, as here; -0.0 becomes +0.0 as in np.mod. Selects only (the loop
    around it vectorises); elsewhere (NaN, far outside) the value is not used (``_wrap``)."""
    reduced = x - 2.0 * TWO_PI  # exact for x in [2 TWO_PI, 8 TWO_PI)
    reduced = reduced - TWO_PI if reduced >= TWO_PI else reduced  # exact: in [TWO_PI, 2 TWO_PI)
    once = x - TWO_PI  # exact for x in [TWO_PI, 2 TWO_PI)
    near = x + TWO_PI if x < 0.0 else x + 0.0
    return reduced if x >= 2.0 * TWO_PI else (once if x >= TWO_PI else near)


@_inline
def _wraps_near(x):
    """True where ``_wrap_near(x)`` is np.mod(x, 2 pi)."""
    return (x > -TWO_PI) & (x < 4.0 * TWO_PI)


@_jit
def _wrap(x):
    """np.mod(x, 2 pi), the same bits (without fmod's call where x lies in (-2 pi, 8 pi))."""
    return _wrap_near(x) if _wraps_near(x) else x % TWO_PI


@_inline
def _safe_step(s, G, d, terms, bound, two_bound):
    """One step of ``impact.first_contact`` for one flight at s, where the gap is G, its slope
    d, the sum of its terms' magnitudes ``terms`` and M = ``bound`` >= |G''| (``two_bound``
    = 2 M): (its root, NaN while not finished; the next s). The same stopping rule, with the
    same constants, in the same order of operations; written as selects without a branch
    (an expression a branch would skip is computed and not used), so that the loop around it
    vectorises."""
    G_pos = G if (G >= 0.0 or G != G) else 0.0  # np.maximum(G, 0.0)
    step = (math.sqrt(G_pos * two_bound + d * d) + d) / bound
    s_next = s + step
    converged = (G <= terms * ROUNDING_LEVEL) | (step <= STEP_FLOOR * s)
    corr = G / d  # the polish, where the crossing is transversal (d < 0)
    corr = corr if d < 0.0 else 0.0
    polished = s - corr if abs(corr) < POLISH_LIMIT * max(s, -d / bound) else s
    delta = -(bound * step + d)  # the last step
    last = ((delta > 0.0) & (two_bound * step * step <= LAST_STEP_LEVEL * s_next * delta)
            & (-d <= bound * s_next))
    return (polished if converged else (s_next if last else np.nan)), s_next


@_jit
def _first_impact(vv, cos_th, sin_th, m, c, max_steps, hop, pos, S, D0, C, SN, V, SH, CH):
    """hop[j] = ``impact.first_impact_phase`` of state j < m (NaN where the ball cannot fly
    or the solve did not converge in ``max_steps``); the other arrays are scratch of size m."""
    a, w, g = c[_A], c[_W], c[_G]
    two_a, bound, two_bound = c[_TWO_A], c[_BOUND], c[_TWO_BOUND]
    w_sq, two_w_sq = c[_W_SQ], c[_TWO_W_SQ]
    for j in range(m):  # can_fly, and the first step of each state (vectorised)
        slope = (vv[j] - c[_AW] * cos_th[j]) / w
        curvature = c[_NEG_G_W2] + a * sin_th[j]
        d0 = vv[j] / w - a * cos_th[j]
        c0 = c[_NEG_G_WW] + a * sin_th[j]
        d0_pos = d0 if (d0 >= 0.0 or d0 != d0) else 0.0  # np.maximum(d0, 0.0)
        SH[j] = (c0 / 2.0 + math.sqrt(c0 * c0 / 4.0 + two_a * d0_pos / 3.0)) / c[_A_3]
        D0[j] = d0
        CH[j] = 1.0 if (slope > 0.0) | ((slope == 0.0) & (curvature > 0.0)) else 0.0
    q = 0
    for j in range(m):  # the flights (without a branch)
        hop[j] = np.nan
        S[q], D0[q], C[q], SN[q], V[q], pos[q] = SH[j], D0[j], cos_th[j], sin_th[j], vv[j], j
        q += CH[j] == 1.0
    for _ in range(max_steps):
        if q == 0:
            break
        for j in range(q):  # one evaluation and one safe step of each flight (vectorised)
            s = S[j]
            sin_half, cos_half = _sincos(s / 2.0)
            cos_mid = C[j] * cos_half - SN[j] * sin_half
            sin_mid = SN[j] * cos_half + C[j] * sin_half
            racket_rise = two_a * cos_mid * sin_half
            ball = V[j] * s / w
            g_s = g * s
            drop = g_s * s / two_w_sq
            G = ball - drop - racket_rise
            d = D0[j] - g_s / w_sq + two_a * sin_mid * sin_half
            terms = abs(ball) + drop + abs(racket_rise)
            # NaN: not finished (a finished phase is finite)
            SH[j], CH[j] = _safe_step(s, G, d, terms, bound, two_bound)
        r = 0
        for j in range(q):  # store the finished, compact the others (without a branch)
            root, at = SH[j], pos[j]
            hop[at] = root  # NaN while not finished: overwritten when it is
            S[r], D0[r], C[r], SN[r], V[r], pos[r] = CH[j], D0[j], C[j], SN[j], V[j], at
            r += root != root
        q = r


@_jit
def _impact(th, vv, cos_th, sin_th, m, c, max_steps, hop, pos, S, D0, C, SN, V, SH, CH):
    """One impact of the m wrapped states (``PassiveMap.step``'s arithmetic): hop[j] the
    flight's phase (``_first_impact``), then into the solver's scratch the impact's phase
    S (wrapped by ``_wrap_near`` in a loop that vectorises; fmod, a call, in a loop of its
    own only where a phase lies beyond it), its sine SN and cosine C and eq. 5's velocity
    V (a loop that vectorises)."""
    _first_impact(vv, cos_th, sin_th, m, c, max_steps, hop, pos, S, D0, C, SN, V, SH, CH)
    far = 0
    for j in range(m):  # np.mod near [0, 2 pi) (vectorised) ...
        phase = th[j] + hop[j]
        S[j] = _wrap_near(phase)
        far += not _wraps_near(phase)
    if far:  # ... and elsewhere (NaN: a flight that did not converge), fmod
        for j in range(m):
            phase = th[j] + hop[j]
            if not _wraps_near(phase):
                S[j] = phase % TWO_PI
    for j in range(m):
        SN[j], C[j] = _sincos(S[j])
        V[j] = c[_V_COEF] * C[j] - c[_ALPHA] * vv[j] + c[_G_ALPHA_W] * hop[j]


@_jit
def _classify(theta0, v0, c, max_iterations, max_steps, outcome, iterations, idx, work, pos):
    """``classify.classify_batch`` of flat arrays into ``outcome`` / ``iterations``, with
    the caller's scratch (``classify_scratch``): it allocates nothing, so that its machine
    code needs no numba runtime (``model.native`` loads it without numba)."""
    n = theta0.size
    a, w = c[_A], c[_W]
    m = 0
    for i in range(n):  # can_fly at the unwrapped initial phase
        m = _launch(i, (v0[i] - c[_AW] * math.cos(theta0[i])) / w,
                    c[_NEG_G_W2] + a * math.sin(theta0[i]), idx, m, outcome, iterations)
    # the states (5 rows) and the solver's scratch (7 rows)
    th, vv, cos_th, sin_th, hop = work[0], work[1], work[2], work[3], work[4]
    S, D0, C, SN, V, SH, CH = work[5], work[6], work[7], work[8], work[9], work[10], work[11]
    for j in range(m):
        th[j] = _wrap(theta0[idx[j]])
        vv[j] = v0[idx[j]]
        sin_th[j], cos_th[j] = _sincos(th[j])
    tol, v_fp, th_fp = c[_TOL], c[_V_FP], c[_TH_FP]
    for k in range(1, max_iterations + 1):
        if m == 0:
            break
        _impact(th, vv, cos_th, sin_th, m, c, max_steps, hop, pos, S, D0, C, SN, V, SH, CH)
        p = 0
        for j in range(m):
            h, t, v, ct, st = hop[j], S[j], V[j], C[j], SN[j]
            if not h / w >= c[_MIN_HOP]:  # sticking (NaN hop: cannot leave the racket)
                outcome[idx[j]] = 1
                iterations[idx[j]] = k
            elif (abs(v - v_fp) < tol
                  and abs(_wrap(t - th_fp + math.pi) - math.pi) < tol):
                outcome[idx[j]] = 0  # period1
                iterations[idx[j]] = k
            else:
                idx[p], th[p], vv[p], cos_th[p], sin_th[p] = idx[j], t, v, ct, st
                p += 1
        m = p
    for j in range(m):
        outcome[idx[j]] = 3  # undecided
        iterations[idx[j]] = max_iterations


def classify_arrays(theta0: np.ndarray, v0: np.ndarray, params: ModelParams, fp: FixedPoint,
                    max_iterations: int, tolerance: float, min_hop_s: float,
                    max_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """(outcome int8, iterations int16) of flat float arrays, as ``classify_batch``."""
    theta0, v0, constants = kernel_inputs(theta0, v0, params, fp, tolerance, min_hop_s)
    outcome, iterations, scratch = classify_scratch(theta0.size)
    _classify(theta0, v0, constants, max_iterations, max_steps, outcome, iterations, *scratch)
    return outcome, iterations


def classify_entry(theta0, v0, c, n, max_iterations, max_steps, outcome, iterations, idx,
                   work, pos):
    """``_classify`` over raw pointers to n points (``native._ENTRY_ARGS``): the function
    ``model.native`` compiles with ``numba.cfunc`` and loads without numba."""
    _classify(numba.carray(theta0, (n,)), numba.carray(v0, (n,)),
              numba.carray(c, (_N_CONSTANTS,)), max_iterations, max_steps,
              numba.carray(outcome, (n,)), numba.carray(iterations, (n,)),
              numba.carray(idx, (n,)), numba.carray(work, (12, n)), numba.carray(pos, (n,)))


# -- the controlled map (``model.control.ControlledMap``, ``switch: impact``) -----------------
# its classification loop: each flight has its own racket frequency (the period the controller
# set at the impact), so each state's solve gets its own constants, filled by the numpy code's
# array expressions (``impact.first_impact_phase`` with an array of frequencies: w**2 is w*w)
(_C_A, _C_G, _C_ALPHA, _C_TAU_BAR, _C_V_REF, _C_GAIN, _C_RATE, _C_V_FP, _C_TH_FP, _C_TOL,
 _C_TOL_TAU, _C_MIN_HOP, _C_V_COEF_A, _C_G_ALPHA, _N_CONTROL) = range(15)


@_jit
def _classify_controlled(theta0, v0, tau0, k, max_iterations, max_steps, outcome, iterations):
    """``classify.classify_states`` of a ``ControlledMap`` with a period controller
    (``switch: impact``) into ``outcome`` / ``iterations``: ``controlled_step``'s arithmetic
    (wrapped), one solve per state (``_first_impact`` on one state, its own frequency)."""
    n = theta0.size
    a, g = k[_C_A], k[_C_G]
    idx = np.empty(n, np.int64)
    m = 0
    for i in range(n):  # can_fly_at at the unwrapped phase, with the period the racket had
        w = TWO_PI / tau0[i]
        m = _launch(i, (v0[i] - a * w * math.cos(theta0[i])) / w,
                    -g / (w * w) + a * math.sin(theta0[i]), idx, m, outcome, iterations)
    state = np.empty((5, m))  # theta, v, tau and theta's cos and sin
    th, vv, tt, cos_th, sin_th = state[0], state[1], state[2], state[3], state[4]
    for j in range(m):
        th[j], vv[j], tt[j] = _wrap(theta0[idx[j]]), v0[idx[j]], tau0[idx[j]]
        sin_th[j], cos_th[j] = _sincos(th[j])
    c = np.empty(_N_CONSTANTS)
    one = np.empty((11, 1))  # one state's v, cos, sin, its hop and the solver's scratch
    pos = np.empty(1, np.int64)
    tau_bar, gain, rate = k[_C_TAU_BAR], k[_C_GAIN], k[_C_RATE]
    for it in range(1, max_iterations + 1):
        if m == 0:
            break
        p = 0
        for j in range(m):
            # the period controller: tau' = tau + c (tau_bar + K 2 (v - v~) / g - tau)
            tau = tt[j] + rate * ((tau_bar + gain * (2.0 * (vv[j] - k[_C_V_REF]) / g)) - tt[j])
            if not tau > 0.0:
                tau = np.nan  # no racket has a period <= 0
            w = TWO_PI / tau
            _flight_constants(a, w, g, c)
            one[0, 0], one[1, 0], one[2, 0] = vv[j], cos_th[j], sin_th[j]
            _first_impact(one[0], one[1], one[2], 1, c, max_steps, one[3], pos, one[4],
                          one[5], one[6], one[7], one[8], one[9], one[10])
            h = one[3, 0]
            t = _wrap(th[j] + h)
            sin_t, cos_t = _sincos(t)  # eq. 5's cosine, and the next solve's
            v = k[_C_V_COEF_A] * w * cos_t - k[_C_ALPHA] * vv[j] + k[_C_G_ALPHA] / w * h
            if not h / w >= k[_C_MIN_HOP]:  # sticking (NaN: cannot leave, or no period)
                outcome[idx[j]] = 1
                iterations[idx[j]] = it
            elif (abs(v - k[_C_V_FP]) < k[_C_TOL]
                  and abs(_wrap(t - k[_C_TH_FP] + math.pi) - math.pi) < k[_C_TOL]
                  and abs(tau - tau_bar) < k[_C_TOL_TAU]):
                outcome[idx[j]] = 0  # period1
                iterations[idx[j]] = it
            else:
                idx[p], th[p], vv[p], tt[p] = idx[j], t, v, tau
                cos_th[p], sin_th[p] = cos_t, sin_t
                p += 1
        m = p
    for j in range(m):
        outcome[idx[j]] = 3  # undecided
        iterations[idx[j]] = max_iterations


def classify_controlled_arrays(theta0: np.ndarray, v0: np.ndarray, tau0: np.ndarray,
                               params: ModelParams, fp: FixedPoint, *, tau_bar: float,
                               v_reference: float, gain: float, rate: float,
                               max_iterations: int, tolerance: float,
                               period_tolerance_s: float, min_hop_s: float,
                               max_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """(outcome int8, iterations int16) of flat float arrays for the controlled map with the
    period controller (gain K, rate c; ``switch: impact``), as ``classify_states`` gives
    them with the numpy code."""
    a, g, alpha = params.racket_amplitude, params.g, params.alpha
    k = np.empty(_N_CONTROL)
    k[_C_A], k[_C_G], k[_C_ALPHA] = a, g, alpha
    k[_C_TAU_BAR], k[_C_V_REF], k[_C_GAIN], k[_C_RATE] = tau_bar, v_reference, gain, rate
    k[_C_V_FP], k[_C_TH_FP] = fp.v_m_s, fp.theta_rad
    k[_C_TOL], k[_C_TOL_TAU], k[_C_MIN_HOP] = tolerance, period_tolerance_s, min_hop_s
    k[_C_V_COEF_A] = (1.0 + alpha) * a  # eq. 5: ((1 + alpha) a) w cos(theta')
    k[_C_G_ALPHA] = g * alpha  # eq. 5: (g alpha / w) s
    outcome = np.empty(theta0.size, dtype=np.int8)
    iterations = np.empty(theta0.size, dtype=np.int16)
    _classify_controlled(np.ascontiguousarray(theta0, dtype=float),
                         np.ascontiguousarray(v0, dtype=float),
                         np.ascontiguousarray(tau0, dtype=float), k, max_iterations, max_steps,
                         outcome, iterations)
    return outcome, iterations


# -- the recurrence of ``analysis.attractors`` -------------------------------------------------
@_jit
def _cell(theta, v, cells_theta, scale_theta, cells_v, v_low, scale_v):
    """``analysis.attractors.Tessellation.code`` of one state, the same expressions (a NaN
    phase in the first column, a NaN velocity below the range, the range's ends clipped)."""
    column = (theta % TWO_PI) * scale_theta
    if column != column:
        column = 0.0
    i = min(max(np.int64(column), 0), cells_theta - 1)
    j = np.floor((v - v_low) * scale_v)
    if j != j:
        j = -1.0
    j = min(max(j, -1.0), float(cells_v))
    return i * (cells_v + 2) + np.int64(j) + 1


@_jit
def _recurrence(theta, v, cos_theta, sin_theta, c, max_steps, cells_theta, scale_theta,
                cells_v, v_low, scale_v, recurrence, max_impacts, visited, recurred, stuck):
    """``analysis.attractors._recurrence``'s loop on wrapped states: each orbit one impact at
    a time (``PassiveMap.step``'s arithmetic, as ``_classify`` repeats it), its cell marked
    in its row of ``visited``, until ``recurrence`` impacts in a row land in visited cells
    (``recurred``), it sticks (a hop shorter than ``min_hop_s``, or NaN: ``stuck``, where it
    did not recur on that impact), or ``max_impacts``. Returns the largest finite velocity
    after impact seen (-inf: none)."""
    m = theta.size
    w = c[_W]
    work = np.empty((12, m))
    th, vv, cos_th, sin_th, hop = work[0], work[1], work[2], work[3], work[4]
    S, D0, C, SN, V, SH, CH = work[5], work[6], work[7], work[8], work[9], work[10], work[11]
    pos = np.empty(m, np.int64)
    idx = np.empty(m, np.int64)
    streak = np.zeros(m, np.int64)
    for j in range(m):
        th[j], vv[j], cos_th[j], sin_th[j], idx[j] = theta[j], v[j], cos_theta[j], \
            sin_theta[j], j
    v_max = -np.inf
    for _ in range(max_impacts):
        if m == 0:
            break
        _impact(th, vv, cos_th, sin_th, m, c, max_steps, hop, pos, S, D0, C, SN, V, SH, CH)
        p = 0
        for j in range(m):
            t, u = S[j], V[j]
            if v_max < u < np.inf:  # finite velocities only (NaN compares False)
                v_max = u
            sticks = not hop[j] / w >= c[_MIN_HOP]
            code = _cell(t, u, cells_theta, scale_theta, cells_v, v_low, scale_v)
            row = idx[j]
            run = 0 if not visited[row, code] else streak[j] + 1
            visited[row, code] = True
            done = run >= recurrence
            if done:
                recurred[row] = True
            elif sticks:
                stuck[row] = True
            if not (done or sticks):
                idx[p], th[p], vv[p], cos_th[p], sin_th[p], streak[p] = row, t, u, C[j], \
                    SN[j], run
                p += 1
        m = p
    return v_max


def recurrence_arrays(theta, v, cos_theta, sin_theta, params: ModelParams, *,
                      min_hop_s: float, cells: tuple[int, float, int, float, float],
                      recurrence: int, max_impacts: int, visited: np.ndarray,
                      recurred: np.ndarray, stuck: np.ndarray, max_steps: int) -> float:
    """``analysis.attractors._recurrence``'s loop at compiled speed, the same bits: wrapped
    states (their cos and sin by ``trig.sincos``) followed until they recur, stick or reach
    ``max_impacts``; ``cells`` = (cells_theta, cells_theta / 2 pi, cells_v, v_low,
    cells_v / (v_high - v_low)), each computed by the tessellation's own expression;
    ``visited`` (orbits x cells, bool), ``recurred`` and ``stuck`` (bool: the orbits that
    stuck before they recurred) are filled in place. Returns
    the largest finite velocity after impact the orbits reached (-inf: none). Section 3's
    sticking rule only (``min_hop_s`` > 0; exact sticking is numpy's)."""
    cells_theta, scale_theta, cells_v, v_low, scale_v = cells
    th, vv, cos_th, sin_th = (np.ascontiguousarray(x, dtype=float)
                              for x in (theta, v, cos_theta, sin_theta))
    c = _constants(params, FixedPoint(math.nan, math.nan), 0.0, min_hop_s)
    return float(_recurrence(th, vv, cos_th, sin_th, c, max_steps, cells_theta, scale_theta,
                             cells_v, v_low, scale_v, recurrence, max_impacts, visited,
                             recurred, stuck))


def first_impact_phase(theta, v, params: ModelParams, *, max_steps: int) -> np.ndarray:
    """``impact.first_impact_phase(..., trig=trig.sincos)`` at one parameter point (flat
    arrays; for the tests that hold the two solvers to the same bits)."""
    th = np.mod(np.asarray(theta, dtype=float).ravel(), TWO_PI)
    sin_th, cos_th = sincos(th)
    return first_impact_phase_of(v, cos_th, sin_th, params, max_steps=max_steps)


def first_impact_phase_of(v, cos_theta, sin_theta, params: ModelParams, *,
                          max_steps: int) -> np.ndarray:
    """``impact.first_impact_phase(theta, v, ..., cos_theta=, sin_theta=, trig=trig.sincos)``
    of states whose cos and sin of the wrapped phase are known (``maps.PassiveMap``'s wrapped
    states), the same bits, at one parameter point: the map's step at compiled speed, for an
    iteration of a few hundred orbits over thousands of impacts (``analysis.attractors``),
    where numpy's cost is its calls. Arrays broadcast; the result has their shape."""
    vv, cos_th, sin_th = (np.ascontiguousarray(x, dtype=float) for x in
                          np.broadcast_arrays(v, cos_theta, sin_theta))
    shape = vv.shape
    vv, cos_th, sin_th = vv.ravel(), cos_th.ravel(), sin_th.ravel()
    m = vv.size
    hop, S, D0, C, SN, V, SH, CH = (np.empty(m) for _ in range(8))
    _first_impact(vv, cos_th, sin_th, m, _solver_constants(params), max_steps,
                  hop, np.empty(m, np.int64), S, D0, C, SN, V, SH, CH)
    return hop.reshape(shape)


@functools.lru_cache(maxsize=64)
def _solver_constants(params: ModelParams) -> np.ndarray:
    """``_constants`` of the solver alone (no fixed point, tolerance or hop), once per
    parameter point, shared by the calls (which only read it: a read-only array would be
    another type to numba, compiled anew)."""
    return _constants(params, FixedPoint(v_m_s=math.nan, theta_rad=math.nan), 0.0, 0.0)


def load() -> None:
    """Load (or compile) the kernel now: one call on one point (``numba_without_blas``)."""
    params = ModelParams(alpha=0.5, g=9.81, racket_amplitude=0.3, racket_period=0.92)
    with numba_without_blas():
        classify_arrays(np.array([1.0]), np.array([5.0]), params, params.fixed_point(), 1,
                        1e-3, 1e-3, 10)


@contextlib.contextmanager
def numba_without_blas() -> Iterator[None]:
    """numba's first dispatch in a process sets up its typing registries, and with them
    looks for BLAS in ``scipy.linalg`` (for np.dot and np.linalg in compiled code), whose
    import is about 0.08 s of a basin's start-up (a 1000^2 grid's whole command takes about
    1.8 s). No kernel here calls BLAS: inside this block ``scipy.linalg`` cannot be
    imported (numba then records that it has no BLAS, and would refuse np.dot in compiled
    code with a clear error); afterwards it imports as usual. Nothing is blocked where
    scipy.linalg is imported already or numba's registries are set up."""
    if "scipy.linalg" in sys.modules:
        yield
        return
    sys.modules["scipy.linalg"] = None  # type: ignore[assignment]  # import -> ImportError
    try:
        yield
    finally:
        if sys.modules.get("scipy.linalg", 0) is None:
            del sys.modules["scipy.linalg"]
