"""data/peaks.py against scipy.signal.find_peaks (the reference it replaces): the same
peaks, index for index, and the same prominences."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import find_peaks, peak_prominences

from bounce_cli.data.peaks import local_maxima, peaks_by_prominence, prominences

signals = st.lists(st.integers(-6, 6), min_size=0, max_size=80).map(
    lambda v: np.array(v, dtype=float))


@settings(max_examples=400, deadline=None)
@given(signals, st.floats(0.0, 8.0))
def test_quantised_signals_with_plateaus(x, level):
    """Small integer signals: plateaus, equal neighbours and ties everywhere."""
    expected, _ = find_peaks(x, prominence=level)
    np.testing.assert_array_equal(peaks_by_prominence(x, level), expected)
    maxima, _ = find_peaks(x)
    np.testing.assert_array_equal(local_maxima(x), maxima)
    if len(maxima):
        np.testing.assert_allclose(prominences(x, maxima), peak_prominences(x, maxima)[0],
                                   rtol=0, atol=0)


@pytest.mark.parametrize("seed", range(6))
def test_a_noisy_racket(seed):
    """A sampled racket (0.55 s period, 0.07 m) with noise, offsets and a drift, at 200 Hz:
    hundreds of small noise maxima, a few prominent ones."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 20, 1 / 200)
    x = (0.07 * np.sin(2 * np.pi * t / 0.55) + 0.01 * np.sin(0.3 * t) + 1.2
         + rng.normal(0, 0.002 * (1 + seed), t.size))
    if seed % 2:
        x = np.round(x, 3)  # a vendor's mm resolution
    for level in (0.0, 0.001, 0.028, 0.2):
        expected, props = find_peaks(x, prominence=level)
        np.testing.assert_array_equal(peaks_by_prominence(x, level), expected)
        np.testing.assert_allclose(prominences(x, expected), props["prominences"], rtol=0,
                                   atol=0)


def test_short_and_flat_signals_have_no_peaks():
    for x in ([], [1.0], [1.0, 2.0], [3.0, 3.0, 3.0], [1.0, 2.0, 2.0]):
        assert peaks_by_prominence(np.array(x), 0.0).size == 0
