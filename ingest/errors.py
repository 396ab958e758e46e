"""Errors raised for bad observation files."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["FormatError", "printable_path"]


def printable_path(path) -> str:
    """A path as text that can be printed and stored: bytes that are not UTF-8 (which Python
    keeps as lone surrogates in str paths) are shown as ``\\xNN`` escapes.

    >>> printable_path(b"night/\\xff.phV".decode("utf-8", "surrogateescape"))
    'night/\\\\xff.phV'
    """
    raw = os.fsencode(path) if isinstance(path, (str, bytes, os.PathLike)) else str(path).encode()
    return raw.decode("utf-8", "backslashreplace")


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
        self.path = printable_path(path)
        self.line = line
        self.reason = reason
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {reason}")

    def __reduce__(self):
        # Errors cross process pools (ingest workers, Dask); rebuild from the three fields.
        return type(self), (self.path, self.line, self.reason)
