"""The memory a config value may make a run allocate: one check, before the allocation, so
that a mistyped count (a grid of 1e9 points, a run of 1e9 bounces) is one line naming it and
the memory it would need, not a ``MemoryError`` or a machine swapping.

Standard library only, and a room of its own below the model (the engine's modules call it as
well as the configs' validators).
"""

from __future__ import annotations

from .errors import ConfigError

#: the most memory one array sized by config values may take, bytes: far above any run of the
#: paper (its largest array, a 1000 x 1000 basin's column, is 8 MB), below the machines' memory
MAX_ARRAY_BYTES = 4_000_000_000


def format_bytes(n: float) -> str:
    """``n`` bytes in decimal units, as disk and memory sizes are quoted: ``7.5 GB``."""
    for unit in ("bytes", "kB", "MB", "GB", "TB"):
        if n < 1000:
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:,.0f} PB"


def check_array_memory(count: float, what: str, fix: str, bytes_each: int = 8) -> None:
    """Refuse an array of ``count`` elements of ``bytes_each`` bytes larger than
    :data:`MAX_ARRAY_BYTES`, before it is allocated.

    Parameters
    ----------
    count : float
        Elements of the array (a product of config values; a float, so that it cannot
        overflow).
    what : str
        What the array holds, naming the config values, e.g. ``grid.n_alpha x grid.n_ac =
        1,000 x 1,000,000,000 points``.
    fix : str
        How to make it smaller, e.g. ``reduce grid.n_alpha or grid.n_ac``.
    bytes_each : int
        Bytes per element (8: a float64).

    Raises
    ------
    ConfigError
        One line: what, the memory it would need, the limit and the fix. (A ``ValueError``:
        inside a pydantic validator it is reported as the block's problem.)
    """
    need = float(count) * bytes_each
    if need > MAX_ARRAY_BYTES:
        raise ConfigError(f"{what} would need about {format_bytes(need)} of memory for one "
                          f"array, more than the {format_bytes(MAX_ARRAY_BYTES)} a run may "
                          f"take; {fix}")
