"""The ``bounce`` command line: thin wrappers that load a config, call an experiment or the
engine, and write or print the result. No numerics here.

User errors (bad YAML, unknown keys, out-of-range values, parameters without a fixed point,
an output directory holding another config's results: every ``errors.BounceError``; typer's
own usage errors) print ONE line ``bounce: error: ...`` to stderr and exit 2. An interrupt
(SIGINT, SIGTERM, SIGHUP) prints ``bounce: interrupted`` and exits 128 + the signal number
(see ``interrupts``).
"""

from __future__ import annotations

import inspect
import json
import math
import os
import sys
import time
import typing
from pathlib import Path
from typing import Annotated, Any, NoReturn, Optional

import numpy as np
import typer
from rich.console import Console
from rich.table import Table
from typer.core import TyperGroup

try:  # typer >= 0.20 vendors click
    from typer._click.exceptions import ClickException, NoArgsIsHelpError
except ImportError:  # pragma: no cover - older typer on click
    # (mypy: click may be absent, or installed beside typer's vendored copy, e.g. by the
    # cluster extra's distributed; either way this branch is only for older typer)
    from click.exceptions import (  # type: ignore[import-not-found,no-redef,assignment,unused-ignore]
        ClickException,
        NoArgsIsHelpError,
    )

from .. import __version__
from ..api import (
    check_model,
    load_run_config,
    open_run_directory,
    run_options,
    warn_if_implausible_racket,
    write_result,
)
from ..runtime.artifacts import FIGURE_DPI
from ..runtime.config import (
    ModelOnlyConfig,
    apply_overrides,
    bundled_config_path,
    parse_override,
    read_yaml,
    refuse_unknown_blocks,
    to_yaml,
    validate,
)
from ..model.params import ModelParams, wrap_phase
from ..model.maps import iterate_orbit
from ..model.linear import stability
from ..errors import BounceError, ConfigError, NoFixedPointError
from ..analysis.classify import ClassifySettings
from ..runtime.interrupts import Interrupted, report as report_interrupt
from .stdout import stdout_failed
from ..experiments.registry import EXPERIMENTS, Entry


def _flags_show_no_type() -> None:
    """typer's help prints ``<bool>`` after a flag (``--quiet <bool>``), as if it took a
    value: a flag's type column is left empty (an option taking a value keeps its type)."""
    option = getattr(typer.core, "TyperOption", None)
    shown = getattr(option, "display_type_rich", None)
    if shown is None or getattr(shown, "flags_show_no_type", False):
        return

    def display_type_rich(self, ctx):
        return None if self.is_flag else shown(self, ctx)

    display_type_rich.flags_show_no_type = True  # type: ignore[attr-defined]
    option.display_type_rich = display_type_rich  # type: ignore[union-attr]


_flags_show_no_type()


class BounceGroup(TyperGroup):
    """typer's group, with bounce's way of ending: a usage error typer finds (``--jobs 0``, a
    missing option, an unknown command) is one line ``bounce: error: ...`` and exit 2 like
    ours, not a boxed usage message; an interrupt is ``bounce: interrupted`` and 128 + the
    signal number."""

    def main(self, args=None, prog_name=None, complete_var=None,  # type: ignore[override]
             standalone_mode=True, **extra):
        try:
            code = super().main(args=args, prog_name=prog_name, complete_var=complete_var,
                                standalone_mode=False, **extra)
            code = code if isinstance(code, int) else 0
        except NoArgsIsHelpError as exc:  # `bounce` alone: the help, as typer prints it
            exc.show()
            code = exc.exit_code
        except ClickException as exc:
            ctx = getattr(exc, "ctx", None)
            hint = f" (see {ctx.command_path} --help)" if ctx is not None else ""
            message = " ".join(exc.format_message().split())
            print(f"bounce: error: {message}{hint}", file=sys.stderr)
            code = exc.exit_code
        except Interrupted as exc:
            code = report_interrupt(exc)
        if standalone_mode:
            sys.exit(code)
        return code


app = typer.Typer(
    cls=BounceGroup,
    name="bounce",
    help="Reproduce the experiments of the ball bouncing map paper from YAML configs.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)
stderr = Console(stderr=True)


def fail(message: str) -> NoReturn:
    """Print one line ``bounce: error: ...`` on stderr and exit 2."""
    print(f"bounce: error: {message}", file=sys.stderr)
    raise typer.Exit(code=2)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"bounce {__version__}")
        raise typer.Exit()


@app.callback()
def main_callback(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="Show the version."),
    ] = False,
) -> None:
    """Reproduce the experiments of the ball bouncing map paper from YAML configs."""


# -- options shared by every command ---------------------------------------------------------
ConfigOption = Annotated[
    Optional[Path],
    typer.Option(
        "--config", "-c", help="YAML config (default: the bundled config of the paper's figure)."
    ),
]
SetOption = Annotated[
    Optional[list[str]],
    typer.Option(
        "--set",
        "-s",
        help="Override a config value: dotted.key=value (YAML scalar); repeatable.",
        metavar="KEY=VALUE",
    ),
]
def output_folder(text: str) -> Path:
    """--out: a folder path; an empty one (an unset shell variable, ``--out "$DIR"``) would
    mean the current folder, so it is refused ("." says so on purpose)."""
    if isinstance(text, Path):
        return text
    if not text.strip():
        raise typer.BadParameter("an empty path (an unset shell variable?); give a folder, "
                                 "or . for the current one")
    return Path(text)


OutOption = Annotated[
    Optional[list[Path]], typer.Option("--out", "-o", parser=output_folder, metavar="PATH",
                                       help="Output directory (default results/<name>).")
]


def only_once(option: str, values: list | None):
    """The one value of an option that may be given once (typer would keep the last one of
    several without a word); None when it is not given."""
    values = list(values or [])
    if len(values) > 1:
        fail(f"{option} given {len(values)} times ({', '.join(map(str, values))}); give it "
             "once")
    return values[0] if values else None
QuietOption = Annotated[bool, typer.Option("--quiet", "-q", help="No progress or summary.")]
ForceOption = Annotated[
    bool, typer.Option("--force", help="Replace results of a different config in --out: the "
                       "files the replaced run wrote are removed (never a file this run reads).")
]
PrintConfigOption = Annotated[
    bool, typer.Option("--print-config", help="Print the resolved config as YAML and exit.")
]
JobsOption = Annotated[
    Optional[int],
    typer.Option(
        "--jobs", "-j", min=1,
        help="Worker processes for the grid's points (default: all cores).",
    ),
]
def figure_formats(values: list[str] | None) -> list[str]:
    """--figure-format: each value one format or a comma list of them (png, pdf, svg), in the
    order given, each once; none given: png."""
    from ..runtime.figure_files import FIGURE_FORMATS

    kinds: list[str] = []
    for text in values or ["png"]:
        for kind in (part.strip().lower() for part in text.split(",")):
            if kind not in FIGURE_FORMATS:
                raise typer.BadParameter(f"{kind!r} is not a figure format; choose from "
                                         + ", ".join(FIGURE_FORMATS))
            if kind not in kinds:
                kinds.append(kind)
    return kinds


FigureFormatOption = Annotated[
    Optional[list[str]],
    typer.Option("--figure-format", "-f", metavar="FORMAT", callback=figure_formats,
                 help="Figure file format: png, pdf or svg; repeatable, or a comma list "
                 "(--figure-format png,pdf). Default: png."),
]
DpiOption = Annotated[
    int, typer.Option("--dpi", min=30, max=2400, metavar="N",
                      help=f"Resolution of PNG figures, dots per inch (default {FIGURE_DPI}).")
]
ResumeOption = Annotated[
    bool,
    typer.Option("--resume", help="Continue an interrupted run in --out: the points it "
                 "finished are kept, the rest computed (the config must be the same)."),
]
SchedulerOption = Annotated[
    Optional[str],
    typer.Option("--scheduler", metavar="ADDRESS",
                 help="Run the tasks on the Dask cluster whose scheduler is at ADDRESS "
                 "(e.g. tcp://host:8786) instead of local processes (needs bounce-cli's "
                 "optional extra named cluster, Dask's distributed package)."),
]


class RichProgress:
    """Progress bar on stderr (rich); shown only while work is under way."""

    def __init__(self) -> None:
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self._progress = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=stderr,
            transient=True,
        )
        self._task: Any = None  # rich's TaskID once started

    def start(self, total: int, description: str) -> None:
        if self._task is None:
            self._progress.start()
            self._task = self._progress.add_task(description, total=total)
        else:
            self._progress.reset(self._task, total=total, description=description)

    def advance(self, n: int = 1) -> None:
        if self._task is not None:
            self._progress.advance(self._task, n)

    def stop(self) -> None:
        self._progress.stop()


class PlainProgress:
    """Progress for a log file or a batch job (stderr not a terminal): a plain line
    ``description: 45% (72,000 of 160,000), 12 s elapsed, about 15 s left`` at most every
    ``interval`` seconds (default INTERVAL_S); nothing for work shorter than that."""

    INTERVAL_S = 10.0

    def __init__(self, interval: float | None = None, clock=time.monotonic) -> None:
        self.interval = self.INTERVAL_S if interval is None else interval
        self._clock = clock
        self._total = 0
        self._done = 0
        self._description = ""
        self._started = self._last = clock()

    def start(self, total: int, description: str) -> None:
        self._total, self._done, self._description = total, 0, description
        self._started = self._last = self._clock()

    def advance(self, n: int = 1) -> None:
        self._done += n
        now = self._clock()
        if now - self._last < self.interval or not self._total:
            return
        self._last = now
        elapsed = now - self._started
        fraction = self._done / self._total
        left = elapsed * (1 - fraction) / fraction if fraction > 0 else float("nan")
        print(
            f"{self._description}: {fraction:.0%} ({self._done:,} of {self._total:,}), "
            f"{elapsed:.0f} s elapsed, about {left:.0f} s left",
            file=sys.stderr,
            flush=True,
        )

    def stop(self) -> None:
        pass


def make_progress():
    """The live bar on a terminal, plain lines otherwise."""
    return RichProgress() if stderr.is_terminal else PlainProgress()


def warn(message: str) -> None:
    print(f"bounce: warning: {message}", file=sys.stderr, flush=True)


def inform(message: str) -> None:
    print(f"bounce: {message}", file=sys.stderr, flush=True)


def run_experiment(
    entry: Entry,
    *,
    config: Path | None,
    overrides: list[str] | None,
    out: Path | None,
    quiet: bool,
    force: bool,
    print_config: bool,
    jobs: int | None = None,
    resume: bool = False,
    scheduler: str | None = None,
    figure_formats: tuple[str, ...] = ("png",),
    dpi: int = FIGURE_DPI,
    agrees=None,
) -> dict[str, str]:
    """Load and validate the config, run the experiment, write its files atomically (each
    figure once in each of ``figure_formats``, PNGs at ``dpi``). On an
    error or an interrupt nothing is written and an output folder the run made is removed;
    a resumable experiment's finished points stay in ``<out>/points/`` (``--resume``).
    ``agrees``: see ``RunDirectory.commit``. Returns its comparison (file -> how it changed;
    {} for ``print_config``)."""
    overrides = list(overrides or [])
    run_dir = None
    checkpoints = None
    try:
        experiment, path, cfg = load_run_config(entry, config, overrides)
        if print_config:
            typer.echo(to_yaml(cfg), nl=False)
            return {}
        check_model(entry, cfg, warn)
        run_dir = open_run_directory(entry, cfg, path, config_given=config is not None,
                                     overrides=overrides, out=out, force=force,
                                     figure_formats=figure_formats, dpi=dpi)
        progress = make_progress() if not quiet else None
        options = run_options(entry, cfg, config, overrides, jobs=jobs or os.cpu_count() or 1,
                              warn=warn, inform=inform, scheduler=scheduler)
        run_dir.record = options.record
        if entry.resumable:
            from ..runtime.checkpoints import PointFolder

            identity: dict = {"command": entry.name}
            if not entry.task_keys:  # else each task knows what it was made from
                identity["config"] = run_dir.resolved_config
            checkpoints = PointFolder(run_dir.out_dir, identity, resume=resume, force=force)
            options.checkpoints = checkpoints
        if progress is not None:
            options.progress = progress
        try:
            result = experiment.run(cfg, options)
        finally:
            if progress is not None:
                progress.stop()
        written = write_result(run_dir, result, agrees)
        if checkpoints is not None:
            checkpoints.remove()
    except BaseException as exc:
        if checkpoints is not None:
            checkpoints.discard_if_empty()
        if run_dir is not None:
            run_dir.discard()
        if isinstance(exc, BounceError):
            fail(str(exc))
        if isinstance(exc, OSError) and not stdout_failed():  # e.g. the disk filled up
            fail(f"writing {exc.filename or 'results'}: {exc.strerror or exc}")
        raise
    if not quiet:
        # as written (no markup: a summary may hold "[a, b]"); wrapped on a terminal only, so
        # that a log file keeps one line per result (grep finds the numbers)
        shown = [str(p.relative_to(run_dir.out_dir)) for p in written]
        if len(shown) > 40:  # a study writes hundreds: the top level and a count
            top = sorted({s.split("/")[0] for s in shown})
            shown = [s for s in top if "/" not in s] + [f"({len(written)} files in all)"]
        lines = [*result.summary, f"wrote {len(written)} files to {run_dir.out_dir}/: "
                 + ", ".join(shown)]
        for line in lines:
            stderr.print(line, highlight=False, markup=False, soft_wrap=not stderr.is_terminal)
    if result.exit_code:
        raise typer.Exit(result.exit_code)
    return run_dir.comparison


# -- engine commands ------------------------------------------------------------------------
def load_model(config: Path | None, overrides: list[str] | None, *,
               need_fixed_point: bool = True) -> ModelParams:
    """The ``model`` block of a config (any experiment's; other blocks are ignored here).
    With ``need_fixed_point``, parameters without a period-1 fixed point (eq. 8) are a user
    error; the map itself (``orbit``) is defined at any valid parameters."""
    return load_model_block(config, overrides, need_fixed_point=need_fixed_point).to_params()


def load_model_block(config: Path | None, overrides: list[str] | None, *,
                     need_fixed_point: bool = True):
    """``load_model``'s validated block, with its ``control`` (racket period control)."""
    path = config if config is not None else bundled_config_path("model")
    overrides = list(overrides or [])
    for text in overrides:
        keys, _ = parse_override(text)
        if keys[0] != "model":
            raise ConfigError(f"--set {'.'.join(keys)}: this command only uses the model block")
    data = apply_overrides(read_yaml(path), overrides)
    others = {key: value for key, value in data.items() if key != "model"}
    if others:  # read no further, but a misspelt block must not pass unseen (issue 36)
        refuse_unknown_blocks(others, str(path), [e.load().schema for e in EXPERIMENTS])
    cfg = validate(ModelOnlyConfig, {"model": data.get("model") or {}}, str(path), overrides)
    warn_if_implausible_racket(cfg.model, warn)
    if need_fixed_point:
        cfg.params.fixed_point()
    return cfg.model


def _model_or_fail(config: Path | None, overrides: list[str] | None, *,
                   need_fixed_point: bool = True) -> ModelParams:
    try:
        return load_model(config, overrides, need_fixed_point=need_fixed_point)
    except BounceError as exc:
        fail(str(exc))
        raise  # unreachable


def fixed_point_report(params: ModelParams) -> dict:
    fp = params.fixed_point()
    st = stability(params)
    return {
        "v_m_s": fp.v_m_s,
        "theta_rad": fp.theta_rad,
        "theta_deg": fp.theta_deg,
        "ac_g": st.ac_g,
        "eigenvalues": [[lam.real, lam.imag] for lam in st.eigenvalues],
        "spectral_radius": st.spectral_radius,
        "regime": st.regime,
        "stable": st.stable,
    }


def no_fixed_point_report(params: ModelParams, error: Exception) -> dict:
    """``fixed-point --json`` where eq. 8 has no solution: why, and the racket amplitude from
    which it has one at the other parameters."""
    return {"exists": False, "reason": str(error), "cos_theta": params.cos_theta_fixed(),
            "min_racket_amplitude_m": params.min_racket_amplitude()}


@app.command("fixed-point")
def fixed_point_command(
    config: ConfigOption = None,
    overrides: SetOption = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON object.")] = False,
) -> None:
    """Period-1 fixed point (eqs. 7, 8), racket acceleration AC, eigenvalues (eq. 10).

    With --json and parameters without a fixed point: {"exists": false, "reason": ...} and
    exit status 1."""
    params = _model_or_fail(config, overrides, need_fixed_point=not as_json)
    if as_json:
        try:
            report = {"exists": True, **fixed_point_report(params)}
        except NoFixedPointError as exc:
            typer.echo(json.dumps(no_fixed_point_report(params, exc), indent=2))
            raise typer.Exit(code=1) from None
        typer.echo(json.dumps(report, indent=2))
        return
    report = fixed_point_report(params)
    table = Table(title="Period-1 fixed point", show_header=True)
    table.add_column("quantity")
    table.add_column("value", justify="right")
    lam = report["eigenvalues"]
    rows = [
        ("alpha, g, a_r, tau", f"{params.alpha:g}, {params.g:g} m/s^2, "
         f"{params.racket_amplitude:g} m, {params.racket_period:g} s"),
        ("v~ (eq. 7)", f"{report['v_m_s']:.4f} m/s"),
        ("theta~ (eq. 8)", f"{report['theta_deg']:.3f} deg = {report['theta_rad']:.5f} rad"),
        ("AC (racket acceleration at impact)", f"{report['ac_g']:.4f} g"),
        ("lambda+ (eq. 10)", f"{lam[0][0]:.4f} {lam[0][1]:+.4f}i"),
        ("lambda- (eq. 10)", f"{lam[1][0]:.4f} {lam[1][1]:+.4f}i"),
        ("spectral radius", f"{report['spectral_radius']:.4f}"),
        ("regime", report["regime"]),
        ("stable", "yes" if report["stable"] else "no"),
    ]
    for key, value in rows:
        table.add_row(key, value)
    Console().print(table)


@app.command("orbit")
def orbit_command(
    theta0_deg: Annotated[
        float, typer.Option("--theta0-deg", help="Phase at which the ball leaves the racket, deg.")
    ],
    v0: Annotated[float, typer.Option("--v0", help="Ball velocity leaving the racket, m/s.")],
    n_impacts: Annotated[int, typer.Option("-n", "--impacts", min=1, help="Impacts.")] = 20,
    min_hop_s: Annotated[
        float,
        typer.Option("--min-hop-s", min=0.0,
                     help="Stop when a hop is shorter than this, s (sticking, section 3); "
                          "0: exact sticking (complete chatters, riding, release)."),
    ] = ClassifySettings().min_hop_s,
    config: ConfigOption = None,
    overrides: SetOption = None,
    as_csv: Annotated[bool, typer.Option("--csv", help="Write CSV to stdout.")] = False,
) -> None:
    """Iterate the map (eqs. 5, 6) from one initial condition, at any parameters (with
    model.control: the racket period as a third state, engine.control)."""
    try:
        block = load_model_block(config, overrides, need_fixed_point=False)
        params, controller = block.to_params(), block.controller()
        if controller is not None:
            params.fixed_point()  # the controller steers toward the period-1 orbit
    except BounceError as exc:
        fail(str(exc))
    if not (math.isfinite(theta0_deg) and math.isfinite(v0)):
        fail("--theta0-deg and --v0 must be finite numbers")
    if controller is not None:
        if min_hop_s == 0.0:
            fail("--min-hop-s 0 (exact sticking) is not implemented with model.control; "
                 "give a shortest hop > 0")
        controlled_orbit_output(math.radians(theta0_deg), v0, params, controller, n_impacts,
                                min_hop_s, as_csv)
        return
    if min_hop_s == 0.0:
        exact_orbit_output(math.radians(theta0_deg), v0, params, n_impacts, as_csv)
        return
    orbit = iterate_orbit(math.radians(theta0_deg), v0, params, n_impacts, min_hop_s)
    rows = orbit_rows(orbit, params)
    if as_csv:
        import pandas as pd

        pd.DataFrame(rows).to_csv(sys.stdout, index=False, lineterminator="\n")
    else:
        table = Table(title=f"Orbit from theta0 = {theta0_deg:g} deg, v0 = {v0:g} m/s")
        for col in ("k", "t_s", "theta_rad", "theta_deg", "v_m_s", "flight_s"):
            table.add_column(col, justify="right")
        for row in rows:
            table.add_row(
                str(row["k"]),
                f"{row['t_s']:.5f}",
                f"{row['theta_rad']:.5f}",
                f"{row['theta_deg']:.4f}",
                f"{row['v_m_s']:.5f}",
                "" if math.isnan(row["flight_s"]) else f"{row['flight_s']:.5f}",
            )
        Console().print(table)
    for note in orbit_notes(orbit, params, min_hop_s):
        print(note, file=sys.stderr)


def controlled_orbit_output(theta0, v0, params, controller, n_impacts, min_hop_s,
                            as_csv) -> None:
    """``bounce orbit`` with racket period control: the passive columns (``event`` among
    them) plus ``racket_period_s`` (the period of the flight ending at each impact)."""
    import pandas as pd

    from ..model.control import iterate_controlled_orbit

    orbit = iterate_controlled_orbit(theta0, v0, params, controller, n_impacts,
                                     min_hop_s)
    frame = pd.DataFrame({"k": np.arange(len(orbit.theta)), "t_s": orbit.t_s,
                          "theta_rad": orbit.theta,
                          "theta_deg": np.degrees(wrap_phase(orbit.theta)), "v_m_s": orbit.v,
                          "flight_s": orbit.flight_s,
                          "event": ["start", *["impact"] * (len(orbit.theta) - 1)],
                          "racket_period_s": orbit.tau})
    write_orbit_frame(frame, as_csv, f"Orbit with racket period control from theta0 = "
                                     f"{math.degrees(theta0):g} deg, v0 = {v0:g} m/s")
    if orbit.stop_reason == "below_racket":
        print(f"note: stopped: the initial velocity {v0:g} m/s is not above the racket's "
              f"velocity at that phase (below the racket)", file=sys.stderr)
    elif orbit.stop_reason == "sticking":
        print(f"note: stopped at impact {len(orbit.theta) - 1}: the hop lasted "
              f"{orbit.flight_s[-1]:.3g} s < {min_hop_s:g} s, or the ball could not "
              f"leave the racket (sticking)", file=sys.stderr)


def write_orbit_frame(frame, as_csv: bool, title: str, small: tuple[str, ...] = ()) -> None:
    """An orbit's table to stdout: CSV, or a rich table with floats to 5 decimals (columns
    in ``small`` to 3 significant digits, NaN blank) and the rest (k, event) as they are."""
    if as_csv:
        frame.to_csv(sys.stdout, index=False, lineterminator="\n")
        return
    table = Table(title=title)
    for col in frame.columns:
        table.add_column(col, justify="right")
    for row in frame.itertuples(index=False):
        table.add_row(*(("" if math.isnan(x) else f"{x:.3g}" if col in small else f"{x:.5f}")
                        if isinstance(x, float) else str(x)
                        for col, x in zip(frame.columns, row)))
    Console().print(table)


def orbit_rows(orbit, params: ModelParams) -> list[dict]:
    w = params.omega
    return [
        {
            "k": k,
            "t_s": orbit.theta[k] / w,
            "theta_rad": orbit.theta[k],
            "theta_deg": math.degrees(float(wrap_phase(orbit.theta[k]))),
            "v_m_s": orbit.v[k],
            "flight_s": orbit.hop_phase[k] / w,
            "event": "start" if k == 0 else "impact",
        }
        for k in range(len(orbit.theta))
    ]


def exact_orbit_output(theta0: float, v0: float, params: ModelParams, n_impacts: int,
                       as_csv: bool) -> None:
    """``bounce orbit --min-hop-s 0``: the hybrid orbit of ``engine.chatter`` (impacts,
    accumulation points of complete chatters, releases), one row per event; ``k`` counts the
    resolved impacts (a stick or release row carries the k of the impact before it)."""
    import pandas as pd

    from ..model.chatter import IMPACT, iterate_exact_orbit, locked_period

    orbit = iterate_exact_orbit(theta0, v0, params, n_impacts)
    w = params.omega
    frame = pd.DataFrame({
        "k": np.cumsum(np.asarray(orbit.event, dtype=object) == IMPACT),
        "t_s": orbit.theta / w, "theta_rad": orbit.theta,
        "theta_deg": np.degrees(wrap_phase(orbit.theta)), "v_m_s": orbit.v,
        "flight_s": orbit.flight / w, "event": orbit.event,
        "chatter_impacts": orbit.chatter_impacts, "tail_error_s": orbit.tail_error_s,
    })
    write_orbit_frame(frame, as_csv, f"Exact orbit from theta0 = {math.degrees(theta0):g} "
                                     f"deg, v0 = {v0:g} m/s", small=("flight_s", "tail_error_s"))
    for note in orbit_notes_exact(orbit, params, locked_period(orbit)):
        print(note, file=sys.stderr)


def below_racket_note(orbit, params: ModelParams) -> str:
    """The note of an orbit whose ball cannot leave the racket at its initial condition."""
    v_r = float(params.racket_velocity(orbit.theta[0]))
    return (f"note: stopped: the initial velocity {orbit.v[0]:g} m/s is not above the racket's "
            f"{v_r:.4f} m/s at that phase (below the racket)")


def orbit_notes_exact(orbit, params: ModelParams, cycles: int) -> list[str]:
    """``orbit_notes`` for the hybrid orbit: below the racket, resting, or locked (with its
    period in racket cycles, the release phase and the Lyapunov exponent -inf)."""
    notes = []
    if orbit.stop_reason == "below_racket":
        notes.append(below_racket_note(orbit, params))
    elif orbit.stop_reason == "resting":
        notes.append(
            f"note: resting: the ball stuck at t = {orbit.theta[-1] / params.omega:.6g} s and "
            f"is never released (Gamma = a_r w^2 / g = "
            f"{params.gamma:.4g} <= 1)")
    elif cycles > 0:
        release = orbit.theta[orbit.rows("release")[-1]]
        notes.append(
            f"note: locked orbit: period {cycles} racket cycle{'s' if cycles > 1 else ''} "
            f"(stick, ride, release at {math.degrees(float(wrap_phase(release))):.4f} deg = "
            f"asin(1/Gamma)); Lyapunov exponent -inf (superstable)")
    return notes


def orbit_notes(orbit, params: ModelParams, min_hop_s: float) -> list[str]:
    """What the user should know about an orbit: no period-1 fixed point at these parameters,
    and why it stopped early."""
    notes = []
    cos_theta = params.cos_theta_fixed()
    if cos_theta > 1.0:
        notes.append(
            f"note: no period-1 fixed point at these parameters (eq. 8 gives cos(theta~) = "
            f"{cos_theta:.4g} > 1): the orbit cannot settle on one"
        )
    if orbit.stop_reason == "below_racket":
        notes.append(below_racket_note(orbit, params))
    elif orbit.stop_reason == "sticking":
        k = len(orbit.theta) - 1
        notes.append(
            f"note: stopped at impact {k}: the hop lasted {orbit.hop_phase[k] / params.omega:.3g} s"
            f" < {min_hop_s:g} s (sticking)"
        )
    return notes


@app.command("reproduce")
def reproduce_command(
    names: Annotated[Optional[list[str]], typer.Argument(
        metavar="[EXPERIMENT]...", help="Only these experiments (default: every one).",
        show_default=False)] = None,
    out: Annotated[Path, typer.Option("--out", "-o", parser=output_folder, metavar="PATH",
                                      help="Results root directory.")] = Path("results"),
    jobs: JobsOption = None,
    quiet: QuietOption = False,
    force: ForceOption = False,
    force_regen: Annotated[bool, typer.Option(
        "--force-regen", help="Rewrite every file, also those that agree within the "
        "reproduction tolerance (and redraw every figure).")] = False,
) -> None:
    """Regenerate every figure from the bundled configs, with a gallery and the claims.

    Runs every bundled config into OUT/<name>/ and writes OUT/README.md: each figure with a
    caption naming the paper's figure, and the table of the paper's claims (bounce verify).
    A table that agrees with the one in OUT within the reproduction tolerance is left as it
    is, and an experiment's figures are redrawn only when one of its tables changed beyond
    it (or a figure is missing); each experiment is reported identical, within tolerance or
    changed (with the files).
    """
    from ..paper.claims import markdown_table, verify
    from ..runtime.artifacts import write_text_atomic
    from ..experiments.registry import reproduced
    from ..paper.reproduce import experiment_status, gallery_markdown, tables_agree

    known = [entry.name for entry in reproduced()]
    unknown = [name for name in names or [] if name not in known]
    if unknown:
        fail(f"reproduce {unknown[0]}: no such reproduced experiment (one of: "
             f"{', '.join(known)})")
    for entry in reproduced():
        if names and entry.name not in names:
            continue
        if not quiet:
            stderr.print(f"[bold]bounce {entry.name}[/bold]")
        comparison = run_experiment(
            entry, config=None, overrides=[], out=out / entry.name, quiet=quiet, force=force,
            print_config=False, jobs=jobs,
            agrees=None if force_regen else tables_agree(entry.name))
        if not quiet:
            print(f"{entry.name}: {experiment_status(comparison)}", flush=True)
    verdicts = verify(out)
    gallery, text = out / "README.md", gallery_markdown(out, markdown_table(verdicts))
    same = gallery.is_file() and gallery.read_text(encoding="utf-8") == text
    if not same:
        write_text_atomic(gallery, text)
    if not quiet:
        stderr.print(f"{'unchanged' if same else 'wrote'} {gallery}", highlight=False)
        print_verdicts(verdicts)


def print_verdicts(verdicts) -> None:
    """The claims as a table on stdout, the known discrepancies as numbered notes below."""
    console = Console(width=None if sys.stdout.isatty() else 160)
    table = Table(title="The paper's claims against our reproduction")
    for col in ("claim", "paper", "ours", "tolerance", "status"):
        table.add_column(col, overflow="fold")
    notes = []
    for v in verdicts:
        if v.status == "reproduced":
            status = "[green]reproduced[/green]"
        elif v.documented:
            notes.append(v.claim.known_discrepancy)
            status = f"[yellow]differs[/yellow] (known [{len(notes)}])"
        else:
            status = f"[red]{v.status}[/red]"
        table.add_row(v.claim.statement, v.claim.paper, v.ours, v.claim.tolerance, status)
    console.print(table)
    for i, note in enumerate(notes, 1):
        console.print(f"[{i}] {note}", highlight=False, markup=False)


@app.command("verify")
def verify_command(
    results: Annotated[
        Path, typer.Option("--results", "-r", help="Results root written by reproduce.")
    ] = Path("results"),
) -> None:
    """Hold the paper's quantitative claims against the reproduced results.

    Exit 0 when each claim is reproduced or differs for a documented reason, 1 otherwise.
    """
    from ..paper.claims import verify

    if not results.is_dir():
        fail(f"--results {results}: no such directory (run `bounce reproduce` first)")
    verdicts = verify(results)
    print_verdicts(verdicts)
    failed = [v for v in verdicts if not v.passed]
    if failed:
        print(f"bounce: {len(failed)} claim(s) not reproduced: "
              + ", ".join(v.claim.key for v in failed), file=sys.stderr)
        raise typer.Exit(code=1)


def add_experiment_command(entry: Entry) -> None:
    """Register ``bounce <name>`` for a registry entry: the common options (and the file
    options ``--data``, ``--events`` where the experiment declares them), then
    ``run_experiment``."""

    def command(
        config: ConfigOption = None,
        overrides: SetOption = None,
        out: OutOption = None,
        quiet: QuietOption = False,
        force: ForceOption = False,
        print_config: PrintConfigOption = False,
        jobs: JobsOption = None,
        data: Optional[list[Path]] = None,
        events: Optional[list[Path]] = None,
        manifest: Optional[list[Path]] = None,
        racket: Optional[list[str]] = None,
        headless: Annotated[bool, typer.Option(
            "--headless", help="No page: the physics and the files only (config key "
            "display.headless).")] = False,
        realtime: Annotated[bool, typer.Option(
            "--realtime", help="Pace a source without a clock of its own (sine, replay, "
            "subject) to the wall clock even when headless (display.realtime).")] = False,
        port: Annotated[Optional[int], typer.Option(
            "--port", help="The page's port on 127.0.0.1, 0 for any free one (display.port); "
            "the URL is printed.", min=0, max=65535)] = None,
        figures: Annotated[Optional[str], typer.Option(
            "--figures", help="Which figures to draw: none, group (the group's) or all (the "
            "group's and every unit's); default: what the reports show (config key "
            "report.figures).", metavar="none|group|all")] = None,
        resume: ResumeOption = False,
        scheduler: SchedulerOption = None,
        figure_format: FigureFormatOption = None,
        dpi: DpiOption = FIGURE_DPI,
    ) -> None:
        overrides = list(overrides or [])
        out_dir = only_once("--out", out)
        data_paths = [str(p) for p in data or []]
        if len(data_paths) > 1:  # several files: the trials of one session, where it can be
            from ..runtime.config import accepts_several_files

            if not accepts_several_files(entry.load().schema):
                fail(f"--data given {len(data_paths)} times ({', '.join(data_paths)}): bounce "
                     f"{entry.name} reads one file per run (several --data files are the trials "
                     "of one session for learning, regression, acf, impulse and control)")
            overrides.append(f"data={json.dumps(data_paths)}")
        elif data_paths:
            overrides.append(f"data={json.dumps(data_paths[0])}")
        for key, paths in (("events", events), ("manifest", manifest)):
            path = only_once(f"--{key}", paths)
            if path is not None:
                overrides.append(f"{key}={json.dumps(str(path))}")
        source = only_once("--racket", racket)
        if source is not None:
            overrides.append(f"racket={json.dumps(source)}")
        if headless:
            overrides.append("display.headless=true")
        if realtime:
            overrides.append("display.realtime=true")
        if port is not None:
            overrides.append(f"display.port={port}")
        if figures is not None:
            overrides.append(f"report.figures={figures}")
        run_experiment(entry, config=config, overrides=overrides, out=out_dir, quiet=quiet,
                       force=force, print_config=print_config, jobs=jobs, resume=resume,
                       scheduler=scheduler, figure_formats=tuple(figure_format or ["png"]),
                       dpi=dpi)

    # the signature typer reads: annotations resolved, file options only where declared,
    # --jobs, --resume and --scheduler only for the experiments that take them
    hints = typing.get_type_hints(command, include_extras=True)
    file_options = {"data": entry.data_help, "events": entry.events_help,
                    "manifest": entry.manifest_help}
    for key, help_text in file_options.items():
        hints[key] = Annotated[Optional[list[Path]],
                               typer.Option(f"--{key}", help=help_text, metavar="PATH")]
    hints["racket"] = Annotated[Optional[list[str]],
                                typer.Option("--racket", help=entry.racket_help,
                                             metavar="SOURCE")]
    declared = {**{k: v is not None for k, v in file_options.items()},
                "racket": entry.racket_help is not None, "headless": entry.live,
                "realtime": entry.live, "port": entry.live,
                "figures": entry.manifest_help is not None,
                "resume": entry.resumable, "scheduler": entry.cluster, "jobs": entry.parallel}
    params = [p.replace(annotation=hints[p.name])
              for p in inspect.signature(command).parameters.values()
              if declared.get(p.name, True)]
    command.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    command.__doc__ = entry.summary
    app.command(entry.name)(command)


for _entry in EXPERIMENTS:
    add_experiment_command(_entry)
