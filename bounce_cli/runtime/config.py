"""YAML configs -> validated pydantic models, with dotted ``--set key=value`` overrides.

Every experiment config has the common ``model`` block; an experiment module subclasses
``ExperimentConfig`` with its own blocks. All models forbid unknown keys.
"""

from __future__ import annotations

import copy
import difflib
import os
import stat
import typing
from importlib import resources
from pathlib import Path
from typing import Any, Literal, Optional, Sequence, TypeVar, Union

import yaml
from pydantic import (
    AliasChoices,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_serializer,
)

from ..analysis.classify import ClassifySettings
from ..errors import ConfigError
from ..model.params import ModelParams
from ..paper.values import FIG3_MODEL


def expects_number(annotation) -> bool:
    """Whether a field of this type holds numbers (int or float, possibly in an Optional, a
    list or an Annotated) and not booleans."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return expects_number(typing.get_args(annotation)[0])
    if origin is not None:  # Optional / Union / list / tuple
        args = typing.get_args(annotation)
        return bool in args or any(expects_number(a) for a in args if a is not type(None))
    return annotation in (int, float)


class StrictModel(BaseModel):
    """Unknown keys, inf/nan and booleans where numbers are expected are errors. (YAML reads
    yes/no/on/off/true/false as booleans, which pydantic would otherwise take as 1 and 0.)"""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _no_booleans_for_numbers(cls, value, info):
        values = value if isinstance(value, (list, tuple)) else [value]
        if any(isinstance(v, bool) for v in values) and expects_number(
            cls.model_fields[info.field_name].annotation
        ):
            raise ValueError(
                "expected a number, got a boolean (YAML reads yes/no/on/off/true/false as "
                "booleans)"
            )
        return value


class ModelBlock(StrictModel):
    """The common ``model`` block: parameters of eqs. 3-6 (default: the paper's Figs. 3, 4)."""

    alpha: float = Field(FIG3_MODEL.alpha, ge=0.0, lt=1.0,
                         description="coefficient of restitution")
    g: float = Field(FIG3_MODEL.g, gt=0.0, description="gravitational acceleration, m/s^2")
    racket_amplitude: float = Field(FIG3_MODEL.racket_amplitude, gt=0.0, description="a_r, m")
    racket_period: float = Field(FIG3_MODEL.racket_period, gt=0.0,
                                 description="tau = 2 pi / omega_r, s")

    def to_params(self) -> ModelParams:
        return ModelParams(self.alpha, self.g, self.racket_amplitude, self.racket_period)


class ControlBlock(StrictModel):
    """Racket period control (``model.control``, the paper's future work, sections 7-8):
    tau_{k+1} = tau_k + c (tau_bar + K 2 (v_k - v~) / g - tau_k), tau_bar = racket_period."""

    kind: Literal["period"] = Field("period", description="controller (model.control)")
    gain: float = Field(description="K: 1 = the period follows the ball's flight time in full")
    rate: float = Field(1.0, ge=0.0, le=2.0,
                        description="c per impact: 1 = immediate, 0 = never; > 1 overshoots")
    switch: Literal["impact", "cycle"] = Field(
        "impact", description="the new period starts at the impact, or at the racket's next "
        "upward mid-position crossing (a racket moved cycle by cycle, as simulate-recording's)")

    @model_serializer(mode="wrap")
    def _default_switch_unwritten(self, handler):
        data = handler(self)
        if self.switch == "impact":  # configs written before the key existed dump unchanged
            data.pop("switch", None)
        return data

    def controller(self):
        from ..model.control import CONTROLLERS

        return CONTROLLERS[self.kind](self.gain, self.rate, switch=self.switch)


class ControllableModelBlock(ModelBlock):
    """The model block of a command that iterates the map: ``control`` (default none, the
    passive map) makes the racket period a state. A config without it dumps exactly as
    before (``run.json`` of passive runs is unchanged)."""

    control: Optional[ControlBlock] = Field(None, description="racket period control")

    @model_serializer(mode="wrap")
    def _passive_without_control(self, handler):
        data = handler(self)
        if self.control is None:
            data.pop("control", None)
        return data

    def controller(self):
        """The engine controller, or None for the passive map."""
        return None if self.control is None else self.control.controller()

    def active_controller(self):
        """The engine controller, or None when the map is the passive one (no control, or
        gain 0: then every result is the passive run's byte for byte)."""
        from ..model.control import is_passive

        controller = self.controller()
        return None if is_passive(controller) else controller


#: section 3's stopping conditions as the engine defines them (the one place of the defaults)
_SECTION3 = ClassifySettings()


class ClassifyBlock(StrictModel):
    """Section 3's stopping conditions for an orbit (Fig. 4; shared by basin and impulse).
    Defaults: :class:`bounce_cli.analysis.classify.ClassifySettings` (the paper's values)."""

    max_iterations: int = Field(_SECTION3.max_iterations, ge=1, le=32767,
                                description="impacts at most")
    tolerance: float = Field(_SECTION3.tolerance, gt=0.0,
                             description="m/s and rad, distance to the fixed point")
    # ``sticking_interval_s``: the former name of this key, still read
    min_hop_s: float = Field(
        default=_SECTION3.min_hop_s, ge=0.0, description="s, sticking when a hop is shorter",
        validation_alias=AliasChoices("min_hop_s", "sticking_interval_s"),
    )

    def settings(self) -> ClassifySettings:
        return ClassifySettings(self.max_iterations, self.tolerance, self.min_hop_s)


class ExperimentConfig(StrictModel):
    """Base of every experiment config: the ``model`` block plus the experiment's own."""

    model: ModelBlock = ModelBlock()

    @property
    def params(self) -> ModelParams:
        return self.model.to_params()


class ModelOnlyConfig(ExperimentConfig):
    """A config holding just the model block (used by ``fixed-point`` and ``orbit``)."""

    model: ControllableModelBlock = ControllableModelBlock()


C = TypeVar("C", bound=BaseModel)


# -- bundled configs -------------------------------------------------------------------------
def bundled_config_dir():
    """The configs shipped inside the package (the repository's ``configs/``)."""
    return resources.files("bounce_cli") / "configs"


def bundled_config_path(name: str) -> Path:
    """Path of the bundled config ``<name>.yaml``; works installed or from a checkout."""
    path = Path(str(bundled_config_dir() / f"{name}.yaml"))
    if not path.is_file():
        raise ConfigError(f"bundled config {name}.yaml is missing from the installation")
    return path


# -- loading ---------------------------------------------------------------------------------
class DuplicateKeyError(yaml.YAMLError):
    def __init__(self, key, line: int) -> None:
        super().__init__(f"line {line}: duplicate key {key!r}")
        self.key, self.line = key, line


class UniqueKeyLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (plain YAML keeps
    the last one silently)."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise DuplicateKeyError(key, key_node.start_mark.line + 1)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


UniqueKeyLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, UniqueKeyLoader.construct_mapping
)


#: the largest config file read, bytes (a config is a few kB; a larger one is a mistake, and
#: its YAML would take many times its size in memory)
MAX_CONFIG_BYTES = 10_000_000


def read_config_text(path: Path) -> str:
    """A config file's text: a regular file of at most :data:`MAX_CONFIG_BYTES`, UTF-8;
    anything else (missing, a device such as ``/dev/zero``, a folder, larger, not UTF-8) is
    a one-line ConfigError, raised before the file is read whole.

    Parameters
    ----------
    path : Path
        The config file.

    Returns
    -------
    str
        Its text.
    """
    try:
        # stat before open: opening a FIFO without a writer would wait for one
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(f"{path}: not a regular file (a device, a pipe or a folder): "
                              "give a YAML config file")
        if info.st_size > MAX_CONFIG_BYTES:
            raise ConfigError(f"{path}: {info.st_size:,} bytes, larger than a config may be "
                              f"({MAX_CONFIG_BYTES // 1_000_000} MB): give a YAML config file")
        with open(path, "rb") as handle:
            raw = handle.read(MAX_CONFIG_BYTES + 1)
    except FileNotFoundError:
        raise ConfigError(f"{path}: config file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config: {exc.strerror}") from None
    if len(raw) > MAX_CONFIG_BYTES:  # it grew after the check
        raise ConfigError(f"{path}: larger than a config may be "
                          f"({MAX_CONFIG_BYTES // 1_000_000} MB): give a YAML config file")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {raw[exc.start]:#04x} at offset "
                          f"{exc.start}): save it as UTF-8") from None


#: parsed configs by their text (a study reads the same bundled config for every recording
#: and analysis: parsing YAML is about 20 ms a time); callers get a copy of their own
_PARSED_CONFIGS: dict[str, dict[str, Any]] = {}
_PARSED_CONFIGS_KEPT = 64


def read_yaml(path: Path) -> dict[str, Any]:
    """Parse a YAML config file (safe loader, duplicate keys refused); errors name the file
    and line (reading: :func:`read_config_text`)."""
    text = read_config_text(Path(path))
    if text in _PARSED_CONFIGS:
        return copy.deepcopy(_PARSED_CONFIGS[text])
    try:
        data = yaml.load(text, Loader=UniqueKeyLoader)
    except DuplicateKeyError as exc:
        raise ConfigError(f"{path}: line {exc.line}: duplicate key {exc.key!r} "
                          "(each key may appear once in a block)") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"{path}:{where}: malformed YAML: {problem}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a config must be a mapping of keys, got {type(data).__name__}")
    if len(_PARSED_CONFIGS) < _PARSED_CONFIGS_KEPT:
        _PARSED_CONFIGS[text] = copy.deepcopy(data)
    return data


def parse_override(text: str) -> tuple[list[str], Any]:
    """``dotted.key=value`` -> (["dotted", "key"], value parsed as a YAML scalar)."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise ConfigError(f"--set {text!r}: expected dotted.key=value")
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError:
        # a lone mark (, ; |) is YAML's syntax: the marks' names say it without quotes
        mark = raw.strip()
        hint = (f"; quote it (--set \"{key}='{mark}'\") or give a mark's name (comma, "
                "semicolon, tab, space)" if len(mark) == 1 else "")
        raise ConfigError(f"--set {key}: cannot parse value {raw!r} as YAML{hint}") from None
    return key.split("."), value


def apply_overrides(data: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Return a copy of ``data`` with each ``dotted.key=value`` set (unknown keys are caught
    by validation, which forbids extra keys). A key given twice (or a key and a mapping that
    holds it) is an error: the last one would win without a word."""
    data = copy.deepcopy(data)
    given: dict[str, Any] = {}
    for text in overrides:
        path, value = parse_override(text)
        dotted = ".".join(path)
        for earlier, before in given.items():
            if earlier == dotted:
                raise ConfigError(f"--set {dotted}: given twice ({show_value(before)}, then "
                                  f"{show_value(value)}); give each key once")
            if dotted.startswith(earlier + ".") or earlier.startswith(dotted + "."):
                raise ConfigError(f"--set {dotted}: overlaps --set {earlier}; give each key "
                                  "once")
        given[dotted] = value
        node = data
        for i, part in enumerate(path[:-1]):
            child = node.get(part)
            if child is None:
                child = node[part] = {}
            if not isinstance(child, dict):
                dotted = ".".join(path[: i + 1])
                raise ConfigError(f"--set {'.'.join(path)}: {dotted} is not a mapping")
            node = child
        node[path[-1]] = value
    return data


#: the ``data`` key of the --data analyses: one file, or several (trials of one session:
#: ``--data a.csv --data b.csv``, read as one table by ``bounce_cli.data.impacts.read_impacts``)
DataFiles = Optional[Union[str, list[str]]]


def accepts_several_files(schema: type[BaseModel]) -> bool:
    """Whether a config's ``data`` key takes several files (``DataFiles``)."""
    field = schema.model_fields.get("data")
    return field is not None and field.annotation == DataFiles


def data_files(data: Any) -> list[str]:
    """The ``data`` key's files as a list (none for null)."""
    if data is None:
        return []
    return [str(p) for p in data] if isinstance(data, (list, tuple)) else [str(data)]


def data_text(data: Any) -> str:
    """The ``data`` key as messages name it: the path, or the paths joined by `` + ``."""
    return " + ".join(data_files(data))


#: the model keys a --data analysis takes from the data unless the user sets them
#: (``bounce_cli.data.data_parameters``)
DATA_MODEL_KEYS: tuple[str, ...] = ("alpha", "g")


def dotted_leaves(data: Any, prefix: str = "") -> dict[str, Any]:
    """Every leaf of a nested mapping with its value, dotted:
    ``{"model": {"g": 1}}`` -> ``{"model.g": 1}``."""
    if not isinstance(data, dict):
        return {prefix: data} if prefix else {}
    leaves: dict[str, Any] = {}
    for key, value in data.items():
        leaves |= dotted_leaves(value, f"{prefix}.{key}" if prefix else str(key))
    return leaves


def dotted_keys(data: Any, prefix: str = "") -> set[str]:
    """Every leaf key of a nested mapping, dotted: ``{"model": {"g": 1}}`` -> ``{"model.g"}``."""
    return set(dotted_leaves(data, prefix))


def keys_set_by_user(config_path: Path | None, overrides: list[str],
                     defaults: dict[str, Any] | None = None) -> frozenset[str]:
    """The dotted keys the user gave: every leaf of their own ``--config`` file (None: the
    bundled config, whose values are not the user's) whose value is not the default, and
    every ``--set`` key (a mapping value counts with its leaves; a ``--set`` always counts).

    A file printed by ``--print-config`` holds every key of the resolved config: loaded back
    unchanged it sets nothing, and after an edit only what was edited. (A user's config that
    writes the bundled value itself is taken as the default too: ``--set`` says "this one".)

    Parameters
    ----------
    config_path : Path or None
        The user's config file, or None when the bundled config is used.
    overrides : list of str
        The ``--set`` texts (``dotted.key=value``).
    defaults : dict, optional
        The bundled config, resolved (``model_dump(mode="json")``): a leaf of the user's file
        equal to its value there is no choice. None: every leaf of the file counts.

    Returns
    -------
    frozenset of str
        Dotted keys such as ``model.alpha``.
    """
    own = dotted_leaves(read_yaml(config_path)) if config_path is not None else {}
    if defaults is not None:
        default_leaves = dotted_leaves(defaults)
        own = {key: value for key, value in own.items()
               if key not in default_leaves or value != default_leaves[key]}
    keys = set(own)
    for text in overrides:
        path, value = parse_override(text)
        keys |= dotted_keys(value, ".".join(path)) if isinstance(value, dict) else {
            ".".join(path)}
    return frozenset(keys)


def keys_at(schema: type[BaseModel], location: tuple) -> list[str]:
    """The keys a config block accepts at ``location`` (a validation error's ``loc`` without
    its last part): the fields of the model found by following the location from ``schema``
    through nested models (also inside Optional, lists and dicts); [] where none is found."""
    annotation: Any = schema
    for part in location:
        model = block_model(annotation)
        if model is None:
            return []
        if isinstance(part, int):  # an item of a list: the list's model stays the same
            continue
        field = model.model_fields.get(str(part))
        if field is None:
            return []
        annotation = field.annotation
    model = block_model(annotation)
    return list(model.model_fields) if model is not None else []


def block_model(annotation) -> type[BaseModel] | None:
    """The pydantic model an annotation holds (``Block``, ``Optional[Block]``,
    ``list[Block]``, ``Annotated[Block, ...]``), or None."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        found = block_model(arg)
        if found is not None:
            return found
    return None


def did_you_mean(key: str, known: list[str]) -> str:
    """`` (did you mean model.alpha?)`` for the known key closest to a misspelt one (difflib's
    ratio at least 0.6), or ''. ``key`` is dotted; only its last part is compared."""
    *block, last = key.split(".")
    close = difflib.get_close_matches(last, known, n=1)
    return f" (did you mean {'.'.join([*block, close[0]])}?)" if close else ""


def format_validation_error(
    exc: ValidationError, source: str, overridden: frozenset[str] = frozenset(),
    schema: type[BaseModel] | None = None,
) -> str:
    """First validation problem as one line: ``source: dotted.key: reason`` (source is
    ``--set`` when the key was set by an override, or when a rule between keys names one).
    An unknown key gets the closest key ``schema`` accepts there (difflib), if any; it is
    the problem reported when a required key of the same block is missing (a misspelt
    required key is both)."""
    errors = exc.errors()
    err = next((e for e in errors if e["type"] == "extra_forbidden"
                and any(m["type"] == "missing" and m["loc"][:-1] == e["loc"][:-1]
                        for m in errors)), errors[0])
    loc = ".".join(str(part) for part in err["loc"]) or "(top level)"
    if any(loc == key or loc.startswith(key + ".") or key.startswith(loc + ".")
           for key in overridden):
        source = "--set"
    elif not err["loc"] and any(named in str(err.get("msg", ""))
                                for key in overridden for named in _as_named(key)):
        # a rule between keys (a model validator) names a key set by --set, or a block's
        # validator names its key after the block: 'extract: units.lenght', or the block
        # it is in: 'extract: unitz: unknown key' of extract.unitz.length
        source = "--set"
    if err["type"] == "extra_forbidden":
        reason = "unknown key"
        if schema is not None:
            reason += did_you_mean(loc, keys_at(schema, tuple(err["loc"][:-1])))
    elif err["type"] == "missing":
        reason = "required key is missing"
    elif (err["type"] == "string_pattern_mismatch"
          and err.get("ctx", {}).get("pattern") == NAME_PATTERN):
        reason = (f"letters, digits, '.', '_' and '-' only: it names files "
                  f"(got {show_value(err.get('input'))})")
    else:
        reason = err["msg"].removeprefix("Value error, ")
        if "input" in err and not isinstance(err["input"], (dict, list)):
            reason += f" (got {show_value(err['input'])})"
    more = len(exc.errors()) - 1
    tail = f" (and {more} more problem{'s' if more > 1 else ''})" if more else ""
    if not err["loc"] and source == "--set":
        return f"--set: {reason}{tail}"  # the reason names the keys
    return f"{source}: {loc}: {reason}{tail}"


#: the pattern of a config value that names files (a subject, a condition): ``Field(...,
#: pattern=NAME_PATTERN)``; a value that does not match is reported in words, not as the regex
NAME_PATTERN = r"^[A-Za-z0-9._\-]+$"


def _as_named(key: str) -> tuple[str, ...]:
    """How a message may name a dotted key: ``a.b.c``, ``a: b.c`` or ``a.b: c`` (a block's
    validator naming a key inside it), or a block on its way named as unknown: ``a: b:``
    (``a.b`` misspelt, so that nothing below it was looked at)."""
    parts = key.split(".")
    blocks = tuple(".".join(parts[:i]) + ": " + ".".join(parts[i:j]) + ":"
                   for j in range(2, len(parts)) for i in range(1, j))
    return (key, *(".".join(parts[:i]) + ": " + ".".join(parts[i:])
                   for i in range(1, len(parts))), *blocks)


def show_value(value: Any) -> str:
    """A value as a user wrote it: ``nan``, ``True``, ``'abc'``; numpy scalars as the Python
    number they hold (never ``np.float64(nan)``)."""
    if hasattr(value, "item") and callable(value.item):
        try:
            value = value.item()
        except (TypeError, ValueError):
            pass
    return repr(value) if isinstance(value, str) else str(value)


def validate(
    schema: type[C], data: dict[str, Any], source: str, overrides: list[str] | None = None,
    commands: Sequence[Any] = (),
) -> C:
    """Validate ``data`` against ``schema``; a failure raises ConfigError with one line.

    ``commands``: the registry's entries (:data:`bounce_cli.experiments.registry.EXPERIMENTS`);
    given, a config that is another command's says so (:func:`other_command_of`)."""
    try:
        return schema.model_validate(data)
    except ValidationError as exc:
        belongs = other_command_of(schema, data, source, commands)
        if belongs:
            raise ConfigError(f"{source}: {belongs}") from None
        overridden = frozenset(".".join(parse_override(t)[0]) for t in overrides or [])
        raise ConfigError(format_validation_error(exc, source, overridden, schema)) from None


def other_command_of(schema: type[BaseModel], data: dict[str, Any], source: str,
                     entries: Sequence[Any]) -> str:
    """When ``data``'s top-level blocks are not ``schema``'s but are all another command's
    (a config of ``bounce basin`` given to ``bounce acf``): one sentence saying which command
    it belongs to; '' otherwise (then the first problem is reported as usual). Of several
    commands sharing a schema, the one whose bundled config has the file's name is named.
    ``entries``: the registry's entries (given by the caller: this module sits below the
    registry)."""
    unknown = sorted(set(data) - set(schema.model_fields))
    if not unknown:
        return ""
    owners = []
    for entry in entries:
        other = entry.load().schema
        if other is not schema and set(data) <= set(other.model_fields):
            owners.append(entry)
    named = [e for e in owners if Path(source).stem == e.config]
    owners = named or owners
    if not owners:
        return ""
    commands = " or ".join(f"bounce {e.name}" for e in owners)
    this = [e.name for e in entries if e.load().schema is schema]
    here = f"bounce {this[0]}" if len(this) == 1 else "this command"
    return (f"a config of {commands}, not of {here} (its keys {', '.join(unknown)} are not "
            f"{here}'s); run bounce {owners[0].name} --config {source}, or start from "
            f"{here} --print-config")


def refuse_unknown_blocks(data: dict[str, Any], source: str,
                          schemas: Sequence[type[BaseModel]]) -> None:
    """Refuse a key no command's config has, at any level, in blocks a command reads no
    further (``fixed-point`` and ``orbit`` read only the ``model`` block of any command's
    config: a misspelt block would be ignored without a word).

    Parameters
    ----------
    data : dict
        The config's blocks other than the one the command validates itself.
    source : str
        The config file, as messages name it.
    schemas : sequence of pydantic model classes
        Every command's config schema. ``data`` is accepted when one schema holding all its
        top-level keys finds no unknown key in it (other problems, such as a missing
        required key, are that command's, not this one's).

    Raises
    ------
    ConfigError
        One line: the first unknown key, dotted, with the closest known key if any.
    """
    found: tuple[tuple, type[BaseModel]] | None = None
    for schema in schemas:
        if not set(data) <= set(schema.model_fields):
            continue
        try:
            schema.model_validate(data)
        except ValidationError as exc:
            unknown = [e["loc"] for e in exc.errors() if e["type"] == "extra_forbidden"]
            if not unknown:
                return
            found = found or (tuple(unknown[0]), schema)
        else:
            return
    if found is None:  # a top-level key of no command's config
        key = sorted(set(data) - {k for s in schemas for k in s.model_fields})[0]
        known = sorted({k for s in schemas for k in s.model_fields})
        raise ConfigError(f"{source}: {key}: unknown key{did_you_mean(key, known)}")
    loc, schema = found
    key = ".".join(str(part) for part in loc)
    raise ConfigError(f"{source}: {key}: unknown key"
                      f"{did_you_mean(key, keys_at(schema, loc[:-1]))}")


def load_config(schema: type[C], path: Path, overrides: list[str] | None = None,
                commands: Sequence[Any] = ()) -> C:
    """Read ``path``, apply ``--set`` overrides, validate against ``schema`` (``commands``: as
    for :func:`validate`)."""
    data = apply_overrides(read_yaml(path), overrides or [])
    return validate(schema, data, str(path), overrides, commands)


def to_yaml(config: BaseModel) -> str:
    """The resolved config as YAML, what ``--print-config`` prints: a config file the user can
    edit and load again. Keys left unset are left out (every optional key of our configs
    defaults to null), so that of two alternative keys (a case's ``theta0_deg`` or
    ``theta0_rad``) only the one given is printed."""
    return yaml.safe_dump(config.model_dump(mode="json", exclude_none=True), sort_keys=False)
