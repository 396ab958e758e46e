"""PassGeometry against the files' PyEphem columns, skyfield, astropy and exact answers."""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest

import ingest
from ingest.site import DERENIVKA, WGS84_A_KM, WGS84_F, Site
from raycast.geometry.attitude import InertialSpin, PrecessingSpin
from raycast.geometry.ephemeris import planets, timescale
from raycast.geometry.orbit import Satellite
from raycast.geometry.pass_geometry import PassGeometry, choose_n_sub
from raycast.geometry.refraction import apparent_elevation_deg, true_elevation_deg
from raycast.geometry.shadow import SUN_RADIUS_KM, disk_visible_fraction, sunlit_fraction
from tests.conftest import COSMOS2540_PHV, COSMOS2553_JD_PHV, TOPEX_PHV

TOPEX_TLE = (
    "0 TOPEX/POSEIDON",
    "1 22076U 92052A   24212.51246405 -.00000054  00000-0  29042-4 0  9994",
    "2 22076  66.0414 118.8147 0008045 267.5347 265.0431 12.81066660495523",
)
TOPEX = Satellite.from_tle(TOPEX_TLE)
PASS_START = np.datetime64("2024-07-30T21:22:40.008849", "ns")
# TOPEX enters the Earth's shadow at about this time on 2024-07-30 (penumbra ~10 s long).
ECLIPSE_WINDOW_START = np.datetime64("2024-07-30T12:09:25", "ns")


def seconds(values) -> np.ndarray:
    return (np.asarray(values) * 1e9).round().astype("int64").astype("timedelta64[ns]")


def file_geometry(path):
    """Geometry at a file's own time stamps (what PyEphem was given), with the pass it came from."""
    (observed,) = ingest.read_file(path)
    stamps = observed.time_utc - seconds(observed.time_shift_s)
    geometry = PassGeometry.compute(Satellite.from_tle(observed.tle), observed.site, stamps, observed.exposure_s)
    return observed, geometry


def pyephem_columns(observed, stamps):
    """Az, El (refracted, PyEphem defaults) and range at `stamps`, computed live by PyEphem."""
    ephem = pytest.importorskip("ephem")
    observer = ephem.Observer()
    observer.lat, observer.lon = str(observed.site.lat_deg), str(observed.site.lon_deg)
    observer.elevation = observed.site.elevation_m
    body = ephem.readtle(*observed.tle)
    rows = []
    for stamp in stamps:
        observer.date = stamp.astype("datetime64[us]").astype(dt.datetime)
        body.compute(observer)
        rows.append((math.degrees(body.az), math.degrees(body.alt), body.range / 1000.0))
    return np.array(rows).T


def assert_matches_sky_columns(geometry, az_deg, el_deg, range_km):
    # Tolerances: 0.02 deg in El and in Az cos(El) (an arc on the sky), 0.5 km in range, over
    # all rows: PyEphem uses its own SGP4 and frames, and the files round to 0.001 deg/km.
    d_el = geometry.el_refracted_deg - el_deg
    d_az_arc = ((geometry.az_deg - az_deg + 180.0) % 360.0 - 180.0) * np.cos(np.radians(el_deg))
    d_range = geometry.range_km - range_km
    assert np.abs(d_el).max() <= 0.02, f"max |dEl| = {np.abs(d_el).max():.5f} deg"
    assert np.abs(d_az_arc).max() <= 0.02, f"max |dAz| cos El = {np.abs(d_az_arc).max():.5f} deg"
    assert np.abs(d_range).max() <= 0.5, f"max |dRg| = {np.abs(d_range).max():.4f} km"


# -- validation against the observation files -------------------------------------------------
@pytest.mark.parametrize("path", [TOPEX_PHV, COSMOS2540_PHV], ids=lambda p: p.name)
def test_az_el_range_match_the_file_columns_on_every_row(path):
    observed, geometry = file_geometry(path)
    assert observed.time_shift_s == 0.0  # files since 2023-02 stamp mid-exposure already
    assert_matches_sky_columns(geometry, observed.az_deg, observed.el_deg, observed.range_km)


def test_jd_file_columns_do_not_follow_its_header_tle_but_pyephem_agrees_with_us():
    # The COSMOS 2553 JD-variant file's Az/El/Rg columns were not computed from its header TLE:
    # PyEphem itself, given the header TLE, site and stamps, is 10 deg off in Az. So this file is
    # checked against PyEphem run live on every row, with the same tolerances.
    observed, geometry = file_geometry(COSMOS2553_JD_PHV)
    az, el, rng = pyephem_columns(observed, geometry.time_utc)
    assert np.abs((az - observed.az_deg + 180) % 360 - 180).max() > 5.0
    assert_matches_sky_columns(geometry, az, el, rng)


def test_pyephem_refraction_model_is_reproduced():
    # PyEphem's apparent altitude (pressure 1010 mbar, 15 C) against its geometric one
    # (pressure 0) over a whole TOPEX pass from the horizon to 82 deg (it culminates at 11:41);
    # libastro's secant solver stops at 0.1 arcsec, which sets the tolerance.
    ephem = pytest.importorskip("ephem")
    observer = ephem.Observer()
    observer.lat, observer.lon, observer.elevation = (
        str(DERENIVKA.lat_deg),
        str(DERENIVKA.lon_deg),
        DERENIVKA.elevation_m,
    )
    body = ephem.readtle(*TOPEX_TLE)
    true, apparent = [], []
    for minute in np.arange(-13.0, 13.0, 0.25):
        observer.date = (
            (np.datetime64("2024-07-30T11:41") + seconds(60.0 * minute)).astype("datetime64[us]").astype(dt.datetime)
        )
        for pressure, out in ((0.0, true), (1010.0, apparent)):
            observer.pressure = pressure
            body.compute(observer)
            out.append(math.degrees(body.alt))
    true, apparent = np.array(true), np.array(apparent)
    keep = true > -1.0
    assert keep.sum() > 60 and true[keep].max() > 80.0
    np.testing.assert_allclose(apparent_elevation_deg(true[keep]), apparent[keep], atol=0.1 / 3600)
    np.testing.assert_allclose(true_elevation_deg(apparent_elevation_deg(true)), true, atol=1e-9)


# -- the interpolated frames against skyfield evaluated at every time ---------------------------
def skyfield_reference(satellite, site, times):
    """Satellite GCRS/ITRS positions, Alt/Az/range/range rate and Sun directions, per time."""
    from skyfield.api import wgs84
    from skyfield.framelib import itrs

    ts = timescale()
    t = ts.from_datetimes([x.astype("datetime64[us]").astype(dt.datetime).replace(tzinfo=dt.UTC) for x in times])
    # from_datetimes drops sub-microsecond parts; our times are whole microseconds here.
    earth_satellite = satellite.to_skyfield()
    position = earth_satellite.at(t)
    topocentre = wgs84.latlon(site.lat_deg, site.lon_deg, site.elevation_m)
    relative = (earth_satellite - topocentre).at(t)
    alt, az, distance = relative.altaz()
    *_, range_rate = relative.frame_latlon_and_rates(topocentre)
    sun = planets()["earth"].at(t).observe(planets()["sun"]).apparent().position.km.T - position.position.km.T
    return {
        "sat_gcrs_km": position.position.km.T,
        "sat_itrs_km": position.frame_xyz(itrs).km.T,
        "el_deg": alt.degrees,
        "az_deg": az.degrees,
        "range_km": distance.km,
        "range_rate_km_s": range_rate.km_per_s,
        "sun": sun / np.linalg.norm(sun, axis=1)[:, None],
    }


def assert_matches_skyfield(geometry, reference):
    # Interpolating the slow frame terms between nodes 60 s apart costs, by the bounds in the
    # module docstring, well under a millimetre; 1e-6 km (1 mm), 1e-7 deg and 1e-9 km/s leave
    # room for float rounding only.
    np.testing.assert_allclose(geometry.sat_gcrs_km, reference["sat_gcrs_km"], atol=1e-6)
    np.testing.assert_allclose(geometry.sat_itrs_km, reference["sat_itrs_km"], atol=1e-6)
    np.testing.assert_allclose(geometry.el_deg, reference["el_deg"], atol=1e-7)
    np.testing.assert_allclose((geometry.az_deg - reference["az_deg"] + 180) % 360 - 180, 0.0, atol=1e-7)
    np.testing.assert_allclose(geometry.range_km, reference["range_km"], atol=1e-6)
    np.testing.assert_allclose(geometry.range_rate_km_s, reference["range_rate_km_s"], atol=1e-8)
    angle_rad = np.linalg.norm(geometry.sun_gcrs[:, 0] - reference["sun"], axis=1)  # chord = angle here
    assert angle_rad.max() < 1e-10


def test_interpolated_frames_match_skyfield_at_every_time_over_three_hours():
    times = PASS_START - seconds(5400.0) + seconds(np.arange(0.0, 10800.0, 7.3))
    geometry = PassGeometry.compute(TOPEX, DERENIVKA, times)
    assert_matches_skyfield(geometry, skyfield_reference(TOPEX, DERENIVKA, times))


def test_times_across_a_leap_second_match_skyfield():
    # UTC 2016-12-31T23:59:60 was inserted; the node interval around it must not smear UT1.
    satellite = Satellite.from_tle(
        [
            "1 22076U 92052A   16366.50000000 -.00000054  00000-0  29042-4 0  9993",
            "2 22076  66.0414 118.8147 0008045 267.5347 265.0431 12.81066660495523",
        ]
    )
    times = np.datetime64("2016-12-31T23:59:00", "ns") + seconds(np.arange(0.0, 120.0, 3.7))
    geometry = PassGeometry.compute(satellite, DERENIVKA, times)
    assert_matches_skyfield(geometry, skyfield_reference(satellite, DERENIVKA, times))


def test_sparse_times_years_apart_are_computed_without_a_dense_grid():
    times = np.array(["2024-07-30T21:22:40", "2025-01-30T17:36:50", "2025-03-11T17:31:20"], dtype="datetime64[ns]")
    geometry = PassGeometry.compute(TOPEX, DERENIVKA, times)
    assert_matches_skyfield(geometry, skyfield_reference(TOPEX, DERENIVKA, times))


# -- the Sun and the Earth's shadow ----------------------------------------------------------
@pytest.fixture(scope="module")
def astropy_offline():
    """astropy with its bundled IERS tables only (astropy-iers-data): no downloads."""
    from astropy.utils import iers

    with iers.conf.set_temp("auto_download", False):
        yield iers


def test_sun_direction_matches_astropy(astropy_offline):
    from astropy.coordinates import get_body
    from astropy.time import Time
    import astropy.units as u

    times = PASS_START + seconds(np.arange(0.0, 460.0, 20.0))
    geometry = PassGeometry.compute(TOPEX, DERENIVKA, times)
    sun = get_body("sun", Time(times, scale="utc")).cartesian.xyz.to_value(u.km).T  # apparent, GCRS
    expected = sun - geometry.sat_gcrs_km
    expected /= np.linalg.norm(expected, axis=1)[:, None]
    angle_deg = np.degrees(np.arccos(np.clip(np.sum(expected * geometry.sun_gcrs[:, 0], axis=1), -1, 1)))
    assert angle_deg.max() < 0.01  # the required agreement; measured ~1e-5 deg


def grazing_discriminant(satellite, when, ts):
    """Independent shadow edge: > 0 while the ray from the satellite to the Sun's centre meets
    the WGS84 ellipsoid, < 0 when it misses. Sun from astropy, satellite from skyfield's full
    frame chain, ellipsoid x A x = 1 intersected with the ray as a quadratic."""
    from astropy.coordinates import ITRS, get_body
    from astropy.time import Time
    import astropy.units as u
    from skyfield.framelib import itrs

    moment = Time(str(when.astype("datetime64[us]")), scale="utc")
    sun = get_body("sun", moment).transform_to(ITRS(obstime=moment)).cartesian.xyz.to_value(u.km)
    p = satellite.to_skyfield().at(ts.from_astropy(moment)).frame_xyz(itrs).km
    polar_km = WGS84_A_KM * (1.0 - WGS84_F)
    a = np.array([WGS84_A_KM**-2, WGS84_A_KM**-2, polar_km**-2])
    d = sun - p
    return np.sum(p * a * d) ** 2 - np.sum(d * a * d) * (np.sum(p * a * p) - 1.0)


@pytest.fixture(scope="module")
def eclipse_entry():
    """Sunlit fraction every millisecond through TOPEX's shadow entry."""
    times = ECLIPSE_WINDOW_START + seconds(np.arange(0.0, 20.0, 0.001))
    return times, PassGeometry.compute(TOPEX, DERENIVKA, times)


def test_eclipse_entry_time_matches_an_independent_computation(astropy_offline, eclipse_entry):
    from scipy.optimize import brentq

    times, geometry = eclipse_entry
    fraction = geometry.sunlit_fraction
    i = int(np.flatnonzero(fraction < 0.5)[0])
    half_s = geometry.t_s[i - 1] + 0.001 * (fraction[i - 1] - 0.5) / (fraction[i - 1] - fraction[i])
    ts = timescale()
    graze_s = brentq(lambda s: grazing_discriminant(TOPEX, ECLIPSE_WINDOW_START + seconds(s), ts), 0.0, 20.0, xtol=1e-5)
    # Half the solar disk is hidden when the Sun's centre sits on the limb. The Sun moves across
    # the limb at ~0.055 deg/s here (0.53 deg in 9.8 s), so 0.02 s is 4 arcsec: above the flat-disk
    # overlap formula's curvature error (~1 arcsec, measured offset 0.005 s) and far above the
    # Sun (astropy vs DE421, 0.04 arcsec) and frame differences.
    assert half_s == pytest.approx(graze_s, abs=0.02)


def test_shadow_is_one_in_sunlight_zero_in_umbra_and_monotonic_in_penumbra(eclipse_entry):
    _, geometry = eclipse_entry
    fraction = geometry.sunlit_fraction
    assert fraction[0] == 1.0 and fraction[-1] == 0.0
    assert np.all(np.diff(fraction) <= 1e-12)
    umbra = PassGeometry.compute(TOPEX, DERENIVKA, ECLIPSE_WINDOW_START + seconds(np.arange(600.0, 1800.0, 60.0)))
    assert np.all(umbra.sunlit_fraction == 0.0)
    observed = PassGeometry.compute(TOPEX, DERENIVKA, PASS_START + seconds(np.arange(0.0, 460.0, 10.0)))
    assert np.all(observed.sunlit_fraction == 1.0)  # the observed pass was in sunlight


def test_penumbra_lasts_as_long_as_the_sun_disk_takes_to_cross_the_limb(astropy_offline, eclipse_entry):
    times, geometry = eclipse_entry
    fraction = geometry.sunlit_fraction
    first_contact = geometry.t_s[np.flatnonzero(fraction < 1.0)[0]]
    second_contact = geometry.t_s[np.flatnonzero(fraction <= 0.0)[0]]
    middle = times[0] + seconds(0.5 * (first_contact + second_contact))
    # Expected: the Sun's angular diameter 2a divided by the rate at which its centre moves
    # across the Earth's limb, d(c - b)/dt, both computed here from skyfield positions and
    # astropy's Sun (Earth stretched to a sphere along its axis, as the model does).
    from astropy.coordinates import ITRS, get_body
    from astropy.time import Time
    import astropy.units as u
    from skyfield.framelib import itrs

    stretch = np.array([1.0, 1.0, 1.0 / (1.0 - WGS84_F)])
    ts = timescale()

    def limb_angles(when):
        moment = Time(str(when.astype("datetime64[us]")), scale="utc")
        sun = get_body("sun", moment).transform_to(ITRS(obstime=moment)).cartesian.xyz.to_value(u.km)
        p = TOPEX.to_skyfield().at(ts.from_astropy(moment)).frame_xyz(itrs).km
        to_sun, p = (sun - p) * stretch, p * stretch
        c = np.arccos(-(p @ to_sun) / (np.linalg.norm(p) * np.linalg.norm(to_sun)))
        b = np.arcsin(WGS84_A_KM / np.linalg.norm(p))
        return c - b, np.arcsin(SUN_RADIUS_KM / np.linalg.norm(sun - p / stretch))

    before, sun_radius = limb_angles(middle - seconds(1.0))
    after, _ = limb_angles(middle + seconds(1.0))
    expected_s = 2.0 * sun_radius / abs(after - before) * 2.0
    # 1 %: the crossing rate drifts slightly over the ~10 s penumbra; sampling is 1 ms.
    assert second_contact - first_contact == pytest.approx(expected_s, rel=0.01)
    assert math.degrees(2 * sun_radius) == pytest.approx(0.525, abs=0.005)  # July: Earth near aphelion


def test_disk_overlap_exact_cases():
    a = math.radians(0.2666)
    assert disk_visible_fraction(a, 1.0, 1.0 + 1.01 * a) == 1.0
    assert disk_visible_fraction(a, 1.0, 1.0 - 1.01 * a) == 0.0
    # Equal disks one radius apart overlap by r^2 (2 pi / 3 - sqrt(3) / 2).
    assert disk_visible_fraction(a, a, a) == pytest.approx(1.0 / 3.0 + math.sqrt(3.0) / (2.0 * math.pi), rel=1e-12)
    # Sun centre on the limb: half hidden but for the limb's curvature, which uncovers a sliver
    # of a^3 / (3 b), i.e. a fraction a / (3 pi b), to first order in a / b.
    assert disk_visible_fraction(a, 1.0, 1.0) == pytest.approx(0.5 + a / (3 * math.pi), abs=1e-6)
    # Small disk in front of the large one's centre (annular): ring of 1 - (b/a)^2 visible.
    assert disk_visible_fraction(2 * a, a, 0.0) == pytest.approx(0.75, rel=1e-12)
    c = np.linspace(1.0 - 1.2 * a, 1.0 + 1.2 * a, 501)
    assert np.all(np.diff(disk_visible_fraction(a, 1.0, c)) >= 0.0)


def test_spherical_earth_shadow_has_the_cylinder_limit():
    # Sun at 1 au along +x; a satellite behind the Earth at distance r from the axis: in the
    # umbra when r < R (1 - ~r_sat tan(a)), in sunlight beyond.
    sun = np.array([1.496e8, 0.0, 0.0])
    inside = np.array([-7000.0, 0.0, WGS84_A_KM - 100.0])
    outside = np.array([-7000.0, 0.0, WGS84_A_KM + 100.0])
    assert sunlit_fraction(np.stack([inside, outside]), sun, flattening=0.0).tolist() == [0.0, 1.0]


# -- per-time quantities, sub-samples and the body frame ----------------------------------------
@pytest.fixture(scope="module")
def topex_pass():
    return PassGeometry.compute(TOPEX, DERENIVKA, PASS_START + seconds(np.arange(0.0, 460.0, 0.2)), exposure_s=0.2)


def test_range_rate_is_the_derivative_of_range(topex_pass):
    # Central difference over 0.2 s: its error, range''' h^2 / 6, is below 1e-6 km/s here. The
    # range rate uses SGP4's velocity, which is SGP4's own approximation and differs from the
    # derivative of SGP4's position by ~5 mm/s for TOPEX; hence 1e-5 km/s.
    derivative = np.gradient(topex_pass.range_km, topex_pass.t_s)[1:-1]
    np.testing.assert_allclose(topex_pass.range_rate_km_s[1:-1], derivative, atol=1e-5)


def test_phase_angle_airmass_and_directions(topex_pass):
    g = topex_pass
    np.testing.assert_allclose(np.linalg.norm(g.sun_gcrs, axis=-1), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(g.obs_gcrs, axis=-1), 1.0, atol=1e-14)
    middle = g.n_sub // 2  # k = 4: sub-samples straddle the observed time
    mean_sun = g.sun_gcrs[:, middle - 1] + g.sun_gcrs[:, middle]
    cosine = np.sum(mean_sun * (g.obs_gcrs[:, middle - 1] + g.obs_gcrs[:, middle]), axis=1) / (
        np.linalg.norm(mean_sun, axis=1) * np.linalg.norm(g.obs_gcrs[:, middle - 1] + g.obs_gcrs[:, middle], axis=1)
    )
    np.testing.assert_allclose(g.phase_angle_deg, np.degrees(np.arccos(cosine)), atol=1e-6)
    np.testing.assert_allclose(g.airmass, 1.0 / np.sin(np.radians(g.el_refracted_deg)), rtol=1e-14)
    # The observer direction points from the satellite back to the site.
    site_gcrs = g.sat_gcrs_km + g.range_km[:, None] * (g.obs_gcrs[:, middle - 1] + g.obs_gcrs[:, middle]) / 2
    np.testing.assert_allclose(np.linalg.norm(site_gcrs, axis=1), np.linalg.norm(DERENIVKA.itrs_km), atol=0.01)


def test_lvlh_frames_are_right_handed_with_z_at_the_earth_centre(topex_pass):
    g = topex_pass
    frames = g.lvlh_gcrs
    np.testing.assert_allclose(
        np.einsum("nkji,nkjl->nkil", frames, frames), np.broadcast_to(np.eye(3), frames.shape), atol=1e-13
    )
    np.testing.assert_allclose(np.linalg.det(frames), 1.0, atol=1e-13)
    centre = -g.sat_gcrs_km / np.linalg.norm(g.sat_gcrs_km, axis=1)[:, None]
    # Sub-samples are +-0.075 s from the observed time: nadir turns by 0.075 s * 2 pi / 112 min.
    assert np.degrees(np.arccos(np.sum(frames[:, 1, :, 2] * centre, axis=1))).max() < 0.01
    velocity = np.gradient(g.sat_gcrs_km, g.t_s, axis=0)
    along = np.sum(frames[1:-1, 1, :, 0] * velocity[1:-1], axis=1) / np.linalg.norm(velocity[1:-1], axis=1)
    # x is the velocity direction up to the flight-path angle, at most e = 0.0008 rad.
    assert np.degrees(np.arccos(along.min())) < 0.06


def test_sub_samples_are_the_geometry_at_the_sub_sample_times(topex_pass):
    g = topex_pass
    assert g.n_sub == 4 and g.weights.tolist() == [0.25] * 4
    np.testing.assert_allclose(
        g.sub_t_s - g.t_s[:, None], np.broadcast_to([-0.075, -0.025, 0.025, 0.075], (g.n, 4)), atol=1e-12
    )
    j = 3
    direct = PassGeometry.compute(TOPEX, DERENIVKA, g.time_utc[:50] + seconds(0.075))
    np.testing.assert_allclose(g.sun_gcrs[:50, j], direct.sun_gcrs[:, 0], atol=1e-13)
    np.testing.assert_allclose(g.obs_gcrs[:50, j], direct.obs_gcrs[:, 0], atol=1e-12)
    np.testing.assert_allclose(g.lvlh_gcrs[:50, j], direct.lvlh_gcrs[:, 0], atol=1e-13)
    np.testing.assert_array_equal(g.sub_sunlit[:50, j], direct.sunlit_fraction)


def test_n_sub_rule_and_no_sub_samples_without_exposure():
    assert [choose_n_sub(0.2), choose_n_sub(0.1), choose_n_sub(1.0), choose_n_sub(0.2, spin_period_s=40.5)] == [
        4,
        2,
        18,
        1,
    ]
    assert choose_n_sub(10.0, spin_period_s=1.0) == 64  # capped
    times = PASS_START + seconds(np.arange(3.0))
    still = PassGeometry.compute(TOPEX, DERENIVKA, times, exposure_s=0.0, n_sub=8)
    assert still.sun_gcrs.shape == (3, 1, 3) and still.weights.tolist() == [1.0]
    chosen = PassGeometry.compute(TOPEX, DERENIVKA, times, exposure_s=1.0, spin_period_s=9.5)
    assert chosen.n_sub == 19 and chosen.weights.sum() == pytest.approx(1.0, abs=1e-15)


def test_body_frame_rotates_the_directions_into_the_body(topex_pass):
    g = topex_pass
    identity = InertialSpin(pole_ra_deg=-90.0, pole_dec_deg=90.0, period_s=np.inf)
    body = g.body_frame(identity)
    np.testing.assert_allclose(body.sun_body, g.sun_gcrs, atol=1e-15)
    model = PrecessingSpin(period_s=9.86, phase_deg=20, precession_period_s=689.0, precession_angle_deg=35.0)
    body = g.body_frame(model)
    rotation = model.orientation(g.sub_t_s, g.lvlh_gcrs)
    np.testing.assert_allclose(np.einsum("nkij,nkj->nki", rotation, body.obs_body), g.obs_gcrs, atol=1e-14)
    assert body.sun_body.shape == (g.n, 4, 3) and body.sunlit.shape == (g.n, 4)
    # In the body frame the angle between Sun and observer is still the phase angle.
    middle = np.degrees(np.arccos(np.sum(body.sun_body[:, 1] * body.obs_body[:, 1], axis=1)))
    assert np.abs(middle - g.phase_angle_deg).max() < 0.01
    with pytest.raises(ValueError):
        body.sun_body[0, 0, 0] = 1.0  # read-only


def test_astropy_time_pass_and_datetime64_agree(topex_pass):
    from astropy.time import Time

    times = PASS_START + seconds(np.arange(0.0, 10.0, 1.0))
    a = PassGeometry.compute(TOPEX, DERENIVKA, times)
    b = PassGeometry.compute(TOPEX, DERENIVKA, Time(times, scale="utc"))
    np.testing.assert_allclose(a.sat_itrs_km, b.sat_itrs_km, atol=1e-9)
    import astropy.units as u

    c = PassGeometry.compute(TOPEX, DERENIVKA, times, exposure_s=200 * u.ms, spin_period_s=0.16 * u.min)
    assert (c.exposure_s, c.n_sub) == (0.2, 4)


def test_from_pass_uses_the_pass_elements_site_times_and_exposure():
    (observed,) = ingest.read_file(TOPEX_PHV)
    geometry = PassGeometry.from_pass(observed)
    assert geometry.n == len(observed) and geometry.n_sub == 4 and geometry.site == observed.site
    assert geometry.satellite.norad == 22076
    frame = geometry.to_pandas()
    assert list(frame.index[:2]) == list(observed.time_utc[:2])


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        (
            dict(time_utc=np.array([1.0, 2.0])),
            TypeError,
            "time_utc must be numpy datetime64 .UTC. or astropy Time, got dtype float64",
        ),
        (
            dict(time_utc=np.array(["2024-07-30", "NaT"], dtype="datetime64[ns]")),
            ValueError,
            "time_utc has 1 NaT values",
        ),
        (
            dict(time_utc=np.array(["1960-01-01"], dtype="datetime64[ns]")),
            ValueError,
            "outside 1972-01-01 .. 2053-10-01",
        ),
        (dict(exposure_s=-0.1), ValueError, "exposure_s=-0.1 must be a finite number of seconds >= 0"),
        (dict(exposure_s="fast"), ValueError, "'fast' is not a number of seconds"),
        (dict(n_sub=0), ValueError, "n_sub=0 must be a whole number from 1 to 4096"),
        (
            dict(satellite=TOPEX_TLE),
            TypeError,
            "satellite must be a raycast.geometry.orbit.Satellite or a raycast.geometry.track.ObservedTrack, got tuple",
        ),
        (dict(site=(48.5, 22.4)), TypeError, "site must be a ingest.site.Site, got tuple"),
    ],
)
def test_bad_arguments_are_refused_with_a_clear_message(kwargs, error, message):
    arguments = dict(satellite=TOPEX, site=DERENIVKA, time_utc=PASS_START + seconds(np.arange(2.0)), exposure_s=0.2)
    arguments.update(kwargs)
    with pytest.raises(error, match=message):
        PassGeometry.compute(**arguments)


def test_site_itrs_matches_skyfield_wgs84():
    from skyfield.api import wgs84

    for site in (DERENIVKA, Site("south", -33.9, 151.2, 40.0)):
        expected = wgs84.latlon(site.lat_deg, site.lon_deg, site.elevation_m).itrs_xyz.km
        np.testing.assert_allclose(site.itrs_km, expected, atol=1e-9)
        up = site.enu_itrs[:, 2]
        np.testing.assert_allclose(np.linalg.norm(site.enu_itrs, axis=0), 1.0, atol=1e-15)
        assert up[2] == pytest.approx(math.sin(math.radians(site.lat_deg)), abs=1e-15)
