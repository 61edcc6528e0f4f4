"""Interrupts of a real ``bounce basin --jobs 2`` process, as a terminal (SIGINT to the whole
process group), ``kill`` (SIGTERM to the process) or a crash (SIGKILL) sends them, at several
moments of a run: imports, pool start-up, computing, writing the results.

After each: exit 130 / 143 within two seconds, one line ``bounce: interrupted`` and no
traceback (from the main process or a worker), the previous results byte-identical, no
temporary file, no output folder the run made, and no process of the run left alive.
Processes are found in /proc (Linux): every descendant of the run, recorded while it runs.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(),
                                reason="needs /proc (Linux)")

#: 490,000 points: above basin.POOL_MIN_POINTS (a pool starts), about a second of classifying
#: on two cores and a second of writing
BIG_GRID = ["--set", "grid.theta0_deg.num=700", "--set", "grid.v0_m_s.num=700"]
SMALL_GRID = ["--set", "grid.theta0_deg.num=20", "--set", "grid.v0_m_s.num=10"]


def bounce(*args: str) -> list[str]:
    return [sys.executable, "-m", "bounce_cli", *args]


#: the numpy kernel, whose --jobs 2 is a pool of worker processes (the compiled kernel runs in
#: threads of the main process: ``test_interrupt_while_threads_classify``)
PROCESS_POOL = {**os.environ, "BOUNCE_KERNEL": "numpy"}


#: the worker processes' command line names this module
WORKER_MODULE = "bounce_cli.runtime.parallel"


def command_line(pid: int) -> str:
    """The process's command line ("" when it has gone)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(
            errors="replace")
    except OSError:
        return ""


def stat_fields(pid: int) -> list[str] | None:
    """/proc/<pid>/stat fields after the command name (state is [0], ppid [1],
    start time [19]); None when there is no such process."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return text[text.rindex(")") + 2:].split()


class ProcessWatch:
    """Records every descendant of ``root`` (pid, start time, command line) while it runs."""

    def __init__(self, root: int) -> None:
        self.root = root
        self.seen: dict[int, tuple[str, str]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        while not self._stop.is_set():
            family = {self.root, *self.seen}
            for entry in os.listdir("/proc"):
                if not entry.isdigit():
                    continue
                pid = int(entry)
                fields = stat_fields(pid)
                if fields and int(fields[1]) in family and pid not in self.seen:
                    self.seen[pid] = (fields[19], command_line(pid))
            # a child seen between its fork and its exec showed its parent's command line:
            # read it again while it lives (a worker may have ended before workers() asks)
            for pid, (start, cmd) in list(self.seen.items()):
                if WORKER_MODULE not in cmd and (fields := stat_fields(pid)) \
                        and fields[19] == start:
                    self.seen[pid] = (start, command_line(pid) or cmd)
            time.sleep(0.01)

    def workers(self) -> list[int]:
        """Recorded processes that ran the worker module."""
        return [pid for pid, (_, cmd) in list(self.seen.items()) if WORKER_MODULE in cmd]

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def alive(self) -> list[str]:
        """Recorded processes that still exist (same pid and start time), zombies aside."""
        left = []
        for pid, (start, cmd) in list(self.seen.items()):  # the watch may be adding
            fields = stat_fields(pid)
            if fields and fields[19] == start and fields[0] != "Z":
                left.append(f"{pid} ({fields[0]}): {cmd}")
        return left


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


#: how long the workers may outlive a SIGKILLed main process (s): they end within
#: milliseconds on an idle machine; 30 s holds with every core busy many times over
ORPHAN_DEADLINE_S = 30.0


#: an interrupted run ends within this (s) on an idle machine
STOP_DEADLINE_S = 2.0


def stop_deadline() -> float:
    """STOP_DEADLINE_S stretched by how many runnable processes share each core (the 1-minute
    load average per core, at least 1): on a 2-core machine at load 19 a run stopped in 4 s
    and failed 2 s; a run that does not stop at all still fails."""
    return STOP_DEADLINE_S * max(1.0, os.getloadavg()[0] / (os.cpu_count() or 1))


def wait_for(condition, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.005)


def writing_started(out: Path):
    """Any result file staged under its temporary name: the CSV is written in a fraction of a
    second, the figures take longer, so a loaded machine's polling still sees one of them."""
    return lambda: any(not p.name.startswith("..write-test") for p in out.glob(".*.tmp"))


@pytest.fixture(scope="module")
def previous_run(tmp_path_factory) -> Path:
    """A finished small basin run: the results an interrupted run must leave alone."""
    out = tmp_path_factory.mktemp("previous") / "basin"
    subprocess.run(bounce("basin", *SMALL_GRID, "--quiet", "--jobs", "1", "--out", str(out)),
                   check=True, capture_output=True)
    return out


def send(proc: subprocess.Popen, signum: int) -> None:
    """SIGINT to the process group, as a terminal's Ctrl-C; others to the process, as kill."""
    if signum == signal.SIGINT:
        os.killpg(proc.pid, signum)
    else:
        proc.send_signal(signum)


def interrupt(proc: subprocess.Popen, signum: int, moment: str) -> tuple[str, float]:
    """Send the signal; (stderr, seconds until the process ended)."""
    sent = time.monotonic()
    send(proc, signum)
    try:
        _, err = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        raise AssertionError(f"still running 10 s after {signum!r} at {moment}") from None
    return err, time.monotonic() - sent


#: a worker's CPU time (s) past which it is classifying: its imports take 0.1-0.2 s; its share
#: of BIG_GRID 1-3.5 s on the machines seen
WORKING_CPU_S = 0.3


def cpu_seconds(pid: int) -> float:
    """The process's user + system CPU time so far (s); 0 when it has gone."""
    fields = stat_fields(pid)
    if fields is None:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def catches_sigterm(pid: int) -> bool:
    """Whether the process has installed bounce's handlers (its first act; Python alone
    leaves SIGTERM at the default action)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    caught = int(status.split("SigCgt:")[1].split()[0], 16)
    return bool(caught >> (signal.SIGTERM - 1) & 1)


MOMENTS = {
    # the handlers are in place, the imports (typer, numpy, pandas ...) under way
    "imports": lambda proc, watch, out: wait_for(lambda: catches_sigterm(proc.pid), 10,
                                                 "the signal handlers"),
    # the first worker process exists: the pool is starting
    "pool start": lambda proc, watch, out: wait_for(watch.workers, 20, "a worker process"),
    # both workers have been classifying for a while: each has used WORKING_CPU_S of CPU
    # time (a fixed sleep after they appeared missed the moment on a fast machine: the run
    # had finished, and the signal reached a zombie)
    "computing": lambda proc, watch, out: (
        wait_for(lambda: len(watch.workers()) == 2, 20, "two workers"),
        wait_for(lambda: all(cpu_seconds(pid) >= WORKING_CPU_S for pid in watch.workers()),
                 20, "the workers' classifying")),
    # the first results file is being written under its temporary name
    "writing": lambda proc, watch, out: wait_for(writing_started(out), 40, "writing"),
}


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("moment", list(MOMENTS))
def test_interrupt_stops_cleanly(tmp_path, previous_run, moment, signum):
    """SIGINT runs over a previous run's results (--force), SIGTERM into folders it must
    create: between them, each moment checks both."""
    existing = tmp_path / "basin"
    subprocess.run(["cp", "-a", str(previous_run), str(existing)], check=True)
    before = snapshot(existing)
    out = existing if signum == signal.SIGINT else tmp_path / "new" / "deeper"
    proc = subprocess.Popen(
        bounce("basin", *BIG_GRID, "--jobs", "2", "--force", "--out", str(out)),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,  # its own process group, as a shell runs a command
        env=PROCESS_POOL,
    )
    watch = ProcessWatch(proc.pid)
    try:
        MOMENTS[moment](proc, watch, out)
        assert proc.poll() is None, f"finished before the interrupt: {moment} was missed"
    except AssertionError:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        raise
    err, took = interrupt(proc, signum, moment)
    time.sleep(0.05)
    watch.stop()
    assert proc.returncode == 128 + signum, err
    assert took < stop_deadline(), f"took {took:.2f} s to stop (load {os.getloadavg()[0]:.1f})"
    assert "Traceback" not in err and "Error" not in err, err
    progress = "basin: classifying: "  # plain progress lines, on a slow machine
    assert [line for line in err.splitlines()
            if line.strip() and not line.startswith(progress)] == ["bounce: interrupted"]
    assert watch.alive() == [], "processes left running"
    if moment != "imports":
        assert watch.workers(), "the pool never started: the moment was missed"
    assert snapshot(existing) == before, "the previous results changed"
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")], "temporary files"
    assert not (tmp_path / "new").exists(), "the run left the output folder it created"


@pytest.mark.slow
def test_sigkill_of_the_main_process_takes_the_workers_down(tmp_path):
    """No clean-up can run after SIGKILL: the workers must still not outlive the run."""
    proc = subprocess.Popen(
        bounce("basin", *BIG_GRID, "--jobs", "2", "--out", str(tmp_path / "basin")),
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
        env=PROCESS_POOL)
    watch = ProcessWatch(proc.pid)
    wait_for(lambda: len(watch.workers()) == 2, 20, "two workers")
    proc.kill()
    proc.wait()
    # the workers notice their parent's death and end: wait for that itself (0.3 s were too
    # short on a loaded machine), with a deadline no scheduler delay reaches
    try:
        wait_for(lambda: watch.alive() == [], ORPHAN_DEADLINE_S, "the workers to end")
    finally:
        watch.stop()
    assert watch.alive() == []


def thread_count(pid: int) -> int:
    try:
        return len(os.listdir(f"/proc/{pid}/task"))
    except OSError:
        return 0


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupt_while_threads_classify(tmp_path, previous_run, signum):
    """The compiled kernel classifies in two threads of the main process (which cannot be
    stopped mid-tile): an interrupt still ends the run within two seconds, with the one line,
    the previous results intact and nothing staged left behind."""
    pytest.importorskip("numba")
    existing = tmp_path / "basin"
    subprocess.run(["cp", "-a", str(previous_run), str(existing)], check=True)
    before = snapshot(existing)
    grid = ["--set", "grid.theta0_deg.num=2000", "--set", "grid.v0_m_s.num=1500"]
    proc = subprocess.Popen(
        bounce("basin", *grid, "--jobs", "2", "--force", "--out", str(existing)),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        env={**os.environ, "BOUNCE_KERNEL": "auto"})
    try:  # the main thread and two workers (numba starts none of its own without parallel)
        wait_for(lambda: thread_count(proc.pid) >= 3, 30, "the classifying threads")
        time.sleep(0.3)
    except AssertionError:
        os.killpg(proc.pid, signal.SIGKILL)
        raise
    assert proc.poll() is None, "finished before the interrupt: the moment was missed"
    err, took = interrupt(proc, signum, "computing in threads")
    assert proc.returncode == 128 + signum, err
    assert took < stop_deadline(), f"took {took:.2f} s to stop (load {os.getloadavg()[0]:.1f})"
    assert [line for line in err.splitlines() if line.strip()
            and not line.startswith("basin: classifying: ")] == ["bounce: interrupted"], err
    assert snapshot(existing) == before, "the previous results changed"
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")], "temporary files"


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupt_while_reproduce_runs_two_experiments_side_by_side(tmp_path, signum):
    """`bounce reproduce --jobs 2` runs its experiments in two forked lanes: a terminal's
    Ctrl-C reaches all three processes, ``kill`` only the parent, which passes it on. Either
    way: the one line, 130 / 143 within the deadline, no process left, nothing staged left,
    and none of the folders the run made."""
    out = tmp_path / "new" / "results"
    proc = subprocess.Popen(
        bounce("reproduce", "bifurcation", "continuation", "control", "--jobs", "2",
               "--out", str(out)),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    watch = ProcessWatch(proc.pid)
    lanes = lambda: [pid for pid in list(watch.seen) if stat_fields(pid)]  # noqa: E731
    try:  # both lanes computing (their imports take about half a second of CPU)
        wait_for(lambda: len(lanes()) >= 2 and all(cpu_seconds(pid) >= 1.0
                                                   for pid in lanes()), 30, "two lanes")
    except AssertionError:
        os.killpg(proc.pid, signal.SIGKILL)
        raise
    assert proc.poll() is None, "finished before the interrupt: the moment was missed"
    err, took = interrupt(proc, signum, "two lanes computing")
    time.sleep(0.05)
    watch.stop()
    assert proc.returncode == 128 + signum, err
    assert took < stop_deadline(), f"took {took:.2f} s to stop (load {os.getloadavg()[0]:.1f})"
    assert [line for line in err.splitlines() if line.strip()] == ["bounce: interrupted"], err
    assert watch.alive() == [], "processes left running"
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")], "temporary files"
    assert not (tmp_path / "new").exists(), "the run left the output folders it created"


@pytest.mark.slow
def test_a_reproduce_lane_killed_outright_is_one_line_naming_its_experiment(tmp_path):
    """SIGKILL to one lane (the out-of-memory killer): no clean-up can run in it; the run
    stops the other lane and ends with one line naming the experiment, exit 2."""
    proc = subprocess.Popen(
        bounce("reproduce", "bifurcation", "continuation", "--jobs", "2",
               "--out", str(tmp_path / "results")),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    watch = ProcessWatch(proc.pid)
    lanes = lambda: [pid for pid in list(watch.seen) if stat_fields(pid)]  # noqa: E731
    try:
        wait_for(lambda: len(lanes()) >= 2 and all(cpu_seconds(pid) >= 1.0
                                                   for pid in lanes()), 30, "two lanes")
    except AssertionError:
        os.killpg(proc.pid, signal.SIGKILL)
        raise
    os.kill(lanes()[0], signal.SIGKILL)
    try:
        _, err = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        raise AssertionError("still running 20 s after a lane was killed") from None
    watch.stop()
    assert proc.returncode == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(
        "bounce: error: reproduce: the process running experiment "), err
    assert "was killed by signal 9" in lines[0]
    assert watch.alive() == [], "processes left running"


#: a signal the moment bounce's handlers are in place (what the "imports" moment above hits
#: now and then on a busy machine): at the end of ``install`` itself, at the garbage
#: collector's settings, at the watched standard output
FIRST_STEPS = {
    "install": "import bounce_cli.runtime.interrupts as m; m.signal.signal = "
               "(lambda real: lambda s, h: (real(s, h), s == m.SIGNALS[-1] and "
               "os.kill(os.getpid(), signal.SIGTERM)))(m.signal.signal)",
    "gc": "import gc; gc.set_threshold = lambda *a: os.kill(os.getpid(), signal.SIGTERM)",
    "stdout": "import bounce_cli.cli.console as c; c.WatchedStdout = lambda s: "
              "(os.kill(os.getpid(), signal.SIGTERM), s)[1]",
}


@pytest.mark.parametrize("step", list(FIRST_STEPS))
def test_a_signal_right_after_the_handlers_are_installed_is_one_line(step):
    code = (f"import os, signal; {FIRST_STEPS[step]}\n"
            "from bounce_cli.cli.console import main\nmain()")
    done = subprocess.run([sys.executable, "-c", code, "--help"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 128 + signal.SIGTERM, done.stderr
    assert done.stderr.strip() == "bounce: interrupted", done.stderr


def test_a_signal_after_the_command_ends_the_process_without_a_traceback():
    # the command's work is done (its files written): a signal during the interpreter's exit
    # raised where nothing caught it, a traceback after a finished run
    code = ("import atexit, os, signal, time\n"
            "atexit.register(lambda: (os.kill(os.getpid(), signal.SIGINT), time.sleep(0.5)))\n"
            "from bounce_cli.cli.console import main\nmain()")
    done = subprocess.run([sys.executable, "-c", code, "--version"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == -signal.SIGINT, done.stderr
    assert "Traceback" not in done.stderr and "Interrupted" not in done.stderr, done.stderr


def _import_error_from_an_interrupt():
    """What a C extension's initialisation (matplotlib._image) raises when the signal handler
    raised inside it: ImportError('initialization failed') from the Interrupted."""
    from bounce_cli.runtime.interrupts import Interrupted

    try:
        raise Interrupted(signal.SIGINT)
    except Interrupted as exc:
        raise ImportError("initialization failed") from exc


def test_the_interrupt_behind_a_library_s_error_is_found():
    from bounce_cli.runtime.interrupts import Interrupted, interrupt_behind

    with pytest.raises(ImportError) as caught:
        _import_error_from_an_interrupt()
    behind = interrupt_behind(caught.value)
    assert isinstance(behind, Interrupted) and behind.signum == signal.SIGINT
    assert interrupt_behind(ValueError("plain")) is None
    loop = ValueError("a")
    loop.__context__ = ValueError("b")
    loop.__context__.__context__ = loop  # a cycle ends the walk
    assert interrupt_behind(loop) is None


def test_a_signal_turned_into_an_import_error_ends_the_run_as_an_interrupt(tmp_path):
    """CI once sent SIGINT while `bounce basin` imported matplotlib.figure beside its
    classification: matplotlib._image's initialisation turned the interrupt into
    'ImportError: initialization failed', and the run ended with a traceback and exit 1 (and,
    reported as an interrupt but left through the interpreter's teardown, once aborted on the
    half-made module). The console script ends it as the interrupt: the one line, 130, at
    once, and the output folder it created removed."""
    out = tmp_path / "new" / "basin"
    code = ("import sys\n"
            "from bounce_cli.experiments import basin\n"
            "from bounce_cli.runtime.interrupts import Interrupted\n"
            "def imports():\n"
            "    try:\n"
            "        raise Interrupted(2)\n"
            "    except Interrupted as exc:\n"
            "        raise ImportError('initialization failed') from exc\n"
            "basin.import_output_libraries = imports\n"
            "from bounce_cli.cli.console import main\n"
            f"sys.argv = ['bounce', 'basin', *{SMALL_GRID!r}, '--jobs', '1', '--out', "
            f"{str(out)!r}]\n"
            "main()\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 130, done.stderr
    assert done.stderr.strip() == "bounce: interrupted"
    assert not (tmp_path / "new").exists()


def test_an_interrupt_a_library_swallowed_during_imports_is_raised_again(monkeypatch):
    """A signal during an import that the importing library took for a failed import (a C
    extension interrupted as it initialises raises ImportError; some libraries fall back)
    left the run going on, deaf to every later signal: seen once as a basin that Ctrl-C did
    not stop. ``lasting_imports`` raises it again when its block ends; an import block
    without a signal, or one that came before the block, raises nothing."""
    from bounce_cli.runtime import interrupts

    monkeypatch.setattr(interrupts, "_state", {"deferring": 0, "pending": None,
                                               "raised": False, "signum": None})
    with interrupts.lasting_imports():
        pass  # nothing happened
    with pytest.raises(interrupts.Interrupted) as info:
        with interrupts.lasting_imports():
            try:
                interrupts._handler(signal.SIGTERM, None)  # the signal, mid-import
            except ImportError:
                pass
            except BaseException:  # the library's fallback took it
                pass
    assert info.value.signum == signal.SIGTERM
    with interrupts.lasting_imports():  # the run already stopping: not raised twice
        pass


@pytest.mark.slow
def test_interrupts_while_threads_classify_and_output_libraries_import_all_stop(tmp_path):
    """Many SIGINTs at moments spread over the classification, while the main thread
    imports the output libraries beside the compiled kernel's threads: every run stops
    (once, one in ten did not: the tiles waited for the import lock an interrupted import
    left held, and the interrupt itself had been taken for a failed import)."""
    pytest.importorskip("numba")
    grid = ["--set", "grid.theta0_deg.num=2000", "--set", "grid.v0_m_s.num=1500"]
    for attempt in range(10):
        out = tmp_path / f"run{attempt}"
        proc = subprocess.Popen(
            bounce("basin", *grid, "--jobs", "2", "--force", "--out", str(out)),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
            env={**os.environ, "BOUNCE_KERNEL": "auto"})
        try:
            pid = proc.pid
            wait_for(lambda: thread_count(pid) >= 3, 30, "the classifying threads")  # noqa: B023
            time.sleep(0.03 * attempt)  # from the threads' start into the imports
        except AssertionError:
            os.killpg(proc.pid, signal.SIGKILL)
            raise
        if proc.poll() is not None:
            continue
        err, took = interrupt(proc, signal.SIGINT, f"attempt {attempt}")
        assert proc.returncode == 130, err
        assert took < stop_deadline(), f"took {took:.2f} s to stop"
        assert not list(tmp_path.rglob("*.tmp")), "temporary files"
