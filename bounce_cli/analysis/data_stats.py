"""Statistics of a lab's impacts held against the model (sections 5-7), and a synthetic lab.

Everything here works per trial: a trial is one array per quantity, statistics never pair
impacts of two trials, and each trial's mean is removed before correlations (the data's
stationary state is not known; the trial mean estimates it).

The synthetic lab (:func:`simulate_impacts`) iterates the stochastic map of eqs. 16-18 per
trial with a coefficient of restitution that may change at chosen impacts (section 7's
perturbations), so that every data analysis can be tested against a known truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import NoPerturbedImpactError
from ..model.impact import next_impact_phase
from ..model.linear import jacobian
from ..model.maps import velocity_after_impact
from ..model.params import (
    MIN_HOP_S,
    ModelError,
    ModelParams,
    circular_mean,
    phase_difference,
    wrap_phase,
)
from ..model.perturbation import perturbed_impact, relaxed_from
from .stochastic import (
    PAIR_NAMES,
    paper_noise_covariance,
    sample_correlations,
    stationary_covariance,
)


# -- a synthetic lab -------------------------------------------------------------------------
@dataclass(frozen=True)
class SimulatedImpacts:
    """Impacts of several trials, arrays of shape (trials, bounces).

    theta: wrapped phase of impact (rad), v: velocity after impact (m/s), t: time of impact
    (s, from the trial's start), hop: time to the next impact (s; NaN for the last),
    alpha: coefficient of restitution of each impact, perturbed: alpha differs from alpha_0.
    lost: trials in which the ball stuck to the racket (rows NaN from then on).
    """

    theta: np.ndarray
    v: np.ndarray
    t: np.ndarray
    hop: np.ndarray
    alpha: np.ndarray
    perturbed: np.ndarray
    lost: np.ndarray


def simulate_impacts(
    params: ModelParams,
    q_v: float,
    q_theta: float,
    n_trials: int,
    n_bounces: int,
    seed: int | np.random.SeedSequence,
    *,
    alpha: np.ndarray | None = None,
    burn_in: int = 20,
    min_hop_s: float = MIN_HOP_S,
) -> SimulatedImpacts:
    """Iterate eqs. 16-18 (cos(theta_{k+1}) in eq. 16, as printed and as ``map_step``) for
    ``n_trials`` independent trials of ``n_bounces`` impacts after ``burn_in``, all trials at
    once. Trial i draws its noise from its own ``default_rng(SeedSequence(seed).spawn(...)[i])``.

    ``alpha``: (n_trials, n_bounces) coefficient of restitution of each recorded impact
    (default: params.alpha everywhere); impact j's alpha is used in the velocity map of that
    impact (section 7: the perturbed impact k = 0 leaves with v_0 of alpha_p).
    """
    seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    rngs = [np.random.default_rng(s) for s in seq.spawn(n_trials)]
    alpha_0 = params.alpha
    alphas = np.full((n_trials, n_bounces), alpha_0) if alpha is None else np.asarray(alpha, float)
    if alphas.shape != (n_trials, n_bounces):
        raise ModelError(f"alpha must have shape ({n_trials}, {n_bounces})")
    fp = params.fixed_point()
    w = params.omega
    total = burn_in + n_bounces
    noise = np.stack([rng.standard_normal((total, 2)) for rng in rngs], axis=1)  # (total, T, 2)
    theta = np.full(n_trials, fp.theta_rad)  # unwrapped
    v = np.full(n_trials, fp.v_m_s)
    out_theta = np.full((n_trials, n_bounces), np.nan)
    out_v = np.full_like(out_theta, np.nan)
    out_t = np.full_like(out_theta, np.nan)
    lost = np.zeros(n_trials, dtype=bool)
    start = np.full(n_trials, np.nan)
    for step in range(total):
        j = step - burn_in
        a = alphas[:, j] if j >= 0 else alpha_0
        hop = next_impact_phase(theta, v, params)
        theta_next = theta + hop + q_theta * noise[step, :, 1]
        v_next = (velocity_after_impact(theta_next, v, hop, params, alpha=a)
                  + q_v * noise[step, :, 0])
        bad = ~(hop >= min_hop_s * w) | ~np.isfinite(v_next)
        lost |= bad
        theta = np.where(lost, fp.theta_rad + 2 * math.pi * (step + 1), theta_next)
        v = np.where(lost, fp.v_m_s, v_next)
        if j == 0:
            start = theta.copy()
        if j >= 0:
            out_theta[:, j] = np.where(lost, np.nan, theta)
            out_v[:, j] = np.where(lost, np.nan, v)
    out_t = (out_theta - start[:, None]) / w
    hop_s = np.full_like(out_t, np.nan)
    hop_s[:, :-1] = np.diff(out_t, axis=1)
    return SimulatedImpacts(
        theta=wrap_phase(out_theta), v=out_v, t=out_t, hop=hop_s, alpha=alphas,
        perturbed=~np.isclose(alphas, alpha_0), lost=lost,
    )


def perturbation_schedule(n_trials: int, n_bounces: int, every: int, alpha_0: float,
                          ranges: Sequence[tuple[float, float]], seed: int | np.random.SeedSequence,
                          first: int | None = None) -> np.ndarray:
    """Section 7's design: every ``every``-th impact (from ``first``, default ``every``) gets
    an alpha_p drawn uniformly from one of ``ranges`` chosen at random (e.g. (0.3, 0.4) and
    (0.6, 0.7)); all other impacts alpha_0. Returns (n_trials, n_bounces)."""
    rng = np.random.default_rng(seed)
    alpha = np.full((n_trials, n_bounces), float(alpha_0))
    idx = np.flatnonzero(perturbed_impact(np.arange(n_bounces), every, first))
    which = rng.integers(0, len(ranges), size=(n_trials, len(idx)))
    lows = np.array([r[0] for r in ranges])[which]
    highs = np.array([r[1] for r in ranges])[which]
    alpha[:, idx] = lows + (highs - lows) * rng.random((n_trials, len(idx)))
    return alpha


# -- correlation functions per trial (Fig. 8) -----------------------------------------------
def trial_correlations(v_trials: Sequence[np.ndarray], theta_trials: Sequence[np.ndarray],
                       max_lag: int) -> dict[str, np.ndarray]:
    """The four correlation functions of each trial, pair -> (n_trials, max_lag + 1), with the
    model's estimator (``sample_correlations``: the trial's own mean removed, covariance at lag
    l = sum_k x_{k+l} y_k / N, normalised by the lag-0 SDs). Trials may differ in length; no
    lag pair crosses a trial boundary."""
    out: dict[str, list[np.ndarray]] = {name: [] for name in PAIR_NAMES}
    for i, (v, th) in enumerate(zip(v_trials, theta_trials)):
        if len(v) <= max_lag + 1:
            raise ModelError(f"trial {i}: {len(v)} bounces, fewer than max_lag + 2 = {max_lag + 2}")
        corr = sample_correlations(np.asarray(v, float), np.asarray(th, float), max_lag)
        for name in PAIR_NAMES:
            out[name].append(corr[name])
    return {name: np.stack(rows) for name, rows in out.items()}


# -- noise strengths (section 6) ------------------------------------------------------------
def noise_from_sds(jac: np.ndarray, sd_v: float, sd_theta: float) -> tuple[float, float]:
    """The (q_v, q_theta) for which eq. 19 with J and diagonal noise diag(q_v^2, q_theta^2)
    has stationary SDs sd_v (m/s) and sd_theta (rad): the paper's own route (section 6,
    "adjusted to get an agreement between observed and theoretical standard deviations"). R(0)
    is linear in (q_v^2, q_theta^2), so it is a 2x2 linear solve; NaN where a solution would
    need a negative variance."""
    unit_v = stationary_covariance(jac, np.diag([1.0, 0.0]))
    unit_t = stationary_covariance(jac, np.diag([0.0, 1.0]))
    a = np.array([[unit_v[0, 0], unit_t[0, 0]], [unit_v[1, 1], unit_t[1, 1]]])
    q2 = np.linalg.solve(a, np.array([sd_v**2, sd_theta**2]))
    return tuple(math.sqrt(x) if x > 0 else math.nan for x in q2)  # type: ignore[return-value]


# -- ball amplitude (section 5, Fig. 6) -----------------------------------------------------
def apex_sd_eq19(params: ModelParams, q_v: float, q_theta: float,
                 noise_cov: np.ndarray | None = None) -> float:
    """SD of the ball apex height (m) that eq. 19 predicts: the gradient of apex_height at the
    fixed point, (v~/g, a_r cos theta~), applied to R(0) of eq. 19 with diagonal noise
    diag(q_v^2, q_theta^2) (or ``noise_cov``, e.g. ``map_noise_covariance``)."""
    fp = params.fixed_point()
    if noise_cov is None:
        noise_cov = paper_noise_covariance(q_v, q_theta)
    cov = stationary_covariance(jacobian(params), noise_cov)
    grad = np.array([fp.v_m_s / params.g, params.racket_amplitude * math.cos(fp.theta_rad)])
    return float(math.sqrt(grad @ cov @ grad))


# -- perturbations (Figs. 9, 11) -------------------------------------------------------------
@dataclass(frozen=True)
class AlignedWindows:
    """Post-perturbation windows, one row per perturbation, columns k = 0..n_after.

    values: (n_windows, n_after + 1) of the aligned quantity minus its baseline, NaN where
    the window was cut (next perturbation or end of trial); trial and start identify each
    window; alpha_p is the perturbed impact's alpha.
    """

    values: np.ndarray
    trial: np.ndarray
    start: np.ndarray
    alpha_p: np.ndarray


def perturbation_windows(perturbed: np.ndarray, n_after: int,
                         k: np.ndarray | None = None) -> list[tuple[int, int]]:
    """(start, stop) of each window in one trial: from a perturbed impact k = 0 up to
    ``n_after`` impacts later, cut before the next perturbed impact, at the trial's end and,
    given the impact indices ``k``, at a gap in k (an impact the table lacks), so no window
    holds the response to another perturbation, another trial's impacts or a missing bounce."""
    idx = np.flatnonzero(np.asarray(perturbed, bool))
    n = len(perturbed)
    gaps = (np.flatnonzero(np.diff(np.asarray(k)) != 1) + 1 if k is not None
            else np.array([], dtype=int))
    windows = []
    for i, start in enumerate(idx):
        stop = min(start + n_after + 1, n)
        if i + 1 < len(idx):
            stop = min(stop, idx[i + 1])
        later = gaps[gaps > start]
        if len(later):
            stop = min(stop, int(later[0]))
        windows.append((int(start), int(stop)))
    return windows


def settled_mask(perturbed: np.ndarray, settle: int) -> np.ndarray:
    """Impacts of the stationary state for the steady-state statistics (correlations,
    per-trial SDs): every impact but the perturbed ones and the ``settle`` impacts after each
    (the relaxation is not the stationary state)."""
    keep = np.ones(len(perturbed), bool)
    for i in np.flatnonzero(np.asarray(perturbed, bool)):
        keep[i:i + settle + 1] = False
    return keep


def baseline_mask(perturbed: np.ndarray, settle: int) -> np.ndarray:
    """Impacts that describe the unperturbed steady state: not perturbed, and at least
    ``settle`` impacts after the last perturbation (before the first, all count)."""
    perturbed = np.asarray(perturbed, bool)
    since = np.full(len(perturbed), np.iinfo(np.int64).max // 2)
    last = None
    for k, p in enumerate(perturbed):
        if p:
            last = k
        if last is not None:
            since[k] = k - last
    return ~perturbed & (since >= settle)


def align(values_trials: Sequence[np.ndarray], perturbed_trials: Sequence[np.ndarray],
          alpha_trials: Sequence[np.ndarray], n_after: int, settle: int,
          phase: bool = False, k_trials: Sequence[np.ndarray] | None = None,
          labels: Sequence | None = None) -> AlignedWindows:
    """Align one quantity on the perturbed impacts of every trial: the one alignment of the
    data side (``bounce impulse --data``, and ``bounce control --data`` through
    ``analysis.control_design.align_perturbations``).

    Baseline per trial: the mean over :func:`baseline_mask` impacts (for a phase, the
    circular mean, and deviations wrapped to [-pi, pi)). Windows from
    :func:`perturbation_windows` (cut at gaps in the trials' impact indices ``k_trials`` when
    given). Raises NoPerturbedImpactError (a ModelError) when there is no perturbed impact,
    ModelError when a trial has no baseline impact (named by its ``labels`` entry, else by
    its position)."""
    rows, trials, starts, alphas = [], [], [], []
    ks = k_trials if k_trials is not None else [None] * len(values_trials)
    for i, (x, p, a, kk) in enumerate(zip(values_trials, perturbed_trials, alpha_trials, ks)):
        x = np.asarray(x, float)
        p = np.asarray(p, bool)
        if not p.any():
            continue
        base = baseline_mask(p, settle) & np.isfinite(x)
        if not base.any():
            name = labels[i] if labels is not None else i
            raise ModelError(f"trial {name}: no unperturbed impact {settle} or more impacts "
                             "after a perturbation to take the baseline from (lower "
                             "data_analysis.settle_after_perturbation, or leave the trial out)")
        if phase:
            ref = circular_mean(x[base])
            dev = phase_difference(x, ref)
        else:
            dev = x - x[base].mean()
        for start, stop in perturbation_windows(p, n_after, kk):
            row = np.full(n_after + 1, np.nan)
            row[: stop - start] = dev[start:stop]
            rows.append(row)
            trials.append(i)
            starts.append(start)
            alphas.append(float(np.asarray(a, float)[start]))
    if not rows:
        raise NoPerturbedImpactError("no perturbed impact in the data")
    return AlignedWindows(np.array(rows), np.array(trials), np.array(starts), np.array(alphas))


@dataclass(frozen=True)
class StillRelaxing:
    """A quantity whose response to the perturbations has not settled at the first impact an
    analysis counts as steady state: after the kicks of one ``direction`` (``up``: the ball
    left the perturbed impact faster, ``down``: slower), ``mean`` the response there, its
    standard error ``se`` over ``windows`` perturbations."""

    quantity: str
    first_settled: int
    direction: str
    mean: float
    se: float
    windows: int

    @property
    def z(self) -> float:
        return abs(self.mean) / self.se if self.se > 0 else math.inf


def still_relaxing(quantities: dict[str, tuple[Sequence[np.ndarray], bool]],
                   perturbed_trials: Sequence[np.ndarray], first_settled: int, *,
                   k_trials: Sequence[np.ndarray] | None = None, z: float = 3.5,
                   min_windows: int = 5, rounding: float = 1e-6) -> list[StillRelaxing]:
    """Whether the steady state an analysis takes after each perturbation still holds its
    relaxation: the quantities' mean response at impact ``first_settled`` after a perturbed
    one (the first impact the analysis counts as steady: ``settled_mask``'s ``settle`` + 1,
    ``baseline_mask``'s ``settle``), against the mean of the impacts from there on.

    Each trial's values are aligned on its perturbations (``align``, its baseline the impacts
    ``first_settled`` or more after the last perturbation), and the windows are split by the
    direction of their kick: the sign of the velocity's response at k = 0 (the first
    quantity's, which must be v after impact: a larger alpha_p sends the ball off faster; no
    alpha column is needed). Each direction is tested on its own: a few impacts after a kick
    the model's response has the same sign whichever way the kick went, so windows signed by
    their kick and pooled cancelled (a session without noise, 20 deg off at impact 3, passed).
    A quantity is still relaxing where, after the kicks of one direction, its mean at
    ``first_settled`` lies beyond ``z`` standard errors of 0 over at least ``min_windows``
    windows that reach it, and beyond ``rounding`` times its largest mean response before it
    (a deterministic session relaxes to rounding, not to 0). The passive model's ball relaxes
    slowly (|lambda| 0.5, and slower after a kick up: section 7): five impacts after a kick of
    alpha by 0.1 it was still a third of the kick off, and a session without noise gave a VAR
    radius of 0.454 against the model's 0.500 with acf's default settle of 4.

    Parameters
    ----------
    quantities : dict
        name -> (one array per trial, is_phase); the first is v after impact.
    perturbed_trials : sequence of ndarray
        Each trial's perturbed impacts (bool).
    first_settled : int
        The first impact after a perturbation the analysis counts as steady state (>= 1).
    k_trials : sequence of ndarray, optional
        Each trial's impact indices (windows are cut at a gap).
    z, min_windows, rounding : float, int, float
        The criterion above (z per test: two directions for each quantity).

    Returns
    -------
    list of StillRelaxing
        Per quantity still relaxing (in the order given), the direction that shows it most.
    """
    if first_settled < 1 or not any(np.asarray(p, bool).any() for p in perturbed_trials):
        return []
    zeros = [np.zeros(len(p)) for p in perturbed_trials]
    kicks = None
    out = []
    for name, (values, is_phase) in quantities.items():
        try:
            w = align(values, perturbed_trials, zeros, first_settled, first_settled,
                      phase=is_phase, k_trials=k_trials)
        except ModelError:  # a trial without a steady impact: nothing to compare with
            return []
        if kicks is None:
            kicks = np.sign(w.values[:, 0])
        found = []
        for direction, sign in (("up", 1.0), ("down", -1.0)):
            rows = w.values[kicks == sign]
            at = rows[:, first_settled]
            at = at[np.isfinite(at)]
            if len(at) < max(min_windows, 2):
                continue
            with np.errstate(invalid="ignore"):
                before = np.nanmean(rows[:, :first_settled], axis=0)
            mean, se = float(at.mean()), float(at.std(ddof=1) / math.sqrt(len(at)))
            if abs(mean) > z * se and abs(mean) > rounding * float(np.nanmax(np.abs(before))):
                found.append(StillRelaxing(name, first_settled, direction, mean, se, len(at)))
        if found:
            out.append(max(found, key=lambda f: f.z))
    return out


def relaxation_impact(means: Sequence[np.ndarray], ses: Sequence[np.ndarray],
                     tolerances: Sequence[float], z: float = 2.0) -> int:
    """Impacts-to-relax, one criterion for data and model: the first k from which, at every
    later k and for every quantity (e.g. v and theta), the |mean deviation| is within
    max(tolerance, z SE) -- inside the tolerance, or not distinguishable from zero at the
    data's sample size (the model's SE is 0, so for it this is ``relaxation_impacts``). -1 when
    the last impact is outside (or NaN). Each array runs over k = 0..N."""
    inside = None
    for mean, se, tol in zip(means, ses, tolerances):
        mean = np.asarray(mean, float)
        se = np.nan_to_num(np.asarray(se, float), nan=0.0)
        ok = np.abs(mean) <= np.maximum(tol, z * se)
        inside = ok if inside is None else inside & ok
    return -1 if inside is None else relaxed_from(inside)
