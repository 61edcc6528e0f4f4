"""Peaks of a sampled signal by their prominence: ``scipy.signal.find_peaks(x,
prominence=p)[0]``, index for index, without importing scipy.signal (0.6 s of every
extraction process's start: it brings scipy.stats and the signal toolbox's backends).

The definitions are scipy's: a peak is a sample, or the middle sample of a flat run, whose
neighbours on both sides are lower (never the first or last sample); its prominence is its
height above the higher of its two bases, each base the lowest sample between the peak and
the nearest higher sample on that side (or the signal's end). The range maxima and minima
these need come from sparse tables, so every peak is measured at once in O(n log n).
``tests/test_peaks.py`` holds the two equal on random, quantised and noisy signals.
"""

from __future__ import annotations

import numpy as np


def _sparse_table(x: np.ndarray, reduce) -> list[np.ndarray]:
    """Level k: ``reduce`` over x[i : i + 2**k] for every i with i + 2**k <= n."""
    levels = [x]
    width = 1
    while 2 * width <= len(x):
        previous = levels[-1]
        levels.append(reduce(previous[:-width], previous[width:]))
        width *= 2
    return levels


def _range(levels: list[np.ndarray], reduce, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``reduce`` over x[lo..hi] (inclusive, lo <= hi) for each pair, from the sparse table."""
    span = hi - lo + 1
    k = np.floor(np.log2(span)).astype(np.intp)
    k = np.where((1 << (k + 1)) <= span, k + 1, k)  # guard log2's rounding
    k = np.where((1 << k) > span, k - 1, k)
    out = np.empty(len(lo))
    for level in np.unique(k):
        at = k == level
        table = levels[level]
        out[at] = reduce(table[lo[at]], table[hi[at] - (1 << level) + 1])
    return out


def local_maxima(x: np.ndarray) -> np.ndarray:
    """Indices of the local maxima of ``x`` (finite): samples, or the middle (rounded down)
    of flat runs, whose neighbouring values on both sides are lower; not the first or last
    sample (scipy.signal's ``_local_maxima_1d``)."""
    n = len(x)
    if n < 3:
        return np.zeros(0, dtype=np.intp)
    change = np.flatnonzero(x[1:] != x[:-1]) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change - 1, [n - 1]])
    values = x[starts]
    inner = np.arange(1, len(values) - 1)
    up = (values[inner - 1] < values[inner]) & (values[inner + 1] < values[inner])
    runs = inner[up]
    return ((starts[runs] + ends[runs]) // 2).astype(np.intp)


def prominences(x: np.ndarray, peaks: np.ndarray) -> np.ndarray:
    """The prominence of each peak of ``x`` (scipy.signal.peak_prominences without a
    window)."""
    n = len(x)
    if len(peaks) == 0:
        return np.zeros(0)
    highest = _sparse_table(x, np.maximum)
    lowest = _sparse_table(x, np.minimum)
    height = x[peaks]
    # the widest stretch [left, right] around each peak with no sample above it
    left = peaks.copy()
    right = peaks.copy()
    for level in range(len(highest) - 1, -1, -1):
        width = 1 << level
        table = highest[level]
        step = left - width
        ok = step >= 0
        ok[ok] = table[step[ok]] <= height[ok]  # max of x[left - width .. left - 1]
        left = np.where(ok, step, left)
        step = right + 1
        ok = right + width <= n - 1
        ok[ok] = table[step[ok]] <= height[ok]  # max of x[right + 1 .. right + width]
        right = np.where(ok, right + width, right)
    left_base = _range(lowest, np.minimum, left, peaks)
    right_base = _range(lowest, np.minimum, peaks, right)
    return height - np.maximum(left_base, right_base)


def peaks_by_prominence(x, prominence: float) -> np.ndarray:
    """Indices of the peaks of ``x`` whose prominence is at least ``prominence``: what
    ``scipy.signal.find_peaks(x, prominence=prominence)[0]`` returns.

    Parameters
    ----------
    x : (n,) array
        The signal, every sample finite.
    prominence : float
        The least prominence kept.

    Returns
    -------
    (m,) int array
        The peaks' indices, ascending.
    """
    x = np.asarray(x, dtype=float)
    peaks = local_maxima(x)
    return peaks[prominences(x, peaks) >= prominence]
