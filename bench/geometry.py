"""Benchmark: pass geometry for 10^4 epochs, and the body-frame step a fit runs per MCMC step.

Measures, after the TLE is loaded and the ephemeris is warm (median of repeats):

* ``PassGeometry.compute`` for 10^4 epochs 0.1 s apart (target: at most 50 ms), without and
  with exposure sub-samples (0.2 s exposure, k = 4);
* the peers in the same run: skyfield with vectorised Time arrays (satellite GCRS, topocentric
  Alt/Az/range, apparent Sun) and plain per-epoch skyfield calls (timed on 200 epochs, scaled);
* ``geometry.body_frame(model)`` for 150 times x 4 sub-samples, model construction included,
  for each attitude model (the torque-free one on first use and from its cache);
* the largest difference from skyfield evaluated at every epoch (the cost of interpolating the
  slow frame terms), and the peak memory of one 10^4-epoch call.

Run ``python bench/geometry.py`` (``--repeats N``, ``--no-record`` to print only, without recording
the run through bench/record.py in docs/benchmarks/history.jsonl and docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import platform
import statistics
import sys
import time
import tracemalloc

import numpy as np

# The project's root first: run as a script, bench/ leads sys.path, where "ingest" would name
# bench/ingest.py rather than the project's package.
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.record import command, figure, record, today  # noqa: E402
from ingest.site import DERENIVKA  # noqa: E402
from raycast.geometry import ephemeris  # noqa: E402
from raycast.geometry.attitude import InertialSpin, PrecessingSpin, TorqueFree  # noqa: E402
from raycast.geometry.orbit import Satellite  # noqa: E402
from raycast.geometry.pass_geometry import PassGeometry  # noqa: E402

TOPEX_TLE = (
    "0 TOPEX/POSEIDON",
    "1 22076U 92052A   24212.51246405 -.00000054  00000-0  29042-4 0  9994",
    "2 22076  66.0414 118.8147 0008045 267.5347 265.0431 12.81066660495523",
)
START = np.datetime64("2024-07-30T21:22:40.008849", "ns")
N_EPOCHS = 10_000
TARGET_MS = 50.0


def median_ms(function, repeats: int) -> tuple[float, float, float]:
    """Median wall, median CPU (this process) and minimum wall time of `function()` in ms,
    after one warm-up call."""
    function()
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        function()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return 1e3 * statistics.median(wall), 1e3 * statistics.median(cpu), 1e3 * min(wall)


def skyfield_vectorised(satellite, times):
    """The peer: skyfield on a Time array (GCRS, Alt/Az/range, apparent Sun)."""
    from skyfield.api import wgs84

    ts = ephemeris.timescale()
    planets = ephemeris.planets()
    day = times[0].astype("datetime64[D]")
    t = ts.utc(*map(int, str(day).split("-")), 0, 0, (times - day) / np.timedelta64(1, "s"))
    earth_satellite = satellite.to_skyfield()
    topocentre = wgs84.latlon(DERENIVKA.lat_deg, DERENIVKA.lon_deg, DERENIVKA.elevation_m)
    gcrs = earth_satellite.at(t).position.km
    alt, az, distance = (earth_satellite - topocentre).at(t).altaz()
    sun = planets["earth"].at(t).observe(planets["sun"]).apparent().position.km
    return gcrs, alt.degrees, az.degrees, distance.km, sun


def interpolation_error(satellite, times, geometry):
    """Largest differences from skyfield evaluated at every epoch."""
    gcrs, alt, az, distance, sun = skyfield_vectorised(satellite, times)
    to_sun = sun.T - gcrs.T
    to_sun /= np.linalg.norm(to_sun, axis=1)[:, None]
    return {
        "position_mm": 1e6 * np.abs(geometry.sat_gcrs_km - gcrs.T).max(),
        "elevation_deg": np.abs(geometry.el_deg - alt).max(),
        "range_mm": 1e6 * np.abs(geometry.range_km - distance).max(),
        "sun_direction_rad": np.linalg.norm(geometry.sun_gcrs[:, 0] - to_sun, axis=1).max(),
    }


def run(repeats: int) -> dict:
    satellite = Satellite.from_tle(TOPEX_TLE)
    times = START + (np.arange(N_EPOCHS) * 100_000_000).astype("timedelta64[ns]")
    results = {}
    results["geometry_ms"] = median_ms(lambda: PassGeometry.compute(satellite, DERENIVKA, times), repeats)
    results["geometry_k4_ms"] = median_ms(
        lambda: PassGeometry.compute(satellite, DERENIVKA, times, exposure_s=0.2), repeats
    )
    results["skyfield_vectorised_ms"] = median_ms(lambda: skyfield_vectorised(satellite, times), max(3, repeats // 3))

    from skyfield.api import wgs84

    ts, planets = ephemeris.timescale(), ephemeris.planets()
    earth_satellite = satellite.to_skyfield()
    topocentre = wgs84.latlon(DERENIVKA.lat_deg, DERENIVKA.lon_deg, DERENIVKA.elevation_m)
    few = [ts.utc(2024, 7, 30, 21, 22, 40.0 + 0.1 * i) for i in range(200)]

    def per_epoch():
        for t in few:
            earth_satellite.at(t)
            (earth_satellite - topocentre).at(t).altaz()
            planets["earth"].at(t).observe(planets["sun"]).apparent()

    results["skyfield_per_epoch_ms"] = tuple(x * N_EPOCHS / len(few) for x in median_ms(per_epoch, 3))

    geometry = PassGeometry.compute(satellite, DERENIVKA, times)
    results["error"] = interpolation_error(satellite, times, geometry)
    tracemalloc.start()
    PassGeometry.compute(satellite, DERENIVKA, times, exposure_s=0.2)
    results["peak_memory_mb"] = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()

    fit_pass = PassGeometry.compute(satellite, DERENIVKA, times[: 150 * 2 : 2], exposure_s=0.2)
    assert fit_pass.sun_gcrs.shape == (150, 4, 3)
    counter = iter(range(10**6))
    cached = TorqueFree.from_angular_momentum((1200.0, 2000.0, 2600.0), (0.3, 0.02, 0.4), 40.0, 30.0)
    cases = {
        "PrecessingSpin": (
            lambda: fit_pass.body_frame(
                PrecessingSpin(
                    period_s=9.86,
                    phase_deg=12.0,
                    precession_period_s=689.0,
                    precession_phase_deg=40.0,
                    precession_angle_deg=35.0,
                )
            ),
            20 * repeats,
        ),
        "InertialSpin": (
            lambda: fit_pass.body_frame(
                InertialSpin(pole_ra_deg=40.0, pole_dec_deg=30.0, period_s=9.86, phase_deg=12.0)
            ),
            20 * repeats,
        ),
        "TorqueFree (first use: integrates 300 s)": (
            lambda: fit_pass.body_frame(
                TorqueFree.from_angular_momentum(
                    (1200.0, 2000.0, 2600.0), (0.3, 0.02, 0.4 + 1e-9 * next(counter)), 40.0, 30.0
                )
            ),
            max(3, repeats // 3),
        ),
        "TorqueFree (cached)": (lambda: fit_pass.body_frame(cached), 20 * repeats),
    }
    results["body_frame_us"] = {
        name: tuple(1e3 * x for x in median_ms(function, n)) for name, (function, n) in cases.items()
    }
    return results


def row(label: str, times_ms: tuple[float, float, float], note: str) -> str:
    return f"| {label} | {times_ms[0]:.1f} | {times_ms[1]:.1f} | {times_ms[2]:.1f} | {note} |"


def report(results: dict) -> str:
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    error = results["error"]
    lines = [
        f"## Pass geometry ({today()}, bench/geometry.py)",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}; load average {load} at the end of the run. The machine (a VM) is "
        "shared with other work, so wall and even CPU times grow with load; the minimum wall time is "
        "the closest to an idle machine.",
        "",
        f"| {N_EPOCHS} epochs, TOPEX over Derenivka | median wall ms | median CPU ms | min wall ms | ratio (CPU) |",
        "|---|---|---|---|---|",
        row(
            "PassGeometry.compute, no exposure sub-samples",
            results["geometry_ms"],
            f"target {TARGET_MS:.0f} ms wall: {'met' if results['geometry_ms'][0] <= TARGET_MS else 'MISSED'}",
        ),
        row("PassGeometry.compute, 0.2 s exposure, k = 4 (5 x 10^4 epochs)", results["geometry_k4_ms"], ""),
        row(
            "skyfield, vectorised Time arrays (GCRS, Alt/Az/range, apparent Sun)",
            results["skyfield_vectorised_ms"],
            f"{results['skyfield_vectorised_ms'][1] / results['geometry_ms'][1]:.0f}x slower",
        ),
        row(
            "skyfield, one call per epoch (200 timed, scaled)",
            results["skyfield_per_epoch_ms"],
            f"{results['skyfield_per_epoch_ms'][1] / results['geometry_ms'][1]:.0f}x slower",
        ),
        "",
        f"Largest difference from skyfield at every epoch (interpolation of the slow frame terms): "
        f"position {error['position_mm']:.2g} mm, elevation {error['elevation_deg']:.2g} deg, "
        f"range {error['range_mm']:.2g} mm, Sun direction {error['sun_direction_rad']:.2g} rad. "
        f"Peak memory of one 10^4-epoch call with k = 4: {results['peak_memory_mb']:.0f} MB.",
        "",
        "| body_frame, 150 times x 4 sub-samples, model built each call | median wall us | median CPU us | min wall us |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {name} | {wall:.0f} | {cpu:.0f} | {least:.0f} |"
        for name, (wall, cpu, least) in results["body_frame_us"].items()
    ]
    return "\n".join(lines) + "\n"


def headline_figures(results: dict) -> list[dict]:
    wall, cpu, _ = results["geometry_ms"]
    return [
        figure(
            f"PassGeometry.compute, {N_EPOCHS} epochs",
            f"{wall:.1f} ms wall ({cpu:.1f} ms CPU)",
            f"<= {TARGET_MS:.0f} ms wall",
        ),
        figure("skyfield, vectorised, same epochs", f"{results['skyfield_vectorised_ms'][1] / cpu:.0f}x the CPU time"),
        figure(
            "body_frame, PrecessingSpin, 150 times x 4", f"{results['body_frame_us']['PrecessingSpin'][0]:.0f} µs wall"
        ),
        figure("largest difference from skyfield", f"{results['error']['position_mm']:.2g} mm in position"),
    ]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], epilog="example: python bench/geometry.py --repeats 21"
    )
    parser.add_argument("--repeats", type=int, default=15, help="timed repeats per figure (median taken)")
    parser.add_argument("--no-record", action="store_true", help="print only; record nothing")
    args = parser.parse_args(argv)
    results = run(args.repeats)
    text = report(results)
    print(text)
    if not args.no_record:
        record("geometry", command("geometry.py", argv), headline_figures(results), text, data=results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
