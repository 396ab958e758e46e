"""Satellite from TLE and OMM: parsing, validation, and propagation against authorities."""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest

from ingest.elements import tle_checksum
from ingest.site import DERENIVKA
from raycast.geometry.orbit import Satellite
from raycast.geometry.pass_geometry import PassGeometry
from tests.conftest import TLES


def tle_sets() -> dict[str, list[str]]:
    """The element sets of tles.txt keyed by their first comment line, title line included."""
    sets, comment, lines = {}, None, []
    for line in TLES.read_text().splitlines():
        if line.startswith("#"):
            comment = line
        elif line.strip():
            lines.append(line)
            if len(lines) == 3:
                sets[comment] = lines
                lines = []
    return sets


def element_set(fragment: str) -> list[str]:
    return next(lines for comment, lines in tle_sets().items() if fragment in comment)


TOPEX_2024 = element_set("epoch 2024-07-30")
TOPEX_PLUS = element_set("'+' signs")

# The TOPEX 2024-07-30 element set as CelesTrak publishes it in OMM JSON (numbers) and as
# Space-Track does (strings): the same elements, field for field.
TOPEX_OMM_CELESTRAK = {
    "OBJECT_NAME": "TOPEX/POSEIDON",
    "OBJECT_ID": "1992-052A",
    "EPOCH": "2024-07-30T12:17:56.893920",
    "MEAN_MOTION": 12.8106666,
    "ECCENTRICITY": 0.0008045,
    "INCLINATION": 66.0414,
    "RA_OF_ASC_NODE": 118.8147,
    "ARG_OF_PERICENTER": 267.5347,
    "MEAN_ANOMALY": 265.0431,
    "EPHEMERIS_TYPE": 0,
    "CLASSIFICATION_TYPE": "U",
    "NORAD_CAT_ID": 22076,
    "ELEMENT_SET_NO": 999,
    "REV_AT_EPOCH": 49552,
    "BSTAR": 2.9042e-05,
    "MEAN_MOTION_DOT": -5.4e-07,
    "MEAN_MOTION_DDOT": 0,
}
TOPEX_OMM_SPACETRACK = {key: str(value) for key, value in TOPEX_OMM_CELESTRAK.items()}

JD = np.full(7, 2460522.0)
FRACTION = np.linspace(0.3, 0.9, 7)


def test_three_lines_two_lines_and_text_give_the_same_satellite():
    three = Satellite.from_tle(TOPEX_2024)
    two = Satellite.from_tle(TOPEX_2024[1:])
    text = Satellite.from_tle("\n".join(TOPEX_2024) + "\n")
    assert (three.name, three.norad) == ("TOPEX/POSEIDON", 22076)
    assert two.name == "NORAD 22076"
    # Epoch 24212.51246405: day 212 of 2024 is 30 July; 0.51246405 d = 12:17:56.893920.
    assert three.epoch_utc == np.datetime64("2024-07-30T12:17:56.893920")
    for other in (two, text):
        assert np.array_equal(other.teme_km(JD, FRACTION)[0], three.teme_km(JD, FRACTION)[0])


def test_plus_signed_zero_padded_variant_parses_like_the_plain_one():
    # Blanking the '+' signs and the inclination's leading zero leaves the checksum unchanged
    # (both count 0) and gives the conventional form of the same elements.
    plain = [TOPEX_PLUS[0], TOPEX_PLUS[1].replace("+", " "), TOPEX_PLUS[2].replace(" 066.", "  66.")]
    variant, reference = Satellite.from_tle(TOPEX_PLUS), Satellite.from_tle(plain)
    assert variant.satrec.bstar == pytest.approx(1.4373e-5, rel=1e-12)
    assert math.degrees(variant.satrec.inclo) == pytest.approx(66.0418, abs=1e-12)
    jd = np.full(3, 2458868.5)
    fraction = np.array([0.3, 0.5, 0.7])
    assert np.array_equal(variant.teme_km(jd, fraction)[0], reference.teme_km(jd, fraction)[0])


def test_plus_signed_variant_agrees_with_pyephem_on_the_sky():
    # PyEphem has its own TLE parser and SGP4: if any '+'-signed or zero-padded field were
    # misread, the satellite would be degrees away. 0.02 deg is the tolerance the files'
    # Az/El columns are held to (tests/test_geometry.py).
    ephem = pytest.importorskip("ephem")
    satellite = Satellite.from_tle(TOPEX_PLUS)
    times = np.datetime64("2020-01-20T07:42:07") + np.arange(0, 6000, 600) * np.timedelta64(1, "s")
    geometry = PassGeometry.compute(satellite, DERENIVKA, times)
    observer = ephem.Observer()
    observer.lat, observer.lon = str(DERENIVKA.lat_deg), str(DERENIVKA.lon_deg)
    observer.elevation = DERENIVKA.elevation_m
    observer.pressure = 0.0  # geometric elevation, no refraction
    body = ephem.readtle(*TOPEX_PLUS)
    for i, time in enumerate(times):
        observer.date = time.astype("datetime64[us]").astype(dt.datetime)
        body.compute(observer)
        assert math.degrees(body.alt) == pytest.approx(geometry.el_deg[i], abs=0.02)
        assert body.range / 1000.0 == pytest.approx(geometry.range_km[i], abs=0.5)


def test_propagation_matches_skyfield_earth_satellite():
    # skyfield parses the lines itself and calls the same SGP4 at the same UTC Julian dates.
    satellite = Satellite.from_tle(TOPEX_2024)
    from skyfield.api import EarthSatellite

    from raycast.geometry.ephemeris import timescale

    reference = EarthSatellite(TOPEX_2024[1], TOPEX_2024[2], TOPEX_2024[0], timescale())
    t = timescale().utc(2024, 7, 30, 21, 22, np.arange(0.0, 600.0, 60.0))
    expected, _, _ = reference._position_and_velocity_TEME_km(t)
    actual, _, error = satellite.teme_km(t.whole, t.tai_fraction - t._leap_seconds() / 86400.0)
    assert not error.any()
    np.testing.assert_allclose(actual.T, expected, atol=1e-9)  # km: identical computation


@pytest.mark.parametrize("record", [TOPEX_OMM_CELESTRAK, TOPEX_OMM_SPACETRACK], ids=["celestrak", "spacetrack"])
def test_omm_record_propagates_like_the_same_tle(record):
    from_omm, from_tle = Satellite.from_omm(record), Satellite.from_tle(TOPEX_2024)
    assert (from_omm.name, from_omm.norad, from_omm.epoch_utc) == (from_tle.name, from_tle.norad, from_tle.epoch_utc)
    # Same elements and an epoch equal to the microsecond: positions agree to float rounding.
    np.testing.assert_allclose(from_omm.teme_km(JD, FRACTION)[0], from_tle.teme_km(JD, FRACTION)[0], atol=1e-6)
    assert from_omm.omm == dict(record) and from_omm.tle is None


def test_checksum_of_every_stored_line_is_valid():
    for lines in tle_sets().values():
        for line in lines[1:]:
            assert tle_checksum(line) == int(line[68])


@pytest.mark.parametrize(
    "lines, message",
    [
        ([TOPEX_2024[1]], "a TLE has 2 or 3 lines but 1 were given"),
        ([TOPEX_2024[1][:-1] + "5", TOPEX_2024[2]], "TLE line 1 checksum is 4 but the line ends in '5'"),
        ([TOPEX_2024[1][:60], TOPEX_2024[2]], "TLE line 1 has 60 characters instead of 69"),
        ([TOPEX_2024[2], TOPEX_2024[1]], "TLE line 1 must start with '1 '"),
        (
            [TOPEX_2024[1], element_set("COSMOS 2502")[2]],
            "TLE lines disagree on the catalogue number ('22076' vs '40358')",
        ),
    ],
)
def test_bad_tle_is_refused_with_a_clear_message(lines, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        Satellite.from_tle(lines)


def test_bad_omm_is_refused_with_a_clear_message():
    record = dict(TOPEX_OMM_CELESTRAK)
    del record["BSTAR"], record["EPOCH"]
    with pytest.raises(ValueError, match="OMM record lacks EPOCH, BSTAR"):
        Satellite.from_omm(record)
    with pytest.raises(ValueError, match="OMM field ECCENTRICITY='abc' is not a number"):
        Satellite.from_omm({**TOPEX_OMM_CELESTRAK, "ECCENTRICITY": "abc"})
    with pytest.raises(ValueError, match="OMM EPOCH='July' is not an ISO 8601 time"):
        Satellite.from_omm({**TOPEX_OMM_CELESTRAK, "EPOCH": "July"})
    with pytest.raises(TypeError, match="an OMM record must be a mapping"):
        Satellite.from_omm("EPOCH=2024")


def test_geometry_refuses_times_sgp4_cannot_reach():
    # A heavy drag term decays the orbit within weeks; SGP4 reports the decay.
    decaying = Satellite.from_omm({**TOPEX_OMM_CELESTRAK, "BSTAR": 0.5, "MEAN_MOTION": 16.2})
    times = np.array(["2024-07-30T12:30", "2026-07-30T12:30"], dtype="datetime64[ns]")
    with pytest.raises(ValueError, match=r"SGP4 cannot propagate TOPEX/POSEIDON \(NORAD 22076\) to 2026-07-30"):
        PassGeometry.compute(decaying, DERENIVKA, times)
