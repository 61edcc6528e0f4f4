"""Control design for the racket period controller (sections 7-8's future work): what is
computed FROM the controlled map of ``model.control`` -- its spectral radius over (K, c) and
the fastest controller, impulse responses and section 3's classification with control,
perturbation trials of the controlled stochastic map, their mean responses and the fit of
(K, c) to them (the data side's alignment, ``analysis.data_stats.align``).

The controlled map itself (controllers, the step behind the step protocol, orbits, the
3 x 3 linearisation, the continuous motion) is ``model.control``; this module only uses it.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Callable, Literal, Sequence

import numpy as np

from ..errors import NoPerturbedImpactError
from ..model.control import (
    Controller,
    ControlledMap,
    PeriodController,
    Reference,
    controlled_fixed_point,
    controlled_jacobian,
    controlled_step,
    iterate_controlled,
    jacobian_from_gradient,
    spectral_radius_3x3,
)
from ..model.linear import iterate_linear, racket_acceleration_at_impact_g
from ..model.params import ModelParams, phase_difference
from ..model.perturbation import perturbed_impact, perturbed_velocity, relaxation_impacts
from .classify import Classification, ClassifySettings, classify_states

TWO_PI = 2.0 * math.pi


def period_control_radius(params: ModelParams, gain, rate) -> np.ndarray:
    """Spectral radius of the period controller's 3 x 3 Jacobian for arrays of K and c."""
    gain, rate = np.broadcast_arrays(np.asarray(gain, float), np.asarray(rate, float))
    gradient = PeriodController(gain, rate).gradient(Reference.of(params))
    return spectral_radius_3x3(jacobian_from_gradient(params, gradient))


@dataclass(frozen=True)
class ControlledResponse:
    """Impacts k = 0..n after the perturbed impact k = 0: v (m/s), wrapped theta (rad), the
    racket period of the flight ending at impact k (s; tau_0 = tau_bar: the perturbation is
    not foreseen) and deviations from (v~, theta~, tau_bar) (dtheta wrapped to [-pi, pi))."""

    v: np.ndarray
    theta: np.ndarray
    tau: np.ndarray
    dv: np.ndarray
    dtheta: np.ndarray
    dtau: np.ndarray

    def relaxation_impacts(self, tol_v: float, tol_theta: float) -> int:
        """``model.perturbation.relaxation_impacts`` of this response (v and theta, as for
        Fig. 9)."""
        return relaxation_impacts(self.dv, self.dtheta, tol_v, tol_theta)


def controlled_impulse_response(params: ModelParams, controller: Controller, alpha_p: float,
                                n_impacts: int) -> ControlledResponse:
    """Section 7's impulse response with control: at the fixed point one impact has alpha_p,
    so the ball leaves at theta~ with v_0 = (1 + 2 alpha_p - alpha_0)/(1 + alpha_0) v~ while the
    racket still has tau_bar; from there the controlled map runs (alpha_0)."""
    v_fp, theta_fp, tau_bar = controlled_fixed_point(params, controller)
    theta, v, tau, _ = iterate_controlled(theta_fp, perturbed_velocity(params, alpha_p), tau_bar,
                                          params, controller, n_impacts)
    dtheta = phase_difference(theta, theta_fp)
    return ControlledResponse(v=v, theta=np.mod(theta_fp + dtheta, TWO_PI), tau=tau,
                              dv=v - v_fp, dtheta=dtheta, dtau=tau - tau_bar)


def classify_controlled(theta0, v0, params: ModelParams, controller: Controller,
                        settings: ClassifySettings = ClassifySettings(), *,
                        tau0: float | None = None,
                        period_tolerance_s: float | None = None,
                        kernel: Literal["auto", "numpy", "compiled"] = "numpy"
                        ) -> Classification:
    """Section 3's classification (``analysis.classify.classify_states``) of initial
    conditions (arrays broadcast) for the controlled map (``ControlledMap``); the racket
    starts with tau0 (default tau_bar) and the controller sets the first flight's period
    from (v0, theta0).

    * below_racket: v0 not above the racket's velocity at theta0 with the period tau0 the
      racket had (section 3's criterion, the same region as the passive basin's);
    * sticking: a hop shorter than ``min_hop_s``; also a ball that cannot leave
      (including at impact 0, when the controller's new period makes the racket faster than
      the ball at once) and a controller asking for a racket period <= 0 (the racket stops);
    * period1: |v - v~| < tol, |wrap(theta) - theta~| < tol and |tau - tau_bar| <
      ``period_tolerance_s`` (default: the same number as tol, in s);
    * undecided: none within ``max_iterations``.

    The loop is the passive map's (phases wrapped every impact), so a controller that
    keeps the period (K = 0) gives the passive classification exactly. ``kernel`` as for
    ``classify_states`` (default numpy: the few points of an impulse or a threshold do not
    repay loading numba; the compiled kernel gives the same codes and counts).
    """
    impact_map = ControlledMap.of(params, controller, require_fixed_point=True,
                                  period_tolerance_s=period_tolerance_s, initial_period_s=tau0)
    return classify_states(impact_map, theta0, v0, settings, kernel=kernel)


def simulate_perturbation_trials(params: ModelParams, controller: Controller, *, n_trials: int,
                                 impacts_per_trial: int, perturb_every: int = 5,
                                 alpha_p_low: tuple[float, float] = (0.3, 0.4),
                                 alpha_p_high: tuple[float, float] = (0.6, 0.7),
                                 velocity_noise_sd: float = 0.0, phase_noise_sd: float = 0.0,
                                 period_noise_sd: float = 0.0, seed: int = 0) -> dict:
    """Trials of the controlled stochastic map with section 7's perturbations: every
    ``perturb_every``-th impact has alpha_p drawn uniformly from ``alpha_p_low`` or
    ``alpha_p_high`` (each with probability 1/2), the others alpha_0. Noise per impact:
    velocity and phase as eqs. 16-18 (independent standard normals times the sd) and the
    racket period's own (sd in s, added to the controller's tau_{k+1}). Each trial starts at
    (theta~, v~, tau_bar) and draws from its own stream (``SeedSequence(seed).spawn``).

    Returns the impacts table's columns as arrays, one entry per impact k = 0..
    impacts_per_trial - 1 of each trial (a trial whose ball stops is cut there): trial, k,
    theta_rad (wrapped), v_m_s, racket_period_s (period of the flight ending at the impact),
    alpha, perturbed."""
    v_fp, theta_fp, tau_bar = controlled_fixed_point(params, controller)
    reference = Reference.of(params)
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n_trials)]
    n = impacts_per_trial
    draws = np.stack([rng.standard_normal((n, 3)) for rng in streams])  # (trial, k, 3)
    ups = np.stack([rng.random(n) < 0.5 for rng in streams])
    fracs = np.stack([rng.random(n) for rng in streams])
    k_all = np.arange(n)
    perturbed = np.broadcast_to(perturbed_impact(k_all, perturb_every), (n_trials, n))
    lo = alpha_p_low[0] + fracs * (alpha_p_low[1] - alpha_p_low[0])
    hi = alpha_p_high[0] + fracs * (alpha_p_high[1] - alpha_p_high[0])
    alpha = np.where(perturbed, np.where(ups, hi, lo), params.alpha)

    theta = np.full((n_trials, n), np.nan)
    v, tau = np.full_like(theta, np.nan), np.full_like(theta, np.nan)
    theta[:, 0], v[:, 0], tau[:, 0] = theta_fp, v_fp, tau_bar
    for k in range(1, n):
        step = controlled_step(theta[:, k - 1], v[:, k - 1], tau[:, k - 1], params, controller,
                               reference=reference, alpha=alpha[:, k],
                               velocity_noise=velocity_noise_sd * draws[:, k, 0],
                               phase_noise=phase_noise_sd * draws[:, k, 1],
                               period_noise=period_noise_sd * draws[:, k, 2])
        theta[:, k], v[:, k], tau[:, k] = step.theta, step.v, step.tau
    alive = np.cumprod(np.isfinite(v) & np.isfinite(theta), axis=1).astype(bool)
    trial = np.broadcast_to(np.arange(n_trials)[:, None], (n_trials, n))
    return {
        "trial": trial[alive], "k": np.broadcast_to(k_all, (n_trials, n))[alive],
        "theta_rad": np.mod(theta[alive], TWO_PI), "v_m_s": v[alive],
        "racket_period_s": tau[alive], "alpha": alpha[alive], "perturbed": perturbed[alive],
    }


@dataclass(frozen=True)
class MeanResponse:
    """Mean deviations at impacts j = 0..n after the perturbed impact (j = 0) of one direction
    of perturbation, with the standard errors of the means: v (m/s), theta (rad), racket
    period (s). ``n_events``: perturbations averaged. ``initial``: each event's own deviation
    at j = 0, (n_events, 3) in (m/s, rad, s), or None when only the means are known."""

    direction: str
    dv_m_s: np.ndarray
    dtheta_rad: np.ndarray
    dtau_s: np.ndarray
    se_v_m_s: np.ndarray
    se_theta_rad: np.ndarray
    se_tau_s: np.ndarray
    n_events: int
    initial: np.ndarray | None = None


def align_perturbations(trial, k, v, theta, tau, perturbed, *, alpha=None, alpha_0=None,
                        n_after: int = 4, settle: int = 0) -> dict[str, MeanResponse]:
    """Mean responses to perturbations, by direction ("decrease" / "increase"), with the data
    side's alignment (``analysis.data_stats.align``, the one ``bounce impulse --data`` uses).

    One window per perturbed impact: impacts j = 0..n_after of the same trial with
    consecutive k; only complete windows are kept (one cut by a trial's end, a gap in k or
    another perturbation at j >= 1 is dropped: the fit compares whole responses).
    Deviations are from each trial's baseline: the mean of its unperturbed impacts at least
    ``settle`` impacts after a perturbation (v, tau; the circular mean for theta). The
    direction is alpha > alpha_0 when alpha is given, else the sign of dv at j = 0.
    """
    from .data_stats import align

    trial, k = np.asarray(trial), np.asarray(k)
    v, theta, tau = (np.asarray(x, float) for x in (v, theta, tau))
    perturbed = np.asarray(perturbed, bool)
    alpha_all = np.zeros_like(v) if alpha is None else np.asarray(alpha, float)
    order = np.lexsort((k, trial))
    labels = list(dict.fromkeys(trial[order]))
    groups = [order[trial[order] == t] for t in labels]
    try:
        aligned = [align([x[g] for g in groups], [perturbed[g] for g in groups],
                         [alpha_all[g] for g in groups], n_after, settle, phase=is_phase,
                         k_trials=[k[g] for g in groups], labels=labels)
                   for x, is_phase in ((v, False), (theta, True), (tau, False))]
    except NoPerturbedImpactError:
        return {}
    values = np.stack([w.values for w in aligned], axis=1)  # (windows, 3, n_after + 1)
    complete = np.all(np.isfinite(values), axis=(1, 2))
    if alpha is not None and alpha_0 is not None:
        up = aligned[0].alpha_p > alpha_0
    else:
        up = values[:, 0, 0] > 0.0
    out = {}
    for direction, sel in (("decrease", ~up & complete), ("increase", up & complete)):
        if not sel.any():
            continue
        arr = values[sel]
        mean = arr.mean(axis=0)
        n = arr.shape[0]
        se = arr.std(axis=0, ddof=1) / math.sqrt(n) if n > 1 else np.full_like(mean, np.nan)
        out[direction] = MeanResponse(direction, mean[0], mean[1], mean[2], se[0], se[1], se[2],
                                      n_events=n, initial=arr[:, :, 0])
    return out


@dataclass(frozen=True)
class ControlFit:
    """Least-squares fit of a period controller (K, c) to mean perturbation responses.

    gain, rate: estimates; *_ci: (low, high) confidence intervals (Wald, t quantile, the
    covariance scaled by the residual variance); offsets: fitted baselines of (v m/s,
    theta rad, tau s) common to both directions (the trial means are not the fixed point);
    eigenvalues: the fitted model's 3 x 3 Jacobian's, by decreasing modulus;
    reduced_chi2: weighted residual sum of squares per degree of freedom (about 1 when the
    standard errors describe the scatter)."""

    gain: float
    rate: float
    gain_ci: tuple[float, float]
    rate_ci: tuple[float, float]
    offsets: tuple[float, float, float]
    eigenvalues: np.ndarray
    spectral_radius: float
    reduced_chi2: float
    n_residuals: int
    success: bool


def predicted_deviations(params: ModelParams, controller: Controller, y0, n_impacts: int):
    """The controlled map's deviations (dv, dtheta, dtau) at impacts 0..n from the fixed point
    (v~, theta~, tau_bar) + y0, y0 = (dv_0 m/s, dtheta_0 rad, dtau_0 s); shape (3, n + 1) or,
    for y0 of shape (3, E) (several starts), (3, n + 1, E)."""
    v_fp, theta_fp, tau_bar = controlled_fixed_point(params, controller)
    theta, v, tau, _ = iterate_controlled(theta_fp + y0[1], v_fp + y0[0], tau_bar + y0[2],
                                          params, controller, n_impacts)
    return np.stack([v - v_fp, phase_difference(theta, theta_fp), tau - tau_bar])


def fit_period_control(params: ModelParams, responses: Sequence[MeanResponse], *,
                       initial: tuple[float, float] = (0.5, 0.5),
                       gain_bounds: tuple[float, float] = (-2.0, 2.0),
                       rate_bounds: tuple[float, float] = (0.0, 2.0),
                       confidence: float = 0.95,
                       controller_of: Callable[[float, float], Controller] = PeriodController,
                       starts_from_grid: int = 3) -> ControlFit:
    """Fit K and c of the period controller to mean responses (``align_perturbations``).

    The model's mean response of a direction is the mean of the controlled map's responses
    (full, not linearised: section 7's perturbations are not small) started from each event's
    own deviation at j = 0 (``MeanResponse.initial``; from the mean deviation when only means
    are known), minus the fitted offsets, at the model's fixed point. Residuals:
    (model + offset - data) / standard error for v, theta and tau at j = 1..n of every
    direction, minimised with ``scipy.optimize.least_squares`` over (K, c, three offsets),
    from ``initial`` and the ``starts_from_grid`` best points of a coarse (K, c) grid (the cost
    has local minima); the lowest minimum wins.

    Measured on trials simulated with K = 0.6, c = 0.7 and section 7's protocol (24 trials
    of 60 impacts, noise 0.05 m/s, 0.02 rad, 5 ms; seeds 100-129, the shared alignment): K is
    biased by about -0.003 (c by +0.002), the 95 % interval's half width is 0.020; the
    intervals held the truth in 29 (K) and 30 (c) of 30 data sets. The bias comes from the
    noise after the perturbed impact (it vanishes without noise): the mean of noisy
    nonlinear responses is not the noiseless response. Starting every model response from
    the mean deviation instead of each event's own adds -0.004 (measured before).
    """
    from scipy import optimize, stats

    data = [(np.stack([r.dv_m_s, r.dtheta_rad, r.dtau_s]),
             np.stack([r.se_v_m_s, r.se_theta_rad, r.se_tau_s]),
             None if r.initial is None else np.asarray(r.initial, float).T)
            for r in responses]
    scales = np.array([np.nanmax(np.abs(d[0][i])) for d in data for i in range(3)]).reshape(
        len(data), 3).max(axis=0)
    floor = 1e-6 * np.where(scales > 0, scales, 1.0)

    def residuals(x):
        controller = controller_of(x[0], x[1])
        offsets = x[2:]
        out = []
        for mean, se, initial in data:
            n = mean.shape[1] - 1
            if initial is None:
                model = predicted_deviations(params, controller, mean[:, 0] - offsets, n)
            else:
                with warnings.catch_warnings():  # every window lost at this (K, c): NaN, a
                    warnings.simplefilter("ignore", RuntimeWarning)  # large residual below
                    model = np.nanmean(predicted_deviations(
                        params, controller, initial - offsets[:, None], n), axis=-1)
            r = (model[:, 1:] + offsets[:, None] - mean[:, 1:]) / np.maximum(se[:, 1:],
                                                                            floor[:, None])
            out.append(np.where(np.isfinite(r), r, 1e3).ravel())
        return np.concatenate(out)

    lower = [gain_bounds[0], rate_bounds[0], -np.inf, -np.inf, -np.inf]
    upper = [gain_bounds[1], rate_bounds[1], np.inf, np.inf, np.inf]
    # the cost has local minima: start from ``initial`` and the best points of a coarse grid
    grid = [(k, c) for k in np.linspace(-0.25, 1.25, 7) for c in (0.25, 0.5, 0.75, 1.0, 1.25, 1.5)
            if gain_bounds[0] <= k <= gain_bounds[1] and rate_bounds[0] <= c <= rate_bounds[1]]
    cost = [float(np.sum(residuals(np.array([k, c, 0.0, 0.0, 0.0])) ** 2)) for k, c in grid]
    starts = [tuple(initial)] + [grid[i] for i in np.argsort(cost)[:starts_from_grid]]
    sol = min((optimize.least_squares(residuals, np.array([k, c, 0.0, 0.0, 0.0]),
                                      bounds=(lower, upper), x_scale="jac") for k, c in starts),
              key=lambda res: res.cost)
    m, p = sol.fun.size, sol.x.size
    dof = max(m - p, 1)
    chi2 = float(sol.fun @ sol.fun) / dof
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * chi2
        half = stats.t.ppf(0.5 + confidence / 2.0, dof) * np.sqrt(np.diag(cov))
    except np.linalg.LinAlgError:
        half = np.full(p, np.nan)
    gain, rate = float(sol.x[0]), float(sol.x[1])
    controller = controller_of(gain, rate)
    eig = np.linalg.eigvals(controlled_jacobian(params, controller))
    eig = eig[np.argsort(-np.abs(eig))]
    return ControlFit(
        gain=gain, rate=rate,
        gain_ci=(gain - half[0], gain + half[0]), rate_ci=(rate - half[1], rate + half[1]),
        offsets=(float(sol.x[2]), float(sol.x[3]), float(sol.x[4])), eigenvalues=eig,
        spectral_radius=float(np.abs(eig).max()), reduced_chi2=chi2, n_residuals=m,
        success=bool(sol.success),
    )


@dataclass(frozen=True)
class FastestController:
    """A (K, c) where the spectral radius of the controlled map is smallest, and that radius."""

    gain: float
    rate: float
    spectral_radius: float


def fastest_immediate_controller(params: ModelParams) -> FastestController:
    """Smallest spectral radius along K at c = 1, in closed form.

    With c = 1 one eigenvalue is 0 and the others solve lambda^2 - T lambda + D = 0 with
    D = alpha^2 - K A, T = 1 + alpha^2 + B - K (A + B), A = (1 - alpha)^2, B = (1+alpha)^2 AC.
    While they are complex |lambda| = sqrt(D) falls with K; the minimum is where the pair
    becomes real (T^2 = 4 D), at the larger root K of
    (A + B)^2 K^2 + (4 A - 2 (1 + alpha^2 + B)(A + B)) K + (1 + alpha^2 + B)^2 - 4 alpha^2 = 0.
    Where the pair is never complex (with D >= 0) the minimum of a fine grid of K in [-2, 2]."""
    alpha = params.alpha
    ac = racket_acceleration_at_impact_g(params)
    A, B = (1.0 - alpha) ** 2, (1.0 + alpha) ** 2 * ac
    t0, s = 1.0 + alpha**2 + B, A + B
    roots = np.roots([s * s, 4.0 * A - 2.0 * t0 * s, t0 * t0 - 4.0 * alpha**2])
    roots = roots[np.isreal(roots)].real
    roots = roots[alpha**2 - roots * A >= 0.0]
    if len(roots):
        gain = float(roots.max())
        return FastestController(gain, 1.0, math.sqrt(alpha**2 - gain * A))
    # the pair never turns complex (the passive map is in eq. 14's real regime): a fine grid
    gains = np.linspace(-2.0, 2.0, 40001)
    radius = period_control_radius(params, gains, 1.0)
    i = int(np.argmin(radius))
    return FastestController(float(gains[i]), 1.0, float(radius[i]))


def fastest_controller(params: ModelParams, guess: tuple[float, float]) -> FastestController:
    """Smallest spectral radius over (K, c): where all three eigenvalues coincide (a triple
    real root: the characteristic polynomial is (lambda - r)^3), found from ``guess`` (the
    best point of a grid) by solving trace = 3 r, sum of principal 2 x 2 minors = 3 r^2,
    det = r^3 for (K, c, r). The radius has a cusp there, which grid or simplex searches
    resolve poorly. Falls back to the guess when the solve fails."""
    from scipy import optimize

    def radius_at(k, c):
        return float(spectral_radius_3x3(controlled_jacobian(params, PeriodController(k, c))))

    def equations(x):
        k, c, r = x
        poly = np.poly(controlled_jacobian(params, PeriodController(k, c)))
        return [poly[1] + 3 * r, poly[2] - 3 * r * r, poly[3] + r**3]

    k0, c0 = guess
    r0 = radius_at(k0, c0)
    sol, _, ok, _ = optimize.fsolve(equations, [k0, c0, r0], full_output=True, xtol=1e-13)
    if ok == 1 and abs(sol[0] - k0) < 0.2 and abs(sol[1] - c0) < 0.2:
        found = radius_at(sol[0], sol[1])
        if found <= r0:
            return FastestController(float(sol[0]), float(sol[1]), found)
    return FastestController(float(k0), float(c0), r0)


def controlled_impulse_response_linear(params: ModelParams, controller: Controller,
                                       alpha_p: float, n_impacts: int) -> ControlledResponse:
    """The linearised controlled map y_{k+1} = M y_k (M: the 3 x 3 Jacobian) from
    y_0 = (v_0 - v~, 0, 0), as ``analysis.impulse.impulse_response_linear`` is for eq. 9's J."""
    v_fp, theta_fp, tau_bar = controlled_fixed_point(params, controller)
    y = iterate_linear(controlled_jacobian(params, controller),
                       [perturbed_velocity(params, alpha_p) - v_fp, 0.0, 0.0], n_impacts)
    v = v_fp + y[:, 0]  # dv = v - v~ as ``analysis.impulse`` computes it (same bits at K = 0)
    return ControlledResponse(v=v, theta=np.mod(theta_fp + y[:, 1], TWO_PI),
                              tau=tau_bar + y[:, 2], dv=v - v_fp, dtheta=y[:, 1], dtau=y[:, 2])

