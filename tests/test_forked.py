"""runtime/forked.py: a call in a forked child, its result or its exception back here."""

from __future__ import annotations

import os
import sys

import pytest

from bounce_cli.runtime.forked import ForkedCall, split_work

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
