"""Run directories: atomic writes of CSVs, figures and the run manifest ``run.json``.

A run computes everything first and then commits its files: each is written to a temporary
name in the output directory and moved into place with ``os.replace``, ``run.json`` last.
An interrupted or failed run therefore leaves no half-written file and leaves the previous
run's files as they were. A directory holding results of a different resolved config is
refused unless ``force``.
"""

from __future__ import annotations

import datetime as _dt
import functools
import hashlib
import json
import os
import platform
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd
import scipy

from . import __version__

MANIFEST = "run.json"


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
    return {
        "bounce": __version__,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "python": platform.python_version(),
    }


def read_manifest(out_dir: Path) -> dict[str, Any]:
    """The ``run.json`` of a previous run in ``out_dir`` ({} when there is none or unreadable)."""
    try:
        data = json.loads((Path(out_dir) / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def data_file_record(data: Any) -> dict[str, Any] | None:
    """The data file a run reads (config key ``data``): its path and SHA-256, so that a
    result can be traced to the exact file (None without data or when it cannot be read; the
    experiment then reports the error)."""
    if not isinstance(data, str) or not data:
        return None
    digest = hashlib.sha256()
    try:
        with open(data, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
    except OSError:
        return None
    return {"path": str(Path(data).resolve()), "sha256": digest.hexdigest()}


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
        force: bool = False,
    ) -> None:
        self.out_dir = Path(out_dir)
        self.command = command
        self.resolved_config = resolved_config
        self.overrides = list(overrides)
        self.config_path = config_path
        self.seed = seed
        self.started = _dt.datetime.now(_dt.timezone.utc)
        self._t0 = time.perf_counter()
        self._frames: dict[str, pd.DataFrame] = {}
        self._figures: dict[str, Any] = {}
        self.previous: dict[str, Any] = {}
        self.data_file = data_file_record(resolved_config.get("data"))
        self.check_writable(force)

    def check_writable(self, force: bool) -> None:
        """Before any computing: the directory can be created and written, and it does not
        hold results of a different resolved config (unless force)."""
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise OutputDirError(f"--out {self.out_dir}: exists and is not a directory")
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
            probe = stage(self.out_dir / ".write-test", lambda tmp: None)
            probe.unlink()
        except OSError as exc:
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
                f"({previous.get('command', '?')} run of {previous.get('started', '?')}); "
                "use --force to replace them or choose another --out"
            )

    def add_csv(self, name: str, frame: pd.DataFrame) -> None:
        self._frames[name] = frame

    def add_figure(self, name: str, figure) -> None:
        self._figures[name] = figure

    def manifest(self, status: str) -> dict[str, Any]:
        return {
            "command": self.command,
            "status": status,
            "config_file": self.config_path,
            "overrides": self.overrides,
            "seed": self.seed,
            "config": self.resolved_config,
            **({"data_file": self.data_file} if self.data_file else {}),
            "versions": versions(),
            "git_commit": git_commit(),
            "started": self.started.isoformat(timespec="seconds"),
            "wall_seconds": round(time.perf_counter() - self._t0, 3),
            "files": sorted([*self._frames, *self._figures]),
        }

    def commit(self) -> list[Path]:
        """Stage every collected file under a temporary name (the slow part: CSVs, PNGs),
        then move them all into place with ``os.replace``, ``run.json`` last. Returns the
        paths. Until the staging is complete, the previous run's files are untouched."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        writers: dict[str, Callable[[Path], object]] = {}
        for name, frame in self._frames.items():
            writers[name] = functools.partial(frame.to_csv, index=False)
        for name, figure in self._figures.items():
            writers[name] = functools.partial(figure.savefig, format="png", dpi=150)
        staged: list[tuple[Path, Path]] = []
        try:
            for name, write in writers.items():
                staged.append((stage(self.out_dir / name, write), self.out_dir / name))
            manifest = json.dumps(self.manifest("completed"), indent=2) + "\n"
            staged.append(
                (
                    stage(self.out_dir / MANIFEST, lambda tmp: tmp.write_text(manifest)),
                    self.out_dir / MANIFEST,
                )
            )
            for tmp, final in staged:
                os.replace(tmp, final)
            # files of the run this one replaces (listed in its manifest) that this run did
            # not write: remove them, so the folder holds one run, as run.json says
            for name in set(self.previous.get("files", [])) - set(writers):
                stale = self.out_dir / Path(name).name
                if stale.is_file():
                    stale.unlink()
        finally:
            for tmp, _ in staged:
                tmp.unlink(missing_ok=True)
        return [final for _, final in staged]
