"""Root finding helpers shared by the engine's inverse problems (which parameter would give a
printed number)."""

from __future__ import annotations

import math
from typing import Callable

import numpy as np


def nearest_root(f: Callable[[float], float], low: float, high: float, near: float,
                 points: int = 200) -> float:
    """The root of ``f`` in [low, high] nearest to ``near``, or NaN when there is none.

    ``f`` is sampled on ``points`` equally spaced values; every sign change between two finite
    neighbouring samples is refined with ``scipy.optimize.brentq``. Where ``f`` is NaN (outside
    its domain) no root is looked for. A root between two samples of equal sign (an even
    number of roots inside one interval) is not found: ``points`` sets that resolution.
    """
    from scipy.optimize import brentq  # (imported here: a fifth of a second, rarely needed)

    grid = np.linspace(low, high, points)
    values = np.array([f(x) for x in grid])
    roots = [brentq(f, grid[i], grid[i + 1]) for i in range(points - 1)
             if np.isfinite(values[i]) and np.isfinite(values[i + 1])
             and values[i] * values[i + 1] < 0]
    return min(roots, key=lambda r: abs(r - near)) if roots else math.nan
