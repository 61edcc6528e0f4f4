"""``bounce study --manifest study.csv``: a lab's whole study in one command.

The manifest (:mod:`bounce_cli.data.study_manifest`) lists the recordings, one row each, with their
subject, condition and other factors. The study groups them into units (default subject x
condition), and for each unit: extracts every recording (``bounce extract``'s engine, with the
study's ``extract:`` settings and the row's own ``extract.<key>`` columns; an impacts table is
read as it is), pools the unit's trials, and runs the chosen analyses on them exactly as
``bounce <analysis> --data impacts.csv`` runs them (Figs. 6-9, 11, eq. 15). Units are
independent tasks on the one executor (``--jobs``, ``--scheduler``), resumable
(``--resume``: a unit whose config, manifest rows or files changed is rerun).

Then group statistics over the units: Fig. 7 pooled by condition (eq. 15's line and its
prediction), Fig. 6's learning trend over subjects (a mixed-effects model), the data's
spectral radius against the model's (eq. 10) with the paired difference across units, and
Figs. 8, 9, 11 averaged over subjects; and ``report.html`` (self-contained) with a section per
subject, and ``<subject>/report.html``.

A recording that cannot be read or a unit that cannot be analysed does not stop the study: it
is a row of ``failures.csv``, and the command exits 1 once everything else is written. An
analysis the unit's design cannot answer (fewer trials than a trend or a line needs,
``TooFewObservationsError``; a perturbation session for acf; no perturbation for impulse)
is not run, with a warning saying why.
"""

from __future__ import annotations

import base64
import copy
import hashlib
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Literal, Optional

import numpy as np
import pandas as pd
from pydantic import Field, field_validator, model_validator

from ..errors import TooFewObservationsError
from ..runtime import parallel
from ..runtime.artifacts import sha256_of
from ..runtime.figure_files import FIGURE_DPI
from ..runtime.config import (
    DATA_MODEL_KEYS,
    ConfigError,
    ExperimentConfig,
    StrictModel,
    apply_overrides,
    bundled_config_path,
    did_you_mean,
    read_yaml,
    validate,
)
from ..model.linear import stability
from ..model.params import ModelError, circular_mean, phase_difference
from ..data.data_parameters import (
    RACKET_COLUMNS,
    DataModel,
    data_model,
    model_at_data,
)
from ..data.impacts import Impacts
from ..data.recordings import keys_in_block, reading_keys_in_block
from ..data.setup_table import SETUP_FILE, SetupQuantity, setup_frame
from .plotting import publication_style
from .report import Section, embed_png, html_table, page
from ..data.study_manifest import Manifest, ManifestRow, Unit, read_manifest
from .base import Experiment, ExperimentResult, RunOptions

#: the analyses a study can run, in the paper's order
ANALYSES = ("learning", "regression", "acf", "impulse", "control")
AnalysisName = Literal["learning", "regression", "acf", "impulse", "control"]
#: what a study runs unless told
DEFAULT_ANALYSES: tuple[AnalysisName, ...] = ("learning", "regression", "acf", "impulse")
#: the analyses that need perturbations in the data (the impacts table's ``perturbed``)
NEEDS_PERTURBATIONS = ("impulse", "control")
#: errors that make a recording or an analysis a failure row (anything else is a bug)
RECORDED_ERRORS = (ConfigError, ModelError, ValueError, OSError)


class StudyModelBlock(StrictModel):
    """alpha and g of the model; null: each unit's own, measured from its data (the impacts
    table's ``alpha_measured`` or event ``alpha``; the extraction's ``setup.csv`` or a
    ``g_m_s2`` column). A value given here is used for every unit."""

    alpha: Optional[float] = Field(None, ge=0.0, lt=1.0, description="coefficient of restitution")
    g: Optional[float] = Field(None, gt=0.0, description="gravitational acceleration, m/s^2")


class ReportBlock(StrictModel):
    """What the reports hold besides the group figures and tables."""

    unit_figures: bool = Field(False, description="each unit's figures (Fig. 2 of its first "
                               "recording and its analyses'), written and in the reports; "
                               "off by default: drawing them costs more than the unit's "
                               "analyses (every unit's tables are written either way)")
    figures: Optional[Literal["none", "group", "all"]] = Field(
        None, description="the figures drawn (--figures): none, the group's, or the group's "
        "and every unit's; null: what the reports show (all, or group without unit_figures)")

    def drawn(self) -> str:
        """none, group or all: ``figures``, else what the reports show."""
        if self.figures is not None:
            return self.figures
        return "all" if self.unit_figures else "group"


class StudyConfig(ExperimentConfig):
    model: StudyModelBlock = StudyModelBlock()  # type: ignore[assignment]
    manifest: Optional[str] = Field(None, description="the study's manifest CSV (--manifest)")
    grouping: list[str] = Field(default_factory=lambda: ["subject", "condition"], min_length=1,
                                description="the factors that make a unit")
    analyses: list[AnalysisName] = Field(
        default_factory=lambda: list(DEFAULT_ANALYSES))
    extract: dict[str, Any] = Field(default_factory=dict,
                                    description="bounce extract's keys for every recording")
    settings: dict[str, dict[str, Any]] = Field(
        default_factory=dict, description="per analysis, its config's keys (e.g. acf: {...})")
    confidence: float = Field(0.95, gt=0.0, lt=1.0, description="level of the group intervals")
    seed: int = Field(0, ge=0, description="each unit's analyses get a stream of their own")
    report: ReportBlock = ReportBlock()

    @field_validator("grouping")
    @classmethod
    def _grouping(cls, value):
        if "subject" not in value:
            raise ValueError("must include subject (a unit is one subject's recordings)")
        if len(set(value)) != len(value):
            raise ValueError("each factor once")
        return value

    @model_validator(mode="after")
    def _blocks(self):
        unknown = [k for k in self.settings if k not in ANALYSES]
        if unknown:
            raise ValueError(f"settings: {unknown[0]!r} is not an analysis (one of "
                             f"{', '.join(ANALYSES)})"
                             f"{did_you_mean(str(unknown[0]), list(ANALYSES))}")
        if len(set(self.analyses)) != len(self.analyses):
            raise ValueError("analyses: each analysis once")
        extraction_config({"extract": self.extract}, ())  # unknown keys fail now
        for name in self.analyses:
            analysis_config(name, self.settings.get(name, {}), 0.5, 9.81, 0, None)
        return self


# -- configs of the steps ------------------------------------------------------------------------
def extraction_config(config: dict[str, Any], overrides: tuple[str, ...], file: Path | None = None,
                      events: Path | None = None, g: float | None = None):
    """``bounce extract``'s config for one recording: the bundled one, the study's
    ``extract`` keys, the manifest row's ``extract.<key>`` columns, the file."""
    from .extract import ExtractConfig
    from .registry import EXPERIMENTS

    data = read_yaml(bundled_config_path("extract"))
    data = _merged(data, config.get("extract", {}))
    if g is not None:
        data.setdefault("model", {})["g"] = g
    data = apply_overrides(data, list(overrides))
    data["data"] = None if file is None else str(file)
    data["events"] = None if events is None else str(events)
    return validate(ExtractConfig, data, "extract" if not overrides else "manifest extract.*",
                    list(overrides), EXPERIMENTS)


def analysis_config(name: str, settings: dict[str, Any], alpha: float, g: float, seed: int,
                    data: str | None):
    """The config of analysis ``name`` for a unit: its bundled config, the study's
    ``settings.<name>`` keys, the unit's alpha and g, its own seed."""
    from .registry import EXPERIMENTS, entry

    experiment = entry(name).load()
    raw = _merged(read_yaml(bundled_config_path(entry(name).config)), settings)
    raw.setdefault("model", {}).update({"alpha": alpha, "g": g})
    if "seed" in experiment.schema.model_fields:
        raw["seed"] = seed
    raw["data"] = data
    return validate(experiment.schema, raw, f"settings.{name}", commands=EXPERIMENTS)


def _merged(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for key, value in extra.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


# -- one unit ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class UnitTask:
    """A unit to analyse: its position, its rows, the study's config (JSON) and its key (what
    its results are made from: config, rows, files' contents)."""

    index: int
    unit: Unit
    config: dict[str, Any]
    key: str
    #: the formats (PNG always: the reports embed it) and resolution of its figures
    figure_formats: tuple[str, ...] = ("png",)
    dpi: float = FIGURE_DPI


def input_digests(manifest: Manifest) -> dict[Path, str]:
    """SHA-256 (hex) of the manifest and of every recording and events file it lists, each
    file once, in the manifest's order: what the study is made from."""
    digests = {manifest.path: sha256_of(manifest.path)}
    for row in manifest.rows:
        for path in (row.file, row.events):
            if path is not None and path not in digests:
                digests[path] = sha256_of(path)
    return digests


def inputs_record(manifest: Manifest, digests: dict[Path, str]) -> dict[str, Any]:
    """run.json's ``inputs``: the manifest and each file it lists, by path and SHA-256 (a
    reader can tell whether the recordings on disk are those the results were made from)."""
    return {"manifest": {"path": str(Path(manifest.path).resolve()),
                         "sha256": digests[manifest.path]},
            "files": [{"path": str(path), "sha256": digest}
                      for path, digest in digests.items() if path != manifest.path]}


def unit_key(unit: Unit, config: dict[str, Any], digests: dict[Path, str],
             figure_formats: tuple[str, ...] = ("png",), dpi: float = FIGURE_DPI) -> str:
    """SHA-256 over the study's config, the unit's manifest rows and its files' bytes (their
    ``digests``, :func:`input_digests`), and its figures' formats and resolution where they
    are not the default (PNG at FIGURE_DPI: the keys of runs before they counted)."""
    h = hashlib.sha256(json.dumps(config, sort_keys=True).encode())
    if (tuple(figure_formats), dpi) != (("png",), FIGURE_DPI):
        h.update(json.dumps([list(figure_formats), dpi]).encode())
    for row in unit.rows:
        h.update(json.dumps([str(row.file), str(row.events), sorted(row.factors.items()),
                             list(row.overrides)]).encode())
        for path in (row.file, row.events):
            if path is not None:
                h.update(bytes.fromhex(digests[path]))
    return h.hexdigest()


def unit_seed(study_seed: int, unit: Unit) -> int:
    """A seed of the unit's own, from the study's seed and the unit's name (not its position:
    adding a subject leaves the others' numbers as they were)."""
    words = np.frombuffer(hashlib.sha256(unit.folder.encode()).digest()[:16], dtype=np.uint32)
    return int(np.random.SeedSequence([study_seed, *words.tolist()]).generate_state(1)[0])


def frame_to_json(frame: pd.DataFrame) -> dict[str, Any]:
    """A DataFrame as JSON that keeps every float exactly (``repr``) and each column's dtype."""
    return {"columns": [str(c) for c in frame.columns],
            "dtypes": [str(t) for t in frame.dtypes],
            "data": [frame[c].tolist() for c in frame.columns]}


#: dtypes that :func:`frame_from_json` builds with numpy directly (a tenth of pandas' time)
_NUMPY_DTYPES = frozenset({"float64", "int64", "bool"})


def frame_from_json(data: dict[str, Any]) -> pd.DataFrame:
    """The DataFrame :func:`frame_to_json` wrote: the same columns, values and dtypes."""
    columns: dict[str, Any] = {}
    for name, dtype, values in zip(data["columns"], data["dtypes"], data["data"]):
        try:
            if dtype in _NUMPY_DTYPES:
                columns[name] = np.array(values, dtype=dtype)
            else:
                columns[name] = pd.Series(values, dtype=dtype)
        except (TypeError, ValueError, OverflowError):
            columns[name] = pd.Series(values)
    return pd.DataFrame(columns, columns=data["columns"])


def recording_names(unit: Unit) -> list[str]:
    """A name for each recording of ``unit`` (in its rows' order) that no other of its
    recordings has: the file's stem, and where several share one (``A/t.csv``, ``B/t.csv``,
    or ``T.csv`` beside ``t.csv``: one folder on macOS and Windows) the stem and the manifest
    line, ``t-line3`` (also where the stem names no folder: a
    file ``...csv`` has the stem ``..``, and gets ``file-line3``). Its per-recording outputs
    (``<unit>/extract/<name>/``) and its trials' labels are keyed by it, so that no two
    recordings overwrite or merge into each other.

    Parameters
    ----------
    unit : Unit
        The unit, its rows as the study reads them.

    Returns
    -------
    list of str
        One name per row, all different.
    """
    stems = [row.file.stem for row in unit.rows]
    # compared without case: T.csv and t.csv would share a folder on macOS and Windows
    folded = [stem.casefold() for stem in stems]
    taken = {fold for stem, fold in zip(stems, folded)
             if folded.count(fold) == 1 and stem.strip(".")}
    names = []
    for row, stem, fold in zip(unit.rows, stems, folded):
        name = stem
        # shared, or no folder's name ('.', '..': a file named ...csv would leave the unit)
        if folded.count(fold) > 1 or not stem.strip("."):
            name = f"{stem.strip('.') or 'file'}-line{row.line}"
            while name.casefold() in taken:  # a file really named so: lengthen until free
                name += "-"
            taken.add(name.casefold())
        names.append(name)
    return names


def row_label(row: ManifestRow, name: str) -> str:
    """The trial label of a recording: its ``trial`` factor, else its name (as
    :func:`recording_names` gives it)."""
    return row.factors.get("trial") or name


def read_unit_impacts(task: UnitTask, frames: dict[str, pd.DataFrame], failures: list[dict],
                      summary: list[str], warnings: list[str]
                      ) -> tuple[pd.DataFrame | None, dict[str, float]]:
    """Extract (or read) every recording of the unit; its pooled impacts table and what the
    extraction measured of the set-up (``setup.csv`` quantities, pooled over files). The
    extraction's warnings (a dropout written as 0, events off the recording's clock, ...)
    go to ``warnings``, each naming the unit and the recording."""
    from ..data.impacts import read_impacts
    from ..data.setup_table import read_setup
    from .data_side import is_impacts_table
    from .runner import execute

    cfg = task.config
    unit = task.unit
    tables, setups = [], []
    user_g = cfg["model"].get("g")
    for row, name in zip(unit.rows, recording_names(unit)):
        label = row_label(row, name)
        try:
            if is_impacts_table(str(row.file)):
                table = read_impacts(str(row.file)).frame
                setup = {q.quantity: q.estimate for q in read_setup(row.file).values()}
            else:
                ex_cfg = extraction_config(cfg, row.overrides, row.file, row.events, user_g)
                result = execute("extract", ex_cfg, write=False, figures=False,
                                 warn=extraction_warning(warnings, f"{unit.label}: {name}")
                                 ).result
                stem = f"{unit.folder}/extract/{name}"
                for file_name, frame in result.frames.items():
                    frames[f"{stem}/{file_name}"] = frame
                table = result.frames["impacts.csv"]
                setup_frame = result.frames.get("setup.csv")
                setup = ({} if setup_frame is None else
                         dict(zip(setup_frame["quantity"], setup_frame["estimate"])))
        except RECORDED_ERRORS as exc:  # the keys it names as the study takes them
            named = keys_in_block(exc, "extract") if isinstance(exc, ConfigError) else exc
            failures.append({"unit": unit.folder, "file": str(row.file), "stage": "extract",
                             "error": one_line(named)})
            continue
        trials = table["trial"].astype(str)
        single = trials.nunique() == 1 and "trial" in row.factors and row.factors["trial"]
        table = table.assign(trial=label if single else label + ":" + trials)
        tables.append(table)
        setups.append((len(table), setup))
    if not tables:
        return None, {}
    pooled = pd.concat(tables, ignore_index=True)
    measured: dict[str, float] = {}
    for quantity in MEASURED_SETUP:
        pairs = [(n, s[quantity]) for n, s in setups
                 if quantity in s and math.isfinite(s[quantity])]
        if pairs:
            weights = np.array([n for n, _ in pairs], float)
            measured[quantity] = float(np.average([v for _, v in pairs], weights=weights))
    summary.append(f"{unit.label}: {len(tables)} of {len(unit.rows)} recording(s), "
                   f"{pooled['trial'].nunique()} trial(s), {len(pooled)} impacts")
    return pooled, measured


def extraction_warning(warnings: list[str], where: str) -> Callable[[str], None]:
    """A ``warn`` for a recording's extraction in a unit: its message to ``warnings``,
    prefixed with ``where`` (unit and recording), with the reading keys it names as the study
    takes them (``extract.csv.missing_heights``)."""
    def warn(message: str) -> None:
        warnings.append(f"{where}: extract: {reading_keys_in_block(message, 'extract')}")

    return warn


#: what the unit's recordings measured of the set-up (their setup.csv), pooled weighted by
#: impacts: g for the model, the measurement noise of v_k and theta_k for acf --data's trust
#: study (which decides the intervals of short data)
MEASURED_SETUP = ("g_m_s2", "measurement_sd_v_m_s", "measurement_sd_theta_rad")


def pooled_setup(measured: dict[str, float], impacts: int) -> pd.DataFrame:
    """The unit's ``setup.csv``: what its recordings measured of the set-up
    (:data:`MEASURED_SETUP`, pooled weighted by impacts), written beside its pooled
    ``impacts.csv`` so that a single command run on that table (``bounce acf --data
    <unit>/impacts.csv``) takes the same g and measurement noise as the study did."""
    return setup_frame([SetupQuantity(quantity, value, n=impacts,
                                      note="the unit's recordings, pooled weighted by impacts")
                        for quantity, value in measured.items()])


def unit_parameters(pooled: pd.DataFrame, measured: dict[str, float],
                    model: dict[str, Any], label: str = "") -> DataModel:
    """alpha and g of a unit's model: the study's model block where set, else what the
    unit's data show (``data_parameters.data_model``, as every ``--data`` analysis applies it:
    ``alpha_measured``, else the events' ``alpha``; g from the recordings' flights, pooled in
    ``measured``, else a ``g_m_s2`` column); a unit that shows neither is a one-line error
    naming both ways."""
    block = StudyModelBlock(**model)
    set_in_config = frozenset(k for k in DATA_MODEL_KEYS if getattr(block, k) is not None)
    return data_model(Impacts(pooled, Path(label)), block, set_in_config,
                      measured_g=measured.get("g_m_s2"), set_source="set in the study's config")


def one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def condensed_warnings(labels: list[str], warnings: list[list[str]]) -> list[str]:
    """The units' warnings (``warnings[i]``: unit ``labels[i]``'s, each starting with its
    label), in order, a message that several units share word for word but for the label
    once, naming them: ``every unit (40): impulse: not run: ...`` or ``2 units (s1/a,
    s3/a): ...`` (a study of steady recordings: one line, not one per unit)."""
    units_of: dict[str, list[str]] = {}  # text -> the units that gave it ("": no unit's)
    for label, messages in zip(labels, warnings):
        prefix = f"{label}: "
        for message in messages:
            own = message.startswith(prefix)
            units_of.setdefault(message.removeprefix(prefix), []).append(label if own else "")
    lines: list[str] = []
    for text, units in units_of.items():
        named = [u for u in units if u]
        lines.extend(text for u in units if not u)
        if len(named) == 1:
            lines.append(f"{named[0]}: {text}")
        elif named and len(named) == len(labels):
            lines.append(f"every unit ({len(named)}): {text}")
        elif named:
            shown = ", ".join(named[:3]) + (f" and {len(named) - 3} more" if len(named) > 3
                                            else "")
            lines.append(f"{len(named)} units ({shown}): {text}")
    return lines


def analyse_unit(task: UnitTask) -> dict[str, Any]:
    """Everything of one unit (a worker's task): its extracted recordings, its analyses' tables,
    its row of group.csv, its warnings and failures; JSON-able (checkpoints, other processes)."""
    cfg, unit = task.config, task.unit
    frames: dict[str, pd.DataFrame] = {}
    failures: list[dict] = []
    summary: list[str] = []
    warnings: list[str] = []
    not_run: dict[str, str] = {}  # analysis -> why it did not run for this unit
    row: dict[str, Any] = {**unit.factors(), "recordings": len(unit.rows)}
    pooled, measured = read_unit_impacts(task, frames, failures, summary, warnings)
    if pooled is not None:
        frames[f"{unit.folder}/impacts.csv"] = pooled
        if measured:  # beside it, so that `bounce <analysis> --data` on it runs the same model
            frames[f"{unit.folder}/{SETUP_FILE}"] = pooled_setup(measured, len(pooled))
        # the recordings' own measurement noise travels with the pooled table to acf --data
        pooled.attrs["setup"] = {q: v for q, v in measured.items() if q != "g_m_s2"}
        found = None
        try:
            found = unit_parameters(pooled, measured, cfg["model"], unit.label)
        except ConfigError as exc:
            failures.append({"unit": unit.folder, "file": "", "stage": "model",
                             "error": one_line(exc)})
        if found is not None:
            alpha, alpha_source, g, g_source = (found.alpha.value, found.alpha.how(),
                                                found.g.value, found.g.how())
            row.update(alpha=alpha, alpha_source=alpha_source, g_m_s2=g, g_source=g_source)
            summary[0] += (f"; model at alpha {alpha:.3f} ({alpha_source}), g {g:.2f} m/s^2 "
                           f"({g_source})")
            seed = unit_seed(cfg["seed"], unit)
            for name in cfg["analyses"]:
                if name in NEEDS_PERTURBATIONS and not has_perturbations(pooled):
                    # nothing to align on: not a failure, the data have no perturbations
                    why = "the unit's impacts hold no perturbed impact to align on"
                    warnings.append(f"{unit.label}: {name}: not run: {why}")
                    not_run[name] = why
                    continue
                if name == "acf":
                    crowded = perturbations_leave_no_run(pooled, cfg, alpha, g, seed)
                    if crowded:  # a perturbation session: the stationary analysis needs
                        warnings.append(f"{unit.label}: acf: not run: {crowded}")  # others
                        not_run[name] = crowded
                        continue
                try:
                    result = run_analysis(name, cfg, alpha, g, seed, unit, pooled, warnings)
                except TooFewObservationsError as exc:  # the design cannot answer it (two
                    # trials for a trend: the virtual set-up's steady protocol): not a failure
                    why = of_unit(one_line(exc), unit)
                    warnings.append(f"{unit.label}: {name}: not run: {why}")
                    not_run[name] = why
                    if name == "regression":  # its trials still count in the pooled Fig. 7
                        trials = regression_trials(cfg, alpha, g, seed, unit, pooled)
                        if trials is not None:
                            frames[f"{unit.folder}/regression/trials.csv"] = trials
                    continue
                except RECORDED_ERRORS as exc:
                    failures.append({"unit": unit.folder, "file": "", "stage": name,
                                     "error": one_line(exc)})
                    not_run[name] = f"failed (failures.csv): {one_line(exc)}"
                    continue
                for file_name, frame in result.frames.items():
                    frames[f"{unit.folder}/{name}/{file_name}"] = frame
                summary += [f"{unit.label}: {name}: {line}" for line in result.summary]
        if found is None:
            not_run.setdefault("acf", "the unit's model parameters failed (failures.csv)")
        elif "acf" not in cfg["analyses"]:
            not_run.setdefault("acf", "acf is not among the study's analyses")
        row.update(unit_row(pooled, frames, unit, found, not_run))
    row["failures"] = len(failures)
    pngs = {}
    if ReportBlock(**cfg["report"]).drawn() == "all":
        import matplotlib

        matplotlib.use("Agg")
        for name, fig in draw_units(frames, [unit]).items():
            for file_name, data in figure_files(name, fig, task.figure_formats,
                                                task.dpi).items():
                pngs[file_name] = base64.b64encode(data).decode("ascii")
    return {"index": task.index, "key": task.key,
            "frames": {name: frame_to_json(f) for name, f in frames.items()}, "pngs": pngs,
            "row": row, "summary": summary, "warnings": warnings, "failures": failures}


def has_perturbations(pooled: pd.DataFrame) -> bool:
    """Whether a unit's pooled impacts hold a perturbed impact."""
    return "perturbed" in pooled.columns and bool(pooled["perturbed"].astype(bool).any())


def perturbations_leave_no_run(pooled: pd.DataFrame, cfg: dict[str, Any], alpha: float,
                               g: float, seed: int) -> str:
    """Why ``acf`` cannot run on a unit whose perturbations leave no run of ``max_lag`` + 2
    consecutive unperturbed, settled impacts (the virtual set-up's every fifth impact: the
    stationary analyses need a session without perturbations); '' where a run exists, or
    where the data have no perturbations (a short trial is then acf's own error)."""
    from .data_side import stationary_segments

    if not has_perturbations(pooled):
        return ""
    config = analysis_config("acf", cfg["settings"].get("acf", {}), alpha, g, seed, None)
    need = config.max_lag + 2
    # the pooled table is checked already (read or extracted): no second reading
    impacts = Impacts(pooled, Path("unit"))
    if stationary_segments(impacts, config.data_analysis.settle_after_perturbation, need):
        return ""
    return (f"the perturbations leave no run of {need} consecutive unperturbed impacts "
            "(max_lag + 2, after settle_after_perturbation): the stationary analyses need a "
            "session without perturbations, or with sparser ones (e.g. the virtual set-up's "
            "steady protocol)")


def run_analysis(name: str, cfg: dict[str, Any], alpha: float, g: float, seed: int, unit: Unit,
                 pooled: pd.DataFrame, warnings: list[str]) -> ExperimentResult:
    """One analysis of a unit, as ``bounce <name> --data`` runs it, on the pooled table held
    in memory (the study draws its own figures: none here)."""
    from .runner import execute

    config = analysis_config(name, cfg["settings"].get(name, {}), alpha, g, seed, None)
    return execute(name, config, write=False, impacts=(f"{unit.label}", pooled), figures=False,
                   warn=lambda message: warnings.append(
                       f"{unit.label}: {name}: {of_unit(message, unit)}")).result


def of_unit(message: str, unit: Unit) -> str:
    """An analysis' message about the unit's pooled table without the ``data: <unit>: `` it
    starts with (the study's warning names the unit first)."""
    return message.removeprefix(f"data: {unit.label}: ")


def regression_trials(cfg: dict[str, Any], alpha: float, g: float, seed: int, unit: Unit,
                      pooled: pd.DataFrame) -> pd.DataFrame | None:
    """Fig. 7's trial means of a unit whose own fit cannot be made (fewer than 3 trials, or
    one racket period for all), as ``run_analysis`` would have written them: they still
    count in the fit pooled over the study (``group_tables``). None where the trials cannot
    be averaged either (the error is then the regression's own, already recorded)."""
    from .base import RunOptions
    from .data_side import trial_means_from_impacts
    from .regression import with_squared_period

    config = analysis_config("regression", cfg["settings"].get("regression", {}), alpha, g,
                             seed, None)
    options = RunOptions()  # its warnings were given by the analysis that stopped
    try:
        trials, _ = trial_means_from_impacts((unit.label, pooled), config, options)
    except RECORDED_ERRORS:
        return None
    return with_squared_period(trials)


def not_run_note(analysis: str, not_run: dict[str, str] | None) -> str:
    """group.csv's note for a unit whose ``analysis`` gave no table: ``<analysis> --data not
    run: <why>`` (``not_run``: analysis -> why)."""
    return f"{analysis} --data not run: {(not_run or {}).get(analysis, '')}".rstrip(": ")


def unit_row(pooled: pd.DataFrame, frames: dict[str, pd.DataFrame], unit: Unit,
             found: DataModel | None, not_run: dict[str, str] | None = None
             ) -> dict[str, Any]:
    """group.csv's numbers of one unit: its bounces, the state's means and SDs, the racket,
    the measured set-up, the data's VAR(1) radius beside the model's eq. 10 radius, the
    impacts to relax, the control fit. ``not_run``: analysis -> why it did not run for the
    unit (the radii's notes say it where acf gave no table)."""
    theta = pooled["theta_rad"].to_numpy(float) if "theta_rad" in pooled.columns else \
        np.radians(pooled["theta_deg"].to_numpy(float))
    mean_theta = circular_mean(theta)
    out: dict[str, Any] = {
        "trials": int(pooled["trial"].nunique()), "impacts": len(pooled),
        "theta_mean_deg": math.degrees(mean_theta),
        "theta_sd_deg": math.degrees(float(np.std(phase_difference(theta, mean_theta), ddof=1))),
        "v_mean_m_s": float(pooled["v_m_s"].mean()), "v_sd_m_s": float(pooled["v_m_s"].std()),
    }
    for column, name in (("racket_acc_g", "ac"), ("racket_period_s", "racket_period"),
                         ("racket_amplitude_m", "racket_amplitude")):
        if column in pooled.columns:
            unit_name = {"ac": "g", "racket_period": "s", "racket_amplitude": "m"}[name]
            out[f"{name}_mean_{unit_name}"] = float(pooled[column].mean())
            out[f"{name}_sd_{unit_name}"] = float(pooled[column].std())
    if "ball_apex_m" in pooled.columns:
        per_trial = pooled.groupby("trial")["ball_apex_m"].std()
        out["apex_sd_m"] = float(per_trial.mean())
    out["model_spectral_radius"] = math.nan
    if found is not None and set(RACKET_COLUMNS) <= set(pooled.columns):
        try:
            params = model_at_data(Impacts(pooled, Path(unit.label)), found, need=None)
            out["model_spectral_radius"] = float(stability(params).spectral_radius)
        except ModelError:  # no fixed point (eq. 8) or parameters out of range: NaN
            pass
    stab = frames.get(f"{unit.folder}/acf/stability_data.csv")
    for method in RADIUS_ESTIMATORS:
        for field in ("estimate", "ci_low", "ci_high"):
            out[f"radius_{method}" + ("" if field == "estimate" else f"_{field}")] = math.nan
        out[f"radius_{method}_note"] = "" if stab is not None else not_run_note("acf", not_run)
        if stab is not None:
            rows = stab[(stab["quantity"] == "spectral_radius")
                        & stab["source"].astype(str).str.startswith(method)]
            if len(rows):
                out.update(radius_entries(method, float(rows["estimate"].iloc[0]),
                                          float(rows["ci_low"].iloc[0]),
                                          float(rows["ci_high"].iloc[0]),
                                          str(rows["note"].iloc[0])))
    relax = frames.get(f"{unit.folder}/impulse/relaxation_data.csv")
    missing = []  # directions the unit's perturbations do not have
    for direction in ("decrease", "increase"):
        value = math.nan
        if relax is not None:
            rows = relax[(relax["direction"] == direction) & (relax["source"] == "data")]
            if len(rows):
                value = float(rows["relaxation_impacts"].iloc[0])
            else:
                missing.append(direction)
        out[f"relax_impacts_{direction}"] = value
    out["relax_impacts_note"] = (
        not_run_note("impulse", not_run) if relax is None else
        "; ".join(f"{d}: no perturbation of that direction" for d in missing))
    fit = frames.get(f"{unit.folder}/control/fit.csv")
    for quantity, name in (("gain_K", "control_K"), ("rate_c", "control_c")):
        value = math.nan
        if fit is not None:
            rows = fit[fit["quantity"] == quantity]
            if len(rows):
                value = float(rows["estimate"].iloc[-1])
        out[name] = value
    return out


def with_difference_verdicts(table: pd.DataFrame, confidence: float) -> pd.DataFrame:
    """group_stability.csv's ``p_value_holm`` and ``verdict``: each row's paired test of
    data against model (its interval at ``confidence``), read together with the table's
    other rows by Holm's step-down adjustment (statsmodels), since the table holds one test
    per estimator and condition (eight with two conditions): on simulated data whose truth
    is the model, one of eight excluding 0 at 95 % is what chance gives a quarter of the
    time. A row whose interval excludes 0 says so either way, and says when the difference
    does not survive the adjustment."""
    from statsmodels.stats.multitest import multipletests

    table = table.copy()
    tested = (table["units"] >= 2) & np.isfinite(table["p_value"])
    holm = pd.Series(np.nan, index=table.index)
    reject = pd.Series(False, index=table.index)
    if tested.any():
        rejected, adjusted, _, _ = multipletests(table.loc[tested, "p_value"],
                                                 alpha=1.0 - confidence, method="holm")
        holm[tested], reject[tested] = adjusted, rejected
    n_tests = int(tested.sum())
    verdicts = []
    for i, row in table.iterrows():
        if row["units"] < 2:
            verdicts.append("too few units with an interval")
            continue
        side = ("data faster than the model" if row["ci_high"] < 0 else
                "data slower than the model" if row["ci_low"] > 0 else None)
        if side is None:
            verdicts.append("no difference detected")
        elif reject[i] or n_tests == 1:
            verdicts.append(side)
        else:
            verdicts.append(f"{side} in this row alone; not after Holm's adjustment over "
                            f"the table's {n_tests} tests")
    table["p_value_holm"] = holm
    table["verdict"] = verdicts
    return table


#: the spectral radius estimates of group.csv and group_stability.csv: the VAR(1) and, with
#: each impact's racket period and amplitude as inputs, the VARX (acf --data's sources)
RADIUS_ESTIMATORS = ("ols", "lag2", "varx_ols", "varx_lag2")


def radius_entries(method: str, estimate: float, low: float, high: float,
                   note: str) -> dict[str, Any]:
    """group.csv's ``radius_<method>``, its interval and ``radius_<method>_note`` from a
    unit's stability_data.csv row: an estimate that is none (NaN there, or not finite or above
    1.5 here: :func:`bounce_cli.analysis.var_fit.radius_problem`) is NaN with the reason in
    the note; an estimate is given with an empty note, or, where it has no interval, with
    the row's note saying why (too few pairs for an interval the trust study vouches for).

    Parameters
    ----------
    method : str
        ``ols``, ``lag2``, ``varx_ols`` or ``varx_lag2`` (``RADIUS_ESTIMATORS``).
    estimate, low, high : float
        The row's estimate and interval.
    note : str
        The row's note (why there is no estimate, where there is none).

    Returns
    -------
    dict
        The four columns of group.csv.
    """
    from ..analysis.var_fit import radius_problem

    name = f"radius_{method}"
    problem = radius_problem(estimate)
    if problem:
        why = note if math.isnan(estimate) and note and note != "nan" else (
            f"spectral radius withheld: {problem}")
        return {name: math.nan, f"{name}_ci_low": math.nan, f"{name}_ci_high": math.nan,
                f"{name}_note": why}
    without = (math.isnan(low) or math.isnan(high)) and note and note != "nan"
    return {name: estimate, f"{name}_ci_low": low, f"{name}_ci_high": high,
            f"{name}_note": note if without else ""}


# -- the study -----------------------------------------------------------------------------------
def run(config: StudyConfig, options: RunOptions) -> ExperimentResult:
    if config.manifest is None:
        raise ConfigError("manifest: give the study's manifest (--manifest study.csv: one row "
                          "per recording with file, subject[, condition, trial])")
    manifest = read_manifest(config.manifest)
    units = manifest.units(tuple(config.grouping))
    for unit in units:
        for message in manifest.trial_order_notes(unit):
            options.warn(message)
    dumped = config.model_dump(mode="json")
    digests = input_digests(manifest)
    options.record["inputs"] = inputs_record(manifest, digests)
    formats = figure_kinds(options.figure_formats)
    tasks = [UnitTask(i, unit, dumped, unit_key(unit, dumped, digests, formats, options.dpi),
                      formats, options.dpi)
             for i, unit in enumerate(units)]
    done = {i: r for i, r in options.checkpoints.load().items()
            if 0 <= i < len(tasks) and r.get("key") == tasks[i].key}
    todo = [t for t in tasks if t.index not in done]
    options.progress.start(len(tasks), "study: units")
    options.progress.advance(len(done))
    if todo:
        jobs = min(options.jobs, len(todo))
        if jobs > 1 or options.scheduler:  # this process waits for the units meanwhile
            preload_in_background(GROUP_MODULES)
        with parallel.executor(jobs, options.scheduler) as executor:
            for result in executor.map(analyse_unit, todo):
                options.checkpoints.save(result["index"], result)
                done[result["index"]] = result
                options.progress.advance()
    results = [done[t.index] for t in tasks]
    warnings = condensed_warnings([t.unit.label for t in tasks],
                                  [result["warnings"] for result in results])
    for message in warnings:
        options.warn(message)
    frames: dict[str, pd.DataFrame] = {}
    for result in results:
        for name, data in result["frames"].items():
            frames[name] = frame_from_json(data)
    group = pd.DataFrame([r["row"] for r in results])
    frames["group.csv"] = group
    failures = pd.DataFrame([f for r in results for f in r["failures"]],
                            columns=["unit", "file", "stage", "error"])
    frames["failures.csv"] = failures
    frames.update(group_tables(frames, units, config))
    # each figure rendered once, to PNG: written as it is and embedded in the reports (the
    # units' own in their workers)
    drawn = config.report.drawn()
    pngs = group_figures(frames, formats, options.dpi) if drawn != "none" else {}
    for result in results:
        pngs.update({name: base64.b64decode(data) for name, data in result["pngs"].items()})
    files = report_files(frames, {name: data for name, data in pngs.items()
                                  if name.endswith(".png")},
                         units, manifest.path, config, warnings)
    summary = [f"study: {len(units)} unit(s) ({' x '.join(config.grouping)}) of "
               f"{len(manifest.rows)} recording(s)"
               + (f"; {len(tasks) - len(todo)} resumed" if len(todo) < len(tasks) else "")]
    summary += [r["summary"][0] for r in results if r["summary"]]
    summary += group_summary(frames)
    exit_code = 0
    if len(failures):
        summary.append(f"{len(failures)} failure(s) in {failures['unit'].nunique()} unit(s): "
                       "see failures.csv (everything else was written)")
        exit_code = 1
    return ExperimentResult(frames=frames, figures={}, summary=summary,
                            files={**pngs, **files}, exit_code=exit_code)


#: what the group statistics, figures and report import (statsmodels' MixedLM and its
#: scipy.stats, matplotlib): half a second, loaded while the units' workers run
GROUP_MODULES = ("statsmodels.formula.api", "matplotlib.figure",
                 "matplotlib.backends.backend_agg")


def preload_in_background(modules: tuple[str, ...]) -> None:
    """Import ``modules`` in a daemon thread of this process (which would otherwise wait for
    its workers): the study's tail, which needs them, then starts at once. A failing import
    is left for the code that needs the module to report."""
    import importlib
    import threading

    def load() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:  # reported where the module is used
                pass

    threading.Thread(target=load, name="bounce-preload", daemon=True).start()


# -- group statistics ----------------------------------------------------------------------------
def _unit_frames(frames: dict[str, pd.DataFrame], units: list[Unit], analysis: str,
                 name: str) -> pd.DataFrame:
    """One analysis table of every unit, stacked, with the unit's factors in front."""
    parts = []
    for unit in units:
        frame = frames.get(f"{unit.folder}/{analysis}/{name}")
        if frame is not None and len(frame):
            factors = unit.factors()
            parts.append(frame.assign(unit=unit.folder, **{k: v for k, v in factors.items()
                                                            if k not in frame.columns}))
    if not parts:
        return pd.DataFrame()
    out = pd.concat(parts, ignore_index=True)
    front = ["unit", *[g for g in units[0].grouping if g in out.columns]]
    return out[front + [c for c in out.columns if c not in front]]


def condition_of(frame: pd.DataFrame) -> pd.Series:
    return (frame["condition"].astype(str) if "condition" in frame.columns
            else pd.Series("all", index=frame.index))


def group_tables(frames: dict[str, pd.DataFrame], units: list[Unit],
                 config: StudyConfig) -> dict[str, pd.DataFrame]:
    """The group statistics' tables (see the module docstring)."""
    # here, not at the top: the units' workers never need scipy.stats and statsmodels
    from ..analysis.group_stats import (
        across_units,
        eq15_prediction,
        mixed_trend,
        paired_difference,
    )

    out: dict[str, pd.DataFrame] = {}
    conf = config.confidence
    group = frames["group.csv"]
    # Fig. 7 over the study: trial means pooled by condition
    trials = _unit_frames(frames, units, "regression", "trials.csv")
    if len(trials):
        trials = trials.assign(condition=condition_of(trials))
        alpha_g = group.set_index(group["subject"].astype(str) + "/" + condition_of(group))
        rows = []
        from ..analysis.regression import narrow_periods, ols_line

        for condition, part in trials.groupby("condition", sort=True):
            key = part["subject"].astype(str) + "/" + str(condition)
            alpha = key.map(alpha_g["alpha"]) if "alpha" in alpha_g else pd.Series(math.nan)
            g = key.map(alpha_g["g_m_s2"]) if "g_m_s2" in alpha_g else pd.Series(math.nan)
            theta = np.radians(part["theta_deg"].to_numpy(float))
            row = {"condition": condition, "n": len(part), "subjects": part["subject"].nunique()}
            narrow = narrow_periods(part["tau_s"])
            if narrow:  # one racket period (a virtual set-up's sessions): no line to fit
                row["note"] = f"not fitted: {narrow}"
                rows.append(row)
                continue
            try:
                fit = ols_line(part["tau_s"].to_numpy(float) ** 2, part["a_r_m"].to_numpy(float),
                               conf)
            except ModelError as exc:
                row["note"] = str(exc)
                rows.append(row)
                continue
            predicted = eq15_prediction(part["tau_s"], theta, alpha, g)
            row.update({
                "slope": float(fit.slope), "slope_ci_low": float(fit.slope_ci_low),
                "slope_ci_high": float(fit.slope_ci_high), "intercept": float(fit.intercept),
                "intercept_ci_low": float(fit.intercept_ci_low),
                "intercept_ci_high": float(fit.intercept_ci_high), "r2": float(fit.r2),
                "predicted_slope": predicted,
                "mean_theta_deg": math.degrees(circular_mean(theta)),
                "confidence": conf,
                "slope_ci_covers_prediction": bool(fit.slope_ci_low <= predicted
                                                   <= fit.slope_ci_high),
                "intercept_ci_covers_zero": bool(fit.intercept_ci_low <= 0.0
                                                 <= fit.intercept_ci_high),
                "note": "",
            })
            rows.append(row)
        out["group_regression_trials.csv"] = trials
        out["group_regression.csv"] = pd.DataFrame(rows)
    # Fig. 6 over the study: the learning trend with a mixed model
    learning = _unit_frames(frames, units, "learning", "trials.csv")
    if len(learning):
        learning = learning.assign(condition=condition_of(learning))
        rows = []
        for condition, part in learning.groupby("condition", sort=True):
            for quantity in ("ac_mean_g", "apex_sd_m"):
                try:
                    trend = mixed_trend(part, quantity, "trial_number", "subject", conf)
                except ValueError as exc:
                    rows.append({"condition": condition, "quantity": quantity,
                                 "method": f"not estimable: {exc}"})
                    continue
                rows.append({"condition": condition, "quantity": quantity,
                             "slope_per_trial": trend.slope, "intercept": trend.intercept,
                             "se": trend.se,
                             "ci_low": trend.ci_low, "ci_high": trend.ci_high, "df": trend.df,
                             "p_value": trend.p_value, "subjects": trend.groups,
                             "trials": trend.observations, "method": trend.method,
                             "mixed_model": trend.mixed, "confidence": conf,
                             "trend": ("decreasing" if trend.ci_high < 0 else "increasing"
                                       if trend.ci_low > 0 else "none detected")})
        out["group_learning_trials.csv"] = learning
        trends = pd.DataFrame(rows)
        if "df" in trends.columns:  # a count: empty where no trend was estimable
            trends["df"] = trends["df"].astype("Int64")
        out["group_learning.csv"] = trends
    # stability across units: the data's radius beside the model's
    if "radius_ols" in group.columns and group["radius_ols"].notna().any():
        rows = []
        cond = condition_of(group)
        for condition in sorted(cond.unique()):
            part = group[cond == condition]
            for method in RADIUS_ESTIMATORS:
                if f"radius_{method}" not in part.columns:
                    continue  # a group.csv of an older run, resumed
                # a unit's estimate counts only where its data were enough for an interval
                # (acf --data gives none below its stated minimum of bounces: such an estimate
                # can be anything, e.g. a lag-2 radius of 30 on 170 bounces), and never where
                # it is no estimate (withheld: NaN with its note; or not finite, above 1.5)
                # and a unit without any estimate (its analysis failed or did not run) is
                # counted as such, not as one whose data were too few for an interval
                withheld = withheld_radii(part, method)
                estimated = part[f"radius_{method}"].notna() & ~withheld
                radius = part[f"radius_{method}"].where(
                    np.isfinite(part[f"radius_{method}_ci_low"]) & estimated)
                d = paired_difference(radius, part["model_spectral_radius"], conf)
                rows.append({"condition": condition, "estimate": method, "units": d.n,
                             "units_without_interval": int((radius.isna() & estimated).sum()),
                             "units_withheld": int(withheld.sum()),
                             "units_without_estimate": int((~estimated & ~withheld).sum()),
                             "data_mean": float(radius.mean()),
                             "model_mean": float(part.loc[radius.notna(),
                                                          "model_spectral_radius"].mean()),
                             "difference_mean": d.mean, "difference_sd": d.sd,
                             "ci_low": d.ci_low, "ci_high": d.ci_high, "p_value": d.p_value,
                             "confidence": conf})
        out["group_stability.csv"] = with_difference_verdicts(pd.DataFrame(rows), conf)
    # Fig. 8 per condition: correlation functions averaged over units
    acf = _unit_frames(frames, units, "acf", "acf_data.csv")
    if len(acf):
        acf = acf.assign(condition=condition_of(acf))
        data = across_units(acf, ["condition", "pair", "lag"], "data_mean")
        theory = across_units(acf, ["condition", "pair", "lag"], "theory")
        out["group_acf.csv"] = data.merge(
            theory.rename(columns={"mean": "theory_mean", "sd": "theory_sd",
                                   "units": "theory_units"}),
            on=["condition", "pair", "lag"], how="left")
    # Figs. 9 and 11 per condition: responses averaged over units
    aligned = _unit_frames(frames, units, "impulse", "aligned.csv")
    if len(aligned):
        aligned = aligned.assign(condition=condition_of(aligned))
        out["group_impulse.csv"] = across_units(
            aligned, ["condition", "quantity", "direction", "k"], "mean")
    return out


def withheld_radii(group: pd.DataFrame, method: str) -> pd.Series:
    """Which units' ``radius_<method>`` is no estimate: withheld by the fit (its note says
    so), or a value not finite or above 1.5 (a row of an older run, resumed)."""
    from ..analysis.var_fit import radius_problem

    note = group.get(f"radius_{method}_note", pd.Series("", index=group.index))
    said = note.fillna("").astype(str).str.startswith("spectral radius withheld")
    value = group[f"radius_{method}"].astype(float)
    wild = value.map(lambda r: not math.isnan(r) and bool(radius_problem(r)))
    return (said | wild).astype(bool)


def _regression_line(r: dict) -> str | None:
    """Fig. 7 of one condition (its note where its fit has no slope)."""
    if not ("slope" in r and isinstance(r["slope"], float) and math.isfinite(r["slope"])):
        note = r.get("note")
        return (f"Fig. 7 ({r['condition']}, {r['n']} trials of {r['subjects']} subjects): "
                f"{note}" if isinstance(note, str) and note else None)
    return (f"Fig. 7 ({r['condition']}, {r['n']} trials of {r['subjects']} "
            f"subjects): slope {r['slope']:.4f} m/s^2 [{r['slope_ci_low']:.4f}, "
            f"{r['slope_ci_high']:.4f}] vs eq. 15 {r['predicted_slope']:.4f}; "
            f"intercept {100 * r['intercept']:.2f} cm "
            f"[{100 * r['intercept_ci_low']:.2f}, "
            f"{100 * r['intercept_ci_high']:.2f}]; R^2 {r['r2']:.3f}")


def _learning_line(r: dict) -> str | None:
    """Fig. 6 of one condition and quantity (none where it has no trend per trial)."""
    if not isinstance(r.get("slope_per_trial"), float):
        return None
    return (f"Fig. 6 ({r['condition']}): {r['quantity']} "
            f"{r['slope_per_trial']:.4g} per trial [{r['ci_low']:.4g}, "
            f"{r['ci_high']:.4g}] over "
            f"{r['subjects']} subjects ({r['method']}): {r['trend']}")


def _stability_line(r: dict) -> str:
    """The stability of one condition and estimate, data against the model."""
    units = f"{r['units']} unit{'' if r['units'] == 1 else 's'}"
    return (f"stability ({r['condition']}, {r['estimate']}, {units}"
            + (f"; {r['units_without_interval']} without an interval, left out"
               if r["units_without_interval"] else "")
            + (f"; {r['units_withheld']} withheld (no estimate), left out"
               if r.get("units_withheld") else "")
            + (f"; {r['units_without_estimate']} without an estimate (failures.csv, or "
               "not run: group.csv), left out" if r.get("units_without_estimate") else "")
            + "): "
            f"data {r['data_mean']:.3f} vs model {r['model_mean']:.3f}, difference "
            f"{r['difference_mean']:.3f} [{r['ci_low']:.3f}, {r['ci_high']:.3f}]: "
            f"{r['verdict']}")


#: the group tables a study summarises, each with its line of a record
GROUP_LINES: tuple[tuple[str, Callable[[dict], str | None]], ...] = (
    ("group_regression.csv", _regression_line),
    ("group_learning.csv", _learning_line),
    ("group_stability.csv", _stability_line),
)


def group_summary(frames: dict[str, pd.DataFrame]) -> list[str]:
    lines = []
    for name, line in GROUP_LINES:
        table = frames.get(name)
        if table is not None:
            lines += [text for r in table.to_dict("records") if (text := line(r)) is not None]
    return lines


# -- figures -------------------------------------------------------------------------------------
@publication_style
def draw(frames: dict[str, pd.DataFrame], names: Iterable[str] | None = None) -> dict:
    """The group figures, from the group tables (those of ``names``, or all)."""
    from .study_figures import draw_group

    return draw_group(frames, names)


def group_figures(frames: dict[str, pd.DataFrame], figure_formats: tuple[str, ...],
                  dpi: float) -> dict[str, bytes]:
    """Every group figure rendered in each of ``figure_formats`` (:func:`figure_files`):
    the later half of them drawn and rendered by a forked child while this process does the
    first half (``runtime.forked``)."""
    from ..runtime.forked import split_work
    from .study_figures import group_figure_builders

    def render(names: list[str]) -> dict[str, bytes]:
        return {file_name: data for name, fig in draw(frames, names).items()
                for file_name, data in figure_files(name, fig, figure_formats, dpi).items()}

    return split_work(list(group_figure_builders(frames)), render)


def draw_units(frames: dict[str, pd.DataFrame], units: list[Unit]) -> dict:
    """Each unit's figures, drawn by each analysis's own ``draw`` from the unit's tables, and
    Fig. 2 of its first extracted recording."""
    from .registry import entry

    figures = {}
    for unit in units:
        prefixes = {name.rsplit("/", 1)[0] for name in frames if name.startswith(unit.folder + "/")}
        for prefix in sorted(prefixes):
            tail = prefix[len(unit.folder) + 1:]
            own = {name[len(prefix) + 1:]: frame for name, frame in frames.items()
                   if name.startswith(prefix + "/") and "/" not in name[len(prefix) + 1:]}
            if tail in ANALYSES:
                try:
                    drawn = entry(tail).load().draw(own)
                except (KeyError, ValueError):
                    continue
            elif tail.startswith("extract/") and prefix == _first_extract(frames, unit):
                from .extract import draw as draw_extract

                drawn = draw_extract(own)
            else:
                continue
            for name, fig in drawn.items():
                fig.suptitle(f"{unit.label}" + (f": {fig.get_suptitle()}"
                                                if fig.get_suptitle() else ""), fontsize=10)
                figures[f"{prefix}/{name}"] = fig
    return figures


def _first_extract(frames: dict[str, pd.DataFrame], unit: Unit) -> str | None:
    names = sorted(n for n in frames if n.startswith(f"{unit.folder}/extract/")
                   and n.endswith("/fig2_samples.csv"))
    return names[0].rsplit("/", 1)[0] if names else None


# -- the report ----------------------------------------------------------------------------------
def figure_kinds(figure_formats: tuple[str, ...]) -> tuple[str, ...]:
    """The formats a study writes its figures in: PNG first (the reports embed it), then the
    others asked for (``--figure-format``), each once."""
    return tuple(dict.fromkeys(("png", *figure_formats)))


def figure_files(name: str, fig, figure_formats: tuple[str, ...], dpi: float
                 ) -> dict[str, bytes]:
    """``fig`` (``name``: its PNG's file name) as a file's bytes in each of
    ``figure_formats`` at ``dpi``, as every run writes its figures (``save_figure``: the
    title and caption in the metadata; PNGs at zlib level 1 as ``artifacts.PNG_OPTIONS``:
    the encoding was a tenth of a study's figure time at the default level; the files are
    about a quarter larger): ``{"<stem>.png": ..., "<stem>.pdf": ...}``."""
    from ..runtime.artifacts import PNG_OPTIONS
    from ..runtime.figure_files import save_figure

    stem = name[:-len(".png")] if name.endswith(".png") else name
    out = {}
    for kind in figure_formats:
        buffer = io.BytesIO()
        save_figure(fig, buffer, kind, dpi=dpi, source="bounce study",
                    png_options=PNG_OPTIONS if kind == "png" else None)
        out[f"{stem}.{kind}"] = buffer.getvalue()
    return out


def report_files(frames, rendered: dict[str, bytes], units: list[Unit], manifest_path: Path,
                 config: StudyConfig, warnings: list[str] | None = None) -> dict[str, bytes]:
    """``report.html`` (the study) and ``<subject>/report.html`` (each subject), each one
    self-contained: the figures (``rendered``: name -> PNG bytes) embedded; ``warnings``
    (the units' analyses', e.g. an estimate withheld as no estimate) counted in the overview
    and listed in a section of their own."""
    warnings = warnings or []
    group = frames["group.csv"]
    failures = frames["failures.csv"]
    impacts = int(group["impacts"].sum()) if "impacts" in group else 0
    overview = Section("Study", [
        f"<p>{len(units)} unit(s) ({' x '.join(config.grouping)}) from "
        f"{html_escape(str(manifest_path))}; {impacts} impacts; {len(failures)} failure(s); "
        f"{len(warnings)} warning(s).</p>",
        html_table(group, digits=4),
    ])
    sections = [overview]
    if len(failures):
        sections.append(Section("Failures", [html_table(failures)]))
    if warnings:
        sections.append(Section("Warnings", [
            "<ul class='warn'>" + "".join(f"<li>{html_escape(w)}</li>" for w in warnings)
            + "</ul>"]))
    titles = {"group_regression.png": "Fig. 7 over the study",
              "group_learning.png": "Fig. 6 over the study (mixed model)",
              "group_stability.png": "Stability: the data against the model (eq. 10)",
              "group_acf.png": "Fig. 8 averaged over subjects",
              "group_impulse.png": "Figs. 9 and 11 averaged over subjects"}
    tables = {"group_regression.png": "group_regression.csv",
              "group_learning.png": "group_learning.csv",
              "group_stability.png": "group_stability.csv"}
    for name, title in titles.items():
        if name in rendered:
            parts = [embed_png(rendered[name], title)]
            if tables.get(name) in frames:
                parts.append(html_table(frames[tables[name]], digits=4))
            sections.append(Section(title, parts))
    # a page per value of the first grouping factor (the subject, by default), in its folder
    subjects: dict[str, list[Unit]] = {}
    for unit in units:
        subjects.setdefault(unit.folder.split("/")[0], []).append(unit)
    factor = units[0].grouping[0] if units else "subject"
    files: dict[str, bytes] = {}
    subject_sections = []
    for subject, subject_units in subjects.items():
        parts = []
        for unit in subject_units:
            parts.append(f"<h3>{html_escape(unit.label)}</h3>")
            parts.append(html_table(group.iloc[[units.index(unit)]], digits=4))
            unit_failures = failures[failures["unit"] == unit.folder]
            if len(unit_failures):
                parts.append("<p class='warn'>Failures:</p>" + html_table(unit_failures))
            figures = sorted(n for n in rendered if n.startswith(unit.folder + "/"))
            for name in figures:
                parts.append(embed_png(rendered[name], name))
            if not figures:
                parts.append(f"<p>This unit's figures: <code>bounce study ... --figures "
                             f"all</code>, or <code>bounce &lt;analysis&gt; --data "
                             f"{html_escape(unit.folder)}/impacts.csv</code>; its tables are "
                             f"in <code>{html_escape(unit.folder)}/</code>.</p>")
        section = Section(f"{factor.capitalize()} {subject}", parts)
        subject_sections.append(section)
        files[f"{subject}/report.html"] = page(f"bounce study: {factor} {subject}",
                                               [section]).encode()
    files["report.html"] = page("bounce study", sections + subject_sections).encode()
    return files


def html_escape(text: str) -> str:
    import html

    return html.escape(text)


EXPERIMENT = Experiment(name="study", schema=StudyConfig, run=run, draw=draw)

__all__ = ["EXPERIMENT", "StudyConfig", "analyse_unit", "group_tables", "run"]

