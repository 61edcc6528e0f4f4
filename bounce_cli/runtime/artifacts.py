"""Run directories: atomic writes of CSVs, figures and the run manifest ``run.json``.

A run computes everything first and then commits its files: each is written to a temporary
name in the output directory and moved into place with ``os.replace``, ``run.json`` last,
with interrupts held while the files move (``interrupts.deferred``). An interrupted or failed
run therefore leaves no half-written file, no temporary file, the previous run's files as
they were, and no output folder of its own making (:meth:`RunDirectory.discard`). A
directory holding results of a different resolved config is refused unless ``force``.

``run.json`` holds what the results were made from and nothing that changes from one run to
the next: command, config file, overrides, the resolved config, the seed (only where the
run drew random numbers), the ``--data`` file (absolute path and SHA-256), what the run
recorded beside the config (``model_at_data``: the alpha and g a ``--data`` analysis used and
where they came from, ``bounce_cli.data.data_parameters``), the versions of
the packages that shape the numbers, the files written. So rerunning an unchanged config
rewrites it byte for byte, and ``bounce reproduce`` on a clean checkout leaves ``git status``
clean. What does change -- start time, wall time, git commit, host -- goes to ``timing.json``
beside it (ignored by git in ``results/``).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import hashlib
import json
import os
import platform
import re
import subprocess
import tempfile
import threading
import time
from importlib import metadata
from pathlib import Path
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Iterator

import numpy as np

from ..version import __version__
from ..errors import OutputDirError, RunDirectoryBusy
from .interrupts import deferred
from .figure_files import FIGURE_DPI, save_figure
from .forked import ForkedCall, can_fork

if TYPE_CHECKING:  # pandas is imported where a table is written or read (fast start-up)
    import pandas as pd

MANIFEST = "run.json"
TIMING = "timing.json"
#: held by the run writing into a directory (``RunDirectoryLock``); removed when it ends
LOCK_FILE = ".bounce.lock"
#: the distributions whose versions shape the numbers and figures (run.json "versions")
VERSIONED_PACKAGES = ("numpy", "scipy", "pandas", "matplotlib", "pydantic", "pyyaml")


@contextlib.contextmanager
def staging(path: Path) -> Iterator[Path]:
    """A new temporary file beside ``path`` (``reserve``), removed if the block fails or is
    interrupted. Signals are held while it is created: one arriving between its creation and
    the clean-up's knowing of it would leave it behind."""
    held: list[Path] = []
    try:
        with deferred():
            held.append(reserve(path))
        yield held[0]
    except BaseException:
        for tmp in held:
            tmp.unlink(missing_ok=True)
        raise


#: a staging file's name as :func:`reserve` makes it: mkstemp's ``.<name>.``, its 8 random
#: characters (lower-case letters, digits, ``_``) and ``.tmp``
STAGING_NAME = re.compile(r"^\..+\.[a-z0-9_]{8}\.tmp$")


def remove_stale_staging(folders, before: float) -> list[Path]:
    """Remove the staging files a killed run left in ``folders``: regular files (not links,
    not folders) named as :data:`STAGING_NAME` says and last modified before ``before``.

    Parameters
    ----------
    folders : iterable of Path
        The folders to look in (not below them); a missing one is skipped.
    before : float
        A time (seconds since the epoch): the start of the run that cleans up, which holds
        the directory's lock, so that no file a live run stages is older.

    Returns
    -------
    list of Path
        The files removed.
    """
    import stat

    removed = []
    for folder in folders:
        try:
            entries = list(os.scandir(folder))
        except OSError:
            continue
        for entry in entries:
            if not STAGING_NAME.match(entry.name):
                continue
            try:
                info = entry.stat(follow_symlinks=False)
                if stat.S_ISREG(info.st_mode) and info.st_mtime < before:
                    os.unlink(entry.path)
                    removed.append(Path(entry.path))
            except OSError:
                continue
    return removed


def reserve(path: Path) -> Path:
    """A new empty temporary file beside ``path`` (its staging name), readable as results
    are (mkstemp makes 0600)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        os.chmod(tmp, 0o666 & ~current_umask())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


#: zlib level of the PNGs: 1 encodes the basin's two figures in 0.5 s instead of 0.8 s, for
#: files about a quarter larger (basin_iterations.png 480 kB instead of 370 kB)
PNG_OPTIONS = {"compress_level": 1}

#: a run with a table of at least this many rows writes its files in child processes too
#: (``RunDirectory._background_groups``, Linux fork): the 1000 x 1000 basin's files (basin.csv
#: 0.1 s, two PNGs 0.3 s each) are staged in 0.40 s on 2 cores (0.58 s with the previous CSV
#: writer's 0.4 s for basin.csv; 1.1 s one after another)
BACKGROUND_TABLE_ROWS = 200_000
#: a run with this many tables or more writes half of them in a child process (a study's units)
BACKGROUND_TABLE_COUNT = 64


def _write_and_compare(jobs: list[tuple[Path, Callable[[Path], object], Path]]) -> bool:
    """Run each writer into its staged temporary file; True if every file is the same, byte
    for byte, as the file it replaces (the parent needs to know for run.json)."""
    for tmp, write, _ in jobs:
        write(tmp)
    return all(same_bytes(tmp, final) for tmp, _, final in jobs)


def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """Write ``path`` through a temporary file and ``os.replace``: never half-written."""
    with staging(path) as tmp:
        write(tmp)
        os.replace(tmp, path)


def write_text_atomic(path: Path, text: str) -> None:
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


class _GitCommit:
    """:func:`git_commit`'s answer, looked up once per process, in a daemon thread started by
    :meth:`start` (a run's directory, before the run computes): its two ``git`` processes
    (about 0.015 s) then run while this process works, not after its last file is written,
    when ``run.json`` asks."""

    def __init__(self) -> None:
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._value: str | None = None
        self._done = False
        # a child forked while the thread looked it up has the thread's object, not the
        # thread: it looks it up again
        os.register_at_fork(after_in_child=self._after_fork)

    def start(self) -> None:
        with self._lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._look_up, daemon=True,
                                                name="bounce-git-commit")
                self._thread.start()

    def _look_up(self) -> None:
        self._value = _git_rev_parse()
        self._done = True

    def _after_fork(self) -> None:
        self._lock = threading.Lock()
        if not self._done:
            self._thread = None

    def __call__(self) -> str | None:
        self.start()
        assert self._thread is not None
        self._thread.join()
        return self._value


def _git_rev_parse() -> str | None:
    """The commit of the bounce checkout this code runs from, if it is a git checkout."""
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5
        )
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    # only when the checkout is bounce's own (the package lies inside the work tree)
    top = subprocess.run(
        ["git", "rev-parse", "--show-toplevel"], cwd=here, capture_output=True, text=True
    ).stdout.strip()
    return out.stdout.strip() if top and (Path(top) / "pyproject.toml").is_file() else None


#: the commit of the bounce checkout this code runs from, if it is a git checkout (looked up
#: once per process, in the background from ``git_commit.start()``)
git_commit = _GitCommit()


def versions() -> dict[str, str]:
    """bounce, Python and each of VERSIONED_PACKAGES (as installed; looked up once per
    process: each look-up reads the installation's metadata, about 0.01 s, and a run asks
    twice, for run.json and timing.json, after its last file is written)."""
    return dict(_installed_versions())


@functools.lru_cache(maxsize=1)
def _installed_versions() -> dict[str, str]:
    found = {"bounce": __version__, "python": platform.python_version()}
    for name in VERSIONED_PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


def remove_empty_folders(folder: Path, root: Path) -> None:
    """``folder`` and its parents up to (not including) ``root``, each removed while it is
    empty: the folders of a replaced run's files this run did not write (a study's subject
    left out of the manifest) go with them."""
    folder, root = Path(folder), Path(root)
    while folder != root and root in folder.parents:
        try:
            folder.rmdir()  # only an empty folder
        except OSError:
            return
        folder = folder.parent


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_manifest(out_dir: Path) -> dict[str, Any]:
    """The ``run.json`` of a previous run in ``out_dir`` ({} when there is none or unreadable)."""
    try:
        data = json.loads((Path(out_dir) / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


#: relative difference below which two numbers of a run's record (run.json) are the same
#: number: floating point's rounding on another CPU or BLAS, never a changed input
RECORD_RTOL = 1e-9


def records_agree(a: Any, b: Any, rtol: float = RECORD_RTOL) -> bool:
    """Whether two JSON records are the same but for floats within ``rtol`` of each other
    (relative to the larger magnitude): same keys, same lengths, same strings, booleans and
    integers."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(records_agree(a[k], b[k], rtol) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(records_agree(x, y, rtol) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float):
        return (a == b or abs(a - b) <= rtol * max(abs(a), abs(b))
                or (a != a and b != b))  # both NaN
    return type(a) is type(b) and a == b


#: ``same_bytes`` reads both files in chunks of this size into two buffers it reuses: reading
#: each whole file into new memory cost the 1000 x 1000 basin's rerun 0.08 s (its 67 MB
#: basin.csv twice, mostly in the kernel's page faults), the chunks 0.015 s
COMPARE_CHUNK_BYTES = 1 << 20


def same_bytes(a: Path, b: Path) -> bool:
    """Whether two files hold the same bytes (False when ``b`` does not exist)."""
    try:
        if a.stat().st_size != b.stat().st_size:
            return False
        chunk_a, chunk_b = bytearray(COMPARE_CHUNK_BYTES), bytearray(COMPARE_CHUNK_BYTES)
        with open(a, "rb", buffering=0) as file_a, open(b, "rb", buffering=0) as file_b:
            while True:
                n = file_a.readinto(chunk_a)
                if file_b.readinto(chunk_b) != n:
                    return False  # one file changed size while read
                if n == 0:
                    return True
                # whole buffers compare as one memcmp; a short read compares its bytes
                if (chunk_a != chunk_b if n == COMPARE_CHUNK_BYTES
                        else chunk_a[:n] != chunk_b[:n]):
                    return False
    except OSError:
        return False


def files_named_in(config: Any) -> set[Path]:
    """Every existing file a (resolved, JSON-like) config names in one of its string values,
    resolved: the files a run reads (``data``, ``events``, ``truth``, ...)."""
    found: set[Path] = set()
    stack = [config]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            stack.extend(node.values())
        elif isinstance(node, (list, tuple)):
            stack.extend(node)
        elif isinstance(node, str) and node:
            try:
                path = Path(node)
                if path.is_file():
                    found.add(path.resolve())
            except (OSError, ValueError):
                pass
    return found


#: run.json's key marking results recorded from a person or a live stream (``bounce
#: virtual`` with the page's mouse or an LSL stream): never replaced without --force, since
#: no rerun can make them again
RECORDED_LIVE = "recorded_live"


class RunDirectoryLock:
    """One run at a time in an output directory: an advisory lock (``flock``) on
    ``<out>/.bounce.lock``, held from the directory's check until the run has committed or
    discarded its files. A second run into the same directory refuses with one line naming
    the holder's pid and command. The lock belongs to the open file, so a run that died
    (SIGKILL, a crash) holds nothing: its stale lock file is taken over. Where ``fcntl`` is
    missing (Windows) runs are not locked."""

    def __init__(self, out_dir: Path) -> None:
        self.path = Path(out_dir) / LOCK_FILE
        self._fd: int | None = None

    def acquire(self, command: str) -> None:
        """Take the lock or raise RunDirectoryBusy, an OutputDirError (the directory
        exists)."""
        try:
            import fcntl
        except ImportError:  # pragma: no cover - no advisory locks on this platform
            return
        while True:
            with deferred():  # the file is open and known to release() in one step
                self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666 & ~current_umask())
            try:
                fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:  # held by a live run
                holder = os.pread(self._fd, 200, 0).decode("utf-8", "replace").strip()
                self._close()
                raise RunDirectoryBusy(
                    f"--out {self.path.parent}: another bounce run is writing there"
                    + (f" ({holder})" if holder else "")
                    + "; wait for it to finish or choose another --out") from None
            try:  # the holder may have removed the file between our open and our lock
                current = os.path.samestat(os.fstat(self._fd), os.stat(self.path))
            except FileNotFoundError:
                current = False
            if current:
                break
            self._close()
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, f"pid {os.getpid()}: bounce {command}\n".encode(), 0)

    def release(self) -> None:
        """Remove the lock file (while still holding it: no one else has it) and unlock."""
        if self._fd is None:
            return
        with deferred():
            try:
                self.path.unlink()
            except FileNotFoundError:
                pass
            self._close()

    def _close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


class RunDirectory:
    """Collects a run's outputs and commits them atomically into ``out_dir``, holding the
    directory's lock (``RunDirectoryLock``) from the check until ``commit`` or ``discard``."""

    def __init__(
        self,
        out_dir: Path,
        *,
        command: str,
        resolved_config: dict[str, Any],
        overrides: list[str],
        config_path: str | None,
        seed: int | None = None,
        data_file: str | list[str] | None = None,
        force: bool = False,
        figure_formats: tuple[str, ...] = ("png",),
        dpi: float = FIGURE_DPI,
    ) -> None:
        self.out_dir = Path(out_dir)
        self.figure_formats, self.dpi = tuple(figure_formats), dpi
        self.command = command
        self.resolved_config = resolved_config
        self.overrides = list(overrides)
        self.config_path = config_path
        self.seed = seed
        self.data_file = data_file
        self.started = _dt.datetime.now(_dt.timezone.utc)
        self._t0 = time.perf_counter()
        self._frames: dict[str, pd.DataFrame] = {}
        self._figures: dict[str, Any] = {}
        self._files: dict[str, bytes] = {}
        self.previous: dict[str, Any] = {}
        #: what the run adds to run.json beside the config (``RunOptions.record``)
        self.record: dict[str, Any] = {}
        #: per file, after ``commit``: identical / within tolerance / kept / changed / new
        self.comparison: dict[str, str] = {}
        self.created: list[Path] = []  # folders this run made, outermost first
        self.lock = RunDirectoryLock(self.out_dir)
        git_commit.start()  # for run.json, while the run computes
        try:
            self.check_writable(force)
        except BaseException:
            self.discard()
            raise

    def check_writable(self, force: bool) -> None:
        """Before any computing: the directory can be created and written, and it does not
        hold results of a different resolved config (unless force)."""
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise OutputDirError(f"--out {self.out_dir}: exists and is not a directory")
        try:
            self._make_folders()
            with staging(self.out_dir / ".write-test") as probe:
                probe.unlink()
        except BaseException as exc:
            self.discard()
            if not isinstance(exc, OSError):
                raise
            reason = exc.strerror or type(exc).__name__
            raise OutputDirError(f"--out {self.out_dir}: cannot write there: {reason}") from None
        self.lock.acquire(self.command)  # before reading what a concurrent run may replace
        self.previous = read_manifest(self.out_dir)
        if force or not self.previous:
            return
        previous = self.previous
        same = (
            previous.get("command") == self.command
            and previous.get("config") == self.resolved_config
        )
        if not same:
            raise OutputDirError(
                f"--out {self.out_dir}: holds results of a different config "
                f"(a run of bounce {previous.get('command', '?')}); "
                "use --force to replace them or choose another --out"
            )
        if previous.get(RECORDED_LIVE):  # a person's session: a rerun cannot make it again
            raise OutputDirError(
                f"--out {self.out_dir}: holds a session recorded live (bounce "
                f"{previous.get('command', '?')}, {previous.get('racket_source', 'a person')}): "
                "a rerun would replace it; choose another --out, or use --force to replace it")

    def _make_folders(self, attempts: int = 3) -> None:
        """The directory and its missing parents, each recorded in ``created`` only where this
        run made it: another run beside this one (``bounce reproduce``'s lanes, which share
        the results folder) may make a folder between our look and our mkdir, or remove one
        it made (its clean-up after an error) before we made ours inside it."""
        for attempt in range(attempts):
            missing = [d for d in (self.out_dir, *self.out_dir.parents) if not d.exists()]
            try:
                for folder in reversed(missing):
                    try:
                        folder.mkdir()
                    except FileExistsError:
                        if not folder.is_dir():
                            raise
                        continue  # made meanwhile by another run: not ours to remove
                    self.created.append(folder)
                return
            except FileNotFoundError:  # a parent removed meanwhile: look again
                if attempt == attempts - 1:
                    raise

    def release(self) -> None:
        """The run is over: the directory's lock is released (``commit`` does it)."""
        self.lock.release()

    def discard(self) -> None:
        """After an error or an interrupt: release the lock and remove the folders this run
        created, if they are still empty (a previous run's folder, or one holding anything, is
        left alone)."""
        self.lock.release()
        for folder in reversed(self.created):
            try:
                folder.rmdir()
            except OSError:
                break
        self.created = []

    def add_csv(self, name: str, frame: pd.DataFrame) -> None:
        """A table to write, in the format its name ends with (``FRAME_FORMATS``)."""
        self._frames[name] = frame

    def add_figure(self, name: str, figure) -> None:
        """A figure to write once in each of the run's figure formats: ``basin.png`` is
        written as ``basin.png``, ``basin.pdf``, ``basin.svg`` as ``figure_formats`` say."""
        stem = Path(name).stem
        for kind in self.figure_formats:
            self._figures[f"{stem}.{kind}"] = (figure, kind)

    def add_file(self, name: str, content: bytes) -> None:
        """Any other file, as bytes (e.g. an HTML report)."""
        self._files[name] = content

    def manifest(self, status: str) -> dict[str, Any]:
        """``run.json``: what the results were made from; the same for the same inputs."""
        manifest: dict[str, Any] = {
            "command": self.command,
            "status": status,
            "config_file": self.config_path,
            "overrides": self.overrides,
            "seed": self.seed,
            "config": self.resolved_config,
        }
        if self.data_file is not None:  # several --data files: a list of them
            files = [{"path": str(Path(p).resolve()), "sha256": sha256_of(Path(p).resolve())}
                     for p in (self.data_file if isinstance(self.data_file, list)
                               else [self.data_file])]
            manifest["data_file"] = files if isinstance(self.data_file, list) else files[0]
        manifest.update(self.record)
        manifest["versions"] = versions()
        manifest["files"] = sorted([*self._frames, *self._figures, *self._files])
        return manifest

    def timing(self) -> dict[str, Any]:
        """``timing.json``: what differs on every run (kept out of ``run.json``)."""
        return {
            "started": self.started.isoformat(timespec="seconds"),
            "wall_seconds": round(time.perf_counter() - self._t0, 3),
            "git_commit": git_commit(),
            "host": platform.node(),
            "versions": versions(),  # this run's (run.json may keep the first run's: below)
        }

    def _background_groups(self) -> list[list[str]]:
        """The files written by child processes while this one writes the rest (Linux only:
        ``runtime.forked``): the tables of ``BACKGROUND_TABLE_ROWS`` rows or more (or, of
        ``BACKGROUND_TABLE_COUNT`` tables or more, the later half) in one child, and with two
        figures or more, the later half of the figures in another: a figure takes 0.2-0.4 s
        to render (the 1000 x 1000 basin: basin.csv 0.1 s, each PNG about 0.3 s; acf
        --data's two figures 0.8 s one after the other)."""
        if not can_fork():
            return []
        tables = [name for name, frame in self._frames.items()
                  if len(frame) >= BACKGROUND_TABLE_ROWS]
        if not tables and len(self._frames) >= BACKGROUND_TABLE_COUNT:
            tables = list(self._frames)[len(self._frames) // 2:]
        figures = list(self._figures)
        return (([tables] if tables else [])
                + ([figures[len(figures) // 2:]] if len(figures) >= 2 else []))

    def _folders(self, names) -> list[Path]:
        """The run directory and the folders of ``names`` and of the previous run's files
        (those inside the directory)."""
        files = [*names, *self.previous.get("files", [])]
        inside = [Path(n) for n in files
                  if isinstance(n, str) and not Path(n).is_absolute() and ".." not in Path(n).parts]
        return sorted({self.out_dir, *(self.out_dir / n.parent for n in inside)})

    def manifest_text(self, results_unchanged: bool) -> str:
        """``run.json``'s text. A rerun whose every result file is the previous run's (byte
        for byte, or within the reproduction tolerance where ``commit`` was given one), and
        whose record differs from the previous one only in package versions and in numbers
        within ``RECORD_RTOL`` (a set-up measured from the data, rounded differently on
        another CPU), keeps the previous record: the results were made with those versions
        (and the newer ones reproduce them, as ``timing.json`` records), and reproducing an
        unchanged result on an upgraded or different machine changes no tracked file."""
        manifest = self.manifest("completed")
        previous = self.previous
        if (results_unchanged and previous
                and records_agree({k: v for k, v in previous.items() if k != "versions"},
                                  {k: v for k, v in manifest.items() if k != "versions"})
                and isinstance(previous.get("versions"), dict)):
            manifest = previous
        return json.dumps(manifest, indent=2) + "\n"

    def commit(self,
               agrees: Callable[[str, pd.DataFrame, pd.DataFrame, RunTables], bool] | None = None,
               ) -> list[Path]:
        """Stage every collected file under a temporary name (the slow part: CSVs, PNGs),
        then move them all into place with ``os.replace``, ``run.json`` last. Returns the
        paths written. Until the staging is complete, the previous run's files are untouched.

        With ``agrees`` (``bounce reproduce``: ``agrees(table, new, previous, tables)``, the
        reproduction tolerance; ``tables``: both runs' tables, :class:`RunTables`), a table
        whose previous file agrees with the new one is left untouched, and the figures are
        not redrawn when every table agrees and they exist (their data did not change); when
        some table changed, every table is rewritten (the folder never holds the tables of
        two runs, which rules comparing one table with the help of another would read).
        ``self.comparison`` then says per file: identical, within tolerance, kept (a figure
        not redrawn), changed, rewritten (within tolerance, but another table changed) or
        new."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        writers: dict[str, Callable[[Path], object]] = {}
        written = {*self._frames, *self._figures, *self._files}
        for name in written:
            if Path(name).is_absolute() or ".." in Path(name).parts:
                raise ValueError(f"result file {name!r} is not a path inside the run directory")
        for name, content in self._files.items():
            writers[name] = functools.partial(_write_bytes, content)
        for name, frame in self._frames.items():
            writers[name] = functools.partial(write_frame, frame, kind=frame_format(name))
        for name, (figure, kind) in self._figures.items():
            writers[name] = functools.partial(save_figure, figure, kind=kind, dpi=self.dpi,
                                              source=f"bounce {self.command}",
                                              png_options=PNG_OPTIONS)
        # what a run killed while staging left (this run holds the lock: no live run's)
        remove_stale_staging(self._folders(written), self.started.timestamp())
        staged: list[tuple[Path, Path]] = []
        children: list[ForkedCall] = []

        def reserved(name: str) -> Path:
            # the temporary file is created and recorded for the clean-up in one step: a
            # signal between the two (a test sends one the moment the first file appears)
            # would leave it behind
            with deferred():
                staged.append((reserve(self.out_dir / name), self.out_dir / name))
            return staged[-1][0]

        try:
            for group in self._background_groups() if agrees is None else []:
                jobs = [(reserved(name), writers.pop(name), self.out_dir / name)
                        for name in group]
                children.append(ForkedCall(
                    functools.partial(_write_and_compare, jobs),
                    f"the process writing {', '.join(t.name for t, _, _ in jobs)}").start())
            unchanged = True
            tables_agree = True
            within: list[tuple[str, Path]] = []  # tables within tolerance of the previous
            both_runs = RunTables(self._frames, FramesOnDisk(self.out_dir), self.resolved_config)
            for name, write in writers.items():  # the tables first, then the figures
                final = self.out_dir / name
                if (agrees is not None and name in self._figures and tables_agree
                        and final.is_file()):
                    self.comparison[name] = "kept"
                    continue
                tmp = reserved(name)
                write(tmp)
                if same_bytes(tmp, final):
                    self.comparison[name] = "identical"
                elif (agrees is not None and name in self._frames and final.is_file()
                      and agrees(name, read_frame(tmp), read_frame(final), both_runs)):
                    self.comparison[name] = "within tolerance"
                    within.append((name, tmp))
                else:
                    self.comparison[name] = "changed" if final.is_file() else "new"
                    unchanged = False
                    tables_agree = tables_agree and name not in self._frames
            for name, tmp in within:
                if tables_agree:  # leave the previous file as it is
                    tmp.unlink()
                    staged.remove((tmp, self.out_dir / name))
                else:  # another table changed: the folder holds the tables of one run
                    self.comparison[name] = "rewritten"
            versions()  # read while the children write (run.json and timing.json ask)
            while children:
                unchanged &= children[0].wait()  # the child compared its files
                children.pop(0)
            for name, text in ((TIMING, json.dumps(self.timing(), indent=2) + "\n"),
                               (MANIFEST, self.manifest_text(unchanged))):
                reserved(name).write_text(text)
            with deferred():  # all of the new run's files, or none
                for tmp, final in staged:
                    os.replace(tmp, final)
                # files of the run this one replaces (listed in its manifest) that this run
                # did not write: remove them, so the folder holds one run, as run.json says --
                # except a file this run read (a --data file in the folder of the run that
                # wrote it): a run never deletes its own input
                inputs = files_named_in(self.resolved_config)
                for name in set(self.previous.get("files", [])) - written:
                    if Path(name).is_absolute() or ".." in Path(name).parts:
                        continue  # not a file of the run directory
                    stale = self.out_dir / name
                    if stale.is_file() and stale.resolve() not in inputs:
                        stale.unlink()
                        remove_empty_folders(stale.parent, self.out_dir)
        finally:
            for child in children:
                child.kill()
            for tmp, _ in staged:
                tmp.unlink(missing_ok=True)
            self.release()  # the run's files are in place (or it failed): the next may start
        return [final for _, final in staged]


def _write_bytes(content: bytes, path: Path) -> None:
    Path(path).write_bytes(content)


# -- tables: CSV (fast, byte for byte what pandas writes) and binary formats -----------------
#: file name suffix -> table format; ``read_frame`` reads each back into the same DataFrame
FRAME_FORMATS = (".csv", ".npz", ".parquet")
#: rows per chunk of the CSV writer (bounds its memory: ~100 bytes a row while a chunk is built)
CSV_CHUNK_ROWS = 1 << 20
#: npz key suffix of a categorical column's categories (the column itself holds the codes)
NPZ_CATEGORIES = ".categories"
_CSV_SPECIAL = re.compile(r'[,"\r\n]')


def write_frame(frame: pd.DataFrame, path: Path, kind: str | None = None) -> None:
    """Write a table to ``path`` as ``kind`` (a ``FRAME_FORMATS`` suffix; default: the one
    ``path`` ends with, CSV for any other)."""
    kind = kind or frame_format(Path(path).name)
    if kind == ".npz":
        write_npz(frame, path)
    elif kind == ".parquet":
        frame.to_parquet(path, index=False)
    else:
        write_csv(frame, path)


def frame_format(name: str) -> str:
    """The table format of a file name: its suffix if one of ``FRAME_FORMATS``, else CSV."""
    suffix = Path(name).suffix
    return suffix if suffix in FRAME_FORMATS else ".csv"


def write_csv(frame: pd.DataFrame, path: Path) -> None:
    """``frame.to_csv(path, index=False)``, byte for byte, many times faster for large
    tables of numbers, categories and plain strings. In chunks of ``CSV_CHUNK_ROWS`` rows
    (bounded memory): every column is cut into codes and distinct values (a grid's columns
    from their structure, ``_factorize``), the distinct values formatted once the way pandas
    formats them (``astype(str)``: repr-exact floats, NaN as an empty cell); neighbouring
    columns whose combinations are few are joined once per combination (``_merge_columns``);
    each row is then a few pre-encoded pieces, joined as bytes ``CSV_BLOCK_ROWS`` rows at a
    time. Anything else (quoting, nullable or date types, an empty table or one column, in
    any chunk) goes to pandas.

    Measured on the shared 2-core EPYC (min of 5): the 1000 x 1000 basin.csv (10^6 rows,
    67 MB) 0.10 s, was 0.40 s with pandas.factorize on every column and a per-row
    ``",".join``; a synthetic 4000 x 4000 grid (1.09 GB, one run each) 3.2 s, was 8.3 s, with
    the same peak memory.

    Text cells a spreadsheet would run as a formula are written as text first
    (:func:`defuse_formulas`)."""
    frame = defuse_formulas(frame)
    if len(frame) < CSV_FAST_MIN_ROWS or _fast_columns(frame.iloc[:0]) is None:
        frame.to_csv(path, index=False)
        return
    with open(path, "wb") as handle:
        handle.write((",".join(frame.columns) + os.linesep).encode("utf-8"))
        for start in range(0, len(frame), CSV_CHUNK_ROWS):
            chunk = frame.iloc[start:start + CSV_CHUNK_ROWS]
            columns = _fast_columns(chunk)
            if columns is None:  # a cell pandas must write (quoting): all of it by pandas
                break
            for block in _csv_blocks(_merge_columns(columns, len(chunk)), len(chunk)):
                handle.write(block)
        else:
            return
    frame.to_csv(path, index=False)


#: tables shorter than this are written by pandas itself: the fast path's work per column
#: (factorising, formatting the distinct values, merging) pays only on long columns of
#: repeated values (a grid's); on a study's unit tables (tens to a thousand rows) pandas took
#: half the time (65 against 158 ms for a 10-trial unit's 61 tables)
CSV_FAST_MIN_ROWS = 20_000

#: the first characters that make a spreadsheet read a cell as a formula (OWASP, CSV injection)
FORMULA_STARTS = ("=", "+", "-", "@")


def _runs_as_formula(value: object) -> bool:
    """A text a spreadsheet would run: it begins with a ``FORMULA_STARTS`` character and is
    not a number (``-1.5`` written as text stays as it is)."""
    if not (isinstance(value, str) and value.startswith(FORMULA_STARTS)):
        return False
    try:
        float(value)
    except ValueError:
        return True
    return False


def defuse_formulas(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with each text cell that a spreadsheet would run as a formula (``=``, ``+``,
    ``-`` or ``@`` first, e.g. a trial label ``=HYPERLINK(...)``) prefixed with ``'``, as
    OWASP's CSV-injection advice says: opened in a spreadsheet, the cell is text.

    Parameters
    ----------
    frame : pandas.DataFrame
        A table about to be written as CSV.

    Returns
    -------
    pandas.DataFrame
        ``frame`` itself when no cell needs it (the usual case: no copy), else a copy with
        those cells changed. Only text columns (objects, strings, categories) are looked at:
        numbers, also negative ones, stay numbers; so do texts that are numbers.
    """
    import pandas as pd

    changed: dict[int, pd.Series] = {}
    for j in range(frame.shape[1]):
        column = frame.iloc[:, j]
        dtype = column.dtype
        if isinstance(dtype, pd.CategoricalDtype):
            categories = list(dtype.categories)
            if any(_runs_as_formula(c) for c in categories):
                renamed = ["'" + c if _runs_as_formula(c) else c for c in categories]
                if len(set(renamed)) == len(renamed):
                    changed[j] = column.cat.rename_categories(renamed)
                    continue
                column = column.astype(object)  # "'=a" was there already: as text
            else:
                continue
        elif not (isinstance(dtype, pd.StringDtype)
                  or (isinstance(dtype, np.dtype) and dtype.kind == "O")):
            continue
        values = column.to_numpy(dtype=object)
        try:
            distinct = pd.unique(values)
        except TypeError:  # unhashable cells (lists): every cell looked at
            distinct = values
        if any(_runs_as_formula(v) for v in distinct):
            changed[j] = pd.Series(["'" + v if _runs_as_formula(v) else v for v in values],
                                   index=column.index, dtype=column.dtype)
    if not changed:
        return frame
    out = frame.copy(deep=False)
    for j, column in changed.items():
        out.isetitem(j, column)
    return out


#: rows joined and written at once: a couple of MB, reused while in cache (the 10^6 rows of
#: basin.csv joined at once: 0.13 s; in blocks of 2^15 rows: 0.04 s)
CSV_BLOCK_ROWS = 1 << 15


def _csv_blocks(columns: list[tuple[np.ndarray, np.ndarray]], rows: int) -> Iterator[bytes]:
    """The rows as CSV bytes (lines end with ``os.linesep``), ``CSV_BLOCK_ROWS`` at a time:
    each column's texts are encoded once with the comma or line end that follows them, so a
    row is its columns' pieces, and a block one ``bytes.join``."""
    endings = [","] * (len(columns) - 1) + [os.linesep]
    pieces = np.empty((rows, len(columns)), dtype=object)
    for j, ((codes, texts), end) in enumerate(zip(columns, endings)):
        encoded = np.empty(len(texts), dtype=object)
        encoded[:] = [(t + end).encode("utf-8") if t is not None else b""
                      for t in texts.tolist()]
        pieces[:, j] = encoded[codes]
    for start in range(0, rows, CSV_BLOCK_ROWS):
        yield b"".join(pieces[start:start + CSV_BLOCK_ROWS].ravel().tolist())


def _csv_header(frame: pd.DataFrame) -> str | None:
    """The header line if every column can take the fast path, else None."""
    if len(frame) == 0 or _fast_columns(frame) is None:
        return None
    return ",".join(frame.columns)


def _fast_columns(frame: pd.DataFrame) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """Each column's (codes, texts) (see ``_distinct_texts``), or None if a column (or the
    header) is not on the fast path. An empty slice checks the header and the dtypes."""
    if frame.shape[1] < 2:  # pandas writes a lone empty cell as ""
        return None
    names = list(frame.columns)
    if not all(isinstance(n, str) and n and not _CSV_SPECIAL.search(n) for n in names):
        return None
    if len(set(names)) != len(names):
        return None
    columns = []
    for j in range(frame.shape[1]):
        found = _distinct_texts(frame.iloc[:, j])
        if found is None:
            return None
        codes, texts = found
        if len(texts):  # code -1 (missing): the last text, ""
            codes = codes % len(texts)
        columns.append((codes, texts))
    return columns


#: neighbouring columns are merged while their combinations are at most rows / this: a
#: combination's text is built once, and every row has a piece fewer to join
CSV_MERGE_RATIO = 8


def _merge_columns(columns: list[tuple[np.ndarray, np.ndarray]],
                   rows: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Join neighbouring columns into one whose texts are "a,b" while the combinations that
    occur are at most ``rows / CSV_MERGE_RATIO`` (the basin's 10^6 rows: five columns become
    two). Combinations are found by direct addressing (a table of all code pairs) when there
    are not many more pairs than rows, else not merged: no hashing of every row."""
    merged = [columns[0]]
    for codes, texts in columns[1:]:
        left_codes, left_texts = merged[-1]
        pairs = len(left_texts) * len(texts)
        if pairs <= 4 * rows + 1024:
            key = left_codes.astype(np.intp) * len(texts) + codes
            present = np.zeros(pairs, dtype=bool)
            present[key] = True
            used = np.flatnonzero(present)
            if len(used) <= rows // CSV_MERGE_RATIO:
                index = np.zeros(pairs, dtype=np.intp)
                index[used] = np.arange(len(used))
                left, right = np.divmod(used, len(texts))
                joined = np.empty(len(used), dtype=object)
                joined[:] = [f"{a},{b}" for a, b in zip(left_texts[left].tolist(),
                                                        texts[right].tolist())]
                merged[-1] = (index[key], joined)
                continue
        merged.append((codes, texts))
    return merged


def _distinct_texts(column: pd.Series):
    """(codes, texts): each row's cell is ``texts[code]`` (``texts`` may hold None where no
    row's code points); None if not on the fast path."""
    import pandas as pd

    dtype = column.dtype
    if isinstance(dtype, pd.CategoricalDtype):
        categories = _distinct_texts(pd.Series(dtype.categories))
        if categories is None:
            return None
        codes = column.cat.codes.to_numpy()
        # code -1 (missing) picks the appended empty cell
        return codes, np.append(categories[1][categories[0]], "")
    if isinstance(dtype, pd.StringDtype) or (isinstance(dtype, np.dtype) and dtype.kind == "O"):
        # strings (pandas' str dtype or objects): missing cells are written empty
        codes, keys = pd.factorize(column.to_numpy(dtype=object))
        keys = np.asarray(keys, dtype=object)
        if not all(type(k) is str and k and not _CSV_SPECIAL.search(k) for k in keys):
            return None
        return codes, np.append(keys, "")
    values = column.to_numpy()
    if not isinstance(dtype, np.dtype):
        return None
    if dtype.kind == "f" and dtype.itemsize == 8:
        # the bit patterns: 0.0 and -0.0 are written differently
        codes, keys = _factorize(values.view(np.int64))
        distinct = keys.view(np.float64)
        texts = distinct.astype(str).astype(object)
        texts[np.isnan(distinct)] = ""
        return codes, texts
    if dtype.kind in "iu" and len(values):
        # small integers (counts): the value less the smallest is the code, no hashing
        low, high = int(values.min()), int(values.max())
        if high - low <= max(len(values), 1 << 16):
            wide = np.int64 if dtype.kind == "i" else np.uint64
            codes = (values.astype(wide) - wide(low)).astype(np.intp)
            used = np.flatnonzero(np.bincount(codes, minlength=high - low + 1))
            texts = np.full(high - low + 1, None, dtype=object)
            texts[used] = (used.astype(wide) + wide(low)).astype(str)
            return codes, texts
    if dtype.kind in "iub":
        codes, keys = _factorize(values)
        return codes, keys.astype(str).astype(object)
    return None


def _factorize(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``pandas.factorize(values)`` (codes, distinct values) without hashing every row of a
    grid's columns (meshgrid order): a column of runs (the outer axis) is factorised run by
    run, one repeating a block (the inner axis) block by block: 0.6 and 1.8 ms instead of 3.6
    and 5.9 ms for the basin's 10^6 rows of v0 and theta0. Other columns: pandas."""
    import pandas as pd

    n = len(values)
    if n > 64:
        starts = np.flatnonzero(np.concatenate(([True], values[1:] != values[:-1])))
        if len(starts) <= n // 4:
            run_codes, keys = pd.factorize(values[starts])
            return np.repeat(run_codes, np.diff(np.append(starts, n))), np.asarray(keys)
        again = np.flatnonzero(values[1:n // 4] == values[0])
        if len(again):
            period = int(again[0]) + 1
            if (values[period:] == values[:-period]).all():
                block_codes, keys = pd.factorize(values[:period])
                return np.resize(block_codes, n), np.asarray(keys)
    codes, keys = pd.factorize(values)
    return codes, np.asarray(keys)


def write_npz(frame: pd.DataFrame, path: Path) -> None:
    """The table as an uncompressed ``.npz`` (numpy only): one array per column; a
    categorical column as its integer codes plus ``<name>.categories``; strings as unicode.
    ``read_frame`` reads it back to the same DataFrame."""
    import pandas as pd

    arrays: dict[str, np.ndarray] = {}
    for name in frame.columns:
        column = frame[name]
        if isinstance(column.dtype, pd.CategoricalDtype):
            arrays[str(name)] = column.cat.codes.to_numpy()
            arrays[f"{name}{NPZ_CATEGORIES}"] = np.asarray(column.cat.categories, dtype=str)
        elif isinstance(column.dtype, pd.StringDtype) or column.dtype == object:
            arrays[str(name)] = np.asarray(column.to_numpy(dtype=object), dtype=str)
        else:
            arrays[str(name)] = column.to_numpy()
    with open(path, "wb") as handle:
        np.savez(handle, allow_pickle=False, **arrays)


def read_frame(path: Path) -> pd.DataFrame:
    """A table written by a run (``.csv``, ``.npz`` or ``.parquet``) as a DataFrame."""
    import pandas as pd

    path = Path(path)
    kind = frame_format(path.name)
    if kind == ".parquet":
        return pd.read_parquet(path)
    if kind == ".csv":
        return pd.read_csv(path)
    with np.load(path, allow_pickle=False) as data:
        names = [k for k in data.files if not k.endswith(NPZ_CATEGORIES)]
        columns: dict[str, Any] = {}
        for name in names:
            if f"{name}{NPZ_CATEGORIES}" in data.files:
                categories = data[f"{name}{NPZ_CATEGORIES}"].tolist()
                columns[name] = pd.Categorical.from_codes(data[name], categories=categories)
            elif data[name].dtype.kind == "U":
                columns[name] = data[name].astype(object)
            else:
                columns[name] = data[name]
    return pd.DataFrame(columns)


class FramesOnDisk(Mapping):
    """The tables of a run directory as a read-only mapping, each read when first asked for
    (``bounce reproduce`` compares some tables with the help of others)."""

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self._read: dict[str, pd.DataFrame] = {}

    def __getitem__(self, name: str) -> pd.DataFrame:
        if name not in self._read:
            path = self.folder / name
            if not path.is_file():
                raise KeyError(name)
            self._read[name] = read_frame(path)
        return self._read[name]

    def __iter__(self) -> Iterator[str]:
        return iter(sorted(p.name for p in self.folder.iterdir() if p.is_file()
                           and not p.name.startswith(".") and p.suffix in FRAME_FORMATS))

    def __len__(self) -> int:
        return sum(1 for _ in self)


@dataclass(frozen=True)
class RunTables:
    """Both runs of one experiment when a new run is compared with the previous one: table
    name -> frame of each (``previous`` read on demand) and the resolved config both were
    made from. What ``RunDirectory.commit`` hands its ``agrees``."""

    fresh: Mapping[str, pd.DataFrame]
    committed: Mapping[str, pd.DataFrame]
    config: Mapping[str, Any]


def read_frames(folder: Path) -> dict[str, pd.DataFrame]:
    """Every table of a run directory, file name -> DataFrame: what ``draw(frames)`` takes."""
    return {p.name: read_frame(p) for p in sorted(Path(folder).iterdir())
            if p.is_file() and not p.name.startswith(".") and p.suffix in FRAME_FORMATS}
