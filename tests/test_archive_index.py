"""The catalog index: survey queries, Archive.catalog() as a DataFrame, ls and show of results.

Timing at survey scale is bench/archive_scale.py's job; here the answers are checked.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from rsodb.archive import Archive
from rsodb.cli import main
from rsodb.samples.synthetic import synthetic_pass
from tests.conftest import REAL_FILES

TOPEX_ID = "22076-20240730T212240-V-derenivka"


class Period:
    """A stand-in period result with the attributes a period search stores."""

    def __init__(self, period_s: float, error_s: float, verdict: str):
        self.period_s, self.error_s, self.verdict = period_s, error_s, verdict

    def to_hdf5(self, group):
        group.attrs["best_period_s"] = self.period_s
        group.attrs["uncertainty_s"] = self.error_s
        group.attrs["verdict"] = self.verdict
        group.attrs["reason"] = "a stand-in"
        candidates = np.zeros(3, dtype=[("period_s", "f8"), ("power", "f8")])
        candidates["period_s"] = [self.period_s, 2 * self.period_s, self.period_s / 2]
        candidates["power"] = [0.9, 0.5, 0.2]
        group.create_dataset("candidates", data=candidates)


@pytest.fixture(scope="module")
def survey(tmp_path_factory, shared_data):
    """The real files plus 40 synthetic passes of 8 objects, with stored period results (the
    tests only read it)."""
    archive = Archive(tmp_path_factory.mktemp("survey") / "archive")
    archive.ingest(REAL_FILES, progress=False, workers=0)
    rng = np.random.default_rng(3)
    start = np.datetime64("2025-02-01T18:00", "ns")
    made = [
        synthetic_pass(90001 + k % 8, start + np.timedelta64(k * 3600, "s"), 200, rng, spin_period_s=5.0 + k)
        for k in range(40)
    ]
    archive.add(made)
    rows = archive.summaries()
    verdicts = ["confident", "ambiguous harmonic", "too short", "no signal"]
    archive.store_results(
        (row.pass_id, "periods", "default", Period(5.0 + k, 0.01 * (k + 1), verdicts[k % 4]))
        for k, row in enumerate(rows)
    )
    return archive, rows


def test_survey_queries_select_by_period_verdict_band_and_time(survey):
    archive, rows = survey
    periods = {row.pass_id: 5.0 + k for k, row in enumerate(rows)}
    chosen = archive.summaries(period_min=10, period_max=20)
    assert {row.pass_id for row in chosen} == {p for p, value in periods.items() if 10 <= value <= 20}
    assert all(10 <= row.period_s <= 20 for row in chosen)
    confident = archive.summaries(verdict="confident")
    assert len(confident) == len(rows[::4]) and {row.verdict for row in confident} == {"confident"}
    since = archive.summaries(since="2025-02-02")
    assert since and all(row.start_utc >= np.datetime64("2025-02-02") for row in since)
    assert [row.band for row in archive.summaries(band="B")] == ["B"]
    assert archive.summaries(period_min=10, periods_name="other") == []  # no such results
    with pytest.raises(ValueError, match=r"since='last tuesday' is not a UTC time"):
        archive.summaries(since="last tuesday")
    with pytest.raises(ValueError, match=r"until='3000-01-01' is not a UTC time between 1678 and 2262"):
        archive.summaries(until="3000-01-01")  # datetime64[ns] would wrap it to 1830


def test_catalog_is_a_dataframe_of_every_pass(survey):
    archive, rows = survey
    frame = archive.catalog()
    assert isinstance(frame, pd.DataFrame) and len(frame) == len(rows) == 45
    assert list(frame.pass_id) == [row.pass_id for row in rows]
    assert frame.start_utc.dtype.kind == "M" and frame.end_utc.dtype.kind == "M"
    assert {
        "norad",
        "band",
        "site",
        "duration_s",
        "n_points",
        "period_s",
        "period_err_s",
        "verdict",
        "elements",
    } <= set(frame.columns)
    topex = frame.set_index("pass_id").loc[TOPEX_ID]
    assert topex.duration_s == pytest.approx(464.162, abs=1e-3) and topex.n_points == 2320
    assert frame.period_s.tolist() == [5.0 + k for k in range(45)]
    assert len(archive.catalog(norad=51511)) == 3
    assert archive.catalog(period_min=1000).empty


def test_ls_shows_period_columns_and_filters(survey, capsys):
    archive, rows = survey
    path = str(archive.path)
    assert main(["ls", "--archive", path, "--periods", "--norad", "22076"]) == 0
    header, line = capsys.readouterr().out.splitlines()
    assert header.split()[-4:] == ["PERIOD", "S", "+-", "VERDICT"]
    assert line.split()[-3:] == ["5.0000", "0.0100", "confident"]
    assert main(["ls", "--archive", path, "--period-min", "10", "--period-max", "12", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [row["period_s"] for row in listed] == [10.0, 11.0, 12.0]
    assert main(["ls", "--archive", path, "--verdict", "nonsense"]) == 0
    assert capsys.readouterr().out.strip().endswith("matching the filters")


def test_show_prints_the_values_of_stored_results(survey, capsys):
    archive, _ = survey
    assert main(["show", TOPEX_ID, "--archive", str(archive.path)]) == 0
    text = capsys.readouterr().out
    assert "periods    default  (stored " in text
    assert "best_period_s            5\n" in text and "uncertainty_s            0.01\n" in text
    assert "verdict                  confident" in text
    assert "candidates:" in text and "period_s" in text
    assert main(["show", TOPEX_ID, "--archive", str(archive.path), "--json"]) == 0
    values = json.loads(capsys.readouterr().out)["results"]["periods"]["default"]
    assert (values["best_period_s"], values["verdict"]) == (5.0, "confident")
    assert values["candidates"][1] == {"period_s": 10.0, "power": 0.5}


class Fit:
    """A stand-in fit result: a verdict, a parameter summary and a long light-curve table."""

    def to_hdf5(self, group):
        group.attrs["verdict"] = "converged"
        group.attrs["n_steps"] = 60
        summary = np.zeros(2, dtype=[("name", "S24"), ("median", "f8")])
        summary["name"], summary["median"] = [b"spin_period_s", b"precession_period_s"], [9.87, 1944.6]
        group.create_dataset("summary", data=summary)
        lightcurve = np.zeros(50, dtype=[("mag_obs", "f8"), ("mag_model", "f8")])
        group.create_dataset("lightcurve", data=lightcurve)


def test_show_puts_a_fits_parameters_first_and_counts_long_tables(tmp_path, shared_data, capsys):
    archive = Archive(tmp_path / "archive")
    archive.ingest(REAL_FILES[:1], progress=False, workers=0)
    archive.store_result(TOPEX_ID, "fits", "quick", Fit())
    assert main(["show", TOPEX_ID, "--archive", str(archive.path)]) == 0
    text = capsys.readouterr().out
    fits = text[text.index("fits       quick") :].splitlines()
    assert fits[1].split() == ["verdict", "converged"] and fits[2].strip() == "summary:"
    assert fits[3].split() == ["name", "median"]  # a header row, names left-aligned
    assert fits[4].startswith("               spin_period_s ") and fits[4].split() == ["spin_period_s", "9.87"]
    assert "lightcurve: 50 rows (--json lists them)" in text
    assert main(["show", TOPEX_ID, "--archive", str(archive.path), "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)["results"]["fits"]["quick"]["lightcurve"]) == 50


def test_prefix_lookup_reads_only_the_object_it_names(survey, monkeypatch, tmp_path):
    source, _ = survey
    shutil.copytree(source.path, tmp_path / "archive")
    archive = Archive(tmp_path / "archive")
    archive.summaries()  # the copy's files have new inodes: index them once
    opened = []
    real = Archive._read_index_entry

    def spy(self, norad, stat):
        opened.append(norad)
        return real(self, norad, stat)

    monkeypatch.setattr(Archive, "_read_index_entry", spy)
    archive.object_path(90003).touch()  # changed behind the index: re-read only when asked about
    fresh = Archive(archive.path)
    assert fresh.get("22076-2024").pass_id == TOPEX_ID and opened == []
    fresh.summaries(norad=90003)
    assert opened == [90003]
