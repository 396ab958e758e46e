"""``rsodb render``: the synthetic light curve of a stored pass (against the observed one), of a
TLE seen from a site over a time span, or of a stored fit's posterior over its pass."""

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
examples:
  rsodb render --model topex --pass 22076-20240730T212240 --archive archive \\
      --period-s 9.86 --phase-deg 120 --precession-period-s 689 --precession-phase-deg 180 \\
      --precession-angle-deg 35 --n-sub 4 --plot topex_model.png
  rsodb render --from-fit 22076-20240730T212240:quick --archive archive --plot replay.png --gif pass.gif
  rsodb render --model cosmos2502-paper --spin-axis x --period-s 40.5 --pass 51511 --archive archive --json
  rsodb render --model topex --pass 22076 --archive archive --frames-png frames/ --frames 4
  rsodb render --model topex --tle ../shared/data/tle/tles.txt --norad 22076 --site derenivka \\
      --start 2024-07-30T21:22:40 --duration 460 --cadence 0.2 --period-s 9.86 --plot topex_span.png --json
  rsodb render --model box.obj --materials box.materials.json --attitude inertial --pole-ra-deg 30 \\
      --pole-dec-deg 60 --period-s 12 --tle cosmos.tle --site 48.56,22.45,200 --start 2024-01-05T18:00:00 \\
      --duration 300 --cadence 1

MODEL is topex, cosmos2502 (code-built look-alike), cosmos2502-paper (the paper's mesh from
../shared/data/models) or a mesh file (OBJ, PLY, glTF; give --materials for its JSON).
The attitude (--attitude, default the seed paper's precessing spin) takes every parameter of its
family; phases are at the reference epoch, the pass's (or span's) mid-time as in a fit of the
whole pass, or --epoch UTC (a fit of a window: its 'phases at' time), so a fitted state renders
as fitted. --n-sub integrates each exposure over that many sub-samples
(default: enough for 2 deg of rotation each). With --pass the model magnitude is reduced to
1000 km and shifted by the median offset to the observed magnitudes (shape, not albedo, is
compared). --from-fit PASS[:NAME] replays a stored fit with its own model: the posterior median
over every sample of the pass and at fine steps, with a band from --draws posterior draws (NAME
defaults to the pass's only fit, or "default"). With --tle (no archive needed) the light curve
of the span is rendered at the true range and at 1000 km; frames with the object below the
horizon are kept (their magnitude is still computed) and counted in the JSON. The TLE file may
hold many element sets (a tles.txt-style list): --norad picks the object and the set whose
epoch is nearest --start. --frames-png writes annotated frames (time, phase angle, Sun
direction, body axes, scale bar; one brightness scale for all), --gif an animation of the
frames beside the light curve.
"""

# rsodb.fit.model.ATTITUDES, named here so that 'rsodb --help' loads none of the library
# (tests/test_cli_render.py checks that they agree).
ATTITUDE_FAMILIES = ("precessing", "inertial", "inertial_tilted", "torque_free")
# Command-line option of each attitude parameter (rsodb.fit.model.ATTITUDES) and its default.
PARAMETER_OPTIONS = {
    "spin_period_s": ("--period-s", 10.0, "spin period, s (precessing: relative to the precessing frame)"),
    "spin_phase_deg": ("--phase-deg", 0.0, "spin phase at the reference epoch, deg"),
    "precession_period_s": ("--precession-period-s", float("inf"), "precession period, s (inf: none)"),
    "precession_phase_deg": ("--precession-phase-deg", 0.0, "precession phase at the reference epoch, deg"),
    "precession_angle_deg": ("--precession-angle-deg", 0.0, "precession cone half-angle, deg"),
    "pole_ra_deg": ("--pole-ra-deg", 0.0, "spin pole right ascension (inertial, inertial_tilted, torque_free), deg"),
    "pole_dec_deg": ("--pole-dec-deg", 90.0, "spin pole declination (inertial, inertial_tilted, torque_free), deg"),
    "axis_tilt_deg": ("--axis-tilt-deg", 0.0, "spin axis tilt from the body axis --spin-axis (inertial_tilted), deg"),
    "axis_tilt_azimuth_deg": (
        "--axis-tilt-azimuth-deg",
        0.0,
        "its direction about that axis, from the next body axis in cyclic order (inertial_tilted), deg",
    ),
    "inertia_ratio_2": ("--inertia-ratio-2", 1.0, "I2/I1 (torque_free)"),
    "inertia_ratio_3": ("--inertia-ratio-3", 1.0, "I3/I1 (torque_free)"),
    "omega_polar_deg": ("--omega-polar-deg", 0.0, "angular velocity from body +z at the epoch (torque_free), deg"),
    "omega_azimuth_deg": ("--omega-azimuth-deg", 0.0, "its azimuth from +x toward +y (torque_free), deg"),
}


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "render",
        help="render the synthetic light curve of a stored pass, a TLE span or a stored fit",
        description="Render a 3D model along a stored pass or a TLE span (ray casting) and compare with the "
        "observations, or replay a stored fit's posterior over its pass.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--model", help="topex, topex_louvered, cosmos2502, cosmos2502-paper or a mesh file (not with --from-fit)"
    )
    parser.add_argument("--materials", metavar="JSON", help="materials JSON for a mesh file")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--pass", dest="pass_id", metavar="ID", help="pass id (or a unique prefix); needs --archive")
    source.add_argument("--tle", metavar="FILE", help="TLE file (2- or 3-line sets); renders --start .. --duration")
    source.add_argument(
        "--from-fit", metavar="PASS[:NAME]", help="replay a stored fit: posterior median and band; needs --archive"
    )
    parser.add_argument("--archive", metavar="DIR", help="archive directory (with --pass, --from-fit)")
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
    parser.add_argument(
        "--attitude",
        choices=ATTITUDE_FAMILIES,
        default="precessing",
        help="attitude family (default precessing, the seed paper's)",
    )
    for name, (option, default, text) in PARAMETER_OPTIONS.items():
        parser.add_argument(option, dest=name, type=float, default=default, help=f"{text} (default {default:g})")
    parser.add_argument(
        "--epoch",
        metavar="UTC",
        help="reference epoch of the phases, ISO UTC (default: the pass's or span's mid-time; a fit's is its "
        "window's mid-time, printed as 'phases at')",
    )
    parser.add_argument("--spin-axis", choices=("x", "y", "z"), default="z", help="body axis that spins")
    parser.add_argument("--panel-pitch-deg", type=float, default=None, help="TOPEX solar-array pitch")
    parser.add_argument(
        "--n-sub", type=int, metavar="K", help="exposure sub-samples per frame (default: 2 deg of rotation each)"
    )
    parser.add_argument("--method", choices=("auto", "direct", "cached"), default="auto")
    parser.add_argument("--accuracy-mag", type=float, default=0.005, help="requested accuracy (direct)")
    parser.add_argument("--draws", type=int, default=100, help="posterior draws of the --from-fit band (default 100)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--plot", metavar="FILE", help="save model vs observed light curve (PNG, PDF, SVG)")
    parser.add_argument(
        "--glint-map",
        metavar="FILE",
        help="with --from-fit: save the residuals mapped over the body direction of the Sun-observer bisector, "
        "beside the directions the model's surfaces face (which smooth surface the data ask for)",
    )
    parser.add_argument("--frames-png", metavar="DIR", help="save annotated frames of the model as PNG images")
    parser.add_argument("--frames", type=int, default=4, help="how many frames --frames-png saves (default 4)")
    parser.add_argument("--gif", metavar="FILE.gif", help="save an animation of the frames beside the light curve")
    parser.add_argument("--gif-frames", type=int, default=60, help="frames of the --gif animation (default 60)")
    parser.set_defaults(func=run)


def _attitude(args, epoch_s: float):
    """The attitude of the command line, its phases at `epoch_s` (seconds after the first frame)."""
    family = rsodb.fit.ATTITUDES[args.attitude]
    values = {name: getattr(args, name) for name in family.parameters}
    settings = {"spin_axis": args.spin_axis} if "spin_axis" in family.settings else {}
    return rsodb.fit.make_attitude(args.attitude, values, settings, epoch_s)


def _attitude_summary(args, epoch_utc) -> dict:
    family = rsodb.fit.ATTITUDES[args.attitude]
    summary = {"family": args.attitude, "epoch_utc": str(epoch_utc)}
    summary.update({name: getattr(args, name) for name in family.parameters})
    if "spin_axis" in family.settings:
        summary["spin_axis"] = args.spin_axis
    return summary


def _utc(text: str, option: str) -> np.datetime64:
    try:
        return np.datetime64(text.rstrip("Z"), "ns")
    except ValueError:
        raise ValueError(f"{option} {text!r} is not an ISO UTC time; give e.g. 2024-07-30T21:22:40") from None


def _epoch(args, first_utc, last_utc):
    """(seconds after `first_utc`, UTC) of the phases' reference epoch: --epoch, else the midpoint
    of the frames (a fit's reference epoch when it fits the whole pass)."""
    if args.epoch:
        epoch_utc = _utc(args.epoch, "--epoch")
    else:
        epoch_utc = (
            np.datetime64(first_utc, "ns") + (np.datetime64(last_utc, "ns") - np.datetime64(first_utc, "ns")) // 2
        )
    return float((epoch_utc - np.datetime64(first_utc, "ns")) / np.timedelta64(1, "s")), epoch_utc


def run(args) -> int:
    try:
        if args.n_sub is not None and not 1 <= args.n_sub <= 64:
            raise ValueError(f"--n-sub {args.n_sub} must be a whole number from 1 to 64")
        if args.from_fit:
            return _run_fit(args)
        if args.glint_map:
            raise ValueError("--glint-map maps a stored fit's residuals; give --from-fit PASS[:NAME]")
        if not args.model:
            raise ValueError("give --model (a built-in name or a mesh file), or replay a fit with --from-fit PASS")
        scene = rsodb.rendering.load_scene(args.model, args.materials, args.panel_pitch_deg)
        if args.tle:
            return _run_span(args, scene)
        if not args.archive:
            raise ValueError("--pass needs --archive DIR (or render a TLE span with --tle)")
        stored = open_archive(args).get(args.pass_id)
        epoch_s, epoch_utc = _epoch(args, stored.time_utc[0], stored.time_utc[-1])
        attitude = _attitude(args, epoch_s)
        model, body = rsodb.rendering.render_pass(stored, scene, attitude, args.method, args.accuracy_mag, args.n_sub)
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
        "attitude": _attitude_summary(args, epoch_utc),
        "method": model.method,
        "settings": model.settings,
        "band": model.band,
        "n_frames": len(model),
        "n_sub": int(body.weights.size),
        "offset_mag": offset,
        "residual_rms_mag": float(np.sqrt(np.mean(residual**2))) if ok.any() else None,
        "model_mag_1000km_min": float(np.nanmin(np.where(np.isfinite(synthetic), synthetic, np.nan))),
        "model_mag_1000km_max": float(np.nanmax(np.where(np.isfinite(synthetic), synthetic, np.nan))),
    }
    if args.plot:
        rsodb.rendering.plot_against_pass(stored, synthetic + offset, args.plot)
        summary["plot"] = args.plot
    if args.frames_png:
        summary["frames_png"] = rsodb.rendering.save_frames(scene, body, args.frames_png, args.frames, stored.time_utc)
    if args.gif:
        summary["gif"] = rsodb.rendering.save_animation(
            scene, body, stored.time_utc, synthetic + offset, (stored.time_utc, observed), args.gif, args.gif_frames
        )
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"{stored.pass_id}: {scene.name} rendered with '{model.method}' over {len(model)} frames "
            f"({summary['n_sub']} sub-samples each), phases at {epoch_utc} UTC; offset {offset:+.3f} mag, "
            f"residual RMS {summary['residual_rms_mag']:.3f} mag"
        )
    return 0


def _run_fit(args) -> int:
    """``--from-fit``: replay a stored fit; raises ValueError/LookupError on bad options."""
    if args.model or args.materials or args.epoch:
        raise ValueError(
            "--from-fit renders the fit's own model at its own epoch; leave out --model, --materials, --epoch"
        )
    if not args.archive:
        raise ValueError("--from-fit needs --archive DIR")
    pass_id, _, name = args.from_fit.partition(":")
    prediction = rsodb.fit.predict_fit(open_archive(args), pass_id, name or None, draws=args.draws)
    result = prediction.result
    samples, curve = prediction.samples, prediction.curve
    low, high = curve.band(0.16, 0.84) if curve.mag_band.size else (curve.mag_best, curve.mag_best)
    summary = {
        "pass_id": result.pass_id,
        "fit": result.name,
        "shape": result.config.get("shape"),
        "attitude": {"family": result.config["model"]["attitude"], "epoch_utc": result.epoch_utc, **prediction.values},
        "draws": prediction.draws,
        "n_samples": int(samples.time_utc.size),
        "n_window": int(np.sum(samples.in_window)),
        "residual_rms_mag": prediction.residual_rms_mag,
        "band_68_width_mag_median": float(np.median(high - low)),
        "spin_periods": dict(result.spin_periods),
    }
    if args.plot:
        rsodb.fit.plots.prediction_figure(prediction, args.plot)
        summary["plot"] = args.plot
    if args.glint_map:
        rsodb.fit.plots.glint_map_figure(prediction, args.glint_map)
        summary["glint_map"] = args.glint_map
    scene = prediction.scene
    if (args.frames_png or args.gif) and scene is None:
        raise ValueError(f"the fit's shape {result.config.get('shape')!r} is analytic: it has no frames to draw")
    if args.frames_png:
        geometry, body = prediction.body_geometry()
        summary["frames_png"] = rsodb.rendering.save_frames(
            scene, body, args.frames_png, args.frames, geometry.time_utc
        )
    if args.gif:
        geometry, body = prediction.body_geometry(curve.time_utc)
        summary["gif"] = rsodb.rendering.save_animation(
            scene,
            body,
            curve.time_utc,
            curve.mag_best,
            (samples.time_utc, samples.mag_obs),
            args.gif,
            args.gif_frames,
        )
    if args.json:
        print(json.dumps(summary, indent=2, default=str))
    else:
        print(
            f"{result.pass_id}: fit {result.name!r} replayed at the posterior median with {prediction.draws} "
            f"draws; residual RMS {prediction.residual_rms_mag:.3f} mag over {summary['n_window']} samples; "
            f"phases at {result.epoch_utc} UTC"
        )
        for line in result.spin_period_lines():
            print(line)
    return 0


def _run_span(args, scene):
    """``--tle``: render a span; raises ValueError on bad options (reported by :func:`run`)."""
    if args.start is None or args.duration is None:
        raise ValueError("--tle needs --start UTC and --duration S")
    start = _utc(args.start, "--start").astype("datetime64[us]")
    site = ingest.Site.from_text(args.site)
    satellite = raycast.Satellite.from_catalogue(args.tle, args.norad, start)
    end = np.datetime64(start, "ns") + np.timedelta64(int(round(args.duration * 1e9)), "ns")
    epoch_s, epoch_utc = _epoch(args, start, end)
    model, body, geometry = rsodb.rendering.render_span(
        satellite,
        site,
        start,
        args.duration,
        args.cadence,
        scene,
        _attitude(args, epoch_s),
        args.method,
        args.accuracy_mag,
        args.exposure_s,
        args.band,
        args.n_sub,
        args.spin_period_s,
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
        "n_sub": int(body.weights.size),
        "frames_above_horizon": int(np.sum(geometry.el_deg > 0.0)),
        "frames_sunlit": int(np.sum(body.sunlit.mean(axis=1) > 0.0)),
        "model": scene.name,
        "parameters": dict(scene.parameters),
        "attitude": _attitude_summary(args, epoch_utc),
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
        summary["frames_png"] = rsodb.rendering.save_frames(
            scene, body, args.frames_png, args.frames, geometry.time_utc
        )
    if args.gif:
        summary["gif"] = rsodb.rendering.save_animation(
            scene, body, geometry.time_utc, model.mag, None, args.gif, args.gif_frames
        )
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"{satellite.name} ({satellite.norad}) from {site.name}: {scene.name} rendered with '{model.method}' "
            f"over {len(model)} frames ({summary['frames_above_horizon']} above the horizon, "
            f"{summary['frames_sunlit']} sunlit); magnitude {summary['mag_min']} .. {summary['mag_max']}"
        )
    return 0
