"""The sample generator: deterministic, current, readable, and true to its own truth.json.

Authorities: the committed data_samples/ (a regeneration must match it line for line, numbers
to one unit in their last printed digit),
PyEphem (Az/El/range of each sample, as the lab's files were computed), the reduction
constants in truth.json, and the light curves the renderer gives for the recorded truths.
Regenerating renders every pass (two renderer caches), so those tests are marked slow; the
others read the committed files.
"""

from __future__ import annotations

from dataclasses import fields
import json
from pathlib import Path
import re
import warnings

import numpy as np
import pytest

import ingest
from ingest.site import DERENIVKA, UZHHOROD
from rsodb.samples.generate import SAMPLES, TLES, SampleSpec, SpinTruth, main, render_mag

DATA_SAMPLES = Path(__file__).resolve().parents[1] / "data_samples"


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("samples")
    with warnings.catch_warnings():
        # Exposure sub-samples too coarse for a glint would make the files depend on luck.
        warnings.simplefilter("error", UserWarning)
        assert main(["--out", str(out), "--seed", "1"]) == 0
    return out


@pytest.fixture(scope="module")
def truth() -> list[dict]:
    return json.loads((DATA_SAMPLES / "truth.json").read_text())["files"]


def passes_of(directory, record):
    return ingest.read_file(directory / record["file"])


def spec_of(record) -> SampleSpec:
    values = {f.name: record[f.name] for f in fields(SampleSpec)}
    return SampleSpec(**{**values, "truth": SpinTruth(**record["truth"])})


def _last_digit_unit(token):
    """One unit in the last printed digit of a decimal number, or None for other tokens."""
    if not re.fullmatch(r"[-+]?\d+(\.\d+)?", token):
        return None
    return 10.0 ** -len(token.partition(".")[2])


def differing_tokens(committed_text, generated_text):
    """(line, committed token, generated token) for every token that differs beyond rounding.

    Rendering sums float32 values in an order that may change with the machine (threads, SIMD
    width), so a number may differ by one unit in its last printed digit, or by 1e-6 of itself
    where the printed precision is finer than that (a 22121.2244 flux derived from float32
    intensities); a change of the generator moves numbers by far more.
    """
    committed, generated = committed_text.splitlines(), generated_text.splitlines()
    if len(committed) != len(generated):
        return [(0, f"{len(committed)} lines", f"{len(generated)} lines")]
    found = []
    for number, (a_line, b_line) in enumerate(zip(committed, generated), start=1):
        a_tokens, b_tokens = a_line.split(), b_line.split()
        if len(a_tokens) != len(b_tokens):
            found.append((number, a_line, b_line))
            continue
        for a, b in zip(a_tokens, b_tokens):
            unit = _last_digit_unit(a)
            if unit is None or _last_digit_unit(b) != unit:
                same = a == b
            else:
                same = abs(float(a) - float(b)) <= max(1.01 * unit, 1e-6 * abs(float(a)))
            if not same:
                found.append((number, a, b))
    return found


def test_sample_comparison_tolerates_only_the_last_digit():
    assert differing_tokens("x 17486.6419 1.0", "x 17486.6420 1.0") == []
    assert differing_tokens("x 17486.6419", "x 17486.6421") == []  # 1e-8 of the value
    assert differing_tokens("x 17486.6419", "x 17486.6621") == [(1, "17486.6419", "17486.6621")]
    assert differing_tokens("x 1.6419", "x 1.6421") == [(1, "1.6419", "1.6421")]
    assert differing_tokens("x 1.50", "x 1.5") == [(1, "1.50", "1.5")]
    assert differing_tokens("# NAME A", "# NAME B") == [(1, "A", "B")]


@pytest.mark.slow
def test_committed_samples_are_the_generator_output(generated):
    committed = sorted(p.name for p in DATA_SAMPLES.iterdir())
    assert committed == sorted(p.name for p in generated.iterdir())
    for name in committed:
        found = differing_tokens((DATA_SAMPLES / name).read_text(), (generated / name).read_text())
        assert found == [], (name, found[:5])


def test_truth_json_describes_the_generator(truth):
    assert [spec_of(record) for record in truth] == list(SAMPLES)
    record = json.loads((DATA_SAMPLES / "truth.json").read_text())
    assert record["command"] == "python -m rsodb.samples --out data_samples --seed 1" and record["seed"] == 1
    assert "F + 1000" in record["noise"]


def test_samples_are_small_and_cover_the_formats(truth):
    total = sum(p.stat().st_size for p in DATA_SAMPLES.iterdir())
    assert total < 1.0e6
    kinds = {(r["file_format"], r["variant"]) for r in truth}
    assert {("ccd_phot", "ut"), ("ccd_phot", "jd"), ("phc", "")} <= kinds
    assert {r["norad"] for r in truth} == {22076, 40358}
    assert "| **9.86** |" in (DATA_SAMPLES / "README.md").read_text()


def test_passes_are_sunlit_high_and_long_enough_for_a_period_search(truth):
    for record in truth:
        for p in passes_of(DATA_SAMPLES, record):
            # The pass search keeps the satellite above 20 deg (refracted) while the Sun is below -6 deg.
            assert p.el_deg.min() > 20.0, record["file"]
            cycles = p.duration_s / record["truth"]["spin_period_s"]
            # A period search needs several cycles; the main job needs few samples.
            assert 6 <= cycles <= 20 and 200 <= len(p) <= 1000, (record["file"], cycles, len(p))
            # Rendered, not blank: the noiseless curve varies by magnitudes, not hundredths.
            assert record["model_mag_max"] - record["model_mag_min"] > 1.0, record["file"]


def test_every_sample_reads_as_recorded(truth):
    for record in truth:
        passes = passes_of(DATA_SAMPLES, record)
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


def test_reduction_constants_and_sign_are_recovered(truth):
    # The reader fits A and k jointly from magnitudes rounded to 0.001 mag. Over a pass that spans
    # little airmass they trade off (dA = -dk X): each comes back within 2e-3, and the law at the
    # pass's mean airmass within 3e-4 (the rounding's 3e-4 rms, averaged over hundreds of rows).
    from ingest.reduction import airmass

    for record in truth:
        passes = passes_of(DATA_SAMPLES, record)
        laws = (
            [
                (record["zero_point_b_mag"], record["extinction_b_mag"]),
                (record["zero_point_mag"], record["extinction_mag"]),
            ]
            if record["file_format"] == "phc"
            else [(record["zero_point_mag"], record["extinction_mag"])]
        )
        wrong_sign = record["extinction_sign_in_file"].startswith("+")
        for p, (zero_point, k) in zip(passes, laws):
            signed_k = k if wrong_sign else -k
            assert p.reduction.zero_point_mag == pytest.approx(zero_point, abs=2e-3)
            assert p.reduction.extinction_term_mag == pytest.approx(signed_k, abs=2e-3)
            x_mean = airmass(p.el_deg).mean()
            assert p.reduction.zero_point_mag + p.reduction.extinction_term_mag * x_mean == pytest.approx(
                zero_point + signed_k * x_mean, abs=3e-4
            )
            assert p.reduction.sign_error is wrong_sign


@pytest.mark.slow
def test_magnitudes_scatter_about_the_rendered_curve_as_their_errors_say(generated, truth):
    # Renders every truth again (the caches are shared with the `generated` fixture in this process).
    for record in truth:
        spec = spec_of(record)
        passes = passes_of(DATA_SAMPLES, record)
        site = UZHHOROD if spec.file_format == "phc" else DERENIVKA
        models = render_mag(spec, passes[0].time_utc, site, tuple(p.band for p in passes))
        for p in passes:
            usable = p.valid & ~p.saturated
            chi2 = ((p.best_mag - models[p.band]) / p.mag_err)[usable] ** 2
            # chi^2 per point is 1 +- sqrt(2/n) (<= 0.1 for n >= 200): 3 sigma is 0.3.
            assert abs(chi2.mean() - 1.0) < 0.3, (record["file"], p.band, chi2.mean())


def test_geometry_agrees_with_pyephem(truth):
    ephem = pytest.importorskip("ephem")
    for record in truth:
        p = passes_of(DATA_SAMPLES, record)[0]
        tle = TLES[record["norad"]]
        satellite = ephem.readtle(tle[0][2:], tle[1], tle[2])
        # The phc writer's Az/El are for Derenivka; so are the ccd_phot files'.
        observer = ephem.Observer()
        observer.lat, observer.lon, observer.elevation = "48.5635505", "22.453751", 231.1325
        for k in range(0, len(p), 37):
            observer.date = ephem.Date(str(p.time_utc[k]).replace("T", " ")[:26])
            satellite.compute(observer)
            az, el = np.radians(p.az_deg[k]), np.radians(p.el_deg[k])
            separation = np.degrees(
                np.arccos(
                    np.clip(
                        np.sin(el) * np.sin(satellite.alt)
                        + np.cos(el) * np.cos(satellite.alt) * np.cos(az - satellite.az),
                        -1,
                        1,
                    )
                )
            )
            # PyEphem's and skyfield's SGP4 and Earth rotation agree to ~0.005 deg and 50 m here.
            assert separation < 0.01, (record["file"], k, separation)
            assert abs(satellite.range / 1000 - p.range_km[k]) < 0.05


@pytest.mark.slow
def test_seed_changes_the_noise_not_the_geometry(tmp_path, generated, truth):
    main(["--out", str(tmp_path), "--seed", "2"])
    record = truth[0]
    (a,) = passes_of(generated, record)
    (b,) = ingest.read_file(tmp_path / record["file"])
    assert np.array_equal(a.time_utc, b.time_utc) and np.array_equal(a.el_deg, b.el_deg)
    assert not np.array_equal(a.flux, b.flux)
    # Same rendered curve, independent noise: the difference is noise of the files' own size.
    difference = (a.best_mag - b.best_mag) / np.hypot(a.mag_err, b.mag_err)
    assert 0.8 < difference.std() < 1.2
