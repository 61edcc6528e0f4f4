"""The model's alpha and g for a ``--data`` analysis: the data's own, unless the user set them.

Every ``--data`` analysis (``learning``, ``regression``, ``acf``, ``impulse``, ``control``)
runs the model at the data's racket (the mean period and amplitude of the impacts) and at the
data's alpha and g:

* alpha (eq. 3): the mean of the impacts table's ``alpha_measured`` column (per impact, from
  the ball's velocities around it), else the median of its ``alpha`` column (logged by a
  virtual set-up's events); over the unperturbed impacts when the table has ``perturbed``.
* g: ``g_m_s2`` of the ``setup.csv`` beside the table (``bounce_cli.data.setup_table``, measured
  from the ball's free flights), else the mean of a ``g_m_s2`` column.

``regression --data`` also reads a trials CSV (one row per trial: ``a_r_m``, ``tau_s``); its
data's alpha and g are its ``alpha`` and ``g`` columns (one value per condition), under the
same rules (``trials_model``).

``model_at_data`` builds that model, once for every analysis of impacts (``acf``, ``impulse``,
``control``, a study's units): alpha and g from here, the racket the means of the table's
``racket_amplitude_m`` and ``racket_period_s`` columns.

"Set by the user" means given on this command line: ``--set model.alpha=...`` (or
``model.g``), or written under ``model:`` in the user's own ``--config`` file with a value
other than the bundled config's (``runtime.config.keys_set_by_user``: a config printed by
``--print-config`` and loaded back holds every default, which are no choice). The values of a
bundled config (the paper's) are not set by the user: with ``--data`` they are replaced by the
data's. A value set by the user wins over the data's. A value that is neither in the data nor
set is a one-line error naming both ways to give it. Library use (``RunOptions`` without
``model_set_by_user``, and the simulated lab sessions, whose config's model made the data)
counts every config value as set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..model.linear import stability
from ..model.params import ModelError, ModelParams
from ..runtime.config import DATA_MODEL_KEYS, ConfigError
from .plausibility import phase_unit_warning, racket_warnings
from .setup_table import SETUP_FILE, read_setup


@dataclass(frozen=True)
class ModelValue:
    """One model parameter and where it came from: ``source`` is ``set`` (by the user),
    ``config`` (library use: the config's value), ``measured`` (per impact,
    ``alpha_measured``; or ``setup.csv``), ``events`` (the ``alpha`` column) or ``column``
    (a ``g_m_s2`` column; a trials CSV's ``alpha`` or ``g``); ``n`` the observations it rests
    on."""

    name: str
    value: float
    source: str
    n: int = 0
    detail: str = ""

    def text(self, unit: str = "") -> str:
        """``alpha 0.49 (measured, 438 impacts)`` or ``g 5.80 m/s^2 (set)``."""
        shown = f"{self.value:.2f}" if self.name == "g" else f"{self.value:.3g}"
        return f"{self.name} {shown}{' ' + unit if unit else ''} ({self.how()})"

    def how(self) -> str:
        """Where the value came from: ``measured, 438 impacts`` or ``set``."""
        return self.source if not self.detail else f"{self.source}, {self.detail}"

    def record(self) -> dict[str, Any]:
        """The entry of ``run.json``'s ``model_at_data``."""
        return {"value": self.value, "source": self.source, "n": self.n,
                "detail": self.detail}


@dataclass(frozen=True)
class DataModel:
    """alpha and g of the model a --data analysis runs at, with their sources."""

    alpha: ModelValue
    g: ModelValue

    def text(self) -> str:
        """``model at the data's alpha 0.49 (measured, 438 impacts), g 5.80 m/s^2 (measured)``;
        where a value is the user's (set) or the config's (library use), not "the data's":
        ``model at alpha 0.5 (set), g 9.50 m/s^2 (measured, setup.csv)``."""
        given = any(v.source == "config" or v.source.startswith("set")
                    for v in (self.alpha, self.g))
        whose = "" if given else "the data's "
        return f"model at {whose}{self.alpha.text()}, {self.g.text('m/s^2')}"

    def record(self) -> dict[str, Any]:
        return {"alpha": self.alpha.record(), "g": self.g.record()}


def _unperturbed(frame) -> Any:
    if "perturbed" in frame.columns:
        return frame[~frame["perturbed"].astype(bool)]
    return frame


def _finite(values) -> np.ndarray:
    x = np.asarray(values, dtype=float)
    return x[np.isfinite(x)]


def alpha_from_data(frame) -> ModelValue | None:
    """The data's alpha: the mean of ``alpha_measured`` (per impact), else the median of the
    ``alpha`` column (events), over the unperturbed impacts; None when the table has neither."""
    rows = _unperturbed(frame)
    if "alpha_measured" in frame.columns:
        values = _finite(rows["alpha_measured"])
        if len(values):
            return ModelValue("alpha", float(values.mean()), "measured", len(values),
                              f"{len(values)} impacts")
    if "alpha" in frame.columns:
        values = _finite(rows["alpha"])
        if len(values):
            return ModelValue("alpha", float(np.median(values)), "events", len(values),
                              f"median of {len(values)} impacts")
    return None


def g_from_data(frame, paths: list) -> ModelValue | None:
    """The data's g: ``g_m_s2`` of each file's ``setup.csv`` (several files: their mean
    weighted by flights), else the mean of a ``g_m_s2`` column; None when neither is there."""
    measured = [q for q in (read_setup(p).get("g_m_s2") for p in paths) if q is not None]
    if measured and len(measured) == len(paths):
        weights = np.array([max(q.n, 1) for q in measured], float)
        value = float(np.average([q.estimate for q in measured], weights=weights))
        n = int(sum(q.n for q in measured))
        where = SETUP_FILE if len(paths) == 1 else f"{len(paths)} {SETUP_FILE} files"
        return ModelValue("g", value, "measured", n, where)
    if "g_m_s2" in frame.columns:
        values = _finite(frame["g_m_s2"])
        if len(values):
            return ModelValue("g", float(values.mean()), "column", len(values), "g_m_s2")
    return None


def data_model(impacts, model, set_by_user: frozenset[str] | None,
               paths: list | None = None, measured_g: float | None = None,
               set_source: str = "set") -> DataModel:
    """alpha and g for the model at the data's parameters (module docstring).

    Parameters
    ----------
    impacts : bounce_cli.data.impacts.Impacts
        The checked impacts table (its ``path`` names it in messages).
    model : ModelBlock
        The config's ``model`` block.
    set_by_user : frozenset of str or None
        The model keys (``alpha``, ``g``) the user set; None: every config value counts as set.
    paths : list of path, optional
        The files the table was read from (their ``setup.csv`` give g); none for a table in
        memory.
    measured_g : float, optional
        g already measured from the recordings' flights (a study pools its recordings'
        ``setup.csv``); in place of ``paths``' ``setup.csv``, before a ``g_m_s2`` column.
    set_source : str
        The source a value the user set is recorded with (a study: ``set in the study's
        config``).

    Returns
    -------
    DataModel
        The values and their sources.

    Raises
    ------
    ConfigError
        When a value is neither in the data nor set by the user (one line naming both ways).
    """
    set_alpha, set_g = _set_values(model, set_by_user, set_source)
    alpha = set_alpha or alpha_from_data(impacts.frame)
    pooled_g = (None if measured_g is None else
                ModelValue("g", measured_g, "measured", 0, "the recordings' flights"))
    g = set_g or pooled_g or g_from_data(impacts.frame, list(paths or []))
    return _checked(impacts.path, alpha, g, {
        "alpha": "no alpha_measured or alpha column in the table",
        "g": f"no {SETUP_FILE} with g_m_s2 beside it, no g_m_s2 column"},
        f"bounce extract writes alpha_measured and {SETUP_FILE}")


def _set_values(model, set_by_user: frozenset[str] | None, set_source: str = "set"
                ) -> tuple[ModelValue | None, ModelValue | None]:
    """The config's alpha and g where they count as given (set by the user, recorded as
    ``set_source``; library use: every config value), None where the data's apply."""
    given = frozenset(DATA_MODEL_KEYS) if set_by_user is None else set_by_user
    how = "config" if set_by_user is None else set_source
    alpha = ModelValue("alpha", float(model.alpha), how) if "alpha" in given else None
    g = ModelValue("g", float(model.g), how) if "g" in given else None
    return alpha, g


def _checked(path, alpha: ModelValue | None, g: ModelValue | None, why_missing: dict[str, str],
             data_hint: str) -> DataModel:
    """The model of a --data analysis, or the one-line error of a value neither in the data
    nor set (naming both ways to give it: ``data_hint`` says how the data would hold it) or of
    a data's value outside its range."""
    missing = [name for name, found in (("alpha", alpha), ("g", g)) if found is None]
    if missing:
        keys = " and ".join(f"--set model.{name}=VALUE" for name in missing)
        raise ConfigError(f"data: {path}: the model needs " + " and ".join(
            f"{name} ({why_missing[name]})" for name in missing)
            + f": give the data's ({data_hint}) or set {keys} (or model: in your own --config)")
    assert alpha is not None and g is not None
    if not math.isfinite(alpha.value) or not 0.0 <= alpha.value < 1.0:
        raise ConfigError(f"data: {path}: the data's alpha {alpha.value:.3g} is "
                          "outside [0, 1); set model.alpha")
    if not math.isfinite(g.value) or g.value <= 0.0:
        raise ConfigError(f"data: {path}: the data's g {g.value:.3g} m/s^2 is not "
                          "positive; set model.g")
    return DataModel(alpha, g)


def trials_column_value(trials, name: str, path) -> ModelValue | None:
    """A trials CSV's ``alpha`` or ``g`` column as the data's value: its value when the trials
    share one, else their mean (then eq. 15 takes each condition's own, which the fit checks
    to be one per condition); None without the column."""
    if name not in trials.columns:
        return None
    values = np.asarray(trials[name], dtype=float)
    absent = int((~np.isfinite(values)).sum())  # several files, some without the column
    if absent:
        raise ConfigError(f"data: {path}: column {name}: missing in {absent} of {len(values)} "
                          f"trials: give it for every trial or set model.{name}")
    distinct = np.unique(values)
    detail = (f"{len(values)} trials" if len(distinct) == 1
              else f"{len(distinct)} values over {len(values)} trials, one per condition")
    return ModelValue(name, float(values.mean()), "column", len(values), detail)


def trials_model(trials, path, model, set_by_user: frozenset[str] | None) -> DataModel:
    """alpha and g for eq. 15 on a trials CSV (``regression --data``: one row per trial,
    ``a_r_m``, ``tau_s``), by the rules of ``data_model``: the user's value where set, else the
    CSV's ``alpha`` / ``g`` column (``trials_column_value``), else a one-line error naming both
    ways.

    Parameters
    ----------
    trials : pandas.DataFrame
        The trials read (``regression.read_trials``; several files concatenated).
    path : str
        The file(s), as messages name them.
    model : ModelBlock
        The config's ``model`` block.
    set_by_user : frozenset of str or None
        The model keys the user set; None: every config value counts as set.

    Returns
    -------
    DataModel
        The values and their sources; a ``column`` source leaves eq. 15 (eq. 15's slope
        (1 - alpha)/(1 + alpha) g / (4 pi cos theta)) each condition's own value.

    Raises
    ------
    ConfigError
        A value neither in the CSV nor set, a column missing for some trials, a value outside
        its range.
    """
    set_alpha, set_g = _set_values(model, set_by_user)
    alpha = set_alpha or trials_column_value(trials, "alpha", path)
    g = set_g or trials_column_value(trials, "g", path)
    return _checked(path, alpha, g, {"alpha": "no alpha column in the trials",
                                     "g": "no g column in the trials"},
                    "an alpha and a g column, one value per condition")


def model_for_data(impacts, config, options, source) -> DataModel:
    """``data_model`` for an analysis: the user's settings from ``options`` (the CLI's
    ``model_set_by_user``), the ``setup.csv`` of the file(s) ``source`` names (none for a
    table in memory), and the result recorded for ``run.json`` (``model_at_data``). The data's
    racket is checked against what a person can do (``plausibility``: a warning naming the
    likely unit slip)."""
    if source is None:
        source = config.data
    paths = [] if isinstance(source, tuple) else (
        list(source) if isinstance(source, list) else [source])
    found = data_model(impacts, config.model, options.model_set_by_user, paths)
    options.record["model_at_data"] = found.record()
    frame = impacts.frame
    if impacts.phase_in_degrees:
        columns = ("racket_acc_g", "racket_amplitude_m", "racket_period_s")
        racket = ((*(frame[c] for c in columns), found.g.value)
                  if set(columns) <= set(frame.columns) else None)
        message = phase_unit_warning(frame["theta_deg"], f"data: {impacts.path}: column "
                                                         "theta_deg", racket)
        if message:
            options.warn(message)
    if {"racket_amplitude_m", "racket_period_s"} & set(frame.columns):
        means = frame.groupby("trial", sort=False).mean(numeric_only=True)
        for message in racket_warnings(
                means.get("racket_amplitude_m", np.nan), means.get("racket_period_s", np.nan),
                f"data: {impacts.path}: column racket_amplitude_m (trial means)",
                f"data: {impacts.path}: column racket_period_s (trial means)"):
            options.warn(message)
    return found


#: the impacts table's racket columns whose means are the racket of the model at the data's
#: parameters
RACKET_COLUMNS = ("racket_amplitude_m", "racket_period_s")

#: trial-mean racket periods spanning more than this fraction of their mean are different
#: racket designs (target heights: 0.57-0.81 s in Fig. 7), not one racket's variation
MIXED_RACKET_PERIODS = 0.05


def mixed_racket_warning(impacts) -> str:
    """A warning where the trials' mean racket periods span more than ``MIXED_RACKET_PERIODS``
    of their mean: the model at the data's parameters (``model_at_data``) runs at one racket,
    their mean, which is none of the trials' (eqs. 8-10 depend on the period through
    a_r w^2); empty otherwise or without a period column."""
    frame = impacts.frame
    if "racket_period_s" not in frame.columns:
        return ""
    periods = frame.groupby("trial", sort=False)["racket_period_s"].mean().dropna()
    if periods.size < 2 or not (np.ptp(periods) > MIXED_RACKET_PERIODS * periods.mean()):
        return ""
    used = float(frame["racket_period_s"].mean())  # the model's: over all impacts
    return (f"data: {impacts.path}: the trials' racket periods range from "
            f"{periods.min():.3g} to {periods.max():.3g} s ({np.ptp(periods) / periods.mean():.0%}"
            f" of their mean): one model at the impacts' mean, {used:.3g} s, stands for them "
            "all; analyse each racket design apart (a condition of its own in a study's "
            "manifest)")


def model_at_data(impacts, found: DataModel,
                  need: Literal["stable", "fixed point"] | None = "stable",
                  racket_period: float | None = None,
                  record: dict[str, Any] | None = None) -> ModelParams:
    """The model at the data's parameters: alpha and g of ``found``, the racket the data's.

    Every analysis of an impacts table builds its model here: ``acf --data``,
    ``impulse --data``, ``control --data`` and a study's units.

    Parameters
    ----------
    impacts : bounce_cli.data.impacts.Impacts
        The impacts table: the racket amplitude a_r and period tau are the means of its
        ``racket_amplitude_m`` and ``racket_period_s`` columns over all its impacts; its
        ``path`` names it in messages.
    found : DataModel
        alpha and g (``data_model`` or ``model_for_data``: the data's unless the user set them).
    need : {"stable", "fixed point"} or None
        What the analysis needs of the model: a linearly stable period-1 fixed point (eq. 10:
        spectral radius below 1; stationary statistics), a fixed point (eq. 8:
        |cos theta~| <= 1) or nothing checked (None).
    racket_period : float, optional
        A racket period (s) in place of the data's mean (``control``'s
        ``fit.racket_period_s``).
    record : dict, optional
        A run's record (``RunOptions.record``): its ``model_at_data`` entry, alpha and g
        from ``model_for_data``, gains the racket amplitude and period used, so that
        ``run.json`` names the whole model and where each value came from.

    Returns
    -------
    ModelParams
        alpha, g, a_r, tau.

    Raises
    ------
    ConfigError
        One line when the model lacks what ``need`` asks: no period-1 fixed point (eq. 8
        gives cos theta~ > 1), or an unstable one (eq. 10).
    ModelError
        Parameters outside the model's range (``ModelParams``).
    """
    frame = impacts.frame
    alpha, g = found.alpha.value, found.g.value

    def data_mean(name: str, column: str) -> ModelValue:
        n = int(frame[column].notna().sum())
        return ModelValue(name, float(frame[column].mean()), "data", n,
                          f"mean of {n} impacts' cycles")

    amplitude_column, period_column = RACKET_COLUMNS
    amplitude = data_mean("racket_amplitude", amplitude_column)
    period_used = (data_mean("racket_period", period_column) if racket_period is None else
                   ModelValue("racket_period", racket_period, "set", 0, "fit.racket_period_s"))
    a_r, tau = amplitude.value, period_used.value
    params = ModelParams(alpha, g, a_r, tau)
    if record is not None:
        record.setdefault("model_at_data", {}).update(
            {value.name: value.record() for value in (amplitude, period_used)})
    if need is None:
        return params
    period = f"period {tau:.4g} s" if racket_period is None else f"the given period {tau:.4g} s"
    where = (f"data: {impacts.path}: the model at the data's racket amplitude {a_r:.4g} m and "
             f"{period} with alpha = {alpha:g}, g = {g:g} m/s^2")
    try:
        st = stability(params)
    except ModelError:
        raise ConfigError(f"{where} has no period-1 fixed point (eq. 8: cos theta~ = "
                          f"{params.cos_theta_fixed():.3g} > 1); check model.alpha and model.g"
                          ) from None
    if need == "stable" and not st.stable:
        raise ConfigError(f"{where} has an unstable fixed point (spectral radius "
                          f"{st.spectral_radius:.3g}, AC = {st.ac_g:.3g} g): no stationary "
                          "statistics to compare with")
    return params
