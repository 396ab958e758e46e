"""Whitespace-separated data rows parsed in one vectorised pass, with file line numbers.

The fast path is one `numpy.loadtxt` call with a structured dtype (C parser, exact column
count enforced). Only when it fails does `_diagnose` tokenise the bytes with numpy to report
the first offending line, column and value, so a clean 2500-row file parses in a few ms and
a bad one still gets a precise message.
"""

from __future__ import annotations

from dataclasses import dataclass
import io

import numpy as np

from ingest.textfile import TextFile

__all__ = [
    "Column",
    "Rows",
    "read_rows",
    "check_rows",
    "check_parsed",
    "check_increasing",
    "ELEVATION",
    "POSITIVE_RANGE",
]


@dataclass(frozen=True)
class Column:
    """One column of a data table.

    Attributes
    ----------
    key : str
        Field name in the parsed array.
    label : str
        The column as the file names it (used in messages).
    kind : str
        ``"float"`` (finite numbers required) or ``"text"`` (kept as bytes).
    width : int
        Bytes kept for text columns; longer tokens are truncated.
    """

    key: str
    label: str
    kind: str = "float"
    width: int = 32


@dataclass(frozen=True, eq=False)
class Rows:
    """Parsed data rows.

    Attributes
    ----------
    columns : dict of str to (n,) array
        One contiguous array per `Column` key (float64, or fixed-width bytes for text).
    line : (n,) int64
        1-based file line of each row.
    """

    columns: dict
    line: np.ndarray

    def __len__(self) -> int:
        return len(self.line)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.columns[key]


def _dtype(columns: tuple[Column, ...]) -> np.dtype:
    return np.dtype([(c.key, np.float64 if c.kind == "float" else f"S{c.width}") for c in columns])


def read_rows(text: TextFile, first_line: int, columns: tuple[Column, ...]) -> Rows:
    """Parse lines `first_line`.. of `text` as rows of `columns`; blank lines are skipped.

    Raises
    ------
    FormatError
        No rows; a row with another number of columns (a last row cut short is reported as a
        truncated file); a value that is not a number; a NaN or infinite value.
    """
    body_lines = np.arange(first_line, text.n_lines + 1)
    body = text.data[text.offset(first_line) :]
    if not body or body.isspace():
        raise text.error(first_line, "the header is not followed by any data rows")
    try:
        values = np.loadtxt(io.BytesIO(body), dtype=_dtype(columns), comments=None, ndmin=1)
    except ValueError as exc:
        raise _diagnose(text, first_line, columns, exc) from None
    nonblank = body_lines if len(values) == len(body_lines) else body_lines[~text.blank[first_line - 1 :]]
    if len(nonblank) != len(values):
        raise text.error(None, f"found {len(values)} data rows in {len(nonblank)} non-blank lines; the file is damaged")
    rows = Rows({c.key: np.ascontiguousarray(values[c.key]) for c in columns}, nonblank.astype(np.int64))
    _check_finite(text, rows, columns)
    return rows


def check_rows(text: TextFile, rows: Rows, columns: tuple[Column, ...], checks) -> None:
    """Raise at the first row whose value fails its check, quoting the value as written.

    Parameters
    ----------
    checks : iterable of (key, predicate, reason)
        `predicate` maps the (n,) column to a bool array (True = good); `reason` completes the
        sentence "<label> <value> <reason>".
    """
    keys = [c.key for c in columns]
    for key, good, reason in checks:
        bad = np.flatnonzero(~good(rows[key]))
        if len(bad):
            line = int(rows.line[bad[0]])
            index = keys.index(key)
            raise text.error(line, f"{columns[index].label} {text.line(line).split()[index]} {reason}")


def check_parsed(text: TextFile, rows: Rows, ok: np.ndarray, key: str, label: str, reason: str) -> None:
    """Raise at the first row whose text column `key` did not parse (`ok` False), quoting it."""
    bad = np.flatnonzero(~ok)
    if len(bad):
        value = rows[key][bad[0]].decode("utf-8", "replace")
        raise text.error(int(rows.line[bad[0]]), f"{label} {value!r} {reason}")


def check_increasing(text: TextFile, rows: Rows, stamps_ns: np.ndarray, time_keys: tuple[str, ...]) -> None:
    """Raise at the first row whose time is not after the previous row's.

    Parameters
    ----------
    stamps_ns : (n,) int64
        The rows' times.
    time_keys : tuple of str
        The text columns that hold the time, quoted in the message as the file writes them.
    """
    step = np.diff(stamps_ns)
    bad = np.flatnonzero(step <= 0)
    if len(bad):
        k = int(bad[0])
        kind = "repeats" if step[k] == 0 else "is earlier than"
        this, previous = (
            " ".join(rows[key][row].decode("utf-8", "replace") for key in time_keys) for row in (k + 1, k)
        )
        raise text.error(
            int(rows.line[k + 1]),
            f"time {this} {kind} the previous row's {previous} "
            f"(line {int(rows.line[k])}); rows must be in time order without repeats",
        )


# Checks shared by the formats' geometry columns.
ELEVATION = ("el_deg", lambda v: np.abs(v) <= 90, "is not an elevation in degrees (-90..90)")
POSITIVE_RANGE = ("range_km", lambda v: v > 0, "is not a positive range")


def _check_finite(text: TextFile, rows: Rows, columns: tuple[Column, ...]) -> None:
    for index, column in enumerate(columns):
        if column.kind != "float":
            continue
        bad = np.flatnonzero(~np.isfinite(rows[column.key]))
        if len(bad):
            line = int(rows.line[bad[0]])
            token = text.line(line).split()[index]
            raise text.error(line, f"{column.label} is {token!r}; every value must be a finite number")


def _tokens(text: TextFile, first_line: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start and end byte offsets of every whitespace-separated token from `first_line` on,
    and the 1-based line of each."""
    base = text.offset(first_line)
    buf = np.frombuffer(text.data, dtype=np.uint8)[base:]
    ink = np.concatenate([[False], buf > 32, [False]])
    starts = np.flatnonzero(ink[1:] & ~ink[:-1])
    ends = np.flatnonzero(~ink[1:] & ink[:-1])
    line = np.searchsorted(text.line_ends, starts + base) + 1
    return starts + base, ends + base, line


def _diagnose(text: TextFile, first_line: int, columns: tuple[Column, ...], exc: Exception):
    """Find the first bad line after `numpy.loadtxt` refused the rows; return the FormatError."""
    starts, ends, line = _tokens(text, first_line)
    counts = np.bincount(line - first_line, minlength=text.n_lines - first_line + 1)
    expected = len(columns)
    wrong = np.flatnonzero((counts != expected) & (counts > 0))
    if len(wrong):
        bad_line = int(wrong[0]) + first_line
        found = int(counts[wrong[0]])
        if bad_line == text.n_lines and found < expected and not text.ends_with_newline:
            return text.error(
                bad_line,
                f"the last row has {found} of {expected} columns and no line end: the file looks truncated",
            )
        labels = " ".join(c.label for c in columns)
        return text.error(bad_line, f"the row has {found} columns, expected {expected} ({labels})")
    n_rows = len(starts) // expected
    starts = starts.reshape(n_rows, expected)
    ends = ends.reshape(n_rows, expected)
    row_line = line.reshape(n_rows, expected)[:, 0]
    first_bad = None
    for index, column in enumerate(columns):
        if column.kind != "float":
            continue
        tokens = _token_strings(text.data, starts[:, index], ends[:, index])
        bad = np.flatnonzero(~_parses_as_float(tokens))
        if len(bad) and (first_bad is None or bad[0] < first_bad[0]):
            first_bad = (int(bad[0]), column, tokens[bad[0]])
    if first_bad is not None:
        row, column, token = first_bad
        return text.error(int(row_line[row]), f"{column.label} is {token!r}, which is not a number")
    return text.error(None, f"the data rows cannot be parsed ({exc})")


def _token_strings(data: bytes, starts: np.ndarray, ends: np.ndarray) -> list[str]:
    """The tokens between `starts` and `ends` as text (error path only)."""
    return [data[s:e].decode("utf-8", "replace") for s, e in zip(starts.tolist(), ends.tolist())]


def _parses_as_float(tokens: list[str]) -> np.ndarray:
    """(n,) bool: which tokens `float()` accepts (error path only; vectorised via numpy's cast)."""
    array = np.array(tokens, dtype=object)
    ok = np.ones(len(array), dtype=bool)
    # Cast in chunks; a failing chunk is split until the bad tokens are isolated.
    pending = [(0, len(array))]
    while pending:
        lo, hi = pending.pop()
        try:
            array[lo:hi].astype(np.float64)
        except (ValueError, TypeError):
            if hi - lo == 1:
                ok[lo] = False
            else:
                mid = (lo + hi) // 2
                pending += [(lo, mid), (mid, hi)]
    return ok
