"""Bifurcation diagram with Lyapunov exponents: beyond the paper's single parameter point.

One parameter (Gamma = a_r w^2 / g, the racket amplitude, the racket period or alpha) is swept
over a range; at every value the map (eqs. 5, 6) is iterated from several initial conditions,
a transient is discarded, and the impacts after it are recorded. Each orbit's attractor
(``period<p>`` in the wrapped phase, ``chaotic``, ``sticking``, ...) and its largest Lyapunov
exponent (the map's Jacobian at every impact, by implicit differentiation of eqs. 5, 6) come
from ``analysis.bifurcation`` and ``analysis.lyapunov``. The figure draws the period-1 orbit's
existence threshold (the fold, eq. 8) and flip threshold (eq. 14) where continuation locates
them (``analysis.continuation``, exact to rounding), with the closed forms beside them in
``thresholds.csv``; the flip is also located by brute force on the map's iterated orbits, by
multisection on the detected period, and compared.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import pandas as pd
from pydantic import Field, model_validator

from ..runtime.config import ConfigError, ExperimentConfig, StrictModel
from ..memory import check_array_memory
from ..model.params import MIN_HOP_S, ModelError, ModelParams
from ..analysis.bifurcation import (
    FlipBracket,
    FlipLocation,
    SweepSettings,
    attractor_names,
    period_doubling_candidates,
    iterate_sweep,
    locate_period_doublings,
    parameter_column,
    parameter_point,
    period1_log_radius,
    period1_thresholds,
    sweep_parameters,
)
from ..analysis.continuation import continued_period1_thresholds
from .plotting import caption_figures, publication_style
from .base import Experiment, ExperimentResult, RunOptions

Parameter = Literal["gamma", "racket_amplitude", "racket_period", "alpha"]
#: outcomes that are not an attractor of the map (the orbit ends)
NOT_ATTRACTORS = ("sticking", "below_racket", "resting")


class SweepBlock(StrictModel):
    """numpy.linspace(start, stop, num) of the swept parameter (its unit: m, s or none)."""

    parameter: Parameter = "gamma"
    start: float = 1.0
    stop: float = 2.6
    num: int = Field(400, ge=2, le=100_000)

    @model_validator(mode="after")
    def _distinct(self):
        if self.start == self.stop:
            raise ValueError("start and stop must differ")
        return self


class InitialConditionsBlock(StrictModel):
    """Every combination of these: the ball leaves the racket at phase theta0 with v0."""

    theta0_deg: list[float] = Field([45.0, 90.0, 135.0], min_length=1, max_length=1000)
    v0_m_s: list[float] = Field([3.0, 5.0, 7.0, 9.0, 11.0], min_length=1, max_length=1000)


class IterateBlock(StrictModel):
    transient_impacts: int = Field(1000, ge=0, description="discarded")
    measured_impacts: int = Field(1000, ge=1, description="Lyapunov exponent averaged over")
    recorded_impacts: int = Field(64, ge=2, description="last measured impacts kept")
    max_period: int = Field(32, ge=1, description="longest period detected")
    period_tolerance: float = Field(1e-6, gt=0.0, description="m/s and rad")
    min_hop_s: float = Field(MIN_HOP_S, ge=0.0, description="s, shortest hop not sticking")
    chaos_threshold: float = Field(0.01, ge=0.0, description="per impact")

    @model_validator(mode="after")
    def _consistent(self):
        if self.recorded_impacts > self.measured_impacts:
            raise ValueError("recorded_impacts must not exceed measured_impacts")
        if self.recorded_impacts < 2 * self.max_period:
            raise ValueError("recorded_impacts must be at least 2 * max_period")
        return self

    def settings(self, **changes) -> SweepSettings:
        fields = self.model_dump()
        fields.update(changes)
        return SweepSettings(**fields)


class FlipBlock(StrictModel):
    """Locating the period-1 -> period-2 changes of the sweep on the map itself."""

    locate: bool = True
    transient_impacts: int = Field(5000, ge=0, description="longer: slow convergence at a flip")
    probes: int = Field(15, ge=1, description="values per multisection round")
    rounds: int = Field(2, ge=0)

    @model_validator(mode="after")
    def _fits_in_memory(self):
        check_array_memory(self.probes + 2, f"probes = {self.probes:,} values",
                           "reduce probes")
        return self


class LimitsBlock(StrictModel):
    max_orbits: int = Field(1_000_000, ge=1, description="values x initial conditions at most")


class BifurcationConfig(ExperimentConfig):
    sweep: SweepBlock = SweepBlock()
    initial_conditions: InitialConditionsBlock = InitialConditionsBlock()
    iterate: IterateBlock = IterateBlock()
    flip: FlipBlock = FlipBlock()
    limits: LimitsBlock = LimitsBlock()


def run(config: BifurcationConfig, options: RunOptions) -> ExperimentResult:
    base = config.params
    sweep = config.sweep
    for key in ("start", "stop"):  # the valid ranges are intervals: the ends suffice
        try:
            parameter_point(base, sweep.parameter, getattr(sweep, key))
        except ModelError as exc:
            raise ConfigError(f"sweep.{key}: {exc}") from None
    values = np.linspace(sweep.start, sweep.stop, sweep.num)
    ics = config.initial_conditions
    theta0_deg, v0 = (a.ravel() for a in np.meshgrid(ics.theta0_deg, ics.v0_m_s, indexing="ij"))
    n_ic = theta0_deg.size
    if values.size * n_ic > config.limits.max_orbits:
        raise ConfigError(
            f"limits.max_orbits: {values.size} values x {n_ic} initial conditions = "
            f"{values.size * n_ic:,} orbits, more than limits.max_orbits = "
            f"{config.limits.max_orbits:,}; reduce sweep.num or initial_conditions, or raise "
            "limits.max_orbits")
    settings = config.iterate.settings()

    params = sweep_parameters(base, sweep.parameter, np.repeat(values, n_ic))
    total = settings.transient_impacts + settings.measured_impacts
    options.progress.start(total, "bifurcation: impacts")
    orbits = iterate_sweep(np.tile(np.deg2rad(theta0_deg), values.size), np.tile(v0, values.size),
                           params, settings, options.progress.advance)
    column = parameter_column(sweep.parameter)
    attractors, bifurcation, periods = orbit_frames(column, values, theta0_deg, v0, params,
                                                    orbits, settings)
    per_value = value_summary(attractors, column, values, base, sweep.parameter)
    thresholds = threshold_frame(config, per_value, periods.reshape(values.size, n_ic), values,
                                 theta0_deg, v0, options)
    frames = {"bifurcation.csv": bifurcation, "attractors.csv": attractors,
              "values.csv": per_value, "thresholds.csv": thresholds}
    figures = draw(frames)
    fixed = {"alpha": f"alpha = {base.alpha:g}", "g": f"g = {base.g:g} m/s^2",
             "racket_amplitude": f"a_r = {base.racket_amplitude:g} m",
             "racket_period": f"tau = {base.racket_period:g} s"}
    fixed.pop("racket_amplitude" if sweep.parameter == "gamma" else sweep.parameter)
    caption_figures(figures, None, ", ".join(fixed.values()) + f"; {sweep.parameter} from "
                    f"{values.min():g} to {values.max():g}")
    return ExperimentResult(frames=frames, figures=figures,
                            summary=summary_lines(thresholds, per_value, column,
                                                  config.flip.locate))


def orbit_frames(column: str, values: np.ndarray, theta0_deg: np.ndarray, v0: np.ndarray,
                 params, orbits, settings: SweepSettings
                 ) -> tuple[pd.DataFrame, pd.DataFrame, np.ndarray]:
    """The tables of a sweep's orbits (``iterate_sweep`` of every value x initial condition,
    values slowest): ``attractors.csv`` (one row per orbit: its attractor, period, Lyapunov
    exponent with its standard error, sticking impact, and ``peak_stretch``, the largest ln
    growth of a perturbation of its start), the recorded impacts (``bifurcation.csv``:
    value, initial condition, impact, v, wrapped theta, of the orbits that did not stick),
    and the periods (0: none)."""
    names, periods = attractor_names(orbits, settings)
    n_ic = theta0_deg.size
    value_of_state = np.repeat(values, n_ic)
    ic_of_state = np.tile(np.arange(n_ic), values.size)
    attractors = pd.DataFrame({
        **with_gamma(column, value_of_state, params.gamma),
        "initial_condition": ic_of_state,
        "theta0_deg": np.tile(theta0_deg, values.size),
        "v0_m_s": np.tile(v0, values.size),
        "attractor": names,
        "period": periods,
        "lyapunov_per_impact": orbits.lyapunov,
        "lyapunov_se_per_impact": orbits.lyapunov_se,
        "stuck_at_impact": orbits.stuck_at,
        "peak_stretch": orbits.peak_stretch,
    })
    if orbits.locked_cycles is not None:  # exact sticking: the locked orbits' periods
        attractors["locked_cycles"] = orbits.locked_cycles
    recorded = np.isfinite(orbits.v[:, 0])
    n_rec = orbits.v.shape[1]
    points = pd.DataFrame({
        column: np.repeat(value_of_state[recorded], n_rec),
        "initial_condition": np.repeat(ic_of_state[recorded], n_rec),
        "impact": np.tile(np.arange(n_rec) + orbits.first_recorded_impact, int(recorded.sum())),
        "v_m_s": orbits.v[recorded].ravel(),
        "theta_deg": np.degrees(orbits.theta[recorded]).ravel(),
    })
    return attractors, points, periods


def with_gamma(column: str, values, gamma) -> dict:
    """The swept parameter's column, then Gamma = a_r w^2 / g unless Gamma is the one swept."""
    return {column: values} if column == "gamma" else {column: values, "gamma": gamma}


def value_summary(attractors: pd.DataFrame, column: str, values, base: ModelParams,
                  parameter: str) -> pd.DataFrame:
    """One row per swept value: the attractors found (most initial conditions first); the
    dominant one (reached by most initial conditions, sticking and below_racket counted only
    when nothing else is found) and its mean exponent; the largest exponent over the orbits
    that did not stick; ln of eq. 10's spectral radius (the period-1 orbit's exponent where it
    is stable; NaN where eq. 8 has no solution)."""
    grouped = attractors.groupby(column, sort=False)

    def found(names: pd.Series) -> str:
        counts = names.value_counts()
        order = sorted(counts.index, key=lambda n: (-counts[n], n))
        return "+".join(order)

    def dominant(names: pd.Series) -> str:
        moving = names[~names.isin(NOT_ATTRACTORS)]
        if moving.empty:
            return names.value_counts().index[0]
        counts = moving.value_counts()
        return min(counts.index, key=lambda n: (-counts[n], n))

    dominant_name = grouped["attractor"].agg(dominant)
    on_dominant = attractors["attractor"].to_numpy() == dominant_name.reindex(
        attractors[column]).to_numpy()
    dominant_exponent = attractors[on_dominant].groupby(column, sort=False)[
        "lyapunov_per_impact"].mean()
    single = sweep_parameters(base, parameter, values)
    return pd.DataFrame({
        **with_gamma(column, values, single.gamma),
        "attractors": grouped["attractor"].agg(found).to_numpy(),
        "dominant_attractor": dominant_name.to_numpy(),
        "n_initial_conditions": grouped.size().to_numpy(),
        "n_sticking": grouped["attractor"].agg(lambda s: int((s == "sticking").sum())).to_numpy(),
        "lyapunov_max_per_impact": grouped["lyapunov_per_impact"].max().to_numpy(),
        "lyapunov_dominant_per_impact": dominant_exponent.reindex(values).to_numpy(),
        "ln_spectral_radius_eq10": period1_log_radius(single),
    })


def threshold_frame(config: BifurcationConfig, per_value: pd.DataFrame, periods: np.ndarray,
                    values: np.ndarray, theta0_deg: np.ndarray, v0: np.ndarray,
                    options: RunOptions) -> pd.DataFrame:
    """Closed-form thresholds of the period-1 orbits (eqs. 8, 14; hopping 1, 2, ... racket
    cycles) that fall inside the sweep, the flip located on the map, and where chaos begins
    (the first value in sweep order with a chaotic orbit)."""
    base, sweep = config.params, config.sweep
    column = parameter_column(sweep.parameter)
    lo, hi = min(sweep.start, sweep.stop), max(sweep.start, sweep.stop)
    rows = []
    for cycles in range(1, 11):
        th = period1_thresholds(base, sweep.parameter, cycles)
        for kind, equation, value in (("existence", "eq. 8", th.existence),
                                      ("flip", "eq. 14", th.flip)):
            if cycles == 1 or lo <= value <= hi:
                rows.append(dict(threshold=kind, cycles=cycles, equation=equation,
                                 closed_form=value))
    table = pd.DataFrame(rows)
    # the thresholds located by continuation (analysis.continuation): the fold where the orbit
    # is born and its flip, exact to rounding; the figure draws its lines there
    continued = {cycles: continued_period1_thresholds(base, sweep.parameter, cycles)
                 for cycles in sorted(set(table.cycles))}
    table["continuation"] = [continued[c][0 if kind == "existence" else 1]
                             for kind, c in zip(table.threshold, table.cycles)]
    for name in ("located", "located_period1_end", "located_period2_end", "relative_difference"):
        table[name] = math.nan

    if config.flip.locate:
        for loc in locate_flips(config, periods, values, theta0_deg, v0, options):
            match = (table.threshold == "flip") & (table.cycles == loc.cycles)
            if not match.any():
                th = period1_thresholds(base, sweep.parameter, loc.cycles)
                table.loc[len(table)] = dict(
                    threshold="flip", cycles=loc.cycles, equation="eq. 14", closed_form=th.flip,
                    continuation=continued_period1_thresholds(base, sweep.parameter,
                                                              loc.cycles)[1])
                match = (table.threshold == "flip") & (table.cycles == loc.cycles)
            table.loc[match, "located"] = loc.value
            table.loc[match, "located_period1_end"] = loc.period1_end
            table.loc[match, "located_period2_end"] = loc.period2_end
            table.loc[match, "relative_difference"] = (
                loc.value / table.loc[match, "closed_form"] - 1.0)

    for name, chaotic in (
        ("chaos_onset", (per_value.dominant_attractor == "chaotic").to_numpy()),
        ("first_chaotic_orbit", per_value.attractors.str.contains("chaotic").to_numpy()),
    ):
        onset = values[np.argmax(chaotic)] if chaotic.any() else math.nan
        table.loc[len(table)] = dict(threshold=name, cycles=0, equation="",
                                     closed_form=math.nan, located=onset)
    return table.rename(columns={c: f"{c}_{column}" for c in
                                 ("closed_form", "continuation", "located",
                                  "located_period1_end", "located_period2_end")})


ONSET_TEXT = {
    "chaos_onset": "chaos begins (first value whose dominant attractor is chaotic)",
    "first_chaotic_orbit": "first chaotic orbit of any initial condition",
}


#: candidate period changes of the sweep checked at most (all in one batch)
MAX_FLIP_CANDIDATES = 8


def locate_flips(config: BifurcationConfig, periods: np.ndarray, values: np.ndarray,
                 theta0_deg: np.ndarray, v0: np.ndarray, options: RunOptions) -> list:
    """Every period-1 <-> period-2 change of the sweep (the first few) that a longer transient
    confirms, narrowed by multisection, all in one batch; the first one (in sweep order) per
    period-1 orbit (racket cycles per hop)."""
    settings = config.iterate.settings(
        # only the period is read: no exponent, so no measuring beyond the recorded impacts
        transient_impacts=config.flip.transient_impacts,
        measured_impacts=config.iterate.recorded_impacts)
    brackets = []
    for i, j, ic in period_doubling_candidates(periods)[:MAX_FLIP_CANDIDATES]:
        # widen by one value each side: the sweep's shorter transient blurs the change
        ends = [values[max(i - 1, 0)], values[min(j + 1, values.size - 1)]]
        if periods[i, ic] == 2:
            ends.reverse()
        brackets.append(FlipBracket(ends[0], ends[1], math.radians(theta0_deg[ic]), v0[ic]))
    options.progress.start(
        # the ends, each round, the narrowed ends
        (config.flip.rounds + 2) * (settings.transient_impacts + settings.measured_impacts),
        "bifurcation: locating the flips")
    located: dict[int, FlipLocation] = {}
    for loc in locate_period_doublings(config.params, config.sweep.parameter, brackets,
                                       settings=settings, probes=config.flip.probes,
                                       rounds=config.flip.rounds,
                                       on_impact=options.progress.advance):
        if loc is not None:
            located.setdefault(loc.cycles, loc)
    return list(located.values())


def summary_lines(thresholds: pd.DataFrame, per_value: pd.DataFrame, column: str,
                  locate: bool) -> list[str]:
    lines = []
    flips = thresholds[thresholds.threshold == "flip"]
    low, high = float(per_value[column].min()), float(per_value[column].max())

    def inside(row: dict) -> bool:  # eq. 14's flip (the continuation's) within the sweep
        value = row[f"continuation_{column}"]
        value = value if np.isfinite(value) else row[f"closed_form_{column}"]
        return bool(np.isfinite(value) and low <= value <= high)

    unlocated = any(inside(row._asdict()) for row in flips.itertuples(index=False)
                    if not np.isfinite(getattr(row, f"located_{column}")))
    if locate and flips[f"located_{column}"].isna().all() and not unlocated:
        lines.append("flip not located: no period-1 <-> period-2 change of the sweep was "
                     "confirmed with flip.transient_impacts")
    for row in thresholds.itertuples(index=False):
        rec = row._asdict()
        closed, located = rec[f"closed_form_{column}"], rec[f"located_{column}"]
        if row.threshold in ONSET_TEXT:
            lines.append(f"{ONSET_TEXT[row.threshold]}: {column} = {located:.6g}"
                         if np.isfinite(located) else f"{ONSET_TEXT[row.threshold]}: none")
        elif np.isfinite(located):
            lines.append(f"flip of the period-1 orbit ({row.cycles} cycle(s) per hop): located "
                         f"{column} = {located:.6g}, eq. 14 {closed:.6g}, relative difference "
                         f"{row.relative_difference:+.2e}; continuation "
                         f"{rec[f'continuation_{column}']:.10g}")
        elif locate and row.threshold == "flip" and inside(rec):
            lines.append(f"flip of the period-1 orbit ({row.cycles} cycle(s) per hop): not "
                         f"located (eq. 14: {column} = {closed:.6g}, inside the sweep): no "
                         "period-1 -> period-2 change there was confirmed with "
                         "flip.transient_impacts (the starts stuck or jumped to another orbit)")
    counts = per_value.attractors.str.split("+").explode().value_counts()
    lines.append("attractors found (values where each occurs): "
                 + ", ".join(f"{name} {n}" for name, n in counts.items()))
    return lines


# -- figure -----------------------------------------------------------------------------------
THRESHOLD_STYLE = {"existence": dict(color="tab:blue", ls="--"),
                   "flip": dict(color="tab:red", ls="--")}


def _runs(mask: np.ndarray):
    """(start, stop) index pairs of the runs of True in ``mask``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return list(zip(edges[::2], edges[1::2] - 1))


@publication_style
def draw(frames: dict[str, pd.DataFrame]) -> dict:
    """bifurcation.png: v after impact against the swept parameter with the closed-form
    thresholds, and the Lyapunov exponents below; from the CSVs alone."""
    from .plotting import sweep_figure

    bif, attractors = frames["bifurcation.csv"], frames["attractors.csv"]
    per_value, thresholds = frames["values.csv"], frames["thresholds.csv"]
    column = per_value.columns[0]
    fig, top, bottom = sweep_figure(column)
    exact = "locked_cycles" in attractors  # exact sticking (min_hop_s 0)
    on_locked = np.zeros(len(bif), dtype=bool)
    if exact:
        locked = attractors.loc[attractors.attractor == "locked", [column, "initial_condition"]]
        on_locked = pd.MultiIndex.from_frame(bif[[column, "initial_condition"]]).isin(
            pd.MultiIndex.from_frame(locked))
    top.plot(bif.loc[~on_locked, column], bif.loc[~on_locked, "v_m_s"], ",", color="black",
             alpha=0.6, rasterized=True)
    if on_locked.any():
        top.plot(bif.loc[on_locked, column], bif.loc[on_locked, "v_m_s"], ",", color="tab:blue",
                 alpha=0.8, rasterized=True,
                 label="locked orbits (exact sticking): resolved impacts of a period")

    x = per_value[column].to_numpy()
    half_step = abs(x[1] - x[0]) / 2 if x.size > 1 else 0.0
    if exact:  # where every initial condition locks: today's grey bands, now resolved
        n_locked = attractors.groupby(column, sort=False)["attractor"].agg(
            lambda s: int((s == "locked").sum())).reindex(x).to_numpy()
        all_stick = n_locked == per_value["n_initial_conditions"].to_numpy()
        band = "every initial condition locks (sticks and is released each period)"
    else:
        all_stick = (per_value["n_sticking"] == per_value["n_initial_conditions"]).to_numpy()
        band = "every initial condition sticks"
    for k, (a, b) in enumerate(_runs(all_stick)):
        for ax in (top, bottom):
            ax.axvspan(min(x[a], x[b]) - half_step, max(x[a], x[b]) + half_step,
                       color="#e3ecf7" if exact else "0.88", lw=0,
                       label=band if (k, ax) == (0, top) else None)

    labelled: set = set()
    for row in thresholds[thresholds.threshold.isin(["existence", "flip"])].itertuples():
        # at the continuation's threshold (the closed form's where it located none)
        value = getattr(row, f"continuation_{column}")
        if not np.isfinite(value):
            value = getattr(row, f"closed_form_{column}")
        if not np.isfinite(value) or not (x.min() - half_step <= value <= x.max() + half_step):
            continue  # outside the sweep: a line there would stretch the axis to it
        paper_orbit = row.cycles == 1
        verb = "exists" if row.threshold == "existence" else "flips"
        text = (f"period-1 orbit {verb} (continuation; {row.equation})" if paper_orbit else
                f"period-1 orbit hopping $n \\geq 2$ racket cycles {verb}")
        label: str | None = None if text in labelled else text
        labelled.add(text)
        for ax in (top, bottom):
            ax.axvline(value, lw=0.9 if paper_orbit else 0.7, alpha=1.0 if paper_orbit else 0.5,
                       label=label if ax is top else None, **THRESHOLD_STYLE[row.threshold])
    onset = thresholds.loc[thresholds.threshold == "chaos_onset", f"located_{column}"]
    if onset.notna().any():
        for ax in (top, bottom):
            ax.axvline(float(onset.iloc[0]), color="tab:purple", lw=0.9, ls=":",
                       label="chaos begins (dominant attractor)" if ax is top else None)

    top.set_ylabel(r"ball velocity after impact $v_k$ (m/s)")
    top.set_title("Bifurcation diagram of the ball bouncing map (eqs. 5, 6)")

    ok = np.isfinite(attractors["lyapunov_per_impact"])
    bottom.plot(attractors.loc[ok, column], attractors.loc[ok, "lyapunov_per_impact"], ".",
                ms=1.5, color="0.4", label="largest Lyapunov exponent of each orbit",
                rasterized=True)
    superstable = np.isneginf(attractors["lyapunov_per_impact"])
    if superstable.any():  # -inf: drawn on the panel's lower edge
        bottom.plot(attractors.loc[superstable, column], np.zeros(int(superstable.sum())), "v",
                    ms=2.5, color="tab:blue", transform=bottom.get_xaxis_transform(),
                    clip_on=False, label="locked orbit: exponent -inf (superstable)")
    log_radius = per_value["ln_spectral_radius_eq10"].where(
        per_value["ln_spectral_radius_eq10"] <= 0.0)
    bottom.plot(x, log_radius, color="tab:green", lw=1.2,
                label=r"$\ln$ spectral radius of the stable period-1 orbit (eq. 10)")
    bottom.axhline(0.0, color="black", lw=0.6)
    bottom.set_ylabel("Lyapunov exponent\n(per impact)")
    handles, labels = [], []
    for ax in (top, bottom):
        h, lab = ax.get_legend_handles_labels()
        handles += h
        labels += lab
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=7, frameon=False,
               markerscale=4)
    return {"bifurcation.png": fig}


EXPERIMENT = Experiment(name="bifurcation", schema=BifurcationConfig, run=run, draw=draw)
