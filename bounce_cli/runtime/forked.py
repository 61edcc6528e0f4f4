"""A call run in a forked child process beside this one: the second core's share of work
that would otherwise wait its turn (a run's files staged, half of a study's figures
rendered), without a worker's start-up (the child has every module and object this process
has, copy-on-write).

Linux only (:func:`can_fork`): fork is unsafe on macOS with some system libraries and absent
on Windows; callers run the work in this process there. The child ignores SIGINT (the parent
decides: a terminal's Ctrl-C reaches both), dies with the parent, never runs the parent's
clean-up (``os._exit``) and sends back its result, or the exception it raised, which
:meth:`ForkedCall.wait` returns or raises again here.
"""

from __future__ import annotations

import os
import sys
from typing import Any, Callable

from .interrupts import deferred


def can_fork() -> bool:
    """True where :class:`ForkedCall` may run (Linux)."""
    return sys.platform.startswith("linux")


class ForkedCall:
    """``fn()`` in a forked child: :meth:`start`, then :meth:`wait` for its (picklable)
    result; :meth:`kill` stops it (left by an exception, the caller kills it)."""

    def __init__(self, fn: Callable[[], Any], what: str = "a child process") -> None:
        self.fn = fn
        self.what = what
        self.pid = 0
        self._pipe = -1

    def start(self) -> ForkedCall:
        """Fork the child. Signals are held during the fork (a signal raised in an at-fork
        handler would be lost) and raised after it; the child is then killed here, before
        the signal leaves :meth:`start` (the caller never saw the child, and a child left
        running would go on writing: a file it was to fill, made again after the caller's
        clean-up removed it)."""
        read_end, write_end = os.pipe()
        self._pipe = read_end
        parent = os.getpid()
        try:
            with deferred():
                self.pid = os.fork()
                if self.pid == 0:
                    os.close(read_end)
                    self._child(write_end, parent)  # never returns
                os.close(write_end)
        except BaseException:
            self.kill()
            raise
        return self

    def _child(self, write_end: int, parent: int) -> None:
        import pickle
        import signal

        code = 1
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            for name in ("SIGTERM", "SIGHUP"):
                if hasattr(signal, name):
                    signal.signal(getattr(signal, name), signal.SIG_DFL)
            from .parallel import _die_with_parent

            _die_with_parent(parent)
            data = pickle.dumps((True, self.fn()))
            code = 0
        except BaseException as exc:  # sent to the parent, which raises it
            try:
                data = pickle.dumps((False, exc))
            except Exception:
                data = pickle.dumps((False, RuntimeError(f"{type(exc).__name__}: {exc}")))
        try:
            with open(write_end, "wb", closefd=False) as pipe:
                pipe.write(data)
        finally:
            os._exit(code)

    def wait(self) -> Any:
        """Wait for the child; its result, or raise what failed in it."""
        import pickle

        with open(self._pipe, "rb") as pipe:  # read before waiting: a full pipe would block
            data = pipe.read()
        self._pipe = -1
        _, status = os.waitpid(self.pid, 0)
        self.pid = 0
        message = pickle.loads(data) if data else None
        if isinstance(message, tuple) and len(message) == 2:
            ok, value = message
            if not ok:
                raise value
            if status == 0:
                return value
        raise OSError(f"{self.what} died (wait status {status})")

    def kill(self) -> None:
        """Stop the child at once (what it staged is the caller's to remove)."""
        import signal

        if self.pid:
            try:
                os.kill(self.pid, signal.SIGKILL)
                os.waitpid(self.pid, 0)
            except OSError:
                pass
            self.pid = 0
        try:
            if self._pipe >= 0:
                os.close(self._pipe)
        except OSError:
            pass
        self._pipe = -1


def split_work(items: list, run: Callable[[list], dict]) -> dict:
    """``run(items)`` with the later half of ``items`` run in a forked child while this
    process runs the first half (where :func:`can_fork` and there are two items or more);
    the two results merged, in the order of ``items``."""
    if len(items) < 2 or not can_fork():
        return run(items)
    half = len(items) // 2
    child = ForkedCall(lambda: run(items[half:]), "the process rendering half of the work")
    child.start()
    try:
        mine = run(items[:half])
        theirs = child.wait()
    finally:
        child.kill()
    return {**mine, **theirs}
