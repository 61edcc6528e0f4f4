"""Which C3D files of a sample collection bounce's reader reads, against ezc3d.

    python benchmarks/c3d_samples.py DIRECTORY [DIRECTORY ...]

For every ``*.c3d`` under the directories (e.g. the Biomechanical ToolKit's BTKData
``Input/C3DSamples``, which holds the c3d.org reference samples): whether bounce's reader
(``bounce_cli.data.recordings.c3d_files.read_c3d_points``) reads it, with how many warnings, whether
ezc3d reads it (each in its own process: ezc3d can crash on a damaged file), and, where both
read it, whether every marker agrees to float32 rounding (relative 1e-6 of the file's largest
coordinate; gaps the same) and the labels are the same. Prints one line per file and the
fractions. Needs ``pip install ezc3d`` for the comparison column.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

EZC3D_SCRIPT = """
import sys, numpy as np, ezc3d
c = ezc3d.c3d(sys.argv[1])
points = c["data"]["points"][:3].transpose(2, 1, 0)
labels = list(c["parameters"]["POINT"]["LABELS"]["value"]) if points.shape[1] else []
np.savez(sys.argv[2], xyz=points, labels=np.array(labels, dtype=object))
"""


def ezc3d_points(path: Path, scratch: Path):
    """(xyz (frame, point, 3), labels) as ezc3d reads the file, or the reason it does not."""
    out = scratch / "ezc3d.npz"
    run = subprocess.run([sys.executable, "-c", EZC3D_SCRIPT, str(path), str(out)],
                         capture_output=True, text=True, timeout=300)
    if run.returncode != 0:
        lines = (run.stderr.strip().splitlines() or [f"exit {run.returncode}"])
        return None, lines[-1][:70]
    data = np.load(out, allow_pickle=True)
    return (data["xyz"], [str(s).strip() for s in data["labels"]]), ""


def compare(ours, theirs) -> str:
    """'agree' when both hold the same labels and coordinates to float32 rounding."""
    xyz, labels = theirs
    if xyz.shape != ours.xyz.shape:
        return f"shape {ours.xyz.shape} vs ezc3d {xyz.shape}"
    scale = np.nanmax(np.abs(ours.xyz)) if np.isfinite(ours.xyz).any() else 1.0
    gaps_ours, gaps_theirs = np.isnan(ours.xyz), np.isnan(xyz)
    # ezc3d keeps an invalid point's coordinates (or zeros); compare where both have values
    both = ~gaps_ours & ~gaps_theirs
    worst = float(np.max(np.abs(ours.xyz[both] - xyz[both]))) if both.any() else 0.0
    same_labels = labels[:len(ours.labels)] == ours.labels
    if worst <= 1e-6 * scale:
        verdict = "agree"
    else:
        # the reader whose marker paths are smooth is right (a shifted frame jumps)
        steps = [float(np.nanmedian(np.abs(np.diff(x, axis=0)))) for x in (ours.xyz, xyz)]
        verdict = (f"differ by {worst:.3g}; median step per frame: bounce {steps[0]:.3g}, "
                   f"ezc3d {steps[1]:.3g}")
    return verdict + ("" if same_labels else ", labels differ")


def main(directories: list[str]) -> None:
    import tempfile

    from bounce_cli.runtime.config import ConfigError
    from bounce_cli.data.recordings.c3d_files import read_c3d_points

    files = sorted(p for d in directories for p in Path(d).rglob("*")
                   if p.suffix.lower() == ".c3d")
    read = agree = ez_read = 0
    with tempfile.TemporaryDirectory() as scratch:
        for path in files:
            notes: list[str] = []
            try:
                ours = read_c3d_points(path, notes.append)
                mine = f"read ({len(notes)} warning(s))"
                read += 1
            except ConfigError as exc:
                ours, mine = None, "refused: " + str(exc).replace(str(path) + ": ", "")[:60]
            theirs, why = ezc3d_points(path, Path(scratch))
            ez_read += theirs is not None
            verdict = ""
            if ours is not None and theirs is not None:
                verdict = compare(ours, theirs)
                agree += verdict == "agree"
            print(f"{path.name[:34]:34s} bounce: {mine:40s} ezc3d: "
                  f"{'read' if theirs is not None else why[:40]:40s} {verdict}")
    print(f"bounce reads {read} of {len(files)} files; ezc3d {ez_read}; where both read a file, "
          f"markers agree in {agree}")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
