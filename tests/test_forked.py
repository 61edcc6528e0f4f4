"""runtime/forked.py: a call in a forked child, its result or its exception back here."""

from __future__ import annotations

import os
import sys

import pytest

from bounce_cli.runtime.forked import ForkedCall, ForkedLanes, LaneDied, split_work

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork: Linux")


def test_the_child_runs_the_call_and_returns_its_result():
    parent = os.getpid()
    call = ForkedCall(lambda: (os.getpid(), os.getppid(), [1.5, "x"])).start()
    pid, ppid, value = call.wait()
    assert pid != parent and ppid == parent and value == [1.5, "x"]
    assert call.pid == 0  # reaped


def test_an_exception_in_the_child_is_raised_here_as_itself():
    def fails():
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left") as info:
        ForkedCall(fails).start().wait()
    assert info.value.errno == 28


def test_a_child_that_dies_is_an_error_not_a_hang():
    with pytest.raises(OSError, match="died"):
        ForkedCall(lambda: os._exit(3), "the test's child").start().wait()


def test_split_work_runs_the_later_half_elsewhere_and_keeps_the_order():
    def run(items):
        return {item: (item * item, os.getpid()) for item in items}

    out = split_work(list(range(5)), run)
    assert list(out) == [0, 1, 2, 3, 4]
    assert [v for v, _ in out.values()] == [0, 1, 4, 9, 16]
    pids = {item: pid for item, (_, pid) in out.items()}
    assert pids[0] == pids[1] == os.getpid() and pids[2] == pids[4] != os.getpid()
    assert split_work([7], run)[7][1] == os.getpid()  # one item: no child


def test_a_signal_during_the_fork_stops_the_child_before_start_raises(tmp_path, monkeypatch):
    """A signal held over the fork is raised as the fork's block ends, before the caller has
    the child: start() kills it, so that it cannot go on to write a file the caller's
    clean-up has already removed (an interrupted `basin --force` left a staged CSV so)."""
    import contextlib
    import time

    from bounce_cli.runtime import forked
    from bounce_cli.runtime.interrupts import Interrupted

    @contextlib.contextmanager
    def signal_at_the_end():
        yield
        raise Interrupted(2)

    monkeypatch.setattr(forked, "deferred", signal_at_the_end)
    late = tmp_path / "late"

    def writes_later():
        time.sleep(0.5)
        late.write_text("the child outlived start()")

    call = ForkedCall(writes_later)
    with pytest.raises(Interrupted):
        call.start()
    assert call.pid == 0  # killed and reaped
    time.sleep(0.8)
    assert not late.exists()


# -- ForkedLanes: tasks taken from a shared queue by forked lanes, results in task order ----
def _square_where(i: int) -> tuple[int, int]:
    import time

    time.sleep(0.05)  # long enough for both lanes to take tasks
    return i * i, os.getpid()


def _no_children_left() -> bool:
    try:
        os.waitpid(-1, os.WNOHANG)
    except ChildProcessError:
        return True
    return False


def test_lanes_yield_every_result_in_task_order_from_two_other_processes():
    with ForkedLanes(list(range(8)), _square_where, 2) as results:
        out = list(results)
    assert [square for square, _ in out] == [i * i for i in range(8)]
    pids = {pid for _, pid in out}
    assert len(pids) == 2 and os.getpid() not in pids  # both lanes worked, none here
    assert _no_children_left()


def test_one_lane_or_one_task_runs_here_in_order():
    for tasks, lanes in (([3, 4], 1), ([5], 2)):
        with ForkedLanes(tasks, _square_where, lanes) as results:
            out = list(results)
        assert [s for s, _ in out] == [t * t for t in tasks]
        assert {pid for _, pid in out} == {os.getpid()}


def test_a_task_s_exception_comes_in_its_turn_and_the_lanes_are_reaped():
    def run(i):
        if i == 2:
            raise OSError(28, "No space left on device")
        return _square_where(i)[0]

    seen = []
    with pytest.raises(OSError, match="No space left") as info:
        with ForkedLanes(list(range(6)), run, 2) as results:
            for value in results:
                seen.append(value)
    assert seen == [0, 1] and info.value.errno == 28
    assert _no_children_left()


def test_a_lane_that_dies_names_its_task():
    def run(i):
        if i == 1:
            os._exit(3)
        return i

    with pytest.raises(LaneDied, match="the process running number 1 exited with status 3"):
        with ForkedLanes([0, 1, 2], run, 2, describe=lambda task: f"number {task}") as results:
            list(results)
    assert _no_children_left()


def test_a_task_s_exception_carries_the_lane_s_traceback():
    """The exception comes back without its traceback (it does not pickle): its text is the
    cause, so that a bug in a lane can be found."""
    def run(i):
        if i == 1:
            return failing_deep_inside(i)
        return i

    with pytest.raises(ZeroDivisionError) as info:
        with ForkedLanes([0, 1, 2], run, 2) as results:
            list(results)
    cause = str(info.value.__cause__)
    assert "in the lane that ran it" in cause and "failing_deep_inside" in cause


def failing_deep_inside(i):
    return i / 0


def test_leaving_early_stops_a_running_lane_whose_clean_up_runs(tmp_path):
    """SIGTERM reaches the lane as bounce's Interrupted: its ``finally`` (a run's staged
    files removed) runs before it exits, well within LANE_GRACE_S."""
    import time

    def run(i):
        if i == 0:
            return "quick"
        try:
            time.sleep(30)
        finally:
            (tmp_path / f"cleaned-{i}").write_text("yes")
        return "never"

    started = time.monotonic()
    with ForkedLanes([0, 1, 2], run, 2) as results:
        assert next(results) == "quick"
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not _lane_sleeping():
            time.sleep(0.02)
    took = time.monotonic() - started
    assert _no_children_left()
    assert took < 5, f"{took:.1f} s to stop the lanes"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cleaned-1", "cleaned-2"]


def _lane_sleeping() -> bool:
    """Both lanes are in their tasks' sleep (state S with this process as parent)."""
    import glob

    lanes = []
    for stat in glob.glob("/proc/[0-9]*/stat"):
        try:
            text = open(stat).read()
        except OSError:
            continue
        fields = text[text.rindex(")") + 2:].split()
        if int(fields[1]) == os.getpid():
            lanes.append(fields[0])
    return len(lanes) == 2 and all(state == "S" for state in lanes)
