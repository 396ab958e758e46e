"""``rsodb render``: the synthetic light curve of a stored pass (against the observed one) or of a
TLE seen from a site over a time span."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from rsodb.cli.archive_options import fail, open_archive

__all__ = ["register", "run", "synthetic_for_pass", "synthetic_for_span", "satellite_from_tle_file", "parse_site"]

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

PAPER_MODEL = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "models" / "cosmos2502_lotos.obj"


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "render", help="render the synthetic light curve of a stored pass and compare it with the observed one",
        description="Render a 3D model along a stored pass (ray casting) and compare with the observations.",
        epilog=EXAMPLE, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", required=True, help="topex, cosmos2502, cosmos2502-paper or a mesh file")
    parser.add_argument("--materials", metavar="JSON", help="materials JSON for a mesh file")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--pass", dest="pass_id", metavar="ID", help="pass id (or a unique prefix); needs --archive")
    source.add_argument("--tle", metavar="FILE", help="TLE file (2- or 3-line sets); renders --start .. --duration")
    parser.add_argument("--archive", metavar="DIR", help="archive directory (with --pass)")
    parser.add_argument("--norad", type=int, help="NORAD number of the element set to take from --tle")
    parser.add_argument("--site", default="derenivka",
                        help="derenivka, uzhhorod or LAT,LON,H (degrees, degrees, metres); default derenivka")
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


def satellite_from_tle_file(path, norad=None, near_utc=None):
    """The element set of ``norad`` in a TLE file whose epoch is nearest ``near_utc``.

    The file holds 2- or 3-line sets (title lines ``0 NAME`` or ``NAME``); ``#`` lines and
    blank lines are skipped. Without ``norad`` the file must hold a single object.
    """
    from raycast.orbit import Satellite

    lines = [line.rstrip() for line in Path(path).read_text().splitlines()
             if line.strip() and not line.lstrip().startswith("#")]
    sets = []
    for index, line in enumerate(lines):
        if line.startswith("1 ") and index + 1 < len(lines) and lines[index + 1].startswith("2 "):
            title = lines[index - 1] if index > 0 and not lines[index - 1][:2] in ("1 ", "2 ") else None
            sets.append(([title] if title else []) + [line, lines[index + 1]])
    if not sets:
        raise ValueError(f"{path} holds no TLE (pairs of lines starting '1 ' and '2 '); give a TLE file")
    numbers = sorted({int(s[-2][2:7]) for s in sets})
    if norad is None and len(numbers) > 1:
        raise ValueError(f"{path} holds element sets of {len(numbers)} objects ({', '.join(map(str, numbers[:5]))}"
                         f"{', ...' if len(numbers) > 5 else ''}); pick one with --norad")
    chosen = [s for s in sets if norad is None or int(s[-2][2:7]) == norad]
    if not chosen:
        raise ValueError(f"{path} holds no element set of NORAD {norad}; its objects are "
                         f"{', '.join(map(str, numbers[:10]))}")
    satellites = [Satellite.from_tle(s) for s in chosen]
    if near_utc is None:
        return satellites[-1]
    gap = [abs((sat.epoch_utc - near_utc) / np.timedelta64(1, "s")) for sat in satellites]
    return satellites[int(np.argmin(gap))]


def parse_site(text):
    """A preset site name or ``LAT,LON,H`` (geodetic degrees and metres) as a :class:`raycast.site.Site`."""
    from raycast.site import Site

    parts = text.split(",")
    if len(parts) == 1:
        return Site.preset(text)
    try:
        lat, lon, height = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"site {text!r} is neither a known site (derenivka, uzhhorod) nor LAT,LON,H; "
                         "give e.g. 48.56,22.45,200") from None
    return Site(f"{lat:.4f},{lon:.4f}", lat, lon, height)


def synthetic_for_span(satellite, site, start_utc, duration_s, cadence_s, scene, attitude, method="auto",
                       accuracy_mag=0.005, exposure_s=0.0, band="V"):
    """(LightCurveModel, BodyGeometry, PassGeometry) of ``scene`` over a time span seen from ``site``."""
    from raycast.geometry import PassGeometry
    from raycast.render import render

    for name, value in (("duration", duration_s), ("cadence", cadence_s)):
        if not (np.isfinite(value) and value > 0.0):
            raise ValueError(f"--{name} {value!r} must be a positive number of seconds")
    n = int(np.floor(duration_s / cadence_s + 1e-9)) + 1
    if n > 200_000:
        raise ValueError(f"--duration {duration_s} at --cadence {cadence_s} makes {n} frames (more than 200000); "
                         "raise the cadence or shorten the span")
    times = start_utc + (np.arange(n) * cadence_s * 1e6).astype("timedelta64[us]")
    geometry = PassGeometry.compute(satellite, site, times, exposure_s=exposure_s,
                                    spin_period_s=attitude.period_s if hasattr(attitude, "period_s") else None)
    body = geometry.body_frame(attitude)
    return render(scene, body, method=method, band=band, accuracy_mag=accuracy_mag), body, geometry


def run(args) -> int:
    from raycast.attitude import PrecessingSpin

    try:
        scene = _scene(args)
        attitude = PrecessingSpin(period_s=args.period_s, phase_deg=args.phase_deg,
                                  precession_period_s=args.precession_period_s,
                                  precession_angle_deg=args.precession_angle_deg, spin_axis=args.spin_axis)
        if args.tle:
            return _run_span(args, scene, attitude)
        if not args.archive:
            raise ValueError("--pass needs --archive DIR (or render a TLE span with --tle)")
        stored = open_archive(args).get(args.pass_id)
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
        "attitude": _attitude_summary(args),
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


def _attitude_summary(args):
    return {"period_s": args.period_s, "phase_deg": args.phase_deg, "precession_period_s": args.precession_period_s,
            "precession_angle_deg": args.precession_angle_deg, "spin_axis": args.spin_axis}


def _run_span(args, scene, attitude):
    """``--tle``: render a span; raises ValueError on bad options (reported by :func:`run`)."""
    if args.start is None or args.duration is None:
        raise ValueError("--tle needs --start UTC and --duration S")
    try:
        start = np.datetime64(args.start.rstrip("Z"), "us")
    except ValueError:
        raise ValueError(f"--start {args.start!r} is not an ISO UTC time; give e.g. 2024-07-30T21:22:40") from None
    site = parse_site(args.site)
    satellite = satellite_from_tle_file(args.tle, args.norad, start)
    model, body, geometry = synthetic_for_span(satellite, site, start, args.duration, args.cadence, scene, attitude,
                                               args.method, args.accuracy_mag, args.exposure_s, args.band)
    mag, mag_1000 = model.mag, model.mag_1000km
    finite = np.isfinite(mag_1000)
    summary = {
        "norad": satellite.norad, "object": satellite.name, "tle_epoch_utc": str(satellite.epoch_utc),
        "site": {"name": site.name, "lat_deg": site.lat_deg, "lon_deg": site.lon_deg, "elevation_m": site.elevation_m},
        "start_utc": str(start), "duration_s": args.duration, "cadence_s": args.cadence, "n_frames": len(model),
        "frames_above_horizon": int(np.sum(geometry.el_deg > 0.0)),
        "frames_sunlit": int(np.sum(body.sunlit.mean(axis=1) > 0.0)),
        "model": scene.name, "parameters": dict(scene.parameters), "attitude": _attitude_summary(args),
        "method": model.method, "settings": model.settings, "band": model.band,
        "mag_min": float(np.min(mag[finite])) if finite.any() else None,
        "mag_max": float(np.max(mag[finite])) if finite.any() else None,
        "mag_1000km_min": float(np.min(mag_1000[finite])) if finite.any() else None,
        "mag_1000km_max": float(np.max(mag_1000[finite])) if finite.any() else None,
    }
    if args.plot:
        _plot_span(geometry, model, f"{satellite.name} ({satellite.norad}) from {site.name}", args.plot)
        summary["plot"] = args.plot
    if args.frames_png:
        summary["frames_png"] = _frames(scene, body, args.frames_png, args.frames)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"{satellite.name} ({satellite.norad}) from {site.name}: {scene.name} rendered with '{model.method}' "
              f"over {len(model)} frames ({summary['frames_above_horizon']} above the horizon, "
              f"{summary['frames_sunlit']} sunlit); magnitude {summary['mag_min']} .. {summary['mag_max']}")
    return 0


def _plot_span(geometry, model, title, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = (geometry.time_utc - geometry.time_utc[0]) / np.timedelta64(1, "s")
    fig, (ax, ax_el) = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax.plot(t, model.mag, "-", lw=0.8, color="C3", label=f"model at the true range ({model.band})")
    ax.plot(t, model.mag_1000km, "-", lw=0.8, color="C0", alpha=0.6, label="model at 1000 km")
    ax.invert_yaxis()
    ax.set_ylabel("magnitude")
    ax.set_title(title)
    ax.legend()
    ax_el.plot(t, geometry.el_deg, color="0.3", lw=0.8)
    ax_el.axhline(0.0, color="0.6", lw=0.6)
    ax_el.set_ylabel("elevation [deg]")
    ax_el.set_xlabel(f"seconds since {np.datetime_as_string(geometry.time_utc[0], unit='s')} UTC")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


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
