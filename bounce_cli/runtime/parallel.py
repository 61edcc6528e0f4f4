"""The one executor: a list of independent tasks -> their results, in order.

Parallel work (tiles of a basin grid today; parameter points of a sweep, a Dask cluster
later) is a function and an iterable of independent tasks, handed to an executor's
``map(fn, tasks)``, which yields ``fn(task)`` for each task in the order of the tasks (as the
built-in ``map`` does, and as emcee takes any ``pool`` with a ``map``). Results never depend
on the executor or its number of workers: the caller makes the tasks, the executor only runs
them.

* :class:`InProcess`: the calling process, one task after another.
* :class:`LocalPool`: ``jobs`` worker processes on this machine.
* :class:`DaskCluster`: the workers of an existing Dask distributed cluster (the optional
  ``cluster`` extra), with the same three things: ``workers``, a ``map`` that submits the
  tasks and yields their results in task order, and a context manager that releases what it
  holds (and cancels what is under way when left by an exception).

Process hygiene of :class:`LocalPool` (what a Ctrl-C, ``kill`` or a batch scheduler needs):

* Workers are plain child processes (``python -m bounce_cli.runtime.parallel``) talking over their
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

import concurrent.futures
import os
import pickle
import subprocess
import sys
import threading
import time
import traceback
import typing
from collections import deque
from multiprocessing.connection import Connection, wait
from typing import Any, Callable, Iterable, Iterator, Protocol

from ..errors import ClusterError
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


class Threads:
    """``jobs`` threads of this process, for tasks whose work releases the GIL (the compiled
    basin kernel, ``model.compiled``): no process start, nothing pickled. Tasks are
    submitted lazily, at most ``AHEAD`` per thread past the next result to yield. Left by an
    exception (an interrupt, a failing task), the tasks not yet started are cancelled and
    the ones under way (a thread cannot be stopped) are waited for: at most one task each."""

    def __init__(self, jobs: int) -> None:
        if jobs < 1:
            raise ValueError("jobs must be >= 1")
        self.workers = jobs
        self._pool: concurrent.futures.ThreadPoolExecutor | None = None

    def __enter__(self) -> "Threads":
        self._pool = concurrent.futures.ThreadPoolExecutor(self.workers,
                                                           thread_name_prefix="bounce")
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=exc_type is not None)
            self._pool = None

    def map(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[Any]:
        """Yield ``fn(task)`` in task order; a failing task's exception is raised here."""
        if self._pool is None:
            raise RuntimeError("Threads.map outside its with block")
        pending = iter(tasks)
        futures: deque[concurrent.futures.Future] = deque()
        try:
            while True:
                while len(futures) < AHEAD * self.workers:
                    task = next(pending, _DONE)
                    if task is _DONE:
                        break
                    futures.append(self._pool.submit(fn, task))
                if not futures:
                    return
                yield result_of(futures.popleft())
        finally:
            for future in futures:
                future.cancel()


_DONE = object()

#: how often ``result_of`` looks at a thread's future while it waits for it (s)
POLL_S = 0.005


def result_of(future: concurrent.futures.Future) -> Any:
    """``future.result()`` of a thread's task, waited for where an interrupt is safe.

    ``Future.result`` waits inside the future's lock, and the exception an interrupt raises
    there (``runtime.interrupts``: Ctrl-C) could leave the lock half released: "cannot
    release un-acquired lock" then replaced the interrupt (a traceback and exit 1 instead of
    130; seen once in a sweep's Ctrl-C test). Here the wait is a sleep, and the future's
    lock is only taken with signals held (``deferred``), which raises a signal that came
    meanwhile at its end. In any other thread (``meanwhile``'s driver) no signal handler
    runs, and holding signals there would take the main thread's interrupt away from it:
    ``Future.result`` as it is."""
    if threading.current_thread() is not threading.main_thread():
        return future.result()
    while True:
        with deferred():
            if future.done():
                break
        time.sleep(POLL_S)
    with deferred():
        return future.result()


class _Worker:
    """One worker process and the two ends of its pipes."""

    def __init__(self) -> None:
        # the workers import what this process can (as multiprocessing's spawn does)
        # (the folder holding the package: this file is bounce_cli/runtime/parallel.py)
        package_root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        python_path = os.pathsep.join(dict.fromkeys(
            p for p in (package_root, *sys.path) if p and os.path.isdir(p)
        ))
        self.process = subprocess.Popen(
            [sys.executable, "-m", "bounce_cli.runtime.parallel", str(os.getpid())],
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
#: the Dask client's timeout to connect to a scheduler, s
CONNECT_TIMEOUT_S = 10.0
#: seconds beyond the Dask client's own timeout that bounce waits for a scheduler's answer
CONNECT_GRACE_S = 5.0


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


class DaskCluster:
    """The tasks on an existing Dask distributed cluster (``dask scheduler`` / ``dask
    worker``, dask-jobqueue, a ``LocalCluster``) reached at ``address``
    (``tcp://host:8786``) or through a ``distributed.Client`` passed as ``client``.

    ``workers`` is the cluster's number of worker threads when entered. ``map`` submits at
    most AHEAD tasks per worker past the next result it yields (memory stays bounded on a
    long sweep) and yields the results in task order; a task that raises is a
    :class:`WorkerError` with its traceback. A task on a worker that dies is rerun by Dask
    elsewhere (tasks are pure). Leaving the ``with`` block by an exception (an interrupt)
    cancels every submitted task; the client this class opened is closed either way (the
    cluster itself is the user's and stays up)."""

    def __init__(self, address: str | None = None, *, client: Any = None,
                 timeout_s: float | None = None) -> None:
        if (address is None) == (client is None):
            raise ValueError("give a scheduler address or a client")
        self.address = address
        self.timeout_s = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
        self._client = client
        self._owns_client = client is None
        self._futures: deque[Any] = deque()
        self.workers = 1

    def __enter__(self) -> "DaskCluster":
        if self._client is None:
            try:
                from distributed import Client
            except ImportError:
                raise ClusterError(
                    "--scheduler needs Dask's distributed package: "
                    "pip install 'bounce-cli[cluster]'") from None
            self._check_reachable()
            self._client = self._connect(Client)
        threads = self._client.nthreads()
        self.workers = max(1, sum(threads.values()))
        return self

    def _connect(self, client_class: Any) -> Any:
        """A client of the scheduler, made in a helper thread that this one waits for at most
        ``timeout_s`` + CONNECT_GRACE_S, interruptibly: a port that accepts connections but is
        not a Dask scheduler can keep ``Client`` waiting far beyond its timeout (a silent
        service) or make it fail in odd ways (an HTTP server's reply read as a frame length:
        a MemoryError). Either is one ClusterError; a client made after it was given up is
        closed by the helper thread."""
        made: dict[str, Any] = {}
        done = threading.Event()

        def connect() -> None:
            try:
                client = client_class(self.address, timeout=self.timeout_s,
                                      set_as_default=False)
            except BaseException as exc:  # handed to the waiting thread
                made["error"] = exc
            else:
                with lock:
                    if made.get("abandoned"):
                        client.close()
                    else:
                        made["client"] = client
            finally:
                done.set()

        lock = threading.Lock()
        threading.Thread(target=connect, name="bounce-dask-connect", daemon=True).start()
        try:
            finished = done.wait(self.timeout_s + CONNECT_GRACE_S)  # a signal interrupts it
        except BaseException:
            with lock:
                made["abandoned"] = True
                client = made.pop("client", None)
            if client is not None:
                client.close()
            raise
        with lock:
            if "client" in made:
                return made["client"]
            made["abandoned"] = True
        error = made.get("error")
        if not finished:
            reason = (f"no answer as a Dask scheduler within "
                      f"{self.timeout_s + CONNECT_GRACE_S:g} s")
        elif isinstance(error, (OSError, TimeoutError, ValueError)):
            reason = " ".join(str(error).split()) or type(error).__name__
        else:
            reason = (f"a service answers there, but not as a Dask scheduler "
                      f"({type(error).__name__} while reading its reply)")
        raise ClusterError(f"--scheduler {self.address}: cannot connect: {reason}") from None

    def _check_reachable(self) -> None:
        """A quick TCP connect to a ``tcp://host:port`` address: a refused connection or an
        unknown host is one clear error at once, not after the client's timeout."""
        import socket
        from urllib.parse import urlsplit

        assert self.address is not None
        try:
            parts = urlsplit(self.address if "://" in self.address
                             else f"tcp://{self.address}")
            host, port = parts.hostname, parts.port
        except ValueError:
            host = port = None
        if parts.scheme != "tcp" or not host or not port:
            return  # another protocol (tls://, inproc://): the client says what is wrong
        try:
            socket.create_connection((host, port), timeout=self.timeout_s).close()
        except OSError as exc:
            reason = exc.strerror or str(exc) or type(exc).__name__
            raise ClusterError(f"--scheduler {self.address}: cannot connect: "
                               f"{reason}") from None

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is not None and self._futures:
                self._client.cancel(list(self._futures), force=True)
        finally:
            self._futures = deque()
            if self._owns_client and self._client is not None:
                self._client.close()
                self._client = None

    def map(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[Any]:
        if self._client is None:
            raise RuntimeError("use DaskCluster as a context manager")
        from uuid import uuid4

        run = uuid4().hex
        pending: deque[Any] = deque()
        self._futures = pending  # cancelled if the block is left by an exception
        submitted = 0
        tasks = iter(tasks)
        exhausted = False
        while True:
            while not exhausted and len(pending) < AHEAD * self.workers:
                try:
                    task = next(tasks)
                except StopIteration:
                    exhausted = True
                    break
                future = self._client.submit(fn, task, key=f"bounce-{run}-{submitted}",
                                             pure=False)
                submitted += 1
                pending.append(future)
            if not pending:
                return
            future = pending.popleft()
            try:
                result = future.result()
            except Exception as exc:  # the task raised on a worker (or was lost for good)
                detail = "".join(traceback.format_exception(type(exc), exc,
                                                            exc.__traceback__))
                raise WorkerError(f"a task failed on the Dask cluster:\n{detail}") from None
            yield result


def meanwhile(work: Callable[[], Any], other: Callable[[], Any]) -> Any:
    """``work()`` in a thread of its own while this thread runs ``other()``; returns what
    ``work`` returned (or raises what it raised). For work that spends its time outside the
    GIL (the compiled kernel in ``Threads``): ``other`` then costs no wall time on a machine
    with a core to spare. An interrupt in this thread goes on at once; the caller's executor,
    left by it, cancels what ``work`` has not started."""
    pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="bounce-driver")
    future = pool.submit(work)
    try:
        other()
        return result_of(future)
    finally:
        # not waiting when left by an exception: the caller's executor, left next, cancels
        # the tasks ``work`` is waiting for, and ``work`` ends with them
        pool.shutdown(wait=future.done(), cancel_futures=True)


def executor(jobs: int, scheduler: str | None = None, *,
             threads: bool = False) -> InProcess | Threads | LocalPool | DaskCluster:
    """The executor for ``jobs`` local workers (in this process for 1, else a pool of
    processes, or of threads with ``threads`` for work that releases the GIL), or the Dask
    cluster at ``scheduler`` (its own workers; ``jobs`` is then ignored)."""
    if scheduler is not None:
        return DaskCluster(scheduler)
    if jobs <= 1:
        return InProcess()
    return Threads(jobs) if threads else LocalPool(jobs)


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
    import gc
    import signal

    from .interrupts import GC_THRESHOLDS
    from .process import keep_freed_memory

    keep_freed_memory()  # the environment's settings came with the parent's (tune)

    gc.set_threshold(*GC_THRESHOLDS)
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
            # every result is sent and a worker writes nothing else: exit at once (the
            # interpreter's orderly shutdown of numpy, matplotlib and numba took about 0.6 s,
            # which the parent waited for at the end of every parallel run)
            sys.stderr.flush()
            os._exit(0)
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
