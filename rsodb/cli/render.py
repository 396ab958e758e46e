"""``rsodb render``: the synthetic light curve of a stored pass (against the observed one) or of a
TLE seen from a site over a time span."""

from __future__ import annotations

import argparse
import json

import numpy as np

import ingest
import raycast
import rsodb
from rsodb.cli.archive_options import fail, open_archive

__all__ = ["register", "run"]

EXAMPLE = """\
example:
  rsodb render --model topex --pass 22076-20240730T212240 --archive archive \\
      --period-s 9.86 --precession-period-s 689 --precession-angle-deg 35 --plot topex_model.png
  rsodb render --model cosmos2502-paper --spin-axis x --period-s 40.5 --pass 51511 --archive archive --json
  rsodb render --model topex --pass 22076 --archive archive --frames-png frames/ --frames 4
  rsodb render --model topex --tle ../shared/data/tle/tles.txt --norad 22076 --site derenivka \
      --start 2024-07-30T21:22:40 --duration 460 --cadence 0.2 --period-s 9.86 --plot topex_span.png --json
  rsodb render --model cosmos2502 --tle cosmos.tle --site 48.56,22.45,200 --start 2024-01-05T18:00:00 \
      --duration 300 --cadence 1 --spin-axis x --period-s 40.5 --frames-png frames/

MODEL is topex, cosmos2502 (code-built look-alike), cosmos2502-paper (the paper's mesh from
../shared/data/models) or a mesh file (OBJ, PLY, glTF; give --materials for its JSON).
The attitude is the seed paper's precessing spin. With --pass the model magnitude is reduced to
1000 km and shifted by the median offset to the observed magnitudes (shape, not albedo, is
compared). With --tle (no archive needed) the light curve of the span is rendered at the true
range and at 1000 km; frames with the object below the horizon are kept (their magnitude is
still computed) and counted in the JSON. The TLE file may hold many element sets (a
tles.txt-style list): --norad picks the object and the set whose epoch is nearest --start.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "render",
        help="render the synthetic light curve of a stored pass and compare it with the observed one",
        description="Render a 3D model along a stored pass (ray casting) and compare with the observations.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--model", required=True, help="topex, cosmos2502, cosmos2502-paper or a mesh file")
    parser.add_argument("--materials", metavar="JSON", help="materials JSON for a mesh file")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--pass", dest="pass_id", metavar="ID", help="pass id (or a unique prefix); needs --archive")
    source.add_argument("--tle", metavar="FILE", help="TLE file (2- or 3-line sets); renders --start .. --duration")
    parser.add_argument("--archive", metavar="DIR", help="archive directory (with --pass)")
    parser.add_argument("--norad", type=int, help="NORAD number of the element set to take from --tle")
    parser.add_argument(
        "--site",
        default="derenivka",
        help="derenivka, uzhhorod or LAT,LON,H (degrees, degrees, metres); default derenivka",
    )
    parser.add_argument("--start", metavar="UTC", help="start of the span, ISO UTC (with --tle)")
    parser.add_argument("--duration", type=float, metavar="S", help="length of the span, seconds (with --tle)")
    parser.add_argument("--cadence", type=float, default=1.0, metavar="S", help="seconds between frames (default 1)")
    parser.add_argument("--exposure-s", type=float, default=0.0, help="exposure per frame, integrated (default 0)")
    parser.add_argument("--band", default="V", help="photometric band with --tle (default V)")
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


def run(args) -> int:
    try:
        scene = rsodb.rendering.load_scene(args.model, args.materials, args.panel_pitch_deg)
        attitude = raycast.PrecessingSpin(
            period_s=args.period_s,
            phase_deg=args.phase_deg,
            precession_period_s=args.precession_period_s,
            precession_angle_deg=args.precession_angle_deg,
            spin_axis=args.spin_axis,
        )
        if args.tle:
            return _run_span(args, scene, attitude)
        if not args.archive:
            raise ValueError("--pass needs --archive DIR (or render a TLE span with --tle)")
        stored = open_archive(args).get(args.pass_id)
        model, body = rsodb.rendering.render_pass(stored, scene, attitude, args.method, args.accuracy_mag)
    except (ValueError, LookupError, FileNotFoundError) as error:
        return fail("render", error)
    observed = np.asarray(stored.best_mag, dtype=float)
    synthetic = model.mag_1000km
    ok = stored.valid & np.isfinite(observed) & np.isfinite(synthetic)
    offset = float(np.median(observed[ok] - synthetic[ok])) if ok.any() else float("nan")
    residual = observed[ok] - synthetic[ok] - offset
    summary = {
        "pass_id": stored.pass_id,
        "model": scene.name,
        "parameters": dict(scene.parameters),
        "attitude": _attitude_summary(args),
        "method": model.method,
        "settings": model.settings,
        "band": model.band,
        "n_frames": len(model),
        "offset_mag": offset,
        "residual_rms_mag": float(np.sqrt(np.mean(residual**2))) if ok.any() else None,
        "model_mag_1000km_min": float(np.nanmin(np.where(np.isfinite(synthetic), synthetic, np.nan))),
        "model_mag_1000km_max": float(np.nanmax(np.where(np.isfinite(synthetic), synthetic, np.nan))),
    }
    if args.plot:
        rsodb.rendering.plot_against_pass(stored, synthetic + offset, args.plot)
        summary["plot"] = args.plot
    if args.frames_png:
        summary["frames_png"] = rsodb.rendering.save_frames(scene, body, args.frames_png, args.frames)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"{stored.pass_id}: {scene.name} rendered with '{model.method}' over {len(model)} frames; "
            f"offset {offset:+.3f} mag, residual RMS {summary['residual_rms_mag']:.3f} mag"
        )
    return 0


def _attitude_summary(args):
    return {
        "period_s": args.period_s,
        "phase_deg": args.phase_deg,
        "precession_period_s": args.precession_period_s,
        "precession_angle_deg": args.precession_angle_deg,
        "spin_axis": args.spin_axis,
    }


def _run_span(args, scene, attitude):
    """``--tle``: render a span; raises ValueError on bad options (reported by :func:`run`)."""
    if args.start is None or args.duration is None:
        raise ValueError("--tle needs --start UTC and --duration S")
    try:
        start = np.datetime64(args.start.rstrip("Z"), "us")
    except ValueError:
        raise ValueError(f"--start {args.start!r} is not an ISO UTC time; give e.g. 2024-07-30T21:22:40") from None
    site = ingest.Site.from_text(args.site)
    satellite = raycast.Satellite.from_catalogue(args.tle, args.norad, start)
    model, body, geometry = rsodb.rendering.render_span(
        satellite,
        site,
        start,
        args.duration,
        args.cadence,
        scene,
        attitude,
        args.method,
        args.accuracy_mag,
        args.exposure_s,
        args.band,
    )
    mag, mag_1000 = model.mag, model.mag_1000km
    finite = np.isfinite(mag_1000)
    summary = {
        "norad": satellite.norad,
        "object": satellite.name,
        "tle_epoch_utc": str(satellite.epoch_utc),
        "site": {"name": site.name, "lat_deg": site.lat_deg, "lon_deg": site.lon_deg, "elevation_m": site.elevation_m},
        "start_utc": str(start),
        "duration_s": args.duration,
        "cadence_s": args.cadence,
        "n_frames": len(model),
        "frames_above_horizon": int(np.sum(geometry.el_deg > 0.0)),
        "frames_sunlit": int(np.sum(body.sunlit.mean(axis=1) > 0.0)),
        "model": scene.name,
        "parameters": dict(scene.parameters),
        "attitude": _attitude_summary(args),
        "method": model.method,
        "settings": model.settings,
        "band": model.band,
        "mag_min": float(np.min(mag[finite])) if finite.any() else None,
        "mag_max": float(np.max(mag[finite])) if finite.any() else None,
        "mag_1000km_min": float(np.min(mag_1000[finite])) if finite.any() else None,
        "mag_1000km_max": float(np.max(mag_1000[finite])) if finite.any() else None,
    }
    if args.plot:
        rsodb.rendering.plot_span(geometry, model, f"{satellite.name} ({satellite.norad}) from {site.name}", args.plot)
        summary["plot"] = args.plot
    if args.frames_png:
        summary["frames_png"] = rsodb.rendering.save_frames(scene, body, args.frames_png, args.frames)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"{satellite.name} ({satellite.norad}) from {site.name}: {scene.name} rendered with '{model.method}' "
            f"over {len(model)} frames ({summary['frames_above_horizon']} above the horizon, "
            f"{summary['frames_sunlit']} sunlit); magnitude {summary['mag_min']} .. {summary['mag_max']}"
        )
    return 0
