"""Impulse responses after a perturbation of the coefficient of restitution (paper Figs. 9,
10, section 7): the full map and its linearisation, the basin threshold in alpha_p, and the
relaxation times of opposite perturbations.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Annotated

import numpy as np
import pandas as pd
from pydantic import Field

from ..paper import values as paper
from ..runtime.config import (
    ClassifyBlock,
    ControllableModelBlock,
    DataFiles,
    ExperimentConfig,
    StrictModel,
)
from ..analysis.impulse import (
    find_threshold,
    impulse_response_full,
    impulse_response_linear,
    perturbed_outcome,
)
from ..model.control import is_passive
from ..model.linear import is_stable, stability
from ..model.params import ModelParams
from ..model.perturbation import perturbed_velocity, relaxation_impacts
from .plotting import (
    IMPACT_AFTER_LABEL,
    PHASE_LABEL,
    VELOCITY_LABEL,
    caption_figures,
    control_caption,
    integer_axis,
    perturbation_title,
    publication_style,
)
from .base import Experiment, ExperimentResult, RunOptions
from .data_side import (
    ImpulseDataBlock,
    data_side_result,
    impulse_data_draw,
    impulse_data_run,
    relaxed_text,
)

MODELS = ("full", "linear")


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
    alpha_p: list[Annotated[float, Field(ge=0.0, lt=1.0)]] = Field(
        [*paper.ALPHA_P_SIMULATED, *paper.ALPHA_P_EXPERIMENT], min_length=1)
    iterations: int = Field(10, ge=1, description="impacts after the perturbed one, shown")
    classify: ClassifyBlock = ClassifyBlock()
    relaxation: RelaxationBlock = RelaxationBlock()
    threshold: ThresholdBlock = ThresholdBlock()
    data: DataFiles = Field(None, description="impacts table with perturbations (--data; "
                            "several: one session)")
    data_analysis: ImpulseDataBlock = ImpulseDataBlock()


# -- where the full response ends (section 3's criteria; the engine decides) -----------------
def threshold_row(params: ModelParams, direction: int, config: ImpulseConfig) -> dict:
    """threshold.csv's row for one direction: the engine's ``find_threshold`` and the paper's
    value beside it (only upwards, and only at the paper's parameters)."""
    block = config.threshold
    controller = config.model.controller()
    found = find_threshold(params, direction, config.classify.settings(),
                           scan_step=block.scan_step,
                           bisection_tolerance=block.bisection_tolerance,
                           alpha_p_max=block.alpha_p_max, controller=controller)
    passive_paper = is_passive(controller) and at_paper_parameters(params)
    quoted = paper.ALPHA_P_THRESHOLD.value if direction > 0 and passive_paper else math.nan
    return {"direction": "increase" if direction > 0 else "decrease",
            "paper_alpha_p": quoted} | dataclasses.asdict(found)


def exit_line(row: dict, scan_end: float, paper_note: str) -> str:
    """One direction of threshold.csv in words: where the response leaves the basin, or that
    the scan never left it."""
    side = "above" if row["direction"] == "increase" else "below"
    if not math.isfinite(row["alpha_p_threshold"]):
        return (f"stays in the period-1 basin for every alpha_p {side} alpha_0 scanned "
                f"(to {scan_end:g}){paper_note}")
    return (f"leaves the period-1 basin {side} alpha_p = {row['alpha_p_threshold']:.4f} "
            f"(v_0 = {row['v0_threshold_m_s']:.3f} m/s, then {row['outcome_outside']}"
            f"{paper_note})")


def at_paper_parameters(params: ModelParams) -> bool:
    """The paper's perturbation model (alpha_0 = 0.5, a_r = 0.30 m, tau = 0.92 s, section 7)."""
    return paper.at_parameters(params, paper.FIG3_MODEL)


def linear_outcome(params: ModelParams, controller=None) -> str:
    """The linear map y_{k+1} = J y_k returns to the fixed point iff J is stable (with a
    controller: the 3 x 3 Jacobian of ``model.control``)."""
    if controller is not None:
        from ..model.control import controlled_jacobian, spectral_radius_3x3

        radius = float(spectral_radius_3x3(controlled_jacobian(params, controller)))
        return "period1" if is_stable(radius) else "diverges"
    return "period1" if stability(params).stable else "diverges"


# -- tables ---------------------------------------------------------------------------------
def responses(params: ModelParams, alpha_p: float, n: int, controller=None):
    if controller is not None:  # racket period control (model.control)
        from ..analysis.control_design import (
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
    linear = linear_outcome(params, controller)
    for ap in config.alpha_p:
        for model, r in responses(params, ap, rel.max_impacts, controller).items():
            shown = slice(1, config.iterations + 1)
            rows.append({
                "alpha_p": ap, "model": model,
                "v0_m_s": perturbed_velocity(params, ap),
                "dv0_m_s": perturbed_velocity(params, ap) - fp.v_m_s,
                "outcome": outcomes[ap][0] if model == "full" else linear,
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


def warn_one_sided(alpha_p: list[float], alpha_0: float, warn) -> None:
    """Warn where every alpha_p lies on one side of alpha_0 (the bundled 0.35-0.65 at
    alpha_0 = 0.7): the figure's other column ("alpha_p above / below alpha_0") stays
    empty."""
    above, below = any(a > alpha_0 for a in alpha_p), any(a < alpha_0 for a in alpha_p)
    if above == below:
        return
    missing, sign = ("above", ">") if below else ("below", "<")
    warn(f"alpha_p: none {missing} alpha_0 = {alpha_0:g} (alpha_p: "
         f"{', '.join(f'{a:g}' for a in alpha_p)}), so the figures' column "
         f"'alpha_p {sign} alpha_0' stays empty; give alpha_p on both sides of alpha_0 to "
         "see both directions")


def run(config: ImpulseConfig, options: RunOptions) -> ExperimentResult:
    if config.data is not None or options.impacts is not None:
        return run_data(config, options, options.impacts)
    params = config.params
    warn_one_sided(config.alpha_p, params.alpha, options.warn)
    options.progress.start(len(config.alpha_p) + 2, "impulse responses")
    outcomes = {}
    for ap in config.alpha_p:
        outcomes[ap] = perturbed_outcome(params, ap, config.classify.settings(),
                                         controller=config.model.controller())
        options.progress.advance(1)
    thresholds = []
    for direction in (+1, -1):
        thresholds.append(threshold_row(params, direction, config))
        options.progress.advance(1)
    frames = {
        "impulse.csv": impulse_frame(params, config, outcomes),
        "relaxation.csv": relaxation_frame(params, config, outcomes),
        "threshold.csv": pd.DataFrame(thresholds),
    }
    up = thresholds[0]
    rel = frames["relaxation.csv"]
    at_paper = is_passive(config.model.controller()) and at_paper_parameters(params)
    summary = [exit_line(up, config.threshold.alpha_p_max,
                         f"; paper: about {paper.ALPHA_P_THRESHOLD.text}" if at_paper else "")
               + "; " + exit_line(thresholds[1], 0.0, "")]
    if at_paper:
        summary.append(
            f"alpha_p = {paper.ALPHA_P_FIG3:g}: v_0 = "
            f"{perturbed_velocity(params, paper.ALPHA_P_FIG3):.3f} m/s "
            f"(paper: {paper.V0_AT_ALPHA_P_FIG3})")
    else:
        summary.append("(not the paper's passive model at section 7's parameters: no paper value "
                       "to compare)")
    for model in MODELS:
        part = rel[rel.model == model]
        summary.append(f"{model}: impacts to relax " + ", ".join(
            f"{r.alpha_p:g}: {relaxed_text(r.relaxation_impacts, config.relaxation.max_impacts)}"
            for r in part.itertuples()))
    figures = draw(frames)
    caption_figures(figures, params, control_caption(config.model.controller()))
    return ExperimentResult(frames=frames, figures=figures, summary=summary)


# -- figures --------------------------------------------------------------------------------
def _stationary(df: pd.DataFrame) -> tuple[float, float]:
    row = df.iloc[0]
    return row.v_m_s - row.dv_m_s, (row.theta_deg - row.dtheta_deg) % 360.0


def _layout(df: pd.DataFrame, title: str):
    from .plotting import new_figure

    fig, axes = new_figure(2, 2, width=11.0, height=7.0, sharex=True)
    v_st, th_st = _stationary(df)
    for col, side in enumerate(("lower", "higher")):
        for row, (label, st) in enumerate(((VELOCITY_LABEL, v_st), (PHASE_LABEL, th_st))):
            ax = axes[row, col]
            ax.axhline(st, color="k", ls="--", lw=1, label="stationary value")
            ax.set_ylabel(label)
            integer_axis(ax)
        # phases are drawn as theta~ + their difference from it (wrapped to +- 180 deg), on an
        # axis fitted to the responses (not fixed at +- 180 deg, which flattens them)
        axes[1, col].set_xlabel(IMPACT_AFTER_LABEL)
        axes[0, col].set_title(perturbation_title(side == "lower"))
    fig.suptitle(title)
    return fig, axes


def _side(df: pd.DataFrame) -> tuple[list[float], list[float]]:
    """alpha_p below and above alpha_0 (the sign of v_0 - v~), each ordered by the size of the
    perturbation |v_0 - v~| (the same order as |alpha_p - alpha_0|)."""
    first = df[df.k == 0]
    dv = first.groupby("alpha_p").dv_m_s.first()
    by_size = dv.abs().sort_values(kind="stable")
    return ([a for a in by_size.index if dv[a] < 0], [a for a in by_size.index if dv[a] >= 0])


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    if "aligned.csv" in frames:
        return draw_data(frames)
    df = frames["impulse.csv"]
    lower, higher = _side(df)
    figs = {}
    th_st = _stationary(df)[1]
    styles = ["-o", "-s", "-^", "-D", "-v", "-x"]

    fig, axes = _layout(df, "Impulse response of the full map (paper Fig. 9; model only)")
    for col, group in enumerate((lower, higher)):
        for i, ap in enumerate(group):
            d = df[(df.alpha_p == ap) & (df.model == "full")].sort_values("k")
            outcome = d.outcome.iloc[0]
            label = f"$\\alpha_p$ = {ap:g}" + ("" if outcome == "period1" else
                                                f" ({outcome.replace('_', ' ')})")
            colour = f"{0.15 + 0.45 * i / max(len(group) - 1, 1):.2f}"
            axes[0, col].plot(d.k, d.v_m_s, styles[i % 6], color=colour, ms=4, label=label)
            axes[1, col].plot(d.k, th_st + d.dtheta_deg, styles[i % 6], color=colour, ms=4,
                              label=label)
        axes[0, col].legend(fontsize=8)
    figs["impulse.png"] = fig

    fig, axes = _layout(df, "Full map (grey) vs linearisation with the same Jacobian (black)"
                               " (paper Fig. 10)")
    for col, group in enumerate((lower, higher)):
        for i, ap in enumerate(group):
            for model, colour, ls in (("full", "0.55", "-"), ("linear", "k", "--")):
                d = df[(df.alpha_p == ap) & (df.model == model)].sort_values("k")
                label = f"{model}, $\\alpha_p$ = {ap:g}"
                if model == "full" and d.outcome.iloc[0] != "period1":
                    label += f" ({d.outcome.iloc[0].replace('_', ' ')})"
                marker = styles[i % 6][1:]
                axes[0, col].plot(d.k, d.v_m_s, ls, marker=marker, color=colour, ms=4, label=label)
                axes[1, col].plot(d.k, th_st + d.dtheta_deg, ls, marker=marker, color=colour, ms=4,
                                  label=label)
        axes[0, col].legend(fontsize=7)
    figs["impulse_linear.png"] = fig
    return figs


# -- the data's side (--data impacts.csv): bounce_cli/experiments/data_side.py ----------------
def run_data(config: ImpulseConfig, options: RunOptions, source=None) -> ExperimentResult:
    """The data's side; ``source``: the impacts (default: the file ``config.data``)."""
    return data_side_result(impulse_data_run, draw_data, config, options, source)


draw_data = publication_style(impulse_data_draw)


EXPERIMENT = Experiment(
    name="impulse",
    schema=ImpulseConfig,
    run=run,
    draw=draw,
)
