"""Section 7's perturbation of the fixed point, shared by the passive and the controlled map,
the simulated lab and the data: which impacts are perturbed (the schedule), the velocity after
the perturbed impact, and the impact from which a response stays relaxed (the rule)."""

from __future__ import annotations

import numpy as np

from .params import ModelParams


def perturbed_velocity(params: ModelParams, alpha_p: float) -> float:
    """v_0 = (1 + 2 alpha_p - alpha_0) / (1 + alpha_0) v~ (section 7), alpha_0 = params.alpha.

    It is eq. 5 with alpha_p at the fixed point (theta_{k+1} = theta~ + 2 pi, v_k = v~):
    (1 + alpha_p) a_r w cos(theta~) - alpha_p v~ + g alpha_p 2 pi / w.
    """
    alpha_0 = params.alpha
    return (1.0 + 2.0 * alpha_p - alpha_0) / (1.0 + alpha_0) * params.fixed_point().v_m_s


def perturbed_impact(k, every: int, first: int | None = None):
    """Section 7's schedule: whether impact ``k`` is perturbed. Every ``every``-th impact from
    ``first`` (default ``every``: "every fifth bounce" is impacts 5, 10, ...; impact 0 is the
    unperturbed start); ``every`` <= 0: none.

    Parameters
    ----------
    k : int or array_like of int
        Impact indices (0 the first impact of a trial).
    every : int
        Impacts from one perturbation to the next (the paper's 5).
    first : int, optional
        The first perturbed impact (default ``every``).

    Returns
    -------
    bool or numpy.ndarray of bool
        ``k``'s shape.

    Examples
    --------
    >>> np.flatnonzero(perturbed_impact(np.arange(16), 5)).tolist()
    [5, 10, 15]
    >>> np.flatnonzero(perturbed_impact(np.arange(16), 5, first=4)).tolist()
    [4, 9, 14]
    """
    k = np.asarray(k)
    start = every if first is None else first
    hit = (every > 0) & (k >= start) & ((k - start) % max(every, 1) == 0)
    return bool(hit) if hit.ndim == 0 else hit


def relaxed_from(inside) -> int:
    """Section 7's impacts-to-relax rule: the first impact k from which the response is inside
    its tolerance at every later impact; -1 when the last impact is outside (a response that
    has not relaxed within the series, or NaN there).

    Parameters
    ----------
    inside : array_like of bool
        Per impact k = 0..N: whether the deviation is within the tolerance.

    Returns
    -------
    int

    Examples
    --------
    >>> relaxed_from([False, True, False, True, True]), relaxed_from([True, True])
    (3, 0)
    >>> relaxed_from([True, False])
    -1
    """
    inside = np.asarray(inside, bool)
    if not inside[-1]:
        return -1
    outside = np.flatnonzero(~inside)
    return int(outside[-1] + 1) if len(outside) else 0


def relaxation_impacts(dv, dtheta, tol_v: float, tol_theta: float) -> int:
    """First impact k from which |dv| <= tol_v and |dtheta| <= tol_theta at every later impact
    of the series (:func:`relaxed_from`); -1 when the series does not end inside the
    tolerance (or holds NaN there)."""
    return relaxed_from((np.abs(dv) <= tol_v) & (np.abs(dtheta) <= tol_theta))
