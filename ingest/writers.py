"""Writers: the inverse of the readers, in the real files' layouts (header lines, column line,
column widths), used by the sample generator and the benchmarks.

``read_file(write_ccd_phot(p, path))`` gives back `p`'s arrays to the printed precision
(times to 1 ms in the UT variant and ~40 us in the JD variant, which ccd_phot prints as the
shortest repr of a float64 JD; magnitudes to 0.001, flux to 1e-4); a pass whose stamps the reader would shift (before 2023-02 or a ``Time_format`` saying
``start``) is written with the shift undone, so the round trip also returns its times.
"""

from __future__ import annotations

from collections.abc import Sequence
import json
import os
from pathlib import Path

import numpy as np

from ingest.ccd_phot import stamp_offset_s
from ingest.csv_table import CSV_MARKER
from ingest.observation import Pass
from ingest.phc import SENTINEL_MAGS
from ingest.times import NS_PER_S, format_date_time_ms, format_iso_us, julian_date_repr, to_datetime64

__all__ = ["write_ccd_phot", "write_phc", "write_csv", "CCD_PHOT_VARIANTS", "CSV_PRECISION"]

CCD_PHOT_VARIANTS = ("ut", "jd")

# ccd_phot's column lines and row formats (sat_phot.py and res_time2jd.py), column for column.
_UT_COLUMN_LINE = (
    "#  Date       UT              X          Y         Xerr      Yerr             Flux     "
    "Flux_err     mag{band}  mag_err     Az(deg)   El(deg)   Rg({unit})    filename"
)
_JD_COLUMN_LINE = (
    "#      JD                     X          Y         Xerr      Yerr             Flux     "
    "Flux_err     mag{band}  mag_err     Az(deg)   El(deg)   Rg({unit})    filename"
)
_UT_ROW = "%s %s    %8.5f  %8.5f  %8.5f  %8.5f     %13.4f  %8.4f   %6.3f  %6.3f    %8.3f %8.3f   %8.3f   %s"
_JD_ROW = "%-18s        %10.5f %10.5f  %8.5f  %8.5f     %13.4f  %8.4f   %6.3f  %6.3f    %8.3f %8.3f   %8.3f   %s"
# The phc writer (phc.pyw): time of day, counts, magnitudes, Az, El, Rg.
_PHC_COLUMN_LINE = (
    "  UT TIME           ImpB-fon     ImpV-fon         FonB       FonV         mB      mV     Az(deg)  El(deg)  Rg(Mm)"
)
_PHC_ROW = "%s%14.3f%12.3f%14.3f%12.3f%10.3f%8.3f    %.3f%8.3f%10.3f"
_PHC_SENTINEL = SENTINEL_MAGS[0]


def write_ccd_phot(
    pass_: Pass,
    path: str | Path,
    variant: str = "ut",
    *,
    range_unit: str = "Km",
    time_format: str | None = None,
    frame_names: Sequence[str] | None = None,
    centroids_px: np.ndarray | None = None,
) -> Path:
    """Write one pass as a ccd_phot ``.phX`` file.

    Parameters
    ----------
    pass_ : Pass
        The light curve; its TLE (or OMM), site, band and exposure go into the header.
    path : str or Path
        Output file (conventionally ``<...>.ph<band>``).
    variant : {"ut", "jd"}
        ``Date UT`` (14 columns) or ``JD`` (13 columns) time columns.
    range_unit : {"Km", "Mm"}
        Label of the range column; the values are km either way, as ccd_phot writes them.
    time_format : str, optional
        Value of a ``# Time_format`` line (e.g. ``"UT mid"``); no such line by default, like
        the real files.
    frame_names : sequence of str, optional
        The ``filename`` column; default ``<norad>_<HH_MM_SS>Z_<index>.fits``. Saturated
        samples get the trailing ``*`` either way.
    centroids_px : (n, 4) float, optional
        The X, Y, Xerr, Yerr columns (the object's centroid on the frame and its error, pixels);
        zeros by default, as in files re-exported from the lab's database.

    Returns
    -------
    Path
        `path`.
    """
    if variant not in CCD_PHOT_VARIANTS:
        raise ValueError(f"variant={variant!r} is not one of {CCD_PHOT_VARIANTS}; use 'ut' or 'jd'")
    if range_unit not in ("Km", "Mm"):
        raise ValueError(f"range_unit={range_unit!r} is not 'Km' or 'Mm'")
    n = len(pass_)
    if frame_names is not None and len(frame_names) != n:
        raise ValueError(f"frame_names has {len(frame_names)} names for {n} samples")
    if not np.all(np.isfinite(pass_.mag)):
        raise ValueError(
            "ccd_phot files cannot hold missing magnitudes; drop the invalid samples first "
            "(pass_.replace(...) with the valid rows)"
        )
    if not np.all(pass_.flux > 0):
        raise ValueError("ccd_phot files hold only positive fluxes; drop the samples whose flux is not positive")

    if time_format is not None:
        named = {"ut": "ut", "utc": "ut", "jd": "jd"}
        variants = {named[w] for w in time_format.lower().replace(",", " ").split() if w in named}
        if variants - {variant}:
            raise ValueError(f"time_format={time_format!r} names other time columns than variant={variant!r}")

    # Undo the shift the reader will apply. Stamps are never later than mid-exposure, so a pass
    # whose first mid-exposure time is before 2023-02-01 also has its first stamp before it.
    shift_s, _ = stamp_offset_s(pass_.time_utc[0], pass_.exposure_s, time_format)
    stamps = to_datetime64(pass_.time_utc.view(np.int64) - int(round(shift_s * NS_PER_S)))

    lines = _ccd_phot_header(pass_, stamps, time_format)
    lines.append((_UT_COLUMN_LINE if variant == "ut" else _JD_COLUMN_LINE).format(band=pass_.band, unit=range_unit))
    names = list(frame_names) if frame_names is not None else _frame_names(pass_.norad, stamps)
    names = [name + "*" if saturated else name for name, saturated in zip(names, pass_.saturated.tolist())]
    if centroids_px is None:
        centroids_px = np.zeros((n, 4))
    centroids_px = np.asarray(centroids_px, dtype=float)
    if centroids_px.shape != (n, 4):
        raise ValueError(f"centroids_px has shape {centroids_px.shape}; give ({n}, 4) columns X, Y, Xerr, Yerr")
    numeric = [
        *centroids_px.T.tolist(),
        pass_.flux.tolist(),
        _finite_or_zero(pass_.flux_err),
        pass_.mag.tolist(),
        _finite_or_zero(pass_.mag_err),
        pass_.az_deg.tolist(),
        pass_.el_deg.tolist(),
        pass_.range_km.tolist(),
    ]
    if variant == "ut":
        dates, times = format_date_time_ms(stamps)
        rows = map(_UT_ROW.__mod__, zip(dates, times, *numeric, names))
    else:
        rows = map(_JD_ROW.__mod__, zip(julian_date_repr(stamps), *numeric, names))
    _write_atomically(path, "\n".join(lines) + "\n" + "\n".join(rows) + "\n")
    return Path(path)


def write_phc(
    pass_b: Pass, pass_v: Pass, path: str | Path, *, sky_b: np.ndarray | None = None, sky_v: np.ndarray | None = None
) -> Path:
    """Write two passes (B and V on one time axis) as a photometer ``.phc`` file.

    Parameters
    ----------
    pass_b, pass_v : Pass
        Same object, times, exposure and geometry; bands B and V.
    path : str or Path
        Output file.
    sky_b, sky_v : (n,) float, optional
        The sky counts (``FonB``, ``FonV``) subtracted from the counts; by default recovered
        from each pass's flux error through the reader's error model,
        ``Fon = (flux_err**2 - flux) / 2``.

    Returns
    -------
    Path
        `path`.

    Notes
    -----
    Invalid samples are written with the sentinel magnitude 10.000. Stamps are integration
    starts (the pass's mid-exposure times minus dt/2).
    """
    if (pass_b.band, pass_v.band) != ("B", "V"):
        raise ValueError(f"write_phc needs a B and a V pass, got bands {pass_b.band!r} and {pass_v.band!r}")
    if len(pass_b) != len(pass_v) or not np.array_equal(pass_b.time_utc, pass_v.time_utc):
        raise ValueError("the B and V passes must share one time axis (the phc file has one UT column)")
    if pass_b.norad != pass_v.norad or pass_b.exposure_s != pass_v.exposure_s:
        raise ValueError("the B and V passes must be of the same object with the same exposure")
    for name, a, b in (
        ("az_deg", pass_b.az_deg, pass_v.az_deg),
        ("el_deg", pass_b.el_deg, pass_v.el_deg),
        ("range_km", pass_b.range_km, pass_v.range_km),
    ):
        if not np.allclose(a, b, rtol=0, atol=1e-9):
            raise ValueError(f"the B and V passes differ in {name}; the phc file has one {name} column")
    exposure_s = pass_b.exposure_s
    stamps = to_datetime64(pass_b.time_utc.view(np.int64) - int(round(exposure_s / 2 * NS_PER_S)))
    start = stamps[0]
    end = stamps[-1] + np.timedelta64(int(round(exposure_s * NS_PER_S)), "ns")
    if np.any(np.diff(stamps) >= np.timedelta64(12, "h")):
        raise ValueError("a phc file cannot hold gaps of 12 h or more: its rows carry only the time of day")

    lines = [
        format_iso_us(start, 0) if _whole_seconds(start) else format_iso_us(start),
        format_iso_us(end, 0) if _whole_seconds(end) else format_iso_us(end),
        f"dt={exposure_s!r}",
        f"COSPAR ID={pass_b.cospar}",
        f"NORAD ID={pass_b.norad}",
        f"NAME={pass_b.name}",
    ]
    if pass_b.tle is not None:
        lines.append("% TLE:")
        lines.extend(f"% {line}" for line in pass_b.tle)
    lines.append(_PHC_COLUMN_LINE)

    clock = [stamp[11:] for stamp in np.datetime_as_string(stamps.astype("datetime64[us]"), unit="us").tolist()]
    columns = []
    for pass_, sky in ((pass_b, sky_b), (pass_v, sky_v)):
        if sky is None:
            sky = (np.nan_to_num(pass_.flux_err) ** 2 - pass_.flux) / 2.0
        sky = np.asarray(sky, dtype=float)
        if sky.shape != (len(pass_),) or not np.all(np.isfinite(sky)):
            raise ValueError(f"the {pass_.band} sky counts must be {len(pass_)} finite values")
        mag = np.where(pass_.valid & np.isfinite(pass_.mag), pass_.mag, _PHC_SENTINEL)
        columns.append((pass_.flux.tolist(), np.maximum(sky, 0.0).tolist(), mag.tolist()))
    (flux_b, sky_b, mag_b), (flux_v, sky_v, mag_v) = columns
    rows = map(
        _PHC_ROW.__mod__,
        zip(
            clock,
            flux_b,
            flux_v,
            sky_b,
            sky_v,
            mag_b,
            mag_v,
            pass_b.az_deg.tolist(),
            pass_b.el_deg.tolist(),
            pass_b.range_km.tolist(),
        ),
    )
    _write_atomically(path, "\n".join(lines) + "\n" + "\n".join(rows) + "\n")
    return Path(path)


# Decimals of each CSV column: one more than the lab's files print (magnitudes 0.001, angles and
# ranges 0.001), so no printed digit is lost and no false precision (16 digits) is added.
CSV_PRECISION = {
    "mag_file": 4,
    "mag_corrected": 4,
    "mag_err": 4,
    "flux": 4,
    "flux_err": 4,
    "az_deg": 4,
    "el_deg": 4,
    "range_km": 3,
}


def write_csv(pass_: Pass, out, notes: dict | None = None) -> None:
    """Write one pass as a CSV light curve that `ingest.read_file` reads back.

    Columns: ``time_utc`` (ISO 8601 UTC at mid-exposure, to the nanosecond), ``mag_file`` (the
    magnitude as the source file wrote it), ``mag_corrected`` (only for passes whose file had
    the extinction sign error: the magnitude to use), ``mag_err``, ``flux``, ``flux_err``,
    ``az_deg``, ``el_deg``, ``range_km``, ``saturated`` and ``valid`` (0/1), with the decimals of
    `CSV_PRECISION`. A ``# key = value`` header gives the object, band, exposure, site, time
    convention, magnitude convention, reduction and elements.

    Parameters
    ----------
    pass_ : Pass
    out : str, Path or text stream
        A file (written to a temporary name, then renamed) or an open stream such as stdout.
    notes : dict, optional
        More ``# key = value`` lines (e.g. the pass id).
    """
    site = pass_.site
    header = {
        "object": pass_.norad,
        "name": pass_.name,
        "cospar": pass_.cospar,
        "band": pass_.band,
        "exposure_s": repr(float(pass_.exposure_s)),
        "site": site.name,
        "site_lat_deg": repr(site.lat_deg),
        "site_lon_deg": repr(site.lon_deg),
        "site_elevation_m": repr(site.elevation_m),
        "time_stamps": "mid",
        "mag_convention": pass_.mag_convention,
    }
    if pass_.mag_corrected is not None:
        header["mag_corrected"] = "mag_file with the extinction sign error undone: the magnitude to use"
    if pass_.reduction is not None:
        header["reduction"] = json.dumps(
            {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in vars(pass_.reduction).items()}
        )
    if pass_.tle is not None:
        header.update({f"tle_{line[0]}": line for line in pass_.tle})
    if pass_.omm is not None:
        header["omm"] = json.dumps(dict(pass_.omm))
    if pass_.elements_source:
        header["elements_source"] = json.dumps(dict(pass_.elements_source))
    header["source"] = f"{pass_.source_name} ({pass_.source_format}, sha256 {pass_.source_sha256})"
    header.update(notes or {})
    lines = [CSV_MARKER + ": one row per sample; times UTC at mid-exposure"]
    lines += [f"# {key} = {' '.join(str(value).splitlines())}" for key, value in header.items() if value != ""]

    columns = {"mag_file": pass_.mag}
    if pass_.mag_corrected is not None:
        columns["mag_corrected"] = pass_.mag_corrected
    columns.update(
        mag_err=pass_.mag_err,
        flux=pass_.flux,
        flux_err=pass_.flux_err,
        az_deg=pass_.az_deg,
        el_deg=pass_.el_deg,
        range_km=pass_.range_km,
    )
    lines.append(",".join(["time_utc", *columns, "saturated", "valid"]))
    times = [stamp + "Z" for stamp in np.datetime_as_string(pass_.time_utc, unit="ns").tolist()]
    formatted = [
        [f"{value:.{CSV_PRECISION[name]}f}" if np.isfinite(value) else "nan" for value in values.tolist()]
        for name, values in columns.items()
    ]
    flags = [pass_.saturated.astype(int).astype(str).tolist(), pass_.valid.astype(int).astype(str).tolist()]
    rows = map(",".join, zip(times, *formatted, *flags))
    content = "\n".join(lines) + "\n" + "\n".join(rows) + "\n"
    if hasattr(out, "write"):
        out.write(content)
    else:
        _write_atomically(out, content)


# -- helpers -----------------------------------------------------------------------------------
def _ccd_phot_header(pass_: Pass, stamps: np.ndarray, time_format: str | None) -> list[str]:
    lines = []
    if pass_.omm is not None:
        lines.append("# OMM: " + json.dumps(dict(pass_.omm), separators=(", ", ": ")))
    elif pass_.tle is not None:
        lines.append("# TLE:")
        lines.extend(f"# {line}" for line in pass_.tle)
    lines += [
        f"# {format_iso_us(stamps[0])}",
        f"# {format_iso_us(stamps[-1])}",
        f"# dt = {pass_.exposure_s!r}",
        f"# Filter = {pass_.band}",
    ]
    if time_format is not None:
        lines.append(f"# Time_format = {time_format}")
    site = pass_.site
    lines += [
        f"# COSPAR = {pass_.cospar}",
        f"# NORAD  = {pass_.norad}",
        f"# NAME   = {pass_.name}",
        f"# SITE_NAME   = {site.name}",
        f"# SITE_LAT   = {site.lat_deg!r}",
        f"# SITE_LON   = {site.lon_deg!r}",
        f"# SITE_ELEV  = {site.elevation_m!r}",
    ]
    return lines


def _frame_names(norad: int, stamps: np.ndarray) -> list[str]:
    """ccd_phot-style frame names: ``<norad>_<HH_MM_SS>Z_<index>.fits``."""
    clock = np.datetime_as_string(stamps.astype("datetime64[s]"), unit="s").tolist()
    return [f"{norad}_{c[11:13]}_{c[14:16]}_{c[17:19]}Z_{k:05d}.fits" for k, c in enumerate(clock, start=1)]


def _finite_or_zero(values: np.ndarray) -> list[float]:
    return np.where(np.isfinite(values), values, 0.0).tolist()


def _whole_seconds(stamp: np.datetime64) -> bool:
    return int(stamp.astype(np.int64)) % NS_PER_S == 0


def _write_atomically(path: str | Path, content: str) -> None:
    """Write `content` to a temporary file beside `path`, then rename: no half-written file."""
    path = Path(path)
    temporary = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with open(temporary, "w", encoding="utf-8", newline="\n") as stream:
        stream.write(content)
    os.replace(temporary, path)
