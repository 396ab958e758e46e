"""Generate `data_samples/`: observation files in the real formats, rendered from known spin states.

Each sample is a pass of a real satellite (public TLEs from the reference paper's code,
Apache-2.0) over Derenivka, found by searching +-20 days around the TLE epoch for a sunlit
satellite above 20 deg with the Sun below -6 deg (the nearest such passes are used). The
light curve is rendered by the project's own renderer along that pass's geometry, from a spin
state written down in `SAMPLES`:

- geometry: `raycast.geometry.PassGeometry.compute` (SGP4, Sun, Earth shadow, exposure
  sub-samples) for the site the file declares;
- attitude: the published precessing spin (`raycast.geometry.attitude.PrecessingSpin`), its phases
  given at the pass mid-time exactly as the fitter defines them (`rsodb.fit.model.EpochShifted`),
  so a fit of the file with the ``precessing`` attitude family recovers the numbers in
  ``truth.json``;
- shape: the models built by code, `raycast.models.topex` (NORAD 22076, solar-array pitch
  from the truth) and `raycast.models.cosmos2502` (NORAD 40358);
- brightness: the fast path (`raycast.renderer.cache.SceneCache` through `raycast.renderer.render`), and
  magnitudes reduced to 1000 km (`raycast.renderer.photometry`) in the file's band(s).

The rendered standard magnitudes are turned into counts through the inverse of each format's
reduction law with Poisson-like noise, and written back as the format's magnitudes, including
ccd_phot's historical ``+kX`` sign error for passes before 2024-08-01. The truths, the
apparent period of each noiseless curve (what a period search should find) and the reduction
constants go to ``README.md`` and ``truth.json`` beside the files, so tests can check what later
stages recover.

Run ``python -m rsodb.samples --out data_samples [--seed N]``; the output is byte-for-byte
deterministic for a given seed (the seed drives the noise and the dropped rows only).
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass
import functools
import importlib
import json
from pathlib import Path

import numpy as np
from skyfield.api import EarthSatellite, wgs84
from skyfield.nutationlib import iau2000b_radians

from ingest.elements import parse_tle, tle_cospar
from ingest.observation import Pass
from ingest.reduction import airmass, instrumental_mag, range_correction_mag
from ingest.site import DERENIVKA, UZHHOROD, Site
from ingest.times import NS_PER_DAY
from ingest.writers import write_ccd_phot, write_phc
from raycast.geometry import ephemeris
from raycast.geometry.attitude import PrecessingSpin
from raycast.geometry.orbit import Satellite
from raycast.geometry.pass_geometry import PassGeometry, choose_n_sub
from raycast.geometry.refraction import apparent_elevation_deg
from raycast.renderer.cache import SceneCache
from raycast.renderer.methods import render
from raycast.renderer.photometry import REFERENCE_RANGE_KM, magnitude
from rsodb.fit.model import EpochShifted
from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.search import find_period

__all__ = ["SpinTruth", "SampleSpec", "SAMPLES", "TLES", "SHAPES", "CACHE_GRID_SIZE", "generate", "render_mag", "main"]

# Public TLEs used by the reference paper's code (vkudak/blender_lc_fit, Apache-2.0).
TLES = {
    22076: (
        "0 TOPEX/POSEIDON",
        "1 22076U 92052A   21160.57864517 -.00000059  00000-0  95149-5 0  9996",
        "2 22076  66.0409 341.5772 0007830 272.3340 147.4137 12.81032194348634",
    ),
    40358: (
        "0 COSMOS 2502",
        "1 40358U 14086A   24009.55814244  .00000043  00000-0  83941-4 0  9993",
        "2 40358  67.1523  12.8839 0007020 252.7955 107.2362 13.97588796459621",
    ),
}
# The model each object is rendered with (a module of raycast.models with a build() function).
SHAPES = {22076: "topex", 40358: "cosmos2502"}
# Visibility grid of the renderer's cache. The fitter's cache uses 32 (directions 2.8 deg apart);
# 16 builds several times faster and changes the light curves by far less than their noise, and data
# rendered with exactly the fitter's model would flatter it.
CACHE_GRID_SIZE = 16
CACHE_ACCURACY_MAG = 0.01
# Exposure sub-samples: this many times the fitter's default (2 deg of spin each), so that the
# solar cells' 1.3 deg glints are integrated over the exposure rather than stepped over.
_GLINT_SUBSAMPLING = 3
# ccd_phot added +kX instead of -kX until this date (PROVENANCE.md).
SIGN_FIX_DATE = np.datetime64("2024-08-01", "ns")
# Counting noise: sigma_F^2 = F + sky variance (counts^2), close to the real files' Flux_err.
SKY_VARIANCE_COUNTS2 = 1000.0
# A frame is saturated above this many counts (the brightest glints can reach it).
SATURATION_COUNTS = 2.0e5
_MIN_ELEVATION_DEG = 20.0
_MAX_SUN_ELEVATION_DEG = -6.0
_SEARCH_STEP_S = 60.0
_SEARCH_DAYS = 20


@dataclass(frozen=True)
class SpinTruth:
    """The spin state a sample is rendered from: the fitter's ``precessing`` attitude family.

    Attributes
    ----------
    spin_period_s : float
        Spin period about `spin_axis`, relative to the precessing frame, s.
    spin_phase_deg : float
        Spin phase at the pass mid-time (midway between the first and last samples).
    precession_period_s : float
        Period of the spin axis around nadir, s.
    precession_phase_deg : float
        Precession phase at the pass mid-time.
    precession_angle_deg : float
        Half-angle of the precession cone about nadir.
    spin_axis : str
        Body axis that spins (TOPEX about its long axis ``"z"``, COSMOS 2502 end over end ``"x"``).
    panel_pitch_deg : float or None
        Solar-array pitch of a model that has one (TOPEX), else None.
    """

    spin_period_s: float
    spin_phase_deg: float
    precession_period_s: float
    precession_phase_deg: float
    precession_angle_deg: float
    spin_axis: str = "z"
    panel_pitch_deg: float | None = None

    def attitude(self, epoch_s: float):
        """The `raycast.geometry.attitude.PrecessingSpin` with its phases at `epoch_s` (s after the first sample)."""
        return EpochShifted(
            PrecessingSpin(
                period_s=self.spin_period_s,
                phase_deg=self.spin_phase_deg,
                precession_period_s=self.precession_period_s,
                precession_phase_deg=self.precession_phase_deg,
                precession_angle_deg=self.precession_angle_deg,
                spin_axis=self.spin_axis,
            ),
            epoch_s,
        )


@dataclass(frozen=True)
class SampleSpec:
    """One sample file and the truth it is rendered from.

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
    truth : SpinTruth
        The spin state.
    zero_point_mag, extinction_mag : float
        A and k (> 0) of the format's reduction law (V values for phc).
    """

    file_format: str
    norad: int
    band: str
    variant: str
    pass_index: int
    exposure_s: float
    n_samples: int
    truth: SpinTruth
    zero_point_mag: float
    extinction_mag: float


# TOPEX: spin 9.86 s (the paper's 2020 value), array pitch 12 deg (the paper's fit), spinning
# about its long axis; COSMOS 2502: 40.5 s (paper, 2023), end over end. Slow precession (about an
# hour) turns the light curves' shape over a pass and keeps the apparent periods within a few
# percent of the spin periods. The truths and passes are chosen so that the light curve repeats
# once per spin rather than twice (a period search then finds the spin period, not half of it).
# The COSMOS 2502 ccd_phot and phc files are the same pass seen from Derenivka and Uzhhorod, with
# one spin state (its phases referred to each file's own mid-time).
_TOPEX_MAY = SpinTruth(9.86, 40.0, 4000.0, 120.0, 20.0, "z", 12.0)
_TOPEX_JUNE = SpinTruth(9.87, 210.0, 4000.0, 300.0, 20.0, "z", 12.0)
_COSMOS = SpinTruth(40.5, 75.0, 4000.0, 60.0, 45.0, "x")
SAMPLES = (
    SampleSpec("ccd_phot", 22076, "V", "ut", 2, 0.2, 600, _TOPEX_MAY, 18.0, 0.10),
    SampleSpec("ccd_phot", 22076, "R", "jd", 1, 0.25, 480, _TOPEX_JUNE, 17.5, 0.08),
    SampleSpec("ccd_phot", 40358, "V", "ut", 0, 1.0, 420, _COSMOS, 13.8, 0.40),
    SampleSpec("phc", 40358, "BV", "", 0, 1.0, 420, _COSMOS, 14.04, 0.45),
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
        Seeds the noise and the dropped rows (one child stream per sample).

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
    (out_dir / "truth.json").write_text(
        json.dumps({"seed": seed, "command": _command(seed), "noise": _NOISE, "files": truth}, indent=1) + "\n"
    )
    (out_dir / "README.md").write_text(_readme(truth, seed))
    return written


def _command(seed: int) -> str:
    return f"python -m rsodb.samples --out data_samples --seed {seed}"


_NOISE = (
    f"counts F from the rendered magnitude through the inverse reduction law; Gaussian noise of variance "
    f"F + {SKY_VARIANCE_COUNTS2:g} counts^2 (ccd_phot) or F + 2 sky (phc, sky = 400 counts); "
    f"frames above {SATURATION_COUNTS:g} counts flagged saturated"
)


def render_mag(spec: SampleSpec, time_utc: np.ndarray, site: Site, bands: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Noiseless standard magnitudes (reduced to 1000 km) of a sample, rendered along its pass.

    Parameters
    ----------
    spec : SampleSpec
    time_utc : (n,) datetime64[ns]
        Mid-exposure times.
    site : Site
        The observer the file declares.
    bands : tuple of str
        Bands to return (the Sun's colour makes B - V = 0.63 for grey materials).

    Returns
    -------
    dict of str to (n,) float
    """
    truth = spec.truth
    n_sub = _GLINT_SUBSAMPLING * choose_n_sub(spec.exposure_s, truth.spin_period_s)
    geometry = PassGeometry.compute(
        Satellite.from_tle(list(TLES[spec.norad])), site, time_utc, spec.exposure_s, n_sub=n_sub
    )
    body = geometry.body_frame(truth.attitude(0.5 * (geometry.t_s[0] + geometry.t_s[-1])))
    scene, cache = _scene_cache(SHAPES[spec.norad], truth.panel_pitch_deg)
    light_curve = render(scene, body, method="cached", cache=cache)
    if not np.all(light_curve.intensity_m2_sr > 0):
        raise RuntimeError(f"the rendered {SHAPES[spec.norad]} is dark in some frames; choose another truth or pass")

    return {band: magnitude(light_curve.intensity_m2_sr, REFERENCE_RANGE_KM, band) for band in bands}


@functools.cache
def _scene_cache(shape: str, panel_pitch_deg: float | None):
    """The model's scene (articulation fixed) and its renderer cache, built once per process."""
    scene = importlib.import_module(f"raycast.models.{shape}").build()
    if panel_pitch_deg is not None:
        scene = scene.with_parameters(panel_pitch_deg=panel_pitch_deg)
    return scene, SceneCache.build(scene, accuracy_mag=CACHE_ACCURACY_MAG, grid_size=CACHE_GRID_SIZE)


def apparent_period_s(spec: SampleSpec, time_utc: np.ndarray, model_mag: np.ndarray) -> float:
    """The period the project's period search finds on the noiseless curve (what noisy data should give)."""
    t_s = (time_utc - time_utc[0]) / np.timedelta64(1, "s")
    lc = LightCurve(t_s=t_s, mag=model_mag, mag_err=np.full(len(t_s), 0.01), exposure_s=spec.exposure_s)
    return float(find_period(lc).best_period_s)


def _write_sample(spec: SampleSpec, out_dir: Path, rng: np.random.Generator) -> tuple[Path, dict]:
    tle = parse_tle(list(TLES[spec.norad]))
    time_utc = _pass_times(tle, DERENIVKA, spec)
    # The phc writer computed Az/El/Rg for Derenivka even at Uzhhorod: so do we.
    az_deg, el_deg, range_km = _topocentric(tle, DERENIVKA, time_utc)
    common = dict(
        norad=spec.norad,
        name=tle[0][2:],
        cospar=tle_cospar(tle),
        tle=tle,
        exposure_s=spec.exposure_s,
        az_deg=az_deg,
        el_deg=el_deg,
        range_km=range_km,
    )
    record = {**asdict(spec), "shape": SHAPES[spec.norad], "start_utc": str(time_utc[0])[:23]}

    if spec.file_format == "ccd_phot":
        model = render_mag(spec, time_utc, DERENIVKA, (spec.band,))[spec.band]
        sign = 1.0 if time_utc[0] < SIGN_FIX_DATE else -1.0
        flux, flux_err, mag, mag_err = _measure(
            model, spec.exposure_s, el_deg, range_km, spec.zero_point_mag, spec.extinction_mag, sign, rng
        )
        pass_ = Pass(
            band=spec.band,
            site=DERENIVKA,
            time_utc=time_utc,
            mag=mag,
            mag_err=mag_err,
            flux=flux,
            flux_err=flux_err,
            saturated=flux > SATURATION_COUNTS,
            valid=np.ones(len(mag), bool),
            **common,
        )
        stamp = str(time_utc[0])
        name = f"result_{spec.norad}_{stamp[:10].replace('-', '')}_UT{stamp[11:19].replace(':', '')}.ph{spec.band}"
        path = write_ccd_phot(pass_, out_dir / name, spec.variant)
        record.update(
            file=name,
            extinction_sign_in_file="+kX (pre-2024-08-01 sign error)" if sign > 0 else "-kX",
            n_rows=len(pass_),
            n_saturated=int(pass_.saturated.sum()),
            apparent_period_s=_rounded_period(spec, time_utc, model),
            **_range_of(model),
        )
        return path, record

    # phc: B and V on one time axis; a few samples lost, three with no signal (sentinel 10).
    keep = np.sort(rng.choice(len(time_utc), size=len(time_utc) - 8, replace=False))
    keep[0], keep[-1] = 0, len(time_utc) - 1
    keep = np.unique(keep)
    models = render_mag(spec, time_utc[keep], UZHHOROD, ("B", "V"))
    passes, sky = [], []
    lost = rng.integers(100, len(keep) - 100) + np.arange(3)
    for band, (zero_point, k) in (("B", _PHC_B), ("V", (spec.zero_point_mag, spec.extinction_mag))):
        flux, flux_err, mag, mag_err = _measure(
            models[band], spec.exposure_s, el_deg[keep], range_km[keep], zero_point, k, -1.0, rng, sky_counts=400.0
        )
        valid = np.ones(len(keep), bool)
        valid[lost] = False
        flux = np.where(valid, flux, np.round(rng.normal(0.0, 5.0, len(keep)), 3))
        sky.append(np.round((flux_err**2 - flux) / 2.0, 3))
        passes.append(
            Pass(
                band=band,
                site=UZHHOROD,
                time_utc=time_utc[keep],
                mag=np.where(valid, mag, np.nan),
                mag_err=mag_err,
                flux=flux,
                flux_err=flux_err,
                saturated=np.zeros(len(keep), bool),
                valid=valid,
                **{**common, "az_deg": az_deg[keep], "el_deg": el_deg[keep], "range_km": range_km[keep]},
            )
        )
    stamp = str(time_utc[0] - np.timedelta64(500, "ms"))
    name = f"{spec.norad}_{stamp[2:10].replace('-', '')}_{stamp[11:16].replace(':', '')}.phc"
    path = write_phc(passes[0], passes[1], out_dir / name, sky_b=sky[0], sky_v=sky[1])
    record.update(
        file=name,
        extinction_sign_in_file="-kX",
        n_rows=len(keep),
        sentinel_rows=lost.tolist(),
        zero_point_b_mag=_PHC_B[0],
        extinction_b_mag=_PHC_B[1],
        apparent_period_s=_rounded_period(spec, time_utc[keep], models["V"]),
        **_range_of(models["V"]),
    )
    return path, record


def _rounded_period(spec: SampleSpec, time_utc: np.ndarray, model_mag: np.ndarray) -> float:
    return round(apparent_period_s(spec, time_utc, model_mag), 4)


def _range_of(model_mag: np.ndarray) -> dict:
    """The noiseless curve's brightest and faintest standard magnitudes (README and sanity checks)."""
    return {"model_mag_min": round(float(model_mag.min()), 3), "model_mag_max": round(float(model_mag.max()), 3)}


def _pass_times(tle: tuple[str, ...], site: Site, spec: SampleSpec) -> np.ndarray:
    """Mid-exposure times of the spec's pass: the `pass_index`-th dark-sky, sunlit window (counted from
    the one nearest the TLE epoch) long enough for the samples, starting on a whole second."""
    grid, starts, stops = _windows(tle, site)
    epoch = _tle_epoch(tle)
    needed = int(np.ceil(spec.n_samples * spec.exposure_s / _SEARCH_STEP_S)) + 2
    windows = sorted((s for s, e in zip(starts, stops) if e - s >= needed), key=lambda s: abs(grid[s] - epoch))
    if len(windows) <= spec.pass_index:
        raise RuntimeError(
            f"only {len(windows)} usable passes of {spec.norad} within {_SEARCH_DAYS} days of the TLE epoch"
        )
    start = grid[windows[spec.pass_index] + 1].astype("datetime64[s]").astype("datetime64[ns]")
    step = np.timedelta64(int(round(spec.exposure_s * 1e9)), "ns")
    # phc stamps are whole seconds at the integration start: mid-exposure is half a sample later.
    offset = step // 2 if spec.file_format == "phc" else np.timedelta64(0, "ns")
    return start + offset + step * np.arange(spec.n_samples)


@functools.cache
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
    # Calendar day + seconds of that day: skyfield counts leap seconds inside a long run of
    # seconds, while datetime64 (POSIX) does not, so "seconds since 1970" would be 27 s off.
    ns = np.asarray(time_utc, dtype="datetime64[ns]").astype(np.int64)
    days, ns_of_day = np.divmod(ns, NS_PER_DAY)
    times = ephemeris.timescale().utc(1970, 1, 1 + days, 0, 0, ns_of_day / 1e9)
    if coarse:
        times._nutation_angles_radians = iau2000b_radians(times)
    return times


def _satellite(tle: tuple[str, ...]):
    return EarthSatellite(tle[-2], tle[-1], tle[0][2:], ephemeris.timescale())


def _topocentric(tle, site: Site, time_utc: np.ndarray, coarse: bool = False):
    """Azimuth, PyEphem-refracted elevation (deg) and range (km) of the satellite from the site."""
    place = wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.elevation_m)
    alt, az, distance = (_satellite(tle) - place).at(_skyfield_times(time_utc, coarse)).altaz()
    return az.degrees, apparent_elevation_deg(alt.degrees), distance.km


def _sunlit(tle, time_utc: np.ndarray) -> np.ndarray:
    return _satellite(tle).at(_skyfield_times(time_utc)).is_sunlit(ephemeris.planets())


def _sun_elevation_deg(site: Site, time_utc: np.ndarray) -> np.ndarray:
    planets = ephemeris.planets()
    place = planets["earth"] + wgs84.latlon(site.lat_deg, site.lon_deg, elevation_m=site.elevation_m)
    alt, _, _ = place.at(_skyfield_times(time_utc)).observe(planets["sun"]).apparent().altaz()
    return alt.degrees


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
    mag = np.round(
        zero_point + instrumental_mag(flux, exposure_s) + sign * extinction * x + range_correction_mag(range_km), 3
    )
    mag_err = np.round(2.5 / np.log(10) * flux_err / flux, 3)
    return flux, flux_err, mag, mag_err


def _readme(truth: list[dict], seed: int) -> str:
    rows = "\n".join(
        f"| `{r['file']}` | {r['norad']} ({r['shape']}) | {r['band']} | {r['file_format']}"
        f"{' ' + r['variant'] if r['variant'] else ''} | {r['start_utc']} | {r['n_rows']} | {r['exposure_s']} "
        f"| **{r['truth']['spin_period_s']}** | {r['truth']['spin_phase_deg']:g} "
        f"| {r['truth']['precession_period_s']:g} / {r['truth']['precession_phase_deg']:g} "
        f"/ {r['truth']['precession_angle_deg']:g} | {r['truth']['spin_axis']} "
        f"| {'-' if r['truth']['panel_pitch_deg'] is None else format(r['truth']['panel_pitch_deg'], 'g')} "
        f"| {r['apparent_period_s']} | {r['model_mag_min']}..{r['model_mag_max']} "
        f"| {r['zero_point_mag']} / {r['extinction_mag']} | {r['extinction_sign_in_file']} |"
        for r in truth
    )
    return f"""# Sample observations (generated)

Written by `{_command(seed)}` (rsodb/samples/generate.py); do not edit by hand. Every
file is synthetic: real public TLEs and real site coordinates, light curves rendered by the
project's renderer from known spin states, and the real file formats with their quirks.
`truth.json` holds the same information, machine-readable.

| file | NORAD (model) | band | format | first sample (UTC, mid-exposure) | rows | dt (s) | spin period P (s) | spin phase (deg) | precession period (s) / phase (deg) / angle (deg) | spin axis | panel pitch (deg) | apparent period (s) | m_st range (mag) | A / k | extinction in file |
|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|
{rows}

How the light curves are made: the pass geometry (`raycast.geometry.PassGeometry`, SGP4,
exposure sub-samples, Earth shadow) for the file's site, the published precessing spin
(`raycast.geometry.attitude.PrecessingSpin`: spin about the body axis given, that axis precessing on a
cone about nadir) with both phases given at the pass mid-time (midway between the first and
last samples, the fitter's reference epoch), and the models built by code
(`raycast.models.topex` with the solar-array pitch given, `raycast.models.cosmos2502`), rendered
with the fast path (`raycast.renderer.cache.SceneCache`, visibility grid {CACHE_GRID_SIZE}) and reduced to
1000 km (m_st). A fit with the `precessing` attitude family and the object's model recovers the
spin state; the free magnitude offset of the fit absorbs the zero point.

The COSMOS 2502 ccd_phot file and the phc file are the same pass, seen from Derenivka and from
Uzhhorod, with one spin state (its phases referred to each file's own mid-time). The main job
(`rsodb pipeline data_samples --archive archive --out reports`) fits every pass with the
object's model and compares the fitted spin periods with the period search.

The apparent period is what the project's period search (`rsodb.periods.find_period`) finds on
the noiseless curve: the light curve of a precessing body in an orbiting frame repeats at
neither the spin period nor exactly any multiple of it, so this is the number a period search
on the file should reproduce.

Noise: {_NOISE}. m_st is the standard magnitude reduced to 1000 km; counts follow from the
inverse of the file's reduction law.

Quirks reproduced on purpose:
- ccd_phot files before 2024-08-01 add +kX (the historical sign error); the reader flags them and
  recovers m_st in `mag_corrected`.
- the 2021 TOPEX files predate 2023-02, so their stamps are exposure starts (mid - dt/2).
- the phc file (Uzhhorod photometer, B and V) has Az/El/Rg computed for Derenivka, integration-start
  stamps on whole seconds, missing samples and 3 samples without signal (sentinel magnitude 10).
"""


def main(argv: list[str] | None = None) -> int:
    """Command line: ``python -m rsodb.samples --out data_samples [--seed N]``."""
    parser = argparse.ArgumentParser(
        prog="python -m rsodb.samples",
        description="Generate the sample observation files (ccd_phot .phX and phc): light curves rendered from "
        "known spin states along real passes, written in the real formats.",
        epilog="example: python -m rsodb.samples --out data_samples --seed 1",
    )
    parser.add_argument("--out", required=True, type=Path, help="output directory (created when missing)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the noise and dropped rows (default 1)")
    args = parser.parse_args(argv)
    for path in generate(args.out, args.seed):
        print(path)
    return 0
