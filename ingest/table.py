"""Data rows parsed in one vectorised pass, with file line numbers and row-level problems.

The fast path is one `numpy.loadtxt` call with a structured dtype (C parser, exact column
count enforced). Only when it fails are the lines checked one by one, so a clean 2500-row file
parses in a few ms while a file with a few damaged rows keeps its good ones: each bad row (wrong
number of columns, a value that is not a number, NaN or infinity, a last row cut short) becomes
an `ingest.problems.RowProblem` and the rest is parsed again. `RowFlags` collects the problems a
reader finds in the parsed values (times out of order, impossible values) and
`RowFlags.finish` refuses the file when they are widespread (`MAX_DAMAGED_FRACTION`).
"""

from __future__ import annotations

from dataclasses import dataclass
import io
import re

import numpy as np

from ingest.problems import MAX_DAMAGED_FRACTION, MIN_GOOD_ROWS, RowProblem, kept_in_time_order, time_order_reasons
from ingest.textfile import TextFile

__all__ = [
    "Column",
    "Rows",
    "RowFlags",
    "read_rows",
    "ELEVATION",
    "POSITIVE_RANGE",
    "MAX_RANGE_KM",
]

# A number as numpy's parser and Python's float() both read it (no '_' digit separators).
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf|infinity)$", re.IGNORECASE)


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
        ``"float"`` or ``"text"`` (kept as bytes).
    width : int
        Bytes kept for text columns; longer tokens are truncated.
    finite : bool
        Whether a float must be finite (a NaN or infinity sets the row aside); False lets NaN
        mean "no value" (CSV light curves).
    """

    key: str
    label: str
    kind: str = "float"
    width: int = 32
    finite: bool = True


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

    def select(self, keep: np.ndarray) -> Rows:
        """The rows where `keep` is True."""
        if bool(np.all(keep)):
            return self
        return Rows({key: np.ascontiguousarray(value[keep]) for key, value in self.columns.items()}, self.line[keep])


def _dtype(columns: tuple[Column, ...]) -> np.dtype:
    return np.dtype([(c.key, np.float64 if c.kind == "float" else f"S{c.width}") for c in columns])


def read_rows(
    text: TextFile, first_line: int, columns: tuple[Column, ...], delimiter: str | None = None
) -> tuple[Rows, list[RowProblem]]:
    """Parse lines `first_line`.. of `text` as rows of `columns`; blank lines are skipped.

    Parameters
    ----------
    delimiter : str, optional
        Column separator (default: runs of whitespace).

    Returns
    -------
    rows : Rows
        The rows that parsed, every float finite.
    problems : list of RowProblem
        The rows set aside: wrong number of columns, a value that is not a number or not finite,
        a last row cut short (no line end and fewer digits in its last value than the row above).

    Raises
    ------
    FormatError
        When no data rows follow the header.
    """
    body = text.data[text.offset(first_line) :]
    if not body or body.isspace():
        raise text.error(first_line, "the header is not followed by any data rows")
    body_lines = np.arange(first_line, text.n_lines + 1)
    try:
        values = np.loadtxt(io.BytesIO(body), dtype=_dtype(columns), comments=None, ndmin=1, delimiter=delimiter)
        problems: list[RowProblem] = []
        # The blank-line table costs 8 bytes per byte of the file: only when some line was skipped.
        lines = body_lines if len(values) == len(body_lines) else body_lines[~text.blank[first_line - 1 :]]
        if len(values) != len(lines):
            raise ValueError("row count")
    except ValueError:
        nonblank = body_lines[~text.blank[first_line - 1 :]]
        values, lines, problems = _parse_line_by_line(text, nonblank, columns, delimiter)
    rows = Rows({c.key: np.ascontiguousarray(values[c.key]) for c in columns}, lines.astype(np.int64))
    flags = RowFlags(text, rows, n_rows=len(rows) + len(problems), problems=problems)
    for column in columns:
        if column.kind == "float" and column.finite:
            flags.check(
                column.key,
                np.isfinite(rows[column.key]),
                lambda token, label=column.label: f"{label} is {token!r}; every value must be a finite number",
                columns,
                delimiter,
            )
    if not text.ends_with_newline:
        _check_last_row_whole(text, rows, columns, flags, delimiter)
    return rows.select(flags.keep), flags.problems


class RowFlags:
    """Rows a reader sets aside, with the first reason found for each.

    Parameters
    ----------
    text : TextFile
    rows : Rows
        The parsed rows the flags refer to (by position).
    n_rows : int
        Data rows of the file, counting those already set aside by the parser.
    problems : list of RowProblem
        Rows already set aside (by the parser).
    """

    def __init__(self, text: TextFile, rows: Rows, n_rows: int, problems: list[RowProblem] = ()):
        self.text = text
        self.rows = rows
        self.n_rows = n_rows
        self._earlier = list(problems)
        self._reasons: dict[int, str] = {}

    @property
    def keep(self) -> np.ndarray:
        """(n,) bool: rows not set aside."""
        keep = np.ones(len(self.rows), dtype=bool)
        keep[list(self._reasons)] = False
        return keep

    def flag(self, bad: np.ndarray, reasons) -> None:
        """Set aside the rows where `bad` is True; `reasons(i)` words the reason for row i."""
        if not bad.any():  # the common case: a check that every row passes
            return
        for i in np.flatnonzero(bad).tolist():
            if i not in self._reasons:
                self._reasons[i] = reasons(i)

    def check(self, key: str, good: np.ndarray, reason, columns: tuple[Column, ...], delimiter=None) -> None:
        """Set aside rows where `good` is False; `reason(token)` words it from the value as written."""
        index = [c.key for c in columns].index(key)

        def word(i: int) -> str:
            tokens = _split(self.text.line(int(self.rows.line[i])), delimiter)
            return reason(tokens[index] if index < len(tokens) else "")

        self.flag(~np.asarray(good, dtype=bool), word)

    def values(self, columns: tuple[Column, ...], checks, delimiter=None) -> None:
        """Physical bounds: each ``(key, predicate, reason)`` sets aside the rows failing it,
        quoting the value as written ("<label> <value> <reason>")."""
        labels = {c.key: c.label for c in columns}
        for key, good, reason in checks:
            ok = good(self.rows[key])
            self.check(key, ok, lambda token, k=key, r=reason: f"{labels[k]} {token} {r}", columns, delimiter)

    def time_order(self, stamps_ns: np.ndarray, labels) -> None:
        """Set aside the fewest rows that break strict time order (among rows still kept).

        Parameters
        ----------
        stamps_ns : (n,) int64
        labels : callable
            ``labels(i)`` gives row i's time as the file writes it.
        """
        candidates = np.flatnonzero(self.keep)
        keep = kept_in_time_order(stamps_ns[candidates])
        if bool(keep.all()):
            return
        words = time_order_reasons(
            stamps_ns[candidates], keep, self.rows.line[candidates], [labels(int(i)) for i in candidates]
        )
        for i, reason in zip(candidates[~keep].tolist(), words):
            self._reasons[i] = reason

    @property
    def problems(self) -> list[RowProblem]:
        """Every row set aside so far, in file order."""
        found = [
            RowProblem(int(self.rows.line[i]), reason, self.text.line(int(self.rows.line[i])))
            for i, reason in self._reasons.items()
        ]
        return sorted(self._earlier + found, key=lambda problem: problem.line)

    def finish(self) -> tuple[np.ndarray, tuple[RowProblem, ...]]:
        """The rows to keep and the problems; refuse the file when the damage is widespread.

        Raises
        ------
        FormatError
            When more than `MAX_DAMAGED_FRACTION` of the data rows, or all but one, are set aside.
        """
        problems = self.problems
        keep = self.keep
        n_good = int(keep.sum())
        if problems and (len(problems) > MAX_DAMAGED_FRACTION * self.n_rows or n_good < MIN_GOOD_ROWS):
            first = problems[0]
            share = f"{len(problems)} of {self.n_rows} data rows are damaged"
            raise self.text.error(
                first.line,
                f"{first.reason} ({share}, more than the {MAX_DAMAGED_FRACTION:.0%} a file may lose"
                + (f", and {n_good} good row(s) are too few" if n_good < MIN_GOOD_ROWS else "")
                + "; check that this is the file you meant)",
            )
        return keep, tuple(problems)


# Checks shared by the formats' geometry columns. Beyond a million km (2.5 lunar distances) a
# range is not a topocentric range to an Earth satellite.
MAX_RANGE_KM = 1.0e6
ELEVATION = ("el_deg", lambda v: np.abs(v) <= 90, "is not an elevation in degrees (-90..90)")
POSITIVE_RANGE = (
    "range_km",
    lambda v: (v > 0) & (v <= MAX_RANGE_KM),
    f"is not a range to an Earth satellite (0 < range <= {MAX_RANGE_KM:.0e} km)",
)


def _split(line: str, delimiter: str | None) -> list[str]:
    return line.split() if delimiter is None else [token.strip() for token in line.split(delimiter)]


def _parse_line_by_line(text: TextFile, lines: np.ndarray, columns: tuple[Column, ...], delimiter: str | None):
    """The slow path, for files with bad rows: check each line, then parse the good ones at once."""
    expected = len(columns)
    labels = " ".join(c.label for c in columns)
    numeric = [i for i, c in enumerate(columns) if c.kind == "float"]
    good, problems = [], []
    for number in lines.tolist():
        raw = text.line(number)
        tokens = _split(raw, delimiter)
        if len(tokens) != expected:
            if number == text.n_lines and len(tokens) < expected and not text.ends_with_newline:
                reason = (
                    f"the last row has {len(tokens)} of {expected} columns and no line end: the file looks truncated"
                )
            else:
                reason = f"the row has {len(tokens)} columns, expected {expected} ({labels})"
            problems.append(RowProblem(number, reason, raw))
            continue
        bad = next((i for i in numeric if not _NUMBER.match(tokens[i])), None)
        if bad is not None:
            reason = f"{columns[bad].label} is {tokens[bad]!r}, which is not a number"
            problems.append(RowProblem(number, reason, raw))
            continue
        good.append(number)
    kept = np.array(good, dtype=np.int64)
    if not len(kept):
        return np.empty(0, dtype=_dtype(columns)), kept, problems
    body = b"\n".join(text.data[text.offset(k) : text.line_ends[k - 1]] for k in good)
    try:
        values = np.loadtxt(io.BytesIO(body), dtype=_dtype(columns), comments=None, ndmin=1, delimiter=delimiter)
    except ValueError as exc:
        raise text.error(None, f"the data rows cannot be parsed ({exc})") from None
    return values, kept, problems


def _decimals(token: str) -> int | None:
    """Digits after the decimal point of a plain decimal number; None for other spellings."""
    if not re.fullmatch(r"[+-]?\d*\.?\d*", token):
        return None
    return len(token.partition(".")[2])


def _check_last_row_whole(
    text: TextFile, rows: Rows, columns: tuple[Column, ...], flags: RowFlags, delimiter: str | None
) -> None:
    """A file without a final line end may have been cut inside its last row's last value
    (``2827.394`` read as ``28``): set that row aside when its last value has fewer decimals than
    the same column of the row above."""
    if len(rows) < 2 or columns[-1].kind != "float" or int(rows.line[-1]) != text.n_lines:
        return
    last, above = (_split(text.line(int(rows.line[i])), delimiter)[-1] for i in (-1, -2))
    digits_last, digits_above = _decimals(last), _decimals(above)
    if digits_last is None or digits_above is None or digits_last >= digits_above:
        return
    bad = np.zeros(len(rows), dtype=bool)
    bad[-1] = True
    flags.flag(
        bad,
        lambda _i: (
            f"the last row has no line end and its {columns[-1].label} {last!r} has fewer digits than the "
            f"rows above ({above!r}): the file was cut inside this row"
        ),
    )
