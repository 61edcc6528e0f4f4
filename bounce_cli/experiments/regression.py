"""Fig. 7 and eq. 15 (section 5): trial means of racket amplitude regressed on squared period.

Either simulated trials (target heights -> periods, eq. 15 amplitudes at per-trial impact
phases plus motor noise, each run through the stochastic map for a 40 s trial), or a
researcher's CSV (``data:`` / ``--data``). Fit: ordinary least squares of a_r on tau^2 with
t-based confidence intervals, per condition when the data has a ``condition`` column, against
eq. 15's two predictions: slope (1/4 pi)(1-alpha)/(1+alpha) g / cos(theta) at the mean observed
phase, and zero intercept.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import numpy as np
import pandas as pd
from pydantic import Field

from ..paper import values as paper
from ..runtime.config import (
    ConfigError,
    DataFiles,
    ExperimentConfig,
    StrictModel,
    data_files,
    data_text,
    show_value,
)
from ..model.linear import stability
from ..errors import TooFewObservationsError
from ..model.params import ModelError, ModelParams, NoFixedPointError
from ..analysis.regression import (
    eq15_amplitude,
    eq15_slope,
    narrow_periods,
    ols_line,
    period_for_height,
    phase_from_slope,
    simulate_trial,
)
from .plotting import caption_figures, new_figure, publication_style
from .base import Experiment, ExperimentResult, RunOptions
from ..data.data_parameters import DataModel, ModelValue, trials_model
from ..data.impacts import read_data_csv
from ..data.plausibility import racket_warnings
from .data_side import is_impacts_table, trial_means_from_impacts

REQUIRED = ("a_r_m", "tau_s")
OPTIONAL = ("theta_deg", "alpha", "g", "condition")


class DesignBlock(StrictModel):
    target_heights_m: list[Annotated[float, Field(gt=0.0)]] = Field([0.4, 0.6, 0.8], min_length=2,
                                          description="ball heights above impact, m")
    subjects: int = Field(6, ge=1)
    trials_per_height: int = Field(3, ge=1, description="trials per subject and height")
    phase_mean_deg: float = Field(32.0, gt=0.0, lt=90.0, description="mean impact phase, deg")
    subject_phase_sd_deg: float = Field(3.0, ge=0.0, description="spread of subjects' means")
    phase_sd_deg: float = Field(2.0, ge=0.0, description="trial-to-trial phase spread, deg")
    period_sd_s: float = Field(0.01, ge=0.0, description="trial-to-trial period spread, s")
    amplitude_sd_m: float = Field(0.002, ge=0.0, description="motor noise in amplitude, m")


class MapNoiseBlock(StrictModel):
    q_v: float = Field(0.04, ge=0.0, description="m/s, eq. 16")
    q_theta: float = Field(0.05, ge=0.0, description="rad, eq. 18")
    duration_s: float = Field(40.0, gt=0.0, description="trial length, s")
    burn_in: int = Field(20, ge=0, description="bounces dropped at the start of a trial")


class RegressionConfig(ExperimentConfig):
    design: DesignBlock = DesignBlock()
    stochastic_map: MapNoiseBlock = MapNoiseBlock()
    confidence: float = Field(0.95, gt=0.0, lt=1.0, description="confidence level of the CIs")
    data: DataFiles = Field(None, description="CSV of real trials; replaces the simulation; "
                            "several: one session")
    seed: int = Field(0, ge=0)


# -- synthetic trials --------------------------------------------------------------------------
def simulate_trials(config: RegressionConfig, options: RunOptions) -> pd.DataFrame:
    d, m = config.design, config.stochastic_map
    alpha, g = config.model.alpha, config.model.g
    cells = [(s, h, t) for s in range(1, d.subjects + 1) for h in d.target_heights_m
             for t in range(1, d.trials_per_height + 1)]
    design_seed, trial_seeds = np.random.SeedSequence(config.seed).spawn(2)
    subject_rng = np.random.default_rng(design_seed)
    subject_phase = (d.phase_mean_deg
                     + d.subject_phase_sd_deg * subject_rng.standard_normal(d.subjects))
    options.progress.start(len(cells), "trials")
    rows = []
    for (subject, height, trial), seed in zip(cells, trial_seeds.spawn(len(cells))):
        draw_seed, map_seed = seed.spawn(2)
        rng = np.random.default_rng(draw_seed)
        z_phase, z_period, z_amp = rng.standard_normal(3)
        phase = math.radians(subject_phase[subject - 1] + d.phase_sd_deg * z_phase)
        tau = float(period_for_height(height, g)) + d.period_sd_s * z_period
        amplitude = float(eq15_amplitude(tau, phase, alpha, g)) + d.amplitude_sd_m * z_amp
        where = f"subject {subject}, height {height:g} m, trial {trial}"
        if not (tau > 0 and amplitude > 0):
            raise ModelError(f"{where}: drew period {tau:.4g} s, amplitude {amplitude:.4g} m; "
                             "reduce design.period_sd_s / design.amplitude_sd_m")
        params = ModelParams(alpha, g, amplitude, tau)
        try:
            st = stability(params)
        except NoFixedPointError:
            raise ModelError(
                f"{where}: drew amplitude {amplitude:.4g} m at period {tau:.4g} s, below the "
                f"{params.min_racket_amplitude():.4g} m a period-1 orbit needs (eq. 8); reduce "
                "design.amplitude_sd_m or design.phase_sd_deg") from None
        if not st.stable:
            raise ModelError(
                f"{where}: fixed point unstable (spectral radius {st.spectral_radius:.3g}) at the "
                f"drawn a_r={amplitude:.4g} m, tau={tau:.4g} s; reduce design.phase_sd_deg / "
                "design.subject_phase_sd_deg or move design.phase_mean_deg")
        means = simulate_trial(params, m.q_v, m.q_theta, m.duration_s, map_seed,
                               burn_in=m.burn_in)
        rows.append({
            "subject": subject, "target_height_m": height, "trial": trial,
            "a_r_m": amplitude, "tau_s": means.tau_s,
            "theta_deg": math.degrees(means.theta_rad), "alpha": alpha, "g": g,
            "racket_period_s": tau, "theta_drawn_deg": math.degrees(phase),
            "bounces": means.bounces, "lost": means.lost,
        })
        options.progress.advance(1)
    frame = pd.DataFrame(rows)
    if frame["lost"].sum() > len(frame) / 2:
        raise ModelError(f"{int(frame['lost'].sum())} of {len(frame)} simulated trials lost the "
                         "ball (it left the period-1 basin and stuck to the racket); lower the "
                         "map noise or move design.phase_mean_deg away from 0")
    return frame


# -- researcher's data -----------------------------------------------------------------------
def cell_text(path: Path, column: str, row: int) -> str:
    """A cell as the file holds it (pandas reads ``n/a``, ``NA``, ``-`` ... as NaN), for an
    error message: ``'n/a'``, or ``an empty cell``."""
    raw = pd.read_csv(path, dtype=str, keep_default_na=False, na_filter=False)
    raw.columns = [str(c).strip() for c in raw.columns]
    text = raw[column].iloc[row]
    return repr(text) if text.strip() else "an empty cell"


def read_trials(path_text: str) -> pd.DataFrame:
    """Read and check a trials CSV: a_r_m, tau_s required; theta_deg, alpha, g, condition
    optional. Any problem is a one-line ConfigError naming ``data`` and the column."""
    path = Path(path_text)
    frame = read_data_csv(path)
    missing = [c for c in REQUIRED if c not in frame.columns]
    if missing:
        raise ConfigError(f"data: {path}: missing column(s) {', '.join(missing)} "
                          f"(required: {', '.join(REQUIRED)}; optional: {', '.join(OPTIONAL)})")
    if frame.empty:
        raise ConfigError(f"data: {path}: no rows")
    checks = {"a_r_m": "> 0", "tau_s": "> 0", "theta_deg": "in (-90, 90)", "alpha": "in [0, 1)",
              "g": "> 0"}
    for column, rule in checks.items():
        if column not in frame.columns:
            continue
        values = pd.to_numeric(frame[column], errors="coerce")
        bad = values.isna() | ~np.isfinite(values.astype(float))
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise ConfigError(f"data: {path}: column {column}: not a number in data row {row + 1} "
                              f"(got {cell_text(path, column, row)})")
        ok = {"> 0": values > 0, "in (-90, 90)": values.abs() < 90,
              "in [0, 1)": (values >= 0) & (values < 1)}[rule]
        if not ok.all():
            row = int(np.flatnonzero(~ok.to_numpy())[0])
            raise ConfigError(f"data: {path}: column {column}: must be {rule} "
                              f"(data row {row + 1}: {show_value(values.iloc[row])})")
        frame[column] = values.astype(float)
    if "condition" in frame.columns:
        if frame["condition"].isna().any():
            row = int(np.flatnonzero(frame["condition"].isna().to_numpy())[0])
            raise ConfigError(f"data: {path}: column condition: empty in data row {row + 1}")
        frame["condition"] = frame["condition"].astype(str)
    return frame


# -- fit ----------------------------------------------------------------------------------


def fit_frame(trials: pd.DataFrame, config: RegressionConfig,
              model: DataModel | None = None) -> pd.DataFrame:
    """fit.csv: one row per condition ("all" without a condition column); simulated trials
    that lost the ball are left out. alpha and g of eq. 15: ``model``'s (a trials CSV's,
    ``data_parameters.trials_model``) where set, else each condition's column (a ``column``
    source, or simulated trials: the config's)."""
    if "lost" in trials.columns:
        trials = trials[~trials["lost"].astype(bool)]
    groups = (trials.groupby("condition", sort=True) if "condition" in trials.columns
              else [("all", trials)])
    rows = []
    for condition, group in groups:
        x = group["tau_s"].to_numpy() ** 2
        y = group["a_r_m"].to_numpy()
        try:
            fit = ols_line(x, y, config.confidence)
        except TooFewObservationsError as exc:  # its class kept: a study skips the analysis
            raise TooFewObservationsError(f"data: condition {condition!r}: {exc}") from None
        except ModelError as exc:
            raise ConfigError(f"data: condition {condition!r}: {exc}") from None
        alpha = _eq15_value(group, "alpha", None if model is None else model.alpha,
                            config.model.alpha, condition)
        g = _eq15_value(group, "g", None if model is None else model.g, config.model.g,
                        condition)
        theta = (math.radians(group["theta_deg"].mean()) if "theta_deg" in group.columns
                 else math.nan)
        predicted = float(eq15_slope(theta, alpha, g)) if math.isfinite(theta) else math.nan
        rows.append({
            "condition": condition, "n": len(group),
            "slope": float(fit.slope), "slope_ci_low": float(fit.slope_ci_low),
            "slope_ci_high": float(fit.slope_ci_high),
            "intercept": float(fit.intercept), "intercept_ci_low": float(fit.intercept_ci_low),
            "intercept_ci_high": float(fit.intercept_ci_high),
            "r2": float(fit.r2), "predicted_slope": predicted,
            "mean_theta_deg": math.degrees(theta) if math.isfinite(theta) else math.nan,
            "implied_theta_deg": math.degrees(float(phase_from_slope(fit.slope, alpha, g))),
            "alpha": alpha, "g": g, "confidence": config.confidence,
            "slope_ci_covers_prediction": bool(fit.slope_ci_low <= predicted <= fit.slope_ci_high)
            if math.isfinite(predicted) else None,
            "intercept_ci_covers_zero": bool(fit.intercept_ci_low <= 0.0 <= fit.intercept_ci_high),
        })
    return pd.DataFrame(rows)


def _eq15_value(group: pd.DataFrame, column: str, given: ModelValue | None, default: float,
                condition) -> float:
    """alpha or g of eq. 15 for one condition: ``given`` (set by the user, or the config's)
    unless that is the trials' own column (or there is none: simulated trials), whose one
    value in the condition is taken."""
    if given is not None and given.source != "column":
        return given.value
    return _constant(group, column, default, condition)


def _constant(group: pd.DataFrame, column: str, default: float, condition) -> float:
    if column not in group.columns:
        return float(default)
    values = group[column].unique()
    if len(values) != 1:
        raise ConfigError(f"data: column {column}: differs within condition {condition!r} "
                          "(eq. 15's slope needs one value per condition)")
    return float(values[0])


def with_squared_period(trials: pd.DataFrame) -> pd.DataFrame:
    """trials.csv's rows with eq. 15's abscissa, the squared racket period ``tau2_s2``."""
    return trials.assign(tau2_s2=trials["tau_s"] ** 2)


def run(config: RegressionConfig, options: RunOptions, source=None) -> ExperimentResult:
    """``source``: an impacts table in memory, ``(label, frame)`` (default:
    ``options.impacts``, else ``config.data``)."""
    source = options.impacts if source is None else source
    # None: simulated trials
    data_label = (data_text(config.data) or None) if source is None else source[0]
    at_model = ""  # with data: the model's alpha and g and where they came from
    model: DataModel | None = None  # with a trials CSV: alpha and g of eq. 15
    impacts_source = source if source is not None else (
        config.data if config.data is not None and all(
            is_impacts_table(p) for p in data_files(config.data)) else None)
    if impacts_source is not None:
        trials, impacts_model = trial_means_from_impacts(impacts_source, config, options)
        described = (f"{'data ' if source is None else ''}{data_label} (impacts averaged per "
                     f"trial); {impacts_model.text()}")
        at_model = f"; {impacts_model.text()}"
    elif config.data is not None:  # several trials CSVs: their trials together
        trials = pd.concat([read_trials(p) for p in data_files(config.data)],
                           ignore_index=True)
        model = trials_model(trials, data_label, config.model, options.model_set_by_user)
        options.record["model_at_data"] = model.record()
        described = f"data {data_label}; {model.text()}"
        at_model = f"; {model.text()}"
        for message in racket_warnings(trials["a_r_m"], trials["tau_s"],
                                       f"data: {data_label}: column a_r_m",
                                       f"data: {data_label}: column tau_s"):
            options.warn(message)
    else:
        trials = simulate_trials(config, options)
        described = (f"{len(trials)} simulated trials ({int(trials['lost'].sum())} lost the "
                     "ball and are not fitted)")
    trials = with_squared_period(trials)
    fitted = trials[~trials["lost"].astype(bool)] if "lost" in trials.columns else trials
    groups = (fitted.groupby("condition") if "condition" in fitted.columns
              else [("all", fitted)])
    narrow = {}  # condition -> the message saying its tau^2 spans nothing
    for condition, group in groups:
        why = narrow_periods(group["tau_s"])
        if why:
            narrow[condition] = f"condition {condition!r}: {why}"
    if narrow and len(narrow) == len(groups):  # no line anywhere: nothing to report
        raise TooFewObservationsError(f"{data_label or 'simulated trials'}: "
                                      + "; ".join(narrow.values()))
    for message in narrow.values():  # the other conditions' lines stand; not these
        options.warn(f"{message}: not fitted (its trials are in trials.csv)")
    fit = fit_frame(trials[~trials["condition"].isin(list(narrow))] if narrow else trials,
                    config, model)
    figures = draw({"trials.csv": trials, "fit.csv": fit}) if options.figures else {}
    if data_label is not None:
        caption_figures(figures, None, f"data: {data_label}{at_model}")
    else:
        caption_figures(figures, None, f"simulated trials: alpha = {config.model.alpha:g}, "
                        f"g = {config.model.g:g} m/s^2; seed {config.seed}")
    # the paper's R^2 (section 5) are of its subjects' trials; beside a simulation of them only
    fig7_like = data_label is None and (config.model.alpha, config.model.g) == (
        paper.FIG3_MODEL.alpha, paper.FIG3_MODEL.g)
    r2_paper = (f" (paper, its subjects: {paper.FIG7_R2['vision'].text} vision / "
                f"{paper.FIG7_R2['no vision'].text} no vision)") if fig7_like else ""
    pct = f"{config.confidence:.0%}"
    lines = [f"{described}; OLS of a_r on tau^2, {pct} confidence intervals"]
    for row in fit.itertuples():
        lines.append(
            f"({row.condition}) slope {row.slope:.4f} m/s^2 [{row.slope_ci_low:.4f}, "
            f"{row.slope_ci_high:.4f}] vs eq. 15 {row.predicted_slope:.4f}; intercept "
            f"{row.intercept * 100:.2f} cm [{row.intercept_ci_low * 100:.2f}, "
            f"{row.intercept_ci_high * 100:.2f}] vs 0; R^2 {row.r2:.3f}{r2_paper}")
    return ExperimentResult(frames={"trials.csv": trials, "fit.csv": fit}, figures=figures,
                            summary=lines)


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    trials, fit = frames["trials.csv"], frames["fit.csv"]
    fig, axes = new_figure(1, 1, width=7, height=5.2)
    ax = axes[0, 0]
    has_condition = "condition" in trials.columns
    # the axis spans the trials drawn: a condition without a line (one racket period) is
    # neither fitted nor drawn, and would stretch it over nothing
    drawn = (trials[trials["condition"].astype(str).isin(fit["condition"].astype(str))]
             if has_condition else trials)
    if "lost" in drawn.columns:
        drawn = drawn[~drawn["lost"].astype(bool)]
    x_max = float(np.nanmax((drawn if len(drawn) else trials)["tau_s"] ** 2)) * 1.08
    xs = np.linspace(0.0, x_max, 50)
    colors = ["k", "tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange"]
    # a marker of its own per condition, each larger than the one before: conditions whose
    # trial means coincide (one racket design for both) stay visible, one around the other
    markers = [("o", 5), ("s", 7.5), ("^", 9), ("D", 8), ("v", 10), ("P", 10)]
    for i, row in enumerate(fit.itertuples()):
        color = colors[i % len(colors)]
        marker, size = markers[i % len(markers)]
        group = trials[trials["condition"].astype(str) == str(row.condition)] if has_condition \
            else trials
        tag = f"{row.condition}: " if has_condition else ""
        if "lost" in group.columns:
            group = group[~group["lost"].astype(bool)]
        ax.plot(group["tau_s"] ** 2, group["a_r_m"] * 100, marker, mfc="none", mec=color,
                ms=size, ls="none", label=f"{tag}trial means ($n$ = {row.n})")
        ax.plot(xs, (row.intercept + row.slope * xs) * 100, "-", color=color, lw=1.5,
                label=f"{tag}OLS fit: slope {row.slope:.3f} m/s$^2$, intercept "
                      f"{row.intercept * 100:.2f} cm, $R^2$ = {row.r2:.3f}")
        if np.isfinite(row.predicted_slope):
            ax.plot(xs, row.predicted_slope * xs * 100, "--", color=color, lw=1.2,
                    label=f"{tag}eq. 15 at mean phase {row.mean_theta_deg:.1f} deg: slope "
                          f"{row.predicted_slope:.3f} m/s$^2$")
    ax.set_xlim(0, x_max)
    ax.set_ylim(bottom=min(0.0, float(ax.get_ylim()[0])))
    ax.axhline(0, color="0.8", lw=0.8)
    ax.set_xlabel(r"squared racket period $\tau^2$ (s$^2$)")
    ax.set_ylabel(r"racket amplitude $a_r$ (cm)")
    ax.set_title("Fig. 7: trial means of racket amplitude vs squared period (eq. 15)")
    ax.legend(fontsize=7, loc="upper left")
    return {"regression.png": fig}


EXPERIMENT = Experiment(
    name="regression", schema=RegressionConfig, run=run,
    draw=draw,
)
