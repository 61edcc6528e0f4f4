"""``model.trig.sincos``: within 0.76 ulp of 120-bit mpmath, NaN where its reduction stops,
and the compiled kernel's copy gives its bits (the basin's numpy and compiled routes agree to
the last bit only if both take the same sine and cosine)."""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest

from bounce_cli.model.trig import REDUCTION_LIMIT, sincos


def ulp_errors(x: np.ndarray, values: np.ndarray, exact) -> np.ndarray:
    """|value - exact(x)| in units of the last place of the value, exact in 120 bits."""
    with mpmath.workprec(120):
        return np.array([abs(float((exact(mpmath.mpf(float(xi))) - mpmath.mpf(float(yi)))
                                   / mpmath.mpf(float(np.spacing(abs(yi))))))
                         for xi, yi in zip(x, values)])


@pytest.mark.parametrize("low, high", [(0.0, 1e-6), (0.0, math.pi / 4), (0.0, 2 * math.pi),
                                       (-40.0, 40.0), (1e3, 1e5)])
def test_within_an_ulp_of_the_exact_values(low, high):
    x = np.random.default_rng(int(high)).uniform(low, high, 600)
    sin_x, cos_x = sincos(x)
    assert ulp_errors(x, sin_x, mpmath.sin).max() < 0.76
    assert ulp_errors(x, cos_x, mpmath.cos).max() < 0.76


def test_hard_arguments():
    """Near multiples of pi/2 (the reduction's cancellation: the doubles nearest to n pi/2
    up to n = 2^19), at zero, and tiny arguments, where sin x = x to the last bit."""
    n = np.array([1, 2, 3, 4, 7, 100, 355, 2 ** 10 + 1, 2 ** 19 - 1], dtype=float)
    near = np.concatenate([n * (math.pi / 2), np.nextafter(n * (math.pi / 2), 0),
                           np.nextafter(n * (math.pi / 2), np.inf)])
    sin_x, cos_x = sincos(near)
    assert ulp_errors(near, sin_x, mpmath.sin).max() < 0.76
    assert ulp_errors(near, cos_x, mpmath.cos).max() < 0.76
    # the doubles nearest to n pi/2 where the reduction cancels most (n up to 2^19, found by
    # an exact search): 1.06 ulp with two stages of the reduction, 0.5 with three
    hardest = np.array([413441.44719405076, 229174.47169039503, 458348.94338079006,
                        346205.081221922, 65359.26436160885, 490807.8786776798,
                        245403.9393388399])
    sin_h, cos_h = sincos(hardest)
    assert ulp_errors(hardest, sin_h, mpmath.sin).max() < 0.51
    assert ulp_errors(hardest, cos_h, mpmath.cos).max() < 0.51
    tiny = np.array([0.0, 1e-300, 5e-324, 1e-9, -1e-12])
    sin_t, cos_t = sincos(tiny)
    np.testing.assert_array_equal(sin_t, tiny)
    np.testing.assert_array_equal(cos_t, 1.0)


def test_nan_where_the_reduction_stops():
    x = np.array([REDUCTION_LIMIT, -REDUCTION_LIMIT, np.nextafter(REDUCTION_LIMIT, np.inf),
                  1e300, np.inf, -np.inf, np.nan])
    sin_x, cos_x = sincos(x)
    assert np.isfinite(sin_x[:2]).all() and np.isfinite(cos_x[:2]).all()
    assert np.isnan(sin_x[2:]).all() and np.isnan(cos_x[2:]).all()
    s, c = sincos(0.5)  # a float: 0-d arrays
    assert s.shape == () and float(s) == pytest.approx(math.sin(0.5), rel=2e-16)


def test_compiled_copy_gives_the_same_bits():
    """``model.compiled._sincos`` (inlined into loops that LLVM vectorises) against the numpy
    function, on arguments of every kind: both are the same IEEE expressions."""
    pytest.importorskip("numba")
    import numba

    from bounce_cli.model.compiled import _sincos

    @numba.njit
    def each(x, s, c):
        for j in range(x.size):
            s[j], c[j] = _sincos(x[j])

    rng = np.random.default_rng(7)
    x = np.concatenate([rng.uniform(-7, 7, 40000), rng.uniform(0, 1e5, 20000),
                        10.0 ** rng.uniform(-300, 5.9, 20000),
                        np.arange(-40, 41) * (math.pi / 4),
                        [REDUCTION_LIMIT, np.nextafter(REDUCTION_LIMIT, np.inf), np.inf,
                         -np.inf, np.nan, 0.0, -0.0]])
    s, c = np.empty_like(x), np.empty_like(x)
    each(x, s, c)
    sin_x, cos_x = sincos(x)
    np.testing.assert_array_equal(s, sin_x)
    np.testing.assert_array_equal(c, cos_x)
