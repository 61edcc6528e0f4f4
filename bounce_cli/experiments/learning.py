"""Fig. 6 (section 5): the learning study. Per trial of a lab's impacts: mean and SD of the
racket acceleration at impact AC (units of g), SD of ball amplitude, SDs of v and theta, and
the trend of each over trials (OLS slope per trial with its confidence interval). The model's
side, with or without data: the SD of ball amplitude that eq. 19 predicts as a function of AC
at fixed noise strengths (q_v, q_theta), over the stable AC range of eq. 14 -- the prediction
"more negative AC, less variability" to read a learning curve against.

The curve is drawn twice: with eq. 19's diagonal noise covariance, and with the covariance
the map of eqs. 16-18 induces when eq. 16 reads cos(theta_{k+1}) as printed (the phase noise
then also moves the racket velocity at impact; see ``map_noise_covariance``), once where the
two agree within ``SAME_CURVE_RTOL``.

Ball amplitude is the apex of the ball's flight above the racket's mid-position,
x_r(theta) + v^2 / 2g; its SD in the model is the gradient (v~/g, a_r cos theta~) applied to
eq. 19's stationary covariance. Along the model curve alpha, g and the racket period are fixed
(the data's mean period when there is data) and a_r is set by AC (section 4's explicit AC).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from pydantic import Field, field_validator

from ..memory import check_array_memory
from ..errors import TooFewObservationsError
from ..runtime.config import (
    ConfigError,
    DataFiles,
    ExperimentConfig,
    ModelBlock,
    StrictModel,
    data_text,
)
from ..analysis.data_stats import apex_sd_eq19, settled_mask
from ..model.linear import jacobian, racket_amplitude_for_ac, stability, stable_ac_range_g
from ..model.params import ModelError, ModelParams, circular_mean, phase_difference
from ..analysis.regression import ols_line
from ..analysis.stochastic import (
    map_noise_covariance,
    paper_noise_covariance,
    stationary_covariance,
)
from ..data.data_parameters import DataModel, model_for_data
from ..data.impacts import read_impacts
from .plotting import caption_figures, data_caption, integer_axis, new_figure, publication_style
from .base import Experiment, ExperimentResult, RunOptions

TREND_QUANTITIES = {
    "ac_mean_g": "mean AC (g)",
    "apex_sd_m": "SD of ball amplitude (m)",
    "ac_sd_g": "SD of AC (g)",
    "v_sd_m_s": "SD of v (m/s)",
    "theta_sd_deg": "SD of theta (deg)",
}


class LearningNoiseBlock(StrictModel):
    q_v: float = Field(0.04, gt=0.0, description="velocity noise strength of the model curve, m/s")
    q_theta: float = Field(0.05, ge=0.0, description="phase noise strength of the model curve, rad")


class LearningConfig(ExperimentConfig):
    model: ModelBlock = ModelBlock()
    noise: LearningNoiseBlock = LearningNoiseBlock()
    ac_points: int = Field(81, ge=5, description="AC values on the model curve")

    @field_validator("ac_points")
    @classmethod
    def _curve_fits_in_memory(cls, value: int) -> int:
        check_array_memory(value, f"{value:,} points", "reduce ac_points")
        return value
    min_bounces: int = Field(10, ge=3, description="fewest impacts a trial may have")
    settle_after_perturbation: int = Field(
        4, ge=0, description="with --data: impacts after a perturbed one left out of the "
                             "per-trial statistics (as acf --data)")
    confidence: float = Field(0.95, gt=0.0, lt=1.0, description="level of the trend intervals")
    data: DataFiles = Field(None, description="impacts table with ball_apex_m (--data; "
                            "several: one session)")


#: learning.png's two eq. 19 curves closer than this everywhere (relative) are drawn as one
SAME_CURVE_RTOL = 0.01


def model_curve(alpha: float, g: float, period: float, q_v: float, q_theta: float,
                points: int) -> pd.DataFrame:
    """Eq. 19's SDs along AC over the open stable range of eq. 14 at fixed alpha, g, period."""
    low, high = (float(x) for x in stable_ac_range_g(alpha))
    span = high - low
    rows = []
    for ac in np.linspace(low + 0.01 * span, high - 0.01 * span, points):
        a_r = float(racket_amplitude_for_ac(alpha, ac, g, period))
        params = ModelParams(alpha, g, a_r, period)
        cov = stationary_covariance(jacobian(params), paper_noise_covariance(q_v, q_theta))
        map_cov = map_noise_covariance(params, q_v, q_theta, "theta")
        rows.append({"ac_g": ac, "racket_amplitude_m": a_r,
                     "apex_sd_m": apex_sd_eq19(params, q_v, q_theta),
                     "apex_sd_map_m": apex_sd_eq19(params, q_v, q_theta, map_cov),
                     "v_sd_m_s": math.sqrt(cov[0, 0]),
                     "theta_sd_deg": math.degrees(math.sqrt(cov[1, 1])),
                     "spectral_radius": stability(params).spectral_radius,
                     "alpha": alpha, "g_m_s2": g, "racket_period_s": period,
                     "q_v_m_s": q_v, "q_theta_rad": q_theta})
    return pd.DataFrame(rows)


def trial_table(config: LearningConfig, options: RunOptions, source=None
                ) -> tuple[pd.DataFrame, float, DataModel, tuple[float, float, int]]:
    """Per-trial statistics of the impacts table (``source``, default the file
    ``config.data``), in the file's order of trials (trial_number 1, 2, ...), the data's
    mean racket period (NaN without that column), the model's alpha and g (the data's
    unless set by the user, ``data_parameters``) and the data's noise strengths (q_v, q_theta,
    pairs) from the VAR(1) residuals of each trial (``data_side.noise_from_trials``)."""
    from .data_side import noise_from_trials, short_trials_warning, warn_if_still_relaxing

    if source is None:
        assert config.data is not None
        source = config.data
    impacts = read_impacts(source, needs=("racket_acc_g", "ball_apex_m"),
                           command="learning --data", min_bounces=config.min_bounces,
                           min_bounces_key="min_bounces",
                           drop_short=short_trials_warning(source, options))
    model = model_for_data(impacts, config, options, source)
    warn_if_still_relaxing(impacts, config.settle_after_perturbation + 1,
                           "settle_after_perturbation", options)
    if impacts.listed:
        def first(trials) -> str:
            return ", ".join(str(t) for t in trials[:6]) + (", ..." if len(trials) > 6 else "")

        options.warn(f"data: {impacts.path}: trials in the order of their numbers "
                     f"({first(impacts.series)}), not as the file lists them "
                     f"({first(impacts.listed)}): trial_number follows the numbers")
    rows = []
    too_few = []  # trials left with fewer than min_bounces settled impacts: (trial, count)
    for trial, g in impacts.by_trial():
        number = impacts.trial_number(trial)  # its place in the series, short trials counted
        if "perturbed" in g.columns:  # the stationary state: not the relaxations
            g = g[settled_mask(g["perturbed"].to_numpy(), config.settle_after_perturbation)]
            if len(g) < config.min_bounces:
                too_few.append((trial, len(g)))
                continue
        theta = g["theta_rad"].to_numpy()
        dtheta = phase_difference(theta, circular_mean(theta))
        apex = g["ball_apex_m"].dropna()
        rows.append({
            "trial": trial, "trial_number": number, "bounces": len(g),
            "ac_mean_g": g["racket_acc_g"].mean(), "ac_sd_g": g["racket_acc_g"].std(ddof=1),
            "apex_mean_m": apex.mean(), "apex_sd_m": apex.std(ddof=1),
            "v_mean_m_s": g["v_m_s"].mean(), "v_sd_m_s": g["v_m_s"].std(ddof=1),
            "theta_mean_deg": math.degrees(circular_mean(theta)),
            "theta_sd_deg": math.degrees(float(np.std(dtheta, ddof=1))),
        })
    if too_few:
        listed = ", ".join(f"{trial} ({n})" for trial, n in too_few[:5]) + (
            f" and {len(too_few) - 5} more" if len(too_few) > 5 else "")
        options.warn(
            f"data: {impacts.path}: {len(too_few)} of {len(impacts.trials)} trials have fewer "
            f"than min_bounces ({config.min_bounces}) impacts outside the perturbations and "
            f"the {config.settle_after_perturbation} after each (settle_after_perturbation): "
            f"left out of the per-trial statistics: trial {listed}")
    period = (float(impacts.frame["racket_period_s"].mean())
              if "racket_period_s" in impacts.frame.columns else math.nan)
    noise = noise_from_trials(impacts, config.settle_after_perturbation)
    return pd.DataFrame(rows), period, model, noise


def trend_table(trials: pd.DataFrame, confidence: float) -> pd.DataFrame:
    rows = []
    x = trials["trial_number"].to_numpy(float)
    for quantity in TREND_QUANTITIES:
        y = trials[quantity].to_numpy(float)
        ok = np.isfinite(y)
        if ok.sum() < 3:
            continue
        fit = ols_line(x[ok], y[ok], confidence)
        rows.append({"quantity": quantity, "trials": int(ok.sum()),
                     "slope_per_trial": float(fit.slope), "slope_ci_low": float(fit.slope_ci_low),
                     "slope_ci_high": float(fit.slope_ci_high), "intercept": float(fit.intercept),
                     "r2": float(fit.r2), "confidence": confidence,
                     "trend": ("decreasing" if fit.slope_ci_high < 0 else
                               "increasing" if fit.slope_ci_low > 0 else "none detected")})
    return pd.DataFrame(rows)


def run(config: LearningConfig, options: RunOptions, source=None) -> ExperimentResult:
    """``source``: an impacts table in memory, ``(label, frame)`` (default:
    ``options.impacts``, else ``config.data``)."""
    source = options.impacts if source is None else source
    alpha, g = config.model.alpha, config.model.g
    frames: dict[str, pd.DataFrame] = {}
    lines = []
    period = config.model.racket_period
    q_v, q_theta = config.noise.q_v, config.noise.q_theta
    noise_words = "the config's noise"
    if config.data is not None or source is not None:
        trials, data_period, model, (data_q_v, data_q_theta, pairs) = trial_table(
            config, options, source)
        alpha, g = model.alpha.value, model.g.value
        lines.append(model.text())
        if len(trials) < 3:
            label = data_text(config.data) if source is None else source[0]
            raise TooFewObservationsError(f"data: {label}: {len(trials)} trial(s); a trend "
                                          "over trials needs at least 3")
        if math.isfinite(data_period):
            period = data_period
        if math.isfinite(data_q_v) and data_q_v > 0.0:
            q_v, q_theta = data_q_v, data_q_theta
            noise_words = (f"the data's noise (VAR(1) residuals of each trial, {pairs} degrees "
                           "of freedom; measurement noise inflates it)")
        else:
            noise_words = ("the config's noise: the data's trials have no run of 8 consecutive "
                           "unperturbed impacts to estimate their own")
        frames["trials.csv"] = trials
        frames["trend.csv"] = trend_table(trials, config.confidence)
        for row in frames["trend.csv"].itertuples():
            lines.append(f"{row.quantity}: slope {row.slope_per_trial:.4g} per trial "
                         f"[{row.slope_ci_low:.4g}, {row.slope_ci_high:.4g}] ({row.trend})")
    try:
        curve = model_curve(alpha, g, period, q_v, q_theta, config.ac_points)
    except ModelError as exc:
        raise ConfigError(f"model curve at racket period {period:.4g} s: {exc}") from None
    frames["model_curve.csv"] = curve
    best = curve.loc[curve["apex_sd_m"].idxmin()]
    lines.append(f"eq. 19 at alpha = {alpha:g}, g = {g:g} m/s^2, tau = {period:.4g} s, q_v = "
                 f"{q_v:.4g} m/s, q_theta = {q_theta:.4g} rad ({noise_words}): SD of ball "
                 f"amplitude smallest ({best.apex_sd_m * 100:.2f} cm) at AC = {best.ac_g:.3f} g; "
                 f"stable AC range ({float(stable_ac_range_g(alpha)[0]):.3f}, 0) g (eq. 14)")
    figures = draw(frames) if options.figures else {}
    caption_figures(figures, None, data_caption(config, source, options.record))
    return ExperimentResult(frames=frames, figures=figures, summary=lines)


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    """learning.png: with trials, each trial's AC and SD of ball amplitude over the trials
    (left; the SD's axis from 0, so that its change is seen at its size) and eq. 19's SD
    against AC with the trials on it (right); without, the model's curve alone."""
    curve = frames["model_curve.csv"]
    trials = frames.get("trials.csv")
    alpha = float(curve["alpha"].iloc[0])
    low = float(stable_ac_range_g(alpha)[0])
    if trials is not None:
        fig, axes = new_figure(1, 2, width=12, height=4.8)
        ax = axes[0, 0]
        ax.axhspan(low, 0.0, color="0.92",
                   label=f"stable AC range, eq. 14 ($\\alpha$ = {alpha:.3g})")
        ax.errorbar(trials["trial_number"], trials["ac_mean_g"], yerr=trials["ac_sd_g"], fmt="-o",
                    color="k", ms=4, capsize=2, label=r"mean AC $\pm$ SD per trial")
        ax.set_xlabel("trial number")
        integer_axis(ax)
        ax.set_ylabel("racket acceleration at impact AC (g)")
        ax.set_ylim(min(low * 1.1, float((trials["ac_mean_g"] - trials["ac_sd_g"]).min()) - 0.1),
                    max(0.3, float((trials["ac_mean_g"] + trials["ac_sd_g"]).max()) + 0.1))
        right = ax.twinx()
        right.plot(trials["trial_number"], trials["apex_sd_m"] * 100, "-s", color="0.55", ms=4,
                   label="SD of ball amplitude")
        right.set_ylabel("SD of ball amplitude (cm)", color="0.4")
        right.set_ylim(0.0, float(trials["apex_sd_m"].max()) * 100 * 1.15)
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = right.get_legend_handles_labels()
        ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.13),
                  ncol=2)
        ax.set_title("Fig. 6: learning over trials (data)", fontsize=10)
        ax2 = axes[0, 1]
    else:
        fig, axes = new_figure(1, 1, width=7, height=4.8)
        ax2 = axes[0, 0]
    ax2.axvspan(low, 0.0, color="0.92", label="stable AC range, eq. 14")
    printed = curve["apex_sd_map_m"].to_numpy(float)
    diagonal = curve["apex_sd_m"].to_numpy(float)
    # the printed reading's curve lies under the other where the phase noise is small: said
    # in the legend instead of a dotted line nobody can see
    apart = bool(np.nanmax(np.abs(printed - diagonal) / diagonal) > SAME_CURVE_RTOL)
    ax2.plot(curve["ac_g"], diagonal * 100, "-", color="0.3",
             label=f"eq. 19: $q_v$ = {curve['q_v_m_s'].iloc[0]:.3g} m/s, $q_\\theta$ = "
                   f"{curve['q_theta_rad'].iloc[0]:.3g} rad" + (
                       "" if apart else "\n(with the noise of eqs. 16-18 as printed: the "
                       f"same within {100 * SAME_CURVE_RTOL:g} %)"))
    if apart:
        ax2.plot(curve["ac_g"], printed * 100, ":", color="0.3",
                 label="eq. 19 with the noise of eqs. 16-18 as printed")
    if trials is not None:
        sc = ax2.scatter(trials["ac_mean_g"], trials["apex_sd_m"] * 100, c=trials["trial_number"],
                         cmap="viridis", s=22, zorder=3, label="data: trials")
        integer_axis(fig.colorbar(sc, ax=ax2, label="trial number").ax, which="y")
    top = float(np.nanpercentile(curve["apex_sd_m"], 90)) * 100
    if trials is not None:
        top = max(top, float(trials["apex_sd_m"].max()) * 100 * 1.1)
    ax2.set_ylim(0, top)
    ax2.set_xlabel("racket acceleration at impact AC (g)")
    ax2.set_ylabel("SD of ball amplitude (cm)")
    ax2.set_title(f"model: SD of ball amplitude vs AC ($\\alpha$ = {alpha:.3g}, $g$ = "
                  f"{curve['g_m_s2'].iloc[0]:.3g} m/s$^2$, $\\tau$ = "
                  f"{curve['racket_period_s'].iloc[0]:.3g} s)", fontsize=10)
    ax2.legend(fontsize=8)
    return {"learning.png": fig}


EXPERIMENT = Experiment(name="learning", schema=LearningConfig, run=run, draw=draw)
