"""Speed against accuracy of the light-curve renderers, charted against Blender Cycles.

One run renders TOPEX (the code-built model) and COSMOS 2502 (the reference paper's own mesh)
along the real TOPEX pass of 2024-07-30 from Derenivka with the paper's attitudes:

* a 30 s stretch at 5 fps (150 frames, the paper's set-up), one direction pair per frame;
* the whole 464 s pass (2320 frames).

For each it measures time per light curve and the RMS magnitude error (over frames brighter
than 1e-3 of the peak, see DARK_FRACTION) against a converged reference (the direct renderer
at the finest pixel size) for the direct renderer at several pixel sizes, the cached fast path
at several direction-grid sizes, with 2x2 edge rays and with 0.15 m visibility elements (its
one-off precomputation timed separately) and Blender Cycles at several sample counts (via
``raycast.cycles``, on a subset of the frames, its time per light curve extrapolated from its
time per frame).

Output: a speed-vs-accuracy chart (docs/img/render_speed_accuracy.png) and a table recorded by
bench/record.py (docs/benchmarks/history.jsonl, docs/benchmarks.md), with the result rows as data
for the chart. The machine is shared: wall times are under load from other
jobs; CPU times of this process are printed beside them.

Run: ``python bench/render.py`` (add ``--no-cycles`` to skip Blender, ``--quick`` for a smoke run,
``--chart-only`` to redraw the chart from the last recorded run).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import resource
import sys
import time

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.record import command, figure, latest, record, today  # noqa: E402
from raycast.geometry.attitude import PrecessingSpin  # noqa: E402
from raycast.models import topex  # noqa: E402
from raycast.renderer.brdf import GGX, Lambertian, Principled  # noqa: E402
from raycast.renderer.cache import SceneCache  # noqa: E402
from raycast.renderer.direct import DirectRenderer  # noqa: E402
from raycast.renderer.scene import Scene  # noqa: E402

SHARED = (ROOT / ".." / "shared" / "data").resolve()
TOPEX_PHV = SHARED / "observations" / "result_22076_20240730_UT212240.phV"
MODELS = SHARED / "models"
CHART = ROOT / "docs" / "img" / "render_speed_accuracy.png"

ATTITUDES = {
    "TOPEX": PrecessingSpin(period_s=9.86, precession_period_s=689.0, precession_angle_deg=35.0, spin_axis="z"),
    "COSMOS 2502": PrecessingSpin(period_s=40.5, precession_period_s=1620.0, precession_angle_deg=7.0, spin_axis="x"),
}


def scenes():
    return {
        "TOPEX": topex.build(),
        "COSMOS 2502": Scene.from_file(
            MODELS / "cosmos2502_lotos.obj", materials=MODELS / "cosmos2502_lotos.materials.json"
        ),
    }


def pass_directions(attitude, rows):
    """Body-frame (Sun, observer) unit vectors (n, 3) of the real TOPEX pass at ``rows``."""
    import ingest
    from raycast.geometry.orbit import Satellite
    from raycast.geometry.pass_geometry import PassGeometry

    observed = ingest.read_file(TOPEX_PHV)[0]
    geometry = PassGeometry.compute(
        Satellite.from_tle(observed.tle), observed.site, observed.time_utc[rows], exposure_s=0.0
    )
    body = geometry.body_frame(attitude)
    return body.sun_body[:, 0], body.obs_body[:, 0]


# Frames fainter than this fraction of the light curve's peak (7.5 mag below it) are left out of
# the magnitude error: a dark frame where one renderer finds 1e-5 m^2/sr and the other exactly 0
# would count as an infinite error, yet no observation resolves it.
DARK_FRACTION = 1e-3


def rms_mag(value, reference):
    ok = reference > DARK_FRACTION * reference.max()
    return float(np.sqrt(np.mean((2.5 * np.log10(np.maximum(value[ok], 1e-300) / reference[ok])) ** 2)))


def timed(function, repeats=1):
    """(result, median wall seconds, median CPU seconds of this process)."""
    walls, cpus, result = [], [], None
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        result = function()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return result, float(np.median(walls)), float(np.median(cpus))


def cycles_mesh(scene):
    """The scene as a raycast.cycles.CyclesMesh with the same BRDF parameters."""
    from raycast.cycles.runner import CyclesMesh

    records = []
    for brdf in scene.brdfs:
        if isinstance(brdf, Lambertian):
            records.append({"blender_node": "Diffuse BSDF", "color": [brdf.albedo] * 3})
        elif isinstance(brdf, GGX):
            records.append({"blender_node": "Glossy BSDF", "color": [brdf.color] * 3, "roughness": brdf.roughness})
        elif isinstance(brdf, Principled):
            records.append(
                {
                    "blender_node": "Principled BSDF",
                    "base_color": [brdf.base_color] * 3,
                    "metallic": brdf.metallic,
                    "roughness": brdf.roughness,
                    "specular_ior_level": brdf.specular_ior_level,
                    "ior": brdf.ior,
                }
            )
        else:
            raise TypeError(f"no Cycles node for {brdf!r}")
    mesh = scene.posed()
    vertices = mesh.vertices_m
    triangles = np.arange(len(vertices)).reshape(-1, 3)
    return CyclesMesh.from_arrays(
        vertices,
        triangles,
        records,
        material_index=mesh.material_index,
        corner_normals=mesh.corner_normals,
        material_names=scene.material_names,
    )


def bench_model(
    name, scene, rows, pixels, grid_pixels, raster_pixels, grids, cycles_samples, cycles_frames, reference_pixel
):
    """All measurements of one model on one stretch of the pass; returns result rows and the
    reference's convergence (RMS mag between it and twice its pixel size)."""
    sun, obs = pass_directions(ATTITUDES[name], rows)
    n = len(sun)
    print(f"\n{name}: {n} frames, reference pixel {reference_pixel} m", flush=True)
    reference, ref_wall, _ = timed(
        lambda: DirectRenderer(scene, reference_pixel, accuracy_mag=0.001, sampling="adaptive").intensity(sun, obs)
    )
    check = DirectRenderer(scene, 2 * reference_pixel, accuracy_mag=0.001, sampling="adaptive").intensity(sun, obs)
    converged = rms_mag(check, reference)
    print(f"  reference rendered in {ref_wall:.1f} s; twice its pixel differs by {converged:.5f} mag", flush=True)
    results, caches = [], {}
    for method, sampling, sizes in (
        ("direct", "adaptive", pixels),
        ("direct-grid", "grid", grid_pixels),
        ("direct-raster", "raster", raster_pixels),
    ):
        for pixel in sizes:
            values, wall, cpu = timed(
                lambda: DirectRenderer(scene, pixel, sampling=sampling).intensity(sun, obs), repeats=3
            )
            results.append(
                dict(
                    model=name,
                    frames=n,
                    method=method,
                    setting=f"pixel {pixel} m",
                    wall_s=wall,
                    cpu_s=cpu,
                    setup_s=0.0,
                    error_mag=rms_mag(values, reference),
                    memory_mb=0.0,
                )
            )
            print(
                f"  {method} {pixel} m: {wall:.2f} s wall, {cpu:.2f} s CPU, {results[-1]['error_mag']:.4f} mag",
                flush=True,
            )
    for grid, edge, element in grids:
        cache, build_wall, _ = timed(
            lambda: SceneCache.build(scene, grid_size=grid, edge_rays_per_side=edge, element_size_m=element)
        )
        if edge == 1 and element is None:
            caches[grid] = cache
        setting = (
            f"grid {grid}"
            + (f"+{edge}x{edge}-edge-rays" if edge > 1 else "")
            + (f"+elements-{element}-m" if element else "")
        )
        values, wall, cpu = timed(lambda: cache.intensity(sun, obs), repeats=5)
        results.append(
            dict(
                model=name,
                frames=n,
                method="cached",
                setting=setting,
                wall_s=wall,
                cpu_s=cpu,
                setup_s=build_wall,
                error_mag=rms_mag(values, reference),
                memory_mb=cache.nbytes / 1e6,
            )
        )
        print(
            f"  cached {setting}: build {build_wall:.1f} s, {1e3 * wall:.1f} ms wall, {1e3 * cpu:.1f} ms CPU, "
            f"{results[-1]['error_mag']:.4f} mag, {cache.nbytes / 1e6:.0f} MB",
            flush=True,
        )
    if cycles_samples:
        from raycast.cycles.runner import CyclesSettings, render_cycles

        subset = np.linspace(0, n - 1, cycles_frames).astype(int)
        mesh = cycles_mesh(scene)
        for samples in cycles_samples:
            result = render_cycles(mesh, sun[subset], obs[subset], CyclesSettings(samples=samples), progress=False)
            per_frame = result.seconds_per_frame
            results.append(
                dict(
                    model=name,
                    frames=n,
                    method="cycles",
                    setting=f"{samples} samples",
                    wall_s=per_frame * n,
                    cpu_s=result.cpu_seconds_per_frame * n,
                    setup_s=result.seconds_setup,
                    error_mag=rms_mag(result.intensity_m2_sr, reference[subset]),
                    memory_mb=0.0,
                )
            )
            print(
                f"  cycles {samples} samples: {per_frame:.2f} s/frame -> {per_frame * n:.0f} s per light curve, "
                f"{results[-1]['error_mag']:.4f} mag on {cycles_frames} frames",
                flush=True,
            )
    return results, caches, converged


def chart(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = sorted({r["model"] for r in results if r["frames"] == 150})
    fig, axes = plt.subplots(1, len(models), figsize=(6 * len(models), 5.4), squeeze=False)
    styles = {
        "direct": ("o-", "C0", "direct ray casting, adaptive (pixel sizes)"),
        "direct-grid": ("o:", "C7", "direct ray casting, regular grid (pixel sizes)"),
        "direct-raster": ("D-", "C1", "direct, regular grid scan-converted + shadow rays (pixel sizes)"),
        "cached": ("s-", "C2", "cached fast path (grid sizes)"),
        "cycles": ("^-", "C3", "Blender Cycles CPU (samples)"),
    }
    for ax, model in zip(axes[0], models):
        for method, (marker, color, label) in styles.items():
            rows = sorted(
                (r for r in results if r["model"] == model and r["method"] == method and r["frames"] == 150),
                key=lambda r: r["cpu_s"],
            )
            if not rows:
                continue
            ax.loglog(
                [r["cpu_s"] for r in rows], [max(r["error_mag"], 1e-4) for r in rows], marker, color=color, label=label
            )
            for r in rows:
                ax.annotate(
                    r["setting"].split(" ")[1] if method != "cycles" else r["setting"].split(" ")[0],
                    (r["cpu_s"], max(r["error_mag"], 1e-4)),
                    textcoords="offset points",
                    xytext=(4, 4),
                    fontsize=7,
                    color=color,
                )
        ax.axvline(0.02, color="C2", lw=0.8, ls=":")
        ax.axhline(0.01, color="C2", lw=0.8, ls=":", label="fast-path target (20 ms, 0.01 mag)")
        ax.axvline(1.0, color="C0", lw=0.8, ls="--")
        ax.axhline(0.005, color="C0", lw=0.8, ls="--", label="direct target (1 s, 0.005 mag)")
        ax.set_xlabel("CPU time per 150-frame light curve [s] (shared 2-core machine)")
        ax.set_ylabel("RMS error vs converged reference [mag]")
        ax.set_title(f"{model}: real TOPEX pass 2024-07-30, 30 s at 5 fps")
        ax.grid(True, which="both", alpha=0.3)
    # One legend below the panels: inside them it hid points (COSMOS 2502's Cycles, 0.65 mag off).
    labels = {}
    for ax in axes[0]:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            labels.setdefault(label, handle)
    fig.legend(labels.values(), labels.keys(), loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0.0, 0.1, 1.0, 1.0))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    print(f"chart written to {path}")


# (method, accuracy target in mag, time target per 150-frame light curve in s), from the renderer's
# specification: the fast path <= 20 ms at <= 0.01 mag, the direct renderer <= 1 s at <= 0.005 mag,
# both at least 100x faster than Cycles at equal accuracy.
TARGETS = (("cached", 0.01, 0.02), ("direct", 0.005, 1.0))
# Monte Carlo error falls as samples**-1/2, so time grows as error**-2 beyond Cycles' measured range.
CYCLES_TIME_ERROR_SLOPE = -2.0


def time_at_error(rows, error_mag, key="cpu_s"):
    """Time a method needs to reach ``error_mag``, interpolated log-log on its measured curve.

    Returns (seconds, how): "interpolated" inside the measured errors, "extrapolated" along
    error**-2 (Monte Carlo) beyond the least accurate setting, None when the method never got as
    accurate as that (returned with the time of its most accurate setting, a lower bound).
    """
    points = sorted((r["error_mag"], r[key]) for r in rows if np.isfinite(r[key]) and r["error_mag"] > 0.0)
    errors = np.array([p[0] for p in points])
    times = np.array([p[1] for p in points])
    # The cheapest setting with at most each error (a more accurate setting also meets a looser
    # error), interpolated between the measured errors.
    envelope = np.minimum.accumulate(times)
    if error_mag < errors[0]:
        return float(times[0]), None
    if error_mag > errors[-1]:
        return float(envelope[-1] * (error_mag / errors[-1]) ** CYCLES_TIME_ERROR_SLOPE), "extrapolated"
    return float(np.exp(np.interp(np.log(error_mag), np.log(errors), np.log(envelope)))), "interpolated"


def headline(rows, method, target_mag):
    """(best, met, cycles_s, how): ``method``'s cheapest setting (CPU) within ``target_mag`` (met) or its
    most accurate one (not met), and, when met and Cycles ran, Cycles' CPU time at the same error and
    how it was found (see :func:`time_at_error`)."""
    # "direct" covers all of its samplings ("direct" adaptive, "direct-grid", "direct-raster").
    mine = [r for r in rows if r["method"].split("-")[0] == method]
    cycles = [r for r in rows if r["method"] == "cycles"]
    met = [r for r in mine if r["error_mag"] <= target_mag]
    if not met:
        return min(mine, key=lambda r: r["error_mag"]), False, None, None
    best = min(met, key=lambda r: r["cpu_s"])
    cycles_s, how = time_at_error(cycles, best["error_mag"]) if cycles else (None, None)
    return best, True, cycles_s, how


def verdict(rows, method, target_mag, target_s):
    """One sentence: does ``method`` meet its target, and how much faster than Cycles at equal accuracy."""
    best, met, cycles_s, how = headline(rows, method, target_mag)
    if not met:
        return (
            f"{method} MISSES {target_mag} mag at every setting (best {best['error_mag']:.4f} mag at "
            f"{best['cpu_s']:.3f} s CPU)"
        )
    text = (
        f"{best['method']} {best['setting']}: {best['error_mag']:.4f} mag in {1e3 * best['cpu_s']:.1f} ms CPU "
        f"({1e3 * best['wall_s']:.1f} ms wall; {'meets' if best['cpu_s'] <= target_s else 'MISSES'} "
        f"{target_s:g} s at {target_mag} mag)"
    )
    if cycles_s is not None:
        ratio = cycles_s / best["cpu_s"]
        if how is None:
            cycles_best = min(r["error_mag"] for r in rows if r["method"] == "cycles")
            text += f", Cycles never reached {best['error_mag']:.4f} mag (best {cycles_best:.4f}): > {ratio:.0f}x"
        else:
            text += f", Cycles at equal accuracy ({how}) {cycles_s:.1f} s CPU: {ratio:.0f}x"
            text += " (meets 100x)" if ratio >= 100 else " (MISSES 100x)"
    return text


def headline_figures(results):
    """The recorded figures: per model, the fast path and the direct renderer at their targets."""
    figures = []
    for model in dict.fromkeys(r["model"] for r in results):
        rows = [r for r in results if r["model"] == model and r["frames"] == 150]
        for method, target_mag, target_s in TARGETS:
            best, met, cycles_s, how = headline(rows, method, target_mag)
            time_text = f"{1e3 * best['cpu_s']:.1f} ms CPU"
            if met:
                value = f"{time_text} at {best['error_mag']:.4f} mag ({best['method']} {best['setting']})"
                if cycles_s is not None:
                    ratio = cycles_s / best["cpu_s"]
                    value += f", {ratio:.0f}x Cycles" if how else f", > {ratio:.0f}x Cycles (never as accurate)"
            else:
                value = f"MISSES {target_mag} mag: best {best['error_mag']:.4f} mag in {time_text}"
            limit = f"{1e3 * target_s:g} ms" if target_s < 1 else f"{target_s:g} s"
            name = "fast path" if method == "cached" else "direct renderer"
            figures.append(figure(f"{model} {name}", value, f"<= {limit} CPU at <= {target_mag} mag; >= 100x Cycles"))
    return figures


def table(results, load, peak_mb, convergence):
    """The run's markdown section."""
    lines = [
        f"## Renderer speed vs accuracy ({today()}, bench/render.py)\n",
        f"Real TOPEX pass 2024-07-30 (Derenivka), paper attitudes; one direction pair per frame. "
        f"Shared 2-core machine, load average {load:.1f} at the start: wall times are inflated by other "
        f"jobs, CPU times are this process's. Errors are RMS magnitudes against a converged reference (the "
        f"adaptive direct renderer at 4 mm, smooth tolerance 0.001 mag; at 8 mm it differs by "
        + ", ".join(f"{v:.5f} mag on {k}" for k, v in convergence.items())
        + f'), over frames brighter than {DARK_FRACTION:g} of the peak; "direct" is the adaptive sampling, '
        f'"direct-grid" the regular grid, "direct-raster" the same grid with its first hits found by scan '
        f"conversion (shadow rays only where another part can shade); Cycles times are per "
        f"frame on a subset times the frame count (CPU summed over Blender's threads). Speed ratios are "
        f"taken at equal accuracy on CPU time: Cycles' time to reach each method's error, interpolated "
        f"log-log on its curve (extrapolated as error**-2 beyond its least accurate setting). "
        f"Peak RSS {peak_mb:.0f} MB.\n",
        "| model | frames | method | setting | wall per LC | CPU per LC | one-off setup | RMS error (mag) | memory |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        cpu = "-" if not np.isfinite(r["cpu_s"]) else f"{r['cpu_s']:.4f} s"
        memory = f"{r['memory_mb']:.0f} MB" if r["memory_mb"] else "-"
        lines.append(
            f"| {r['model']} | {r['frames']} | {r['method']} | {r['setting']} | {r['wall_s']:.4f} s | {cpu} "
            f"| {r['setup_s']:.1f} s | {r['error_mag']:.4f} | {memory} |"
        )
    verdicts = []
    for model in sorted({r["model"] for r in results}):
        rows = [r for r in results if r["model"] == model and r["frames"] == 150]
        verdicts.append(
            f"- {model}: "
            + "; ".join(verdict(rows, method, target_mag, target_s) for method, target_mag, target_s in TARGETS)
        )
    lines += ["", *verdicts]
    return "\n".join(lines) + "\n"


def recorded_results():
    """The rows of the last recorded run (its history data), as :func:`bench_model` gives them."""
    run = latest("render")
    if run is None or not run.get("data"):
        raise SystemExit("the benchmark history holds no renderer run; run bench/render.py first")
    # The history keeps missing numbers (no CPU time) as null.
    return [{k: float("nan") if v is None else v for k, v in row.items()} for row in run["data"]]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--no-cycles", action="store_true", help="skip Blender Cycles")
    parser.add_argument("--quick", action="store_true", help="fewer settings (smoke run); writes nothing")
    parser.add_argument(
        "--chart-only",
        action="store_true",
        help="redraw the chart from the last recorded run (docs/benchmarks/history.jsonl); renders nothing",
    )
    args = parser.parse_args(argv)
    if args.chart_only:
        chart(recorded_results(), CHART)
        return 0
    load = os.getloadavg()[0]
    short = np.arange(150)  # 30 s at 5 fps
    long = np.arange(2320)  # the whole 464 s pass
    quick = args.quick
    results, convergence = [], {}
    for name, scene in scenes().items():
        rows, caches, converged = bench_model(
            name,
            scene,
            short,
            pixels=(0.1,) if quick else (0.12, 0.06, 0.03, 0.015),
            grid_pixels=(0.1,) if quick else (0.06, 0.045, 0.03),
            raster_pixels=(0.1,) if quick else (0.06, 0.045, 0.03, 0.02),
            grids=((16, 1, None),)
            if quick
            else ((16, 1, None), (32, 1, None), (48, 1, None), (32, 2, None), (32, 1, 0.15)),
            cycles_samples=() if args.no_cycles else ((4,) if quick else (4, 16, 64)),
            cycles_frames=3 if quick else 8,
            reference_pixel=0.05 if quick else 0.004,
        )
        results += rows
        convergence[name] = converged
        if not quick:
            # The long pass: every 10th frame against the reference (rendering all 2320 at the
            # reference resolution would take most of the run); times are for all 2320 frames.
            subset = long[::10]
            sun, obs = pass_directions(ATTITUDES[name], long)
            reference = DirectRenderer(scene, 0.004, accuracy_mag=0.001, sampling="adaptive").intensity(
                sun[subset], obs[subset]
            )
            cache = caches[32]
            build = cache.precompute_s
            values, wall, cpu = timed(lambda: cache.intensity(sun, obs), repeats=3)
            results.append(
                dict(
                    model=name,
                    frames=len(long),
                    method="cached",
                    setting="grid 32",
                    wall_s=wall,
                    cpu_s=cpu,
                    setup_s=build,
                    error_mag=rms_mag(values[subset], reference),
                    memory_mb=cache.nbytes / 1e6,
                )
            )
            for method, sampling in (("direct", "adaptive"), ("direct-raster", "raster")):
                values, wall, cpu = timed(lambda: DirectRenderer(scene, 0.03, sampling=sampling).intensity(sun, obs))
                results.append(
                    dict(
                        model=name,
                        frames=len(long),
                        method=method,
                        setting="pixel 0.03 m",
                        wall_s=wall,
                        cpu_s=cpu,
                        setup_s=0.0,
                        error_mag=rms_mag(values[subset], reference),
                        memory_mb=0.0,
                    )
                )
            print(
                f"  long pass: cached {results[-3]['wall_s']:.2f} s / direct {results[-2]['wall_s']:.1f} s / "
                f"direct-raster {results[-1]['wall_s']:.1f} s",
                flush=True,
            )
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    if quick:
        for r in results:
            print(r)
        return 0
    chart(results, CHART)
    section = table(results, load, peak_mb, convergence)
    print(section)
    record("render", command("render.py", argv), headline_figures(results), section, data=results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
