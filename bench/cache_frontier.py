"""The fast path's speed against its accuracy on one comparison scene, over its build settings.

Each setting builds a `SceneCache` of the scene (raycast.cycles.comparison: the paper's COSMOS
2502 mesh with all-Glossy materials by default, the scene where the fast path is slowest) and
renders the 150-frame tumble light curve with it: the wall time per light curve (median of
``--repeats`` runs after two warm-ups, all the process's threads) and the CPU time, against the
direct renderer at pixels of the mesh radius / 300 on the same 150 frames (RMS and largest
difference in magnitudes, frames where the direct renderer's scene is dark left out as in
bench/render.py). The chart puts every setting on the plane of time and error, with the
issue's target (<= 20 ms, <= 0.01 mag) as a box.

    python bench/cache_frontier.py                              # paper_glossy, the settings below
    python bench/cache_frontier.py --scene paper --settings "default;bins=1"
    python bench/cache_frontier.py --cycles                     # and against Blender Cycles

With ``--cycles`` every setting is also compared with Blender Cycles at the comparison benchmark's
reference (bench/render.py: 256^2 pixels x 16 samples, object terminator offsets 0) on all 150
frames, the authority the targets are stated against; the chart and the targets then use that error.

A setting is ``default`` or options joined by commas: ``bins=`` (normal_bins_per_step),
``elements=`` (element_size_m, as a fraction of the mesh radius written ``r/40`` or metres),
``step=`` (normal_step_deg), ``grid=`` (grid_size, the visibility's cube map: a finer grid leaves fewer
element-direction pairs for exact rays), ``edge=`` (edge_rays_per_side), ``tail=`` (coarse_bin_ratio, a
fraction such as ``1/3``) and ``far=`` (far_lobe_widths): how much of a glossy lobe's tail is shaded in
coarser bins and left to the visibility bits' interpolation.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import sys

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench.record import HISTORY, command, figure, latest, record, timed, today  # noqa: E402
from bench.render import MODELS, REFERENCE_CYCLES  # noqa: E402

CHART = ROOT / "docs" / "img" / "cache_frontier.png"
SETTINGS = (
    "default;bins=1;bins=1,tail=1/3,far=2;elements=r/40,bins=1;elements=r/50,bins=1;elements=r/30,bins=1;elements=r/30,bins=1,edge=2;"
    "elements=r/30,bins=1,edge=2,tail=1/4,far=2;elements=r/30,bins=1,edge=2,tail=1/3,far=2;"
    "elements=r/30,bins=2;elements=r/30,bins=1,step=6"
)
TARGET_MS, TARGET_MAG = 20.0, 0.01
OPTIONS = {
    "bins": "normal_bins_per_step",
    "elements": "element_size_m",
    "step": "normal_step_deg",
    "grid": "grid_size",
    "edge": "edge_rays_per_side",
    "tail": "coarse_bin_ratio",
    "far": "far_lobe_widths",
}
# Options that count something: whole numbers.
COUNTS = ("grid", "edge")


def parse_setting(text: str, radius_m: float) -> dict:
    """``SceneCache.build`` options of one setting (module docstring); ``{}`` for ``default``."""
    text = text.strip()
    if text == "default":
        return {}
    options = {}
    for part in text.split(","):
        key, _, value = part.partition("=")
        if key not in OPTIONS or not value:
            raise SystemExit(f"--settings: {part!r} is not one of {', '.join(k + '=' for k in OPTIONS)} with a value")
        if key == "elements" and value.startswith("r/"):
            options[OPTIONS[key]] = radius_m / float(value[2:])
        elif key == "tail" and "/" in value:
            numerator, _, denominator = value.partition("/")
            options[OPTIONS[key]] = float(numerator) / float(denominator)
        elif key in COUNTS:
            if not value.isdigit() or int(value) < 1:
                raise SystemExit(f"--settings: {part!r}: {key} takes a whole number of at least 1")
            options[OPTIONS[key]] = int(value)
        else:
            options[OPTIONS[key]] = float(value)
    return options


def timed_light_curves(cache, sun, obs, repeats: int) -> tuple[np.ndarray, float, float]:
    """(intensity, median wall ms, median CPU ms) of ``repeats`` renders after two warm-ups."""
    for _ in range(2):
        cache.intensity(sun, obs)
    values, wall_s, cpu_s = timed(lambda: cache.intensity(sun, obs), repeats)
    return values, 1e3 * wall_s, 1e3 * cpu_s


def errors(values, reference) -> tuple[float, float]:
    """RMS and largest difference in magnitudes of ``values`` from ``reference``, over the frames
    the comparison counts (raycast.cycles.comparison.mag_difference: dark frames left out)."""
    from raycast.cycles.comparison import mag_difference  # with the renderer: not for --chart-only

    error = mag_difference(values, reference)
    error = error[np.isfinite(error)]
    return float(np.sqrt(np.mean(error**2))), float(np.max(np.abs(error)))


def chart(rows, scene: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure_, axis = plt.subplots(figsize=(8.4, 4.2), layout="constrained")
    axis.add_patch(plt.Rectangle((0, 0), TARGET_MS, TARGET_MAG, color="C2", alpha=0.2, label="target"))
    # Against Cycles where the run had it (--cycles), else against the direct renderer.
    key = "rms_cycles_mag" if all("rms_cycles_mag" in row for row in rows) else "rms_mag"
    # Settings crowd near the target: numbered at their points, named in the legend.
    for number, row in enumerate(rows, 1):
        axis.plot(row["wall_ms"], row[key], "o", color="C0", label=f"{number}: {row['setting']}")
        axis.annotate(str(number), (row["wall_ms"], row[key]), fontsize=8, xytext=(4, 3), textcoords="offset points")
    axis.set_xscale("log")
    axis.set_yscale("log")
    plain = matplotlib.ticker.FormatStrFormatter("%g")
    for which in (axis.xaxis, axis.yaxis):
        which.set_major_formatter(plain)
        which.set_minor_formatter(plain)
    axis.tick_params(which="minor", labelsize=7)
    axis.set_xlabel("wall time per 150-frame light curve (ms)")
    axis.set_ylabel("RMS from Cycles (mag)" if key == "rms_cycles_mag" else "RMS from the direct renderer (mag)")
    axis.set_title(f"fast path on {scene}: speed against accuracy by build setting", fontsize=9)
    axis.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), handlelength=0.8, frameon=False)
    figure_.savefig(path, dpi=110)
    plt.close(figure_)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="paper_glossy", help="a comparison scene (default paper_glossy)")
    parser.add_argument("--settings", default=SETTINGS, help=f"settings joined by ';' (default {SETTINGS!r})")
    parser.add_argument("--repeats", type=int, default=7, help="timed light curves per setting (default 7)")
    parser.add_argument("--cycles", action="store_true", help="also compare with Blender Cycles (about a minute)")
    parser.add_argument("--no-record", action="store_true", help="print only")
    parser.add_argument("--chart-only", action="store_true", help="redraw the chart from the last recorded run")
    args = parser.parse_args(argv)
    if args.chart_only:
        last = latest("cache_frontier")
        if last is None:
            raise SystemExit(f"no cache_frontier run in {HISTORY}; run the benchmark first")
        rows = last["data"]
        # The first recorded run's rows lack the scene: its section's text names it.
        scene = rows[0].get("scene") or last["section"].split("Scene `")[1].split("`")[0]
        chart(rows, scene, CHART)
        return 0
    from raycast.cycles.comparison import DARK_FRACTION, comparison_scenes, tumble_frames
    from raycast.renderer.cache import SceneCache
    from raycast.renderer.direct import DirectRenderer

    comparison = comparison_scenes(MODELS, (args.scene,))[args.scene]
    scene = comparison.scene
    radius_m = scene.posed().radius_m
    settings = [(text.strip(), parse_setting(text, radius_m)) for text in args.settings.split(";")]
    frames = tumble_frames(150)
    reference = DirectRenderer(scene, radius_m / 300.0).intensity(frames.sun_body, frames.obs_body)
    cycles = None
    if args.cycles:
        from raycast.cycles.runner import CyclesSettings, render_cycles

        resolution, samples = REFERENCE_CYCLES
        cycles = render_cycles(
            comparison.mesh,
            frames.sun_body,
            frames.obs_body,
            CyclesSettings(samples=samples, resolution=resolution, noise_passes=2),
            progress=True,
        ).intensity_m2_sr
        direct_rms, direct_max = errors(reference, cycles)
        print(f"the direct renderer at radius / 300: {direct_rms:.4f} mag RMS (max {direct_max:.4f}) from Cycles")
    rows = []
    for text, options in settings:
        cache, build_s, _ = timed(lambda: SceneCache.build(scene, **options))
        values, wall_ms, cpu_ms = timed_light_curves(cache, frames.sun_body, frames.obs_body, args.repeats)
        rms, largest = errors(values, reference)
        row = {
            "scene": args.scene,
            "setting": text,
            "options": options,
            "classes": int(cache.poses[0].n_classes),
            "elements": int(cache.n_elements),
            "build_s": build_s,
            "wall_ms": wall_ms,
            "cpu_ms": cpu_ms,
            "rms_mag": rms,
            "max_mag": largest,
        }
        from_cycles = ""
        if cycles is not None:
            row["rms_cycles_mag"], row["max_cycles_mag"] = errors(values, cycles)
            from_cycles = f", {row['rms_cycles_mag']:.4f} (max {row['max_cycles_mag']:.4f}) from Cycles"
        rows.append(row)
        print(
            f"{text}: {row['classes']} classes, {row['elements']} elements, build {build_s:.0f} s; "
            f"{wall_ms:.1f} ms wall ({cpu_ms:.1f} ms CPU) a light curve; {row['rms_mag']:.4f} mag RMS "
            f"(max {row['max_mag']:.4f}) from the direct renderer{from_cycles}",
            flush=True,
        )
    judged = "rms_cycles_mag" if cycles is not None else "rms_mag"
    meets = [r for r in rows if r["wall_ms"] <= TARGET_MS and r[judged] <= TARGET_MAG]
    print("settings meeting both targets: " + (", ".join(r["setting"] for r in meets) or "none"))
    if args.no_record:
        return 0
    chart(rows, args.scene, CHART)
    lines = [
        f"| {r['setting']} | {r['classes']} | {r['elements']} | {r['build_s']:.0f} | {r['wall_ms']:.1f} | "
        f"{r['cpu_ms']:.1f} | {r['rms_mag']:.4f} | {r['max_mag']:.4f} |"
        + (f" {r['rms_cycles_mag']:.4f} | {r['max_cycles_mag']:.4f} |" if cycles is not None else "")
        for r in rows
    ]
    columns = "| setting | shading classes | elements | build (s) | wall (ms) | CPU (ms) | RMS (mag) | max (mag) |"
    against = "the direct renderer at pixels of radius / 300"
    if cycles is not None:
        columns += " RMS from Cycles (mag) | max from Cycles (mag) |"
        against += (
            f" and Blender Cycles at {REFERENCE_CYCLES[0]}^2 pixels x {REFERENCE_CYCLES[1]} samples (bench/render.py's "
            f"reference; the direct renderer is {direct_rms:.4f} mag RMS from it; targets judged against Cycles)"
        )
    section = (
        f"""
## The fast path's speed against its accuracy ({today()}, bench/cache_frontier.py)

Scene `{args.scene}` (raycast.cycles.comparison), radius {radius_m:.2f} m; the 150-frame tumble light curve
rendered by the fast path built with each setting, against {against} on
the same frames (frames darker than {DARK_FRACTION:g} of the brightest left out, as in bench/render.py). Times: median of {args.repeats} light curves after two warm-ups, wall (all threads) and CPU.
Targets: <= {TARGET_MS:g} ms and <= {TARGET_MAG:g} mag RMS. Settings meeting both:
{", ".join(r["setting"] for r in meets) or "none"}. Load average at the end {os.getloadavg()[0]:.1f}.

{columns}
{"|---" * (columns.count(" | ") + 1)}|
"""
        + "\n".join(lines)
        + f"\n\n![fast path: speed against accuracy]({CHART.relative_to(ROOT / 'docs')})\n"
    )
    figures = [
        figure(
            f"{args.scene}, {r['setting']}",
            f"{r['wall_ms']:.1f} ms wall, {r[judged]:.4f} mag" + (" from Cycles" if cycles is not None else ""),
            f"<= {TARGET_MS:g} ms, <= {TARGET_MAG:g}",
        )
        for r in rows
    ]
    record("cache_frontier", command("cache_frontier.py", argv), figures, section, data=rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
