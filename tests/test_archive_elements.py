"""Orbits for every pass (issue 17): elements from a TLE or OMM catalogue, at ingest
(``rsodb ingest --tle``) or for stored passes (``rsodb elements add``), with their provenance.

The authority is the files' own Az/El columns: PyEphem (ccd_phot) and phc.pyw computed them from
an element set for Derenivka, so a set that puts the satellite where they say is the right one.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import ingest
from ingest.elements import ElementCatalogue, tle_epoch_utc
from raycast.geometry.orbit import Satellite
from raycast.geometry.pass_geometry import PassGeometry
from raycast.geometry.track import ObservedTrack
from rsodb.archive import Archive
from rsodb.cli import main
from tests.conftest import COSMOS2553_JD_PHV, COSMOS2553_PHC, TLES, TOPEX_PHV

B_ID = "51511-20250130T171941-B-uzhhorod"


@pytest.fixture
def topex_without_tle(tmp_path, shared_data):
    """The real TOPEX file with its TLE block removed (NORAD still in the header)."""
    lines = TOPEX_PHV.read_text().splitlines(keepends=True)
    path = tmp_path / TOPEX_PHV.name
    path.write_text("".join(lines[4:]))
    return path


@pytest.fixture
def cosmos2553_catalogue(tmp_path, shared_data):
    """A TLE catalogue holding the only COSMOS 2553 set we have: the one in the header of the
    real 2025-03-11 file (epoch 2025-03-10, 39 days after the 2025-01-30 .phc pass).
    ../shared/data/tle/tles.txt has no set of 51511."""
    (observed,) = ingest.read_file(COSMOS2553_JD_PHV)
    path = tmp_path / "cosmos2553.tle"
    path.write_text("# from the header of 51511_20250311_UT173120_OES30.phV\n" + "\n".join(observed.tle) + "\n")
    return path


def test_catalogues_read_tle_and_omm(tmp_path, shared_data):
    catalogue = ElementCatalogue.from_file(TLES)
    assert catalogue.norads == [22076, 40358] and len(catalogue) == 4
    chosen = catalogue.nearest(22076, np.datetime64("2020-08-02T00:00"))
    assert chosen.where == "line 12" and chosen.epoch_utc == np.datetime64("2020-01-20T07:42:07.380", "ns")
    # The epoch as skyfield reads it (line 1 columns 19-32).
    assert tle_epoch_utc(chosen.tle) == chosen.epoch_utc
    omm = tmp_path / "omm.json"
    omm.write_text(json.dumps([{"NORAD_CAT_ID": 51511, "EPOCH": "2025-03-10T21:53:34.301184", "MEAN_MOTION": 11.3}]))
    (record,) = [ElementCatalogue.from_file(omm).nearest(51511, np.datetime64("2025-03-01"))]
    assert record.omm["MEAN_MOTION"] == 11.3 and record.where == "record 1"
    (tmp_path / "bad.json").write_text('[{"NORAD_CAT_ID": 5, "EPOCH": "yesterday"}]')
    with pytest.raises(ValueError, match=r"bad\.json: record 1: the OMM record's EPOCH 'yesterday' is not"):
        ElementCatalogue.from_file(tmp_path / "bad.json")


def test_ingest_with_a_catalogue_gives_the_nearest_set_and_records_it(tmp_path, topex_without_tle, capsys):
    archive = tmp_path / "archive"
    assert main(["ingest", str(topex_without_tle), "--tle", str(TLES), "--archive", str(archive), "--no-progress"]) == 0
    capsys.readouterr()
    stored = Archive(archive).get("22076")
    assert stored.tle[1].startswith("1 22076U 92052A   24212.51246405")  # the 2024-07-30 set, not 2020/2021
    source = dict(stored.elements_source)
    assert (source["source"], source["file"], source["where"]) == ("catalogue", "tles.txt", "line 4")
    assert source["epoch_utc"] == "2024-07-30T12:17:56.893920Z" and 0.37 < source["age_days"] < 0.38
    # That set puts TOPEX where the file's Az/El say (PyEphem, same set): measured 0.003 deg in
    # azimuth and 0.053 deg in elevation at most (17 deg elevation, where refraction models differ).
    geometry = PassGeometry.from_pass(stored)
    assert np.max(np.abs(geometry.az_deg - stored.az_deg)) < 0.01
    assert np.max(np.abs(geometry.el_deg - stored.el_deg)) < 0.1
    assert main(["show", "22076", "--archive", str(archive)]) == 0
    assert "elements   from tles.txt (line 4), epoch 2024-07-30T12:17:56.893920Z, 0.4 days" in capsys.readouterr().out


def test_the_real_phc_pass_gets_an_orbit_within_the_stated_age(tmp_path, cosmos2553_catalogue, capsys):
    archive = tmp_path / "archive"
    args = ["ingest", str(COSMOS2553_PHC), "--tle", str(cosmos2553_catalogue), "--archive", str(archive)]
    assert main([*args, "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert (
        "no orbit: the nearest element set of NORAD 51511 in cosmos2553.tle (line 3, epoch 2025-03-10T21:53:34)" in out
    )
    assert "is 39.2 days from the pass, more than the 30 allowed" in out
    stored = Archive(archive).get(B_ID)
    assert stored.tle is None and stored.warnings[0].reason.startswith("no orbit:")
    assert main(["show", B_ID, "--archive", str(archive)]) == 0
    assert (
        "orbit      no elements: the geometry is a track fitted to the file's Az/El/range columns, good within the "
        "pass; add elements with 'rsodb elements add FILE'" in capsys.readouterr().out
    )
    # Without elements, render and fit use the track of the file's own columns (tests/test_track.py).
    assert isinstance(PassGeometry.from_pass(stored, n_sub=1).satellite, ObservedTrack)

    # rsodb elements add, with the age stated, for the stored passes.
    assert main(["elements", "add", str(cosmos2553_catalogue), "--archive", str(archive), "--max-age-days", "45"]) == 0
    assert "added elements from cosmos2553.tle to 2 pass(es); 0 left without" in capsys.readouterr().out
    b, v = Archive(archive).passes(norad=51511)
    assert b.tle == v.tle and b.elements_source["age_days"] == pytest.approx(39.19, abs=0.01)
    assert not b.warnings  # the "no orbit" warning went with the orbit's arrival
    # The pass is fittable: its geometry. phc.pyw computed Az/El for Derenivka at each integration
    # start; the 39-day-old set reproduces them to 0.18 deg (azimuth) and 0.07 deg (elevation).
    geometry = PassGeometry.compute(
        Satellite.from_tle(b.tle),
        ingest.DERENIVKA,
        b.time_utc - np.timedelta64(500, "ms"),
        b.exposure_s,
    )
    assert np.max(np.abs(geometry.az_deg - b.az_deg)) < 0.25
    assert np.max(np.abs(geometry.el_deg - b.el_deg)) < 0.1
    rows = Archive(archive).summaries(norad=51511)
    assert [row.elements for row in rows] == ["catalogue", "catalogue"]


def test_header_elements_are_never_replaced_and_nearer_sets_replace_catalogue_ones(
    tmp_path, topex_without_tle, shared_data
):
    archive = Archive(tmp_path / "archive")
    far = tmp_path / "far.tle"
    far.write_text("\n".join(ElementCatalogue.from_file(TLES).nearest(22076, np.datetime64("2021-06-09")).tle) + "\n")
    archive.ingest([topex_without_tle, COSMOS2553_JD_PHV], progress=False, workers=0, elements=far, max_age_days=5000)
    assert archive.get("22076").elements_source["where"] == "line 2"  # the 2021 set: the only one given
    report = archive.add_elements(TLES, max_age_days=5000)
    assert report.changed == ()  # without replace_catalogue nothing that has elements changes
    report = archive.add_elements(TLES, max_age_days=5000, replace_catalogue=True)
    assert report.changed == ("22076-20240730T212240-V-derenivka",)
    assert archive.get("22076").elements_source["epoch_utc"].startswith("2024-07-30")
    # The JD file's own header TLE stays (its Az/El were computed with it).
    (jd,) = ingest.read_file(COSMOS2553_JD_PHV)
    assert archive.get("51511").tle == jd.tle and archive.get("51511").elements_source is None
