"""SIGINT / SIGTERM / SIGHUP: stop the run at once, clean up, say one line, exit 128 + signal.

Light on purpose (standard library only): :func:`install` runs before the heavy imports of a
``bounce`` command, so that an interrupt during the imports is handled like one later on.

The handler raises :class:`Interrupted` in the main thread. It derives from BaseException
(not KeyboardInterrupt), so that ``except Exception`` clauses, click's KeyboardInterrupt
handling and the like let it through, while ``finally`` blocks and ``except BaseException``
clean-ups (temporary files, worker processes, the output folder a run created) still run.
Only the first signal raises; later ones arrive during that clean-up and are ignored.

Critical sections (moving a run's staged files into place) run under :func:`deferred`: a
signal arriving there is held and raised when the section ends, so a run's files are either
all the previous run's or all the new run's.
"""

from __future__ import annotations

import contextlib
import gc
import signal
import sys
from typing import Any, Iterator, NoReturn

#: the signals a terminal, ``kill`` or a batch scheduler sends to stop a program
SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)


class Interrupted(BaseException):
    """The run was stopped by a signal; ``exit_code`` is 128 + the signal number."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum
        #: what the one line adds in parentheses (a resumable run: where its finished tasks
        #: are kept), set on the way out
        self.note = ""

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


_state: dict[str, Any] = {"deferring": 0, "pending": None, "raised": False, "signum": None}


def _handler(signum: int, frame) -> None:
    if _state["raised"]:
        return  # already stopping: clean-up is under way
    if _state["deferring"]:
        _state["pending"] = _state["pending"] or signum
        return
    _state["raised"], _state["signum"] = True, signum
    raise Interrupted(signum)


def install() -> None:
    """Route SIGINT, SIGTERM and SIGHUP to :class:`Interrupted` (main thread only). The state
    is reset first: a signal may arrive the moment a handler is in place (the caller's
    ``try`` around this call then takes it)."""
    _state.update(deferring=0, pending=None, raised=False, signum=None)
    for signum in SIGNALS:
        signal.signal(signum, _handler)


def uninstall() -> None:
    """The operating system's default action for the signals again: once a command is over, a
    signal during the interpreter's exit ends the process at once (status 128 + signal, as
    any program) instead of raising :class:`Interrupted` where nothing catches it (a
    traceback after the run's files were written)."""
    for signum in SIGNALS:
        signal.signal(signum, signal.SIG_DFL)


def forked_child() -> None:
    """In a child forked inside :func:`deferred` (its copy of this module's state holds the
    parent's deferral, which the child never leaves): the handlers installed afresh and a
    signal the child was sent meanwhile raised now."""
    pending = _state["pending"]
    install()
    if pending is not None:
        _state["raised"], _state["signum"] = True, pending
        raise Interrupted(pending)


def exit_now(code: int) -> NoReturn:
    """Flush stdout and stderr (as far as they still can be) and end the process at once
    with ``code``: no interpreter teardown, no clean-up of a parent's that a forked child
    inherited."""
    import os

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def installed() -> bool:
    return signal.getsignal(signal.SIGINT) is _handler


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold signals for the duration of the block; raise the first one after it."""
    _state["deferring"] += 1
    try:
        yield
    finally:
        _state["deferring"] -= 1
        pending = _state["pending"]
        if pending is not None and not _state["deferring"] and not _state["raised"]:
            _state["pending"] = None
            _state["raised"], _state["signum"] = True, pending
            raise Interrupted(pending)


def interrupt_behind(exc: BaseException) -> Interrupted | None:
    """The :class:`Interrupted` an exception stands for: itself, or one in its chain of
    causes and contexts. A signal that arrives while a C extension module initialises
    (``import matplotlib.figure`` loading ``matplotlib._image``) is turned by it into
    ``ImportError: initialization failed``, raised from the interrupt: it is still the
    interrupt, and the run ends as one (one line, 128 + signal), not with a traceback."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        if isinstance(current, Interrupted):
            return current
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return None


def report(exc: Interrupted) -> int:
    """Print the one line and return the exit code (128 + signal number)."""
    try:
        note = f" ({exc.note})" if exc.note else ""
        print(f"bounce: interrupted{note}", file=sys.stderr, flush=True)
    except (OSError, ValueError):  # stderr gone (terminal closed)
        pass
    return exc.exit_code


#: gc.set_threshold of a bounce process, the console script's and its workers' (the
#: interpreter's default: 700, 10, 10): the cyclic collector every 100,000 new containers.
#: The imports of numpy, pandas, scipy and matplotlib and the analyses' many small objects
#: hold few cycles, and the default's collections were a tenth of a short run (acf --data on
#: 3 trials: 2.22 -> 1.97 s median)
GC_THRESHOLDS = (100_000, 50, 50)


@contextlib.contextmanager
def lasting_imports() -> Iterator[None]:
    """Imports whose objects last as long as the process (modules and their classes,
    functions and tables): the cyclic collector paused while they run and everything it
    tracks frozen afterwards (``gc.freeze``: never traversed again), then the collector as
    it was. Each collection in an import traverses every young object, none of which is
    garbage: a 1000 x 1000 basin's two (the CLI's imports, pandas') took about 0.03 s each,
    one of them on start-up's single core.

    An interrupt raised in one of the imports and taken by the importing library for a
    failed import (a C extension interrupted as it initialised raises ImportError, which
    some libraries answer with a fallback) is raised again when the block ends: the run
    would otherwise go on, deaf to every later signal (only the first one raises)."""
    raised_before = _state["raised"]
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        gc.freeze()
        if enabled:
            gc.enable()
    if _state["raised"] and not raised_before:
        raise Interrupted(_state["signum"])
