"""A corpus of bad input: each case is reported as file:line: reason, the batch goes on, and
nothing already stored changes.

The bad files are made from a real ccd_phot file (COSMOS 2540) by one edit each, so the line
each error must point at is known from the edit: data row k (0-based) is file line 17 + k.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from rsodb.archive import Archive
from rsodb.cli import main
from tests.conftest import COSMOS2540_PHV, COSMOS2553_PHC, REAL_FILES, TOPEX_PHV

FIRST_DATA_LINE = 17  # 15 header lines, the column line, then data


def _lines() -> list[str]:
    return COSMOS2540_PHV.read_text().splitlines(keepends=True)


def _row_line(k: int) -> int:
    return FIRST_DATA_LINE + k


def _edit_field(k: int, column: int, value: str) -> str:
    """The file with column `column` of data row `k` replaced by `value`."""
    lines = _lines()
    index = FIRST_DATA_LINE - 1 + k
    old = lines[index].split()[column]
    lines[index] = lines[index].replace(f" {old} ", f" {value} ", 1)
    return "".join(lines)


def _swap_rows(k: int) -> str:
    lines = _lines()
    i = FIRST_DATA_LINE - 1 + k
    lines[i], lines[i + 1] = lines[i + 1], lines[i]
    return "".join(lines)


def _repeat_time(k: int) -> str:
    lines = _lines()
    i = FIRST_DATA_LINE - 1 + k
    lines[i + 1] = lines[i][:23] + lines[i + 1][23:]  # "YYYY-MM-DD HH:MM:SS.fff" is 23 characters
    return "".join(lines)


def _truncated(k: int) -> str:
    lines = _lines()
    cut = FIRST_DATA_LINE - 1 + k
    return "".join(lines[:cut]) + lines[cut][:40]


def _drop_field(k: int) -> str:
    lines = _lines()
    i = FIRST_DATA_LINE - 1 + k
    fields = lines[i].split()
    lines[i] = " ".join(fields[:-2] + fields[-1:]) + "\n"
    return "".join(lines)


# name -> (content, expected line or None, words the reason must contain)
# Columns: 0 date, 1 time, 2-5 centroid, 6 Flux, 7 Flux_err, 8 magV, 9 mag_err, 10 Az, 11 El, 12 Rg.
CASES = {
    "empty.phV": (b"", None, ["empty"]),
    "header-only.phV": (lambda: "".join(_lines()[: FIRST_DATA_LINE - 1]), FIRST_DATA_LINE, ["no", "data rows"]),
    "truncated-mid-row.phV": (lambda: _truncated(99), _row_line(99), ["truncated"]),
    "wrong-column-count.phV": (lambda: _drop_field(9), _row_line(9), ["13 columns", "expected 14"]),
    "non-numeric.phV": (lambda: _edit_field(20, 8, "6.2x3"), _row_line(20), ["magV", "'6.2x3'", "not a number"]),
    "nan-magnitude.phV": (lambda: _edit_field(21, 8, "nan"), _row_line(21), ["magV", "'nan'", "finite"]),
    "inf-flux.phV": (lambda: _edit_field(22, 6, "inf"), _row_line(22), ["Flux", "'inf'", "finite"]),
    "non-monotonic.phV": (lambda: _swap_rows(30), _row_line(31), ["earlier", "time order"]),
    "duplicate-time.phV": (lambda: _repeat_time(31), _row_line(32), ["repeats", "time order"]),
    "negative-flux.phV": (lambda: _edit_field(40, 6, "-12.5000"), _row_line(40), ["Flux -12.5000", "not positive"]),
    "zero-flux.phV": (lambda: _edit_field(41, 6, "0.0000"), _row_line(41), ["Flux 0.0000", "not positive"]),
    "utf16.phV": (lambda: COSMOS2540_PHV.read_text().encode("utf-16"), 1, ["UTF-16", "UTF-8"]),
    "latin1.phV": (
        lambda: COSMOS2540_PHV.read_text().replace("NAME   = COSMOS 2540", "NAME   = COSMOS 2540 é").encode("latin-1"),
        11,
        ["0xe9", "UTF-8"],
    ),
    "binary-garbage.phV": (lambda: np.random.default_rng(0).bytes(5000), 1, ["binary"]),
    "ten-megabyte-line.phV": (b"x" * (10 * 2**20), 1, ["longer than"]),
}


def _write_corpus(directory: Path) -> dict[Path, tuple[int | None, list[str]]]:
    directory.mkdir(parents=True, exist_ok=True)
    expected = {}
    for name, (content, line, words) in CASES.items():
        content = content() if callable(content) else content
        path = directory / name
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
        expected[path] = (line, words)
    return expected


@pytest.fixture
def stored(tmp_path, shared_data):
    """An archive holding the real files, and a byte snapshot of its object files."""
    archive = Archive(tmp_path / "archive")
    assert archive.ingest(REAL_FILES, progress=False, workers=0).ok
    snapshot = {path.name: path.read_bytes() for path in archive.objects_dir.glob("*.h5")}
    return archive, snapshot


def test_each_bad_file_is_reported_and_nothing_stored_is_lost(stored, tmp_path):
    archive, snapshot = stored
    corpus = tmp_path / "night"
    expected = _write_corpus(corpus)
    # Good files in the same batch: a new one with an odd name and one already stored.
    odd = corpus / "new file; $(rm -rf ~) ..x.phc"
    odd.write_bytes(COSMOS2553_PHC.read_bytes().replace(b"17:19:41", b"17:19:42", 1))
    (corpus / "again.phV").write_bytes(TOPEX_PHV.read_bytes())
    loop = corpus / "loop"
    loop.mkdir()
    os.symlink("..", loop / "up")  # a symlink loop: loop/up/loop/up/...
    os.symlink("missing.phV", corpus / "dangling.phV")

    report = archive.ingest([corpus], progress=False, workers=2)

    failures = {Path(error.path): error for error in report.failed}
    assert set(failures) == set(expected) | {corpus / "dangling.phV"}
    for path, (line, words) in expected.items():
        error = failures[path]
        assert error.line == line, f"{path.name}: {error}"
        for word in words:
            assert word in error.reason, f"{path.name}: {error.reason!r} lacks {word!r}"
        prefix = f"{path}:{line}: " if line is not None else f"{path}: "
        assert str(error).startswith(prefix)
    assert "broken symbolic link" in failures[corpus / "dangling.phV"].reason

    # The edited photometer file (only its header's start time changed) holds the same two
    # observations as the stored one: new versions of them, B and V.
    assert [item.path for item in report.ingested] == [str(odd)]
    assert report.ingested[0].pass_ids == ("51511-20250130T171941-B-uzhhorod-v2", "51511-20250130T171941-V-uzhhorod-v2")
    assert report.already_present == (str(corpus / "again.phV"),)
    # The files that were stored before are untouched, byte for byte; only the object of the
    # new .phc (51511) gained its two new versions, and its earlier passes are still there.
    for name, content in snapshot.items():
        if name != "51511.h5":
            assert (archive.objects_dir / name).read_bytes() == content, name
    assert len(archive.passes()) == 5 and len(archive.passes(all_versions=True)) == 7
    assert archive.get("51511-20250130T171941-B-uzhhorod").superseded_by.endswith("-v2")


def test_cli_reports_file_line_reason_and_exits_1(stored, tmp_path, capsys):
    archive, _ = stored
    corpus = tmp_path / "night"
    expected = _write_corpus(corpus)
    status = main(["ingest", str(corpus), "--archive", str(archive.path), "--no-progress"])
    out = capsys.readouterr().out
    assert status == 1
    assert "0 file(s) (0 pass(es))" in out and f"{len(expected)} failed" in out
    for path, (line, _) in expected.items():
        where = f"{path}:{line}: " if line is not None else f"{path}: "
        assert f"\n  {where}" in out


def test_a_file_given_twice_and_through_a_link_is_read_once(tmp_path, shared_data):
    link = tmp_path / "link.phV"
    os.symlink(TOPEX_PHV, link)
    report = Archive(tmp_path / "archive").ingest([TOPEX_PHV, link, TOPEX_PHV], progress=False, workers=0)
    assert report.n_files == 1 and len(report.ingested) == 1
