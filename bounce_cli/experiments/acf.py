"""Fig. 8 (section 6): correlation functions of the stochastic ball bouncing map.

Theory: the linearised VAR(1) model (eq. 19) with the paper's diagonal noise covariance, and
with the covariance the map of eqs. 16-18 actually induces. Samples: long runs of eqs. 16-18
(the paper's crosses) and simulated trials as the experiment recorded them (three of 40 s).
The inverse problems behind the candidate explanations are solved by the engine
(``analysis.stochastic``); the paper's values come from :mod:`bounce_cli.paper.values`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd
from pydantic import Field

from ..paper import values as paper
from ..runtime.config import (
    ConfigError,
    ControllableModelBlock,
    DataFiles,
    ExperimentConfig,
    StrictModel,
)
from ..model.linear import is_stable, jacobian, stability
from ..model.control import controlled_jacobian
from ..model.params import ModelError, ModelParams, phase_difference
from ..errors import NotStableError
from ..analysis.stochastic import (
    PAIR_NAMES,
    map_noise_covariance,
    noise_strengths_for_sds,
    paper_noise_covariance,
    racket_amplitude_for_sd,
    sample_correlations,
    simulate_stochastic_map,
    stationary_sds,
    var1_theory,
)
from .plotting import (
    PANELS,
    caption_figures,
    finish_correlation_panel,
    new_figure,
    publication_style,
)
from .base import Experiment, ExperimentResult, RunOptions
from .data_side import AcfDataBlock, acf_data_draw, acf_data_run, data_side_result

OBSERVED_AMPLITUDE_M, OBSERVED_PERIOD_S = paper.OBSERVED_AMPLITUDE_M, paper.OBSERVED_PERIOD_S


def paper_sds(params: ModelParams) -> dict[str, tuple[float, float]]:
    """The paper's (theoretical, observed) SDs of v (m/s) and theta (deg), section 6, when
    ``params`` are its Fig. 8 parameters; NaN elsewhere (they describe another system)."""
    if not paper.at_parameters(params, paper.FIG8_MODEL):
        return {"sd_v": (math.nan, math.nan), "sd_theta": (math.nan, math.nan)}
    return {"sd_v": (paper.SD_V_THEORY.value, paper.SD_V_OBSERVED.value),
            "sd_theta": (paper.SD_THETA_THEORY.value, paper.SD_THETA_OBSERVED.value)}


class NoiseBlock(StrictModel):
    q_v: float = Field(paper.Q_V_M_S, ge=0.0, description="velocity noise strength, m/s")
    q_theta: float = Field(paper.Q_THETA_RAD, ge=0.0, description="phase noise strength, rad")
    velocity_phase: Literal["theta", "phi"] = Field(
        "theta", description="phase in eq. 16's cos(): theta_{k+1} (printed) or phi_{k+1}"
    )


class TrialsBlock(StrictModel):
    repetitions: int = Field(paper.TRIALS, ge=2, description="simulated trials (the experiment "
                             "had 3)")
    duration_s: float = Field(paper.TRIAL_DURATION_S, gt=0.0, description="trial length, s")


class LongRunsBlock(StrictModel):
    runs: int = Field(100, ge=2, description="independent long runs")
    bounces: int = Field(5000, ge=20, description="bounces per long run after burn-in")


class AcfConfig(ExperimentConfig):
    model: ControllableModelBlock = ControllableModelBlock(
        alpha=paper.FIG8_MODEL.alpha, g=paper.FIG8_MODEL.g,
        racket_amplitude=paper.FIG8_MODEL.racket_amplitude,
        racket_period=paper.FIG8_MODEL.racket_period)
    noise: NoiseBlock = NoiseBlock()
    trials: TrialsBlock = TrialsBlock()
    long_runs: LongRunsBlock = LongRunsBlock()
    burn_in: int = Field(100, ge=0, description="bounces dropped at the start of every run")
    max_lag: int = Field(10, ge=1, description="largest lag, bounces")
    seed: int = Field(0, ge=0)
    data: DataFiles = Field(None, description="impacts table: the data's side (--data; "
                            "several: one session)")
    data_analysis: AcfDataBlock = AcfDataBlock()


def run(config: AcfConfig, options: RunOptions) -> ExperimentResult:
    if config.data is not None or options.impacts is not None:
        return run_data(config, options, options.impacts)
    params = config.params
    noise = config.noise
    controller = config.model.active_controller()  # None: the passive map
    if controller is not None and noise.velocity_phase != "theta":
        raise ConfigError("noise.velocity_phase: with model.control only eq. 16 as printed "
                          "(theta) is implemented")
    jac = jacobian(params) if controller is None else controlled_jacobian(params, controller)
    radius = float(np.abs(np.linalg.eigvals(jac)).max())
    if not is_stable(radius):
        raise NotStableError(
            f"the fixed point is unstable (spectral radius {radius:.4g}"
            " >= 1): no stationary correlation functions (eq. 19)"
        )
    n_trial = max(int(round(config.trials.duration_s / params.racket_period)), config.max_lag + 2)

    def covariance(cov2: np.ndarray) -> np.ndarray:
        """The noise covariance of the state: (v, theta), with control also tau (no noise)."""
        if controller is None:
            return cov2
        cov3 = np.zeros((3, 3))
        cov3[:2, :2] = cov2
        return cov3

    theory = var1_theory(jac, covariance(paper_noise_covariance(noise.q_v, noise.q_theta)),
                         config.max_lag)
    theory_map = var1_theory(
        jac, covariance(map_noise_covariance(params, noise.q_v, noise.q_theta,
                                             noise.velocity_phase)),
        config.max_lag,
    )
    trial_seeds, long_seeds = np.random.SeedSequence(config.seed).spawn(2)
    reps, runs = config.trials.repetitions, config.long_runs.runs
    total = (n_trial + config.burn_in) + (config.long_runs.bounces + config.burn_in)
    options.progress.start(total, "stochastic map")
    trials: Any
    long: Any
    if controller is None:
        trials, long = (
            simulate_stochastic_map(params, noise.q_v, noise.q_theta, n_bounces, seeds,
                                    burn_in=config.burn_in, velocity_phase=noise.velocity_phase,
                                    on_block=options.progress.advance)
            for n_bounces, seeds in ((n_trial, trial_seeds.spawn(reps)),
                                     (config.long_runs.bounces, long_seeds.spawn(runs)))
        )
    else:
        trials, long = (
            controlled_runs(params, controller, noise.q_v, noise.q_theta, n_bounces, count,
                            seeds, config.burn_in, options.progress.advance)
            for n_bounces, count, seeds in ((n_trial, reps, trial_seeds),
                                            (config.long_runs.bounces, runs, long_seeds))
        )
    lost = int(long.lost.sum() + trials.lost.sum())
    if long.lost.all() or trials.lost.all():
        raise ModelError("every run lost the ball (it stuck to the racket): noise too strong")
    keep = ~long.lost
    sample = sample_correlations(long.dv[keep], long.dtheta[keep], config.max_lag)
    trial = sample_correlations(trials.dv[~trials.lost], trials.dtheta[~trials.lost],
                                config.max_lag)
    n_kept = int(keep.sum())
    rows = []
    for name in PAIR_NAMES:
        for lag in range(config.max_lag + 1):
            rows.append({
                "lag": lag, "pair": name,
                "theory": theory.correlations[name][lag],
                "theory_map": theory_map.correlations[name][lag],
                "sample_mean": sample[name][:, lag].mean(),
                "sample_sd": sample[name][:, lag].std(ddof=1),
                "sample_se": sample[name][:, lag].std(ddof=1) / math.sqrt(n_kept),
                "trial_mean": trial[name][:, lag].mean(),
                "trial_sd": trial[name][:, lag].std(ddof=1),
            })
    acf = pd.DataFrame(rows)
    summary_df = summary_frame(config, theory, theory_map, long.dv[keep], long.dtheta[keep])
    figures = draw({"acf.csv": acf, "summary.csv": summary_df})
    sd = summary_df.set_index(["quantity", "source"])["ours"]
    quoted = paper_sds(params)
    at_paper = paper.at_parameters(params, paper.FIG8_MODEL)

    def paper_note(name: str) -> str:
        theory_sd, observed_sd = quoted[name]
        return (f" (paper: theory {theory_sd:g}, observed {observed_sd:g})" if at_paper
                else " (not the paper's Fig. 8 parameters: no paper value to compare)")

    lines = [
        f"SD v: theory (eq. 19) {sd['sd_v', 'theory_eq19']:.4f} m/s, sample "
        f"{sd['sd_v', 'sample']:.4f} m/s" + paper_note("sd_v"),
        f"SD theta: theory (eq. 19) {sd['sd_theta', 'theory_eq19']:.2f} deg, sample "
        f"{sd['sd_theta', 'sample']:.2f} deg" + paper_note("sd_theta"),
        f"long runs: {n_kept} x {config.long_runs.bounces} bounces; trials: {reps} x {n_trial} "
        f"bounces ({config.trials.duration_s:g} s); runs lost to sticking: {lost}",
    ]
    control = ("" if controller is None else
               f"racket period control K = {controller.gain:g}, c = {controller.rate:g}; ")
    caption_figures(figures, params, f"{control}{config.long_runs.runs} runs x "
                    f"{config.long_runs.bounces} bounces; {reps} simulated trials of "
                    f"{config.trials.duration_s:g} s ({n_trial} bounces); seed {config.seed}")
    return ExperimentResult(frames={"acf.csv": acf, "summary.csv": summary_df},
                            figures=figures, summary=lines)


@dataclass(frozen=True)
class ControlledRuns:
    """Runs of the controlled stochastic map: deviations from the fixed point (runs, bounces)
    of v (m/s) and theta (rad, wrapped), and which runs lost the ball (rows NaN)."""

    dv: np.ndarray
    dtheta: np.ndarray
    lost: np.ndarray


def controlled_runs(params: ModelParams, controller, q_v: float, q_theta: float,
                    n_bounces: int, n_runs: int, seeds: np.random.SeedSequence, burn_in: int,
                    advance) -> ControlledRuns:
    """The stochastic map of eqs. 16-18 with racket period control (``model.control``: the
    same noise, eq. 16 as printed), ``n_runs`` runs of ``n_bounces`` after ``burn_in``,
    started at the fixed point, one stream per run (spawned from ``seeds``). A run whose ball
    stops is lost (rows NaN)."""
    from ..analysis.control_design import simulate_perturbation_trials

    n = burn_in + n_bounces + 1  # impact 0 is the start
    sim = simulate_perturbation_trials(
        params, controller, n_trials=n_runs, impacts_per_trial=n, perturb_every=n + 1,
        velocity_noise_sd=q_v, phase_noise_sd=q_theta, seed=int(seeds.generate_state(1)[0]))
    advance(n)
    fp = params.fixed_point()
    dv = np.full((n_runs, n_bounces), np.nan)
    dtheta = np.full_like(dv, np.nan)
    lost = np.ones(n_runs, dtype=bool)
    for i in range(n_runs):
        rows = sim["trial"] == i
        if rows.sum() == n:
            lost[i] = False
            dv[i] = sim["v_m_s"][rows][burn_in + 1:] - fp.v_m_s
            dtheta[i] = phase_difference(sim["theta_rad"][rows][burn_in + 1:], fp.theta_rad)
    return ControlledRuns(dv, dtheta, lost)


def _sds(params: ModelParams, noise_cov: np.ndarray) -> tuple[float, float]:
    """Stationary SDs of eq. 19: v in m/s, theta in deg."""
    sd_v, sd_theta = stationary_sds(params, noise_cov)
    return sd_v, math.degrees(sd_theta)


def _sds_or_nan(params: ModelParams, q_v: float, q_theta: float) -> tuple[float, float]:
    try:
        return _sds(params, paper_noise_covariance(q_v, q_theta))
    except ModelError:
        return math.nan, math.nan


def _radius_or_nan(params: ModelParams) -> float:
    try:
        return stability(params).spectral_radius
    except ModelError:
        return math.nan


def candidate_rows(config: AcfConfig) -> list[dict]:
    """Possible reasons for a difference from the paper's theoretical SDs (section 6),
    computed by the engine: other readings of eq. 16, the observed racket, the a_r or the
    noise strengths that would give the printed SDs. Only at the paper's Fig. 8 parameters
    (elsewhere there is no printed value to explain)."""
    p, q = config.params, config.noise
    rows: list[dict] = []
    if not paper.at_parameters(p, paper.FIG8_MODEL):
        return rows
    sd_v_paper, sd_theta_paper = paper.SD_V_THEORY.value, paper.SD_THETA_THEORY.value

    def add(quantity, unit, source, ours, paper=np.nan, note=""):
        rows.append({"quantity": quantity, "unit": unit, "source": source, "ours": ours,
                     "ours_se": np.nan, "paper": paper, "note": note})

    for reading in ("theta", "phi"):
        sv, st = _sds(p, map_noise_covariance(p, q.q_v, q.q_theta, reading))
        label = "cos(theta_k+1) as printed" if reading == "theta" else "cos(phi_k+1)"
        add("sd_v", "m/s", f"candidate: eq. 16 with {label}, linearised", sv, sd_v_paper)
        add("sd_theta", "deg", f"candidate: eq. 16 with {label}, linearised", st, sd_theta_paper)
    same = np.outer([q.q_v, q.q_theta], [q.q_v, q.q_theta])
    sv, st = _sds(p, same)
    add("sd_v", "m/s", "candidate: one xi_k in both eqs. 16 and 18", sv, sd_v_paper)
    add("sd_theta", "deg", "candidate: one xi_k in both eqs. 16 and 18", st, sd_theta_paper)
    observed_tau = ModelParams(p.alpha, p.g, OBSERVED_AMPLITUDE_M, p.racket_period)
    sv, st = _sds_or_nan(observed_tau, q.q_v, q.q_theta)  # NaN where unstable at these alpha, g
    note = "" if np.isfinite(sv) else "fixed point unstable or absent at a_r = 0.076 m here"
    add("sd_v", "m/s", f"candidate: observed a_r {OBSERVED_AMPLITUDE_M} m", sv, sd_v_paper,
        note)
    add("sd_theta", "deg", f"candidate: observed a_r {OBSERVED_AMPLITUDE_M} m", st,
        sd_theta_paper, note)
    observed = ModelParams(p.alpha, p.g, OBSERVED_AMPLITUDE_M, OBSERVED_PERIOD_S)
    add("spectral_radius", "1", f"candidate: observed a_r {OBSERVED_AMPLITUDE_M} m and period "
        f"{OBSERVED_PERIOD_S} s", _radius_or_nan(observed), np.nan,
        "fixed point unstable (>= 1): no stationary SDs at the observed racket parameters")
    # a_r that alone reproduces each paper SD, and the noise strengths that reproduce both
    targets = {"sd_v": {"sd_v_m_s": sd_v_paper}, "sd_theta": {"sd_theta_deg": sd_theta_paper}}
    for (name, target), unit in zip(targets.items(), ("m/s", "deg")):
        a_fit = racket_amplitude_for_sd(p, q.q_v, q.q_theta, OBSERVED_AMPLITUDE_M, **target)
        add("racket_amplitude", "m", f"candidate: a_r giving the paper's {name}", a_fit,
            paper.FIG8_MODEL.racket_amplitude,
            f"a single a_r matching {name} = {next(iter(target.values()))} {unit}")
    q_v, q_theta = noise_strengths_for_sds(jacobian(p), sd_v_paper, math.radians(sd_theta_paper))
    add("q_v", "m/s", "candidate: noise strength giving both paper SDs (eq. 19)", q_v,
        paper.Q_V_M_S)
    add("q_theta", "rad", "candidate: noise strength giving both paper SDs (eq. 19)", q_theta,
        paper.Q_THETA_RAD)
    return rows


def summary_frame(config: AcfConfig, theory, theory_map, dv, dtheta) -> pd.DataFrame:
    """summary.csv: quantity, unit, source, ours, ours_se, paper, note."""
    p = config.params
    st = stability(p)
    fp = p.fixed_point()
    rows = []

    def add(quantity, unit, source, ours, ours_se=np.nan, paper=np.nan, note=""):
        rows.append({"quantity": quantity, "unit": unit, "source": source, "ours": ours,
                     "ours_se": ours_se, "paper": paper, "note": note})

    runs = dv.shape[0]
    sd_v_runs = dv.std(axis=1)
    sd_t_runs = np.degrees(dtheta.std(axis=1))
    quoted = paper_sds(p)  # NaN away from the paper's Fig. 8 parameters
    at_paper = paper.at_parameters(p, paper.FIG8_MODEL)
    theory_note = "paper: theoretical SD" if at_paper else ""
    sample_note = "long runs of eqs. 16-18" + ("; paper: observed (human) SD" if at_paper else "")
    add("sd_v", "m/s", "theory_eq19", theory.sd_v_m_s, paper=quoted["sd_v"][0],
        note=theory_note)
    add("sd_theta", "deg", "theory_eq19", math.degrees(theory.sd_theta_rad),
        paper=quoted["sd_theta"][0], note=theory_note)
    add("sd_v", "m/s", "theory_map", theory_map.sd_v_m_s, paper=quoted["sd_v"][0],
        note=f"eq. 19 with the noise covariance of eqs. 16-18 ({config.noise.velocity_phase})")
    add("sd_theta", "deg", "theory_map", math.degrees(theory_map.sd_theta_rad),
        paper=quoted["sd_theta"][0],
        note=f"eq. 19 with the noise covariance of eqs. 16-18 ({config.noise.velocity_phase})")
    add("sd_v", "m/s", "sample", float(np.sqrt(np.mean(sd_v_runs**2))),
        sd_v_runs.std(ddof=1) / math.sqrt(runs), quoted["sd_v"][1], sample_note)
    add("sd_theta", "deg", "sample", float(np.sqrt(np.mean(sd_t_runs**2))),
        sd_t_runs.std(ddof=1) / math.sqrt(runs), quoted["sd_theta"][1], sample_note)
    add("mean_v_offset", "m/s", "sample", float(dv.mean()),
        dv.mean(axis=1).std(ddof=1) / math.sqrt(runs),
        note="sample mean of v - v~ (nonlinear drift)")
    add("mean_theta_offset", "deg", "sample", float(np.degrees(dtheta.mean())),
        np.degrees(dtheta.mean(axis=1)).std(ddof=1) / math.sqrt(runs),
        note="sample mean of theta - theta~ (nonlinear drift)")
    add("v_fixed", "m/s", "theory", fp.v_m_s, note="eq. 7")
    add("theta_fixed", "deg", "theory", fp.theta_deg, note="eq. 8")
    add("ac", "g", "theory", st.ac_g, note="racket acceleration at impact")
    for label, lam in zip(("lambda_plus", "lambda_minus"), st.eigenvalues):
        add(f"{label}_re", "1", "theory", lam.real, note="eq. 10")
        add(f"{label}_im", "1", "theory", lam.imag, note="eq. 10")
    add("spectral_radius", "1", "theory", st.spectral_radius, note=f"regime {st.regime}")
    rows.extend(candidate_rows(config))
    return pd.DataFrame(rows)


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    if "acf_data.csv" in frames:
        return draw_data(frames)
    acf = frames["acf.csv"]
    fig, axes = new_figure(2, 2, width=10, height=7.5, sharex=True)
    for (r, c), pair in PANELS.items():
        ax = axes[r, c]
        d = acf[acf["pair"] == pair].sort_values("lag")
        lag = d["lag"].to_numpy()
        ax.axhline(0, color="0.7", lw=0.8)
        ax.fill_between(lag, d["trial_mean"] - d["trial_sd"], d["trial_mean"] + d["trial_sd"],
                        color="0.85", label=r"simulated trials, mean $\pm$ SD")
        ax.plot(lag, d["trial_mean"], color="0.55", lw=1.2)
        ax.errorbar(lag, d["sample_mean"], yerr=d["sample_sd"], fmt="x", color="k", ms=7,
                    capsize=2, lw=0.8, label=r"sample, long runs (mean $\pm$ SD)")
        ax.plot(lag, d["theory"], "o", mfc="none", mec="k", ms=9,
                label="theory eq. 19 (diagonal noise)")
        if not np.allclose(d["theory"], d["theory_map"], atol=5e-3):
            ax.plot(lag, d["theory_map"], "s", mfc="none", mec="tab:blue", ms=5,
                    label="theory with the noise of eqs. 16-18")
        finish_correlation_panel(ax, pair, bottom=r == 1)
    handles: dict[str, Any] = {}
    for ax in axes.flat:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    fig.legend(list(handles.values()), list(handles.keys()), loc="outside lower center", ncol=4,
               fontsize=8)
    title = "Fig. 8: correlation functions of the stochastic ball bouncing map"
    summary = frames.get("summary.csv")
    if summary is not None:
        indexed = summary.set_index(["quantity", "source"])
        s, quoted = indexed["ours"], indexed["paper"]
        title += (f"\nSD theory (eq. 19): $v$ {s['sd_v', 'theory_eq19']:.3f} m/s, $\\theta$ "
                  f"{s['sd_theta', 'theory_eq19']:.1f} deg")
        if np.isfinite(quoted["sd_v", "theory_eq19"]):  # only at the paper's parameters
            title += (f" (paper {quoted['sd_v', 'theory_eq19']:g}, "
                      f"{quoted['sd_theta', 'theory_eq19']:g})")
        title += f"; sample: {s['sd_v', 'sample']:.3f} m/s, {s['sd_theta', 'sample']:.1f} deg"
    fig.suptitle(title, fontsize=11)
    return {"acf.png": fig}


# -- the data's side (--data impacts.csv): bounce_cli/experiments/data_side.py ----------------
def run_data(config: AcfConfig, options: RunOptions, source=None) -> ExperimentResult:
    """The data's side; ``source``: the impacts (default: the file ``config.data``)."""
    return data_side_result(acf_data_run, draw_data, config, options, source)


draw_data = publication_style(acf_data_draw)


EXPERIMENT = Experiment(
    name="acf", schema=AcfConfig, run=run,
    draw=draw,
)
