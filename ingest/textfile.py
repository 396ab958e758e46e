"""An observation file as bytes and lines, loaded with bounds and checked for being text.

Every reader starts here. `TextFile.from_path` refuses, with the file and line, what no reader
could use: an empty file, a file larger than `MAX_FILE_BYTES`, a line longer than
`MAX_LINE_BYTES` (a 10 MB single line fails after reading only the first `HEAD_BYTES`),
binary bytes, UTF-16/32 text and bytes that are not UTF-8. All checks are vectorised over the
byte buffer, so a clean 400 kB file costs well under a millisecond.
"""

from __future__ import annotations

from dataclasses import dataclass
import fcntl
from functools import cached_property
import hashlib
import os
from pathlib import Path
import stat

import numpy as np

from ingest.errors import FormatError, printable_path

__all__ = ["TextFile", "open_regular_file", "MAX_FILE_BYTES", "MAX_LINE_BYTES", "HEAD_BYTES"]

# The largest real file is ~0.4 MB (2500 rows); 64 MB is ~400k rows, far beyond any pass.
MAX_FILE_BYTES = 64 * 2**20
# Real rows are < 200 bytes; an OMM JSON header line is < 2 kB.
MAX_LINE_BYTES = 8192
# Read first; a file whose first line does not end within MAX_LINE_BYTES stops here.
HEAD_BYTES = 64 * 1024

_NEWLINE = 10
# Bytes that may appear in a text observation file besides printable ones: TAB, LF, CR.
_ALLOWED_CONTROL = np.zeros(256, dtype=bool)
_ALLOWED_CONTROL[32:127] = True
_ALLOWED_CONTROL[128:] = True  # non-ASCII: checked as UTF-8 separately
_ALLOWED_CONTROL[[9, 10, 13]] = True

_UTF16_32_BOMS = (b"\xff\xfe", b"\xfe\xff", b"\x00\x00\xfe\xff")
_UTF8_BOM = b"\xef\xbb\xbf"


@dataclass(frozen=True, eq=False)
class TextFile:
    """The bytes of one observation file with its line table.

    Attributes
    ----------
    path : str
        The file as given (used in error messages).
    data : bytes
        The file's bytes (without a UTF-8 byte-order mark, if it had one).
    line_starts, line_ends : (n_lines,) int64
        Byte offsets of each line's first byte and one past its last byte (the newline and a
        trailing carriage return excluded). Line ``k`` (1-based) is ``data[line_starts[k-1]:line_ends[k-1]]``.
    ends_with_newline : bool
        Whether the last line is terminated (a missing newline hints at a truncated file).
    raw_sha256 : str
        SHA-256 of the bytes exactly as stored on disk.
    """

    path: str
    data: bytes
    line_starts: np.ndarray
    line_ends: np.ndarray
    ends_with_newline: bool
    raw_sha256: str

    @classmethod
    def from_path(cls, path: str | Path) -> TextFile:
        """Read `path` with the bounds above; raise `FormatError` for anything not line-oriented text.

        OS errors (missing file, permission, a directory) propagate unchanged: they are not
        problems of the file's format. A FIFO, socket or device is refused without reading it
        (reading a FIFO would wait for a writer forever).
        """
        path = os.fspath(path)
        with open_regular_file(path) as stream:
            size = os.fstat(stream.fileno()).st_size
            if size == 0:
                raise FormatError(path, None, "the file is empty; an observation file needs a header and data rows")
            if size > MAX_FILE_BYTES:
                raise FormatError(
                    path,
                    None,
                    f"the file is {size / 2**20:.1f} MiB, more than the {MAX_FILE_BYTES // 2**20} MiB "
                    "an observation file can hold; split it or check that it is an observation file",
                )
            head = stream.read(HEAD_BYTES)
            _check_head(path, head)
            # Ask for exactly what fstat reported: read(n) allocates n bytes up front.
            data = head + stream.read(max(size - len(head), 0)) if size > len(head) else head
        return cls.from_bytes(path, data)

    @classmethod
    def from_bytes(cls, path: str, data: bytes) -> TextFile:
        """Check `data` (the whole file) and build its line table; `path` is only for messages."""
        path = printable_path(path)
        raw_sha256 = hashlib.sha256(data).hexdigest()
        if data.isspace():
            raise FormatError(
                path, None, "the file is empty (only whitespace); an observation file needs a header and data rows"
            )
        if len(data) > MAX_FILE_BYTES:
            raise FormatError(
                path,
                None,
                f"the file is larger than {MAX_FILE_BYTES // 2**20} MiB; check that it is an observation file",
            )
        _check_head(path, data[:HEAD_BYTES])
        if data.startswith(_UTF8_BOM):
            data = data[len(_UTF8_BOM) :]
        buf = np.frombuffer(data, dtype=np.uint8)
        newlines = np.flatnonzero(buf == _NEWLINE)
        ends_with_newline = bool(len(newlines)) and newlines[-1] == len(buf) - 1
        line_ends = newlines if ends_with_newline else np.append(newlines, len(buf))
        line_starts = np.empty_like(line_ends)
        line_starts[0] = 0
        line_starts[1:] = line_ends[:-1] + 1

        # Control bytes other than TAB, LF, CR (and DEL) mean binary data. Look only at bytes < 32.
        low = np.flatnonzero(buf < 32)
        bad = low[~_ALLOWED_CONTROL[buf[low]]]
        delete = np.flatnonzero(buf == 127)
        if len(bad) or len(delete):
            offset = int(min(bad[:1].tolist() + delete[:1].tolist()))
            line = int(np.searchsorted(line_ends, offset)) + 1
            column = offset - int(line_starts[line - 1]) + 1
            raise FormatError(
                path,
                line,
                f"control byte 0x{buf[offset]:02x} at column {column}: this is binary data, not a text observation file",
            )

        lengths = line_ends - line_starts
        too_long = np.flatnonzero(lengths > MAX_LINE_BYTES)
        if len(too_long):
            line = int(too_long[0]) + 1
            raise FormatError(
                path,
                line,
                f"the line is {int(lengths[line - 1])} bytes long, more than {MAX_LINE_BYTES}; "
                "this is not a text observation file",
            )

        try:
            if not data.isascii():
                data.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = int(np.searchsorted(line_ends, exc.start)) + 1
            column = exc.start - int(line_starts[line - 1]) + 1
            raise FormatError(
                path,
                line,
                f"byte 0x{data[exc.start]:02x} at column {column} is not UTF-8 text; "
                "the file is in another encoding: save it as UTF-8 or ASCII",
            ) from None

        # Trailing carriage returns (CRLF files) are not part of a line.
        has_cr = (lengths > 0) & (buf[np.maximum(line_ends - 1, 0)] == 13)
        line_ends = line_ends - has_cr
        return cls(
            path, data, line_starts.astype(np.int64), line_ends.astype(np.int64), bool(ends_with_newline), raw_sha256
        )

    # -- lines ------------------------------------------------------------------------------
    @property
    def n_lines(self) -> int:
        """Number of lines (a last line without a newline counts)."""
        return len(self.line_starts)

    def line(self, number: int) -> str:
        """Line `number` (1-based) as text, without its newline."""
        return self.data[self.line_starts[number - 1] : self.line_ends[number - 1]].decode("utf-8")

    def lines(self, first: int, last: int) -> list[str]:
        """Lines `first`..`last` inclusive (1-based) as text."""
        return [self.line(k) for k in range(first, min(last, self.n_lines) + 1)]

    def offset(self, number: int) -> int:
        """Byte offset where line `number` (1-based) starts; the file length past the last line."""
        return int(self.line_starts[number - 1]) if number <= self.n_lines else len(self.data)

    @cached_property
    def blank(self) -> np.ndarray:
        """(n_lines,) bool: lines holding only whitespace."""
        ink = np.concatenate([[0], np.cumsum(np.frombuffer(self.data, dtype=np.uint8) > 32)])
        return ink[self.line_ends] == ink[self.line_starts]

    @property
    def name(self) -> str:
        """The file name without directories."""
        return os.path.basename(self.path)

    @property
    def sha256(self) -> str:
        """SHA-256 of the file's bytes as stored (the archive's content hash)."""
        return self.raw_sha256

    def error(self, line: int | None, reason: str) -> FormatError:
        """A `FormatError` for this file."""
        return FormatError(self.path, line, reason)


def open_regular_file(path):
    """Open `path` for reading bytes, refusing anything but a regular file before any read.

    The file is opened without blocking (so a FIFO with no writer does not hang the open) and
    checked with ``fstat`` on the open descriptor (so nothing can swap the file in between).

    Raises
    ------
    FormatError
        For a FIFO, socket, character or block device.
    OSError
        Missing file, permission, a directory.
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise IsADirectoryError(21, "Is a directory", path)
        if not stat.S_ISREG(mode):
            kind = (
                "a FIFO (named pipe)"
                if stat.S_ISFIFO(mode)
                else "a socket"
                if stat.S_ISSOCK(mode)
                else "a device"
                if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
                else "not a regular file"
            )
            raise FormatError(path, None, f"is {kind}, not an observation file; give a regular file")
        flags = fcntl.fcntl(fd, fcntl.F_GETFL)
        fcntl.fcntl(fd, fcntl.F_SETFL, flags & ~os.O_NONBLOCK)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _check_head(path: str, head: bytes) -> None:
    """Refuse UTF-16/32 text and an over-long first line before reading further."""
    if head.startswith(_UTF16_32_BOMS) or (len(head) > 1 and head[1:2] == b"\x00" and head[0:1] != b"\x00"):
        raise FormatError(path, 1, "the file is UTF-16 or UTF-32 encoded; save it as UTF-8 or ASCII")
    limit = MAX_LINE_BYTES + 2  # a line of MAX_LINE_BYTES plus CR LF
    if len(head) >= limit and b"\n" not in head[:limit]:
        raise FormatError(
            path,
            1,
            f"the first line is longer than {MAX_LINE_BYTES} bytes; this is not a text observation file",
        )
