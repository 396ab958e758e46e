"""Format detection and the table of readers: `read_file(path)` is the one entry point.

Detection looks at the content (the header lines), never only at the extension, so a
``.txt`` copy of a ccd_phot file reads as ccd_phot and a ``.phV`` file holding something else
is refused with a clear message.
"""

from __future__ import annotations

from pathlib import Path

from ingest.ccd_phot import CcdPhotReader
from ingest.csv_table import CsvReader
from ingest.observation import Pass
from ingest.phc import PhcReader
from ingest.textfile import TextFile

__all__ = ["READERS", "detect_format", "read_file", "read_pass"]

# Name -> reader; detection tries them in this order.
READERS = {
    "ccd_phot": CcdPhotReader(),
    "phc": PhcReader(),
    "csv": CsvReader(),
}


def detect_format(text: TextFile) -> str:
    """Name of the reader (a key of `READERS`) whose format the file's header matches.

    Raises
    ------
    FormatError
        When no reader recognises the header.
    """
    for name, reader in READERS.items():
        if reader.sniff(text):
            return name
    first = text.line(1).strip()[:60]
    raise text.error(
        1,
        f"unknown file format (line 1 reads {first!r}); expected a ccd_phot light curve "
        "('# TLE:' header and a '# Date UT ...' or '# JD ...' column line) or a photometer "
        ".phc file (a date and time on line 1 and a 'UT TIME ImpB-fon ...' column line) or a CSV light curve "
        "('# key = value' lines, then a column line such as 'time_utc,mag,mag_err')",
    )


def read_file(path: str | Path, format: str = "auto") -> tuple[Pass, ...]:
    """Read an observation file into its passes.

    Parameters
    ----------
    path : str or Path
        A ccd_phot ``.phX`` file (one pass) or a photometer ``.phc`` file (two passes, B and V,
        sharing the time axis).
    format : str
        ``"auto"`` (detect from the content) or a key of `READERS`.

    Returns
    -------
    tuple of Pass

    Raises
    ------
    FormatError
        ``path:line: reason`` for anything that is not a valid observation file.
    OSError
        When the file cannot be opened (missing, a directory, no permission).

    Examples
    --------
    >>> (topex,) = read_file("result_22076_20240730_UT212240.phV")  # doctest: +SKIP
    >>> b, v = read_file("51511_250130_1719.phc")                     # doctest: +SKIP
    """
    if format != "auto" and format not in READERS:
        raise ValueError(f"format={format!r} is not one of 'auto', {', '.join(map(repr, READERS))}")
    text = TextFile.from_path(path)
    name = detect_format(text) if format == "auto" else format
    return READERS[name].parse(text)


def read_pass(path: str | Path) -> Pass:
    """The one pass of an observation file; `read_file` returns all passes of any file.

    Raises
    ------
    ValueError
        When the file holds several passes (a ``.phc`` file holds B and V).
    FormatError
        When the file is not a valid observation file.
    """
    passes = read_file(path)
    if len(passes) != 1:
        bands = ", ".join(p.band for p in passes)
        raise ValueError(
            f"{path} holds {len(passes)} passes (bands {bands}); use ingest.read_file(path) to get all of them"
        )
    return passes[0]
