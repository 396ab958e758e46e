"""Synthetic ccd_phot corpora: many realistic files, fast, for benchmarks, crash tests and demos.

Each pass is a spinning object on a plausible overhead pass: elevation rising and falling,
range from a 1000 km orbit, flux from a two-harmonic spin signal with Poisson-like noise, and
magnitudes from ccd_phot's reduction ``m = A - 2.5 log10(F/dt) + c X - 5 log10(R/1000 km)``
with A = 20.0 and c = -0.30 (the correct sign), so the reader's regression recovers A and c.
Files are written with `ingest.writers.write_ccd_phot`, in the real layout.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ingest.elements import tle_checksum
from ingest.observation import Pass
from ingest.site import DERENIVKA, Site
from ingest.writers import write_ccd_phot

__all__ = ["synthetic_tle", "synthetic_pass", "write_synthetic_corpus", "ZERO_POINT_MAG", "EXTINCTION_TERM_MAG"]

ZERO_POINT_MAG = 20.0
EXTINCTION_TERM_MAG = -0.30
_EARTH_RADIUS_KM = 6371.0
_ALTITUDE_KM = 1000.0


def _with_checksum(line68: str) -> str:
    return line68 + str(tle_checksum(line68))


def synthetic_tle(norad: int, name: str) -> tuple[str, str, str]:
    """A syntactically valid TLE (title, line 1, line 2) for catalogue number `norad` (< 100000)."""
    if not 0 < norad < 100000:
        raise ValueError(f"norad={norad} must be between 1 and 99999 for a classic TLE")
    line1 = _with_checksum(f"1 {norad:05d}U 25001A   25060.50000000  .00000050  00000-0  81985-4 0  999")
    line2 = _with_checksum(f"2 {norad:05d}  99.2328  44.2251 0016558  67.2163 293.0740 13.8593659327411")
    return (f"0 {name}", line1, line2)


def synthetic_pass(
    norad: int,
    start_utc: np.datetime64,
    n_points: int,
    rng: np.random.Generator,
    *,
    exposure_s: float = 0.1,
    band: str = "V",
    site: Site = DERENIVKA,
    spin_period_s: float = 9.5,
) -> Pass:
    """One synthetic pass of `n_points` consecutive exposures starting at `start_utc` (mid-exposure).

    Parameters
    ----------
    norad : int
    start_utc : numpy.datetime64
    n_points : int
    rng : numpy.random.Generator
        Noise, spin phase and geometry are drawn from it.
    exposure_s, band, site, spin_period_s
        As their names say.

    Returns
    -------
    Pass
    """
    if n_points < 2:
        raise ValueError(f"n_points={n_points} must be at least 2")
    t_s = np.arange(n_points) * exposure_s
    frac = t_s / t_s[-1]
    peak_el_deg = rng.uniform(35.0, 80.0)
    el_deg = 15.0 + (peak_el_deg - 15.0) * np.sin(np.pi * frac)
    az_deg = (rng.uniform(0.0, 360.0) + 140.0 * frac) % 360.0
    el_rad = np.radians(el_deg)
    orbit_km = _EARTH_RADIUS_KM + _ALTITUDE_KM
    range_km = np.sqrt(orbit_km**2 - (_EARTH_RADIUS_KM * np.cos(el_rad)) ** 2) - _EARTH_RADIUS_KM * np.sin(el_rad)
    phase = 2.0 * np.pi * (t_s / spin_period_s + rng.uniform())
    signal = 1.0 + 0.45 * np.sin(phase) + 0.25 * np.sin(2.0 * phase + 1.0)
    flux_true = rng.uniform(5e3, 4e4) * signal * (1000.0 / range_km) ** 2
    flux_err = np.sqrt(flux_true + 80.0**2)
    flux = np.maximum(flux_true + rng.normal(0.0, 1.0, n_points) * flux_err, 0.05 * flux_true)
    airmass = 1.0 / np.sin(el_rad)
    mag = (
        ZERO_POINT_MAG
        - 2.5 * np.log10(flux / exposure_s)
        + EXTINCTION_TERM_MAG * airmass
        - 5.0 * np.log10(range_km / 1000.0)
    )
    time_utc = np.datetime64(start_utc, "ns") + np.round(t_s * 1e9).astype("int64").astype("timedelta64[ns]")
    name = f"SYNTH {norad}"
    return Pass(
        norad=norad,
        name=name,
        band=band,
        site=site,
        exposure_s=exposure_s,
        time_utc=time_utc,
        mag=mag,
        mag_err=2.5 / np.log(10.0) * flux_err / flux,
        flux=flux,
        flux_err=flux_err,
        az_deg=az_deg,
        el_deg=el_deg,
        range_km=range_km,
        saturated=rng.uniform(size=n_points) < 0.002,
        valid=np.ones(n_points, dtype=bool),
        cospar="25001A",
        tle=synthetic_tle(norad, name),
    )


def write_synthetic_corpus(
    directory,
    n_files: int,
    n_points: int,
    n_objects: int,
    *,
    seed: int = 0,
    first_norad: int = 90001,
    variant: str = "ut",
    indices: range | None = None,
) -> list[Path]:
    """Write `n_files` ccd_phot files spread round-robin over `n_objects` objects.

    Passes of one object start about five hours apart from 2025-03-01, so ids never collide.
    File names follow the lab's ``result_<norad>_<YYYYmmdd>_UT<HHMMSS>.phV`` pattern. File k
    depends only on (`seed`, k), so a corpus can be written in parallel pieces.

    Parameters
    ----------
    directory : path-like
    n_files, n_points, n_objects : int
    seed : int
    first_norad : int
        Catalogue number of the first object; objects are numbered consecutively.
    variant : {"ut", "jd"}
        Time columns of the files.
    indices : range, optional
        Write only these files of the corpus (default: all `n_files`).

    Returns
    -------
    list of Path
        The files written, in index order.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    base = np.datetime64("2025-03-01T18:00:00", "ns")
    paths = []
    for k in range(n_files) if indices is None else indices:
        rng = np.random.default_rng([seed, k])
        norad = first_norad + k % n_objects
        start = base + np.timedelta64(int((k // n_objects) * 5.3 * 3600e9 + rng.uniform(0, 600e9)), "ns")
        start = start.astype("datetime64[ms]").astype("datetime64[ns]")  # the UT variant prints ms
        pass_ = synthetic_pass(norad, start, n_points, rng)
        stamp = np.datetime_as_string(start, unit="s").replace("-", "").replace(":", "")
        paths.append(
            write_ccd_phot(
                pass_, directory / f"result_{norad}_{stamp[:8]}_UT{stamp[9:15]}.ph{pass_.band}", variant=variant
            )
        )
    return paths
