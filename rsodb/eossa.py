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
Eph_RA_DE                   topocentric RA/Dec (ICRS, deg) of the ephemeris direction
Eph_AZ_EL                   azimuth, elevation (deg) from the TLE, as in the source file
                            (elevation includes refraction, 1010 hPa and 15 C)
Met_RA_DE, Met_AZ_EL        null: the source files carry no measured astrometry
Sun_AZ_EL                   geometric azimuth and elevation of the Sun (deg)
Tel_Obj_Range               range, m
Solar_Phase_Ang             Sun-object-observer angle, deg

Samples marked invalid (sentinel magnitudes) carry null magnitudes.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ingest.observation import Pass

__all__ = ["EOSSA_VERSION", "D_NULL", "J_NULL", "eossa_hdus", "write_eossa", "read_eossa"]

EOSSA_VERSION = "3.1.1"
D_NULL = -9999.0          # EOSSA null for double columns
J_NULL = -2147483648      # EOSSA null for 32-bit integer columns
RANGE_NORM_KM = 1000.0
# The files' elevations are PyEphem's, which adds refraction for 1010 hPa and 15 C.
REFRACTION_PRESSURE_HPA = 1010.0
REFRACTION_TEMPERATURE_C = 15.0
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


def _sky_geometry(pass_: Pass) -> dict[str, np.ndarray]:
    """RA/Dec of the object, Sun Az/El and the solar phase angle, all (n,) in degrees."""
    import astropy.units as u
    from astropy.coordinates import AltAz, EarthLocation, ICRS, SkyCoord, get_body
    from astropy.time import Time
    from astropy.utils import iers

    with iers.conf.set_temp("auto_download", False), iers.conf.set_temp("auto_max_age", None):
        location = EarthLocation.from_geodetic(lon=pass_.site.lon_deg * u.deg, lat=pass_.site.lat_deg * u.deg,
                                               height=pass_.site.elevation_m * u.m)
        time = Time(pass_.time_utc, scale="utc")
        observed_frame = AltAz(obstime=time, location=location, pressure=REFRACTION_PRESSURE_HPA * u.hPa,
                               temperature=REFRACTION_TEMPERATURE_C * u.deg_C, relative_humidity=0.0,
                               obswl=0.55 * u.micron)
        geometric_frame = AltAz(obstime=time, location=location)
        observed = SkyCoord(az=pass_.az_deg * u.deg, alt=pass_.el_deg * u.deg, frame=observed_frame)
        radec = observed.transform_to(ICRS())
        target = observed.transform_to(geometric_frame)
        sun = get_body("sun", time, location).transform_to(geometric_frame)
    target_km = target.cartesian.xyz.value.T * pass_.range_km[:, None]      # (n, 3) unit * range
    sun_km = sun.cartesian.xyz.to_value(u.km).T                               # (n, 3)
    to_sun = sun_km - target_km
    to_observer = -target_km
    cos_phase = np.sum(to_sun * to_observer, axis=1) / (
        np.linalg.norm(to_sun, axis=1) * np.linalg.norm(to_observer, axis=1))
    return {
        "ra_deg": radec.ra.deg, "dec_deg": radec.dec.deg,
        "sun_az_deg": sun.az.deg, "sun_el_deg": sun.alt.deg,
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
    from astropy.io import fits

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
        fits.Column("Sun_AZ_EL", "2D", unit="deg",
                    array=np.column_stack([sky["sun_az_deg"], sky["sun_el_deg"]])),
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
    header["COMMENT"] = ("Eph_AZ_EL elevation includes refraction (1010 hPa, 15 C); Eph_RA_DE and "
                         "Solar_Phase_Ang use the refraction-free direction.")
    if pass_.reduction is not None and pass_.reduction.sign_error:
        header["COMMENT"] = "Magnitudes corrected for the source file's extinction sign error."
    return fits.HDUList([fits.PrimaryHDU(), table])


def write_eossa(pass_: Pass, path, *, overwrite: bool = False) -> Path:
    """Write the EOSSA FITS file of a pass to `path` and return the path."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; choose another --out or pass overwrite=True")
    eossa_hdus(pass_).writeto(path, overwrite=overwrite)
    return path


def read_eossa(path):
    """Read an EOSSA file: ``(header, table)`` with the table as an `astropy.table.Table`."""
    from astropy.io import fits
    from astropy.table import Table

    with fits.open(path) as hdus:
        return hdus[1].header.copy(), Table(hdus[1].data)
