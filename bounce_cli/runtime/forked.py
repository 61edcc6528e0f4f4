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
import typing
from typing import Any, Callable, Iterator, Sequence

from .interrupts import deferred, exit_now


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


#: seconds a lane is given to clean up after SIGTERM (its run's staged files removed) before
#: it is killed
LANE_GRACE_S = 10.0


class LaneDied(OSError):
    """A lane ended without reporting the task it had taken (killed: SIGKILL, the
    out-of-memory killer)."""


class ForkedLanes:
    """``run(task)`` for every task, each run in one of ``lanes`` forked children (*lanes*)
    that take the next task from a shared queue as they become free, while this process
    only waits and reorders: ``with ForkedLanes(tasks, run, lanes) as results`` forks the
    lanes, and ``results`` yields each task's result in task order, as soon as every
    earlier task's is in. For independent work of about one core each whose results are
    small (an experiment: its files written by the lane, its report returned). A lane has
    every module and object this process had when the block began (copy-on-write): start a
    live display only inside the block.

    Where :func:`can_fork` is false, or with one lane or one task, the tasks run here, one
    after another, as ``results`` is read. Each result must pickle; an exception a task
    raises is raised here, in task order. Signals: a lane keeps this process's handlers
    (:mod:`.interrupts`), so a terminal's Ctrl-C, which reaches every process of the group,
    stops each where it is, its clean-up done. When the block is left with lanes still
    running (a task failed, an interrupt, the caller stopped reading), they are sent
    SIGTERM, given ``LANE_GRACE_S`` seconds to clean up, then killed; every one is reaped.
    """

    def __init__(self, tasks: Sequence[Any], run: Callable[[Any], Any], lanes: int, *,
                 describe: Callable[[Any], str] = lambda task: f"task {task!r}") -> None:
        self.tasks, self.run, self.describe = list(tasks), run, describe
        self.lanes = min(lanes, len(self.tasks)) if can_fork() else 1
        self._children: dict[Any, int] = {}  # a lane's result pipe -> its pid

    def __enter__(self) -> Iterator[Any]:
        if self.lanes < 2:
            return (self.run(task) for task in self.tasks)
        import struct
        from multiprocessing.connection import Connection

        queue_read, queue_write = os.pipe()
        try:
            # every task's index, then end of input: a lane's read of 4 bytes takes one
            # index whole (a pipe's reads are serialised), the next free lane the next one
            os.write(queue_write, b"".join(struct.pack("<I", i)
                                           for i in range(len(self.tasks))))
            os.close(queue_write)
            for stream in (sys.stdout, sys.stderr):  # not written twice by a lane
                stream.flush()
            parent = os.getpid()
            for _ in range(self.lanes):
                read_end, write_end = os.pipe()
                with deferred():
                    pid = os.fork()
                    if pid == 0:
                        os.close(read_end)
                        _lane(self.tasks, self.run, queue_read, write_end, parent)
                    os.close(write_end)
                    self._children[Connection(read_end, writable=False)] = pid
        except BaseException:
            self._stop()
            raise
        finally:
            os.close(queue_read)
        return self._results()

    def __exit__(self, exc_type, exc, tb) -> None:
        self._stop()

    def _results(self) -> Iterator[Any]:
        import pickle
        from multiprocessing.connection import Connection, wait

        running: dict[int, int] = {}  # a lane's pid -> the task it took
        done: dict[int, tuple[bool, Any]] = {}
        for next_out in range(len(self.tasks)):
            while next_out not in done:
                if not self._children:
                    raise OSError(f"the lanes ended before task {next_out} was reported")
                for ready in wait(list(self._children)):
                    conn = typing.cast(Connection, ready)
                    pid = self._children[conn]
                    try:
                        kind, index, *value = pickle.loads(conn.recv_bytes())
                    except (EOFError, OSError):
                        conn.close()
                        del self._children[conn]
                        _, status = os.waitpid(pid, 0)
                        if pid in running:
                            how = (f"was killed by signal {os.WTERMSIG(status)}"
                                   if os.WIFSIGNALED(status) else
                                   f"exited with status {os.waitstatus_to_exitcode(status)}")
                            raise LaneDied(
                                f"the process running {self.describe(self.tasks[running[pid]])}"
                                f" {how} (out of memory?); its staged files are removed by "
                                "the next run there") from None
                        continue
                    if kind == "started":
                        running[pid] = index
                    else:
                        running.pop(pid, None)
                        done[index] = (value[0], value[1])
            ok, value = done.pop(next_out)
            if not ok:
                error, where = value
                raise error from RuntimeError(f"in the lane that ran it:\n{where}")
            yield value

    def _stop(self) -> None:
        """SIGTERM to every lane still running, ``LANE_GRACE_S`` for their clean-up, then
        SIGKILL; every one reaped."""
        import signal
        import time

        pids = list(self._children.values())
        for conn in self._children:
            conn.close()
        self._children.clear()
        for pid in pids:
            try:
                os.kill(pid, signal.SIGTERM)
            except OSError:
                pass
        deadline = time.monotonic() + LANE_GRACE_S
        for pid in pids:
            while True:
                try:
                    reaped, _ = os.waitpid(pid, os.WNOHANG)
                except ChildProcessError:
                    break
                if reaped:
                    break
                if time.monotonic() > deadline:
                    try:
                        os.kill(pid, signal.SIGKILL)
                        os.waitpid(pid, 0)
                    except OSError:
                        pass
                    break
                time.sleep(0.02)


def _lane(tasks: Sequence[Any], run: Callable[[Any], Any], queue: int, results: int,
          parent: int) -> None:
    """A lane's loop: take an index, say so, run the task, send the result; at the end of
    the queue, exit. Never returns (``os._exit``: none of the parent's clean-up)."""
    import pickle
    import struct
    import traceback
    from multiprocessing.connection import Connection

    code = 0
    try:
        from .interrupts import forked_child
        from .parallel import _die_with_parent

        forked_child()
        _die_with_parent(parent)
        out = Connection(results, readable=False)
        while True:
            taken = os.read(queue, 4)
            if len(taken) < 4:
                break
            (index,) = struct.unpack("<I", taken)
            out.send_bytes(pickle.dumps(("started", index)))
            try:
                reply: tuple[bool, Any] = (True, run(tasks[index]))
            except Exception as exc:  # with its traceback's text (a traceback does not pickle)
                reply = (False, (exc, traceback.format_exc()))
            try:
                data = pickle.dumps(("done", index, *reply))
            except Exception:  # an exception (or result) that does not pickle
                data = pickle.dumps(("done", index, False, (RuntimeError(
                    f"{type(reply[1]).__name__}: {reply[1]}"), traceback.format_exc())))
            out.send_bytes(data)
    except BaseException as exc:  # an interrupt (its clean-up done on the way), a lost pipe
        code = getattr(exc, "exit_code", 1)
    finally:
        exit_now(code)
