"""The raster's slivers: what sampling them on their own surface costs and gains.

A flat triangle under 8 pixels of projected area but not of its own, seen with at most
``raycast.renderer.direct.SLIVER_COSINE`` of its area projected, is a sliver: the raster samples
it at 9 points of its surface with rays toward the observer and the Sun instead of counting its
pixels (docs/renderer.md, "raster"). This runs the raster with that fraction at 0 (no slivers:
every small triangle counts its pixels), at the default and at 1 (every small triangle of 8
pixels of its own) on

* TOPEX along the real pass of 2024-07-30 (150 frames, the paper's attitudes, as bench/render.py),
  against the adaptive direct renderer at 4 mm: a mesh of large boxes whose dim frames are lit
  by faces seen nearly edge-on;
* a flat-shaded icosphere of 20 480 faces (radius 1 m; 150 random direction pairs), against the
  ray grid at radius / 300: a finely cut surface, where sampling every small triangle would cost
  18 rays a face.

Prints and records (docs/benchmarks.md) the CPU time per 150-frame light curve (median of 3 after
a warm-up, this process) and the RMS error in magnitudes.

    python bench/raster_slivers.py
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
import sys

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench.record import command, figure, record, timed, today  # noqa: E402

COSINES = (0.0, None, 1.0)  # None: the default


def flat_sphere():
    """A Scene of one flat-shaded icosphere of 20 480 faces, radius 1 m, Lambertian 0.4."""
    from raycast.renderer.brdf import Lambertian
    from raycast.renderer.scene import Part, Scene

    sphere = Part.sphere("sphere", 1.0, "paint", subdivisions=5)
    corners = sphere.corners_m
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    flat = replace(sphere, corner_normals=np.repeat(normals[:, None], 3, axis=1))
    return Scene.from_parts([flat], {"paint": Lambertian(0.4)})


def cases():
    """(name, scene, sun, obs, reference, pixel sizes in m) of the two scenes."""
    from bench.render import ATTITUDES, pass_directions, scenes
    from raycast.renderer.direct import DirectRenderer

    topex = scenes()["TOPEX"]
    sun, obs = pass_directions(ATTITUDES["TOPEX"], np.arange(150))
    reference = DirectRenderer(topex, 0.004, accuracy_mag=0.001, sampling="adaptive").intensity(sun, obs)
    yield "TOPEX, real pass", topex, sun, obs, reference, (0.06, 0.045, 0.03)
    sphere = flat_sphere()
    rng = np.random.default_rng(1)
    sun, obs = (d / np.linalg.norm(d, axis=1, keepdims=True) for d in rng.normal(size=(2, 150, 3)))
    reference = DirectRenderer(sphere, 1.0 / 300.0, sampling="grid").intensity(sun, obs)
    yield "flat icosphere, 20 480 faces", sphere, sun, obs, reference, (1.0 / 75.0, 1.0 / 150.0)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-record", action="store_true", help="print only")
    args = parser.parse_args(argv)
    from bench.render import rms_mag
    from raycast.renderer import _direct_kernels, direct
    from raycast.renderer.direct import DirectRenderer

    default = direct.SLIVER_COSINE
    slivers = []
    finder = _direct_kernels.raster_hits

    def counting(*arguments):
        found = finder(*arguments)
        slivers.append(len(found[5]))
        return found

    rows = []
    _direct_kernels.raster_hits = counting
    try:
        for name, scene, sun, obs, reference, pixels in cases():
            for pixel_m in pixels:
                for cosine in COSINES:
                    direct.SLIVER_COSINE = default if cosine is None else cosine
                    renderer = DirectRenderer(scene, pixel_m, sampling="raster")
                    renderer.intensity(sun, obs)  # warm: compiled loops, the scene's set-up
                    slivers.clear()
                    values, _, cpu_s = timed(lambda: renderer.intensity(sun, obs), 3)
                    row = {
                        "scene": name,
                        "pixel_m": pixel_m,
                        "sliver_cosine": direct.SLIVER_COSINE,
                        "default": cosine is None,
                        "slivers_per_frame": sum(slivers) / 3 / len(sun),
                        "cpu_s": cpu_s,
                        "rms_mag": rms_mag(values, reference),
                    }
                    rows.append(row)
                    print(
                        f"{name}, pixel {100 * pixel_m:.2f} cm, sliver cosine {row['sliver_cosine']:g}"
                        f"{' (default)' if row['default'] else ''}: {row['slivers_per_frame']:.1f} slivers a frame, "
                        f"{cpu_s:.3f} s CPU, {row['rms_mag']:.4f} mag",
                        flush=True,
                    )
    finally:
        direct.SLIVER_COSINE = default
        _direct_kernels.raster_hits = finder
    if args.no_record:
        return 0
    lines = [
        f"| {r['scene']} | {100 * r['pixel_m']:.2f} cm | {r['sliver_cosine']:g}{' (default)' if r['default'] else ''} | "
        f"{r['slivers_per_frame']:.1f} | {r['cpu_s']:.3f} | {r['rms_mag']:.4f} |"
        for r in rows
    ]
    section = (
        f"""
## The raster's slivers ({today()}, bench/raster_slivers.py)

The raster (`DirectRenderer(..., sampling="raster")`) with flat slivers sampled on their own surface, by the
fraction of a triangle's own area seen under which a triangle of 8 pixels of its own is a sliver: 0 (none:
small triangles count their pixels), the default {default:g}, 1 (every small triangle of 8 pixels of its own).
TOPEX along the real pass against the adaptive renderer at 4 mm; a flat-shaded icosphere of 20 480 faces,
150 random direction pairs, against the ray grid at radius / 300. CPU per 150-frame light curve, median of 3.

| scene | pixel | sliver cosine | slivers a frame | CPU (s) | RMS (mag) |
|---|---|---|---|---|---|
"""
        + "\n".join(lines)
        + "\n"
    )
    by_case = {(r["scene"], r["pixel_m"], r["sliver_cosine"]): r for r in rows}
    figures = []
    for scene, pixel_m in (("TOPEX, real pass", 0.06), ("flat icosphere, 20 480 faces", 1.0 / 150.0)):
        on, off = by_case[scene, pixel_m, default], by_case[scene, pixel_m, 0.0]
        figures.append(
            figure(
                f"{scene}, {100 * pixel_m:.2f} cm",
                f"{on['rms_mag']:.4f} mag in {on['cpu_s']:.3f} s CPU with slivers, "
                f"{off['rms_mag']:.4f} in {off['cpu_s']:.3f} s without",
            )
        )
    record("raster_slivers", command("raster_slivers.py", argv), figures, section, data=rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
