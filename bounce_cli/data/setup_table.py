"""The set-up table (``setup.csv``): what a recording shows of the physical set-up, written by
``bounce extract`` beside ``impacts.csv`` and read by the data analyses (``--data``), so that
the model runs at the data's own parameters.

One row per measured quantity, columns ``quantity, estimate, se, n, note``:

==============================  ===============================================================
``g_m_s2``                      gravity of the set-up from the ball's free flights, m/s^2
``alpha``                       mean coefficient of restitution (eq. 3, per impact), 1
``alpha_sd``                    its SD across impacts, 1
``contact_s``                   mean time the ball is off its free flights at an impact, s
``ball_offset_m``               ball marker above the racket marker at the equivalent impact, m
``position_noise_m``            residual SD of the ball's flight fits, m
``racket_noise_m``              residual SD of the racket's local fits, m
``measurement_sd_v_m_s``        typical standard error of an extracted v_k, m/s
``measurement_sd_theta_rad``    typical standard error of an extracted theta_k, rad
``event_lag_s``                 with events: their times less the ball's contacts, median, s
==============================  ===============================================================

A lab may write the table itself; every row is optional, and a missing file is an empty set-up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ..runtime.config import ConfigError

#: the file's name, beside the impacts table it describes
SETUP_FILE = "setup.csv"
#: its columns, in this order
SETUP_COLUMNS: tuple[str, ...] = ("quantity", "estimate", "se", "n", "note")


@dataclass(frozen=True)
class SetupQuantity:
    """One measured quantity of the set-up: its estimate, standard error (NaN when unknown),
    the number of observations it rests on, and a note (how it was measured)."""

    quantity: str
    estimate: float
    se: float = math.nan
    n: int = 0
    note: str = ""


def setup_frame(quantities: list[SetupQuantity]) -> pd.DataFrame:
    """The set-up table as a DataFrame (one row per quantity, in the order given).

    Parameters
    ----------
    quantities : list of SetupQuantity
        The measured quantities; names must be unique.

    Returns
    -------
    pandas.DataFrame
        Columns ``quantity, estimate, se, n, note``.
    """
    names = [q.quantity for q in quantities]
    if len(set(names)) != len(names):
        raise ValueError(f"setup quantities named twice: {sorted(names)}")
    return pd.DataFrame(
        {
            "quantity": names,
            "estimate": [float(q.estimate) for q in quantities],
            "se": [float(q.se) for q in quantities],
            "n": [int(q.n) for q in quantities],
            "note": [q.note for q in quantities],
        },
        columns=list(SETUP_COLUMNS),
    )


def setup_path(impacts_path: str | Path) -> Path:
    """The ``setup.csv`` beside an impacts table."""
    return Path(impacts_path).with_name(SETUP_FILE)


def read_setup(impacts_path: str | Path) -> dict[str, SetupQuantity]:
    """The set-up measured with an impacts table: ``setup.csv`` beside it, by quantity name.

    Parameters
    ----------
    impacts_path : str or Path
        The impacts table (``impacts.csv``); its folder is searched for ``setup.csv``.

    Returns
    -------
    dict of str to SetupQuantity
        Empty when there is no ``setup.csv``.

    Raises
    ------
    ConfigError
        When the file exists but lacks a column, names a quantity twice, or holds an estimate
        that is not a finite number (one line naming the file).
    """
    path = setup_path(impacts_path)
    if not path.is_file():
        return {}
    try:
        frame = pd.read_csv(path, keep_default_na=False, na_values=[""])
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ConfigError(f"data: {path}: cannot read as CSV: {first}") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    missing = [c for c in ("quantity", "estimate") if c not in frame.columns]
    if missing:
        raise ConfigError(f"data: {path}: missing column(s) {', '.join(missing)} "
                          f"(a set-up table has {', '.join(SETUP_COLUMNS)})")
    out: dict[str, SetupQuantity] = {}
    for row, record in enumerate(frame.to_dict("records"), start=2):
        name = str(record["quantity"]).strip()
        if name in out:
            raise ConfigError(f"data: {path}: line {row}: quantity {name!r} given twice")
        estimate = pd.to_numeric(pd.Series([record["estimate"]]), errors="coerce").iloc[0]
        if not math.isfinite(float(estimate)):
            raise ConfigError(f"data: {path}: line {row}: estimate of {name!r} is not a finite "
                              f"number (got {record['estimate']!r})")
        se = pd.to_numeric(pd.Series([record.get("se", math.nan)]), errors="coerce").iloc[0]
        n = pd.to_numeric(pd.Series([record.get("n", 0)]), errors="coerce").iloc[0]
        note = record.get("note", "")
        out[name] = SetupQuantity(
            quantity=name,
            estimate=float(estimate),
            se=float(se),
            n=int(n) if math.isfinite(float(n)) else 0,
            note="" if not isinstance(note, str) else note,
        )
    return out
