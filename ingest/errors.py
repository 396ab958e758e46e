"""Errors raised for bad observation files."""

from __future__ import annotations

from pathlib import Path

__all__ = ["FormatError"]


class FormatError(ValueError):
    """A file that cannot be read as an observation, with where and why.

    Parameters
    ----------
    path : str or Path
        The offending file.
    line : int or None
        1-based line number in the file, or None when the problem is not tied to a line
        (empty file, undecodable bytes, unknown format).
    reason : str
        One sentence: what is wrong and, where it helps, what to do.

    The message reads ``path:line: reason`` (or ``path: reason``), like a compiler's.
    """

    def __init__(self, path: str | Path, line: int | None, reason: str):
        self.path = str(path)
        self.line = line
        self.reason = reason
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {reason}")

    def __reduce__(self):
        # Errors cross process pools (ingest workers, Dask); rebuild from the three fields.
        return type(self), (self.path, self.line, self.reason)
