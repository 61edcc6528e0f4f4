"""Impulse responses after a perturbation of the coefficient of restitution (paper Figs. 9,
10, section 7): the full map and its linearisation, the basin threshold in alpha_p, and the
relaxation times of opposite perturbations.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
import pandas as pd
from pydantic import Field

from ..config import ClassifyBlock, ControllableModelBlock, ExperimentConfig, StrictModel
from ..engine import (
    OUTCOMES,
    ModelParams,
    classify_batch,
    impulse_response_full,
    impulse_response_linear,
    perturbed_velocity,
    relaxation_impacts,
    stability,
)
from .base import Experiment, ExperimentResult, RunOptions

MODELS = ("full", "linear")
PAPER_THRESHOLD = 0.65


class RelaxationBlock(StrictModel):
    """'Back at the fixed point': within these tolerances from some impact on."""

    tolerance_v_m_s: float = Field(0.05, gt=0.0)
    tolerance_theta_deg: float = Field(1.0, gt=0.0)
    max_impacts: int = Field(100, ge=1, description="horizon of the relaxation count")


class ThresholdBlock(StrictModel):
    scan_step: float = Field(0.01, gt=0.0, lt=0.5)
    bisection_tolerance: float = Field(1e-4, gt=0.0)
    alpha_p_max: float = Field(0.99, gt=0.0, lt=1.0)


class ImpulseConfig(ExperimentConfig):
    model: ControllableModelBlock = ControllableModelBlock()
    alpha_p: list[Annotated[float, Field(ge=0.0, lt=1.0)]] = Field([0.4, 0.6, 0.35, 0.65], min_length=1)
    iterations: int = Field(10, ge=1, description="impacts after the perturbed one, shown")
    classify: ClassifyBlock = ClassifyBlock()
    relaxation: RelaxationBlock = RelaxationBlock()
    threshold: ThresholdBlock = ThresholdBlock()


# -- classification of the full response (section 3's criteria) -----------------------------
def classify(params: ModelParams, v0: float, block: ClassifyBlock,
             controller=None) -> tuple[str, int]:
    """Outcome of the full map from (theta~, v0) with section 3's criteria (the basin's
    classifier, ``engine.classify_batch``): ``period1`` | ``sticking`` | ``below_racket`` |
    ``undecided``, and the number of impacts until it was decided. With a racket period
    controller (``model.control``), the controlled map's (``engine.control``)."""
    if controller is not None:
        from ..engine.control import classify_controlled

        result = classify_controlled(params.fixed_point().theta_rad, v0, params, controller,
                                     block.settings())
        return OUTCOMES[int(result.outcome)], int(result.iterations)
    result = classify_batch(params.fixed_point().theta_rad, v0, params, block.settings())
    return OUTCOMES[int(result.outcome)], int(result.iterations)


def find_threshold(params: ModelParams, direction: int, config: ImpulseConfig) -> dict:
    """Scan alpha_p away from alpha_0 (direction +1 or -1) in steps until the full response
    leaves the period-1 basin, then bisect between the last inside and first outside value."""
    block, cls = config.threshold, config.classify
    alpha_0 = params.alpha
    end = block.alpha_p_max if direction > 0 else 0.0

    def outcome(a):
        return classify(params, perturbed_velocity(params, a), cls, config.model.controller())

    scan = np.arange(1, int(abs(end - alpha_0) / block.scan_step) + 1)
    values = alpha_0 + direction * block.scan_step * scan
    outcomes = [outcome(a)[0] for a in values]
    row = {"direction": "increase" if direction > 0 else "decrease",
           "paper_alpha_p": PAPER_THRESHOLD if direction > 0 else math.nan}
    leaving = [i for i, o in enumerate(outcomes) if o != "period1"]
    if not leaving:
        return row | {"alpha_p_inside": values[-1] if len(values) else alpha_0,
                      "alpha_p_outside": math.nan, "alpha_p_threshold": math.nan,
                      "v0_threshold_m_s": math.nan, "outcome_outside": "",
                      "bisection_steps": 0, "period1_beyond_in_scan": 0}
    first = leaving[0]
    inside = alpha_0 if first == 0 else float(values[first - 1])
    outside, outside_outcome = float(values[first]), outcomes[first]
    steps = 0
    while abs(outside - inside) > block.bisection_tolerance:
        mid = 0.5 * (inside + outside)
        o = outcome(mid)[0]
        if o == "period1":
            inside = mid
        else:
            outside, outside_outcome = mid, o
        steps += 1
    threshold = 0.5 * (inside + outside)
    return row | {
        "alpha_p_inside": inside,
        "alpha_p_outside": outside,
        "alpha_p_threshold": threshold,
        "v0_threshold_m_s": perturbed_velocity(params, threshold),
        "outcome_outside": outside_outcome,
        "bisection_steps": steps,
        "period1_beyond_in_scan": sum(o == "period1" for o in outcomes[first:]),
    }


def linear_outcome(params: ModelParams, controller=None) -> str:
    """The linear map y_{k+1} = J y_k returns to the fixed point iff J is stable (with a
    controller: the 3 x 3 Jacobian of ``engine.control``)."""
    if controller is not None:
        from ..engine.control import controlled_jacobian, spectral_radius_3x3

        radius = float(spectral_radius_3x3(controlled_jacobian(params, controller)))
        return "period1" if radius < 1.0 else "diverges"
    return "period1" if stability(params).stable else "diverges"


# -- tables ---------------------------------------------------------------------------------
def responses(params: ModelParams, alpha_p: float, n: int, controller=None):
    if controller is not None:  # racket period control (model.control)
        from ..engine.control import (
            controlled_impulse_response,
            controlled_impulse_response_linear,
        )

        return {"full": controlled_impulse_response(params, controller, alpha_p, n),
                "linear": controlled_impulse_response_linear(params, controller, alpha_p, n)}
    return {"full": impulse_response_full(params, alpha_p, n),
            "linear": impulse_response_linear(params, alpha_p, n)}


def impulse_frame(params: ModelParams, config: ImpulseConfig, outcomes: dict) -> pd.DataFrame:
    controller = config.model.controller()
    linear = linear_outcome(params, controller)
    rows = []
    for ap in config.alpha_p:
        for model, r in responses(params, ap, config.iterations, controller).items():
            for k in range(config.iterations + 1):
                rows.append({
                    "alpha_p": ap, "model": model, "k": k, "v_m_s": r.v[k],
                    "theta_deg": math.degrees(r.theta[k]), "dv_m_s": r.dv[k],
                    "dtheta_deg": math.degrees(r.dtheta[k]),
                    "outcome": outcomes[ap][0] if model == "full" else linear,
                })
    return pd.DataFrame(rows)


def relaxation_frame(params: ModelParams, config: ImpulseConfig, outcomes: dict) -> pd.DataFrame:
    rel = config.relaxation
    tol_theta = math.radians(rel.tolerance_theta_deg)
    fp = params.fixed_point()
    rows = []
    controller = config.model.controller()
    for ap in config.alpha_p:
        for model, r in responses(params, ap, rel.max_impacts, controller).items():
            shown = slice(1, config.iterations + 1)
            rows.append({
                "alpha_p": ap, "model": model,
                "v0_m_s": perturbed_velocity(params, ap),
                "dv0_m_s": perturbed_velocity(params, ap) - fp.v_m_s,
                "outcome": outcomes[ap][0] if model == "full" else linear_outcome(params,
                                                                                  controller),
                "relaxation_impacts": relaxation_impacts(r.dv, r.dtheta, rel.tolerance_v_m_s,
                                                         tol_theta),
                "sum_abs_dv_m_s": float(np.nansum(np.abs(r.dv[shown]))),
                "sum_abs_dtheta_deg": float(np.degrees(np.nansum(np.abs(r.dtheta[shown])))),
            })
    df = pd.DataFrame(rows)
    # opposite perturbation: alpha_p' = 2 alpha_0 - alpha_p (same |v_0 - v~|, other sign)
    opposite = []
    for row in df.itertuples():
        match = df[(df.model == row.model)
                   & np.isclose(df.alpha_p, 2 * params.alpha - row.alpha_p, atol=1e-9)]
        opposite.append(match.iloc[0] if len(match) else None)
    df["opposite_alpha_p"] = [o.alpha_p if o is not None else math.nan for o in opposite]
    df["relaxation_impacts_opposite"] = [
        o.relaxation_impacts if o is not None else math.nan for o in opposite]
    both = (df.relaxation_impacts >= 0) & (df.relaxation_impacts_opposite >= 0)
    df["asymmetry_impacts"] = (df.relaxation_impacts - df.relaxation_impacts_opposite).where(both)
    df["asymmetry_sum_abs_dv_ratio"] = df.sum_abs_dv_m_s / [
        o.sum_abs_dv_m_s if o is not None else math.nan for o in opposite]
    return df


def run(config: ImpulseConfig, options: RunOptions) -> ExperimentResult:
    params = config.params
    options.progress.start(len(config.alpha_p) + 2, "impulse responses")
    outcomes = {}
    for ap in config.alpha_p:
        outcomes[ap] = classify(params, perturbed_velocity(params, ap), config.classify,
                                config.model.controller())
        options.progress.advance(1)
    thresholds = []
    for direction in (+1, -1):
        thresholds.append(find_threshold(params, direction, config))
        options.progress.advance(1)
    frames = {
        "impulse.csv": impulse_frame(params, config, outcomes),
        "relaxation.csv": relaxation_frame(params, config, outcomes),
        "threshold.csv": pd.DataFrame(thresholds),
    }
    up = thresholds[0]
    rel = frames["relaxation.csv"]
    summary = [
        f"leaves the period-1 basin above alpha_p = {up['alpha_p_threshold']:.4f} "
        f"(v_0 = {up['v0_threshold_m_s']:.3f} m/s, then {up['outcome_outside']}; paper: about "
        f"{PAPER_THRESHOLD}); below alpha_p = {thresholds[1]['alpha_p_threshold']:.4f}",
        f"alpha_p = 0.7: v_0 = {perturbed_velocity(params, 0.7):.3f} m/s (paper: 5.7 m/s)",
    ]
    for model in MODELS:
        part = rel[rel.model == model]
        summary.append(f"{model}: impacts to relax " + ", ".join(
            f"{r.alpha_p:g}: {r.relaxation_impacts}" for r in part.itertuples()))
    return ExperimentResult(frames=frames, figures=draw(frames), summary=summary)


# -- figures --------------------------------------------------------------------------------
def _stationary(df: pd.DataFrame) -> tuple[float, float]:
    row = df.iloc[0]
    return row.v_m_s - row.dv_m_s, (row.theta_deg - row.dtheta_deg) % 360.0


def _layout(df: pd.DataFrame, title: str):
    from ..plotting import new_figure

    fig, axes = new_figure(2, 2, width=11.0, height=7.0, sharex=True)
    v_st, th_st = _stationary(df)
    for col, side in enumerate(("lower", "higher")):
        for row, (label, st) in enumerate((("velocity after impact v_k (m/s)", v_st),
                                           ("phase of impact theta_k (deg, wrapped)", th_st))):
            ax = axes[row, col]
            ax.axhline(st, color="k", ls="--", lw=1, label="stationary value")
            ax.set_ylabel(label)
            if row == 1:  # phases are drawn wrapped to theta~ +- 180 deg, not [0, 360)
                ax.set_ylim(st - 180.0, st + 180.0)
        axes[1, col].set_xlabel("iteration (impact) k; 0 = perturbed impact")
        axes[0, col].set_title(f"alpha_p {'<' if side == 'lower' else '>'} alpha_0")
    fig.suptitle(title)
    return fig, axes


def _side(df: pd.DataFrame) -> tuple[pd.Series, pd.Series]:
    first = df[df.k == 0]
    dv = first.groupby("alpha_p").dv_m_s.first()
    return dv[dv < 0].index, dv[dv >= 0].index


def draw(frames: dict[str, pd.DataFrame]) -> dict:
    df = frames["impulse.csv"]
    lower, higher = _side(df)
    figs = {}
    th_st = _stationary(df)[1]
    styles = ["-o", "-s", "-^", "-D", "-v", "-x"]

    fig, axes = _layout(df, "Impulse response of the full map (paper Fig. 9; model only)")
    for col, group in enumerate((lower, higher)):
        for i, ap in enumerate(sorted(group, key=lambda a: abs(a - 0.5))):
            d = df[(df.alpha_p == ap) & (df.model == "full")].sort_values("k")
            outcome = d.outcome.iloc[0]
            label = f"alpha_p = {ap:g}" + ("" if outcome == "period1" else f" ({outcome})")
            colour = f"{0.15 + 0.45 * i / max(len(group) - 1, 1):.2f}"
            axes[0, col].plot(d.k, d.v_m_s, styles[i % 6], color=colour, ms=4, label=label)
            axes[1, col].plot(d.k, th_st + d.dtheta_deg, styles[i % 6], color=colour, ms=4,
                              label=label)
        axes[0, col].legend(fontsize=8)
    figs["impulse.png"] = fig

    fig, axes = _layout(df, "Full map (grey) vs linearisation with the same Jacobian (black)"
                               " (paper Fig. 10)")
    for col, group in enumerate((lower, higher)):
        for i, ap in enumerate(sorted(group, key=lambda a: abs(a - 0.5))):
            for model, colour, ls in (("full", "0.55", "-"), ("linear", "k", "--")):
                d = df[(df.alpha_p == ap) & (df.model == model)].sort_values("k")
                label = f"{model}, alpha_p = {ap:g}"
                if model == "full" and d.outcome.iloc[0] != "period1":
                    label += f" ({d.outcome.iloc[0]})"
                marker = styles[i % 6][1:]
                axes[0, col].plot(d.k, d.v_m_s, ls, marker=marker, color=colour, ms=4, label=label)
                axes[1, col].plot(d.k, th_st + d.dtheta_deg, ls, marker=marker, color=colour, ms=4,
                                  label=label)
        axes[0, col].legend(fontsize=7)
    figs["impulse_linear.png"] = fig
    return figs


EXPERIMENT = Experiment(
    name="impulse",
    schema=ImpulseConfig,
    run=run,
    draw=draw,
)
