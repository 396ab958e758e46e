"""A corpus of bad input: a bad file is reported as file:line: reason, a bad row is set aside
with a warning file:line: reason and the rest of its file is stored, the batch goes on, and
nothing already stored changes or is superseded.

The bad files are made from real files (COSMOS 2540's ccd_phot file, COSMOS 2553's .phc file)
by one edit each, so the line each problem must point at is known from the edit: data row k
(0-based) of the ccd_phot file is file line 17 + k. The issue each case came from is named.
"""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

import ingest
from rsodb.archive import Archive
from rsodb.cli import main
from tests.conftest import COSMOS2540_PHV, COSMOS2553_PHC, PROJECT_ROOT, REAL_FILES, TOPEX_PHV

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


def _set_date(k: int, date: str) -> str:
    lines = _lines()
    i = FIRST_DATA_LINE - 1 + k
    lines[i] = date + lines[i][10:]
    return "".join(lines)


def _every_date(date: str) -> str:
    lines = _lines()
    return "".join(date + line[10:] if k >= FIRST_DATA_LINE - 1 else line for k, line in enumerate(lines))


def _header(old: str, new: str) -> str:
    return COSMOS2540_PHV.read_text().replace(old, new, 1)


def _clock_glitch() -> str:
    # issue 17: a row stamped 0.8 s before the previous one, with the Az/El of the frame that
    # really had that time (the real file from the observatory had three such rows in 1484).
    lines = _lines()
    i = FIRST_DATA_LINE - 1 + 60
    earlier = lines[i - 9]
    lines[i] = earlier[:23] + lines[i][23:].replace(lines[i].split()[10], earlier.split()[10], 1)
    return "".join(lines)


def _phc_cut_in_last_column() -> bytes:
    # issue 17: a .phc file cut inside its last value ("2827.394" read as 28 km).
    data = COSMOS2553_PHC.read_bytes()
    return data[: data.rindex(b"2827.394") + 2]


# Files refused whole: name -> (content, expected line or None, words the reason must contain).
REFUSED = {
    "empty.phV": (b"", None, ["empty"]),
    "header-only.phV": (lambda: "".join(_lines()[: FIRST_DATA_LINE - 1]), FIRST_DATA_LINE, ["no", "data rows"]),
    "utf16.phV": (lambda: COSMOS2540_PHV.read_text().encode("utf-16"), 1, ["UTF-16", "UTF-8"]),
    "latin1.phV": (
        lambda: COSMOS2540_PHV.read_text().replace("NAME   = COSMOS 2540", "NAME   = COSMOS 2540 é").encode("latin-1"),
        11,
        ["0xe9", "UTF-8"],
    ),
    "binary-garbage.phV": (lambda: np.random.default_rng(0).bytes(5000), 1, ["binary"]),
    "ten-megabyte-line.phV": (b"x" * (10 * 2**20), 1, ["longer than"]),
    # issue 17: every date past 2262 used to wrap around (2999-01-30 stored as 1829-12-22).
    "dated-2999.phV": (lambda: _every_date("2999-01-30"), 17, ["2999-01-30", "outside the dates"]),
    # issue 17: a 20-digit NORAD number gave a traceback and stopped the batch.
    "norad-overflow.phV": (
        lambda: _header("NORAD  = 44517", "NORAD  = 99999999999999999999"),
        10,
        ["NORAD", "'99999999999999999999'", "not a catalogue number"],
    ),
    "exposure-overflow.phV": (lambda: _header("dt = 0.1", "dt = 1e300"), 7, ["dt", "1e300", "exposure"]),
    "widespread-damage.phV": (
        lambda: "".join(
            line.replace(line.split()[6], "x", 1) if k >= FIRST_DATA_LINE - 1 and k % 5 == 0 else line
            for k, line in enumerate(_lines())
        ),
        21,  # file line 21 is line index 20, the first row with k % 5 == 0
        ["Flux is 'x'", "data rows are damaged", "10%"],
    ),
    "phc-dated-2999.phc": (
        lambda: COSMOS2553_PHC.read_bytes().replace(b"2025-01-30", b"2999-01-30"),
        1,
        ["2999-01-30", "outside the dates"],
    ),
}

# Files stored with rows set aside: name -> (content, lines set aside, words of the first reason).
ROWS_SET_ASIDE = {
    "truncated-mid-row.phV": (lambda: _truncated(99), [_row_line(99)], ["truncated"]),
    "wrong-column-count.phV": (lambda: _drop_field(9), [_row_line(9)], ["13 columns", "expected 14"]),
    "non-numeric.phV": (lambda: _edit_field(20, 8, "6.2x3"), [_row_line(20)], ["magV", "'6.2x3'", "not a number"]),
    "nan-magnitude.phV": (lambda: _edit_field(21, 8, "nan"), [_row_line(21)], ["magV", "'nan'", "finite"]),
    "inf-flux.phV": (lambda: _edit_field(22, 6, "inf"), [_row_line(22)], ["Flux", "'inf'", "finite"]),
    "non-monotonic.phV": (lambda: _swap_rows(30), [_row_line(31)], ["earlier", "time stamp is wrong"]),
    "duplicate-time.phV": (lambda: _repeat_time(31), [_row_line(32)], ["repeats", "time stamp is wrong"]),
    "negative-flux.phV": (lambda: _edit_field(40, 6, "-12.5000"), [_row_line(40)], ["Flux -12.5000", "not positive"]),
    "zero-flux.phV": (lambda: _edit_field(41, 6, "0.0000"), [_row_line(41)], ["Flux 0.0000", "not positive"]),
    "elevation-118.phV": (lambda: _edit_field(42, 11, "118.566"), [_row_line(42)], ["El(deg) 118.566"]),
    "one-row-dated-2999.phV": (lambda: _set_date(50, "2999-01-30"), [_row_line(50)], ["2999-01-30", "outside"]),
    "clock-glitch.phV": (_clock_glitch, [_row_line(60)], ["earlier than", "time stamp is wrong"]),
    "cut-in-last-column.phc": (_phc_cut_in_last_column, [699], ["Rg(Mm) '28'", "cut inside this row"]),
}


def _write(directory: Path, cases: dict) -> dict[Path, tuple]:
    directory.mkdir(parents=True, exist_ok=True)
    written = {}
    for name, (content, *expected) in cases.items():
        content = content() if callable(content) else content
        path = directory / name
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
        written[path] = tuple(expected)
    return written


@pytest.fixture
def stored(tmp_path, shared_data):
    """An archive holding the real files, and a byte snapshot of its object files."""
    archive = Archive(tmp_path / "archive")
    assert archive.ingest(REAL_FILES, progress=False, workers=0).ok
    snapshot = {path.name: path.read_bytes() for path in archive.objects_dir.glob("*.h5")}
    return archive, snapshot


def test_each_bad_file_is_refused_with_file_line_and_reason(tmp_path, shared_data):
    refused = _write(tmp_path / "bad", REFUSED)
    report = Archive(tmp_path / "archive").ingest([tmp_path / "bad"], progress=False, workers=2)
    failures = {Path(error.path): error for error in report.failed}
    assert set(failures) == set(refused) and not report.ingested
    for path, (line, words) in refused.items():
        error = failures[path]
        assert error.line == line, f"{path.name}: {error}"
        for word in words:
            assert word in error.reason, f"{path.name}: {error.reason!r} lacks {word!r}"
        assert str(error).startswith(f"{path}:{line}: " if line is not None else f"{path}: ")


def test_bad_rows_are_set_aside_and_the_rest_is_stored_exactly(tmp_path, shared_data):
    cases = _write(tmp_path / "rows", ROWS_SET_ASIDE)
    (cosmos,) = ingest.read_file(COSMOS2540_PHV)
    b, _ = ingest.read_file(COSMOS2553_PHC)
    for k, (path, (lines, words)) in enumerate(cases.items()):
        archive = Archive(tmp_path / f"archive-{k}")  # each case alone: no copy to be a duplicate of
        report = archive.ingest([path], progress=False, workers=0)
        assert report.ok and len(report.ingested) == 1, report.summary()
        assert {(w.path, w.line) for w in report.warnings} >= {(str(path), line) for line in lines}
        stored = archive.get(report.ingested[0].pass_ids[0])
        assert [problem.line for problem in stored.row_problems] == lines, path.name
        for word in words:
            assert word in stored.row_problems[0].reason, f"{path.name}: {stored.row_problems[0].reason!r}"
        # 0 wrong values: every stored row is a row of the original file, exactly.
        original = b if path.suffix == ".phc" else cosmos
        index = np.searchsorted(original.time_utc, stored.time_utc)
        np.testing.assert_array_equal(original.time_utc[index], stored.time_utc, err_msg=path.name)
        for name in ("mag", "flux", "az_deg", "el_deg", "range_km"):
            np.testing.assert_array_equal(getattr(original, name)[index], getattr(stored, name), err_msg=path.name)
        first_data_line = 8 if path.suffix == ".phc" else FIRST_DATA_LINE
        rows = [line for line in path.read_bytes().splitlines()[first_data_line - 1 :] if line.strip()]
        assert len(stored) + len(lines) == len(rows), path.name


def test_a_mixed_batch_stores_every_good_file_and_supersedes_nothing(stored, tmp_path):
    archive, snapshot = stored
    corpus = tmp_path / "night"
    refused = _write(corpus, REFUSED)
    rows = _write(corpus, ROWS_SET_ASIDE)
    # Good files in the same batch: a new pass with an odd name, one already stored, and the
    # real TOPEX file re-reduced (one magnitude changed): a new version of the stored pass.
    odd = corpus / "new file; $(rm -rf ~) ..x.phV"
    odd.write_bytes(COSMOS2540_PHV.read_bytes().replace(b"2025-01-30 ", b"2025-01-31 "))
    (corpus / "again.phV").write_bytes(TOPEX_PHV.read_bytes())
    changed = corpus / "topex-rereduced.phV"
    changed.write_bytes(TOPEX_PHV.read_bytes().replace(b" 4.467 ", b" 4.567 ", 1))
    loop = corpus / "loop"
    loop.mkdir()
    os.symlink("..", loop / "up")  # a symlink loop: loop/up/loop/up/...
    os.symlink("missing.phV", corpus / "dangling.phV")

    report = archive.ingest([corpus], progress=False, workers=2)

    failures = {Path(error.path) for error in report.failed}
    assert failures == set(refused) | {corpus / "dangling.phV"}
    assert sorted(item.path for item in report.ingested) == sorted([str(odd), str(changed)])
    assert report.already_present == (str(corpus / "again.phV"),)
    # The files with rows set aside hold only rows of stored passes: duplicate sources, and
    # nothing they hold supersedes the complete pass (issue 17).
    assert {Path(item.path) for item in report.duplicates} == set(rows)
    assert archive.get("44517-20250130T173650").version == 1
    assert [p.version for p in archive.passes(norad=51511)] == [1, 1, 1]
    # Only the re-reduced TOPEX file made a new version.
    assert archive.get("22076").pass_id == "22076-20240730T212240-V-derenivka-v2"
    assert len(archive.passes()) == 6 and len(archive.passes(all_versions=True)) == 7
    # Every pass stored before is still there with exactly its original arrays.
    originals = {(p.source_sha256, p.band): p for path in REAL_FILES for p in ingest.read_file(path)}
    before = [p for p in archive.passes(all_versions=True) if (p.source_sha256, p.band) in originals]
    assert len(before) == len(originals) == 5
    for stored_pass in before:
        original = originals[(stored_pass.source_sha256, stored_pass.band)]
        for name in ("time_utc", "mag", "mag_err", "flux", "az_deg", "el_deg", "range_km", "valid"):
            np.testing.assert_array_equal(getattr(stored_pass, name), getattr(original, name), err_msg=name)
    assert set(snapshot) == {path.name for path in archive.objects_dir.glob("*.h5")}


def test_special_files_and_odd_names_do_not_stop_the_batch(tmp_path, shared_data):
    night = tmp_path / "night"
    night.mkdir()
    fifo = night / "pipe.phV"
    os.mkfifo(fifo)  # reading it would wait for a writer forever
    # A file name that is not UTF-8 (bytes 0xff 0xfe), holding a good file.
    odd_name = os.fsdecode(bytes(night) + b"/caf\xff\xfe.phV")
    Path(odd_name).write_bytes(COSMOS2540_PHV.read_bytes())
    bad_name = os.fsdecode(bytes(night) + b"/bad\xff.phV")
    Path(bad_name).write_bytes(b"not an observation\n")
    report = Archive(tmp_path / "archive").ingest(
        [fifo, "/dev/null", odd_name, bad_name, TOPEX_PHV], progress=False, workers=0
    )
    reasons = {error.path: error.reason for error in report.failed}
    assert reasons[str(fifo)].startswith("is a FIFO (named pipe), not an observation file")
    assert reasons["/dev/null"].startswith("is a device, not an observation file")
    assert reasons[str(night / "bad\\xff.phV")].startswith("unknown file format")
    assert sorted(item.path for item in report.ingested) == sorted([str(night / "caf\\xff\\xfe.phV"), str(TOPEX_PHV)])
    print(report.summary())  # the summary prints: no surrogate reaches stdout


def test_cli_reports_file_line_reason_and_exits_1(stored, tmp_path, capsys):
    archive, _ = stored
    corpus = tmp_path / "night"
    refused = _write(corpus, REFUSED)
    rows = _write(corpus, ROWS_SET_ASIDE)
    status = main(["ingest", str(corpus), "--archive", str(archive.path), "--no-progress", "--workers", "999999999999"])
    captured = capsys.readouterr()
    assert status == 1
    assert "--workers 999999999999 is more than the" in captured.err and "Traceback" not in captured.err
    assert f"{len(rows)} duplicate(s)" in captured.out and f"{len(refused)} failed" in captured.out
    for path, (line, _) in refused.items():
        where = f"{path}:{line}: " if line is not None else f"{path}: "
        assert f"\n  {where}" in captured.out
    for path, (lines, _) in rows.items():
        assert f"\n  {path}:{lines[0]}: " in captured.out and "(row set aside)" in captured.out


def test_a_file_given_twice_and_through_a_link_is_read_once(tmp_path, shared_data):
    link = tmp_path / "link.phV"
    os.symlink(TOPEX_PHV, link)
    report = Archive(tmp_path / "archive").ingest([TOPEX_PHV, link, TOPEX_PHV], progress=False, workers=0)
    assert report.n_files == 1 and len(report.ingested) == 1


@pytest.mark.parametrize(
    "command",
    [
        "ls --json | head -c1",
        "ls | head -n1",
        "show 22076 | head -n1",
        "export 22076 --format csv | head -n2",
    ],
)
def test_a_reader_that_stops_early_gets_no_traceback(stored, command):
    # issue 17: BrokenPipe from 'ls --json | head -c1' reached the user as a traceback.
    archive, _ = stored
    rsodb = f"{sys.executable} -m rsodb"
    verb, _, rest = command.partition(" ")
    script = f"{rsodb} {verb} --archive {archive.path} {rest}"
    done = subprocess.run(["bash", "-c", script], capture_output=True, text=True, cwd=PROJECT_ROOT, timeout=120)
    assert done.stdout and "Traceback" not in done.stderr and "Exception" not in done.stderr, done.stderr


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["ingest", "{sample}", "--tle", "{missing}"], "--tle {missing}"),
        (["ingest", "{sample}", "--tle", "{directory}"], "--tle {directory}"),
        (["elements", "add", "{missing}"], "the catalogue {missing}"),
    ],
)
def test_an_unreadable_element_catalogue_is_named_with_its_option(tmp_path, shared_data, capsys, argv, named):
    # A missing --tle file gave a bare "[Errno 2] ..." without saying which input it was.
    places = {"sample": str(TOPEX_PHV), "missing": str(tmp_path / "tles.txt"), "directory": str(tmp_path)}
    argv = [item.format(**places) for item in argv] + ["--archive", str(tmp_path / "archive")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and named.format(**places) in err and "cannot read the element catalogue" in err
