"""parallel.DaskCluster against a LocalCluster the test starts: ordered results, a failing task
is a WorkerError with its traceback, an exception in the caller cancels the submitted tasks,
a bad address or a missing package is one clear error."""

from __future__ import annotations

import os
import time

import pytest

from bounce_cli.runtime import parallel

distributed = pytest.importorskip("distributed")


def slow_square(x):
    time.sleep(0.01 * (x % 3))
    return x * x


def fail_on_three(x):
    if x == 3:
        raise ValueError("three is not allowed")
    return x


def sleep_unless_zero(x):
    if x:
        time.sleep(2)
    return x


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as local:
        yield local


@pytest.mark.slow
def test_results_in_task_order_and_workers_counted(cluster):
    with parallel.executor(1, scheduler=cluster.scheduler_address) as executor:
        assert isinstance(executor, parallel.DaskCluster)
        assert executor.workers == 2
        assert list(executor.map(slow_square, iter(range(40)))) == [x * x for x in range(40)]
        # at most AHEAD tasks per worker are submitted past the result being waited for
        results = executor.map(slow_square, range(100))
        next(results)
        assert len(executor._futures) <= parallel.AHEAD * executor.workers
        results.close()


def test_a_failing_task_is_a_worker_error_with_its_traceback(cluster):
    with pytest.raises(parallel.WorkerError, match="three is not allowed") as info:
        with parallel.DaskCluster(cluster.scheduler_address) as executor:
            list(executor.map(fail_on_three, range(6)))
    assert "ValueError" in str(info.value)


def test_leaving_by_an_exception_cancels_what_was_submitted(cluster):
    """As an interrupt does: the caller raises while tasks are under way on the cluster."""
    with distributed.Client(cluster.scheduler_address, set_as_default=False) as client:
        outstanding = []
        with pytest.raises(RuntimeError, match="stop"):
            with parallel.DaskCluster(client=client) as executor:
                for result in executor.map(sleep_unless_zero, range(5)):
                    assert result == 0
                    outstanding = list(executor._futures)
                    raise RuntimeError("stop")
        assert len(outstanding) == 4
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(f.status != "cancelled" for f in outstanding):
            time.sleep(0.05)
        assert [f.status for f in outstanding] == ["cancelled"] * 4
        assert client.status == "running"  # a client passed in is the caller's to close


def die_once(args):
    """Kill this worker process the first time task 2 runs (a node lost mid-task)."""
    x, marker = args
    if x == 2 and not os.path.exists(marker):
        open(marker, "w").close()
        os._exit(1)
    return x * 10


@pytest.mark.slow
def test_a_task_on_a_lost_worker_is_rerun_and_nothing_is_lost(cluster, tmp_path):
    marker = str(tmp_path / "died")
    with parallel.DaskCluster(cluster.scheduler_address) as executor:
        results = list(executor.map(die_once, [(x, marker) for x in range(6)]))
    assert os.path.exists(marker)  # a worker did die
    assert results == [0, 10, 20, 30, 40, 50]


def test_a_bad_address_is_a_cluster_error():
    start = time.monotonic()
    with pytest.raises(parallel.ClusterError, match="cannot connect"):
        with parallel.DaskCluster("tcp://127.0.0.1:9", timeout_s=1):
            pass
    assert time.monotonic() - start < 15


def test_without_the_extra_installed_the_error_names_it(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    with pytest.raises(parallel.ClusterError, match=r"bounce-cli\[cluster\]"):
        with parallel.executor(2, scheduler="tcp://127.0.0.1:8786"):
            pass
