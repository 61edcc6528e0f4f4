"""The executor (bounce_cli.runtime.parallel): ordered results, whatever the executor; failures and
dead workers are errors, not hangs; no worker outlives its ``with`` block."""

from __future__ import annotations

import concurrent.futures
import os
import signal
import time

import numpy as np
import pytest

from bounce_cli.runtime import parallel


def slow_square(x):
    """A task whose duration varies, so that results come back out of order."""
    time.sleep(0.02 * (x % 3))
    return x * x


def fail_on_three(x):
    if x == 3:
        raise ValueError("three is not allowed")
    return x


def worker_pid(_):
    return os.getpid()


def kill_myself(_):
    os.kill(os.getpid(), signal.SIGKILL)


@pytest.mark.slow
def test_results_in_task_order_for_every_executor():
    expected = [x * x for x in range(12)]
    assert list(parallel.InProcess().map(slow_square, range(12))) == expected
    for jobs in (1, 2, 3):
        for threads in (False, True):
            with parallel.executor(jobs, threads=threads) as executor:
                assert list(executor.map(slow_square, iter(range(12)))) == expected


def test_executor_choice():
    assert isinstance(parallel.executor(1), parallel.InProcess)
    pool = parallel.executor(2)
    assert isinstance(pool, parallel.LocalPool) and pool.workers == 2
    with pytest.raises(ValueError):
        parallel.LocalPool(0)
    threads = parallel.executor(2, threads=True)
    assert isinstance(threads, parallel.Threads) and threads.workers == 2
    assert isinstance(parallel.executor(1, threads=True), parallel.InProcess)


def test_workers_are_separate_processes_and_gone_after_the_block():
    with parallel.LocalPool(2) as pool:
        pids = set(pool.map(worker_pid, range(8)))
        processes = [w.process for w in pool._pool]
    assert os.getpid() not in pids and 1 <= len(pids) <= 2
    assert all(p.returncode is not None for p in processes)


def test_a_failing_task_raises_with_the_workers_traceback_and_stops_the_pool():
    with pytest.raises(parallel.WorkerError, match="three is not allowed") as info:
        with parallel.LocalPool(2) as pool:
            processes = []
            for _ in pool.map(fail_on_three, range(6)):
                processes = processes or [w.process for w in pool._pool]
    assert "ValueError" in str(info.value)
    assert all(p.returncode is not None for p in processes)


def test_a_dead_worker_is_an_error_not_a_hang():
    start = time.monotonic()
    with pytest.raises(parallel.WorkerError, match="killed by signal 9"):
        with parallel.LocalPool(2) as pool:
            list(pool.map(kill_myself, range(4)))
    assert time.monotonic() - start < 10


@pytest.mark.slow
@pytest.mark.parametrize("pool", [parallel.LocalPool, parallel.Threads])
def test_the_engine_classifies_through_any_executor_identically(paper_params, pool):
    np = pytest.importorskip("numpy")
    from bounce_cli.analysis.classify import classify_grid

    theta, v = np.meshgrid(np.linspace(0, 2 * np.pi, 30), np.linspace(0, 10, 20))
    reference = classify_grid(theta, v, paper_params)  # the built-in map
    with pool(2) as executor:
        pooled = classify_grid(theta, v, paper_params, map=executor.map, workers=2,
                               tile_points=64)
    np.testing.assert_array_equal(pooled.outcome, reference.outcome)
    np.testing.assert_array_equal(pooled.iterations, reference.iterations)


def test_threads_raise_a_failing_tasks_error_and_cancel_the_rest():
    started = []

    def record_then_fail(x):
        started.append(x)
        return fail_on_three(x)

    with pytest.raises(ValueError, match="three is not allowed"):
        with parallel.Threads(2) as executor:
            list(executor.map(record_then_fail, range(1000)))
    # tasks are submitted lazily (AHEAD per thread) and the unstarted ones cancelled
    assert len(started) <= 3 + 2 * parallel.AHEAD + 2 < 1000


def slow_first(x):
    time.sleep(0.5 if x == 0 else 0.0)
    return x


@pytest.mark.slow
def test_results_held_for_a_slow_first_task_are_bounded():
    """Tasks are read lazily and at most AHEAD per worker run past the next result, so a slow
    task does not make the pool read (and hold) the whole task list."""
    read = []

    def tasks():
        for x in range(100):
            read.append(x)
            yield x

    for pool in (parallel.LocalPool(2), parallel.Threads(2)):
        read.clear()
        with pool:
            results = pool.map(slow_first, tasks())
            assert next(results) == 0
            assert len(read) <= 2 * parallel.AHEAD + 1 < 100
            assert list(results) == list(range(1, 100))


def test_an_interrupt_while_waiting_for_threads_is_the_interrupt():
    """Ctrl-C while this thread waits for a thread's task (``Threads.map``): the interrupt
    itself, at any moment of the wait, and the futures' locks left whole (a second map
    works); was, once, 'cannot release un-acquired lock' from inside Future.result."""
    import threading

    from bounce_cli.runtime import interrupts

    previous = {s: signal.getsignal(s) for s in interrupts.SIGNALS}
    try:
        for delay in np.linspace(0.001, 0.06, 12):
            interrupts.install()
            timer = threading.Timer(delay, os.kill, (os.getpid(), signal.SIGINT))
            with pytest.raises(interrupts.Interrupted):
                with parallel.Threads(2) as threads:
                    timer.start()
                    list(threads.map(time.sleep, [0.05] * 8))
            timer.join()
        with parallel.Threads(2) as threads:
            assert list(threads.map(slow_square, range(6))) == [x * x for x in range(6)]
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def test_result_of_returns_or_raises_what_the_task_did():
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        assert parallel.result_of(pool.submit(slow_square, 4)) == 16
        with pytest.raises(ValueError, match="three"):
            parallel.result_of(pool.submit(fail_on_three, 3))


def test_a_thread_other_than_the_main_one_never_holds_the_signals(monkeypatch):
    """``meanwhile``'s driver thread waits for ``Threads.map`` too: holding signals there
    (``deferred``) would take the main thread's interrupt away from it (the handler, seeing
    signals held, leaves it to the holder: the driver raised it in itself, and the run
    crashed at exit). Only the main thread holds them."""
    import contextlib
    import threading

    holders: list[str] = []
    real = parallel.deferred

    @contextlib.contextmanager
    def recording():
        holders.append(threading.current_thread().name)
        with real():
            yield

    monkeypatch.setattr(parallel, "deferred", recording)

    def drive():
        with parallel.Threads(2) as threads:
            return list(threads.map(slow_square, range(6)))

    assert parallel.meanwhile(drive, lambda: time.sleep(0.05)) == [x * x for x in range(6)]
    assert holders and set(holders) == {threading.main_thread().name}
