"""Active period control: the racket period as a third state (the paper's future work,
sections 7-8; model in ``model.control``).

Asks of the controlled map what the paper asked of the passive one: where is it linearly
stable and how fast does it relax (spectral radius over the controller's gain K and rate c;
the data suggest < 0.2, section 7), how does it answer section 7's perturbations (Fig. 9 with
control, and the racket period per impact, the model's Fig. 11), where does a perturbation
leave the basin (the passive map above alpha_p ~ 0.63), how large is the Fig. 4 basin with
control, and -- on perturbation trials, simulated with a known controller or a lab's
``impacts.csv`` -- which K and c fit the mean responses.
"""

from __future__ import annotations

import math
from typing import Annotated, Optional

import numpy as np
import pandas as pd
from pydantic import Field, model_validator

from ..data.data_parameters import model_at_data, model_for_data
from ..data.impacts import Impacts, read_impacts as shared_read_impacts
from ..memory import check_array_memory
from ..runtime.config import (
    DataFiles,
    data_text,
    ClassifyBlock,
    ConfigError,
    ControlBlock,
    ControllableModelBlock,
    ExperimentConfig,
    StrictModel,
)
from ..analysis.classify import OUTCOMES
from ..analysis.impulse import find_threshold
from ..model.perturbation import perturbed_velocity, relaxation_impacts
from ..model.linear import jacobian, radius_below
from ..model.params import ModelError, ModelParams, eq8_amplitude, phase_difference
from ..analysis.stochastic import (
    PAIR_NAMES,
    map_noise_covariance,
    sample_correlations,
    var1_theory,
)
from .basin import classify_map_grid
from ..model.control import (
    ControlledMap,
    PASSIVE,
    PeriodController,
    controlled_jacobian,
    spectral_radius_3x3,
    iterate_controlled,
)
from ..analysis.control_design import (
    FastestController,
    align_perturbations,
    classify_controlled,
    controlled_impulse_response,
    fastest_controller,
    fastest_immediate_controller,
    fit_period_control,
    period_control_radius,
    predicted_deviations,
    simulate_perturbation_trials,
)
from ..paper import values as paper
from .plotting import (
    IMPACT_AFTER_LABEL,
    IMPACT_AFTER_LABEL_NARROW,
    LAG_LABEL,
    PANELS,
    PHASE_LABEL,
    TITLES,
    VELOCITY_LABEL,
    integer_axis,
    perturbation_title,
    publication_style,
)
from .base import Experiment, ExperimentResult, RunOptions
from .basin import OUTCOME_COLOURS, OUTCOME_LABELS, GridAxis
from .impulse import RelaxationBlock, ThresholdBlock
from .data_side import relaxed_text

MODELS = ("passive", "controlled")


# -- config -----------------------------------------------------------------------------------
class ControlledModelBlock(ControllableModelBlock):
    """The model block with the controller studied (``model.control``, required here)."""

    control: ControlBlock = ControlBlock(gain=0.7, rate=1.0)


class RadiusBlock(StrictModel):
    """Spectral radius of the 3 x 3 Jacobian over a (K, c) grid and along K at one c."""

    gain: GridAxis = GridAxis(start=-0.5, stop=1.5, num=101)
    rate: GridAxis = GridAxis(start=0.0, stop=2.0, num=101)
    rate_line: float = Field(1.0, ge=0.0, le=2.0, description="c of the line along K")
    target_radius: float = Field(0.2, gt=0.0, lt=1.0,
                                 description="what the data suggest (section 7: < 0.2)")
    zoom_half_width: float = Field(0.08, gt=0.0, description="K and c around the fastest")
    zoom_num: int = Field(121, ge=2, description="grid points per axis of the zoom")

    @model_validator(mode="after")
    def _grids_fit_in_memory(self):
        check_array_memory(self.gain.num * self.rate.num, f"gain.num x rate.num = "
                           f"{self.gain.num:,} x {self.rate.num:,} points", "reduce them")
        check_array_memory(self.zoom_num ** 2, f"zoom_num^2 = {self.zoom_num:,}^2 points",
                           "reduce zoom_num")
        return self


class ImpulseBlock(StrictModel):
    alpha_p: list[Annotated[float, Field(ge=0.0, lt=1.0)]] = Field([0.4, 0.6, 0.35, 0.65],
                                                                    min_length=1)
    iterations: int = Field(10, ge=1, description="impacts after the perturbed one, shown")


class ControlClassifyBlock(ClassifyBlock):
    period_tolerance_s: float = Field(1e-3, gt=0.0,
                                      description="s, |tau - tau_bar| for period-1")


class BasinGridBlock(StrictModel):
    theta0_deg: GridAxis = GridAxis(start=0.0, stop=360.0, num=120)
    v0_m_s: GridAxis = GridAxis(start=0.0, stop=10.0, num=120)

    @model_validator(mode="after")
    def _fits_in_memory(self):
        check_array_memory(self.theta0_deg.num * self.v0_m_s.num,
                           f"theta0_deg.num x v0_m_s.num = {self.theta0_deg.num:,} x "
                           f"{self.v0_m_s.num:,} points", "reduce them")
        return self


class SimulateBlock(StrictModel):
    """Perturbation trials of the configured controller (when no ``data`` is given): section
    7's protocol, alpha_p at every ``perturb_every``-th impact."""

    trials: int = Field(20, ge=2)
    impacts_per_trial: int = Field(60, ge=10)
    perturb_every: int = Field(5, ge=2)
    alpha_p_low: tuple[float, float] = (0.3, 0.4)
    alpha_p_high: tuple[float, float] = (0.6, 0.7)
    velocity_noise_sd_m_s: float = Field(0.05, ge=0.0)
    phase_noise_sd_rad: float = Field(0.02, ge=0.0)
    period_noise_sd_s: float = Field(0.005, ge=0.0)
    seed: int = Field(1, ge=0)

    @model_validator(mode="after")
    def _fits_in_memory(self):
        check_array_memory(3 * self.trials * self.impacts_per_trial,
                           f"trials x impacts_per_trial = {self.trials:,} x "
                           f"{self.impacts_per_trial:,} impacts (3 numbers each)", "reduce them")
        return self


class FitBlock(StrictModel):
    impacts_after: int = Field(4, ge=1, description="impacts after the perturbed one fitted")
    initial_gain: float = 0.5
    initial_rate: float = Field(0.5, ge=0.0, le=2.0)
    confidence: float = Field(0.95, gt=0.0, lt=1.0)
    racket_period_s: Optional[float] = Field(
        None, gt=0.0, description="with data: the controller's set point tau_bar, s (null: the "
        "data's mean racket period, which control shifts: +4 ms in the README's example)")
    simulate: SimulateBlock = SimulateBlock()

    @model_validator(mode="after")
    def _fits_in_memory(self):
        check_array_memory(self.impacts_after + 1, f"impacts_after = {self.impacts_after:,} "
                           "impacts", "reduce impacts_after")
        return self


class CorrelationsBlock(StrictModel):
    """Correlation functions (Fig. 8, eq. 19) of the stochastic map with and without control,
    at this config's model: VAR(1) theory with the 2 x 2 / 3 x 3 Jacobian, checked against
    long runs of the controlled stochastic map."""

    q_v_m_s: float = Field(0.04, ge=0.0, description="velocity noise (section 6)")
    q_theta_rad: float = Field(0.05, ge=0.0, description="phase noise (section 6)")
    q_tau_s: float = Field(0.0, ge=0.0, description="racket period noise per impact")
    max_lag: int = Field(10, ge=1)
    runs: int = Field(40, ge=2, description="runs of the controlled map for the check")
    bounces: int = Field(1000, ge=20, description="bounces per run after burn-in")
    burn_in: int = Field(50, ge=0)
    seed: int = Field(0, ge=0)

    @model_validator(mode="after")
    def _fits_in_memory(self):
        check_array_memory(3 * self.runs * (self.burn_in + self.bounces),
                           f"runs x (burn_in + bounces) = {self.runs:,} x "
                           f"{self.burn_in + self.bounces:,} impacts (3 numbers each)",
                           "reduce them")
        check_array_memory(9 * (self.max_lag + 1), f"max_lag = {self.max_lag:,} lags",
                           "reduce max_lag")
        return self


class ControlConfig(ExperimentConfig):
    model: ControlledModelBlock = ControlledModelBlock()
    radius: RadiusBlock = RadiusBlock()
    impulse: ImpulseBlock = ImpulseBlock()
    relaxation: RelaxationBlock = RelaxationBlock()
    threshold: ThresholdBlock = ThresholdBlock()
    classify: ControlClassifyBlock = ControlClassifyBlock()
    basin: BasinGridBlock = BasinGridBlock()
    fit: FitBlock = FitBlock()
    correlations: CorrelationsBlock = CorrelationsBlock()
    data: DataFiles = Field(None, description="impacts.csv of perturbation trials to fit")


def _controllers(config: ControlConfig) -> dict:
    return {"passive": PASSIVE, "controlled": config.model.control.controller()}


# -- stability over (K, c) ---------------------------------------------------------------------
def _eigen_row(params: ModelParams, label: str, gain: float, rate: float) -> dict:
    eig = np.linalg.eigvals(controlled_jacobian(params, PeriodController(gain, rate)))
    eig = eig[np.lexsort((-eig.imag, -np.abs(eig)))]
    row = {"model": label, "gain_K": gain, "rate_c": rate}
    for i, lam in enumerate(eig, 1):
        row[f"lambda{i}_re"], row[f"lambda{i}_im"] = lam.real, lam.imag
    row["spectral_radius"] = float(np.abs(eig).max())
    return row


def radius_frames(params: ModelParams, config: ControlConfig) -> dict[str, pd.DataFrame]:
    block = config.radius
    gains, rates = block.gain.values(), block.rate.values()
    K, c = np.meshgrid(gains, rates)
    radius = period_control_radius(params, K, c)
    grid = pd.DataFrame({"gain_K": K.ravel(), "rate_c": c.ravel(),
                         "spectral_radius": radius.ravel()})
    line_radius = period_control_radius(params, gains, block.rate_line)
    line = pd.DataFrame({"gain_K": gains, "rate_c": block.rate_line,
                         "spectral_radius": line_radius})
    line_best = (fastest_immediate_controller(params) if block.rate_line == 1.0 else None)
    if line_best is None:  # another c: the best grid point
        i = int(np.argmin(line_radius))
        line_best = FastestController(float(gains[i]), block.rate_line, float(line_radius[i]))
    j = np.unravel_index(np.argmin(radius), radius.shape)
    best = fastest_controller(params, (float(K[j]), float(c[j])))
    zoom = block.zoom_half_width
    zk, zc = np.meshgrid(np.linspace(best.gain - zoom, best.gain + zoom, block.zoom_num),
                         np.linspace(best.rate - zoom, best.rate + zoom, block.zoom_num))
    zoomed = pd.DataFrame({"gain_K": zk.ravel(), "rate_c": zc.ravel(),
                           "spectral_radius": period_control_radius(params, zk, zc).ravel()})
    control = config.model.control
    rows = [_eigen_row(params, "passive", PASSIVE.gain, PASSIVE.rate),
            _eigen_row(params, "controlled", control.gain, control.rate),
            _eigen_row(params, f"fastest at c = {block.rate_line:g}", line_best.gain,
                       line_best.rate),
            _eigen_row(params, "fastest", best.gain, best.rate)]
    regions = pd.DataFrame([
        _region("stable", 1.0, "map", K, c, radius),
        _region("fast", block.target_radius, "zoom", zk, zc, zoomed.spectral_radius.to_numpy()
                .reshape(zk.shape)),
    ])
    eigen = pd.DataFrame(rows)
    return {"radius_map.csv": grid, "radius_gain.csv": line, "radius_zoom.csv": zoomed,
            "eigen.csv": eigen, "regions.csv": regions}


def _region(name: str, below: float, grid: str, K, c, radius) -> dict:
    """Where the spectral radius is below ``below`` on a grid: area in the (K, c) plane (cells
    times cell area), extent, and whether it touches the grid's edge (then it is cut).

    A point whose radius equals ``below`` to within rounding is on the boundary, not inside
    (``model.linear.radius_below``: at K = 1 and at c = 0 an eigenvalue is on the unit
    circle exactly)."""
    inside = radius_below(radius, below)
    cell = (K[0, 1] - K[0, 0]) * (c[1, 0] - c[0, 0])
    edge = inside[0].any() or inside[-1].any() or inside[:, 0].any() or inside[:, -1].any()

    def extent(values, fn):
        return float(fn(values[inside])) if inside.any() else math.nan

    return {"region": name, "radius_below": below, "grid": grid,
            "area_K_c": float(inside.sum() * cell),
            "gain_min_K": extent(K, np.min), "gain_max_K": extent(K, np.max),
            "rate_min_c": extent(c, np.min), "rate_max_c": extent(c, np.max),
            "touches_grid_edge": bool(edge)}


# -- impulse responses, relaxation, thresholds, basin ------------------------------------------
def impulse_frames(params: ModelParams, config: ControlConfig) -> dict[str, pd.DataFrame]:
    rows, relax = [], []
    tol_theta = math.radians(config.relaxation.tolerance_theta_deg)
    settings = config.classify.settings()
    fp_theta = params.fixed_point().theta_rad
    for model, controller in _controllers(config).items():
        v0 = np.array([perturbed_velocity(params, a) for a in config.impulse.alpha_p])
        outcome = classify_controlled(fp_theta, v0, params, controller, settings,
                                      period_tolerance_s=config.classify.period_tolerance_s)
        for i, alpha_p in enumerate(config.impulse.alpha_p):
            r = controlled_impulse_response(params, controller, alpha_p,
                                            max(config.relaxation.max_impacts,
                                                config.impulse.iterations))
            for k in range(config.impulse.iterations + 1):
                rows.append({"alpha_p": alpha_p, "model": model, "k": k, "v_m_s": r.v[k],
                             "theta_deg": math.degrees(r.theta[k]),
                             "racket_period_s": r.tau[k], "dv_m_s": r.dv[k],
                             "dtheta_deg": math.degrees(r.dtheta[k]),
                             "dtau_ms": 1e3 * r.dtau[k]})
            horizon = slice(0, config.relaxation.max_impacts + 1)
            relax.append({"alpha_p": alpha_p, "model": model, "v0_m_s": v0[i],
                          "outcome": outcome.names()[i],
                          "relaxation_impacts": relaxation_impacts(
                              r.dv[horizon], r.dtheta[horizon],
                              config.relaxation.tolerance_v_m_s, tol_theta),
                          "max_abs_dtau_ms": float(1e3 * np.nanmax(np.abs(r.dtau[horizon])))})
    return {"impulse.csv": pd.DataFrame(rows), "relaxation.csv": pd.DataFrame(relax)}


def relaxation_gain_frame(params: ModelParams, config: ControlConfig) -> pd.DataFrame:
    """Impacts to relax of the FULL map after each alpha_p along K at c = radius.rate_line
    (the linear spectral radius measures the slowest mode; section 7's perturbation, a
    velocity kick at theta~, need not excite it)."""
    gains = config.radius.gain.values()
    rate = config.radius.rate_line
    v_fp, theta_fp, tau_bar = params.fixed_point().v_m_s, params.fixed_point().theta_rad, \
        params.racket_period
    tol_theta = math.radians(config.relaxation.tolerance_theta_deg)
    rows = []
    for alpha_p in config.impulse.alpha_p:
        v0 = np.full(gains.shape, perturbed_velocity(params, alpha_p))
        theta, v, _, _ = iterate_controlled(theta_fp, v0, tau_bar, params,
                                            PeriodController(gains, rate),
                                            config.relaxation.max_impacts)
        dtheta = phase_difference(theta, theta_fp)
        for i, gain in enumerate(gains):
            rows.append({"gain_K": gain, "rate_c": rate, "alpha_p": alpha_p,
                         "relaxation_impacts": relaxation_impacts(
                             v[:, i] - v_fp, dtheta[:, i], config.relaxation.tolerance_v_m_s,
                             tol_theta)})
    return pd.DataFrame(rows)


def threshold_frame(params: ModelParams, config: ControlConfig) -> pd.DataFrame:
    block, settings = config.threshold, config.classify.settings()
    rows = []
    for model, controller in _controllers(config).items():
        for direction in (+1, -1):
            t = find_threshold(params, direction, settings, scan_step=block.scan_step,
                               bisection_tolerance=block.bisection_tolerance,
                               alpha_p_max=block.alpha_p_max, controller=controller)
            rows.append({"model": model, "direction": "increase" if direction > 0 else "decrease",
                         "alpha_p_inside": t.alpha_p_inside, "alpha_p_outside": t.alpha_p_outside,
                         "alpha_p_threshold": t.alpha_p_threshold,
                         "v0_threshold_m_s": t.v0_threshold_m_s,
                         "outcome_outside": t.outcome_outside,
                         "period1_beyond_in_scan": t.period1_beyond_in_scan})
    return pd.DataFrame(rows)


def basin_frames(params: ModelParams, config: ControlConfig,
                 options: RunOptions) -> dict[str, pd.DataFrame]:
    theta_deg, v0 = config.basin.theta0_deg.values(), config.basin.v0_m_s.values()
    theta_grid, v_grid = np.meshgrid(theta_deg, v0)  # rows: v0 outer, theta0 inner
    frames, fractions = [], []
    for model, controller in _controllers(config).items():
        impact_map = ControlledMap.of(params, controller, require_fixed_point=True,
                                      period_tolerance_s=config.classify.period_tolerance_s)
        # the basin command's classifier: worker processes (--jobs), compiled kernel
        res = classify_map_grid(np.deg2rad(theta_grid).ravel(), v_grid.ravel(), impact_map,
                                config.classify.settings(), jobs=options.jobs)
        frames.append(pd.DataFrame({"model": model, "theta0_deg": theta_grid.ravel(),
                                    "v0_m_s": v_grid.ravel(), "outcome": res.names(),
                                    "iterations": res.iterations}))
        counts = np.bincount(res.outcome.ravel(), minlength=len(OUTCOMES))
        fractions += [{"model": model, "outcome": o, "count": int(n),
                       "fraction": n / res.outcome.size} for o, n in zip(OUTCOMES, counts)]
        options.progress.advance(1)
    return {"basin.csv": pd.concat(frames, ignore_index=True),
            "basin_fractions.csv": pd.DataFrame(fractions)}


# -- correlation functions with control (Fig. 8) -------------------------------------------------
def correlations_frame(params: ModelParams, config: ControlConfig) -> pd.DataFrame:
    """acf.csv: per lag and pair (``analysis.stochastic.PAIR_NAMES``), the VAR(1) correlation
    functions (eq. 19) of the passive map (2 x 2 J, eq. 9) and of the controlled one (3 x 3
    Jacobian, the period's noise q_tau), both with the noise covariance the map of eqs. 16-18
    induces (``analysis.stochastic.map_noise_covariance``, phase noise inside
    cos(theta_{k+1})), and the sample correlations (mean and standard error over runs) of
    the controlled stochastic map."""
    block = config.correlations
    controller = config.model.control.controller()
    noise2 = map_noise_covariance(params, block.q_v_m_s, block.q_theta_rad, "theta")
    noise3 = np.zeros((3, 3))
    noise3[:2, :2], noise3[2, 2] = noise2, block.q_tau_s**2
    try:  # with --data the passive map at the data's parameters may be unstable: NaN then
        passive = var1_theory(jacobian(params), noise2, block.max_lag)
    except ModelError:
        passive = None
    try:
        controlled = var1_theory(controlled_jacobian(params, controller), noise3, block.max_lag)
    except ModelError:  # unstable with this controller: no stationary correlations
        controlled = None
    n = block.burn_in + block.bounces
    sim = simulate_perturbation_trials(
        params, controller, n_trials=block.runs, impacts_per_trial=n, perturb_every=n + 1,
        velocity_noise_sd=block.q_v_m_s, phase_noise_sd=block.q_theta_rad,
        period_noise_sd=block.q_tau_s, seed=block.seed)
    complete = pd.Series(sim["trial"]).value_counts()
    keep = np.isin(sim["trial"], complete.index[complete.to_numpy() == n])
    v = sim["v_m_s"][keep].reshape(-1, n)[:, block.burn_in:]
    theta = sim["theta_rad"][keep].reshape(-1, n)[:, block.burn_in:]
    runs = v.shape[0]
    sample = (sample_correlations(v, phase_difference(theta, params.fixed_point().theta_rad),
                                  block.max_lag) if runs >= 2 else None)
    rows = []
    for name in PAIR_NAMES:
        for lag in range(block.max_lag + 1):
            rows.append({
                "pair": name, "lag": lag,
                "passive_theory": passive.correlations[name][lag] if passive else math.nan,
                "controlled_theory": (controlled.correlations[name][lag] if controlled
                                      else math.nan),
                "controlled_sample_mean": (sample[name][:, lag].mean() if sample else math.nan),
                "controlled_sample_se": (sample[name][:, lag].std(ddof=1) / math.sqrt(runs)
                                         if sample else math.nan),
                "runs": runs,
                "passive_sd_v_m_s": passive.sd_v_m_s if passive else math.nan,
                "controlled_sd_v_m_s": controlled.sd_v_m_s if controlled else math.nan,
                "passive_sd_theta_deg": (math.degrees(passive.sd_theta_rad) if passive
                                         else math.nan),
                "controlled_sd_theta_deg": (math.degrees(controlled.sd_theta_rad)
                                            if controlled else math.nan),
            })
    return pd.DataFrame(rows)


# -- fit of K and c to perturbation trials ------------------------------------------------------
DATA_COLUMNS = ("trial", "k", "theta_rad", "v_m_s", "racket_period_s", "perturbed")


def read_impacts(path_text: str | list[str]) -> Impacts:
    """An impacts table (``bounce_cli.data.impacts``, the data side's reader) with the columns the
    fit and the model at the data's racket need: trial, k, theta_rad (or theta_deg), v_m_s,
    racket_period_s, racket_amplitude_m, perturbed (and alpha if present). Problems are
    one-line ConfigErrors naming ``data``."""
    impacts = shared_read_impacts(path_text, needs=("racket_period_s", "racket_amplitude_m",
                                                    "perturbed"),
                                  command="control --data", optional=("alpha",))
    if not impacts.frame["perturbed"].any():
        raise ConfigError(f"data: {impacts.path}: no perturbed impact (column perturbed)")
    return impacts


def data_source(config: ControlConfig, options: RunOptions | None):
    """The impacts ``control --data`` fits: a table in memory (``options.impacts``, the
    study's units), else the file(s) ``config.data``; None: none (simulated trials)."""
    if options is not None and options.impacts is not None:
        return options.impacts
    return config.data


def data_label(config: ControlConfig, options: RunOptions) -> str:
    """Where the fitted impacts came from, as the summary and captions name it."""
    source = data_source(config, options)
    return source[0] if isinstance(source, tuple) else data_text(source)


def fit_inputs(config: ControlConfig, options: RunOptions | None = None
               ) -> tuple[pd.DataFrame, ModelParams, dict]:
    """The impacts to fit (a lab's ``data`` or simulated trials of the configured controller),
    the model at their parameters (with data: ``data_parameters.model_at_data``, the data's
    racket, alpha and g, as ``model_for_data`` and ``fit.racket_period_s`` say; a one-line
    error without a fixed point), and the truth (simulated) or NaN. Every result of
    ``control --data`` is computed at that model."""
    params = config.params
    control = config.model.control
    source = data_source(config, options)
    if source is None:
        sim = config.fit.simulate
        impacts = pd.DataFrame(simulate_perturbation_trials(
            params, control.controller(), n_trials=sim.trials,
            impacts_per_trial=sim.impacts_per_trial, perturb_every=sim.perturb_every,
            alpha_p_low=sim.alpha_p_low, alpha_p_high=sim.alpha_p_high,
            velocity_noise_sd=sim.velocity_noise_sd_m_s, phase_noise_sd=sim.phase_noise_sd_rad,
            period_noise_sd=sim.period_noise_sd_s, seed=sim.seed))
        per_trial = impacts.groupby("trial").size()
        lost = int((per_trial < sim.impacts_per_trial).sum() + (sim.trials - len(per_trial)))
        return impacts, params, {"gain_K": control.gain, "rate_c": control.rate,
                                 "source": "simulated", "trials_lost": lost}
    table = read_impacts(source)
    impacts = table.frame
    # the model at the data's racket (section 7: "identical to the ones of the experiment"),
    # alpha_0 and g the data's unless the user set them
    run = options or RunOptions()
    model = model_for_data(table, config, run, source)
    data_params = model_at_data(table, model, need="fixed point",
                                racket_period=config.fit.racket_period_s, record=run.record)
    return impacts, data_params, {"model": model, "gain_K": math.nan, "rate_c": math.nan,
                                  "source": "data", "trials_lost": math.nan}


def align_frame(impacts: pd.DataFrame, params: ModelParams, n_after: int) -> dict:
    """Mean responses by direction (``analysis.control_design.align_perturbations``: one
    function the shared data-side alignment can replace)."""
    alpha = impacts["alpha"].to_numpy() if "alpha" in impacts else None
    return align_perturbations(impacts["trial"].to_numpy(), impacts["k"].to_numpy(),
                               impacts["v_m_s"].to_numpy(), impacts["theta_rad"].to_numpy(),
                               impacts["racket_period_s"].to_numpy(),
                               impacts["perturbed"].to_numpy(), alpha=alpha,
                               alpha_0=params.alpha, n_after=n_after)


#: perturbation windows a direction needs to enter the fit of K and c (its mean's SE)
MIN_WINDOWS = 2


def fit_frames(config: ControlConfig, inputs=None) -> dict[str, pd.DataFrame]:
    """fit.csv (K, c with confidence intervals, the fitted model's eigenvalues, offsets) and
    fit_responses.csv (mean responses and the fitted model's) from ``fit_inputs``."""
    impacts, params, truth = fit_inputs(config) if inputs is None else inputs
    block = config.fit
    responses = align_frame(impacts, params, block.impacts_after)
    if not responses:
        raise ConfigError(f"data: no perturbation window of {block.impacts_after + 1} "
                          "consecutive impacts inside one trial (fit.impacts_after)")
    # a mean of one window has no standard error to weigh the fit by: the least squares
    # would stay at its starting point and report it as the fit
    if all(r.n_events < MIN_WINDOWS for r in responses.values()):
        counts = ", ".join(f"{r.n_events} {d}" for d, r in responses.items())
        raise ConfigError(f"data: too few perturbations to fit K and c: {counts} window(s) "
                          f"of {block.impacts_after + 1} impacts, fewer than {MIN_WINDOWS} in "
                          "every direction (fit.impacts_after)")
    responses = {d: r for d, r in responses.items() if r.n_events >= MIN_WINDOWS}
    switch = config.model.control.switch  # when the racket takes the new period (the data's)

    def controller_of(gain: float, rate: float) -> PeriodController:
        return PeriodController(gain, rate, switch=switch)

    fit = fit_period_control(params, list(responses.values()),
                             initial=(block.initial_gain, block.initial_rate),
                             confidence=block.confidence, controller_of=controller_of)
    truth_radius = (float(spectral_radius_3x3(controlled_jacobian(
        params, controller_of(truth["gain_K"], truth["rate_c"]))))
        if truth["source"] == "simulated" else math.nan)
    n_events = {d: r.n_events for d, r in responses.items()}
    rows = [
        ("gain_K", "1", truth["gain_K"], fit.gain, *fit.gain_ci),
        ("rate_c", "1/impact", truth["rate_c"], fit.rate, *fit.rate_ci),
        ("spectral_radius", "1", truth_radius, fit.spectral_radius, math.nan, math.nan),
    ]
    for i, lam in enumerate(fit.eigenvalues, 1):
        rows.append((f"lambda{i}_abs", "1", math.nan, abs(lam), math.nan, math.nan))
    rows += [
        ("offset_v", "m/s", math.nan, fit.offsets[0], math.nan, math.nan),
        ("offset_theta", "deg", math.nan, math.degrees(fit.offsets[1]), math.nan, math.nan),
        ("offset_tau", "ms", math.nan, 1e3 * fit.offsets[2], math.nan, math.nan),
        ("reduced_chi2", "1", math.nan, fit.reduced_chi2, math.nan, math.nan),
        ("events_decrease", "count", math.nan, n_events.get("decrease", 0), math.nan, math.nan),
        ("events_increase", "count", math.nan, n_events.get("increase", 0), math.nan, math.nan),
        ("trials_lost", "count", math.nan, truth["trials_lost"], math.nan, math.nan),
        ("model_alpha_0", "1", math.nan, params.alpha, math.nan, math.nan),
        ("model_racket_period", "s", math.nan, params.racket_period, math.nan, math.nan),
        ("model_racket_amplitude", "m", math.nan, params.racket_amplitude, math.nan, math.nan),
    ]
    table = pd.DataFrame(rows, columns=["quantity", "unit", "truth", "estimate", "ci_low",
                                        "ci_high"])
    table.insert(0, "source", truth["source"])
    fitted = controller_of(fit.gain, fit.rate)
    offsets = np.array(fit.offsets)
    curves = []
    for direction, r in responses.items():
        mean = np.stack([r.dv_m_s, r.dtheta_rad, r.dtau_s])
        se = np.stack([r.se_v_m_s, r.se_theta_rad, r.se_tau_s])
        model = predicted_deviations(params, fitted, mean[:, 0] - offsets,
                                     block.impacts_after) + offsets[:, None]
        for j in range(block.impacts_after + 1):
            curves.append({"direction": direction, "k": j, "events": r.n_events,
                           "dv_m_s": mean[0, j], "se_v_m_s": se[0, j],
                           "dtheta_deg": math.degrees(mean[1, j]),
                           "se_theta_deg": math.degrees(se[1, j]),
                           "dtau_ms": 1e3 * mean[2, j], "se_tau_ms": 1e3 * se[2, j],
                           "fit_dv_m_s": model[0, j], "fit_dtheta_deg": math.degrees(model[1, j]),
                           "fit_dtau_ms": 1e3 * model[2, j]})
    return {"fit.csv": table, "fit_responses.csv": pd.DataFrame(curves)}


# -- run ------------------------------------------------------------------------------------------
def run(config: ControlConfig, options: RunOptions) -> ExperimentResult:
    with_data = data_source(config, options) is not None
    if not with_data:
        config.params.fixed_point()  # NoFixedPointError: one line naming model.racket_amplitude
    fit_data = fit_inputs(config, options)  # a bad --data file fails before any work
    params = fit_data[1]  # with --data: the model at the data's racket, alpha and g
    if with_data:
        data_model_text = fit_data[2]["model"].text()
        where = (f"data: {data_label(config, options)}: the model at the data's racket a_r = "
                 f"{params.racket_amplitude:.4g} m, tau = {params.racket_period:.4g} s, "
                 f"{data_model_text}")
        try:
            params.fixed_point()
        except ModelError as exc:
            raise ConfigError(f"{where}: {exc}") from None
    options.progress.start(6, "control: stability, impulses, thresholds, basins, fit")
    frames = radius_frames(params, config)
    options.progress.advance(1)
    frames.update(impulse_frames(params, config))
    frames["relaxation_gain.csv"] = relaxation_gain_frame(params, config)
    options.progress.advance(1)
    frames["threshold.csv"] = threshold_frame(params, config)
    options.progress.advance(1)
    frames.update(basin_frames(params, config, options))
    frames["acf.csv"] = correlations_frame(params, config)
    frames.update(fit_frames(config, fit_data))
    options.progress.advance(1)
    from .plotting import caption_figures

    figures = draw(frames) if options.figures else {}
    caption_figures(figures, params, f"controller K = {config.model.control.gain:g}, "
                    f"c = {config.model.control.rate:g}"
                    + (f"; fit to data: {data_label(config, options)} (the model at the data's "
                       "racket)" if with_data else ""))
    summary = summary_lines(frames)
    if with_data:
        summary.insert(0, f"data {data_label(config, options)}: every result at the data's "
                       f"racket a_r = {params.racket_amplitude:.4g} m, tau = "
                       f"{params.racket_period:.4g} s; {data_model_text}")
    return ExperimentResult(frames=frames, figures=figures, summary=summary)


def summary_lines(frames: dict[str, pd.DataFrame]) -> list[str]:
    eigen = frames["eigen.csv"].set_index("model")
    lines = []
    for label, row in eigen.iterrows():
        lines.append(f"{label}: K = {row.gain_K:.4g}, c = {row.rate_c:.4g}, spectral radius "
                     f"{row.spectral_radius:.4f}")
    regions = frames["regions.csv"].set_index("region")
    for name, row in regions.iterrows():
        lines.append(f"radius < {row.radius_below:g} ({name}): area {row.area_K_c:.4g} in "
                     f"(K, c), K in [{row.gain_min_K:.3g}, {row.gain_max_K:.3g}], "
                     f"c in [{row.rate_min_c:.3g}, {row.rate_max_c:.3g}]"
                     + (" (cut by the grid's edge)" if row.touches_grid_edge else ""))
    relax = frames["relaxation.csv"]
    for model in MODELS:
        part = relax[relax.model == model]
        lines.append(f"{model}: impacts to relax " + ", ".join(
            f"{r.alpha_p:g}: {relaxed_text(r.relaxation_impacts)}" for r in part.itertuples()))
    th = frames["threshold.csv"]
    for model in MODELS:
        part = th[th.model == model].set_index("direction")
        lines.append(f"{model}: leaves the basin above alpha_p = "
                     f"{_fmt(part.loc['increase', 'alpha_p_threshold'])}, below "
                     f"{_fmt(part.loc['decrease', 'alpha_p_threshold'])}")
    frac = frames["basin_fractions.csv"]
    lines.append("basin period-1 fraction: " + ", ".join(
        f"{m} {frac[(frac.model == m) & (frac.outcome == 'period1')].fraction.iloc[0]:.4f}"
        for m in MODELS))
    fit = frames["fit.csv"].set_index("quantity")
    source = fit.source.iloc[0]
    lines.append(f"fit ({source}): K = {fit.loc['gain_K', 'estimate']:.4f} "
                 f"[{fit.loc['gain_K', 'ci_low']:.4f}, {fit.loc['gain_K', 'ci_high']:.4f}], "
                 f"c = {fit.loc['rate_c', 'estimate']:.4f} "
                 f"[{fit.loc['rate_c', 'ci_low']:.4f}, {fit.loc['rate_c', 'ci_high']:.4f}]"
                 + (f" (truth K = {fit.loc['gain_K', 'truth']:g}, c = "
                    f"{fit.loc['rate_c', 'truth']:g})" if source == "simulated" else ""))
    if fit.loc["gain_K", "ci_low"] <= 0.0 <= fit.loc["gain_K", "ci_high"]:
        lines.append("fit: K's interval includes 0, no period control is detected: c then "
                     "only describes how the racket period relaxes on its own, and the fitted "
                     "model's spectral radius (|1 - c| when that is the largest) says nothing "
                     "about the ball; read the passive eigenvalues (eq. 10) for these data")
    chi2, lost = fit.loc["reduced_chi2", "estimate"], fit.loc["trials_lost", "estimate"]
    if chi2 > 3.0:
        lines.append(f"fit: reduced chi2 = {chi2:.3g} >> 1: the controlled map does not describe "
                     "these mean responses (see fit.csv, control_fit.png)")
    if lost > 0:
        lines.append(f"fit: {lost:g} simulated trial(s) lost the ball (cut there); responses "
                     "close to a loss are far from the fixed point")
    return lines


def _fmt(x: float) -> str:
    return "never (scan end)" if not np.isfinite(x) else f"{x:.4f}"


# -- figures --------------------------------------------------------------------------------------
def passive_model(frames: dict[str, pd.DataFrame]) -> ModelParams:
    """The model a run was made at, recovered from its tables alone (a figure is drawn from
    its CSVs): tau from the passive impulse response's racket period, g from v~ = g tau / 2
    (eq. 7), alpha from the passive Jacobian's determinant alpha^2 (eq. 9: the product of the
    eigenvalues of eq. 10 is alpha^2), and a_r from theta~ (eq. 8: cos theta~ is inversely
    proportional to a_r at the other parameters).

    Parameters
    ----------
    frames : dict of DataFrame
        The run's tables; ``impulse.csv`` and ``eigen.csv`` are read.

    Returns
    -------
    ModelParams
        alpha, g, racket amplitude and period, to within the tables' rounding.
    """
    impulse = frames["impulse.csv"]
    row = impulse[(impulse.model == "passive") & (impulse.k == 0)].iloc[0]
    tau = float(row.racket_period_s)
    g = 2.0 * float(row.v_m_s - row.dv_m_s) / tau
    eig = frames["eigen.csv"].set_index("model").loc["passive"]
    alpha = math.sqrt(abs(complex(eig.lambda1_re, eig.lambda1_im)
                          * complex(eig.lambda2_re, eig.lambda2_im)))
    theta = math.radians(float(row.theta_deg - row.dtheta_deg))
    amplitude = eq8_amplitude(alpha, g, 2.0 * math.pi / tau, theta)
    return ModelParams(alpha, g, amplitude, tau)


def at_section7(frames: dict[str, pd.DataFrame]) -> bool:
    """Whether the run's model (:func:`passive_model`) is section 7's (the paper's Figs. 3, 9
    parameters) to 1e-6: only there are the subject's numbers (Fig. 9: about one impact to
    relax, eigenvalues below 0.2) references for the figure."""
    model = passive_model(frames)
    return all(math.isclose(getattr(model, name), getattr(paper.FIG3_MODEL, name), rel_tol=1e-6)
               for name in ("alpha", "g", "racket_amplitude", "racket_period"))


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    return {"control_stability.png": draw_stability(frames),
            "control_impulse.png": draw_impulse(frames),
            "control_basin.png": draw_basin(frames),
            "control_acf.png": draw_acf(frames),
            "control_fit.png": draw_fit(frames)}


def draw_acf(frames):
    from .plotting import new_figure

    df = frames["acf.csv"]
    fig, axes = new_figure(2, 2, width=11.0, height=7.5, sharex=True)
    first = df.iloc[0]
    for (r, c), pair in PANELS.items():
        ax = axes[r, c]
        d = df[df.pair == pair].sort_values("lag")
        ax.plot(d.lag, d.passive_theory, "o-", color="0.6", ms=4,
                label=f"passive, eq. 19 (SD $v$ {first.passive_sd_v_m_s:.3f} m/s, "
                      f"$\\theta$ {first.passive_sd_theta_deg:.2f} deg)")
        ax.plot(d.lag, d.controlled_theory, "o-", color="k", ms=4,
                label=f"controlled, eq. 19 with the 3$\\times$3 Jacobian (SD $v$ "
                      f"{first.controlled_sd_v_m_s:.3f} m/s, $\\theta$ "
                      f"{first.controlled_sd_theta_deg:.2f} deg)")
        ax.errorbar(d.lag, d.controlled_sample_mean, yerr=2 * d.controlled_sample_se, fmt="x",
                    color="tab:red", ms=6, label=f"controlled map, {int(first.runs)} runs "
                    r"($\pm$2 SE)")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_title(TITLES[pair], fontsize=10)
        ax.set_ylabel("correlation")
        integer_axis(ax)
    for ax in axes[1]:
        ax.set_xlabel(LAG_LABEL)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Correlation functions (paper Fig. 8) without and with racket period control "
                 "(the model's parameters below)")
    return fig


def _radius_image(ax, frame: pd.DataFrame, target: float, levels_extra=(0.5,)):
    gains, rates = np.unique(frame.gain_K), np.unique(frame.rate_c)
    radius = frame.pivot(index="rate_c", columns="gain_K", values="spectral_radius").to_numpy()
    unstable = ~radius_below(radius)  # grey, as _region counts (neutral: K = 1)
    im = ax.pcolormesh(gains, rates, np.ma.masked_where(unstable, radius), cmap="viridis",
                       vmin=0.0, vmax=1.0, shading="nearest")
    ax.set_facecolor("0.85")
    ax.contour(gains, rates, radius, levels=[target], colors="w", linewidths=1.4)
    ax.contour(gains, rates, radius, levels=list(levels_extra), colors="w", linewidths=0.8,
               linestyles=":")
    ax.set_xlabel("gain $K$ (1: the period follows the ball's flight time)")
    ax.set_ylabel("rate $c$ (per impact; 1: immediate)")
    return im


def _controller_markers(ax, eigen: pd.DataFrame, window=None):
    styles = {"controlled": ("s", "white", "configured"), "fastest": ("*", "red", "fastest")}
    for row in eigen.itertuples():
        if row.model == "passive":
            continue
        marker, colour, label = styles.get(row.model, ("^", "orange", row.model))
        if window is not None:
            (k0, k1), (c0, c1) = window
            if not (k0 <= row.gain_K <= k1 and c0 <= row.rate_c <= c1):
                continue
        ax.plot(row.gain_K, row.rate_c, marker, ms=10 if marker == "*" else 7, mfc=colour,
                mec="k", label=f"{label}: $K$ = {row.gain_K:.3f}, $c$ = {row.rate_c:.3f}, "
                f"radius {row.spectral_radius:.3f}")


def draw_stability(frames):
    from .plotting import new_figure

    grid, zoom = frames["radius_map.csv"], frames["radius_zoom.csv"]
    line = frames["radius_gain.csv"]
    eigen = frames["eigen.csv"]
    target = float(frames["regions.csv"].set_index("region").loc["fast", "radius_below"])
    fig, axes = new_figure(2, 2, width=13.0, height=10.5)
    im = _radius_image(axes[0, 0], grid, target)
    _controller_markers(axes[0, 0], eigen)
    axes[0, 0].set_title(f"Spectral radius over ($K$, $c$); white: {target:g}, dotted: 0.5")
    axes[0, 0].legend(fontsize=7, loc="lower left")
    _radius_image(axes[0, 1], zoom, target, levels_extra=(0.25, 0.3))
    window = ((zoom.gain_K.min(), zoom.gain_K.max()), (zoom.rate_c.min(), zoom.rate_c.max()))
    _controller_markers(axes[0, 1], eigen, window)
    axes[0, 1].set_title(f"Around the fastest: white {target:g}, dotted 0.25, 0.3")
    axes[0, 1].legend(fontsize=7, loc="lower left")
    fig.colorbar(im, ax=axes[0, :], label="spectral radius of the 3$\\times$3 Jacobian "
                 r"(grey: $\geq 1$, not stable)", shrink=0.9)

    ax = axes[1, 0]
    rate = line.rate_c.iloc[0]
    passive = float(eigen.set_index("model").loc["passive", "spectral_radius"])
    section7 = at_section7(frames)  # the subject's numbers are references there only
    ax.plot(line.gain_K, line.spectral_radius, "k-", label=f"$c$ = {rate:g}")
    ax.axhline(passive, color="0.5", ls="--", label=f"passive $K$ = 0: {passive:.2f} (eq. 10)")
    ax.axhline(target, color="tab:red", ls=":",
               label=f"data: < {target:g} (section 7)" if section7
               else f"target {target:g} (radius.target_radius)")
    ax.axhline(1.0, color="k", lw=0.6)
    ax.set_ylim(0.0, 1.5)
    ax.set_xlabel("gain $K$")
    ax.set_ylabel("spectral radius")
    ax.set_title(f"Linear: spectral radius along $K$ at $c$ = {rate:g}")
    ax.legend(fontsize=8)

    ax = axes[1, 1]
    relax = frames["relaxation_gain.csv"]
    for i, (alpha_p, part) in enumerate(relax.groupby("alpha_p")):
        n = part.relaxation_impacts.where(part.relaxation_impacts >= 0)
        ax.plot(part.gain_K, n, ["-o", "-s", "--^", "--D"][i % 4], ms=3,
                label=f"$\\alpha_p$ = {alpha_p:g}")
    if section7:
        ax.axhline(1.0, color="tab:red", ls=":", label="the subject: about 1 impact (Fig. 9)")
    ax.set_yscale("log")
    ax.set_xlabel("gain $K$")
    ax.set_ylabel("impacts to relax (full map; missing: never)")
    ax.set_title(f"Full map: perturbations along $K$ at $c$ = {rate:g}")
    ax.legend(fontsize=8)
    return fig


def draw_impulse(frames):
    from .plotting import new_figure

    df = frames["impulse.csv"]
    outcome = frames["relaxation.csv"].set_index(["model", "alpha_p"]).outcome
    first = df[(df.k == 0) & (df.model == "passive")].set_index("alpha_p").dv_m_s
    sides = (sorted(first[first < 0].index, key=lambda a: -a),
             sorted(first[first >= 0].index))
    row0 = df.iloc[0]
    v_st, th_st = row0.v_m_s - row0.dv_m_s, (row0.theta_deg - row0.dtheta_deg) % 360.0
    fig, axes = new_figure(3, 2, width=11.0, height=9.0, sharex=True)
    styles = {"passive": dict(color="0.6", ls="-"), "controlled": dict(color="k", ls="-")}
    markers = ["o", "s", "^", "D"]
    for col, group in enumerate(sides):
        for i, alpha_p in enumerate(group):
            for model in MODELS:
                d = df[(df.alpha_p == alpha_p) & (df.model == model)].sort_values("k")
                label = f"{model}, $\\alpha_p$ = {alpha_p:g}"
                if outcome.get((model, alpha_p), "period1") != "period1":
                    label += f" ({outcome[(model, alpha_p)].replace('_', ' ')})"
                kw = dict(styles[model], marker=markers[i % 4], ms=4,
                          ls="-" if i == 0 else "--", label=label)
                axes[0, col].plot(d.k, d.v_m_s, **kw)
                axes[1, col].plot(d.k, th_st + d.dtheta_deg, **kw)
                axes[2, col].plot(d.k, d.dtau_ms, **kw)
        axes[0, col].axhline(v_st, color="k", lw=0.8, ls=":")
        axes[1, col].axhline(th_st, color="k", lw=0.8, ls=":")
        axes[2, col].axhline(0.0, color="k", lw=0.8, ls=":")
        axes[0, col].set_title(perturbation_title(col == 0))
        axes[2, col].set_xlabel(IMPACT_AFTER_LABEL)
        integer_axis(*axes[:, col])
        if group:
            axes[0, col].legend(fontsize=7)
    axes[0, 0].set_ylabel(VELOCITY_LABEL)
    axes[1, 0].set_ylabel(PHASE_LABEL)  # theta~ + the wrapped difference, axis fitted to it
    axes[2, 0].set_ylabel(r"racket period $-\ \bar\tau$ (ms)")
    fig.suptitle("Impulse responses, passive (grey) vs period control (black): paper Fig. 9 "
                 "with the model's Fig. 11 (bottom)")
    return fig


def draw_basin(frames):
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    from .plotting import new_figure

    basin, frac = frames["basin.csv"], frames["basin_fractions.csv"]
    fig, axes = new_figure(1, 2, width=12.0, height=5.6, sharey=True)
    cmap = ListedColormap([OUTCOME_COLOURS[o] for o in OUTCOMES])
    norm = BoundaryNorm(np.arange(len(OUTCOMES) + 1) - 0.5, cmap.N)
    for ax, model in zip(axes[0], MODELS):
        part = basin[basin.model == model]
        codes = pd.Categorical(part.outcome, categories=list(OUTCOMES)).codes
        th, vs = np.unique(part.theta0_deg), np.unique(part.v0_m_s)
        image = np.full((vs.size, th.size), OUTCOMES.index("undecided"), dtype=int)
        image[np.searchsorted(vs, part.v0_m_s), np.searchsorted(th, part.theta0_deg)] = codes
        dth, dv = th[1] - th[0], vs[1] - vs[0]
        ax.imshow(image, origin="lower", aspect="auto", cmap=cmap, norm=norm,
                  interpolation="nearest",
                  extent=(th[0] - dth / 2, th[-1] + dth / 2, vs[0] - dv / 2, vs[-1] + dv / 2))
        p1 = frac[(frac.model == model) & (frac.outcome == "period1")].fraction.iloc[0]
        ax.set_title(f"{model}: period-1 fraction {p1:.3f}")
        ax.set_xlabel(r"initial phase $\theta_0$ (deg)")
    axes[0, 0].set_ylabel(r"initial velocity $v_0$ (m/s)")
    fig.legend(handles=[Patch(facecolor=OUTCOME_COLOURS[o], edgecolor="0.3",
                              label=OUTCOME_LABELS[o]) for o in OUTCOMES],
               loc="outside lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle("Domain of attraction (paper Fig. 4) without and with racket period control")
    return fig


def draw_fit(frames):
    from .plotting import new_figure

    curves, fit = frames["fit_responses.csv"], frames["fit.csv"].set_index("quantity")
    fig, axes = new_figure(1, 3, width=13.0, height=4.2, sharex=True)
    columns = (("dv_m_s", "se_v_m_s", "fit_dv_m_s", "$v_k$ $-$ mean (m/s)"),
               ("dtheta_deg", "se_theta_deg", "fit_dtheta_deg", r"$\theta_k$ $-$ mean (deg)"),
               ("dtau_ms", "se_tau_ms", "fit_dtau_ms", "racket period $-$ mean (ms)"))
    colours = {"decrease": "0.55", "increase": "k"}
    for ax, (mean, se, model, label) in zip(axes[0], columns):
        for direction, part in curves.groupby("direction"):
            c = colours.get(direction, "b")
            ax.errorbar(part.k, part[mean], yerr=part[se], fmt="o", color=c, ms=4, capsize=2,
                        label=f"{direction} ({int(part.events.iloc[0])} perturbations)")
            ax.plot(part.k, part[model], "-", color=c, lw=1, label=f"fit, {direction}")
        ax.axhline(0.0, color="k", lw=0.6, ls=":")
        ax.set_xlabel(IMPACT_AFTER_LABEL_NARROW)
        ax.set_ylabel(label)
        integer_axis(ax)
    axes[0, 0].legend(fontsize=7)
    source = fit.source.iloc[0]
    k, c = fit.loc["gain_K"], fit.loc["rate_c"]
    title = (f"Fit to {source} perturbation trials: $K$ = {k.estimate:.3f} "
             f"[{k.ci_low:.3f}, {k.ci_high:.3f}], $c$ = {c.estimate:.3f} "
             f"[{c.ci_low:.3f}, {c.ci_high:.3f}], spectral radius "
             f"{fit.loc['spectral_radius', 'estimate']:.3f}")
    if source == "simulated":
        title += f" (truth $K$ = {k.truth:g}, $c$ = {c.truth:g})"
    fig.suptitle(title, fontsize=10)
    return fig


EXPERIMENT = Experiment(name="control", schema=ControlConfig, run=run, draw=draw)
