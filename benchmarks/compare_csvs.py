"""Compare every CSV of two output folders (e.g. two `bounce study` runs): same files, same
columns and rows, text cells equal, numbers equal within a tolerance:
|a - b| <= atol + rtol max(|a|, |b|).

    python benchmarks/compare_csvs.py OLD_DIR NEW_DIR [--rtol 1e-9] [--atol 1e-11]

The absolute part is for quantities that are rounding itself or a difference of two large
ones: an ACF's SD at lag 0 (1e-16 or 0), a contact's duration (1e-4 s, the difference of two
times near 10 s, each exact to 1e-15 relative). 1e-11 in a table of metres, seconds and
metres per second is far below any measurement's resolution.

Prints one line per file (identical bytes; equal within tolerance, with the largest relative
difference of the values beyond atol; or what differs) and exits 1 when any file differs
beyond the tolerance.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd


def compare(old: Path, new: Path, rtol: float, atol: float = 0.0) -> tuple[str, bool]:
    """(a line, whether the two files agree within atol + rtol max(|a|, |b|))."""
    if old.read_bytes() == new.read_bytes():
        return "identical bytes", True
    a, b = pd.read_csv(old), pd.read_csv(new)
    if list(a.columns) != list(b.columns) or a.shape != b.shape:
        return f"shape or columns differ: {a.shape} vs {b.shape}", False
    worst, where, agree = 0.0, "", True
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
            agree = agree and bool(np.all(diff <= atol + rtol * scale))
            beyond_atol = diff > atol
            rel = np.where(beyond_atol & (scale > 0), diff / np.where(scale > 0, scale, 1.0),
                           0.0)
            if rel.size and rel.max() > worst:
                worst, where = float(rel.max()), column
        elif not x.astype(str).equals(y.astype(str)):
            return f"{column}: text differs", False
    verdict = "within tolerance" if agree else "BEYOND TOLERANCE"
    return f"{verdict} (largest relative difference {worst:.3g} in {where})", agree


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", type=Path)
    parser.add_argument("new", type=Path)
    parser.add_argument("--rtol", type=float, default=1e-9)
    parser.add_argument("--atol", type=float, default=1e-11)
    args = parser.parse_args(argv)
    old = {p.relative_to(args.old) for p in args.old.rglob("*.csv")}
    new = {p.relative_to(args.new) for p in args.new.rglob("*.csv")}
    bad = 0
    for name in sorted(old ^ new):
        print(f"{name}: only in {'old' if name in old else 'new'}")
        bad += 1
    counts = {"identical": 0, "within": 0}
    for name in sorted(old & new):
        line, ok = compare(args.old / name, args.new / name, args.rtol, args.atol)
        counts["identical" if line == "identical bytes" else "within"] += ok
        if line != "identical bytes":
            print(f"{name}: {line}")
        bad += not ok
    print(f"{len(old & new)} CSVs in both: {counts['identical']} identical, "
          f"{counts['within']} within rtol {args.rtol:g} + atol {args.atol:g}, {bad} differ")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
