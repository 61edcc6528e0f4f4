"""The ``bounce`` console script: the signal handlers first (:mod:`bounce_cli.runtime.interrupts`,
standard library only), then the typer app's imports and run (:mod:`bounce_cli.cli.commands`)."""

from __future__ import annotations

import gc
import os
import sys

from ..runtime.interrupts import Interrupted, install, report


def main() -> None:
    """The ``bounce`` console script: handlers first, then the CLI's imports and run."""
    install()
    try:
        from .commands import app

        app(prog_name="bounce")
    except Interrupted as exc:
        code = report(exc)
        # what the run must undo was undone on the way here (staged files removed, worker
        # processes and writers killed and reaped, threads' tiles cancelled or waited for);
        # the interpreter's teardown after an interrupt can meet a library interrupted half
        # way through its import, which once aborted the process (SIGABRT instead of 143):
        # leave without it
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)
    finally:
        # the interpreter's last garbage collections at exit traverse every object numba,
        # pandas and matplotlib made: 0.36 s of a basin run; frozen, they are skipped (the
        # exit itself, atexit handlers and finalizers included, is unchanged): 0.04 s
        gc.freeze()
