"""Problems of single rows and mismatches between a file's header and its data.

A real file can hold a few damaged rows (a clock glitch that stamps a frame with an earlier
time, a row cut short, a value no instrument can give) among thousands of good ones. Readers set
such rows aside as `RowProblem` s, which travel with the pass (and are stored with it), and
refuse the file only when the damage is widespread: more than `MAX_DAMAGED_FRACTION` of its data
rows. A header that disagrees with the data (an end time far after the last row, a filter letter
that contradicts the magnitude column) gives a `FileWarning`. docs/formats.md states the rules.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ingest.times import NS_PER_S

__all__ = [
    "RowProblem",
    "FileWarning",
    "MAX_DAMAGED_FRACTION",
    "MIN_GOOD_ROWS",
    "kept_in_time_order",
    "time_order_reasons",
    "missing_data_warnings",
    "missing_data_tolerance_s",
]

# A file may lose up to this share of its data rows to row-level problems; beyond it the file is
# refused, because damage that widespread means the file is not what it claims to be.
MAX_DAMAGED_FRACTION = 0.10
# A light curve needs at least two samples.
MIN_GOOD_ROWS = 2


@dataclass(frozen=True)
class RowProblem:
    """A data row set aside by a reader.

    Attributes
    ----------
    line : int
        1-based line of the file.
    reason : str
        One sentence: what is wrong with the row.
    text : str
        The row as the file wrote it (kept for provenance; its values are not used).
    """

    line: int
    reason: str
    text: str = ""

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return {"line": self.line, "reason": self.reason, "text": self.text}


@dataclass(frozen=True)
class FileWarning:
    """Something about a file that is worth knowing but does not make its rows wrong.

    Attributes
    ----------
    line : int or None
        1-based line of the header the warning is about, or None for the whole file.
    reason : str
        One sentence.
    """

    line: int | None
    reason: str

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return {"line": self.line, "reason": self.reason}


def kept_in_time_order(stamps_ns: np.ndarray) -> np.ndarray:
    """(n,) bool: the largest set of rows whose times strictly increase in file order.

    The rows left out are the fewest that must go for the rest to be in time order (the
    complement of a longest strictly increasing subsequence), so one row stamped 0.8 s too early
    costs that row, not every row after it, and a block of frames written twice costs one copy.

    Parameters
    ----------
    stamps_ns : (n,) int64

    Returns
    -------
    (n,) bool

    Examples
    --------
    >>> kept_in_time_order(np.array([0, 2, 4, 1, 6, 8])).tolist()
    [True, True, True, False, True, True]
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    n = len(stamps)
    if n < 2 or bool(np.all(np.diff(stamps) > 0)):
        return np.ones(n, dtype=bool)
    # Between equally long orders, keep the earlier rows and set aside the later one (a repeated
    # row loses its second copy): search the reversed sequence for a decreasing order.
    return _longest_increasing(-stamps[::-1])[::-1]


def _longest_increasing(values: np.ndarray) -> np.ndarray:
    """(n,) bool: one longest strictly increasing subsequence (patience sorting, O(n log n)).

    Only damaged files come here, so a plain loop is fine.
    """
    n = len(values)
    tail_values: list[int] = []  # tail_values[k]: smallest last value of an increasing run of length k + 1
    tail_index: list[int] = []
    previous = np.full(n, -1, dtype=np.int64)
    for i, value in enumerate(values.tolist()):
        k = int(np.searchsorted(tail_values, value, side="left")) if tail_values else 0
        if k > 0:
            previous[i] = tail_index[k - 1]
        if k == len(tail_values):
            tail_values.append(value)
            tail_index.append(i)
        else:
            tail_values[k] = value
            tail_index[k] = i
    keep = np.zeros(n, dtype=bool)
    i = tail_index[-1]
    while i >= 0:
        keep[i] = True
        i = int(previous[i])
    return keep


def time_order_reasons(stamps_ns: np.ndarray, keep: np.ndarray, lines: np.ndarray, labels: list[str]) -> list[str]:
    """One reason per row left out by `kept_in_time_order`, naming the kept row it clashes with.

    Parameters
    ----------
    stamps_ns : (n,) int64
    keep : (n,) bool
    lines : (n,) int
        File line of each row.
    labels : list of str, length n
        Each row's time as the file writes it.

    Returns
    -------
    list of str
        For the rows where `keep` is False, in order.
    """
    kept = np.flatnonzero(keep)
    reasons = []
    for i in np.flatnonzero(~keep).tolist():
        k = int(np.searchsorted(kept, i))
        before = int(kept[k - 1]) if k > 0 else None
        after = int(kept[k]) if k < len(kept) else None
        if before is not None and stamps_ns[i] <= stamps_ns[before]:
            other, word = before, ("repeats" if stamps_ns[i] == stamps_ns[before] else "is earlier than")
        elif after is not None:
            other, word = after, ("repeats" if stamps_ns[i] == stamps_ns[after] else "is later than")
        else:  # pragma: no cover - a left-out row always clashes with a kept neighbour
            other, word = before, "is out of order with"
        where = "the previous kept row" if other == before else "the next kept row"
        reasons.append(
            f"time {labels[i]} {word} {where}'s {labels[other]} (line {int(lines[other])}): "
            "the frame's time stamp is wrong"
        )
    return reasons


def missing_data_warnings(first, last, stamps_ns: np.ndarray, exposure_s: float) -> list[FileWarning]:
    """Warnings when the data start well after, or end well before, the header's times.

    Parameters
    ----------
    first, last : tuple (datetime64 or None, int, str)
        The header's time of the first sample's stamp and of the last (or of the end of the
        last sample), its line and what the header calls it.
    stamps_ns : (n,) int64
        The kept rows' stamps, as the file writes them.
    exposure_s : float

    A gap counts when it exceeds `missing_data_tolerance_s` (rows dropped here and there by the
    writer are normal; minutes missing at an end mean the file was cut).
    """
    found = []
    tolerance_s = missing_data_tolerance_s(exposure_s)
    start, end = int(stamps_ns[0]), int(stamps_ns[-1])
    for (time, line, what), gap_ns, side, data_word in (
        (first, lambda t: start - t, "start", "start at"),
        (last, lambda t: t - end, "end", "stop at"),
    ):
        if time is None:
            continue
        header_ns = int(np.datetime64(time, "ns").astype(np.int64))
        gap_s = gap_ns(header_ns) / NS_PER_S
        if gap_s > tolerance_s:
            data_ns = start if side == "start" else end
            found.append(
                FileWarning(
                    line,
                    f"the header's {what} is {_clock(header_ns)} but the data {data_word} {_clock(data_ns)}: "
                    f"{gap_s:.0f} s of data are missing at the {side}"
                    + (" (was the file cut short?)" if side == "end" else ""),
                )
            )
    return found


def missing_data_tolerance_s(exposure_s: float) -> float:
    """Seconds of data that may be missing at either end of a pass before it is worth a warning:
    10 s or 5 samples, whichever is longer."""
    return max(10.0, 5.0 * exposure_s)


def _clock(ns: int) -> str:
    return str(np.datetime64(ns, "ns"))[11:19]
