"""The one executor: a list of independent tasks -> their results, in order.

Parallel work (tiles of a basin grid today; parameter points of a sweep, a Dask cluster
later) is a function and an iterable of independent tasks, handed to an executor's
``map(fn, tasks)``, which yields ``fn(task)`` for each task in the order of the tasks (as the
built-in ``map`` does, and as emcee takes any ``pool`` with a ``map``). Results never depend
on the executor or its number of workers: the caller makes the tasks, the executor only runs
them.

* :class:`InProcess`: the calling process, one task after another.
* :class:`LocalPool`: ``jobs`` worker processes on this machine.

Another backend (a Dask cluster) is a class with the same three things: ``workers``, a
``map`` that submits the tasks and yields their results in task order, and a context manager
that releases what it holds (and cancels what is under way when left by an exception).

Process hygiene of :class:`LocalPool` (what a Ctrl-C, ``kill`` or a batch scheduler needs):

* Workers are plain child processes (``python -m bounce_cli.parallel``) talking over their
  stdin/stdout pipes: no forkserver, no resource tracker, no semaphores to leak.
* They run in their own session, so a terminal's Ctrl-C (sent to the foreground process
  group) reaches only the main process, which stops them; they ignore SIGINT in any case and
  never print a traceback for an interrupt.
* Leaving the ``with`` block normally lets them finish and exit; leaving it by an exception
  (an interrupt, an error) kills them (SIGKILL) and reaps them before the exception goes on.
* If the main process dies without clean-up (SIGKILL), each worker gets SIGKILL too (Linux
  ``PR_SET_PDEATHSIG``), and elsewhere exits when its task pipe closes.
* A worker that dies (out of memory, killed) is an error (:class:`WorkerError`), not a hang.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import traceback
import typing
from collections import deque
from multiprocessing.connection import Connection, wait
from typing import Any, Callable, Iterable, Iterator, Protocol

from .interrupts import deferred


class Executor(Protocol):
    """What parallel work is handed to: ``map(fn, tasks)`` yields ``fn(task)`` in task order.

    ``workers`` is how many tasks run at once (callers may cut work into a multiple of it
    for balance; it must never change their results)."""

    workers: int

    def map(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[Any]: ...

    def __enter__(self) -> "Executor": ...

    def __exit__(self, *exc) -> None: ...


class WorkerError(RuntimeError):
    """A task failed in a worker process, or a worker process died."""


class InProcess:
    """Run each task in this process, one after another."""

    workers = 1

    def map(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[Any]:
        for task in tasks:
            yield fn(task)

    def __enter__(self) -> "InProcess":
        return self

    def __exit__(self, *exc) -> None:
        pass


class _Worker:
    """One worker process and the two ends of its pipes."""

    def __init__(self) -> None:
        # the workers import what this process can (as multiprocessing's spawn does)
        package_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        python_path = os.pathsep.join(dict.fromkeys(
            p for p in (package_root, *sys.path) if p and os.path.isdir(p)
        ))
        self.process = subprocess.Popen(
            [sys.executable, "-m", "bounce_cli.parallel", str(os.getpid())],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            start_new_session=True,
            close_fds=True,
            env={**os.environ, "PYTHONPATH": python_path},
        )
        stdin, stdout = self.process.stdin, self.process.stdout
        assert stdin is not None and stdout is not None  # both are PIPE
        self.tasks = Connection(os.dup(stdin.fileno()), readable=False)
        self.results = Connection(os.dup(stdout.fileno()), writable=False)
        stdin.close()
        stdout.close()
        self.index: int | None = None  # the task it is working on

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait()
        self.close_pipes()

    def finish(self, timeout: float = 5.0) -> None:
        """Close its task pipe (it exits at end of input) and reap it."""
        self.close_pipes()
        try:
            self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill()

    def close_pipes(self) -> None:
        for conn in (self.tasks, self.results):
            if not conn.closed:
                conn.close()


#: how many tasks per worker LocalPool.map runs ahead of the next result it yields
AHEAD = 4


class LocalPool:
    """``jobs`` worker processes on this machine, started on the first ``map``; use as a
    context manager (the workers are stopped when the block is left)."""

    def __init__(self, jobs: int) -> None:
        if jobs < 1:
            raise ValueError("jobs must be >= 1")
        self.workers = jobs
        self._pool: list[_Worker] = []

    def __enter__(self) -> "LocalPool":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.terminate()

    def close(self) -> None:
        """Let the workers exit and reap them."""
        while self._pool:
            self._pool.pop().finish()

    def terminate(self) -> None:
        """Kill the workers at once and reap them."""
        while self._pool:
            self._pool.pop().kill()

    def map(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[Any]:
        """Yield ``fn(task)`` in task order; tasks are sent to workers as they become idle
        (the iterable is read lazily). A failing task raises :class:`WorkerError` with the
        worker's traceback; the other workers are killed when the ``with`` block is left."""
        pending = iter(tasks)
        done: dict[int, Any] = {}
        next_out = 0
        submitted = 0
        exhausted = False
        idle: deque[_Worker] = deque()
        try:
            while len(self._pool) < self.workers:
                # not interruptible half-way: a worker is either started and recorded (so
                # that clean-up kills it) or not started at all
                with deferred():
                    self._pool.append(_Worker())
            idle.extend(self._pool)
            busy: dict[Connection, _Worker] = {}
            while True:
                # at most AHEAD tasks per worker past the next result to yield: results
                # waiting for a slow earlier task are held in memory
                while idle and not exhausted and submitted - next_out < AHEAD * self.workers:
                    try:
                        task = next(pending)
                    except StopIteration:
                        exhausted = True
                        break
                    worker = idle.popleft()
                    worker.index = submitted
                    submitted += 1
                    try:
                        worker.tasks.send_bytes(pickle.dumps((fn, task), protocol=5))
                    except OSError:
                        raise WorkerError(self._died(worker)) from None
                    busy[worker.results] = worker
                while next_out in done:
                    yield done.pop(next_out)
                    next_out += 1
                if not busy:
                    if exhausted:
                        return
                    continue
                for ready in wait(list(busy)):
                    conn = typing.cast(Connection, ready)
                    worker = busy.pop(conn)
                    try:
                        ok, value = pickle.loads(conn.recv_bytes())
                    except (EOFError, OSError):
                        raise WorkerError(self._died(worker)) from None
                    if not ok:
                        raise WorkerError(f"a task failed in a worker process:\n{value}")
                    assert worker.index is not None  # it was busy with that task
                    done[worker.index] = value
                    worker.index = None
                    idle.append(worker)
        except BaseException:
            self.terminate()
            raise

    @staticmethod
    def _died(worker: _Worker) -> str:
        code = worker.process.wait()
        how = f"was killed by signal {-code}" if code < 0 else f"exited with status {code}"
        return f"a worker process {how} (out of memory?)"


def executor(jobs: int) -> InProcess | LocalPool:
    """The local executor for ``jobs`` workers: in this process for 1, else a pool."""
    return InProcess() if jobs <= 1 else LocalPool(jobs)


# -- the worker process -----------------------------------------------------------------------
def _die_with_parent(parent_pid: int) -> None:
    """SIGKILL this worker when its parent dies (Linux); elsewhere the closed task pipe
    ends it after the task under way."""
    import signal

    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:  # the parent died before prctl
        os._exit(1)


def _serve(parent_pid: int) -> None:
    """Read (fn, task) pickles from stdin, write (ok, result or traceback) to stdout, until
    stdin closes. stdout is kept for the results: anything a task prints goes to stderr."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _die_with_parent(parent_pid)
    tasks = Connection(os.dup(0), writable=False)
    results = Connection(os.dup(1), readable=False)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    while True:
        try:
            message = tasks.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            fn, task = pickle.loads(message)
            reply = (True, fn(task))
        except Exception:
            reply = (False, traceback.format_exc())
        try:
            data = pickle.dumps(reply, protocol=5)
        except Exception:  # a result that cannot be pickled
            data = pickle.dumps((False, traceback.format_exc()), protocol=5)
        try:
            results.send_bytes(data)
        except OSError:  # the parent is gone
            return


if __name__ == "__main__":
    _serve(int(sys.argv[1]))
