"""Finished tasks of a long run, kept on disk as they finish, so that an interrupted run
resumes without recomputing them (``bounce sweep --resume``).

``<out>/points/`` holds ``run.json`` (the command and resolved config the points belong to)
and one ``point-<index>.json`` per finished task, each written atomically (temporary name,
then ``os.replace``), so a kill at any moment leaves whole points only. JSON keeps floats
exactly (``repr`` round-trips), so a resumed run's tables are identical to an uninterrupted
run's. The folder is removed once the run's results are committed; an interrupted run's
stays (its one line says where, and that ``--resume`` continues).

A folder of another config is never resumed into, and finished points are never discarded
silently: without ``--resume`` a folder holding points is refused unless ``--force``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from .artifacts import OutputDirError, write_text_atomic

FOLDER = "points"
IDENTITY = "run.json"


def changed_keys(old: Any, new: Any, prefix: str = "") -> list[str]:
    """Dotted keys whose values differ between two nested dicts."""
    if isinstance(old, dict) and isinstance(new, dict):
        keys = sorted(set(old) | set(new))
        return [k for key in keys
                for k in changed_keys(old.get(key), new.get(key), f"{prefix}{key}.")]
    return [] if old == new else [prefix.rstrip(".") or "(all)"]


class PointFolder:
    """The checkpoint store of one run directory (see the module docstring).

    ``identity``: what the points are made from (command, resolved config); ``resume``:
    continue from the points found; ``force``: discard points found instead of refusing."""

    def __init__(self, out_dir: Path, identity: dict[str, Any], *, resume: bool,
                 force: bool) -> None:
        self.folder = Path(out_dir) / FOLDER
        self.identity = identity
        self._found: dict[int, Any] = {}
        stored = self._stored_identity()
        points = self._point_files()
        if stored is not None or points:
            if resume and stored == identity:
                self._found = {index: json.loads(path.read_text(encoding="utf-8"))
                               for index, path in points.items()}
            elif force:
                shutil.rmtree(self.folder)
            elif resume:
                changed = ", ".join(changed_keys(stored, identity)[:4])
                raise OutputDirError(
                    f"--resume: {self.folder} holds {len(points)} finished points of a run "
                    f"with a different config (changed: {changed}); run with --force "
                    f"instead of --resume to start over")
            elif points:
                raise OutputDirError(
                    f"--out {self.folder.parent}: holds {len(points)} finished points of an "
                    f"interrupted run in {FOLDER}/; use --resume to continue it or --force "
                    f"to start over")
        self.folder.mkdir(parents=True, exist_ok=True)
        write_text_atomic(self.folder / IDENTITY, json.dumps(identity, indent=1) + "\n")

    def _stored_identity(self) -> Any:
        try:
            return json.loads((self.folder / IDENTITY).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None

    def _point_files(self) -> dict[int, Path]:
        found = {}
        for path in self.folder.glob("point-*.json"):
            try:
                found[int(path.stem.split("-", 1)[1])] = path
            except ValueError:
                continue
        return found

    def load(self) -> dict[int, Any]:
        """The points found at the start (with ``resume``; else none)."""
        return dict(self._found)

    def save(self, index: int, result: Any) -> None:
        write_text_atomic(self.folder / f"point-{index:06d}.json", json.dumps(result) + "\n")

    def remove(self) -> None:
        """After the results are committed: the points are in them."""
        shutil.rmtree(self.folder, ignore_errors=True)

    def finished(self) -> int:
        """How many finished tasks the folder holds."""
        return len(self._point_files())

    def discard_if_empty(self) -> None:
        """After a failure before any point finished: leave no folder behind."""
        if not self._point_files():
            shutil.rmtree(self.folder, ignore_errors=True)
