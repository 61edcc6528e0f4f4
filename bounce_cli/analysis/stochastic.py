"""The stochastic ball bouncing map (eqs. 16-18) and its linearised VAR(1) theory (eq. 19).

State deviations from the fixed point are y_k = (v_k - v~, theta_k - theta~) (order (v, theta)
as in eq. 9). Lagged covariances follow the paper's convention R(l) = E[y_{k+l} y_k^T], so

    R(l)[0, 0] = E[v_{k+l} v_k]          pair "v_v"
    R(l)[1, 1] = E[theta_{k+l} theta_k]  pair "theta_theta"
    R(l)[1, 0] = E[theta_{k+l} v_k]      pair "v_to_theta" (velocity leads phase)
    R(l)[0, 1] = E[v_{k+l} theta_k]      pair "theta_to_v" (phase leads velocity)

(the matrix printed in section 6 lists the two cross terms in the transposed positions; the
pair names above are what matters). Correlations are covariances divided by the standard
deviations.

Noise: two independent standard normal draws per bounce, xi (velocity) and xi' (phase).
Each run draws from its own ``numpy.random.Generator`` built from a ``SeedSequence`` given by
the caller (``SeedSequence(seed).spawn(n)``), in fixed-size blocks, so a run's result does not
depend on which other runs are advanced with it or on the block size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.linalg import solve_discrete_lyapunov

from ..errors import NotStableError
from ..memory import check_array_memory
from .classify import ClassifySettings
from ..model.linear import is_stable, jacobian
from ..model.impact import next_impact_phase
from ..model.maps import map_step, velocity_after_impact
from ..model.params import ModelError, ModelParams, phase_difference, wrap_phase
from .roots import nearest_root

#: (name, row, column) of R(l) = E[y_{k+l} y_k^T] with y = (v, theta)
PAIRS: tuple[tuple[str, int, int], ...] = (
    ("v_v", 0, 0),
    ("theta_theta", 1, 1),
    ("v_to_theta", 1, 0),
    ("theta_to_v", 0, 1),
)
PAIR_NAMES = tuple(name for name, _, _ in PAIRS)

#: phase in cos(.) of eq. 16: "theta" = theta_{k+1} (as printed: the phase noise also moves
#: the racket velocity at impact), "phi" = the noiseless phi_{k+1}
VELOCITY_PHASES = ("theta", "phi")


# -- linear theory (eq. 19) --------------------------------------------------------------------
def paper_noise_covariance(q_v: float, q_theta: float) -> np.ndarray:
    """R_eps(0) = diag(q_v^2, q_theta^2), the noise covariance stated under eq. 19."""
    return np.diag([q_v**2, q_theta**2])


def map_noise_covariance(
    params: ModelParams, q_v: float, q_theta: float, velocity_phase: str = "theta"
) -> np.ndarray:
    """Noise covariance of the linearisation of eqs. 16-18 as iterated here.

    With cos(theta_{k+1}) in eq. 16 ("theta") the phase kick q_theta xi' also changes the
    velocity by dv/dtheta_{k+1} = -(1+alpha) a_r w sin(theta~) times the kick, so
    eps = (q_v xi + c q_theta xi', q_theta xi') with c = -(1+alpha) a_r w sin(theta~): not
    diagonal. With cos(phi_{k+1}) ("phi") it is exactly the paper's diagonal R_eps(0).
    """
    check_velocity_phase(velocity_phase)
    if velocity_phase == "phi":
        return paper_noise_covariance(q_v, q_theta)
    fp = params.fixed_point()
    c = -(1.0 + params.alpha) * params.racket_amplitude * params.omega * math.sin(fp.theta_rad)
    mix = np.array([[1.0, c], [0.0, 1.0]])
    return mix @ paper_noise_covariance(q_v, q_theta) @ mix.T


def check_velocity_phase(velocity_phase: str) -> None:
    if velocity_phase not in VELOCITY_PHASES:
        raise ModelError(
            f"velocity_phase must be one of {VELOCITY_PHASES} (got {velocity_phase!r})")


def stationary_covariance(jac: np.ndarray, noise_cov: np.ndarray) -> np.ndarray:
    """R(0) solving R = J R J^T + Q (discrete Lyapunov equation) for y_{k+1} = J y_k + eps_k.

    Raises NotStableError (a ModelError) when J has an eigenvalue of modulus >= 1 (to
    rounding, ``linear.is_stable``): then y
    has no stationary distribution and the correlation functions of eq. 19 do not exist.
    """
    radius = float(np.max(np.abs(np.linalg.eigvals(jac))))
    if not is_stable(radius):
        raise NotStableError(
            f"the fixed point is not linearly stable (spectral radius {radius:.4g} >= 1): "
            "no stationary covariance for eq. 19"
        )
    cov = solve_discrete_lyapunov(jac, noise_cov)
    return (cov + cov.T) / 2.0


def lagged_covariances(jac: np.ndarray, cov0: np.ndarray, max_lag: int) -> np.ndarray:
    """R(l) = J^l R(0) for l = 0..max_lag, shape (max_lag + 1, 2, 2); a max_lag whose
    array would not fit in memory is a one-line ConfigError (``bounce_cli.memory``)."""
    check_array_memory((max_lag + 1) * cov0.size, f"max_lag = {max_lag:,} lags",
                       "reduce max_lag")
    out = np.empty((max_lag + 1,) + cov0.shape)
    out[0] = cov0
    for lag in range(1, max_lag + 1):
        out[lag] = jac @ out[lag - 1]
    return out


def correlations_from_covariances(covs: np.ndarray) -> dict[str, np.ndarray]:
    """Normalise R(l) (shape (..., L+1, 2, 2)) by the lag-0 standard deviations:
    pair -> (..., L+1)."""
    sd = np.sqrt(np.stack([covs[..., 0, 0, 0], covs[..., 0, 1, 1]], axis=-1))
    return {
        name: covs[..., i, j] / (sd[..., i, None] * sd[..., j, None]) for name, i, j in PAIRS
    }


@dataclass(frozen=True)
class Var1Theory:
    """Stationary statistics of eq. 19 for given J and noise covariance."""

    jacobian: np.ndarray
    noise_cov: np.ndarray
    cov0: np.ndarray
    correlations: dict[str, np.ndarray]  # pair -> correlation at lags 0..max_lag

    @property
    def sd_v_m_s(self) -> float:
        return math.sqrt(self.cov0[0, 0])

    @property
    def sd_theta_rad(self) -> float:
        return math.sqrt(self.cov0[1, 1])


def var1_theory(jac: np.ndarray, noise_cov: np.ndarray, max_lag: int) -> Var1Theory:
    cov0 = stationary_covariance(jac, noise_cov)
    corr = correlations_from_covariances(lagged_covariances(jac, cov0, max_lag))
    return Var1Theory(np.asarray(jac), np.asarray(noise_cov), cov0, corr)


# -- sample correlation functions ----------------------------------------------------------------
def sample_correlations(v: np.ndarray, theta: np.ndarray, max_lag: int) -> dict[str, np.ndarray]:
    """Sample correlation functions of series (..., N) of v and theta deviations.

    Each series has its own mean removed; covariance at lag l is sum_k x_{k+l} y_k / N (the
    usual biased estimator, so the matrix of lags is positive semi-definite), normalised by the
    lag-0 standard deviations. Returns pair -> array (..., max_lag + 1).
    """
    y = np.stack([np.asarray(v, float), np.asarray(theta, float)], axis=-2)  # (..., 2, N)
    y = y - y.mean(axis=-1, keepdims=True)
    n = y.shape[-1]
    if max_lag >= n:
        raise ModelError(f"max_lag {max_lag} must be smaller than the series length {n}")
    covs = np.empty(y.shape[:-2] + (max_lag + 1, 2, 2))
    for lag in range(max_lag + 1):
        # E[y_{k+lag} y_k^T]: rows index the later sample
        covs[..., lag, :, :] = np.einsum("...in,...jn->...ij", y[..., lag:], y[..., : n - lag]) / n
    return correlations_from_covariances(covs)


# -- iterating the stochastic map ------------------------------------------------------------------
def stochastic_step(theta, v, params: ModelParams, velocity_noise, phase_noise,
                    velocity_phase: str = "theta"):
    """One bounce of eqs. 16-18 from arrays of states; returns (theta_{k+1}, v_{k+1}, hop).

    ``velocity_noise`` = q_v xi, ``phase_noise`` = q_theta xi' (already scaled). "theta" is
    eq. 16 as printed (``map_step``); "phi" evaluates cos(phi_{k+1}) instead.
    """
    if velocity_phase == "theta":
        step = map_step(theta, v, params, velocity_noise=velocity_noise, phase_noise=phase_noise)
        return step.theta, step.v, step.hop_phase
    check_velocity_phase(velocity_phase)
    hop = next_impact_phase(theta, v, params)
    phi = theta + hop
    v_next = velocity_after_impact(phi, v, hop, params) + velocity_noise
    return phi + phase_noise, v_next, hop


@dataclass(frozen=True)
class StochasticRuns:
    """Runs of the stochastic map after burn-in: deviations from the fixed point.

    dv: v_k - v~ (m/s), dtheta: theta_k - theta~ wrapped to [-pi, pi) (rad), shape (runs, N).
    lost: runs in which the ball at some bounce could not leave the racket or stuck to it
    (a hop shorter than the sticking interval); their rows are NaN from then on.
    """

    dv: np.ndarray
    dtheta: np.ndarray
    lost: np.ndarray


def simulate_stochastic_map(
    params: ModelParams,
    q_v: float,
    q_theta: float,
    n_bounces: int,
    seeds: Sequence[np.random.SeedSequence],
    *,
    burn_in: int = 0,
    velocity_phase: str = "theta",
    min_hop_s: float = ClassifySettings().min_hop_s,
    block: int = 1024,
    on_block: Callable[[int], None] | None = None,
) -> StochasticRuns:
    """Iterate eqs. 16-18 for len(seeds) independent runs at once, starting at the fixed point.

    Each run draws its noise (xi, xi') per bounce from ``default_rng(seed)`` in blocks of
    ``block`` bounces (rows of a (block, 2) standard normal array); the phase is kept wrapped to
    [0, 2 pi) so long runs do not lose precision. ``on_block(n)`` is called after every block
    with the number of bounces done.
    """
    check_velocity_phase(velocity_phase)
    fp = params.fixed_point()
    runs = len(seeds)
    check_array_memory(2 * runs * n_bounces, f"the stochastic map's {runs:,} runs x "
                       f"{n_bounces:,} bounces", "shorten the trials (duration_s) or the runs "
                       "(bounces), or run fewer")
    rngs = [np.random.default_rng(s) for s in seeds]
    total = burn_in + n_bounces
    theta = np.full(runs, wrap_phase(fp.theta_rad))
    v = np.full(runs, fp.v_m_s)
    lost = np.zeros(runs, dtype=bool)
    dv = np.full((runs, n_bounces), np.nan)
    dtheta = np.full((runs, n_bounces), np.nan)
    min_hop = min_hop_s * params.omega
    k = 0
    while k < total:
        size = min(block, total - k)
        xi = np.stack([rng.standard_normal((size, 2)) for rng in rngs], axis=1)  # (size, runs, 2)
        for i in range(size):
            theta, v, hop = stochastic_step(
                theta, v, params, q_v * xi[i, :, 0], q_theta * xi[i, :, 1], velocity_phase
            )
            bad = ~(hop >= min_hop) | ~np.isfinite(v)
            if bad.any():
                lost |= bad
                # park lost runs at the fixed point so the solver keeps working; masked below
                theta = np.where(lost, fp.theta_rad, theta)
                v = np.where(lost, fp.v_m_s, v)
            theta = wrap_phase(theta)
            j = k + i - burn_in
            if j >= 0:
                dv[:, j] = np.where(lost, np.nan, v - fp.v_m_s)
                dtheta[:, j] = np.where(lost, np.nan, phase_difference(theta, fp.theta_rad))
        k += size
        if on_block is not None:
            on_block(size)
    return StochasticRuns(dv=dv, dtheta=dtheta, lost=lost)


# -- inverse problems: what would give the paper's printed SDs (section 6) ---------------------
def stationary_sds(params: ModelParams, noise_cov: np.ndarray) -> tuple[float, float]:
    """Stationary standard deviations of eq. 19 at the fixed point of ``params`` with noise
    covariance ``noise_cov``: (SD of v in m/s, SD of theta in rad). ModelError when the fixed
    point is absent or unstable."""
    cov = stationary_covariance(jacobian(params), noise_cov)
    return math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1])


def noise_strengths_for_sds(jac: np.ndarray, sd_v_m_s: float,
                            sd_theta_rad: float) -> tuple[float, float]:
    """The diagonal noise strengths (q_v in m/s, q_theta in rad) under which eq. 19 gives the
    stationary SDs ``sd_v_m_s`` and ``sd_theta_rad``.

    R(0) is linear in the noise covariance diag(q_v^2, q_theta^2), so the two variances are
    a 2 x 2 linear system in (q_v^2, q_theta^2); a strength whose square comes out <= 0 (no
    real noise gives those SDs) is NaN.
    """
    unit_v = stationary_covariance(jac, np.diag([1.0, 0.0]))
    unit_t = stationary_covariance(jac, np.diag([0.0, 1.0]))
    a = np.array([[unit_v[0, 0], unit_t[0, 0]], [unit_v[1, 1], unit_t[1, 1]]])
    b = np.array([sd_v_m_s**2, sd_theta_rad**2])
    q2 = np.linalg.solve(a, b)
    q_v, q_theta = (math.sqrt(value) if value > 0 else math.nan for value in q2)
    return q_v, q_theta


def racket_amplitude_for_sd(
    params: ModelParams, q_v: float, q_theta: float, a_max: float, *,
    sd_v_m_s: float | None = None, sd_theta_deg: float | None = None,
) -> float:
    """The racket amplitude a_r (m) at which eq. 19 with the diagonal noise (q_v, q_theta)
    gives the target SD of v (m/s) or of theta (deg; give exactly one), all other parameters
    as in ``params``: the root nearest to ``params.racket_amplitude`` between just above the
    smallest a_r with a fixed point and ``a_max``; NaN when there is none."""
    if (sd_v_m_s is None) == (sd_theta_deg is None):
        raise ValueError("give exactly one of sd_v_m_s and sd_theta_deg")
    noise_cov = paper_noise_covariance(q_v, q_theta)

    def excess(a: float) -> float:
        try:
            sd_v, sd_theta = stationary_sds(
                ModelParams(params.alpha, params.g, a, params.racket_period), noise_cov)
        except ModelError:  # no fixed point, or an unstable one: no stationary SDs
            return math.nan
        if sd_v_m_s is not None:
            return sd_v - sd_v_m_s
        assert sd_theta_deg is not None
        return math.degrees(sd_theta) - sd_theta_deg

    return nearest_root(excess, params.min_racket_amplitude() * 1.001, a_max,
                        params.racket_amplitude)
