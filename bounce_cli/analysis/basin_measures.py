"""How fragmented a basin is: basin entropy, boundary basin entropy and the uncertainty
exponent of a grid of outcomes (the atlas over parameters; not in the paper, whose Fig. 4
shows one basin and calls its structure "complicated" for high initial velocities).

* Basin entropy (Daza, Wagemakers, Georgeot, Guery-Odelin & Sanjuan 2016, Sci. Rep. 6,
  31416): cover the grid with boxes of ``box`` x ``box`` cells; in box i the fraction of
  cells with outcome j is p_ij and its Gibbs entropy S_i = sum_j p_ij ln(1/p_ij).
  ``basin_entropy`` S_b = mean of S_i over all boxes; ``boundary_basin_entropy``
  S_bb = mean over the boxes holding more than one outcome (boundary boxes). S_bb > ln 2
  is a sufficient condition for a fractal boundary. Natural logarithms throughout.
* Uncertainty exponent (McDonald, Grebogi, Ott & Yorke 1985): the fraction f(eps) of initial
  conditions whose outcome changes when one coordinate is moved by +-eps (coordinates
  normalised by the span of the grid) scales as eps^alpha; alpha = D - d with D = 2 the
  dimension of the space and d that of the boundary (alpha = 1 for a smooth boundary, < 1
  for a fractal one).
"""

from __future__ import annotations

import math

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class BasinEntropy:
    """S_b, S_bb, the number of boxes and of boundary boxes, the box size in cells, and
    the standard error of S_bb as the mean of the boundary boxes' entropies (NaN with fewer
    than two)."""

    basin_entropy: float
    boundary_basin_entropy: float
    boxes: int
    boundary_boxes: int
    box: int
    boundary_basin_entropy_se: float = math.nan


def basin_entropy(outcome: np.ndarray, box: int = 5) -> BasinEntropy:
    """Basin entropy and boundary basin entropy of a 2-D grid of outcome codes.

    Rows and columns that do not fill a whole box at the far edges are left out. A grid
    smaller than one box in either direction raises ValueError. ``boundary_basin_entropy``
    is 0 when no box holds two outcomes (a grid of one outcome).
    """
    grid = np.asarray(outcome)
    if grid.ndim != 2:
        raise ValueError("basin_entropy takes a 2-D grid of outcomes")
    if box < 1:
        raise ValueError("box must be >= 1 cell")
    nr, nc = grid.shape[0] // box, grid.shape[1] // box
    if nr == 0 or nc == 0:
        raise ValueError(f"the grid {grid.shape} is smaller than one box of {box} x {box} cells")
    cells = grid[: nr * box, : nc * box].reshape(nr, box, nc, box).swapaxes(1, 2)
    cells = cells.reshape(nr * nc, box * box)
    codes = np.unique(cells)
    counts = np.stack([(cells == c).sum(axis=1) for c in codes], axis=1)
    p = counts / float(box * box)
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where(p > 0.0, -p * np.log(p), 0.0)
    entropy = terms.sum(axis=1)
    boundary = (counts > 0).sum(axis=1) > 1
    n_boundary = int(boundary.sum())
    se = (float(np.std(entropy[boundary], ddof=1) / math.sqrt(n_boundary))
          if n_boundary >= 2 else math.nan)
    return BasinEntropy(
        basin_entropy=float(entropy.mean()),
        boundary_basin_entropy=float(entropy[boundary].mean()) if n_boundary else 0.0,
        boxes=int(entropy.size),
        boundary_boxes=n_boundary,
        box=box,
        boundary_basin_entropy_se=se,
    )


#: the uncertain points an eps needs to enter the exponent's fit (``uncertainty_exponent``):
#: their count's relative error is then at most about 1 / sqrt(10), a third
MIN_UNCERTAIN_POINTS = 10


@dataclass(frozen=True)
class UncertaintyExponent:
    """Fit of f(eps) ~ eps^alpha: the exponent with its standard error, and the data."""

    alpha: float
    alpha_se: float
    eps: np.ndarray
    uncertain_fraction: np.ndarray
    samples: int


def uncertainty_exponent(
    classify: Callable[[np.ndarray, np.ndarray], np.ndarray],
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    eps: np.ndarray,
    samples: int,
    rng: np.random.Generator,
) -> UncertaintyExponent:
    """Uncertainty exponent of the outcome map ``classify(x, y) -> codes`` over a rectangle.

    For each eps (a fraction of each span), ``samples`` points drawn uniformly are compared
    with their four neighbours at +-eps (in x and in y, neighbours falling outside the
    rectangle are left out); a point is uncertain when any neighbour's outcome differs.
    alpha is the least-squares slope of ln f against ln eps over the eps at which at least
    ``MIN_UNCERTAIN_POINTS`` points were uncertain (a count below it is too noisy to fit:
    200 samples of a short boundary gave slopes of -0.08 and 1.6 where the exponent lies in
    [0, 1]); NaN when fewer than two eps have that many.
    """
    eps = np.asarray(eps, dtype=float)
    if eps.ndim != 1 or eps.size < 2 or np.any(eps <= 0) or np.any(eps >= 1):
        raise ValueError("eps: give at least two values in (0, 1)")
    (x0, x1), (y0, y1) = x_range, y_range
    dx, dy = x1 - x0, y1 - y0
    fractions = np.empty(eps.size)
    counts = np.empty(eps.size, dtype=int)
    for i, e in enumerate(eps):
        x = x0 + dx * rng.random(samples)
        y = y0 + dy * rng.random(samples)
        centre = classify(x, y)
        uncertain = np.zeros(samples, dtype=bool)
        for sx, sy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nx, ny = x + sx * e * dx, y + sy * e * dy
            inside = (nx >= x0) & (nx <= x1) & (ny >= y0) & (ny <= y1)
            other = classify(nx[inside], ny[inside])
            uncertain[np.flatnonzero(inside)[other != centre[inside]]] = True
        fractions[i] = uncertain.mean()
        counts[i] = int(uncertain.sum())
    ok = counts >= MIN_UNCERTAIN_POINTS
    if ok.sum() < 2:
        return UncertaintyExponent(float("nan"), float("nan"), eps, fractions, samples)
    lx, ly = np.log(eps[ok]), np.log(fractions[ok])
    design = np.column_stack([np.ones_like(lx), lx])
    coef, *_ = np.linalg.lstsq(design, ly, rcond=None)
    resid = ly - design @ coef
    dof = lx.size - 2
    if dof > 0:
        cov = (resid @ resid / dof) * np.linalg.inv(design.T @ design)
        se = float(np.sqrt(cov[1, 1]))
    else:
        se = float("nan")
    return UncertaintyExponent(float(coef[1]), se, eps, fractions, samples)
