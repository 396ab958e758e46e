"""The sample generator: deterministic, current, readable, and true to its own truth.json.

Authorities: the committed data_samples/ (a regeneration must match it byte for byte),
PyEphem (Az/El/range of each sample, as the lab's files were computed), the injected
periods and reduction constants (truth.json) and the model magnitudes.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from astropy.timeseries import LombScargle

import ingest
from rsodb.samples import SAMPLES, TLES, SampleSpec, main, model_mag

DATA_SAMPLES = Path(__file__).resolve().parents[1] / "data_samples"


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("samples")
    assert main(["--out", str(out), "--seed", "1"]) == 0
    return out


@pytest.fixture(scope="module")
def truth(generated) -> list[dict]:
    return json.loads((generated / "truth.json").read_text())["files"]


def passes_of(generated, record):
    return ingest.read_file(generated / record["file"])


def spec_of(record) -> SampleSpec:
    return SampleSpec(**{k: record[k] for k in SampleSpec.__dataclass_fields__})


def test_committed_samples_are_the_generator_output(generated):
    committed = sorted(p.name for p in DATA_SAMPLES.iterdir())
    assert committed == sorted(p.name for p in generated.iterdir())
    for name in committed:
        assert (DATA_SAMPLES / name).read_bytes() == (generated / name).read_bytes(), name


def test_samples_are_small_and_cover_the_formats(generated, truth):
    total = sum(p.stat().st_size for p in generated.iterdir())
    assert total < 1.5e6
    kinds = {(r["file_format"], r["variant"], r["band"]) for r in truth}
    assert {("ccd_phot", "ut"), ("ccd_phot", "jd"), ("phc", "")} <= {k[:2] for k in kinds}
    assert len({r["norad"] for r in truth}) >= 2 and len(truth) == len(SAMPLES)
    assert "**9.86**" in (generated / "README.md").read_text()


def test_every_sample_reads_as_recorded(generated, truth):
    for record in truth:
        passes = passes_of(generated, record)
        assert len(passes) == (2 if record["file_format"] == "phc" else 1)
        for p in passes:
            assert (p.norad, len(p), p.exposure_s) == (record["norad"], record["n_rows"], record["exposure_s"])
            # The JD variant prints float64 Julian dates: 40 us steps.
            assert abs(p.start_utc - np.datetime64(record["start_utc"], "ns")) <= np.timedelta64(41, "us")
            assert p.tle == TLES[record["norad"]]
        if record["file_format"] == "phc":
            b, v = passes
            assert np.flatnonzero(~b.valid).tolist() == record["sentinel_rows"] == np.flatnonzero(~v.valid).tolist()
        else:
            assert passes[0].band == record["band"] and passes[0].saturated.sum() == record["n_saturated"]


def test_reduction_constants_and_sign_are_recovered(generated, truth):
    # The written magnitudes are rounded to 0.001 mag: A and c come back to ~1e-4 (1e-3 allowed).
    for record in truth:
        passes = passes_of(generated, record)
        laws = ([(record["zero_point_b_mag"], record["extinction_b_mag"]),
                 (record["zero_point_mag"], record["extinction_mag"])]
                if record["file_format"] == "phc" else [(record["zero_point_mag"], record["extinction_mag"])])
        wrong_sign = record["extinction_sign_in_file"].startswith("+")
        for p, (zero_point, k) in zip(passes, laws):
            assert p.reduction.zero_point_mag == pytest.approx(zero_point, abs=1e-3)
            assert p.reduction.extinction_term_mag == pytest.approx(k if wrong_sign else -k, abs=1e-3)
            assert p.reduction.sign_error is wrong_sign


def test_magnitudes_scatter_about_the_model_as_their_errors_say(generated, truth):
    for record in truth:
        spec = spec_of(record)
        for p in passes_of(generated, record):
            colour = spec.colour_bv_mag if p.band == "B" and spec.file_format == "phc" else 0.0
            model = model_mag(spec, p.t_s, record["phase1_cycles"], record["phase2_cycles"],
                              record["glint_phase_cycles"]) + colour
            chi2 = ((p.best_mag - model) / p.mag_err)[p.valid] ** 2
            # chi^2 per point is 1 +- sqrt(2/n) (<= 0.083 for n >= 290): 3 sigma is 0.25.
            assert abs(chi2.mean() - 1.0) < 0.25, (record["file"], p.band, chi2.mean())


def test_injected_periods_are_recovered(generated, truth):
    for record in truth:
        for p in passes_of(generated, record):
            periodogram = LombScargle(p.t_s[p.valid], p.best_mag[p.valid], nterms=2)
            # Coarse search up to the Nyquist frequency, then a fine grid around the best peak.
            frequency, power = periodogram.autopower(
                minimum_frequency=1 / 200, maximum_frequency=0.5 / p.exposure_s, samples_per_peak=5)
            best, step = frequency[np.argmax(power)], frequency[1] - frequency[0]
            fine = np.linspace(best - 2 * step, best + 2 * step, 201)
            found = 1 / fine[np.argmax(periodogram.power(fine))]
            cycles = p.duration_s / record["period_s"]
            # The peak is 1/cycles wide in relative frequency; its centre is found to a tenth of that.
            assert abs(found / record["period_s"] - 1) < 0.1 / cycles, (record["file"], found)


def test_geometry_agrees_with_pyephem(generated, truth):
    ephem = pytest.importorskip("ephem")
    for record in truth:
        p = passes_of(generated, record)[0]
        tle = TLES[record["norad"]]
        satellite = ephem.readtle(tle[0][2:], tle[1], tle[2])
        # The phc writer's Az/El are for Derenivka; so are the ccd_phot files'.
        observer = ephem.Observer()
        observer.lat, observer.lon, observer.elevation = "48.5635505", "22.453751", 231.1325
        for k in range(0, len(p), 37):
            observer.date = ephem.Date(str(p.time_utc[k]).replace("T", " ")[:26])
            satellite.compute(observer)
            az, el = np.radians(p.az_deg[k]), np.radians(p.el_deg[k])
            separation = np.degrees(np.arccos(np.clip(
                np.sin(el) * np.sin(satellite.alt) + np.cos(el) * np.cos(satellite.alt) * np.cos(az - satellite.az),
                -1, 1)))
            # PyEphem's and skyfield's SGP4 and Earth rotation agree to ~0.005 deg and 50 m here.
            assert separation < 0.01, (record["file"], k, separation)
            assert abs(satellite.range / 1000 - p.range_km[k]) < 0.05


def test_seed_changes_the_noise_not_the_geometry(tmp_path, generated, truth):
    main(["--out", str(tmp_path), "--seed", "2"])
    record = truth[0]
    (a,) = passes_of(generated, record)
    (b,) = ingest.read_file(tmp_path / record["file"])
    assert np.array_equal(a.time_utc, b.time_utc) and np.array_equal(a.el_deg, b.el_deg)
    assert not np.array_equal(a.flux, b.flux)
