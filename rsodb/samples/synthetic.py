"""Synthetic corpora: many realistic files, fast, and whole survey-size archives, for benchmarks,
crash tests and demos.

Each pass is a spinning object on a plausible overhead pass: elevation rising and falling,
range from a 1000 km orbit, flux from a two-harmonic spin signal with Poisson-like noise, and
magnitudes from ccd_phot's reduction ``m = A - 2.5 log10(F/dt) + c X - 5 log10(R/1000 km)``
with A = 20.0 and c = -0.30 (the correct sign), so the reader's regression recovers A and c.
Files are written with `ingest.writers.write_ccd_phot`, in the real layout.
`write_synthetic_archive` builds an archive of many objects directly (no text files): the passes
go through the archive's own commit path, a round of objects at a time, with one stored period
result each (`SyntheticPeriod`, the pass's true spin period) for survey queries.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
import multiprocessing
import os
from pathlib import Path

import h5py
import numpy as np

from ingest.elements import tle_checksum
from ingest.observation import Pass
from ingest.site import DERENIVKA, Site
from ingest.writers import write_ccd_phot
from rsodb.archive import Archive, layout, versions
from rsodb.archive.commits import utc_now
from rsodb.archive.integrity import seal_result
from rsodb.archive.locking import temp_path

__all__ = [
    "synthetic_tle",
    "synthetic_pass",
    "write_synthetic_corpus",
    "write_synthetic_archive",
    "SyntheticPeriod",
    "ZERO_POINT_MAG",
    "EXTINCTION_TERM_MAG",
    "VERDICTS",
]

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
    first_utc: str = "2025-03-01T18:00:00",
) -> list[Path]:
    """Write `n_files` ccd_phot files spread round-robin over `n_objects` objects.

    Passes of one object start about five hours apart from `first_utc`, so ids never collide.
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
    first_utc : str
        When the first passes start (UTC, ISO 8601).

    Returns
    -------
    list of Path
        The files written, in index order.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    base = np.datetime64(first_utc, "ns")
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


# Verdicts of a period search and how often the synthetic archive gives each.
VERDICTS = {"confident": 0.55, "ambiguous harmonic": 0.2, "too short": 0.15, "no signal": 0.1}


class SyntheticPeriod:
    """A stored period result with what a period search stores for survey queries: the best
    period, its error and a verdict (here the synthetic truth, not a search)."""

    def __init__(self, period_s: float, uncertainty_s: float, verdict: str):
        self.period_s, self.uncertainty_s, self.verdict = period_s, uncertainty_s, verdict

    def to_hdf5(self, group) -> None:
        group.attrs["best_period_s"] = self.period_s
        group.attrs["uncertainty_s"] = self.uncertainty_s
        group.attrs["verdict"] = self.verdict
        group.attrs["reason"] = "synthetic: the pass's true spin period"


def _object_passes(norad: int, n_passes: int, n_points: int, seed: int, first_utc: np.datetime64):
    """The passes of one object and their period results (object k depends only on (seed, norad))."""
    rng = np.random.default_rng([seed, norad])
    passes, periods = [], []
    verdicts = list(VERDICTS)
    for k in range(n_passes):
        start = first_utc + np.timedelta64(int(rng.uniform(0, 365 * 86400)), "s")
        period_s = float(np.exp(rng.uniform(np.log(2.0), np.log(200.0))))
        exposure_s = float(rng.choice([0.1, 0.2, 0.5, 1.0]))
        passes.append(
            synthetic_pass(
                norad,
                start.astype("datetime64[ms]").astype("datetime64[ns]"),
                n_points,
                rng,
                exposure_s=exposure_s,
                band=str(rng.choice(["V", "V", "B", "R"])),
                spin_period_s=period_s,
            ).replace(source_name=f"synthetic_{norad}_{k}")
        )
        verdict = verdicts[int(rng.choice(len(verdicts), p=list(VERDICTS.values())))]
        periods.append(SyntheticPeriod(period_s, period_s * float(rng.uniform(1e-4, 1e-2)), verdict))
    return passes, periods


def _write_objects(args) -> int:
    """Worker: write the object files of `norads` straight into ``objects/`` (a new archive)."""
    path, norads, passes_of, n_points, seed, first_utc = args
    objects = Path(path) / layout.OBJECTS_DIR
    now = utc_now()
    for norad in norads:
        passes, periods = _object_passes(norad, passes_of[norad], n_points, seed, np.datetime64(first_utc, "ns"))
        final = objects / layout.object_file_name(norad)
        tmp = temp_path(final)
        with h5py.File(tmp, "w", libver=layout.LIBVER) as file:
            layout.write_file_attributes(file, norad)
            file.attrs["name"], file.attrs["cospar"] = passes[0].name, passes[0].cospar
            group = file.create_group("passes")
            rows, results, placed = [], [], {}
            for pass_, period in zip(passes, periods):
                pass_ = pass_.replace(source_sha256=layout.memory_sha256(pass_))
                placement = versions.place(pass_, rows, placed.__getitem__, now)
                rows = placement.rows
                pass_id = placement.metadata["pass_id"]
                placed[pass_id] = layout.samples_table(pass_)
                layout.write_pass(group, pass_, placement.metadata)
                result = group[pass_id].create_group("periods").create_group("default")
                result.attrs["stored_utc"] = now
                result.attrs["result_type"] = f"{__name__}.SyntheticPeriod"
                period.to_hdf5(result)
                attrs = seal_result(result)
                results.append(layout.result_summary(pass_id, "periods", "default", result, attrs))
            layout.write_catalog(file, sorted(rows, key=lambda row: (row.start_utc, row.pass_id)))
            layout.write_results(file, results)
            file.attrs["updated_utc"] = now
        os.replace(tmp, final)
    return len(norads)


def write_synthetic_archive(
    path,
    n_objects: int,
    n_passes: int,
    *,
    n_points: int = 200,
    seed: int = 0,
    first_norad: int = 10001,
    first_utc: str = "2025-01-01T00:00:00",
    processes: int = 1,
) -> Archive:
    """Build an archive of `n_objects` objects holding `n_passes` passes in all, in bulk.

    Passes are spread as evenly as possible over the objects and over a year from `first_utc`;
    each has `n_points` samples, a random band, exposure and spin period (log-uniform 2-200 s),
    and a stored period result named "default" (`SyntheticPeriod`) with a verdict drawn from
    `VERDICTS`. Each object file is written in one go with the archive's own layout functions
    (`rsodb.archive.layout`; ids by `rsodb.archive.versions.place`), without fsync, in
    `processes` processes working on disjoint objects; the catalog index is then built from the
    files, as ``rsodb check`` builds it.

    Returns
    -------
    Archive
        The archive, opened.
    """
    if n_objects < 1 or n_passes < n_objects:
        raise ValueError(f"n_passes={n_passes} must be at least n_objects={n_objects} (>= 1)")
    if Archive(path).summaries():
        raise ValueError(f"{path} already holds passes; give a new directory")
    norads = list(range(first_norad, first_norad + n_objects))
    passes_of = {norad: n_passes // n_objects + (k < n_passes % n_objects) for k, norad in enumerate(norads)}
    pieces = [norads[k::processes] for k in range(processes)]
    tasks = [(str(path), piece, passes_of, n_points, seed, first_utc) for piece in pieces if piece]
    if processes == 1:
        for task in tasks:
            _write_objects(task)
    else:
        with ProcessPoolExecutor(processes, mp_context=multiprocessing.get_context("spawn")) as pool:
            list(pool.map(_write_objects, tasks))
    archive = Archive(path)
    archive.rebuild_index()
    return archive
