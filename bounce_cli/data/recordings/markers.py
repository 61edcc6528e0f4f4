"""Marker-based recordings (C3D and the vendors' text exports): markers chosen by label.

A label is found as written, or, when no label is exactly it, as the part after the last
``:`` of a ``Subject:Marker`` label (Vicon, Motive) if only one label has that part. The
racket's height is the mean of its markers' heights (a racket face carries three or four), a
gap wherever one of them is missing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...runtime.config import ConfigError


@dataclass(frozen=True)
class MarkerSet:
    """A file's markers: ``labels``, ``xyz`` (sample, marker, 3) in metres with NaN for gaps,
    ``t`` (s) on the capture clock; ``kinds``: label -> the group of a point that is not a
    position (C3D's POINT:MOMENTS, ...)."""

    labels: list[str]
    xyz: np.ndarray
    t: np.ndarray
    kinds: dict[str, str] = field(default_factory=dict)


def marker_index(path: Path, markers: MarkerSet, name: str, key: str) -> int:
    """The column of marker ``name`` (module doc); a missing, doubled, ambiguous or
    non-position marker is a one-line ConfigError naming ``key``.

    Parameters
    ----------
    path : Path
        The file (for messages).
    markers : MarkerSet
        The file's markers.
    name : str
        The label asked for.
    key : str
        The config key that names it.

    Returns
    -------
    int
    """
    where = [i for i, label in enumerate(markers.labels) if label == name]
    if not where:
        where = [i for i, label in enumerate(markers.labels)
                 if ":" in label and label.rsplit(":", 1)[1] == name]
        if len(where) > 1:
            raise ConfigError(f"{path}: marker {name!r} is ambiguous: "
                              f"{', '.join(markers.labels[i] for i in where)} (set {key} to "
                              "one of them)")
    elif len(where) > 1:
        raise ConfigError(f"{path}: marker {name!r} is named {len(where)} times (columns or "
                          f"points {', '.join(str(i + 1) for i in where)}): rename it in the "
                          "file")
    if not where:
        shown = ", ".join(markers.labels[:40]) + (", ..." if len(markers.labels) > 40 else "")
        raise ConfigError(f"{path}: no marker {name!r} (set {key}; the file has: {shown})")
    label = markers.labels[where[0]]
    if label in markers.kinds:
        raise ConfigError(f"{path}: point {label!r} is listed in {markers.kinds[label]}, not a "
                          f"marker position (set {key} to a marker)")
    return where[0]


def marker_heights(path: Path, markers: MarkerSet, racket: list[str], ball: str | None,
                   axis: str):
    """(racket height, ball height or None) in metres along the vertical ``axis``: the
    racket's is the mean of its markers' (NaN where any is missing).

    Parameters
    ----------
    path : Path
        The file (for messages).
    markers : MarkerSet
        The file's markers.
    racket : list of str
        The racket's marker labels.
    ball : str or None
        The ball's marker label.
    axis : str
        ``x``, ``y`` or ``z``.

    Returns
    -------
    tuple of numpy.ndarray
    """
    column = "xyz".index(axis)
    chosen = [marker_index(path, markers, name, "markers.racket") for name in racket]
    if len(set(chosen)) < len(chosen):
        raise ConfigError(f"{path}: markers.racket names a marker twice ({', '.join(racket)})")
    racket_height = markers.xyz[:, chosen, column].mean(axis=1)
    ball_height = (markers.xyz[:, marker_index(path, markers, ball, "markers.ball"), column]
                   if ball is not None else None)
    return racket_height, ball_height
