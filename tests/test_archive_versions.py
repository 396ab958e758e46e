"""Versions that do not lose the better copy (docs/archive.md, "Pass ids and versions").

The cases are the real ones of issue 17, built from the real files: a truncated copy of a stored
.phc file (its header ends at 17:31:25, its data at 17:25:47) became the current version and hid
the complete one; a file with ``Filter = V'`` superseded the real V pass.
"""

from __future__ import annotations

import numpy as np
import pytest

import ingest
from rsodb.archive import Archive, layout
from rsodb.cli import main
from tests.conftest import COSMOS2540_PHV, COSMOS2553_PHC, PROJECT_ROOT

B_ID, V_ID = "51511-20250130T171941-B-uzhhorod", "51511-20250130T171941-V-uzhhorod"


@pytest.fixture
def truncated_phc(tmp_path, shared_data):
    """The real .phc file cut after its row at 17:25:47 (line 2 still says 17:31:25)."""
    lines = COSMOS2553_PHC.read_text().splitlines(keepends=True)
    cut = next(k for k, line in enumerate(lines) if line.startswith("17:25:47"))
    path = tmp_path / "51511_250130_1719_copy.phc"
    path.write_text("".join(lines[: cut + 1]))
    return path


def test_a_truncated_copy_is_a_duplicate_source_with_a_warning(tmp_path, truncated_phc):
    archive = Archive(tmp_path / "archive")
    archive.ingest([COSMOS2553_PHC], progress=False, workers=0)
    report = archive.ingest([truncated_phc], progress=False, workers=0)
    assert report.ok and not report.ingested
    (duplicate,) = report.duplicates
    assert duplicate.pass_ids == (B_ID, V_ID) and "367 of the stored pass's 692 rows" in duplicate.note
    # The file was cut short (and carries no orbital elements, as every .phc file).
    warning, no_orbit = sorted(report.warnings, key=lambda item: item.reason.startswith("no orbit:"))
    assert no_orbit.reason.startswith("no orbit: the file carries no orbital elements")
    # line 2 (17:31:25) is the end of the last 1 s sample, so the last stamp it allows is 17:31:24
    assert (warning.line, warning.reason) == (
        2,
        "the header's last sample time (line 2 less dt) is 17:31:24 but the data stop at 17:25:47: 337 s of data "
        "are missing at the end (was the file cut short?)",
    )
    # The complete passes stay current, whole.
    b, v = ingest.read_file(COSMOS2553_PHC)
    assert [(p.pass_id, len(p), p.is_current) for p in archive.passes(norad=51511)] == [
        (B_ID, 692, True),
        (V_ID, 692, True),
    ]
    np.testing.assert_array_equal(archive.get(V_ID).mag, v.mag)
    assert [item.source_name for item in archive.duplicate_sources(B_ID)] == [truncated_phc.name]
    assert archive.ingest([truncated_phc], progress=False, workers=0).already_present == (str(truncated_phc),)


def test_the_complete_file_after_a_truncated_one_supersedes_it(tmp_path, truncated_phc):
    archive = Archive(tmp_path / "archive")
    first = archive.ingest([truncated_phc], progress=False, workers=0)
    (warning,) = [item for item in first.warnings if "cut short" in item.reason]  # stored with the pass
    assert warning.reason in [item.reason for item in archive.get(B_ID).warnings]
    report = archive.ingest([COSMOS2553_PHC], progress=False, workers=0)
    assert [item.superseded for item in report.ingested] == [(B_ID, V_ID)]
    current = archive.passes(norad=51511)
    assert [(p.pass_id, len(p)) for p in current] == [(B_ID + "-v2", 692), (V_ID + "-v2", 692)]


def test_a_changed_filter_letter_is_a_warning_not_a_new_band(tmp_path, shared_data):
    archive = Archive(tmp_path / "archive")
    archive.ingest([COSMOS2540_PHV], progress=False, workers=0)
    renamed = tmp_path / "result_44517_20250130_UT173650.phV"
    renamed.write_text(COSMOS2540_PHV.read_text().replace("# Filter = V", "# Filter = V'"))
    report = archive.ingest([renamed], progress=False, workers=0)
    assert not report.ingested
    assert report.duplicates[0].note == "its header says band V' but its rows are those of the band V pass"
    assert {w.reason.split(":")[0] for w in report.warnings} == {
        "Filter = V' but the magnitude column is magV",
        "Filter = V' but the file name ends in .phV",
    }
    (current,) = archive.passes()
    assert (current.band, current.version) == ("V", 1)

    # New data under the odd letter is a pass of its own band, with an id of its own.
    renamed.write_text(renamed.read_text().replace(" 6.124 ", " 6.125 ", 1))
    report = archive.ingest([renamed], progress=False, workers=0)
    assert report.ingested[0].pass_ids == ("44517-20250130T173650-Vp-derenivka",) and not report.ingested[0].superseded
    assert [p.band for p in archive.passes()] == ["V", "V'"]


@pytest.mark.parametrize("band, key", [("V", "V"), ("V'", "Vp"), ("R_c", "Rx5fc"), ("g'", "gp")])
def test_every_band_has_its_own_id(band, key):
    assert layout.band_key(band) == key


def test_pass_ids_are_exact_to_the_second_of_the_first_sample(tmp_path):
    # issue 19: the sample file's first sample is at 01:07:14.000, but its JD column read as a
    # float64 gives 01:07:13.9999952: the id said T010713.
    path = PROJECT_ROOT / "data_samples" / "result_22076_20210626_UT010714.phR"
    (observed,) = ingest.read_file(path)
    assert observed.start_utc < np.datetime64("2021-06-26T01:07:14", "ns")
    assert layout.natural_pass_id(observed) == "22076-20210626T010714-R-derenivka"


def test_ls_and_show_print_the_start_second_of_the_id(tmp_path, capsys):
    # issue 19: the id said T010714 while ls printed 01:07:13 and show 01:07:13.999.
    path = PROJECT_ROOT / "data_samples" / "result_22076_20210626_UT010714.phR"
    archive = str(tmp_path / "archive")
    assert main(["ingest", str(path), "--archive", archive, "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["ls", "--archive", archive]) == 0
    row = capsys.readouterr().out.splitlines()[1]
    assert row.startswith("22076-20210626T010714-R-derenivka") and "2021-06-26 01:07:14" in row
    assert main(["show", "22076-20210626T010714", "--archive", archive]) == 0
    assert "time       2021-06-26T01:07:14.000Z .. 2021-06-26T01:09:13.750Z" in capsys.readouterr().out
