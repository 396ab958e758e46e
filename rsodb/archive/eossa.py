"""Export a pass to EOSSA, the SSA community's FITS exchange format for photometry (version 3.1.1).

An EOSSA file is a FITS file with an empty primary HDU and one binary table: one row per
exposure, with the ground-based columns of the specification (Table K-2) and the header
keywords that describe the sensor, the target and the filters (Table K-1). The field list follows
ccd_phot's converter ``res2eossa.py`` (Uzhhorod National University, the producer of the files
this project reads), with two corrections: the files' range column is in km (not Mm), and values
the files do not contain are written as EOSSA's null values rather than copied from other columns.

Columns written
---------------
UTC_Begin_exp, UTC_End_exp  ``yyyy-mm-ddThh:mm:ss.sss``, mid-exposure -/+ half the exposure
JD_Mid_Exp                  Julian date (UTC) of mid-exposure
Exp_Duration                exposure, s
Cur_Spec_Filt_Num           1 (the one filter named by SPFNAM1); Cur_ND_Filt_Num: null
Mag_Exo_Atm, _Unc           exo-atmospheric magnitude at the true range and its 1-sigma error
Mag_Range_Norm              the same reduced to 1000 km range
Eph_RA_DE                   topocentric RA/Dec (ICRS, deg) of the ephemeris direction, from
                            the file's Az/El with PyEphem's refraction removed
Eph_AZ_EL                   azimuth, elevation (deg) from the TLE, as in the source file
                            (elevation includes refraction, 1010 hPa and 15 C)
Met_RA_DE, Met_AZ_EL        null: the source files carry no measured astrometry
Sun_AZ_EL                   apparent azimuth and elevation of the Sun (deg, no refraction)
Tel_Obj_Range               range, m
Solar_Phase_Ang             Sun-object-observer angle, deg

Samples marked invalid (sentinel magnitudes) carry null magnitudes.
"""

from __future__ import annotations

from pathlib import Path

from astropy.io import fits
from astropy.table import Table
import numpy as np
from skyfield.api import wgs84
from skyfield.framelib import itrs

from ingest.observation import Pass
from raycast.geometry import ephemeris
from raycast.geometry.refraction import true_elevation_deg

__all__ = ["EOSSA_VERSION", "D_NULL", "J_NULL", "eossa_hdus", "write_eossa", "read_eossa"]

EOSSA_VERSION = "3.1.1"
D_NULL = -9999.0  # EOSSA null for double columns
J_NULL = -2147483648  # EOSSA null for 32-bit integer columns
RANGE_NORM_KM = 1000.0
_JD_UNIX_EPOCH = 2440587.5
_NS_PER_DAY = 86400e9


def _magnitudes(pass_: Pass) -> tuple[np.ndarray, np.ndarray]:
    """(exo-atmospheric at range, reduced to 1000 km), each (n,), with invalid samples nulled."""
    mag = pass_.best_mag
    distance_modulus = 5.0 * np.log10(pass_.range_km / RANGE_NORM_KM)
    if "1000 km" in pass_.mag_convention:
        at_range, normalised = mag + distance_modulus, mag
    else:
        at_range, normalised = mag, mag - distance_modulus
    bad = ~pass_.valid | ~np.isfinite(mag)
    return np.where(bad, D_NULL, at_range), np.where(bad, D_NULL, normalised)


def _skyfield_times(time_utc: np.ndarray):
    """(n,) datetime64[ns] UTC -> skyfield Time (leap seconds handled by the calendar fields)."""
    days = time_utc.astype("datetime64[D]")
    years = days.astype("datetime64[Y]")
    months = days.astype("datetime64[M]")
    return ephemeris.timescale().utc(
        years.astype(int) + 1970,
        (months - years).astype(int) + 1,
        (days - months).astype(int) + 1,
        0,
        0,
        (time_utc - days) / np.timedelta64(1, "s"),
    )


def _sky_geometry(pass_: Pass) -> dict[str, np.ndarray]:
    """RA/Dec of the object, Sun Az/El and the solar phase angle, all (n,) in degrees.

    Computed with skyfield and the offline DE421 ephemeris (`raycast.geometry.ephemeris`), like the rest
    of the project's geometry. The object's direction is the file's Az/El with PyEphem's
    refraction removed, turned from the site's East-North-Up axes into GCRS (ICRS axes): the
    geometric topocentric direction, as skyfield gives ``(satellite - site).at(t).radec()``.
    The Sun is its apparent topocentric position.
    """
    t = _skyfield_times(pass_.time_utc)
    az = np.radians(pass_.az_deg)
    el = np.radians(true_elevation_deg(pass_.el_deg))
    target_enu = np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], axis=1)  # (n, 3)
    target_itrs = target_enu @ pass_.site.enu_itrs.T
    gcrs_to_itrs = itrs.rotation_at(t)  # (3, 3, n)
    target_gcrs = np.einsum("jin,nj->ni", gcrs_to_itrs, target_itrs)  # transpose applied
    ra_deg = np.degrees(np.arctan2(target_gcrs[:, 1], target_gcrs[:, 0])) % 360.0
    dec_deg = np.degrees(np.arcsin(np.clip(target_gcrs[:, 2], -1.0, 1.0)))

    planets = ephemeris.planets()
    site = wgs84.latlon(pass_.site.lat_deg, pass_.site.lon_deg, elevation_m=pass_.site.elevation_m)
    sun_alt, sun_az, sun_distance = (planets["earth"] + site).at(t).observe(planets["sun"]).apparent().altaz()
    sun_enu_km = sun_distance.km[:, None] * np.stack(
        [
            np.sin(sun_az.radians) * np.cos(sun_alt.radians),
            np.cos(sun_az.radians) * np.cos(sun_alt.radians),
            np.sin(sun_alt.radians),
        ],
        axis=1,
    )
    to_sun = sun_enu_km - target_enu * pass_.range_km[:, None]
    cos_phase = np.sum(to_sun * -target_enu, axis=1) / np.linalg.norm(to_sun, axis=1)
    return {
        "ra_deg": ra_deg,
        "dec_deg": dec_deg,
        "sun_az_deg": sun_az.degrees,
        "sun_el_deg": sun_alt.degrees,
        "phase_angle_deg": np.degrees(np.arccos(np.clip(cos_phase, -1.0, 1.0))),
    }


def _tle_lines(pass_: Pass) -> tuple[str, str] | None:
    if not pass_.tle:
        return None
    lines = [line.strip() for line in pass_.tle if line.strip()[:2] in ("1 ", "2 ")]
    if len(lines) != 2:
        return None
    # EOSSA stores each line without its leading line number: 67 characters.
    return lines[0][2:], lines[1][2:]


def eossa_hdus(pass_: Pass):
    """The EOSSA file of a pass as an `astropy.io.fits.HDUList` (primary HDU plus the table).

    Parameters
    ----------
    pass_ : Pass
        Any pass (a `StoredPass` adds its id to the header).

    Returns
    -------
    astropy.io.fits.HDUList
    """
    n = len(pass_)
    half = np.timedelta64(int(round(pass_.exposure_s * 5e8)), "ns")
    begin = np.datetime_as_string(pass_.time_utc - half, unit="ms")
    end = np.datetime_as_string(pass_.time_utc + half, unit="ms")
    jd_mid = _JD_UNIX_EPOCH + pass_.time_utc.view("int64") / _NS_PER_DAY
    at_range, normalised = _magnitudes(pass_)
    mag_err = np.where(pass_.valid & np.isfinite(pass_.mag_err), pass_.mag_err, D_NULL)
    sky = _sky_geometry(pass_)
    null_pair = np.full((n, 2), D_NULL)

    columns = [
        fits.Column("UTC_Begin_exp", "23A", unit="yyyy-mm-ddThh:mm:ss.sss", array=begin),
        fits.Column("UTC_End_exp", "23A", unit="yyyy-mm-ddThh:mm:ss.sss", array=end),
        fits.Column("JD_Mid_Exp", "D", unit="days", array=jd_mid),
        fits.Column("Exp_Duration", "D", unit="sec", array=np.full(n, float(pass_.exposure_s))),
        fits.Column("Cur_Spec_Filt_Num", "J", unit="num", array=np.ones(n, dtype=np.int32)),
        fits.Column("Cur_ND_Filt_Num", "J", unit="num", array=np.full(n, J_NULL, dtype=np.int32)),
        fits.Column("Mag_Exo_Atm", "D", unit="mag", array=at_range),
        fits.Column("Mag_Exo_Atm_Unc", "D", unit="mag", array=mag_err),
        fits.Column("Mag_Range_Norm", "D", unit="mag", array=normalised),
        fits.Column("Eph_RA_DE", "2D", unit="deg", array=np.column_stack([sky["ra_deg"], sky["dec_deg"]])),
        fits.Column("Met_RA_DE", "2D", unit="deg", array=null_pair),
        fits.Column("Eph_AZ_EL", "2D", unit="deg", array=np.column_stack([pass_.az_deg, pass_.el_deg])),
        fits.Column("Met_AZ_EL", "2D", unit="deg", array=null_pair),
        fits.Column("Sun_AZ_EL", "2D", unit="deg", array=np.column_stack([sky["sun_az_deg"], sky["sun_el_deg"]])),
        fits.Column("Tel_Obj_Range", "D", unit="m", array=pass_.range_km * 1000.0),
        fits.Column("Solar_Phase_Ang", "D", unit="deg", array=sky["phase_angle_deg"]),
    ]
    table = fits.BinTableHDU.from_columns(columns)
    pass_id = getattr(pass_, "pass_id", "") or Path(pass_.source_name).stem or f"{pass_.norad}"
    header = table.header
    header["EXTNAME"] = (f"{pass_id}.eossa"[:68], "name of this table")
    header["CLASSIF"] = ("UNCLASS", "security classification of the data")
    header["VERS"] = (EOSSA_VERSION, "EOSSA format version")
    header["OBSEPH"] = ("GROUND", "observer type")
    header["BASING"] = ("Ground", "sensor basing")
    header["TELESCOP"] = (pass_.site.name, "telescope site")
    header["OBSNAME"] = (pass_.site.name, "telescope name")
    header["TELLAT"] = (pass_.site.lat_deg, "[deg] geodetic latitude, north positive")
    header["TELLONG"] = (pass_.site.lon_deg, "[deg] longitude, east positive")
    header["TELALT"] = (pass_.site.elevation_m, "[m] height of the telescope")
    header["OBJTYPE"] = ("SCN", "target has a space catalog number")
    header["OBJNUM"] = (int(pass_.norad), "space catalog (NORAD) number")
    header["OBJECT"] = (pass_.name, "common name of the target")
    tle = _tle_lines(pass_)
    header["OBJEPH"] = ("TLE" if tle else ("OMM" if pass_.omm else "NONE"), "target ephemeris source")
    if tle:
        # 67-character values fill the card: no room for a comment.
        header["TLELN1"] = tle[0]
        header["TLELN2"] = tle[1]
    header["SPFNUM"] = (1, "number of spectral filters")
    header["SPFNAM1"] = (pass_.band, "spectral filter 1")
    header["DATE-OBS"] = (str(begin[0]), "UTC start of the first exposure")
    header["DATE-END"] = (str(end[-1]), "UTC end of the last exposure")
    header["ORIGIN"] = ("rsodb", "software that wrote this file")
    header["COMMENT"] = f"Source file {pass_.source_name} (sha256 {pass_.source_sha256[:16]}...)"
    header["COMMENT"] = f"Mag_Range_Norm is reduced to {RANGE_NORM_KM:g} km range."
    header["COMMENT"] = (
        "Eph_AZ_EL elevation includes refraction (1010 hPa, 15 C); Eph_RA_DE and "
        "Solar_Phase_Ang use the refraction-free direction."
    )
    if pass_.reduction is not None and pass_.reduction.sign_error:
        header["COMMENT"] = "Magnitudes corrected for the source file's extinction sign error."
    return fits.HDUList([fits.PrimaryHDU(), table])


def write_eossa(pass_: Pass, path, *, overwrite: bool = False) -> Path:
    """Write the EOSSA FITS file of a pass to `path` and return the path."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; choose another path, or pass overwrite=True (rsodb export --force)")
    eossa_hdus(pass_).writeto(path, overwrite=overwrite)
    return path


def read_eossa(path):
    """Read an EOSSA file: ``(header, table)`` with the table as an `astropy.table.Table`."""
    with fits.open(path) as hdus:
        return hdus[1].header.copy(), Table(hdus[1].data)
