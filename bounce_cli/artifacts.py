"""Run directories: atomic writes of CSVs, figures and the run manifest ``run.json``.

A run computes everything first and then commits its files: each is written to a temporary
name in the output directory and moved into place with ``os.replace``, ``run.json`` last,
with interrupts held while the files move (``interrupts.deferred``). An interrupted or failed
run therefore leaves no half-written file, no temporary file, the previous run's files as
they were, and no output folder of its own making (:meth:`RunDirectory.discard`). A
directory holding results of a different resolved config is refused unless ``force``.

``run.json`` holds what the results were made from and nothing that changes from one run to
the next: command, config file, overrides, the resolved config, the seed (only where the
run drew random numbers), the ``--data`` file (absolute path and SHA-256), the versions of
the packages that shape the numbers, the files written. So rerunning an unchanged config
rewrites it byte for byte, and ``bounce reproduce`` on a clean checkout leaves ``git status``
clean. What does change -- start time, wall time, git commit, host -- goes to ``timing.json``
beside it (ignored by git in ``results/``).
"""

from __future__ import annotations

import datetime as _dt
import functools
import hashlib
import json
import os
import platform
import re
import subprocess
import tempfile
import time
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from . import __version__
from .interrupts import deferred

if TYPE_CHECKING:  # pandas is imported where a table is written or read (fast start-up)
    import pandas as pd

MANIFEST = "run.json"
TIMING = "timing.json"
#: the distributions whose versions shape the numbers and figures (run.json "versions")
VERSIONED_PACKAGES = ("numpy", "scipy", "pandas", "matplotlib", "pydantic", "pyyaml")


class OutputDirError(ValueError):
    """The output directory cannot be used (holds another config's results, not writable)."""


def stage(path: Path, write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp)`` on a new temporary file beside ``path``; return ``tmp``.

    On failure the temporary file is removed and the error propagates."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        os.chmod(tmp, 0o666 & ~current_umask())  # mkstemp makes 0600; results are shared
        write(tmp)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """Write ``path`` through a temporary file and ``os.replace``: never half-written."""
    tmp = stage(path, write)
    try:
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(path: Path, text: str) -> None:
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def git_commit() -> str | None:
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


def versions() -> dict[str, str]:
    """bounce, Python and each of VERSIONED_PACKAGES (as installed)."""
    found = {"bounce": __version__, "python": platform.python_version()}
    for name in VERSIONED_PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


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


def same_bytes(a: Path, b: Path) -> bool:
    """Whether two files hold the same bytes (False when ``b`` does not exist)."""
    try:
        if a.stat().st_size != b.stat().st_size:
            return False
        return a.read_bytes() == b.read_bytes()
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


class RunDirectory:
    """Collects a run's outputs and commits them atomically into ``out_dir``."""

    def __init__(
        self,
        out_dir: Path,
        *,
        command: str,
        resolved_config: dict[str, Any],
        overrides: list[str],
        config_path: str | None,
        seed: int | None = None,
        data_file: str | None = None,
        force: bool = False,
    ) -> None:
        self.out_dir = Path(out_dir)
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
        self.previous: dict[str, Any] = {}
        self.created: list[Path] = []  # folders this run made, outermost first
        self.check_writable(force)

    def check_writable(self, force: bool) -> None:
        """Before any computing: the directory can be created and written, and it does not
        hold results of a different resolved config (unless force)."""
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise OutputDirError(f"--out {self.out_dir}: exists and is not a directory")
        missing = [d for d in (self.out_dir, *self.out_dir.parents) if not d.exists()]
        try:
            for folder in reversed(missing):
                folder.mkdir()
                self.created.append(folder)
            probe = stage(self.out_dir / ".write-test", lambda tmp: None)
            probe.unlink()
        except BaseException as exc:
            self.discard()
            if not isinstance(exc, OSError):
                raise
            reason = exc.strerror or type(exc).__name__
            raise OutputDirError(f"--out {self.out_dir}: cannot write there: {reason}") from None
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

    def discard(self) -> None:
        """After an error or an interrupt: remove the folders this run created, if they are
        still empty (a previous run's folder, or one holding anything, is left alone)."""
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
        self._figures[name] = figure

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
        if self.data_file is not None:
            path = Path(self.data_file).resolve()
            manifest["data_file"] = {"path": str(path), "sha256": sha256_of(path)}
        manifest["versions"] = versions()
        manifest["files"] = sorted([*self._frames, *self._figures])
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

    def manifest_text(self, results_unchanged: bool) -> str:
        """``run.json``'s text. A rerun whose every result file is byte for byte the previous
        run's, and whose record differs from the previous one only in package versions, keeps
        the previous record: the results were made with those versions (and the newer ones
        reproduce them, as ``timing.json`` records), and reproducing an unchanged result on an
        upgraded machine changes no tracked file."""
        manifest = self.manifest("completed")
        previous = self.previous
        if (results_unchanged and previous
                and {k: v for k, v in previous.items() if k != "versions"}
                == {k: v for k, v in manifest.items() if k != "versions"}
                and isinstance(previous.get("versions"), dict)):
            manifest = {**manifest, "versions": previous["versions"]}
        return json.dumps(manifest, indent=2) + "\n"

    def commit(self) -> list[Path]:
        """Stage every collected file under a temporary name (the slow part: CSVs, PNGs),
        then move them all into place with ``os.replace``, ``run.json`` last. Returns the
        paths. Until the staging is complete, the previous run's files are untouched."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        writers: dict[str, Callable[[Path], object]] = {}
        for name, frame in self._frames.items():
            writers[name] = functools.partial(write_frame, frame, kind=frame_format(name))
        for name, figure in self._figures.items():
            writers[name] = functools.partial(figure.savefig, format="png", dpi=150)
        staged: list[tuple[Path, Path]] = []
        try:
            for name, write in writers.items():
                staged.append((stage(self.out_dir / name, write), self.out_dir / name))
            unchanged = all(same_bytes(tmp, final) for tmp, final in staged)
            for name, text in ((TIMING, json.dumps(self.timing(), indent=2) + "\n"),
                               (MANIFEST, self.manifest_text(unchanged))):
                write_json = functools.partial(Path.write_text, data=text)
                staged.append((stage(self.out_dir / name, write_json), self.out_dir / name))
            with deferred():  # all of the new run's files, or none
                for tmp, final in staged:
                    os.replace(tmp, final)
                # files of the run this one replaces (listed in its manifest) that this run
                # did not write: remove them, so the folder holds one run, as run.json says --
                # except a file this run read (a --data file in the folder of the run that
                # wrote it): a run never deletes its own input
                inputs = files_named_in(self.resolved_config)
                for name in set(self.previous.get("files", [])) - set(writers):
                    stale = self.out_dir / Path(name).name
                    if stale.is_file() and stale.resolve() not in inputs:
                        stale.unlink()
        finally:
            for tmp, _ in staged:
                tmp.unlink(missing_ok=True)
        return [final for _, final in staged]


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
    """``frame.to_csv(path, index=False)``, byte for byte, about ten times faster for large
    tables of numbers, categories and plain strings: every column is factorised, its distinct
    values formatted once the way pandas formats them (``astype(str)``: repr-exact floats,
    NaN as an empty cell) and the rows joined in chunks of ``CSV_CHUNK_ROWS``. Anything else
    (quoting, nullable or date types, an empty table or one column) goes to pandas."""
    columns = _csv_header(frame)
    if columns is None:
        frame.to_csv(path, index=False)
        return
    with open(path, "w", encoding="utf-8", newline="") as handle:
        handle.write(columns + os.linesep)
        for start in range(0, len(frame), CSV_CHUNK_ROWS):
            chunk = frame.iloc[start:start + CSV_CHUNK_ROWS]
            cells = [_csv_cells(chunk.iloc[:, j]) for j in range(chunk.shape[1])]
            handle.write(os.linesep.join(map(",".join, zip(*cells))) + os.linesep)


def _csv_header(frame: pd.DataFrame) -> str | None:
    """The header line if every column can take the fast path, else None."""
    if len(frame) == 0 or frame.shape[1] < 2:  # pandas writes a lone empty cell as ""
        return None
    names = list(frame.columns)
    if not all(isinstance(n, str) and n and not _CSV_SPECIAL.search(n) for n in names):
        return None
    if len(set(names)) != len(names):
        return None
    for j in range(frame.shape[1]):
        if _distinct_texts(frame.iloc[:, j]) is None:
            return None
    return ",".join(names)


def _distinct_texts(column: pd.Series):
    """(codes, texts): each row's cell is ``texts[code]``; None if not on the fast path."""
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
        # factorise the bit patterns: 0.0 and -0.0 are written differently
        codes, keys = pd.factorize(values.view(np.int64))
        distinct = np.asarray(keys).view(np.float64)
        texts = distinct.astype(str).astype(object)
        texts[np.isnan(distinct)] = ""
        return codes, texts
    if dtype.kind in "iub":
        codes, keys = pd.factorize(values)
        return codes, np.asarray(keys).astype(str).astype(object)
    return None


def _csv_cells(column: pd.Series):
    found = _distinct_texts(column)
    assert found is not None  # _csv_header checked every column
    codes, texts = found
    return texts[codes].tolist()


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


def read_frames(folder: Path) -> dict[str, pd.DataFrame]:
    """Every table of a run directory, file name -> DataFrame: what ``draw(frames)`` takes."""
    return {p.name: read_frame(p) for p in sorted(Path(folder).iterdir())
            if p.is_file() and not p.name.startswith(".") and p.suffix in FRAME_FORMATS}
