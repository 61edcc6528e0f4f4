"""Sine and cosine of the basin classifier's phases, written out: the same bits everywhere.

The basin's classifier (``analysis.classify``: ``bounce basin``, ``bounce sweep``; and the
wrapped steps ``bounce attractors`` follows its starts with) takes
the sine and cosine of half the elapsed phase at every evaluation of the gap (``impact``) and
those of every new impact phase: about 75 million pairs on the Fig. 4 grid, in two routes that
must agree to the last bit (numpy, and the compiled kernel ``model.compiled``). ``sincos``
computes both from one argument reduction with FreeBSD's fdlibm kernels (``k_sin.c``,
``k_cos.c``; the reduction is ``e_rem_pio2.c``'s medium case with its three stages, each
always taken, the second stage's rounding carried into the third), in plain IEEE double
arithmetic (additions, multiplications, ``floor``, no fused multiply-add; in the compiled
kernel no branch either: the quadrant's signs are selects):

* the result is the same to the last bit whatever the CPU, the C library or numpy's SIMD
  dispatch (``np.sin`` and the C library's ``sin`` differ from one machine to the next in
  the last bit: glibc picks its code by the CPU's features, and a basin's boundary and its
  chaotic transients move with a last bit; docs/performance.md, "On other CPUs");
* the compiled kernel repeats these expressions in the same order, so it gives the numpy
  route's bits, and LLVM vectorises its loops (no call into the C library): about 2 ns for
  both functions against about 24 ns for ``math.sin`` and ``math.cos``;
* accuracy: below 0.76 ulp, 0.25 ulp on average, against 120-bit mpmath on random
  arguments from 1e-6 to 1e5, and at most 0.5 ulp at the doubles nearest to n pi/2 for n up
  to 2^19, where the reduction cancels most (``tests/engine/test_trig.py``; with two stages
  those reached 1.06 ulp).

Everything else in the map (orbits, bifurcation diagrams, the data side's model) keeps
numpy's functions (``numpy_sincos``): one route, and on a few values numpy's are faster.
The classifier's launch test on the grid's (unwrapped) theta0 (``can_fly``) takes numpy's
``cos`` and ``sin`` in the numpy route and the C library's in the compiled one, which numpy
calls for float64: the one place where the routes' agreement rests on the C library.

The reduction x = n pi/2 + (y0 + y1) holds for |x| <= ``REDUCTION_LIMIT`` (2^19 pi/2, about
8.2e5 rad: n times each 33-bit part of pi/2 stays exact); beyond it, and for
inf and NaN, both functions give NaN. The map's arguments are wrapped phases (below 2 pi)
and half the phase of one flight: 8.2e5 rad is a flight of 260,000 racket cycles.
"""

from __future__ import annotations

import math

import numpy as np

#: |x| above which ``sincos`` gives NaN (module docstring)
REDUCTION_LIMIT = 2.0**19 * (math.pi / 2.0)

# e_rem_pio2.c: 2/pi; pi/2 as 33 + 33 + 33 + 53 bits
INV_PIO2 = 6.36619772367581382433e-01
PIO2_1 = 1.57079632673412561417e00
PIO2_2 = 6.07710050630396597660e-11
PIO2_3 = 2.02226624871116645580e-21
PIO2_3T = 8.47842766036889956997e-32
#: 1.5 * 2^52: (x + ROUND_SHIFT) - ROUND_SHIFT rounds |x| < 2^51 to the nearest integer
ROUND_SHIFT = 6755399441055744.0
# k_sin.c and k_cos.c: the minimax polynomials on [-pi/4, pi/4]
S1, S2, S3, S4, S5, S6 = (-1.66666666666666324348e-01, 8.33333333332248946124e-03,
                          -1.98412698298579493134e-04, 2.75573137070700676789e-06,
                          -2.50507602534068634195e-08, 1.58969099521155010221e-10)
C1, C2, C3, C4, C5, C6 = (4.16666666666666019037e-02, -1.38888888888741095749e-03,
                          2.48015872894767294178e-05, -2.75573143513906633035e-07,
                          2.08757232129817482790e-09, -1.13596475577881948265e-11)


def numpy_sincos(x) -> tuple[np.ndarray, np.ndarray]:
    """(np.sin x, np.cos x): the map's sine and cosine outside the basin's classifier (one
    route only, where numpy's functions are the fastest: about 0.6 us for one value against
    ``sincos``'s 3 us, 2 us for a hundred against its 30 us)."""
    x = np.asarray(x, dtype=float)
    return np.sin(x), np.cos(x)


def sincos(x) -> tuple[np.ndarray, np.ndarray]:
    """(sin x, cos x) of an array (or a float) to within 0.76 ulp (module docstring), the
    same bits everywhere.

    Parameters
    ----------
    x : array_like
        Angles (rad).

    Returns
    -------
    tuple of numpy.ndarray
        sin x and cos x (float arrays of x's shape); NaN where |x| > ``REDUCTION_LIMIT`` or
        x is not finite (module docstring).

    Notes
    -----
    A few values (an orbit's single state) take Python's float arithmetic, an array numpy's:
    the same IEEE operations in the same order, so the same bits, without numpy's per-call
    overhead on one value (about 3 us against 30 us); large arrays go in chunks of 4096
    (about 24 ns a value, against 19 ns for ``np.sin`` and ``np.cos``).
    """
    x = np.asarray(x, dtype=float)
    if x.size <= _FEW:
        pairs = [sincos_of_float(float(xi)) for xi in x.flat]
        return (np.array([p[0] for p in pairs]).reshape(x.shape),
                np.array([p[1] for p in pairs]).reshape(x.shape))
    if x.size <= _CHUNK:
        return _sincos_array(x)
    flat = x.ravel()
    sin_x, cos_x = np.empty(flat.size), np.empty(flat.size)
    for at in range(0, flat.size, _CHUNK):
        sin_x[at:at + _CHUNK], cos_x[at:at + _CHUNK] = _sincos_array(flat[at:at + _CHUNK])
    return sin_x.reshape(x.shape), cos_x.reshape(x.shape)


def _sincos_array(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``sincos`` of an array, in numpy's operations (some fifty, most in place)."""
    outside = ~(np.abs(x) <= REDUCTION_LIMIT)
    if outside.any():  # computed at 0 there (no overflow warnings), then NaN
        x = np.where(outside, 0.0, x)
    # x = n pi/2 + (y0 + y1), |y0| <= pi/4 (e_rem_pio2.c, medium case, three stages)
    n = x * INV_PIO2
    n += ROUND_SHIFT
    n -= ROUND_SHIFT
    t = n * PIO2_1
    np.subtract(x, t, out=t)
    w = n * PIO2_2
    r = t - w
    t -= r
    t -= w  # d2 = (t - r) - w: the rounding of r = t - w
    d2 = t
    w = n * PIO2_3
    t = r - w
    r -= t
    r -= w  # d3 = (r - t) - w
    r += d2
    w = n * PIO2_3T
    w -= r  # w = n PIO2_3T - (d3 + d2)
    r = t
    y0 = r - w
    r -= y0
    r -= w
    y1 = r  # (r - y0) - w
    # k_sin.c (with the tail y1) and k_cos.c
    z = y0 * y0
    zz = z * z
    v = z * y0
    poly = z * S6  # S2 + z (S3 + z S4) + (z zz) (S5 + z S6)
    poly += S5
    poly *= z * zz
    part = z * S4
    part += S3
    part *= z
    part += S2
    part += poly
    poly = part
    sin_y = y1 * 0.5
    sin_y -= np.multiply(v, poly, out=part)
    sin_y *= z
    sin_y -= y1
    sin_y -= np.multiply(v, S1, out=part)
    np.subtract(y0, sin_y, out=sin_y)  # y0 - ((z (y1 / 2 - v poly) - y1) - v S1)
    poly = z * C6  # z (C1 + z (C2 + z C3)) + (zz zz) (C4 + z (C5 + z C6))
    poly += C5
    poly *= z
    poly += C4
    poly *= zz * zz
    part = z * C3
    part += C2
    part *= z
    part += C1
    part *= z
    poly += part
    half_z = np.multiply(z, 0.5, out=zz)
    one_minus = np.subtract(1.0, half_z, out=v)
    cos_y = np.subtract(1.0, one_minus, out=d2)  # (t holds y1)
    cos_y -= half_z
    poly *= z
    poly -= np.multiply(y0, y1, out=part)
    cos_y += poly
    cos_y += one_minus  # one_minus + (((1 - one_minus) - half_z) + (z poly - y0 y1))
    # the quadrant n mod 4: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s)
    quadrant = n.astype(np.int64) & 3
    odd = (quadrant & 1).astype(bool)
    sin_x = np.where(odd, cos_y, sin_y)
    cos_x = np.where(odd, sin_y, cos_y)
    sin_x *= _SIN_SIGN[quadrant]
    cos_x *= _COS_SIGN[quadrant]
    if outside.any():
        sin_x[outside] = np.nan
        cos_x[outside] = np.nan
    return sin_x, cos_x


#: arrays up to this size take ``sincos_of_float`` value by value
_FEW = 8
#: larger arrays go through in chunks of this size: their temporaries (32 kB) stay in the
#: cache and in malloc's pool (at 32768 values a call would take 3 times as long)
_CHUNK = 4096
#: the signs of sin and cos by quadrant (a multiplication by -1 is an exact negation)
_SIN_SIGN = np.array([1.0, 1.0, -1.0, -1.0])
_COS_SIGN = np.array([1.0, -1.0, -1.0, 1.0])


def sincos_of_float(x: float) -> tuple[float, float]:
    """``sincos`` of one float: the same operations in the same order, written with selects
    and no branch, so that ``model.compiled`` inlines this very function into loops that LLVM
    vectorises (Python's floats and numba's doubles give the same bits)."""
    inside = abs(x) <= REDUCTION_LIMIT
    x = x if inside else 0.0  # computed at 0 there, then NaN (as the array path)
    n = (x * INV_PIO2 + ROUND_SHIFT) - ROUND_SHIFT
    t = x - n * PIO2_1
    w = n * PIO2_2
    r = t - w
    d2 = (t - r) - w
    t = r
    w = n * PIO2_3
    r = t - w
    w = n * PIO2_3T - (((t - r) - w) + d2)
    y0 = r - w
    y1 = (r - y0) - w
    z = y0 * y0
    zz = z * z
    poly = S2 + z * (S3 + z * S4) + z * zz * (S5 + z * S6)
    v = z * y0
    sin_y = y0 - ((z * (0.5 * y1 - v * poly) - y1) - v * S1)
    poly = z * (C1 + z * (C2 + z * C3)) + zz * zz * (C4 + z * (C5 + z * C6))
    half_z = 0.5 * z
    one_minus = 1.0 - half_z
    cos_y = one_minus + (((1.0 - one_minus) - half_z) + (z * poly - y0 * y1))
    # the quadrant n mod 4: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s)
    quadrant = n - 4.0 * math.floor(n * 0.25)
    odd = (quadrant == 1.0) | (quadrant == 3.0)
    sin_x = cos_y if odd else sin_y
    cos_x = sin_y if odd else cos_y
    sin_x = -sin_x if quadrant >= 2.0 else sin_x
    cos_x = -cos_x if (quadrant == 1.0) | (quadrant == 2.0) else cos_x
    return (sin_x if inside else math.nan), (cos_x if inside else math.nan)
