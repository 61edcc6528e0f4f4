"""The ``bounce`` console script: the signal handlers first (:mod:`bounce_cli.runtime.interrupts`,
standard library only), then the typer app's imports and run (:mod:`bounce_cli.cli.commands`).
Standard output is watched (:class:`WatchedStdout`): when it cannot be written (``> /dev/full``)
the run ends with one line ``bounce: error: cannot write to standard output: ...``, exit 2."""

from __future__ import annotations

import contextlib
import errno
import gc
import os
import sys
from typing import Iterator, NoReturn

from ..runtime.interrupts import (GC_THRESHOLDS, Interrupted, exit_now, install,
                                  interrupt_behind, lasting_imports, report, uninstall)
from ..runtime.process import tune
from .stdout import WatchedStdout


def _report_stdout_failure(failure: OSError) -> int:
    """Standard output cannot be written: one line and status 2 (a closed pipe, ``| head``:
    no line and status 1, as click ends a command whose reader left), and the rest of the
    output goes to the null device so that the interpreter's last flush does not fail again.
    Returns the exit status."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError):
        pass
    if failure.errno == errno.EPIPE:
        return 1
    print(f"bounce: error: cannot write to standard output: "
          f"{failure.strerror or failure}", file=sys.stderr, flush=True)
    return 2


def main() -> None:
    """The ``bounce`` console script: the process's settings (:func:`runtime.process.tune`),
    :func:`run` (handlers first, then the CLI's imports and the command), then out with its
    exit status (:func:`leave`)."""
    tune()  # before numpy is imported
    try:
        run()
    except SystemExit as exc:
        leave(exc)
        raise


def leave(exc: SystemExit) -> None:
    """End the process with the command's status, without the interpreter's teardown: the
    atexit handlers run (temporary folders removed, logging flushed, child processes
    joined), standard output and error are flushed, and the process exits at once. The
    teardown would then only free every module and object the command loaded, one by one:
    0.035 s of a 1.4 s basin run. Returns (the interpreter's own exit follows) where the
    status is a message to print, or where a thread that is not a daemon still runs (the
    interpreter would wait for it)."""
    import atexit
    import threading

    code = exc.code
    if code is not None and not isinstance(code, int):
        return
    main_thread = threading.main_thread()
    if any(t.is_alive() and not t.daemon for t in threading.enumerate() if t is not main_thread):
        return
    atexit._run_exitfuncs()
    exit_now(code or 0)


def run() -> None:
    """Handlers first, then the CLI's imports and the command; it ends with SystemExit (its
    status). A signal may come the moment a handler is in place: everything from there on
    is in the ``try``."""
    watched: WatchedStdout | None = None
    try:
        install()
        gc.set_threshold(*GC_THRESHOLDS)
        watched = sys.stdout = WatchedStdout(sys.stdout)
        with lasting_imports():
            from .commands import app

        try:
            with only_the_command_named(app, sys.argv[1:]):
                app(prog_name="bounce")
        except SystemExit:
            # what is still buffered is written here, where a failure is reported (at the
            # interpreter's exit it would be an "Exception ignored" and status 120)
            sys.stdout.flush()
            raise
    except Interrupted as exc:
        _leave_interrupted(exc)
    except Exception as exc:
        if isinstance(exc, OSError) and watched is not None and watched.failure is not None:
            sys.exit(_report_stdout_failure(watched.failure))
        behind = interrupt_behind(exc)  # a library's own error raised from an interrupt
        if behind is None:
            raise
        _leave_interrupted(behind)
    finally:
        uninstall()  # the command is over: a signal now ends the process as any program's
        # the interpreter's last garbage collections at exit traverse every object numba,
        # pandas and matplotlib made: 0.36 s of a basin run; frozen, they are skipped (the
        # exit itself, atexit handlers and finalizers included, is unchanged): 0.04 s
        gc.freeze()


@contextlib.contextmanager
def only_the_command_named(app, args: list[str]) -> Iterator[None]:
    """typer builds the click command of every registered command at each start (its
    parameters from the function's signature and type hints: 0.03 s for 25 commands); where
    the command line starts with a command's exact name, only that one is registered while
    the app runs. Anything else (``--help``, ``--version``, no command, a misspelt one,
    which typer then names its nearest neighbours for) meets every command."""
    commands = app.registered_commands
    named = [c for c in commands if args and c.name == args[0]]
    if len(named) == 1:
        app.registered_commands = named
    try:
        yield
    finally:
        app.registered_commands = commands


def _leave_interrupted(exc: Interrupted) -> NoReturn:
    """The one line, and out at once with 128 + the signal. What the run must undo was undone
    on the way here (staged files removed, worker processes and writers killed and reaped,
    threads' tiles cancelled or waited for); the interpreter's teardown after an interrupt
    can meet a library interrupted half way through its import, which once aborted the
    process (SIGABRT instead of 143): leave without it."""
    exit_now(report(exc))
