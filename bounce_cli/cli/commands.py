"""The ``bounce`` commands: each parses its options, calls the one front door of a run
(:func:`bounce_cli.experiments.runner.execute`) or an engine function, and renders what it
returns. No numerics here, and no numpy, pandas or model import at module level (``bounce
--help`` stays fast): a command imports what it runs when it runs.

No ``from __future__ import annotations`` here: typer reads every command's annotations
(``typing.get_type_hints``) each time ``bounce`` starts, and as strings each of the
commands' some 900 annotations is compiled and evaluated anew (about 0.03 s of every
start-up); written as objects they are made once, when the module is imported.
"""

import contextlib
import functools
import inspect
import json
import math
import os
import sys
import typing
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.table import Table

from ..errors import BounceError, NoFixedPointError
from ..experiments.registry import EXPERIMENTS, Entry
from ..runtime.figure_files import FIGURE_DPI
from .shell import (
    ConfigOption,
    DpiOption,
    FigureFormatOption,
    ForceOption,
    JobsOption,
    OutOption,
    PrintConfigOption,
    QuietOption,
    ResumeOption,
    SchedulerOption,
    SetOption,
    app,
    fail,
    inform,
    only_once,
    output_folder,
    stderr,
    warn,
)
from .progress import make_progress
from .stdout import stdout_failed

#: the files a run lists by name; a study writes hundreds: then the top level and a count
LISTED_FILES = 40


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
    show_progress: bool = True,
) -> dict[str, str]:
    """``bounce <name>``: the run through ``execute`` (each figure once in each of
    ``figure_formats``, PNGs at ``dpi``), then its summary and the files written on stderr.
    A user error is one line and exit 2 (nothing written, an output folder the run made
    removed; a resumable run's finished points stay for ``--resume``). ``agrees``: see
    ``RunDirectory.commit``. Returns its comparison (file -> how it changed; {} for
    ``print_config``)."""
    from ..experiments.runner import execute, load_run_config

    overrides = list(overrides or [])
    try:
        if print_config:
            from ..runtime.config import to_yaml

            typer.echo(to_yaml(load_run_config(entry, config, overrides)[2]), nl=False)
            return {}
        done = execute(entry, config, overrides, out=out, force=force,
                       jobs=jobs or os.cpu_count() or 1, scheduler=scheduler, resume=resume,
                       figure_formats=figure_formats, dpi=dpi,
                       progress=make_progress() if show_progress and not quiet else None,
                       warn=warn, inform=inform,
                       agrees=agrees)
    except BounceError as exc:
        fail(str(exc))
    except OSError as exc:
        if stdout_failed():
            raise
        fail(f"writing {exc.filename or 'results'}: {exc.strerror or exc}")  # a full disk
    assert done.out_dir is not None
    if not quiet:
        # as written (no markup: a summary may hold "[a, b]"); wrapped on a terminal only, so
        # that a log file keeps one line per result (grep finds the numbers)
        shown = [str(p.relative_to(done.out_dir)) for p in done.written]
        if len(shown) > LISTED_FILES:
            top = sorted({s.split("/")[0] for s in shown})
            shown = [s for s in top if "/" not in s] + [f"({len(done.written)} files in all)"]
        lines = [*done.result.summary, f"wrote {len(done.written)} files to {done.out_dir}/: "
                 + ", ".join(shown)]
        for line in lines:
            stderr.print(line, highlight=False, markup=False, soft_wrap=not stderr.is_terminal)
    if done.result.exit_code:
        raise typer.Exit(done.result.exit_code)
    return done.comparison


# -- engine commands ------------------------------------------------------------------------
def _model_or_fail(config: Path | None, overrides: list[str] | None, *,
                   need_fixed_point: bool = True):
    """The config's ``model`` block (``runner.load_model_block``) and its parameters, or one
    line and exit 2."""
    from ..experiments.runner import load_model_block

    try:
        block = load_model_block(config, overrides, need_fixed_point=need_fixed_point,
                                 warn=warn)
        return block, block.to_params()
    except BounceError as exc:
        fail(str(exc))


#: ``bounce orbit``'s largest launch velocity (m/s) and phase (deg): a hop of 200 s at 9.81
#: m/s^2, and a phase a thousand cycles out (both far beyond any ball on a racket)
ORBIT_MAX_V0_M_S = 1000.0
ORBIT_MAX_THETA0_DEG = 360_000.0


@app.command("fixed-point")
def fixed_point_command(
    config: ConfigOption = None,
    overrides: SetOption = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON object.")] = False,
) -> None:
    """Period-1 fixed point (eqs. 7, 8), racket acceleration AC, eigenvalues (eq. 10).

    With --json and parameters without a fixed point: {"exists": false, "reason": ...} and
    exit status 1."""
    from ..experiments.orbit import fixed_point_report, no_fixed_point_report

    _, params = _model_or_fail(config, overrides, need_fixed_point=not as_json)
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


#: ``--min-hop-s``'s default, s: section 3's sticking threshold (``model.params.MIN_HOP_S``;
#: written here so that ``bounce --help`` imports no model; a test holds the two equal)
MIN_HOP_S = 1e-3


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
    ] = MIN_HOP_S,
    config: ConfigOption = None,
    overrides: SetOption = None,
    as_csv: Annotated[bool, typer.Option("--csv", help="Write CSV to stdout.")] = False,
) -> None:
    """Iterate the map (eqs. 5, 6) from one initial condition, at any parameters.

    With model.control the racket period is a third state (bounce_cli.model.control)."""
    from ..experiments.orbit import controlled_orbit, exact_orbit, passive_orbit

    block, params = _model_or_fail(config, overrides, need_fixed_point=False)
    controller = block.controller()
    if controller is not None:
        try:
            params.fixed_point()  # the controller steers toward the period-1 orbit
        except BounceError as exc:
            fail(str(exc))
    if not (math.isfinite(theta0_deg) and math.isfinite(v0)):
        fail("--theta0-deg and --v0 must be finite numbers")
    # beyond these the flight's phase has no digits left for the contact (a NaN row and
    # numpy's overflow warnings at --v0 1e200; a phase that never advanced at 1e308 deg)
    if abs(v0) > ORBIT_MAX_V0_M_S:
        fail(f"--v0: {v0:g} m/s is beyond what the map can follow (|v0| <= "
             f"{ORBIT_MAX_V0_M_S:g} m/s)")
    if abs(theta0_deg) > ORBIT_MAX_THETA0_DEG:
        fail(f"--theta0-deg: {theta0_deg:g} deg is beyond what the map can follow (give the "
             f"phase within a cycle; |theta0| <= {ORBIT_MAX_THETA0_DEG:g} deg)")
    theta0 = math.radians(theta0_deg)
    if controller is not None:
        if min_hop_s == 0.0:
            fail("--min-hop-s 0 (exact sticking) is not implemented with model.control; "
                 "give a shortest hop > 0")
        orbit = controlled_orbit(theta0, v0, params, controller, n_impacts, min_hop_s)
    elif min_hop_s == 0.0:
        orbit = exact_orbit(theta0, v0, params, n_impacts)
    else:
        orbit = passive_orbit(theta0, v0, params, n_impacts, min_hop_s)
    if as_csv:
        orbit.frame.to_csv(sys.stdout, index=False, lineterminator="\n")
    elif controller is None and min_hop_s > 0.0:
        passive_orbit_table(orbit)
    else:
        orbit_table(orbit)
    for note in orbit.notes:
        print(note, file=sys.stderr)


def passive_orbit_table(orbit) -> None:
    """The passive map's orbit as a rich table: phases in rad to 5 decimals and in deg to 4,
    a hop that did not happen blank."""
    table = Table(title=orbit.title)
    for col in ("k", "t_s", "theta_rad", "theta_deg", "v_m_s", "flight_s"):
        table.add_column(col, justify="right")
    for row in orbit.frame.to_dict("records"):
        table.add_row(
            str(row["k"]),
            f"{row['t_s']:.5f}",
            f"{row['theta_rad']:.5f}",
            f"{row['theta_deg']:.4f}",
            f"{row['v_m_s']:.5f}",
            "" if math.isnan(row["flight_s"]) else f"{row['flight_s']:.5f}",
        )
    Console().print(table)


def orbit_table(orbit) -> None:
    """An orbit as a rich table: floats to 5 decimals (its ``small`` columns to 3
    significant digits, NaN blank) and the rest (k, event) as they are."""
    frame = orbit.frame
    table = Table(title=orbit.title)
    for col in frame.columns:
        table.add_column(col, justify="right")
    for row in frame.itertuples(index=False):
        table.add_row(*(("" if math.isnan(x) else f"{x:.3g}" if col in orbit.small else f"{x:.5f}")
                        if isinstance(x, float) else str(x)
                        for col, x in zip(frame.columns, row)))
    Console().print(table)


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
    changed (with the files). With --jobs N (default every core) N experiments run at a
    time, each in a process of its own (Linux; elsewhere one after another); their lines
    come in the order above.
    """
    from ..reproduction.claims import markdown_table, verify
    from ..runtime.artifacts import write_text_atomic
    from ..experiments.registry import reproduced
    from ..reproduction.reproduce import experiment_status, gallery_markdown
    from ..runtime.forked import ForkedLanes, LaneDied

    known = [entry.name for entry in reproduced()]
    unknown = [name for name in names or [] if name not in known]
    if unknown:
        fail(f"reproduce {unknown[0]}: no such reproduced experiment (one of: "
             f"{', '.join(known)})")
    chosen = [entry for entry in reproduced() if not names or entry.name in names]
    workers = jobs or os.cpu_count() or 1
    lanes = min(workers, len(chosen))
    run = functools.partial(reproduce_one, out=out, quiet=quiet, force=force,
                            force_regen=force_regen, jobs=max(1, workers // lanes))
    made = [folder for folder in (out, *out.absolute().parents) if not folder.exists()]
    progress = None if quiet else make_progress()
    try:
        with ForkedLanes(chosen, run, lanes, describe=lambda e: f"experiment {e.name}") as reports:
            if progress is not None:  # after the fork: the lanes have no live display
                progress.start(len(chosen), "bounce reproduce")
            for entry, (printed, said, code, comparison) in zip(chosen, reports):
                if progress is not None:
                    progress.advance(1)
                if not quiet:
                    stderr.print(f"[bold]bounce {entry.name}[/bold]")
                sys.stderr.write(said)
                sys.stderr.flush()
                sys.stdout.write(printed)
                if code:
                    raise typer.Exit(code)
                if not quiet:
                    print(f"{entry.name}: {experiment_status(comparison)}", flush=True)
    except BaseException as exc:
        # each lane removed the folders its experiment made, but not the ones two shared
        for folder in made:  # the deepest first; one that holds something stays
            with contextlib.suppress(OSError):
                folder.rmdir()
        if isinstance(exc, LaneDied):
            fail(f"reproduce: {exc}")
        raise
    finally:
        if progress is not None:
            progress.stop()
    verdicts = verify(out)
    gallery, text = out / "README.md", gallery_markdown(out, markdown_table(verdicts))
    same = gallery.is_file() and gallery.read_text(encoding="utf-8") == text
    if not same:
        write_text_atomic(gallery, text)
    if not quiet:
        stderr.print(f"{'unchanged' if same else 'wrote'} {gallery}", highlight=False)
        print_verdicts(verdicts)


def reproduce_one(entry: Entry, *, out: Path, quiet: bool, force: bool, force_regen: bool,
                  jobs: int) -> tuple[str, str, int, dict[str, str]]:
    """One experiment of ``bounce reproduce``, run as its own command would into
    OUT/<name>/ with its output captured (a lane's, shown by the parent in the experiments'
    order): what it printed on stdout and on stderr, its exit status (0, or the failure's,
    whose one line is in the stderr text) and its comparison with the files there."""
    import io

    from ..reproduction.reproduce import tables_agree

    printed, said = io.StringIO(), io.StringIO()
    code, comparison = 0, {}
    with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(said):
        try:
            comparison = run_experiment(
                entry, config=None, overrides=[], out=out / entry.name, quiet=quiet,
                force=force, print_config=False, jobs=jobs, show_progress=False,
                agrees=None if force_regen else tables_agree(entry.name))
        except typer.Exit as exc:  # fail(): its line is in `said`
            code = exc.exit_code
    return printed.getvalue(), said.getvalue(), code, comparison


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
    from ..reproduction.claims import verify

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
            "group's and every unit's); default: what the reports show, the group's unless "
            "report.unit_figures is set (config key report.figures).",
            metavar="none|group|all")] = None,
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
