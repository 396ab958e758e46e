"""Geometry from a file's own Az/El/range columns (`raycast.geometry.track`), against SGP4.

Authorities: the TOPEX file of 2024-07-30 carries both its TLE and PyEphem's columns computed
from it; the COSMOS 2553 ``.phc`` pass of 2025-01-30 carries no TLE, and the only COSMOS 2553
set we have is the one in the header of the 2025-03-11 file, 39 days later: SGP4 carries its
orbital plane back across those days (the node drifts ~1.5 deg a day), so the plane of the
track must agree with it, while the position along the orbit may not (drag, 39 days).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import ingest
from raycast.geometry import ObservedTrack, PassGeometry, orbit_of
from raycast.geometry.orbit import Satellite
from raycast.geometry.pass_geometry import COLUMNS_AGREE_DEG, columns_offset_deg, track_of
from rsodb.cli import main
from rsodb.fit.curves import geometry_at
from tests.conftest import COSMOS2553_JD_PHV, COSMOS2553_PHC, TOPEX_PHV


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


@pytest.fixture(scope="module")
def topex(shared_data):
    (observed,) = ingest.read_file(TOPEX_PHV)
    return observed


def test_the_track_of_the_topex_columns_is_where_sgp4_puts_topex(topex):
    track = track_of(topex)
    assert track.rms_km < 0.03 and track.n_clipped == 0 and track.degree <= 8  # the columns' rounding
    assert track.site.name == "Derenivka" and track.n_rows == topex.time_utc.size
    from_track = PassGeometry.compute(track, topex.site, topex.time_utc, topex.exposure_s, n_sub=2)
    from_tle = PassGeometry.from_pass(topex, n_sub=2)
    # Measured: 68 m median, 74 m at most; lines of sight 6.4", orbital frame 2.2" at most.
    distance_km = np.linalg.norm(from_track.sat_gcrs_km - from_tle.sat_gcrs_km, axis=1)
    assert np.median(distance_km) < 0.12 and distance_km.max() < 0.15
    assert _angle_deg(from_track.obs_gcrs, from_tle.obs_gcrs).max() < 15 / 3600
    for column in range(3):
        frame_error = _angle_deg(from_track.lvlh_gcrs[..., column], from_tle.lvlh_gcrs[..., column])
        assert frame_error.max() < 10 / 3600
    assert np.abs(from_track.range_rate_km_s - from_tle.range_rate_km_s).max() < 0.001
    np.testing.assert_allclose(from_track.sunlit_fraction, from_tle.sunlit_fraction, atol=1e-3)


def test_the_phc_track_lies_in_the_plane_of_the_only_cosmos_2553_set_39_days_later(shared_data):
    blue, visual = ingest.read_file(COSMOS2553_PHC)
    (later,) = ingest.read_file(COSMOS2553_JD_PHV)
    assert visual.tle is None and visual.omm is None
    geometry = PassGeometry.from_pass(visual, n_sub=1)  # no elements: the track of its columns
    track = geometry.satellite
    assert isinstance(track, ObservedTrack) and track.site.name == "Derenivka"  # the writer's site, not Uzhhorod
    assert "computed for Derenivka" in track.description
    sgp4 = PassGeometry.compute(Satellite.from_tle(later.tle), visual.site, visual.time_utc, 0.0, n_sub=1)
    # Measured: 0.026 deg between the orbit normals, 6.8 km apart along the orbit, radii within 1 km.
    plane_deg = _angle_deg(geometry.lvlh_gcrs[:, 0, :, 1], sgp4.lvlh_gcrs[:, 0, :, 1])
    assert plane_deg.max() < 0.1
    assert np.median(np.linalg.norm(geometry.sat_gcrs_km - sgp4.sat_gcrs_km, axis=1)) < 30.0
    radius = np.linalg.norm(geometry.sat_gcrs_km, axis=1)
    assert np.abs(radius - np.linalg.norm(sgp4.sat_gcrs_km, axis=1)).max() < 2.0
    # The observer is the photometer at Uzhhorod, whatever site the columns were computed for.
    assert geometry.site.name == "Uzhhorod"
    # B and V of one pass share their rows' columns: one track.
    assert orbit_of(blue).rms_km == pytest.approx(track.rms_km, rel=0.05)


def test_the_jd_file_s_columns_contradict_its_own_header_tle(shared_data):
    """A fact about that file the phc track brings out: its Az/El/range columns are not the orbit its
    header TLE (confirmed by the phc pass above) describes. The fit uses the TLE."""
    (observed,) = ingest.read_file(COSMOS2553_JD_PHV)
    from_columns = PassGeometry.compute(track_of(observed), observed.site, observed.time_utc, 0.0, n_sub=1)
    from_tle = PassGeometry.from_pass(observed, n_sub=1)
    assert isinstance(from_tle.satellite, Satellite)
    # Measured: 10.8 deg between the lines of sight (median), 8.0 deg between the orbital planes.
    assert np.median(_angle_deg(from_columns.obs_gcrs[:, 0], from_tle.obs_gcrs[:, 0])) > 5.0
    # The same, straight from the columns: 10.77 deg median, 12.47 at most.
    median, most = columns_offset_deg(observed)
    assert COLUMNS_AGREE_DEG < 5.0 < median <= most < 20.0


def test_the_columns_of_the_other_files_follow_their_elements(topex, tmp_path, capsys):
    # Measured: TOPEX 0.0016 deg median, 0.0023 at most (PyEphem from the same TLE).
    median, most = columns_offset_deg(topex)
    assert median < 0.005 and most < 0.01 < COLUMNS_AGREE_DEG
    (phc_v, _) = ingest.read_file(COSMOS2553_PHC)[::-1]
    assert columns_offset_deg(phc_v) is None  # no elements to compare with
    archive = tmp_path / "archive"
    assert main(["ingest", str(TOPEX_PHV), str(COSMOS2553_JD_PHV), "--archive", str(archive), "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["show", "51511-20250311", "--archive", str(archive)]) == 0
    assert "columns    the file's Az/El DISAGREE with the elements by 10.77 deg" in capsys.readouterr().out
    assert main(["show", "22076", "--archive", str(archive), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["columns_vs_elements_deg"]["median"] < 0.005


def test_a_damaged_row_is_set_aside_and_the_track_holds(topex):
    az = topex.az_deg.copy()
    az[1000] += 5.0  # one row's azimuth off by 5 deg: ~270 km at that range
    damaged = dataclasses.replace(topex, az_deg=az)
    track = track_of(damaged)
    assert track.n_clipped == 1 and "1 rows set aside" in track.description
    clean = track_of(topex)
    times = topex.time_utc[::97]
    position, _ = track.gcrs_state_km(times)
    reference, _ = clean.gcrs_state_km(times)
    assert np.linalg.norm(position - reference, axis=0).max() < 0.01


def test_a_track_is_refused_outside_its_span_and_for_rough_or_missing_columns(topex):
    track = track_of(topex)
    inside = topex.time_utc[-1] + np.timedelta64(10, "s")  # within the margin (2 s + 5% of 464 s)
    assert track.gcrs_state_km(np.array([inside]))[0].shape == (3, 1)
    later = topex.time_utc[-1] + np.timedelta64(60, "s")
    with pytest.raises(ValueError, match="has no orbital elements, only a track .* outside it"):
        track.gcrs_state_km(np.array([later]))
    with pytest.raises(ValueError, match="outside it"):
        geometry_at(dataclasses.replace(topex, tle=None), np.array([later]), 0.0, 1, None)
    rng = np.random.default_rng(3)
    rough = dataclasses.replace(topex, el_deg=topex.el_deg + rng.normal(0.0, 0.5, topex.el_deg.size))
    with pytest.raises(ValueError, match="do not describe a smooth orbit"):
        track_of(rough)
    empty = dataclasses.replace(topex, tle=None, range_km=np.full(topex.range_km.size, np.nan))
    with pytest.raises(ValueError, match="has 0 rows with Az, El and range .* 'rsodb elements add TLE_FILE'"):
        orbit_of(empty)
