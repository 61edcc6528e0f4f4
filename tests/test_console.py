"""cli/console.py: the console script's way out (atexit handlers run, then an immediate
exit with the command's status, except where a thread still runs) and the one command typer
builds when the command line names it."""

from __future__ import annotations

import subprocess
import sys

import pytest


def console(prelude: str, *args: str) -> subprocess.CompletedProcess:
    """The console script in a fresh interpreter, ``prelude`` run before it."""
    code = (f"import sys\n{prelude}\nsys.argv = ['bounce', *{list(args)!r}]\n"
            "from bounce_cli.cli.console import main\nmain()\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)


ATEXIT = ("import atexit\n"
          "atexit.register(lambda: print('atexit handler ran', file=sys.stderr, flush=True))")


@pytest.mark.parametrize(("args", "status"), [(("--version",), 0),
                                              (("fixed-point", "--set", "model.alpha=7"), 2),
                                              (("no-such-command",), 2)])
def test_the_atexit_handlers_run_and_the_status_is_the_command_s(args, status):
    done = console(ATEXIT, *args)
    assert done.returncode == status, done.stderr
    assert done.stderr.rstrip().endswith("atexit handler ran"), done.stderr
    assert "Traceback" not in done.stderr


def test_a_thread_still_running_is_waited_for_as_by_the_interpreter():
    """A thread that is not a daemon (a library's, still at work when the command returns):
    the interpreter's own exit, which waits for it, not the immediate one."""
    prelude = ("import threading, time\n"
               "def late():\n"
               "    time.sleep(1.0)\n"
               "    print('the thread finished', flush=True)\n"
               "threading.Thread(target=late).start()")
    done = console(prelude, "--version")
    assert done.returncode == 0, done.stderr
    from bounce_cli import __version__

    assert done.stdout.splitlines() == [f"bounce {__version__}", "the thread finished"]


def test_only_the_command_named_first_is_registered_while_the_app_runs():
    from bounce_cli.cli.commands import app
    from bounce_cli.cli.console import only_the_command_named

    every = list(app.registered_commands)
    with only_the_command_named(app, ["basin", "--quiet"]):
        assert [c.name for c in app.registered_commands] == ["basin"]
    assert app.registered_commands == every
    for args in ([], ["--help"], ["basn"], ["--version", "basin"]):
        with only_the_command_named(app, args):
            assert app.registered_commands == every, args


def test_a_misspelt_command_is_still_named_its_neighbour():
    done = console("", "basn")
    assert done.returncode == 2
    assert "No such command 'basn'. Did you mean 'basin'?" in done.stderr


@pytest.mark.parametrize(("given", "seen"), [({}, "16"),
                                             ({"OPENBLAS_THREAD_TIMEOUT": "20"}, "20"),
                                             ({"GOTO_THREAD_TIMEOUT": "12"}, "None")])
def test_openblas_idle_threads_sleep_soon_unless_the_user_says_otherwise(given, seen):
    """BLAS_THREAD_TIMEOUT: set before numpy is imported, where the user set neither name."""
    import os

    prelude = ("import atexit, os\n"
               "atexit.register(lambda: print(os.environ.get('OPENBLAS_THREAD_TIMEOUT')))")
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_THREAD_TIMEOUT", "GOTO_THREAD_TIMEOUT")} | given
    code = (f"import sys\n{prelude}\nsys.argv = ['bounce', 'fixed-point']\n"
            "from bounce_cli.cli.console import main\nmain()\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == seen


def test_numpy_is_not_imported_before_the_console_script_sets_the_timeout():
    code = "import sys, bounce_cli.cli.console\nprint('numpy' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.stdout.strip() == "False", done.stderr


HEAP_OR_MAPPING = """
import ctypes, sys
from bounce_cli.runtime.process import keep_freed_memory
kept = keep_freed_memory()
block = bytearray(8 * 1024 * 1024)  # above glibc's default 128 kB: a mapping of its own
address = ctypes.addressof((ctypes.c_char * len(block)).from_buffer(block))
heap = [line.split()[0] for line in open("/proc/self/maps") if line.rstrip().endswith("[heap]")]
low, high = (int(x, 16) for x in heap[0].split("-"))
print(kept, low <= address < high)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt: Linux")
@pytest.mark.parametrize(("given", "seen"), [({}, "True True"),
                                             ({"MALLOC_MMAP_THRESHOLD_": "131072"},
                                              "False False")])
def test_arrays_of_a_few_mb_come_from_the_heap_unless_the_user_set_malloc(given, seen):
    """keep_freed_memory: an 8 MB block lies in the heap (memory that is reused, not
    unmapped at its free), where the user did not set the allocator's thresholds."""
    import os

    env = {k: v for k, v in os.environ.items()
           if not k.startswith("MALLOC_") and k != "GLIBC_TUNABLES"} | given
    done = subprocess.run([sys.executable, "-c", HEAP_OR_MAPPING], capture_output=True,
                          text=True, timeout=60, env=env)
    assert done.stdout.strip() == seen, done.stderr
