"""``bounce trajectory``: continuous-time motion of ball and racket (eqs. 1-4; Figs. 2, 3).

For each case the ball leaves the racket at phase theta0 with velocity v0; the engine
(``model.flight.simulate``) integrates the motion with the configured integrator, including
the sticking phases where the ball rides on the racket.
"""

from __future__ import annotations

import math
from typing import Literal, Optional

import numpy as np
import pandas as pd
from pydantic import Field, model_validator

from ..runtime.config import ConfigError, ControllableModelBlock, ExperimentConfig, StrictModel
from ..model.flight import FlightSettings, simulate
from ..model.params import ModelParams, phase_difference, wrap_phase
from .plotting import caption_figures, control_caption, integer_axis, publication_style
from .base import Experiment, ExperimentResult, RunOptions


class CaseBlock(StrictModel):
    """One initial condition: the ball leaves the racket at theta0 with velocity v0."""

    name: str = Field(min_length=1)
    theta0_deg: Optional[float] = None
    theta0_rad: Optional[float] = None
    v0_m_s: float

    @model_validator(mode="after")
    def _one_phase(self):
        if (self.theta0_deg is None) == (self.theta0_rad is None):
            raise ValueError("give exactly one of theta0_deg and theta0_rad")
        return self

    @property
    def theta0(self) -> float:
        if self.theta0_rad is not None:
            return self.theta0_rad
        assert self.theta0_deg is not None  # the validator demands exactly one
        return math.radians(self.theta0_deg)


#: the engine's defaults (the one place they live)
_FLIGHT = FlightSettings()


class StickingBlock(StrictModel):
    """When the ball counts as stuck on the racket."""

    min_hop_s: float = Field(_FLIGHT.min_hop_s, ge=0.0, description="s, a shorter hop sticks")
    min_relative_velocity_m_s: float = Field(_FLIGHT.min_relative_velocity_m_s, ge=0.0)


class TrajectoryConfig(ExperimentConfig):
    model: ControllableModelBlock = ControllableModelBlock()
    integrator: Literal["exact", "rk4"] = "exact"
    # a coarser fixed step misses short hops (at 0.02 s, 9 of 87 impacts of the sticking case)
    rk4_step_s: float = Field(_FLIGHT.rk4_step_s, gt=0.0, le=5e-3)
    duration_s: float = Field(10.0, gt=0.0, le=1e4)
    sample_interval_s: float = Field(0.005, gt=0.0)
    sticking: StickingBlock = StickingBlock()
    cases: list[CaseBlock] = Field(min_length=1)

    @model_validator(mode="after")
    def _unique_names(self):
        names = [c.name for c in self.cases]
        if len(set(names)) != len(names):
            raise ValueError("case names must be unique")
        if self.duration_s / self.sample_interval_s > 2e6:
            raise ValueError("duration_s / sample_interval_s exceeds 2e6 samples per case")
        return self

    def settings(self) -> FlightSettings:
        return FlightSettings(
            integrator=self.integrator,
            rk4_step_s=self.rk4_step_s,
            min_hop_s=self.sticking.min_hop_s,
            min_relative_velocity_m_s=self.sticking.min_relative_velocity_m_s,
        )


#: a case "ends near the period-1 fixed point" when its last impact is within these of it
NEAR_FIXED_POINT_V = 0.02  # relative, of v~
NEAR_FIXED_POINT_DEG = 2.0


def case_ending(track: pd.DataFrame, impacts: pd.DataFrame, v_fp: float,
                theta_fp_deg: float) -> str:
    """How one case's simulation ends, in words: on the racket, near the period-1 fixed
    point (its last impact within ``NEAR_FIXED_POINT_V`` of v~ and ``NEAR_FIXED_POINT_DEG``
    of theta~), or neither. The cases are named by the user (the bundled ones after what
    they do at Fig. 3's model, which other parameters may not do)."""
    if len(track) and track["state"].iloc[-1] == "stuck":
        return "stuck on the racket"
    last = impacts.iloc[-1]
    off = phase_difference(math.radians(float(last["theta_deg"])), math.radians(theta_fp_deg))
    if (abs(float(last["v_m_s"]) - v_fp) <= NEAR_FIXED_POINT_V * abs(v_fp)
            and abs(float(off)) <= math.radians(NEAR_FIXED_POINT_DEG)):
        return "near the period-1 fixed point"
    return "in flight, away from the period-1 fixed point"


def case_frames(name: str, traj, params: ModelParams, sample_interval_s: float, theta0: float,
                v0: float):
    """(trajectory rows, impact rows) of one simulated case."""
    w = params.omega
    grid = np.arange(traj.t0, traj.t_end, sample_interval_s)
    events = [im.t_s for im in traj.impacts]
    events += [t for seg in traj.segments for t in (seg.t_start, seg.t_end)]
    t = np.unique(np.concatenate([grid, np.array(events), [traj.t_end]]))
    t = t[(t >= traj.t0) & (t <= traj.t_end)]
    x, v, stuck = traj.sample(t)
    track = pd.DataFrame({
        "case": name,
        "t_s": t,
        "ball_x_m": x,
        "ball_v_m_s": v,
        "racket_x_m": params.racket_position(w * t),
        "racket_v_m_s": params.racket_velocity(w * t),
        "state": np.where(stuck, "stuck", "flight"),
    })
    theta = np.array([theta0] + [im.theta_rad for im in traj.impacts])
    impacts = pd.DataFrame({
        "case": name,
        "k": np.arange(len(theta)),
        "t_s": theta / w,
        "theta_deg": np.degrees(wrap_phase(theta)),
        "v_m_s": [v0] + [im.v_after_m_s for im in traj.impacts],
        "racket_acc_g": params.racket_acceleration(theta) / params.g,
    })
    return track, impacts


def controlled_case_frames(name: str, traj, clock, periods, params: ModelParams,
                           sample_interval_s: float, theta0: float, v0: float):
    """``case_frames`` of a run with racket period control: the racket's position from its
    clock (the phase rate changes at impacts), each impact's time as simulated, and the
    period of the flight ending at each impact (``racket_period_s``; k = 0: tau_bar)."""
    grid = np.arange(traj.t0, traj.t_end, sample_interval_s)
    events = [im.t_s for im in traj.impacts]
    events += [t for seg in traj.segments for t in (seg.t_start, seg.t_end)]
    t = np.unique(np.concatenate([grid, np.array(events), [traj.t_end]]))
    t = t[(t >= traj.t0) & (t <= traj.t_end) & np.isfinite(t)]
    x, v, stuck = traj.sample(t)
    phase, omega = clock.phase(t)
    a = params.racket_amplitude
    racket_x, racket_v = a * np.sin(phase), a * omega * np.cos(phase)
    x = np.where(stuck, racket_x, x)
    v = np.where(stuck, racket_v, v)
    track = pd.DataFrame({"case": name, "t_s": t, "ball_x_m": x, "ball_v_m_s": v,
                          "racket_x_m": racket_x, "racket_v_m_s": racket_v,
                          "state": np.where(stuck, "stuck", "flight")})
    theta = np.array([theta0] + [im.theta_rad for im in traj.impacts])
    impacts = pd.DataFrame({
        "case": name, "k": np.arange(len(theta)),
        "t_s": [traj.t0] + [im.t_s for im in traj.impacts],
        "theta_deg": np.degrees(wrap_phase(theta)),
        "v_m_s": [v0] + [im.v_after_m_s for im in traj.impacts],
        "racket_acc_g": -a * np.sin(theta) * np.concatenate(
            [[params.omega], clock.omega[1:len(theta)]]) ** 2 / params.g,
        "racket_period_s": np.concatenate([[params.racket_period], periods]),
    })
    return track, impacts


def run(config: TrajectoryConfig, options: RunOptions) -> ExperimentResult:
    from ..model.control import simulate_controlled_motion

    params = config.params
    fp = params.fixed_point()
    settings = config.settings()
    controller = config.model.active_controller()  # None: the passive map
    if controller is not None and config.integrator != "exact":
        raise ConfigError("integrator: with model.control only the exact integrator is "
                          "implemented")
    if controller is not None and settings.min_hop_s == 0.0:
        raise ConfigError("sticking.min_hop_s: 0 (exact sticking) is not implemented with "
                          "model.control; give a shortest hop > 0")
    options.progress.start(len(config.cases), f"trajectory ({config.integrator})")
    tracks, impacts, summary, accumulations = [], [], [], []
    for case in config.cases:
        if controller is None:
            traj = simulate(case.theta0, case.v0_m_s, params, config.duration_s, settings)
            track, imp = case_frames(case.name, traj, params, config.sample_interval_s,
                                     case.theta0, case.v0_m_s)
        else:
            traj, clock, periods = simulate_controlled_motion(
                case.theta0, case.v0_m_s, params, controller, config.duration_s, settings)
            track, imp = controlled_case_frames(case.name, traj, clock, periods, params,
                                                config.sample_interval_s, case.theta0,
                                                case.v0_m_s)
        tracks.append(track)
        impacts.append(imp)
        if settings.min_hop_s == 0.0:  # exact sticking: where the chatters accumulate
            t_acc = np.array(traj.accumulations, dtype=float)
            accumulations.append(pd.DataFrame({
                "case": case.name, "t_s": t_acc,
                "theta_deg": np.degrees(wrap_phase(params.omega * t_acc)),
                "racket_x_m": params.racket_position(params.omega * t_acc)}))
        stuck = traj.stuck_phases
        last = imp.iloc[-1]
        summary.append(
            f"{case.name}: {len(traj.impacts)} impacts, last v = {last.v_m_s:.4f} m/s, "
            f"theta = {last.theta_deg:.3f} deg (fixed point {fp.v_m_s:.4f} m/s, "
            f"{fp.theta_deg:.3f} deg); {len(stuck)} stuck phases"
            + (f", first {stuck[0][0]:.4f}-{stuck[0][1]:.4f} s" if stuck else "")
            + f"; ends {case_ending(track, imp, fp.v_m_s, fp.theta_deg)}"
        )
        options.progress.advance(1)
    frames = {
        "trajectory.csv": pd.concat(tracks, ignore_index=True),
        "impacts.csv": pd.concat(impacts, ignore_index=True),
    }
    if accumulations:
        frames["accumulations.csv"] = pd.concat(accumulations, ignore_index=True)
    frames["fixed_point.csv"] = pd.DataFrame(
        {"v_m_s": [fp.v_m_s], "theta_deg": [fp.theta_deg], "integrator": [config.integrator]}
    )
    figures = draw(frames)
    caption_figures(figures, params, control_caption(controller))
    return ExperimentResult(frames=frames, figures=figures, summary=summary)


def _stuck_spans(t, stuck):
    """(start, end) times of runs of consecutive stuck samples."""
    spans, start = [], None
    for ti, si in zip(t, stuck):
        if si and start is None:
            start = ti
        elif not si and start is not None:
            spans.append((start, ti))
            start = None
    if start is not None:
        spans.append((start, t[-1]))
    return spans


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    """Fig. 3 style: per case, ball and racket position over time, then v_k and theta_k."""
    from .plotting import new_figure

    track, impacts = frames["trajectory.csv"], frames["impacts.csv"]
    fixed = frames["fixed_point.csv"]
    v_fp, th_fp = float(fixed["v_m_s"].iloc[0]), float(fixed["theta_deg"].iloc[0])
    cases = list(dict.fromkeys(track["case"]))
    fig, axes = new_figure(3 * len(cases), 1, width=8.0, height=3.2 * len(cases) + 1.0,
                           gridspec_kw={"height_ratios": [2.2, 1, 1] * len(cases)})
    for i, name in enumerate(cases):
        tr = track[track["case"] == name]
        imp = impacts[impacts["case"] == name]
        ax_x, ax_v, ax_th = axes[3 * i, 0], axes[3 * i + 1, 0], axes[3 * i + 2, 0]
        t = tr["t_s"].to_numpy()
        ax_x.plot(t, tr["ball_x_m"], color="C0", lw=1.0, label="ball $x_b$")
        ax_x.plot(t, tr["racket_x_m"], color="k", lw=0.9, label="racket $x_r$")
        for j, (a, b) in enumerate(_stuck_spans(t, (tr["state"] == "stuck").to_numpy())):
            ax_x.axvspan(a, b, color="C3", alpha=0.25, lw=0,
                         label="ball stuck on racket" if j == 0 else None)
        if "accumulations.csv" in frames:  # exact sticking
            acc = frames["accumulations.csv"]
            acc = acc[acc["case"] == name]
            if len(acc):
                ax_x.plot(acc["t_s"], acc["racket_x_m"], "v", ms=5, color="C3", mec="k",
                          mew=0.5, label="accumulation point (complete chatter)")
        ax_x.set_ylabel("position (m)")
        ax_x.set_title(f"{name}: $v_0$ = {imp['v_m_s'].iloc[0]:g} m/s, "
                       f"$\\theta_0$ = {imp['theta_deg'].iloc[0]:.1f} deg; ends "
                       f"{case_ending(tr, imp, v_fp, th_fp)}", fontsize=9)
        ax_x.legend(loc="upper right", fontsize=7, ncol=3)
        ax_v.plot(imp["k"], imp["v_m_s"], "o-", ms=2.5, lw=0.8, color="C0")
        ax_v.axhline(v_fp, ls="--", color="0.4", lw=0.8, label=f"$\\tilde v$ = {v_fp:.3f} m/s")
        ax_v.set_ylabel("$v_k$ (m/s)")
        ax_v.legend(loc="best", fontsize=7)
        ax_th.plot(imp["k"], imp["theta_deg"], "o-", ms=2.5, lw=0.8, color="C2")
        ax_th.axhline(th_fp, ls="--", color="0.4", lw=0.8,
                      label=f"$\\tilde\\theta$ = {th_fp:.2f} deg")
        ax_th.set_ylabel("$\\theta_k$ (deg)")
        ax_th.set_xlabel("bounce $k$")
        integer_axis(ax_v, ax_th)
        ax_th.legend(loc="best", fontsize=7)
        ax_x.set_xlabel("time $t$ (s)")
    fig.suptitle("Ball and racket trajectories (eqs. 1-4; paper Fig. 3)\n"
                 "dashed: fixed point (eqs. 7, 8); shaded: ball riding on the racket",
                 fontsize=10)
    return {"trajectory.png": fig}


EXPERIMENT = Experiment(name="trajectory", schema=TrajectoryConfig, run=run, draw=draw)
