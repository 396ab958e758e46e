"""Generate `data_samples/`: small observation files in the real formats with known truth.

Each sample is a pass of a real satellite (public TLEs from the reference paper's code,
Apache-2.0) over Derenivka, found by searching +-20 days around the TLE epoch for a sunlit
satellite above 20 deg with the Sun below -6 deg (the nearest such passes are used). Geometry comes from skyfield (SGP4, offline
DE421 and timescale via `raycast.ephemeris`), with the elevation refracted as PyEphem does,
like the lab's files. Brightness is a simple periodic model of the range-normalised standard
magnitude,

    m_st(t) = m0 + a1 cos(2 pi t / P + phi1) + a2 cos(4 pi t / P + phi2) - g exp(-d^2 / (2 w^2)),

(d: distance in phase cycles to a glint at phase phi_g), turned into counts through the
inverse of each format's reduction law with Poisson-like noise, and written back as the
format's magnitudes, including ccd_phot's historical ``+kX`` sign error for passes before
2024-08-01. The injected periods and reduction constants go to ``README.md`` and
``truth.json`` beside the files, so tests can check what later stages recover.

Run ``python -m rsodb.samples --out data_samples [--seed N]``; the output is byte-for-byte
deterministic for a given seed. The ray-cast renderer will replace the brightness model.
"""
from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass
import functools
import json
from pathlib import Path
import sys

import numpy as np

from ingest.elements import parse_tle, tle_cospar, tle_norad
from ingest.observation import Pass
from ingest.reduction import airmass, instrumental_mag, range_correction_mag
from ingest.times import NS_PER_DAY
from ingest.writers import write_ccd_phot, write_phc
from raycast.site import DERENIVKA, UZHHOROD, Site

__all__ = ["SampleSpec", "SAMPLES", "TLES", "generate", "model_mag", "main"]

# Public TLEs used by the reference paper's code (vkudak/blender_lc_fit, Apache-2.0).
TLES = {
    22076: ("0 TOPEX/POSEIDON",
            "1 22076U 92052A   21160.57864517 -.00000059  00000-0  95149-5 0  9996",
            "2 22076  66.0409 341.5772 0007830 272.3340 147.4137 12.81032194348634"),
    40358: ("0 COSMOS 2502",
            "1 40358U 14086A   24009.55814244  .00000043  00000-0  83941-4 0  9993",
            "2 40358  67.1523  12.8839 0007020 252.7955 107.2362 13.97588796459621"),
}
# ccd_phot added +kX instead of -kX until this date (PROVENANCE.md).
SIGN_FIX_DATE = np.datetime64("2024-08-01", "ns")
# Counting noise: sigma_F^2 = F + sky variance (counts^2), close to the real files' Flux_err.
SKY_VARIANCE_COUNTS2 = 1000.0
# A frame is saturated above this many counts (the glints reach it).
SATURATION_COUNTS = 2.0e5
_MIN_ELEVATION_DEG = 20.0
_MAX_SUN_ELEVATION_DEG = -6.0
_SEARCH_STEP_S = 60.0
_SEARCH_DAYS = 20


@dataclass(frozen=True)
class SampleSpec:
    """One sample file and the truth it is generated from.

    Attributes
    ----------
    file_format : str
        ``"ccd_phot"`` or ``"phc"``.
    norad : int
        Object (a key of `TLES`).
    band : str
        Band (``"BV"`` for a phc file, which holds both).
    variant : str
        ccd_phot time variant (``"ut"`` or ``"jd"``); empty for phc.
    pass_index : int
        Which qualifying pass, counted from the one nearest the TLE epoch (0 = nearest).
    exposure_s : float
        Exposure (sample) time, s.
    n_samples : int
        Samples before any are dropped (phc files lose a few, as real ones do).
    period_s : float
        Injected spin period P.
    mean_mag, amplitude1_mag, amplitude2_mag, glint_mag, glint_width_cycles : float
        m0, a1, a2, g and w of the brightness model.
    zero_point_mag, extinction_mag : float
        A and k (> 0) of the format's reduction law (V values for phc; B = V + colour).
    colour_bv_mag : float
        B - V added to the model for phc files.
    """

    file_format: str
    norad: int
    band: str
    variant: str
    pass_index: int
    exposure_s: float
    n_samples: int
    period_s: float
    mean_mag: float
    amplitude1_mag: float
    amplitude2_mag: float
    glint_mag: float
    glint_width_cycles: float
    zero_point_mag: float
    extinction_mag: float
    colour_bv_mag: float = 0.0


# TOPEX: spin 9.86 s (the paper's 2020 value); COSMOS 2502: 40.5 s (paper, 2023).
SAMPLES = (
    SampleSpec("ccd_phot", 22076, "V", "ut", 0, 0.2, 1100, 9.86, 5.2, 0.45, 0.25, 1.6, 0.015, 19.4, 0.10),
    SampleSpec("ccd_phot", 22076, "R", "jd", 1, 0.25, 900, 9.87, 4.8, 0.40, 0.20, 1.4, 0.015, 19.0, 0.08),
    SampleSpec("ccd_phot", 40358, "V", "ut", 0, 0.5, 600, 40.5, 8.0, 0.50, 0.30, 1.2, 0.01, 21.4, 0.40),
    SampleSpec("ccd_phot", 40358, "B", "jd", 0, 0.5, 440, 40.6, 7.1, 0.50, 0.30, 1.2, 0.01, 20.5, 0.20),
    SampleSpec("phc", 40358, "BV", "", 1, 1.0, 300, 40.5, 5.4, 0.50, 0.30, 1.0, 0.01, 14.04, 0.45, 0.7),
)
# phc B-band reduction constants (the real phc file's B law: A = 14.42, k = 0.65).
_PHC_B = (14.42, 0.65)


def generate(out_dir: str | Path, seed: int = 1) -> list[Path]:
    """Write every sample of `SAMPLES` plus README.md and truth.json into `out_dir`.

    Parameters
    ----------
    out_dir : str or Path
        Created when missing; existing sample files are overwritten.
    seed : int
        Seeds the noise, phases and dropped rows (one child stream per sample).

    Returns
    -------
    list of Path
        The observation files written, in `SAMPLES` order.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    streams = np.random.SeedSequence(seed).spawn(len(SAMPLES))
    written, truth = [], []
    for spec, stream in zip(SAMPLES, streams):
        rng = np.random.default_rng(stream)
        path, record = _write_sample(spec, out_dir, rng)
        written.append(path)
        truth.append(record)
    (out_dir / "truth.json").write_text(json.dumps({"seed": seed, "files": truth}, indent=1) + "\n")
    (out_dir / "README.md").write_text(_readme(truth, seed))
    return written


def _write_sample(spec: SampleSpec, out_dir: Path, rng: np.random.Generator) -> tuple[Path, dict]:
    tle = parse_tle(list(TLES[spec.norad]))
    time_utc = _pass_times(tle, DERENIVKA, spec)
    # The phc writer computed Az/El/Rg for Derenivka even at Uzhhorod: so do we.
    az_deg, el_deg, range_km = _topocentric(tle, DERENIVKA, time_utc)
    phase0, phase2, glint_phase = rng.uniform(0, 1, 3)
    t_s = (time_utc - time_utc[0]) / np.timedelta64(1, "s")
    model = model_mag(spec, t_s, phase0, phase2, glint_phase)
    common = dict(norad=spec.norad, name=tle[0][2:], cospar=tle_cospar(tle), tle=tle, exposure_s=spec.exposure_s,
                  az_deg=az_deg, el_deg=el_deg, range_km=range_km)
    record = {**asdict(spec), "phase1_cycles": round(float(phase0), 6), "phase2_cycles": round(float(phase2), 6),
              "glint_phase_cycles": round(float(glint_phase), 6), "start_utc": str(time_utc[0])[:23]}

    if spec.file_format == "ccd_phot":
        sign = 1.0 if time_utc[0] < SIGN_FIX_DATE else -1.0
        flux, flux_err, mag, mag_err = _measure(model, spec.exposure_s, el_deg, range_km, spec.zero_point_mag,
                                                spec.extinction_mag, sign, rng)
        pass_ = Pass(band=spec.band, site=DERENIVKA, time_utc=time_utc, mag=mag, mag_err=mag_err, flux=flux,
                     flux_err=flux_err, saturated=flux > SATURATION_COUNTS, valid=np.ones(len(mag), bool), **common)
        stamp = str(time_utc[0])
        name = f"result_{spec.norad}_{stamp[:10].replace('-', '')}_UT{stamp[11:19].replace(':', '')}.ph{spec.band}"
        path = write_ccd_phot(pass_, out_dir / name, spec.variant)
        record.update(file=name, extinction_sign_in_file="+kX (pre-2024-08-01 sign error)" if sign > 0 else "-kX",
                      n_rows=len(pass_), n_saturated=int(pass_.saturated.sum()))
        return path, record

    # phc: B and V on one time axis; a few samples lost, three with no signal (sentinel 10).
    keep = np.sort(rng.choice(len(time_utc), size=len(time_utc) - 8, replace=False))
    keep[0] = 0
    passes, sky = [], []
    lost = rng.integers(100, len(keep) - 100) + np.arange(3)
    for band, colour, (zero_point, k) in (("B", spec.colour_bv_mag, _PHC_B),
                                          ("V", 0.0, (spec.zero_point_mag, spec.extinction_mag))):
        flux, flux_err, mag, mag_err = _measure(model[keep] + colour, spec.exposure_s, el_deg[keep],
                                                range_km[keep], zero_point, k, -1.0, rng, sky_counts=400.0)
        valid = np.ones(len(keep), bool)
        valid[lost] = False
        flux = np.where(valid, flux, np.round(rng.normal(0.0, 5.0, len(keep)), 3))
        sky.append(np.round((flux_err**2 - flux) / 2.0, 3))
        passes.append(Pass(band=band, site=UZHHOROD, time_utc=time_utc[keep], mag=np.where(valid, mag, np.nan),
                           mag_err=mag_err, flux=flux, flux_err=flux_err, saturated=np.zeros(len(keep), bool),
                           valid=valid, **{**common, "az_deg": az_deg[keep], "el_deg": el_deg[keep],
                                           "range_km": range_km[keep]}))
    stamp = str(time_utc[0] - np.timedelta64(500, "ms"))
    name = f"{spec.norad}_{stamp[2:10].replace('-', '')}_{stamp[11:16].replace(':', '')}.phc"
    path = write_phc(passes[0], passes[1], out_dir / name, sky_b=sky[0], sky_v=sky[1])
    record.update(file=name, extinction_sign_in_file="-kX", n_rows=len(keep), sentinel_rows=lost.tolist(),
                  zero_point_b_mag=_PHC_B[0], extinction_b_mag=_PHC_B[1])
    return path, record


def _pass_times(tle: tuple[str, ...], site: Site, spec: SampleSpec) -> np.ndarray:
    """Mid-exposure times of the spec's pass: the `pass_index`-th dark-sky, sunlit window (counted from
    the one nearest the TLE epoch) long enough for the samples, starting on a whole second."""
    grid, starts, stops = _windows(tle, site)
    epoch = _tle_epoch(tle)
    needed = int(np.ceil(spec.n_samples * spec.exposure_s / _SEARCH_STEP_S)) + 2
    windows = sorted((s for s, e in zip(starts, stops) if e - s >= needed), key=lambda s: abs(grid[s] - epoch))
    if len(windows) <= spec.pass_index:
        raise RuntimeError(f"only {len(windows)} usable passes of {spec.norad} within {_SEARCH_DAYS} days of "
                           "the TLE epoch")
    start = grid[windows[spec.pass_index] + 1].astype("datetime64[s]").astype("datetime64[ns]")
    step = np.timedelta64(int(round(spec.exposure_s * 1e9)), "ns")
    # phc stamps are whole seconds at the integration start: mid-exposure is half a sample later.
    offset = step // 2 if spec.file_format == "phc" else np.timedelta64(0, "ns")
    return start + offset + step * np.arange(spec.n_samples)


@functools.lru_cache(maxsize=None)
def _windows(tle: tuple[str, ...], site: Site) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grid times (+-_SEARCH_DAYS around the epoch) and the start/stop grid indices of the windows where
    the satellite is above _MIN_ELEVATION_DEG and sunlit while the Sun is below _MAX_SUN_ELEVATION_DEG."""
    epoch = _tle_epoch(tle)
    offsets_s = np.arange(-_SEARCH_DAYS * 86400, _SEARCH_DAYS * 86400, _SEARCH_STEP_S)
    grid = epoch + (offsets_s * 1e9).astype("timedelta64[ns]")
    _, el_deg, _ = _topocentric(tle, site, grid, coarse=True)
    good = el_deg > _MIN_ELEVATION_DEG
    # The Sun and the shadow only where the satellite is high enough (a few % of the grid).
    high = np.flatnonzero(good)
    good[high] = _sunlit(tle, grid[high]) & (_sun_elevation_deg(site, grid[high]) < _MAX_SUN_ELEVATION_DEG)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], good.astype(np.int8), [0]])))
    return grid, edges[::2], edges[1::2]


def _tle_epoch(tle: tuple[str, ...]) -> np.datetime64:
    year, day = int(tle[-2][18:20]), float(tle[-2][20:32])
    start = np.datetime64(f"{2000 + year if year < 57 else 1900 + year}-01-01", "ns")
    return start + np.timedelta64(int(round((day - 1) * 86400e9)), "ns")


def _skyfield_times(time_utc: np.ndarray, coarse: bool = False):
    """skyfield Time for datetime64 UTC; `coarse` swaps in the IAU 2000B nutation (1 mas), which is
    ~20x cheaper and plenty for searching a 40-day grid for passes."""
    from raycast import ephemeris

    # Calendar day + seconds of that day: skyfield counts leap seconds inside a long run of
    # seconds, while datetime64 (POSIX) does not, so "seconds since 1970" would be 27 s off.
    ns = np.asarray(time_utc, dtype="datetime64[ns]").astype(np.int64)
    days, ns_of_day = np.divmod(ns, NS_PER_DAY)
    times = ephemeris.timescale().utc(1970, 1, 1 + days, 0, 0, ns_of_day / 1e9)
    if coarse:
        from skyfield.nutationlib import iau2000b_radians

        times._nutation_angles_radians = iau2000b_radians(times)
    return times


def _satellite(tle: tuple[str, ...]):
    from skyfield.api import EarthSatellite

    from raycast import ephemeris

    return EarthSatellite(tle[-2], tle[-1], tle[0][2:], ephemeris.timescale())


def _topocentric(tle, site: Site, time_utc: np.ndarray, coarse: bool = False):
    """Azimuth, PyEphem-refracted elevation (deg) and range (km) of the satellite from the site."""
    from skyfield.api import wgs84

    from raycast.refraction import apparent_elevation_deg

    place = wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.elevation_m)
    alt, az, distance = (_satellite(tle) - place).at(_skyfield_times(time_utc, coarse)).altaz()
    return az.degrees, apparent_elevation_deg(alt.degrees), distance.km


def _sunlit(tle, time_utc: np.ndarray) -> np.ndarray:
    from raycast import ephemeris

    return _satellite(tle).at(_skyfield_times(time_utc)).is_sunlit(ephemeris.planets())


def _sun_elevation_deg(site: Site, time_utc: np.ndarray) -> np.ndarray:
    from skyfield.api import wgs84

    from raycast import ephemeris

    planets = ephemeris.planets()
    place = planets["earth"] + wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.elevation_m)
    alt, _, _ = place.at(_skyfield_times(time_utc)).observe(planets["sun"]).apparent().altaz()
    return alt.degrees


def model_mag(spec: SampleSpec, t_s: np.ndarray, phase1: float, phase2: float, glint_phase: float) -> np.ndarray:
    """The brightness model: range-normalised standard magnitude at `t_s` seconds after the first sample.

    Parameters
    ----------
    spec : SampleSpec
    t_s : (n,) float
    phase1, phase2, glint_phase : float
        Phases in cycles (``truth.json`` records them per file).

    Returns
    -------
    (n,) float
    """
    cycles = t_s / spec.period_s
    distance = (cycles - glint_phase + 0.5) % 1.0 - 0.5
    return (spec.mean_mag
            + spec.amplitude1_mag * np.cos(2 * np.pi * (cycles + phase1))
            + spec.amplitude2_mag * np.cos(4 * np.pi * (cycles + phase2))
            - spec.glint_mag * np.exp(-0.5 * (distance / spec.glint_width_cycles) ** 2))


def _measure(model_mag, exposure_s, el_deg, range_km, zero_point, extinction, sign, rng, sky_counts=None):
    """Counts from the model through the inverse law, noise, and the magnitudes as the file writes them.

    The correct law is m = A + m_inst - k X + m_r; the file writes A + m_inst + sign * k X + m_r
    from the noisy counts (sign = +1 reproduces ccd_phot's pre-2024-08 error).

    Returns
    -------
    flux, flux_err, mag, mag_err : (n,) float, rounded as the files print them
    """
    x = airmass(el_deg)
    m_inst = model_mag - zero_point + extinction * x - range_correction_mag(range_km)
    counts = exposure_s * 10.0 ** (-0.4 * m_inst)
    variance = counts + (SKY_VARIANCE_COUNTS2 if sky_counts is None else 2.0 * sky_counts)
    flux = np.round(counts + rng.normal(0.0, 1.0, len(counts)) * np.sqrt(variance), 4 if sky_counts is None else 3)
    flux_err = np.sqrt(variance)
    if sky_counts is None:
        flux_err = np.round(flux_err, 4)
    mag = np.round(zero_point + instrumental_mag(flux, exposure_s) + sign * extinction * x
                   + range_correction_mag(range_km), 3)
    mag_err = np.round(2.5 / np.log(10) * flux_err / flux, 3)
    return flux, flux_err, mag, mag_err


def _readme(truth: list[dict], seed: int) -> str:
    rows = "\n".join(
        f"| `{r['file']}` | {r['norad']} | {r['band']} | {r['file_format']}{' ' + r['variant'] if r['variant'] else ''} "
        f"| {r['start_utc']} | {r['n_rows']} | {r['exposure_s']} | **{r['period_s']}** | {r['mean_mag']} "
        f"| {r['zero_point_mag']} / {r['extinction_mag']} | {r['extinction_sign_in_file']} |"
        for r in truth)
    return f"""# Sample observations (generated)

Written by `python -m rsodb.samples --out data_samples --seed {seed}` (rsodb/samples.py); do not
edit by hand. Every file is synthetic: real public TLEs and real site coordinates, a simple
periodic brightness model, and the real file formats with their quirks. `truth.json` holds the
same information, machine-readable.

| file | NORAD | band | format | first sample (UTC, mid-exposure) | rows | dt (s) | injected period P (s) | m0 | A / k | extinction in file |
|---|---|---|---|---|---|---|---|---|---|---|
{rows}

Model: m_st(t) = m0 + a1 cos(2 pi (t/P + phi1)) + a2 cos(4 pi (t/P + phi2)) - g exp(-d^2 / 2w^2),
d the distance in cycles to the glint phase (all values in `truth.json`); t from the first sample.
m_st is the standard magnitude reduced to 1000 km. Counts follow from the inverse of the reduction
law with noise sigma^2 = F + {SKY_VARIANCE_COUNTS2:g} (ccd_phot) or F + 2 Fon (phc); frames above
{SATURATION_COUNTS:g} counts are marked saturated (`*`).

Quirks reproduced on purpose:
- ccd_phot files before 2024-08-01 add +kX (the historical sign error); the reader flags them and
  recovers m_st in `mag_corrected`.
- the 2021 TOPEX files predate 2023-02, so their stamps are exposure starts (mid - dt/2).
- the phc file (Uzhhorod photometer, B and V) has Az/El/Rg computed for Derenivka, integration-start
  stamps on whole seconds, 8 missing samples and 3 samples without signal (sentinel magnitude 10).
"""


def main(argv: list[str] | None = None) -> int:
    """Command line: ``python -m rsodb.samples --out data_samples [--seed N]``."""
    parser = argparse.ArgumentParser(
        prog="python -m rsodb.samples",
        description="Generate the sample observation files (ccd_phot .phX and phc) with known injected periods.",
        epilog="example: python -m rsodb.samples --out data_samples --seed 1",
    )
    parser.add_argument("--out", required=True, type=Path, help="output directory (created when missing)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the noise and phases (default 1)")
    args = parser.parse_args(argv)
    for path in generate(args.out, args.seed):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
