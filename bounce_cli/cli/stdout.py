"""Standard output as the commands see it during ``bounce``'s run: watched, so that a write
that failed (``> /dev/full``) is told from a failure to write a results file. Its own module,
so that the console script (which installs it) and the commands (which ask it) both import it
and not each other."""

from __future__ import annotations

import sys


class WatchedStdout:
    """Standard output as the commands see it (``sys.stdout`` during :func:`main`): the same
    stream, remembering a write or flush that failed (a full disk or ``/dev/full``, a closed
    pipe), so that :func:`main` can tell that failure from one of a results file."""

    def __init__(self, stream) -> None:
        self._stream = stream
        self.failure: OSError | None = None

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except OSError as exc:
            self.failure = exc
            raise

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as exc:
            self.failure = exc
            raise

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def stdout_failed() -> bool:
    """Whether a write to standard output failed in this run (:class:`WatchedStdout`)."""
    return isinstance(sys.stdout, WatchedStdout) and sys.stdout.failure is not None
