"""The shell of the ``bounce`` app: the typer group and its way of ending, the options
every command shares, and the sinks of what a run tells its user. Light on purpose (typer,
rich and the standard library): ``bounce --help`` imports no numpy; the commands
(:mod:`bounce_cli.cli.commands`) import what they run when they run it.

User errors (bad YAML, unknown keys, out-of-range values, parameters without a fixed point,
an output directory holding another config's results: every ``errors.BounceError``; typer's
own usage errors) print ONE line ``bounce: error: ...`` to stderr and exit 2. An interrupt
(SIGINT, SIGTERM, SIGHUP) prints ``bounce: interrupted`` and exits 128 + the signal number
(see ``interrupts``).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, NoReturn, Optional

import typer
from rich.console import Console
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

from ..version import __version__
from ..runtime.interrupts import Interrupted, interrupt_behind, report as report_interrupt


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
        except Exception as exc:
            # a library's own error raised from an interrupt (a C extension interrupted as it
            # initialised): the interrupt goes on to the console script, which leaves at
            # once (the interpreter's teardown met such a half-made module and aborted)
            behind = interrupt_behind(exc)
            if behind is None:
                raise
            raise behind from None
        if standalone_mode:
            sys.exit(code)
        return code


#: what ``bounce --help`` says the app is (pyproject.toml's description says the same)
SUMMARY = ("The ball bouncing map paper's experiments: the model, a lab's data against it, "
           "the virtual set-up.")

app = typer.Typer(
    cls=BounceGroup,
    name="bounce",
    help=SUMMARY,
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


@app.callback(help=SUMMARY)
def main_callback(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="Show the version."),
    ] = False,
) -> None:
    """The app's summary (:data:`SUMMARY`) and its version option."""


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
        help="Workers for the run's independent tasks: a grid's points, a study's units "
        "(default: all cores).",
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
                      help="Resolution of PNG figures, dots per inch.")
]
ResumeOption = Annotated[
    bool,
    typer.Option("--resume", help="Continue an interrupted run in --out: the tasks it "
                 "finished (in --out/points/) are kept, the rest computed (the config must be "
                 "the same)."),
]
SchedulerOption = Annotated[
    Optional[str],
    typer.Option("--scheduler", metavar="ADDRESS",
                 help="Run the tasks on the Dask cluster whose scheduler is at ADDRESS "
                 "(e.g. tcp://host:8786) instead of local processes (needs bounce-cli's "
                 "optional extra named cluster, Dask's distributed package)."),
]


def warn(message: str) -> None:
    print(f"bounce: warning: {message}", file=sys.stderr, flush=True)


def inform(message: str) -> None:
    print(f"bounce: {message}", file=sys.stderr, flush=True)
