"""Compare every CSV of two output folders (e.g. two `bounce study` runs): same files, same
columns and rows, text cells equal, numbers equal within a relative tolerance.

    python benchmarks/compare_csvs.py OLD_DIR NEW_DIR [--rtol 1e-9]

Prints one line per file (identical bytes, equal within rtol with the largest relative
difference, or what differs) and exits 1 when any file differs beyond rtol.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd


def compare(old: Path, new: Path, rtol: float) -> tuple[str, bool]:
    """(a line, whether the two files agree within rtol)."""
    if old.read_bytes() == new.read_bytes():
        return "identical bytes", True
    a, b = pd.read_csv(old), pd.read_csv(new)
    if list(a.columns) != list(b.columns) or a.shape != b.shape:
        return f"shape or columns differ: {a.shape} vs {b.shape}", False
    worst, where = 0.0, ""
    for column in a.columns:
        x, y = a[column], b[column]
        if pd.api.types.is_numeric_dtype(x) and pd.api.types.is_numeric_dtype(y):
            xv, yv = x.to_numpy(float), y.to_numpy(float)
            same_nan = np.isnan(xv) == np.isnan(yv)
            if not same_nan.all():
                return f"{column}: NaN in different rows", False
            ok = ~np.isnan(xv)
            scale = np.maximum(np.abs(xv[ok]), np.abs(yv[ok]))
            diff = np.abs(xv[ok] - yv[ok])
            rel = np.where(scale > 0, diff / np.where(scale > 0, scale, 1.0), 0.0)
            if rel.size and rel.max() > worst:
                worst, where = float(rel.max()), column
        elif not x.astype(str).equals(y.astype(str)):
            return f"{column}: text differs", False
    return f"within rtol (largest relative difference {worst:.3g} in {where})", worst <= rtol


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", type=Path)
    parser.add_argument("new", type=Path)
    parser.add_argument("--rtol", type=float, default=1e-9)
    args = parser.parse_args(argv)
    old = {p.relative_to(args.old) for p in args.old.rglob("*.csv")}
    new = {p.relative_to(args.new) for p in args.new.rglob("*.csv")}
    bad = 0
    for name in sorted(old ^ new):
        print(f"{name}: only in {'old' if name in old else 'new'}")
        bad += 1
    counts = {"identical": 0, "within": 0}
    for name in sorted(old & new):
        line, ok = compare(args.old / name, args.new / name, args.rtol)
        counts["identical" if line == "identical bytes" else "within"] += ok
        if line != "identical bytes":
            print(f"{name}: {line}")
        bad += not ok
    print(f"{len(old & new)} CSVs in both: {counts['identical']} identical, "
          f"{counts['within']} within rtol {args.rtol:g}, {bad} differ")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
