"""The data's side of Figs. 7, 8, 9 and 11 (sections 5-7): ``bounce regression|acf|impulse
--data impacts.csv``. Not an experiment module: ``regression``, ``acf`` and ``impulse``
dispatch here when their config has ``data`` set to an impacts table, and draw the figures
below from the frames these functions return.

The model at the data's parameters (``bounce_cli.data.data_parameters.model_at_data``): racket
period and amplitude from the data's cycles (means over all impacts of the file), alpha and g
the data's unless the user set them.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import pandas as pd
from pydantic import Field

from ..errors import TooFewObservationsError
from ..runtime.config import ConfigError, StrictModel
from ..runtime.forked import ForkedCall, can_fork
from ..analysis.impulse import impulse_response_full
from ..model.linear import jacobian, stability
from ..model.params import ModelError, ModelParams, circular_mean, eq8_alpha, phase_difference
from ..analysis.stochastic import PAIR_NAMES, paper_noise_covariance, var1_theory
from ..analysis.data_stats import (
    align,
    noise_from_sds,
    relaxation_impact,
    settled_mask,
    still_relaxing,
    trial_correlations,
)
from ..analysis.racket_inputs import INPUT_COEFFICIENTS, racket_input_jacobian
from ..analysis.var_fit import (EIGEN_QUANTITIES, J_ENTRIES, MAX_PLAUSIBLE_RADIUS, Var1Fit,
                                 fit_var1)
from ..data.data_parameters import (DataModel, mixed_racket_warning, model_at_data,
                                    model_for_data)
from ..data.impacts import Impacts, ImpactsSource, read_impacts
from .base import ExperimentResult, RunOptions
from .plotting import (
    IMPACT_AFTER_LABEL,
    PANELS,
    caption_figures,
    data_caption,
    finish_correlation_panel,
    integer_axis,
    new_figure,
    perturbation_title,
)
from ..data.setup_table import SETUP_FILE, read_setup

MODEL_COLUMNS = ("racket_period_s", "racket_amplitude_m")


class AcfDataBlock(StrictModel):
    """``bounce acf --data``: how the data's stability is measured (used only with ``data``)."""

    settle_after_perturbation: int = Field(
        4, ge=0, description="impacts after a perturbed one left out of the stationary analyses")
    confidence: float = Field(0.95, gt=0.0, lt=1.0, description="level of the intervals")
    jackknife: bool = Field(True, description="split-panel jackknife against the O(1/N) bias "
                                              "of removing each trial's mean")
    measurement_sd_v_m_s: float = Field(0.03, ge=0.0, description="measurement noise on v "
                                        "for the trust study, m/s, assumed when the data's "
                                        "setup.csv does not give it")
    measurement_sd_theta_deg: float = Field(1.0, ge=0.0, description="measurement noise on "
                                            "theta for the trust study, deg, assumed when the "
                                            "data's setup.csv does not give it")
    trust_bounces: list[Annotated[int, Field(ge=16)]] = Field(
        [100, 200, 400, 800, 1600, 3200], description="data-set sizes of the trust study")
    trust_repetitions: int = Field(200, ge=10, description="simulated data sets per size")
    trust_coverage_slack: float = Field(0.05, ge=0.0, lt=1.0, description="a size is trusted "
                                        "when coverage >= confidence - slack and |median bias| <= "
                                        "a quarter of the 16-84 % spread")
    trust_seed: int = Field(0, ge=0)
    model_sessions: int = Field(
        39, ge=0, description="sessions simulated by the model at the data's racket "
        "variability for the model's prediction of each VARX estimate (0: none)")


class ImpulseDataBlock(StrictModel):
    """``bounce impulse --data``: alignment on the perturbed impacts (used only with ``data``)."""

    settle_after_perturbation: int = Field(
        3, ge=0, description="a trial's baseline: unperturbed impacts at least this many after "
                             "the last perturbation")
    relaxation_z: float = Field(2.0, gt=0.0, description="a mean within z SE of 0 counts as "
                                "relaxed (data and model alike; the model's SE is 0)")
    min_windows_per_impact: int = Field(
        10, ge=2, description="impacts to relax are judged only over the impacts k that at "
        "least this many perturbation windows reach; fewer at k = 0: 'too few perturbations'")


def data_side_result(data_run, draw, config, options, source: ImpactsSource | None = None
                     ) -> ExperimentResult:
    """An experiment's data side (``--data``): the frames and summary lines of
    ``data_run(config, options, source)``, and ``draw``'s figures of them, captioned with where
    the impacts came from (``source``: the impacts; default: the file ``config.data``)."""
    frames, lines = data_run(config, options, source)
    figures = draw(frames) if options.figures else {}
    caption_figures(figures, None, data_caption(config, source, options.record))
    return ExperimentResult(frames=frames, figures=figures, summary=lines)


# -- the model at the data's parameters ------------------------------------------------------
def racket_text(params: ModelParams) -> str:
    """``model at the data's racket a_r = 0.11 m, tau = 0.6 s``."""
    return (f"model at the data's racket a_r = {params.racket_amplitude:.4g} m, tau = "
            f"{params.racket_period:.4g} s")


def relaxed_text(impacts: int, horizon: int | None = None) -> str:
    """An impacts-to-relax count in words (-1 in the CSVs: not back within the horizon)."""
    if impacts >= 0:
        return str(impacts)
    return "not within the impacts shown" if horizon is None else f"not within {horizon}"


def stationary_segments(impacts: Impacts, settle: int, min_length: int):
    """(trial, v, dtheta, theta, racket) of each run of consecutive, unperturbed impacts:
    perturbed impacts and the ``settle`` impacts after each are cut out (they are not the
    stationary state), dtheta is the phase minus the trial's circular mean, wrapped to [-pi,
    pi), racket the (n, 2) period and amplitude of each impact's racket cycle."""
    out = []
    for trial, rows in impacts.by_trial():
        keep = (settled_mask(rows["perturbed"].to_numpy(), settle)
                if "perturbed" in rows.columns else np.ones(len(rows), bool))
        theta = rows["theta_rad"].to_numpy()
        ref = circular_mean(theta[keep]) if keep.any() else 0.0
        dtheta = phase_difference(theta, ref)
        v = rows["v_m_s"].to_numpy()
        racket = (rows[list(MODEL_COLUMNS)].to_numpy(float)
                  if set(MODEL_COLUMNS) <= set(rows.columns) else np.full((len(rows), 2), np.nan))
        k = rows["k"].to_numpy()
        cut = np.ones(len(rows), bool)  # start of a new run
        cut[1:] = (np.diff(k) != 1) | ~keep[:-1]
        idx = np.flatnonzero(keep)
        for part in np.split(idx, np.flatnonzero(cut[idx][1:]) + 1):
            if len(part) >= min_length:
                out.append((trial, v[part], dtheta[part], theta[part], racket[part]))
    return out


def noise_from_residual_covariance(sigma: np.ndarray) -> tuple[float, float]:
    """(q_v, q_theta) of eqs. 16-18 from a VAR(1) residual covariance: q_theta =
    sqrt(Sigma_tt), q_v = sqrt(Sigma_vv - Sigma_vt^2 / Sigma_tt) (the second term removes the
    phase noise that cos(theta_{k+1}) in eq. 16 passes to v). Measurement noise inflates
    both."""
    q_theta = math.sqrt(max(sigma[1, 1], 0.0))
    q_v = math.sqrt(max(sigma[0, 0] - (sigma[0, 1] ** 2 / sigma[1, 1] if sigma[1, 1] > 0
                                       else 0.0), 0.0))
    return q_v, q_theta


#: an SD of the impacts' v (relative to their mean, at least 1 m/s) or theta (rad) at or below
#: this is rounding, not fluctuations: ``acf --data`` has nothing to correlate (a session
#: without noise: the virtual set-up's sine racket gave 1.3e-8 m/s and 7.5e-9 rad)
ROUNDING_SD = 1e-6

#: impacts whose SDs are both at most this many times their measured measurement noise
#: (setup.csv) vary by the measurement, not the ball: acf --data warns (a session without
#: motor noise, extracted: SD of v 0.14 mm/s)
NOISE_ONLY_FACTOR = 1.5

#: the shortest run of consecutive unperturbed impacts a VAR is fitted to, and the shortest
#: trial of the trust study's simulated data (a VAR(1) per trial needs a few pairs beyond its
#: six coefficients)
MIN_RUN_LENGTH = 8
#: impacts of the trust study's linear VAR dropped before each simulated trial, so that its
#: start at the fixed point is forgotten (|lambda|^100 < 1e-4 for a radius below 0.91)
TRUST_BURN_IN = 100


def noise_from_trials(impacts: Impacts, settle: int, min_length: int = MIN_RUN_LENGTH
                      ) -> tuple[float, float, int]:
    """The data's own noise strengths (q_v m/s, q_theta rad) and the pairs they rest on: an
    OLS VAR(1) per trial (each trial its own J: a learning series changes the racket, so J,
    from trial to trial) on its runs of consecutive unperturbed impacts, the residual
    covariances pooled over trials by their degrees of freedom, then
    :func:`noise_from_residual_covariance`. NaN when no trial has a run long enough.

    Parameters
    ----------
    impacts : Impacts
        The impacts table.
    settle : int
        Impacts after a perturbed one left out (as :func:`stationary_segments`).
    min_length : int
        Shortest run used.

    Returns
    -------
    tuple
        (q_v, q_theta, pairs).
    """
    by_trial: dict = {}
    for trial, v, dtheta, _, _ in stationary_segments(impacts, settle, min_length):
        by_trial.setdefault(trial, []).append(np.column_stack([v, dtheta]))
    pooled, dof = np.zeros((2, 2)), 0
    for runs in by_trial.values():
        try:
            fit = fit_var1(runs, "ols", jackknife=False)
        except ModelError:
            continue
        d = fit.n_pairs - 2 - fit.n_trials
        pooled += fit.noise_cov * d
        dof += d
    if dof <= 0:
        return math.nan, math.nan, 0
    q_v, q_theta = noise_from_residual_covariance(pooled / dof)
    return q_v, q_theta, dof


def stationary_means(runs) -> tuple[float, float]:
    """Mean v (m/s) and circular mean phase (rad) over the impacts of (v, theta) runs."""
    v = np.concatenate([r[0] for r in runs])
    theta = np.concatenate([r[1] for r in runs])
    return float(v.mean()), circular_mean(theta)


def implied_alpha(params: ModelParams, theta_rad: float) -> float:
    """Eq. 8 solved for alpha: (1 - alpha)/(1 + alpha) = r with r = cos(theta) w^2 a_r / (pi g),
    so alpha = (1 - r)/(1 + r); NaN where the phase is outside (-90, 90) deg."""
    return eq8_alpha(params.g, params.racket_amplitude, params.omega, theta_rad)


# -- acf --data (Fig. 8 and the stability measured from data) --------------------------------
@dataclass(frozen=True)
class MeasurementNoise:
    """The measurement noise of a data set's v_k (m/s) and theta_k (rad), and where it comes
    from: ``"setup.csv"`` (measured by the extraction, beside the impacts table) or
    ``"assumed"`` (the config's data_analysis values)."""

    sd_v_m_s: float
    sd_theta_rad: float
    source: str


def measurement_noise(block, source: ImpactsSource | None, data_path) -> MeasurementNoise:
    """The data's own measurement noise when its ``setup.csv`` gives both quantities
    (``measurement_sd_v_m_s``, ``measurement_sd_theta_rad``), else the config's assumed
    ``measurement_sd_v_m_s`` and ``measurement_sd_theta_deg``. A source that is no file
    (the simulated lab's impacts in memory) has no setup table; a study's unit (a (label,
    table) pair) carries its recordings' pooled ``setup.csv`` values in the table's
    ``attrs["setup"]``.

    Parameters
    ----------
    block : AcfDataBlock
        The config's data_analysis block (the assumed values).
    source : ImpactsSource or None
        The impacts given to the run (None: the file ``data_path``).
    data_path : str or Path or None
        The config's ``data``.

    Returns
    -------
    MeasurementNoise
    """
    path = data_path if source is None else source
    if isinstance(path, (str, Path)):
        setup = {q: value.estimate for q, value in read_setup(path).items()}
    elif isinstance(path, tuple) and len(path) == 2 and isinstance(path[1], pd.DataFrame):
        setup = path[1].attrs.get("setup", {})  # a study's unit: its recordings' setup.csv
    else:
        setup = {}
    v, theta = setup.get("measurement_sd_v_m_s"), setup.get("measurement_sd_theta_rad")
    if v is not None and theta is not None and math.isfinite(v) and math.isfinite(theta):
        return MeasurementNoise(abs(v), abs(theta), SETUP_FILE)
    return MeasurementNoise(block.measurement_sd_v_m_s,
                            math.radians(block.measurement_sd_theta_deg), "assumed")


#: the units of stability_data.csv's matrix entries, with v in m/s and theta in rad (eqs.
#: 9, 16-18; the racket inputs per s of period and per m of amplitude)
ENTRY_UNITS = {
    "J_vv": "1", "J_vtheta": "(m/s)/rad", "J_thetav": "rad/(m/s)", "J_thetatheta": "1",
    "noise_cov_vv": "m^2/s^2", "noise_cov_vtheta": "(m/s) rad", "noise_cov_thetatheta": "rad^2",
    **{name: f"{'(m/s)' if name.split('_')[1] == 'v' else 'rad'}/"
             f"{'s' if name.endswith('period') else 'm'}" for name in INPUT_COEFFICIENTS},
}


def warn_if_still_relaxing(impacts: Impacts, first_settled: int, settle_key: str,
                           options: RunOptions) -> None:
    """Warn where the steady state an analysis takes after each perturbation (from impact
    ``first_settled`` after it on) still holds the relaxation (``data_stats.still_relaxing``
    on v and theta), naming the setting to raise (``settle_key``)."""
    if "perturbed" not in impacts.frame.columns:
        return
    groups = [g for _, g in impacts.by_trial()]
    found = still_relaxing(
        {"v_m_s": ([g["v_m_s"].to_numpy(float) for g in groups], False),
         "theta_rad": ([g["theta_rad"].to_numpy(float) for g in groups], True)},
        [g["perturbed"].to_numpy(bool) for g in groups], first_settled,
        k_trials=[g["k"].to_numpy() for g in groups])
    if not found:
        return
    gaps = [np.diff(np.flatnonzero(g["perturbed"].to_numpy(bool))) for g in groups]
    spacing = np.concatenate(gaps) if gaps else np.array([])
    every = int(np.median(spacing)) if len(spacing) else 0
    if every and every - 1 <= first_settled:  # no later impact to start the steady state at
        advice = (f"the perturbations come every {every} impacts, too close for the response "
                  "to die out between them")
    else:
        advice = f"raise {settle_key}" + (
            f" (the perturbations come every {every} impacts)" if every else "")
    off = " and ".join(
        (f"v {f.mean:+.3g} m/s (SE {f.se:.2g})" if f.quantity == "v_m_s" else
         f"theta {math.degrees(f.mean):+.3g} deg (SE {math.degrees(f.se):.2g})")
        + f" after the {f.windows} kicks {f.direction}" for f in found)
    options.warn(f"data: {impacts.path}: the response to the perturbations has not settled "
                 f"by impact {first_settled} after them: {off} (mean response there, from "
                 f"the steady state), so the steady state holds the relaxation; {advice}")


def one_racket_model(impacts, used: DataModel, options: RunOptions) -> ModelParams:
    """``model_at_data`` (stable) for an analysis of the data's fluctuations (acf, impulse),
    with a warning where its trials are at different racket designs
    (``mixed_racket_warning``): one model at their mean stands for them all."""
    mixed = mixed_racket_warning(impacts)
    if mixed:  # before the model: at the mean racket it may have no stable fixed point
        options.warn(mixed)
    return model_at_data(impacts, used, record=options.record)


def short_trials_warning(source: ImpactsSource | None, options: RunOptions):
    """``read_impacts``'s ``drop_short`` for a table handed over in memory (a study's unit,
    the Python API: a short trial is left out with a warning), None for a file given with
    --data (a short trial is an error there, naming the setting to lower)."""
    return options.warn if isinstance(source, tuple) else None


def acf_data_run(config, options, source: ImpactsSource | None = None
                 ) -> tuple[dict[str, pd.DataFrame], list[str]]:
    """``source``: the impacts (default: the file ``config.data``)."""
    d = config.data_analysis
    impacts = read_impacts(config.data if source is None else source, needs=MODEL_COLUMNS,
                           command="acf --data", min_bounces=config.max_lag + 2,
                           min_bounces_key="max_lag", drop_short=short_trials_warning(
                               source, options))
    used = model_for_data(impacts, config, options, source)
    params = one_racket_model(impacts, used, options)
    noise = measurement_noise(d, source, config.data)
    segments = stationary_segments(impacts, d.settle_after_perturbation, config.max_lag + 2)
    warn_if_still_relaxing(impacts, d.settle_after_perturbation + 1,
                           "data_analysis.settle_after_perturbation", options)
    segments_means = [(s[1], s[3]) for s in segments]
    racket = [s[4] for s in segments]
    segments = [s[:3] for s in segments]
    if not segments:
        raise ConfigError(f"data: {impacts.path}: no run of {config.max_lag + 2} consecutive "
                          "unperturbed impacts (max_lag + 2) in any trial; lower max_lag or "
                          "data_analysis.settle_after_perturbation")
    options.progress.start(5 + len(d.trust_bounces), "data: correlations, VAR(1) fits")
    corr = trial_correlations([s[1] for s in segments], [s[2] for s in segments], config.max_lag)
    options.progress.advance(1)
    jac = jacobian(params)
    dv_all = np.concatenate([s[1] - s[1].mean() for s in segments])
    dth_all = np.concatenate([s[2] - s[2].mean() for s in segments])
    sd_v, sd_theta = float(np.sqrt(np.mean(dv_all**2))), float(np.sqrt(np.mean(dth_all**2)))
    mean_v = float(np.mean(np.concatenate([s[1] for s in segments])))
    if sd_v <= ROUNDING_SD * max(abs(mean_v), 1.0) or sd_theta <= ROUNDING_SD:
        raise TooFewObservationsError(
            f"data: {impacts.path}: the impacts barely vary (SD of v {sd_v:.2g} m/s, of theta "
            f"{math.degrees(sd_theta):.2g} deg: rounding, not fluctuations), so there are no "
            "fluctuations to correlate (a session without noise, such as the virtual set-up's "
            "sine racket without perturbations)")
    if (noise.source == SETUP_FILE and sd_v <= NOISE_ONLY_FACTOR * noise.sd_v_m_s
            and sd_theta <= NOISE_ONLY_FACTOR * noise.sd_theta_rad):
        options.warn(
            f"data: {impacts.path}: the impacts vary no more than their measurement noise (SD "
            f"of v {sd_v:.2g} m/s against {noise.sd_v_m_s:.2g}, of theta "
            f"{math.degrees(sd_theta):.2g} deg against {math.degrees(noise.sd_theta_rad):.2g}; "
            f"{SETUP_FILE}): the correlations and the stability below are the measurement's, "
            "not the ball's")
    q_v, q_theta = noise_from_sds(jac, sd_v, sd_theta)
    noise_note = "q from the data's SDs through eq. 19 at the model's J (section 6's route)"
    noise_source = "data_sd_match"
    if not (math.isfinite(q_v) and math.isfinite(q_theta)):
        noise_source = "data_sd_fallback"
        noise_note = ("the data's SDs need a negative noise variance at the model's J: theory "
                      "drawn with q_v = SD(v) (1 - |lambda|^2)^0.5 and likewise for theta")
        rad2 = 1 - stability(params).spectral_radius ** 2
        q_v, q_theta = sd_v * math.sqrt(rad2), sd_theta * math.sqrt(rad2)
    theory = var1_theory(jac, paper_noise_covariance(q_v, q_theta), config.max_lag)
    rows = []
    n_seg = len(segments)
    for name in PAIR_NAMES:
        for lag in range(config.max_lag + 1):
            x = corr[name][:, lag]
            rows.append({"lag": lag, "pair": name, "data_mean": float(x.mean()),
                         "data_sd": float(x.std(ddof=1)) if n_seg > 1 else math.nan,
                         "data_trials": n_seg, "theory": float(theory.correlations[name][lag])})
    acf = pd.DataFrame(rows)
    trials = [np.column_stack([s[1], s[2]]) for s in segments]
    fits: dict[str, Var1Fit | ModelError] = {}
    for method in ("ols", "lag2"):
        for label, exog in ((method, None), (f"varx_{method}", racket)):
            try:
                fits[label] = plausible_fit(fit_var1(trials, method, jackknife=d.jackknife,
                                                     exog=exog))
            except ModelError as exc:
                fits[label] = exc
                if str(exc).startswith(WITHHELD):
                    options.warn(f"{label}: {exc}; written as NaN")
        options.progress.advance(1)
    trust_call = functools.partial(trust_frame, params, q_v, q_theta, config, segments,
                                   noise=noise)
    # with a core to spare, the trust study runs in a forked child while this process
    # simulates the VARX prediction's sessions (independent draws: the same numbers)
    trust_child = (ForkedCall(lambda: trust_call(quiet_options()),
                              "the process of the trust study").start()
                   if options.jobs > 1 and can_fork() else None)
    try:
        try:
            prediction = varx_prediction(params, fits, trials, pooled_racket_sd(racket), d)
        except ModelError as exc:  # the model's sessions stick: the fits stand without it
            prediction = None
            options.warn(f"the model's prediction for the VARX estimates is not made: {exc}; "
                         "the fits are written without it (--set "
                         "data_analysis.model_sessions=0 skips it)")
        if trust_child is None:
            trust = trust_call(options)
        else:
            trust = trust_child.wait()
            options.progress.advance(len(trust) // 2)  # (trust_frame's, one per size)
    finally:
        if trust_child is not None:
            trust_child.kill()
    options.progress.advance(1)
    fits = {label: fit if isinstance(fit, ModelError) else
            calibrated(fit, trust, d.confidence, d.trust_coverage_slack)
            for label, fit in fits.items()}
    st = stability(params)
    fp = params.fixed_point()
    conf = d.confidence
    srows = []

    def add(quantity, unit, source, estimate, se=math.nan, low=math.nan, high=math.nan, note=""):
        srows.append({"quantity": quantity, "unit": unit, "source": source, "estimate": estimate,
                      "se": se, "ci_low": low, "ci_high": high, "note": note})

    for name, value in zip(J_ENTRIES, jac.ravel()):
        add(name, ENTRY_UNITS[name], "model_eq9", float(value),
            note="eq. 9 at the data's parameters")
    add("spectral_radius", "1", "model_eq10", st.spectral_radius, note=f"regime {st.regime}")
    for label, lam in zip(("lambda_plus", "lambda_minus"), st.eigenvalues):
        add(f"{label}_re", "1", "model_eq10", lam.real)
        add(f"{label}_im", "1", "model_eq10", lam.imag)
    b_model = racket_input_jacobian(params).as_varx()
    for name, value in zip(INPUT_COEFFICIENTS, b_model.ravel()):
        add(name, ENTRY_UNITS[name], "model_racket", float(value),
            note="d(v, theta)_{k+1} / d(period s, amplitude m) of impact k+1's (next) or k's "
                 "(this) racket cycle: eqs. 5-6 by the implicit function theorem")
    for method, fit in fits.items():
        if isinstance(fit, ModelError):
            add("spectral_radius", "1", method, math.nan, note=str(fit))
            continue
        label = ("varx_" if method.startswith("varx_") else "") + fit.method
        se = fit.jacobian_se.ravel()
        z = _z(conf)
        half = z if fit.has_interval else math.nan  # too few bounces: no interval
        for name, value, s in zip(J_ENTRIES, fit.jacobian.ravel(), se):
            add(name, ENTRY_UNITS[name], label, float(value), float(s), value - half * s,
                value + half * s, f"{fit.n_pairs} pairs in {fit.n_trials} runs")
        eig = fit.eigen_summary(conf)
        for name in EIGEN_QUANTITIES:
            value, se_, low, high = eig[name]
            add(name, "1", label, value, se_, low, high, note=interval_note(fit, name))
        value, _, low, high = eig["spectral_radius"]
        if low > 1.0:  # (NaN: no interval, no claim)
            options.warn(
                f"{label}: spectral radius {value:.3g} [{low:.3g}, {high:.3g}] lies above 1 "
                "with its whole interval: a ball that kept bouncing has a stable map, so the "
                "estimate is off (runs too short or too few, a nonlinearity a VAR(1) does not "
                "hold, or an extraction problem); it is written, and a study's group "
                "statistics include it")
        for (i, j), name in zip(((0, 0), (1, 1), (0, 1)), ("noise_cov_vv", "noise_cov_thetatheta",
                                                           "noise_cov_vtheta")):
            add(name, ENTRY_UNITS[name], label, float(fit.noise_cov[i, j]),
                note="residual covariance")
        for name, value, s_ in zip(INPUT_COEFFICIENTS, fit.exog_coef.ravel(),
                                   fit.exog_se.ravel()):
            add(name, ENTRY_UNITS[name], label, float(value), float(s_), value - half * s_,
                value + half * s_, note="racket input (deviation from the run's mean)")
    add("sd_v", "m/s", "data", sd_v, note="pooled within-run SD")
    add("sd_theta", "deg", "data", math.degrees(sd_theta), note="pooled within-run SD")
    add("q_v", "m/s", noise_source, q_v, note=noise_note)
    add("q_theta", "rad", noise_source, q_theta, note=noise_note)
    if not isinstance(fits["ols"], ModelError):
        q_v_resid, q_theta_resid = noise_from_residual_covariance(fits["ols"].noise_cov)
        add("q_theta", "rad", "ols_residual", q_theta_resid,
            note="sqrt of the VAR residual variance of theta (eq. 18's noise)")
        add("q_v", "m/s", "ols_residual", q_v_resid,
            note="residual variance of v given theta's (removes eq. 16's phase-noise term)")
    add("v_fixed", "m/s", "model_eq7", fp.v_m_s)
    add("theta_fixed", "deg", "model_eq8", fp.theta_deg)
    v_mean, theta_mean = stationary_means(segments_means)
    add("v_mean", "m/s", "data", v_mean, note="mean over the runs' impacts (compare eq. 7)")
    add("theta_mean", "deg", "data", math.degrees(theta_mean),
        note="circular mean phase of impact (compare eq. 8)")
    add("alpha", "1", "data_eq8", implied_alpha(params, theta_mean),
        note=f"the alpha for which eq. 8 puts theta~ at the data's mean phase (a check of "
             f"the model's alpha, {used.alpha.source})")
    add("ac", "g", "model", st.ac_g)
    add("racket_period", "s", "data", params.racket_period, note="mean over impacts")
    add("racket_amplitude", "m", "data", params.racket_amplitude, note="mean over impacts")
    racket_spread = pooled_racket_sd(racket)
    add("racket_period_sd", "s", "data", float(racket_spread[0]),
        note="pooled within-run SD of the cycles' periods")
    add("racket_amplitude_sd", "m", "data", float(racket_spread[1]),
        note="pooled within-run SD of the cycles' amplitudes")
    add("bounces", "1", "data", float(sum(len(s[1]) for s in segments)),
        note=f"in {n_seg} runs of consecutive unperturbed impacts")
    add("measurement_sd_v", "m/s", noise.source, noise.sd_v_m_s,
        note="measurement noise of v_k used by the trust study")
    add("measurement_sd_theta", "deg", noise.source, math.degrees(noise.sd_theta_rad),
        note="measurement noise of theta_k used by the trust study")
    prediction_lines: list[str] = []
    if prediction is not None:
        more, prediction_lines = prediction_rows(prediction, fits, params, conf)
        srows.extend(more)
    stab = pd.DataFrame(srows)
    diagnostics, diagnostic_lines = var_diagnostics(fits, trials, config.max_lag)
    frames = {"acf_data.csv": acf, "stability_data.csv": stab, "trust.csv": trust,
              "var_diagnostics.csv": diagnostics}
    lines = [f"data {impacts.path}: {n_seg} runs, {len(dv_all)} bounces; {racket_text(params)}",
             f"{used.text()}: spectral radius {st.spectral_radius:.3f}"]
    for method, fit in fits.items():
        if isinstance(fit, ModelError):
            lines.append(f"{method}: {fit}")
            continue
        prefix = ("VARX (each impact's racket period and amplitude as inputs) "
                  if method.startswith("varx_") else "")
        lines.append(f"{prefix}{fit.method}: {radius_text(fit, conf)}")
    lines.extend(prediction_lines)
    lines.extend(diagnostic_lines)
    warning = racket_warning(fits, racket_spread)
    if warning:
        options.warn(warning)
    if noise_source == "data_sd_match":
        lines.append(f"noise from the data's SDs: q_v = {q_v:.4f} m/s, q_theta = {q_theta:.4f} "
                     "rad")
    else:
        lines.append(f"noise: the data's SDs cannot be matched at the model's J (a negative "
                     f"variance); theory drawn with q = SD (1 - radius^2)^0.5: q_v = {q_v:.4f} "
                     f"m/s, q_theta = {q_theta:.4f} rad (the model's J may not be the data's)")
    lines.append(f"data's mean phase {math.degrees(theta_mean):.1f} deg vs eq. 8's "
                 f"{fp.theta_deg:.1f} deg (eq. 8 would need alpha = "
                 f"{implied_alpha(params, theta_mean):.3f}; the model's alpha = {params.alpha:g}, "
                 f"{used.alpha.source})")
    n_data = int(sum(len(s[1]) for s in segments))
    run_length = max(int(round(np.mean([len(s[1]) for s in segments]))), MIN_RUN_LENGTH)
    noise_words = (f"assumed: no {SETUP_FILE} beside the data gives it" if noise.source ==
                   "assumed" else f"the data's own, from {SETUP_FILE}")
    sized = trust[~trust.data_size.astype(bool)]
    for method in ("ols", "lag2"):
        ok = sized[(sized.method == method) & sized.trusted.astype(bool)]
        need = f"from {int(ok.bounces.min())} bounces" if len(ok) else "at none of the sizes tried"
        own = trust[(trust.method == method) & trust.data_size.astype(bool)]
        at_own = f" ({own_size_words(own.iloc[0])})" if len(own) else ""
        lines.append(f"trust study ({noise.sd_v_m_s:.3g} m/s, "
                     f"{math.degrees(noise.sd_theta_rad):.3g} deg measurement noise, "
                     f"{noise_words}; sizes in whole "
                     f"runs of the data's mean length, {run_length}): {method} trusted "
                     f"{need}; these data have {n_data}{at_own}")
    return frames, lines


def own_size_words(row) -> str:
    """The trust study's verdict at the data's own size (a row of :func:`trust_frame` with
    ``data_size`` true), in words: its coverage and whether it is trusted, or, where no
    simulated data set of that size could be fitted (too few bounces for the estimator), that
    it has no coverage."""
    if not int(row["repetitions"]):
        return ("at their own run lengths: no simulated data set of that size could be "
                "fitted, so no coverage; not trusted")
    return (f"at their own run lengths: coverage {float(row['coverage']):.1%}, "
            f"{'trusted' if bool(row['trusted']) else 'not trusted'}")


#: how the note of a spectral radius that is no estimate begins (``plausible_fit``)
WITHHELD = "spectral radius withheld: "


def plausible_fit(fit: Var1Fit) -> Var1Fit:
    """``fit``, unless its spectral radius is no estimate (:meth:`Var1Fit.radius_problem`:
    not finite, above 1.5, or an ill-conditioned fit): then a ModelError saying why, so that
    the fit is treated as one that failed (its rows NaN with the reason as their note, left
    out of every comparison, prediction and warning that reads the fits).

    Parameters
    ----------
    fit : Var1Fit
        A fit of the data, or of a session simulated like them.

    Returns
    -------
    Var1Fit
        ``fit`` itself.

    Raises
    ------
    ModelError
        ``spectral radius withheld: <reason>``.
    """
    problem = fit.radius_problem()
    if problem:
        raise ModelError(f"{WITHHELD}{problem}")
    return fit


# -- the model's prediction for the VARX estimates ---------------------------------------------
def simulated_trials(runs) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(v, theta) and (period, amplitude) of simulated runs (``data.simulated_runs.SimulatedRun``)
    as :func:`stationary_segments` gives the data's: the phase minus the run's circular mean,
    wrapped to [-pi, pi)."""
    trials = [np.column_stack([r.v_m_s, phase_difference(r.theta_rad,
                                                         circular_mean(r.theta_rad))])
              for r in runs]
    racket = [np.column_stack([r.racket_period_s, r.racket_amplitude_m]) for r in runs]
    return trials, racket


@dataclass(frozen=True)
class VarxPrediction:
    """The model's prediction for each VARX estimate: the same fit on ``sessions`` sessions
    simulated by the model at the data's racket, racket variability, run lengths and velocity
    noise ``q_v`` (module docstring of ``analysis.racket_inputs``). ``estimates[label]``: (sessions,
    5) J entries (row-major) and spectral radius per session."""

    sessions: int
    q_v: float
    q_v_residual: float
    redrawn: int
    estimates: dict[str, np.ndarray]


def varx_prediction(params: ModelParams, fits: dict, trials: list[np.ndarray],
                    racket_sd: np.ndarray, block) -> VarxPrediction | None:
    """Simulate the data's session by the model and fit it as the data were fitted.

    The map is nonlinear: at the spread a varying racket gives the state (the phase's SD is
    several degrees), the best linear predictor that OLS and the lag-2 fit estimate is not
    eq. 9's Jacobian (section 6's linearisation holds only for small noise), and theta's
    equation has no noise of its own, so its SEs are small and that difference counts. The
    model's own prediction for each estimate is its mean over sessions simulated at the data's
    parameters (``model_at_data``), racket SDs per cycle, run lengths and eq. 16's velocity
    noise. That noise is calibrated: first simulated at the data's OLS VARX residual q_v
    (:func:`noise_from_residual_covariance`), q0, which the nonlinearity inflates, then at
    q0^2 / s with s the simulated sessions' mean residual q_v (one multiplicative step of
    matching the data's residual). No
    measurement noise is simulated (the extraction's is far below the racket's spread; the
    trust study asks about measurement noise).

    Parameters
    ----------
    params : ModelParams
        The model at the data's parameters.
    fits : dict
        The data's fits by label (``varx_ols``, ``varx_lag2``: Var1Fit or ModelError).
    trials : list of (N_i, 2) arrays
        The data's runs (their lengths are simulated).
    racket_sd : (2,) array
        The data's pooled within-run SDs of period (s) and amplitude (m).
    block : AcfDataBlock
        ``model_sessions`` (0: no prediction), ``jackknife``, ``trust_seed``.

    Returns
    -------
    VarxPrediction or None
        None when the OLS VARX did not fit or ``model_sessions`` is 0.
    """
    from ..analysis.var_stacked import stacked_fit
    from ..data.simulated_runs import RacketSession, simulate_sessions
    from ..model.linear import spectral_radii_2x2

    base = fits.get("varx_ols")
    if block.model_sessions == 0 or not isinstance(base, Var1Fit):
        return None
    labels = [label for label in ("varx_ols", "varx_lag2") if isinstance(fits.get(label),
                                                                          Var1Fit)]
    lengths = [len(t) for t in trials]
    seeds = np.random.SeedSequence([block.trust_seed, 9]).spawn(2)
    q_residual = noise_from_residual_covariance(base.noise_cov)[0]
    calibration = max(2, block.model_sessions // 4)  # sessions of the first step
    first = RacketSession(float(racket_sd[0]), float(racket_sd[1]), q_residual)
    residual, redrawn = [], 0
    # every session's runs simulated at once (data.simulated_runs.simulate_sessions)
    for runs, again in simulate_sessions(params, first, lengths, seeds[0].spawn(calibration)):
        redrawn += again
        sim_trials, sim_racket = simulated_trials(runs)
        residual.append(noise_from_residual_covariance(
            fit_var1(sim_trials, "ols", jackknife=False, exog=sim_racket).noise_cov)[0])
    q_v = q_residual * q_residual / float(np.mean(residual))
    session = RacketSession(first.period_sd_s, first.amplitude_sd_m, q_v)
    panels, inputs = [], []
    for runs, again in simulate_sessions(params, session, lengths,
                                         seeds[1].spawn(block.model_sessions)):
        redrawn += again
        sim_trials, sim_racket = simulated_trials(runs)
        panels.append(np.concatenate(sim_trials))
        inputs.append(np.concatenate(sim_racket))
    # every session fitted as the data were (fit_var1, plausible_fit), all at once: the
    # sessions share the data's run lengths (analysis.var_stacked, each its own inputs)
    estimates: dict[str, np.ndarray] = {}
    for label in labels:
        try:
            fit = stacked_fit(np.stack(panels), lengths, label.removeprefix("varx_"),
                              block.jackknife, np.stack(inputs))
        except ModelError:
            continue
        kept = fit.valid  # fit_var1 fitted it and plausible_fit kept it
        if np.count_nonzero(kept) > 1:
            estimates[label] = np.column_stack([fit.jacobian[kept].reshape(-1, 4),
                                                spectral_radii_2x2(fit.jacobian[kept])])
    return VarxPrediction(block.model_sessions, q_v, q_residual, redrawn, estimates)


def rank_interval(sims: np.ndarray, confidence: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The k-th smallest and k-th largest of R simulated estimates (per column), k =
    max(1, floor((R + 1)(1 - confidence) / 2)), and the interval's level 1 - 2 k / (R + 1): a
    further estimate exchangeable with the R (the data, when they are the model) falls
    outside with probability 2 k / (R + 1), whatever the estimates' distribution (a Monte
    Carlo test's interval; heavy tails do not shorten it).

    Parameters
    ----------
    sims : (R, q) array
        R simulated estimates of q quantities.
    confidence : float
        The wanted level; R >= 2 / (1 - confidence) - 1 reaches it.

    Returns
    -------
    tuple
        (low (q,), high (q,), level).
    """
    n = len(sims)
    k = max(1, int(math.floor((n + 1) * (1.0 - confidence) / 2.0)))
    ordered = np.sort(sims, axis=0)
    return ordered[k - 1], ordered[n - k], 1.0 - 2.0 * k / (n + 1)


def prediction_rows(prediction: VarxPrediction, fits: dict, params: ModelParams,
                    confidence: float) -> tuple[list[dict], list[str]]:
    """stability_data.csv rows and summary lines of the model's prediction for each VARX
    estimate and of each estimate corrected by the model's bias.

    ``model_<estimator>``: the mean over the simulated sessions (se: their SD; interval:
    :func:`rank_interval` of the sessions' estimates, where the data's estimate falls with
    the interval's level when the data are the model). ``<estimator>+model_bias``: the
    estimate minus the model's bias for it (mean minus eq. 9's J, eq. 10's radius), with
    the same interval shifted: [estimate - (high - target), estimate - (low - target)],
    which holds eq. 9's J exactly when the estimate lies in the model's interval."""
    st = stability(params)
    target = np.append(jacobian(params).ravel(), st.spectral_radius)
    names = list(J_ENTRIES) + ["spectral_radius"]
    rows, lines = [], []
    how = (f"sessions simulated by the model at the data's racket variability and run "
           f"lengths, q_v = {prediction.q_v:.4f} m/s (calibrated to the data's VARX residual "
           f"q_v, {prediction.q_v_residual:.4f} m/s)")
    for label, sims in prediction.estimates.items():
        fit = fits[label]
        source = "varx_" + fit.method
        mean, sd = sims.mean(axis=0), sims.std(axis=0, ddof=1)
        low, high, level = rank_interval(sims, confidence)
        observed = np.append(fit.jacobian.ravel(), fit.eigen_summary()["spectral_radius"][0])
        corrected = observed - (mean - target)
        lows, highs = observed - (high - target), observed - (low - target)
        # a modulus: a bias larger than the estimate holds it (and its interval) at 0
        held = corrected[-1] < 0.0
        corrected[-1], lows[-1], highs[-1] = (max(x, 0.0) for x in
                                              (corrected[-1], lows[-1], highs[-1]))
        used = (f"{len(sims)} of the {prediction.sessions}" if len(sims) < prediction.sessions
                else f"{len(sims)}")
        fewer = f" (from {used} sessions)" if len(sims) < prediction.sessions else ""
        interval = f"{level:.0%} interval from the order statistics of {used} {how}"
        for i, name in enumerate(names):
            unit = "1" if name == "spectral_radius" else ENTRY_UNITS[name]
            rows.append({"quantity": name, "unit": unit, "source": f"model_{source}",
                         "estimate": float(mean[i]), "se": float(sd[i]),
                         "ci_low": float(low[i]), "ci_high": float(high[i]),
                         "note": f"the model's prediction for the {source} estimate: mean, SD "
                                 f"and {interval}"})
            rows.append({"quantity": name, "unit": unit, "source": f"{source}+model_bias",
                         "estimate": float(corrected[i]), "se": float(sd[i]),
                         "ci_low": float(lows[i]), "ci_high": float(highs[i]),
                         "note": f"{source} minus the model's bias for it (prediction minus "
                                 f"eq. 9/10); its {level:.0%} interval{fewer} holds eq. 9's J "
                                 "when the data are the model"
                                 + ("; held at 0: the bias is larger than the estimate, and a "
                                    "modulus is not negative"
                                    if held and name == "spectral_radius" else "")})
        lines.append(f"VARX {source}: the model predicts spectral radius {mean[4]:.3f} "
                     f"[{low[4]:.3f}, {high[4]:.3f}] for this estimate (eq. 10: "
                     f"{st.spectral_radius:.3f}: the map's nonlinearity at the data's spread); "
                     f"corrected by that bias {corrected[4]:.3f} [{lows[4]:.3f}, "
                     f"{highs[4]:.3f}] ({interval})")
    if prediction.redrawn:
        lines.append(f"the model's simulated sessions: {prediction.redrawn} run(s) fell into "
                     "sticking and were drawn again")
    return rows, lines


def interval_note(fit: Var1Fit, quantity: str) -> str:
    """How a fitted quantity's interval was made, or why there is none."""
    method = "delta method, log scale" if quantity == "spectral_radius" else "delta method"
    if not fit.has_interval:
        return f"no interval: {_too_few(fit)}"
    if fit.n_pairs < fit.min_pairs_for_interval:
        return (f"{method}; {fit.n_pairs} {_rows_word(fit)}, below the fixed minimum of "
                f"{fit.min_pairs_for_interval}: its coverage at this size measured by the trust "
                f"study, {fit.calibrated_coverage:.1%}")
    return method


def _too_few(fit: Var1Fit) -> str:
    """Why a fit below ``MIN_PAIRS_FOR_INTERVAL`` has no interval."""
    words = (f"{fit.n_pairs} {_rows_word(fit)}, fewer than the {fit.min_pairs_for_interval} "
             f"the {fit.method.split('+')[0]} interval needs without a check")
    if math.isnan(fit.calibrated_coverage):
        return words
    return f"{words}; the trust study at this size: {fit.calibration_note}"


def var_diagnostics(fits: dict, trials: list[np.ndarray], max_lag: int
                    ) -> tuple[pd.DataFrame, list[str]]:
    """var_diagnostics.csv and its summary lines: the Ljung-Box test of the OLS fits'
    residuals (VAR and VARX; per run, pooled) at min(max_lag, shortest run / 4) lags, and the
    lag orders 1..min(5, shortest run / 4) by AIC and BIC beside the paper's VAR(1)."""
    from ..analysis.var_fit import ROWS_PER_COEFFICIENT, lag_order_criteria, ljung_box

    shortest = min(len(t) for t in trials)
    lags = max(1, min(max_lag, shortest // 4))
    rows, lines = [], []
    for label in ("ols", "varx_ols"):
        fit = fits.get(label)
        if not isinstance(fit, Var1Fit):
            continue
        tests = ljung_box(fit, lags)
        for t in tests:
            rows.append({"diagnostic": "ljung_box", "estimator": label, "component": t.component,
                         "lags": t.lags, "statistic": t.statistic, "df": t.df,
                         "p_value": t.p_value, "aic": math.nan, "bic": math.nan,
                         "preferred_by": ""})
        if not all(t.df > 0 for t in tests):  # chi^2 with no degree of freedom left
            lines.append(f"Ljung-Box ({label} residuals, {lags} lags): not tested: the runs' "
                         f"{lags} lags leave no degree of freedom beside the "
                         f"{2 + fit.exog_coef.shape[1]} fitted slopes (too few impacts)")
            continue
        verdict = ", ".join(f"{t.component} p = {t.p_value:.3g}" for t in tests)
        white = all(t.p_value >= 0.05 for t in tests)
        lines.append(f"Ljung-Box ({label} residuals, {lags} lags, each run's own, pooled): "
                     f"{verdict}: {'white' if white else 'NOT white'} at 5 %")
    orders = lag_order_criteria(trials, max(1, min(5, shortest // 4)))
    if len(orders) == 1:
        lines.append(f"lag order: not compared: {orders[0].n_rows} impacts fit no VAR(p) "
                     f"beyond p = 1 with {ROWS_PER_COEFFICIENT} impacts per coefficient")
    if orders:
        best_aic = min(orders, key=lambda o: o.aic).order
        best_bic = min(orders, key=lambda o: o.bic).order
        for o in orders:
            by = ",".join(name for name, best in (("aic", best_aic), ("bic", best_bic))
                          if best == o.order)
            rows.append({"diagnostic": "lag_order", "estimator": "ols", "component": "",
                         "lags": o.order, "statistic": math.nan, "df": math.nan,
                         "p_value": math.nan, "aic": o.aic, "bic": o.bic, "preferred_by": by})
        if len(orders) > 1:
            lines.append(f"lag order (VAR(p) by OLS, p = 1..{orders[-1].order}, on the same "
                         f"{orders[0].n_rows} impacts): AIC prefers {best_aic}, BIC {best_bic} "
                         "(eq. 19 is a VAR(1))")
    columns = ["diagnostic", "estimator", "component", "lags", "statistic", "df", "p_value",
               "aic", "bic", "preferred_by"]
    return pd.DataFrame(rows, columns=columns), lines


#: how many of the VARX's SEs the VAR's spectral radius must be away for the racket warning
RACKET_WARNING_SE = 2.0


def racket_warning(fits: dict, racket_sd: np.ndarray) -> str:
    """A warning when the racket's cycle-to-cycle variability moves the VAR(1)'s spectral
    radius: for an estimator whose VARX has an interval, VAR and VARX differ by more than
    twice the VARX's SE ("" when not). One SE (and fits without an interval, whose SE says
    little) warned on a steady racket's 43 impacts, by chance."""
    moved = []
    for method in ("ols", "lag2"):
        var, varx = fits.get(method), fits.get(f"varx_{method}")
        if not isinstance(var, Var1Fit) or not isinstance(varx, Var1Fit):
            continue
        r_var = var.eigen_summary()["spectral_radius"][0]
        r_varx, se_varx = varx.eigen_summary()["spectral_radius"][:2]
        if varx.has_interval and abs(r_var - r_varx) > RACKET_WARNING_SE * se_varx:
            moved.append(f"{method} {r_var:.3f} without, {r_varx:.3f} +- {se_varx:.3f} with")
    if not moved:
        return ""
    return (f"the racket varies from cycle to cycle enough to matter (SD {1e3 * racket_sd[0]:.1f}"
            f" ms, {1e3 * racket_sd[1]:.1f} mm per cycle): the VAR(1) spectral radius moves "
            f"when the racket is an input ({'; '.join(moved)}): read the VARX rows")


def _rows_word(fit: Var1Fit) -> str:
    return "triples" if fit.method.startswith("lag2") else "pairs"


def radius_text(fit: Var1Fit, confidence: float) -> str:
    """The fitted spectral radius with its interval, or with the reason it has none."""
    value, se, low, high = fit.eigen_summary(confidence)["spectral_radius"]
    if not fit.has_interval:
        return (f"spectral radius {value:.3f} (SE {se:.3f}): no interval ({_too_few(fit)})")
    checked = (f"; coverage at this size {fit.calibrated_coverage:.0%} in the trust study"
               if fit.n_pairs < fit.min_pairs_for_interval else "")
    return (f"spectral radius {value:.3f} [{low:.3f}, {high:.3f}] ({confidence:.0%} CI, delta "
            f"method on the log scale{checked})")


def _z(confidence: float) -> float:
    from scipy.special import ndtri  # scipy.stats.norm.ppf, without scipy.stats' import

    return float(ndtri(0.5 + confidence / 2.0))


def pooled_racket_sd(racket: list[np.ndarray]) -> np.ndarray:
    """The pooled within-run SDs of the racket's cycles (period s, amplitude m) of runs of
    (period, amplitude) rows."""
    return np.sqrt(np.mean(np.concatenate([r - r.mean(axis=0) for r in racket]) ** 2, axis=0))


def quiet_options() -> RunOptions:
    """RunOptions that report nothing (a forked child's: the parent holds the terminal)."""
    return RunOptions()


def trust_frame(params, q_v, q_theta, config, segments, options,
                noise: MeasurementNoise) -> pd.DataFrame:
    """How many bounces each estimator needs: linear VAR data at the model's J (data
    parameters) and the data's noise, plus white measurement noise ``noise`` (the data's own
    from setup.csv, or the config's assumed), split into trials of the data's mean run length;
    per total size and estimator the bias, SD and interval coverage (the delta method's, at
    every size) of the spectral radius over repetitions. The last row per estimator
    (``data_size`` true) is the data's own size: trials of the data's own run lengths, each
    started in eq. 19's stationary distribution; it decides whether the data's fits below
    ``MIN_PAIRS_FOR_INTERVAL`` get an interval (:func:`calibrated`). The repetitions of a
    size are fitted at once (``analysis.var_stacked``)."""
    from ..analysis.var_stacked import simulate_panels

    d = config.data_analysis
    jac = jacobian(params)
    truth = stability(params).spectral_radius
    noise_cov = paper_noise_covariance(max(q_v, 1e-12), max(q_theta, 1e-12))
    chol = np.linalg.cholesky(noise_cov)
    meas = np.array([noise.sd_v_m_s, noise.sd_theta_rad])
    run_length = int(round(np.mean([len(s[1]) for s in segments])))
    rng = np.random.default_rng(np.random.SeedSequence(d.trust_seed))
    z = _z(d.confidence)
    reps = d.trust_repetitions
    sizes: list[tuple[list[int], np.ndarray, bool]] = []
    for total in d.trust_bounces:
        per = max(run_length, MIN_RUN_LENGTH)
        n_trials = max(1, int(round(total / per)))
        # every step's shocks drawn at once: the stream's values in the order the steps
        # drew them one by one
        shocks = rng.standard_normal((TRUST_BURN_IN + per, reps * n_trials, 2)) @ chol.T
        y = np.zeros((reps * n_trials, 2))
        series = np.empty((reps * n_trials, per, 2))
        for k, shock in enumerate(shocks):
            y = y @ jac.T + shock
            if k >= TRUST_BURN_IN:
                series[:, k - TRUST_BURN_IN] = y
        series += rng.standard_normal(series.shape) * meas
        sizes.append(([per] * n_trials, series.reshape(reps, n_trials * per, 2), False))
    own = [len(s[1]) for s in segments]
    if truth < 1.0:
        sizes.append((own, simulate_panels(jac, noise_cov, own, reps, rng,
                                           measurement_sd=meas), True))
    rows = []
    for lengths, panels, data_size in sizes:
        for method in ("ols", "lag2"):
            est, inside = _trust_fits(panels, lengths, method, d.jackknife, truth, z)
            q16, med, q84 = np.percentile(est, [16, 50, 84]) if len(est) else (math.nan,) * 3
            rows.append({"bounces": sum(lengths), "trials": len(lengths), "method": method,
                         "repetitions": len(est), "true_spectral_radius": truth,
                         "median_estimate": med, "median_bias": med - truth,
                         "spread_16_84": q84 - q16, "q16": q16, "q84": q84,
                         "coverage": inside / len(est) if len(est) else math.nan,
                         "measurement_sd_v_m_s": meas[0],
                         "measurement_sd_theta_deg": math.degrees(meas[1]),
                         "measurement_noise": noise.source, "data_size": data_size})
        options.progress.advance(1)
    frame = pd.DataFrame(rows)
    frame["trusted"] = (frame["coverage"] >= d.confidence - d.trust_coverage_slack) & (
        frame["median_bias"].abs() <= 0.25 * frame["spread_16_84"])
    return frame


def _trust_fits(panels, lengths, method, jackknife, truth, z):
    """The trust study's estimates of one size and estimator (those ``fit_var1`` fits) and how
    many of their delta-method intervals (log scale) hold the truth."""
    from ..analysis.var_stacked import log_radius_se, stacked_fit
    from ..model.linear import spectral_radii_2x2

    try:
        fit = stacked_fit(panels, lengths, method, jackknife)
    except ModelError:
        return np.zeros(0), 0
    jac, cov = fit.jacobian[fit.identified], fit.cov_vec[fit.identified]
    value = spectral_radii_2x2(jac)
    half = np.minimum(z * log_radius_se(jac, cov), 700.0)
    with np.errstate(over="ignore"):  # an interval of a wild fit reaching infinity holds it
        inside = int(np.sum((value * np.exp(-half) <= truth) & (truth <= value * np.exp(half))))
    return value, inside


def calibrated(fit: Var1Fit, trust: pd.DataFrame, confidence: float, slack: float
               ) -> Var1Fit:
    """``fit`` with its interval given below ``MIN_PAIRS_FOR_INTERVAL`` where the trust study
    at the data's own size (its ``data_size`` row for the fit's estimator) trusts the delta
    method there (coverage >= confidence - slack, |median bias| <= a quarter of the spread).

    Parameters
    ----------
    fit : Var1Fit
        A fit of the data (VAR or VARX: the VAR's trust study stands for both).
    trust : pandas.DataFrame
        :func:`trust_frame`'s table.
    confidence, slack : float
        The intervals' level and ``trust_coverage_slack`` (the rule of ``trusted``).

    Returns
    -------
    Var1Fit
        ``fit``, with ``calibrated_coverage`` set where its size was checked.
    """
    method = fit.method.split("+")[0]
    rows = trust[(trust["method"] == method) & trust["data_size"].astype(bool)]
    if fit.n_pairs >= fit.min_pairs_for_interval or not len(rows):
        return fit
    row = rows.iloc[0]
    coverage = float(row["coverage"])
    if not coverage >= confidence - slack:
        note = (f"the {confidence:.0%} interval covers the truth in {coverage:.1%} of "
                f"{int(row['repetitions'])} simulated data sets (below {confidence - slack:.0%})")
    else:
        note = (f"the estimate's median bias {row['median_bias']:+.3f} is more than a quarter "
                f"of its 16-84 % spread {row['spread_16_84']:.3f}")
    checked = dataclasses.replace(fit, calibrated_coverage=coverage,
                                  calibration_trusted=bool(row["trusted"]),
                                  calibration_note=note)
    if checked.calibration_trusted:
        # a trusted coverage does not make an interval informative: one that reaches above
        # MAX_PLAUSIBLE_RADIUS (30 pairs of a VARX: [0.000, 633]) says nothing a reader can
        # use, and a group's statistics would take it as a unit's estimate
        high = checked.eigen_summary(confidence)["spectral_radius"][3]
        if not high <= MAX_PLAUSIBLE_RADIUS:
            checked = dataclasses.replace(checked, calibration_trusted=False, calibration_note=(
                f"trusted, but this fit's {confidence:.0%} interval would reach {high:.3g}, "
                f"above {MAX_PLAUSIBLE_RADIUS:g}, which a ball that kept bouncing cannot have: "
                "not informative at this size"))
    return checked


def acf_data_draw(frames: dict[str, pd.DataFrame]) -> dict:

    acf = frames["acf_data.csv"]
    fig, axes = new_figure(2, 2, width=10, height=7.5, sharex=True)
    for (r, c), pair in PANELS.items():
        ax = axes[r, c]
        d = acf[acf["pair"] == pair].sort_values("lag")
        ax.axhline(0, color="0.8", lw=0.8)
        ax.errorbar(d["lag"], d["data_mean"], yerr=d["data_sd"].fillna(0), color="0.5", lw=1.5,
                    capsize=3,
                    label=f"data: mean $\\pm$ SD over {int(d['data_trials'].iloc[0])} runs")
        ax.plot(d["lag"], d["theory"], "o", mfc="none", mec="k", ms=9,
                label="model, eq. 19 at the data's parameters")
        finish_correlation_panel(ax, pair, bottom=r == 1)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=9)
    fig.suptitle("Fig. 8 with data: correlation functions of the data (grey) and eq. 19 (circles)")
    stab = frames.get("stability_data.csv")
    figs = {"acf_data.png": fig}
    if stab is not None:
        figs["stability_data.png"] = _stability_figure(stab, frames.get("trust.csv"))
    return figs


def _stability_figure(stab: pd.DataFrame, trust: pd.DataFrame | None):
    fig, axes = new_figure(1, 2, width=11, height=6.0)
    ax = axes[0, 0]
    s = stab.set_index(["quantity", "source"])
    styles = {"model_eq10": ("o", "k"), "ols": ("s", "tab:blue"), "lag2": ("D", "tab:red"),
              "varx_ols": ("P", "tab:cyan"), "varx_lag2": ("X", "tab:orange")}
    names = {"model_eq10": "model (eq. 10)", "ols": "VAR(1), OLS", "lag2": "VAR(1), lag 2",
             "varx_ols": "VARX (racket inputs), OLS", "varx_lag2": "VARX (racket inputs), lag 2"}
    sources = [src for src in dict.fromkeys(stab["source"]) if src.split("+")[0] in styles]
    t = np.linspace(0, 2 * np.pi, 200)
    ax.plot(np.cos(t), np.sin(t), color="0.8", lw=0.8)
    for src in sorted(sources, key=lambda x: x == "model_eq10"):  # the model on top
        marker, colour = styles[src.split("+")[0]]
        radius = s.loc[("spectral_radius", src)]
        method, _, interval = src.partition("+")  # e.g. ols+jackknife
        label = (f"{names[method]}{f' ({interval})' if interval else ''}: "
                 f"radius {radius['estimate']:.3f}")
        if np.isfinite(radius["ci_low"]):
            label += f" [{radius['ci_low']:.3f}, {radius['ci_high']:.3f}]"
        elif not np.isfinite(radius["estimate"]):
            label = f"{names[method]}: no estimate (stability_data.csv's note says why)"
        elif src != "model_eq10":
            label += " (too few bounces for an interval)"
        for lam in ("lambda_plus", "lambda_minus"):
            try:
                re = s.loc[(f"{lam}_re", src)]
                im = s.loc[(f"{lam}_im", src)]
            except KeyError:
                continue
            model = src == "model_eq10"
            ax.errorbar(re["estimate"], im["estimate"], xerr=0 if model else re["se"],
                        yerr=0 if model else im["se"], fmt=marker, color=colour,
                        mfc="none" if model else colour, ms=12 if model else 7,
                        mew=2 if model else 1,
                        capsize=2, zorder=3 if model else 2,
                        label=label if lam == "lambda_plus" else None)
    ax.set_aspect("equal")
    ax.set_xlim(-1.1, 1.1)
    ax.set_ylim(-1.1, 1.1)
    ticks = [-1.0, -0.5, 0.0, 0.5, 1.0]  # a tick every 0.25 ran its labels together
    ax.set_xticks(ticks)
    ax.set_yticks(ticks)
    ax.set_xlabel(r"Re $\lambda$")
    ax.set_ylabel(r"Im $\lambda$")
    ax.set_title(r"eigenvalues of $J$ ($\pm$ SE): model eq. 10 vs VAR(1) and VARX fits",
                 fontsize=10)
    # below the circle: inside it, it hid real eigenvalues and ran over the axis' labels
    ax.legend(fontsize=7, title="spectral radius [95 % CI]", title_fontsize=7,
              loc="upper center", bbox_to_anchor=(0.5, -0.13), frameon=False)
    ax = axes[0, 1]
    if trust is not None and len(trust):
        sized = trust[~trust.get("data_size", pd.Series(False, index=trust.index))
                      .astype(bool)]
        for method, colour in (("ols", "tab:blue"), ("lag2", "tab:red")):
            d = sized[sized["method"] == method]
            ax.errorbar(d["bounces"], d["median_estimate"],
                        yerr=[d["median_estimate"] - d["q16"], d["q84"] - d["median_estimate"]],
                        fmt="-o", color=colour, capsize=2,
                        label=f"{names[method]}: median and 16-84 % of the estimates")
            ok = d[d["trusted"].astype(bool)]
            if len(ok):
                ax.plot(ok["bounces"], ok["median_estimate"], "*", color=colour, ms=13,
                        mec="k", label=f"{names[method]}: trusted (coverage, bias)")
        ax.axhline(trust["true_spectral_radius"].iloc[0], color="k", ls="--",
                   label="true (model at the data's parameters)")
        n_data = stab.loc[(stab.quantity == "bounces") & (stab.source == "data"), "estimate"]
        if len(n_data):
            ax.axvline(float(n_data.iloc[0]), color="0.5", ls=":", label="these data's bounces")
        ax.set_xscale("log")
        ax.set_ylim(0.0, 1.5)
        ax.set_xlabel("bounces in the data set (simulated, with measurement noise)")
        ax.set_ylabel("estimated spectral radius")
        meas = trust.iloc[0]
        how = meas.get("measurement_noise", "assumed")
        how = "assumed" if how == "assumed" else "the data's, " + str(how)
        # two lines: with the measured noise's source the title is wider than the panel
        ax.set_title(f"bias from measurement noise\n({meas['measurement_sd_v_m_s']:.3g} m/s, "
                     f"{meas['measurement_sd_theta_deg']:.3g} deg, {how})", fontsize=10)
        ax.legend(fontsize=8)
    fig.suptitle("Stability measured from data (VAR(1) of eq. 19) beside eqs. 9-10")
    return fig


# -- impulse --data (Figs. 9 and 11) ----------------------------------------------------------
def impulse_data_run(config, options, source: ImpactsSource | None = None
                     ) -> tuple[dict[str, pd.DataFrame], list[str]]:
    """``source``: the impacts (default: the file ``config.data``)."""
    d = config.data_analysis
    needs = ("alpha", "perturbed", *MODEL_COLUMNS)
    impacts = read_impacts(config.data if source is None else source, needs=needs,
                           command="impulse --data", min_bounces=2,
                           drop_short=short_trials_warning(source, options))
    frame = impacts.frame
    if not frame["perturbed"].any():
        raise ConfigError(f"data: {impacts.path}: column perturbed: no perturbed impact, nothing "
                          "to align (bounce impulse --data needs perturbations)")
    used = model_for_data(impacts, config, options, source)
    params = one_racket_model(impacts, used, options)
    warn_if_still_relaxing(impacts, d.settle_after_perturbation,
                           "data_analysis.settle_after_perturbation", options)
    n = config.iterations
    groups = list(impacts.by_trial())
    alpha_0 = params.alpha
    quantities = {"v_m_s": ("v_m_s", False, 1.0), "theta_deg": ("theta_rad", True, 180 / math.pi),
                  "racket_period_s": ("racket_period_s", False, 1.0),
                  "racket_amplitude_m": ("racket_amplitude_m", False, 1.0)}
    rows, windows = [], {}
    options.progress.start(len(quantities), "aligning perturbations")
    for name, (column, is_phase, scale) in quantities.items():
        try:
            w = align([g[column].to_numpy() for _, g in groups],
                      [g["perturbed"].to_numpy() for _, g in groups],
                      [g["alpha"].to_numpy() for _, g in groups], n,
                      d.settle_after_perturbation, phase=is_phase,
                      k_trials=[g["k"].to_numpy() for _, g in groups],
                      labels=[label for label, _ in groups])
        except ModelError as exc:
            raise ConfigError(f"data: {impacts.path}: {exc}") from None
        windows[name] = (w, scale)
        options.progress.advance(1)
    w_v = windows["v_m_s"][0]
    direction = np.where(w_v.alpha_p > alpha_0, "increase", "decrease")
    for name, (w, scale) in windows.items():
        for side in ("decrease", "increase"):
            sel = direction == side
            if not sel.any():
                continue
            vals = w.values[sel] * scale
            count = np.sum(np.isfinite(vals), axis=0)
            with np.errstate(invalid="ignore", divide="ignore"):
                mean = np.nanmean(np.where(count > 0, vals, 0.0), axis=0) if vals.size else vals
                sd = np.array([np.nanstd(vals[:, k], ddof=1) if count[k] > 1 else math.nan
                               for k in range(n + 1)])
            for k in range(n + 1):
                rows.append({"quantity": name, "direction": side, "k": k,
                             "mean": float(mean[k]) if count[k] else math.nan,
                             "sd": float(sd[k]), "n": int(count[k]),
                             "mean_alpha_p": float(w.alpha_p[sel].mean())})
    aligned = pd.DataFrame(rows)
    model_rows, relax_rows = [], []
    fp = params.fixed_point()
    rel = config.relaxation
    for side in ("decrease", "increase"):
        sel = direction == side
        if not sel.any():
            continue
        ap = float(w_v.alpha_p[sel].mean())
        r = impulse_response_full(params, ap, n)
        for k in range(n + 1):
            model_rows.append({"direction": side, "alpha_p": ap, "k": k, "dv_m_s": r.dv[k],
                               "dtheta_deg": math.degrees(r.dtheta[k]),
                               "v_m_s": r.v[k], "theta_deg": math.degrees(r.theta[k])})
        a = aligned[aligned.direction == side]
        mv = a[a.quantity == "v_m_s"].sort_values("k")
        mt = a[a.quantity == "theta_deg"].sort_values("k")
        se_v = (mv["sd"] / np.sqrt(mv["n"])).to_numpy()
        se_t = (mt["sd"] / np.sqrt(mt["n"])).to_numpy()
        tol = (rel.tolerance_v_m_s, rel.tolerance_theta_deg)
        # both over the impacts k = 0.. that enough of the data's windows reach
        windows = mv["n"].to_numpy()
        reach = int(np.argmin(windows >= d.min_windows_per_impact)
                    if not (windows >= d.min_windows_per_impact).all() else len(windows))
        too_few = reach == 0
        shown = slice(0, reach if not too_few else n + 1)
        relax_rows.append({
            "direction": side, "source": "data", "mean_alpha_p": ap,
            "perturbations": int(sel.sum()), "impacts_compared": reach,
            "relaxation_impacts": None if too_few else relaxation_impact(
                [mv["mean"].to_numpy()[shown], mt["mean"].to_numpy()[shown]],
                [se_v[shown], se_t[shown]], tol, d.relaxation_z),
            "verdict": (f"too few perturbations ({int(windows[0])} < "
                        f"data_analysis.min_windows_per_impact = {d.min_windows_per_impact})"
                        if too_few else ""),
        })
        relax_rows.append({
            "direction": side, "source": "model", "mean_alpha_p": ap, "perturbations": 0,
            "impacts_compared": reach if not too_few else n + 1,
            "relaxation_impacts": relaxation_impact(
                [r.dv[shown], np.degrees(r.dtheta[shown])], [np.zeros(n + 1)[shown]] * 2, tol,
                d.relaxation_z),
        })
    model = pd.DataFrame(model_rows)
    relax = pd.DataFrame(relax_rows)
    relax["relaxation_impacts"] = relax["relaxation_impacts"].astype(float)  # NaN: no verdict
    relax["verdict"] = [v if isinstance(v, str) and v else relaxed_text(int(k), int(h))
                        for v, k, h in zip(relax.get("verdict", [""] * len(relax)),
                                           relax["relaxation_impacts"].fillna(-1),
                                           relax["impacts_compared"])]
    relax["criterion"] = (f"|mean| <= max(tol, {d.relaxation_z:g} SE) for v (tol "
                          f"{rel.tolerance_v_m_s:g} m/s) and theta (tol "
                          f"{rel.tolerance_theta_deg:g} deg) from k on")
    cut = int(np.sum(np.isnan(w_v.values[:, -1])))
    n_down, n_up = int((direction == "decrease").sum()), int((direction == "increase").sum())
    lines = [f"data {impacts.path}: {len(w_v.values)} perturbations ({n_down}"
             f" decrease, {n_up} increase); {cut} windows cut short "
             "by the next perturbation, the trial's end or a gap in k (their later impacts are "
             "not averaged)",
             f"{racket_text(params)}; {used.text()} (alpha_0): v~ = {fp.v_m_s:.3f} m/s,"
             f" theta~ = {fp.theta_deg:.1f} deg"]
    for row in relax.itertuples():
        judged = (f" (judged over k < {row.impacts_compared}: the impacts at least "
                  f"{d.min_windows_per_impact} windows reach)"
                  if row.source == "data" and not row.verdict.startswith("too few") else "")
        lines.append(f"{row.direction} (alpha_p {row.mean_alpha_p:.3f}), {row.source}: impacts "
                     f"to relax {row.verdict}{judged}")
    frames = {"aligned.csv": aligned, "model_response.csv": model, "relaxation_data.csv": relax}
    return frames, lines


def impulse_data_draw(frames: dict[str, pd.DataFrame]) -> dict:
    aligned, model = frames["aligned.csv"], frames["model_response.csv"]
    fig, axes = new_figure(2, 2, width=11, height=7, sharex=True)
    for col, side in enumerate(("decrease", "increase")):
        for row, (q, mq, label) in enumerate((("v_m_s", "dv_m_s", "deviation of $v_k$ (m/s)"),
                                              ("theta_deg", "dtheta_deg",
                                               r"deviation of $\theta_k$ (deg)"))):
            ax = axes[row, col]
            ax.axhline(0, color="k", ls="--", lw=1)
            a = aligned[(aligned.quantity == q) & (aligned.direction == side)].sort_values("k")
            m = model[model.direction == side].sort_values("k")
            if len(a):
                ax.errorbar(a["k"], a["mean"], yerr=a["sd"], fmt="-o", color="k", capsize=3,
                            ms=4, label=r"data: mean $\pm$ SD")
            if len(m):
                ax.plot(m["k"], m[mq], "-s", color="0.6", ms=4,
                        label=f"model at $\\alpha_p$ = {m['alpha_p'].iloc[0]:.3f}")
            ax.set_ylabel(label)
            integer_axis(ax)
            if row == 1:
                ax.set_xlabel(IMPACT_AFTER_LABEL)
            if row == 0:
                ax.set_title(perturbation_title(side == "decrease"))
                if ax.get_legend_handles_labels()[0]:
                    ax.legend(fontsize=8)
            if not len(a) and not len(m):  # a lab that perturbs one way only
                ax.text(0.5, 0.5, "no perturbations this way", transform=ax.transAxes,
                        ha="center", va="center", color="0.4")
    fig.suptitle("Fig. 9 with data: relaxation after a perturbation (data black, model grey)")
    fig2, axes2 = new_figure(2, 1, width=7, height=7, sharex=True)
    modulations = (("racket_period_s", "racket period change (ms)", 1e3),
                   ("racket_amplitude_m", "racket amplitude change (mm)", 1e3))
    for row, (q, label, unit_scale) in enumerate(modulations):
        ax = axes2[row, 0]
        ax.axhline(0, color="0.7", lw=0.8)
        for side, colour in (("increase", "k"), ("decrease", "0.6")):
            a = aligned[(aligned.quantity == q) & (aligned.direction == side)].sort_values("k")
            if len(a):
                ax.errorbar(a["k"], a["mean"] * unit_scale, yerr=a["sd"] * unit_scale, fmt="-o",
                            color=colour, capsize=3, ms=4, label=f"$\\alpha$ {side}")
        ax.set_ylabel(label)
        integer_axis(ax)
        low, high = ax.get_ylim()
        ax.set_ylim(min(low, -1.0), max(high, 1.0))  # a constant racket shows as flat, not noise
        ax.legend(fontsize=8)
    axes2[1, 0].set_xlabel(IMPACT_AFTER_LABEL)
    fig2.suptitle("Fig. 11 with data: racket period and amplitude modulation\n(difference from "
                  r"the trial's baseline, mean $\pm$ SD)")
    return {"impulse_data.png": fig, "modulation_data.png": fig2}


# -- regression --data impacts.csv (Fig. 7) ---------------------------------------------------
def is_impacts_table(path_text: str) -> bool:
    """An impacts table (trial, k, v_m_s, ...) rather than a trials CSV (a_r_m, tau_s)."""
    try:
        header = pd.read_csv(path_text, nrows=0).columns
    except Exception:  # the trials reader gives the one-line error
        return False
    cols = {str(c).strip() for c in header}
    return {"trial", "k", "racket_period_s", "racket_amplitude_m"} <= cols and "a_r_m" not in cols


def trial_means_from_impacts(source: ImpactsSource, config, options
                             ) -> tuple[pd.DataFrame, DataModel]:
    """One row per trial: mean racket amplitude (a_r_m), mean racket period (tau_s), the
    circular mean phase of impact (theta_deg, in (-180, 180]), and the model's alpha and g
    (``data_parameters.model_for_data``: the data's unless set by the user); and that model."""
    impacts = read_impacts(source, needs=MODEL_COLUMNS, command="regression --data",
                           min_bounces=2, drop_short=short_trials_warning(source, options))
    model = model_for_data(impacts, config, options, source)
    rows = []
    for trial, g in impacts.by_trial():
        theta = circular_mean(g["theta_rad"])
        rows.append({"trial": trial, "a_r_m": float(g["racket_amplitude_m"].mean()),
                     "tau_s": float(g["racket_period_s"].mean()),
                     "theta_deg": (math.degrees(theta) + 180.0) % 360.0 - 180.0,
                     "alpha": model.alpha.value, "g": model.g.value, "bounces": len(g)})
    frame = pd.DataFrame(rows)
    if (frame["theta_deg"].abs() >= 90).any():
        bad = frame[frame["theta_deg"].abs() >= 90].iloc[0]
        # the data cannot answer (a session that ends in chatter): a study skips it, warned
        raise TooFewObservationsError(
            f"data: {impacts.path}: trial {bad['trial']}: mean phase of impact "
            f"{bad['theta_deg']:.1f} deg is outside (-90, 90): eq. 15 has no positive slope "
            "there")
    return frame, model
