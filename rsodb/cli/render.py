"""``rsodb render``: the synthetic light curve of a stored pass, against the observed one."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run", "synthetic_for_pass"]

EXAMPLE = """\
example:
  rsodb render --model topex --pass 22076-20240730T212240 --archive archive \\
      --period-s 9.86 --precession-period-s 689 --precession-angle-deg 35 --plot topex_model.png
  rsodb render --model cosmos2502-paper --spin-axis x --period-s 40.5 --pass 51511 --archive archive --json
  rsodb render --model topex --pass 22076 --archive archive --frames-png frames/ --frames 4

MODEL is topex, cosmos2502 (code-built look-alike), cosmos2502-paper (the paper's mesh from
../shared/data/models) or a mesh file (OBJ, PLY, glTF; give --materials for its JSON).
The attitude is the seed paper's precessing spin; the model magnitude is reduced to 1000 km
and shifted by the median offset to the observed magnitudes (shape, not albedo, is compared).
"""

PAPER_MODEL = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "models" / "cosmos2502_lotos.obj"


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "render", help="render the synthetic light curve of a stored pass and compare it with the observed one",
        description="Render a 3D model along a stored pass (ray casting) and compare with the observations.",
        epilog=EXAMPLE, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", required=True, help="topex, cosmos2502, cosmos2502-paper or a mesh file")
    parser.add_argument("--materials", metavar="JSON", help="materials JSON for a mesh file")
    parser.add_argument("--pass", dest="pass_id", required=True, metavar="ID", help="pass id (or a unique prefix)")
    add_archive_option(parser)
    parser.add_argument("--period-s", type=float, default=10.0, help="spin period (default 10)")
    parser.add_argument("--phase-deg", type=float, default=0.0, help="spin phase at the first sample")
    parser.add_argument("--precession-period-s", type=float, default=float("inf"), help="precession period")
    parser.add_argument("--precession-angle-deg", type=float, default=0.0, help="precession cone half-angle")
    parser.add_argument("--spin-axis", choices=("x", "y", "z"), default="z", help="body axis that spins")
    parser.add_argument("--panel-pitch-deg", type=float, default=None, help="TOPEX solar-array pitch")
    parser.add_argument("--method", choices=("auto", "direct", "cached"), default="auto")
    parser.add_argument("--accuracy-mag", type=float, default=0.005, help="requested accuracy (direct)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--plot", metavar="FILE", help="save model vs observed light curve (PNG, PDF, SVG)")
    parser.add_argument("--frames-png", metavar="DIR", help="save rendered frames of the model as PNG images")
    parser.add_argument("--frames", type=int, default=4, help="how many frames --frames-png saves (default 4)")
    parser.set_defaults(func=run)


def _scene(args):
    from raycast.models import MODELS
    from raycast.scene import Scene

    name = args.model.lower()
    if name in MODELS:
        scene = MODELS[name]()
    elif name == "cosmos2502-paper":
        scene = Scene.from_file(PAPER_MODEL, materials=PAPER_MODEL.with_suffix("").with_suffix(".materials.json"))
    elif Path(args.model).is_file():
        scene = Scene.from_file(args.model, materials=args.materials)
    else:
        raise ValueError(f"model {args.model!r} is neither a known model (topex, cosmos2502, cosmos2502-paper) "
                         "nor a mesh file; check the name or path")
    if args.panel_pitch_deg is not None:
        scene = scene.with_parameters(panel_pitch_deg=args.panel_pitch_deg)
    return scene


def synthetic_for_pass(stored, scene, attitude, method="auto", accuracy_mag=0.005):
    """(LightCurveModel, BodyGeometry) of ``scene`` along a stored pass with ``attitude``."""
    from raycast.geometry import PassGeometry
    from raycast.orbit import Satellite
    from raycast.render import render

    if stored.tle:
        satellite = Satellite.from_tle(stored.tle)
    elif stored.omm:
        satellite = Satellite.from_omm(stored.omm)
    else:
        raise ValueError(f"pass {stored.pass_id} has neither a TLE nor an OMM; re-ingest it with orbital elements")
    geometry = PassGeometry.compute(satellite, stored.site, stored.time_utc, exposure_s=stored.exposure_s)
    body = geometry.body_frame(attitude)
    return render(scene, body, method=method, band=stored.band, accuracy_mag=accuracy_mag), body


def run(args) -> int:
    from raycast.attitude import PrecessingSpin

    try:
        stored = open_archive(args).get(args.pass_id)
        scene = _scene(args)
        attitude = PrecessingSpin(period_s=args.period_s, phase_deg=args.phase_deg,
                                  precession_period_s=args.precession_period_s,
                                  precession_angle_deg=args.precession_angle_deg, spin_axis=args.spin_axis)
        model, body = synthetic_for_pass(stored, scene, attitude, args.method, args.accuracy_mag)
    except (ValueError, LookupError, FileNotFoundError) as error:
        return fail("render", error)
    observed = np.asarray(stored.best_mag, dtype=float)
    synthetic = model.mag_1000km
    ok = stored.valid & np.isfinite(observed) & np.isfinite(synthetic)
    offset = float(np.median(observed[ok] - synthetic[ok])) if ok.any() else float("nan")
    residual = observed[ok] - synthetic[ok] - offset
    summary = {
        "pass_id": stored.pass_id, "model": scene.name, "parameters": dict(scene.parameters),
        "attitude": {"period_s": args.period_s, "phase_deg": args.phase_deg,
                     "precession_period_s": args.precession_period_s,
                     "precession_angle_deg": args.precession_angle_deg, "spin_axis": args.spin_axis},
        "method": model.method, "settings": model.settings, "band": model.band, "n_frames": len(model),
        "offset_mag": offset, "residual_rms_mag": float(np.sqrt(np.mean(residual ** 2))) if ok.any() else None,
        "model_mag_1000km_min": float(np.nanmin(np.where(np.isfinite(synthetic), synthetic, np.nan))),
        "model_mag_1000km_max": float(np.nanmax(np.where(np.isfinite(synthetic), synthetic, np.nan))),
    }
    if args.plot:
        _plot(stored, synthetic + offset, args.plot)
        summary["plot"] = args.plot
    if args.frames_png:
        summary["frames_png"] = _frames(scene, body, args.frames_png, args.frames)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"{stored.pass_id}: {scene.name} rendered with '{model.method}' over {len(model)} frames; "
              f"offset {offset:+.3f} mag, residual RMS {summary['residual_rms_mag']:.3f} mag")
    return 0


def _plot(stored, model_mag, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = (stored.time_utc - stored.time_utc[0]) / np.timedelta64(1, "s")
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(t, stored.best_mag, ".", ms=2, color="0.4", label=f"observed ({stored.band})")
    ax.plot(t, model_mag, "-", lw=0.8, color="C3", label="model + median offset")
    ax.invert_yaxis()
    ax.set_xlabel(f"seconds since {np.datetime_as_string(stored.time_utc[0], unit='s')} UTC")
    ax.set_ylabel("magnitude at 1000 km")
    ax.set_title(f"{stored.name} ({stored.norad}), pass {stored.pass_id}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _frames(scene, body, directory, count):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from raycast.direct import DirectRenderer

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    renderer = DirectRenderer(scene, scene.posed().radius_m / 150.0)
    written = []
    for index in np.linspace(0, len(body.range_km) - 1, max(count, 1)).astype(int):
        image = renderer.image(body.sun_body[index, 0], body.obs_body[index, 0])
        path = out / f"frame_{index:05d}.png"
        plt.imsave(path, np.sqrt(image / max(image.max(), 1e-12)), cmap="gray", origin="lower")
        written.append(str(path))
    return written
