"""``rsodb show PASS --archive DIR``: everything the archive knows about one pass."""

from __future__ import annotations

import argparse
import json

import numpy as np

import rsodb
from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run", "describe"]

EXAMPLE = """\
example:
  rsodb show 22076-20240730T212240 --archive archive
  rsodb show 22076-20240730T212240 --archive archive --json
  rsodb show 22076-20240730T212240 --archive archive --plot topex.png

PASS is a pass id from 'rsodb ls' or a unique beginning of one.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "show",
        help="show one pass: object, site, times, photometry, reduction, source, results",
        description="Show what the archive holds about one pass.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("pass_id", metavar="PASS", help="pass id (or a unique prefix)")
    add_archive_option(parser)
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.add_argument("--plot", metavar="FILE", help="also save the light curve as an image (PNG, PDF, SVG)")
    parser.set_defaults(func=run)


def _iso(t: np.datetime64) -> str:
    return np.datetime_as_string(t, unit="ms") + "Z"


def describe(stored, results: dict[str, list[str]]) -> dict:
    """JSON-ready description of a stored pass (no per-sample arrays; see ``rsodb export``)."""
    mag = stored.best_mag[stored.valid & np.isfinite(stored.best_mag)]
    reduction = stored.reduction
    return {
        "pass_id": stored.pass_id,
        "version": stored.version,
        "supersedes": stored.supersedes,
        "superseded_by": stored.superseded_by,
        "ingested_utc": stored.ingested_utc,
        "norad": stored.norad,
        "name": stored.name,
        "cospar": stored.cospar,
        "site": {
            "name": stored.site.name,
            "lat_deg": stored.site.lat_deg,
            "lon_deg": stored.site.lon_deg,
            "elevation_m": stored.site.elevation_m,
        },
        "band": stored.band,
        "exposure_s": stored.exposure_s,
        "start_utc": _iso(stored.start_utc),
        "end_utc": _iso(stored.end_utc),
        "duration_s": round(stored.duration_s, 6),
        "n_points": len(stored),
        "n_valid": int(stored.valid.sum()),
        "n_saturated": int(stored.saturated.sum()),
        "mag_min": float(mag.min()) if mag.size else None,
        "mag_median": float(np.median(mag)) if mag.size else None,
        "mag_max": float(mag.max()) if mag.size else None,
        "range_km_min": float(np.nanmin(stored.range_km)),
        "range_km_max": float(np.nanmax(stored.range_km)),
        "el_deg_min": float(np.nanmin(stored.el_deg)),
        "el_deg_max": float(np.nanmax(stored.el_deg)),
        "time_convention": stored.time_convention,
        "time_shift_s": stored.time_shift_s,
        "mag_convention": stored.mag_convention,
        "has_mag_corrected": stored.mag_corrected is not None,
        "reduction": None
        if reduction is None
        else {
            "zero_point_mag": reduction.zero_point_mag,
            "extinction_term_mag": reduction.extinction_term_mag,
            "rms_mag": reduction.rms_mag,
            "n_points": reduction.n_points,
            "sign_error": reduction.sign_error,
        },
        "tle": list(stored.tle) if stored.tle else None,
        "omm": stored.omm,
        "source_name": stored.source_name,
        "source_sha256": stored.source_sha256,
        "source_format": stored.source_format,
        "results": results,
    }


def _text(info: dict) -> str:
    site = info["site"]
    state = "current" if info["superseded_by"] is None else f"superseded by {info['superseded_by']}"
    lines = [
        f"pass       {info['pass_id']}  (version {info['version']}, {state}"
        + (f", replaces {info['supersedes']})" if info["supersedes"] else ")"),
        f"object     {info['norad']} {info['name']}" + (f"  COSPAR {info['cospar']}" if info["cospar"] else ""),
        f"site       {site['name']}  ({site['lat_deg']:.5f} N, {site['lon_deg']:.5f} E, {site['elevation_m']:.0f} m)",
        f"band       {info['band']}   exposure {info['exposure_s']:g} s",
        f"time       {info['start_utc']} .. {info['end_utc']}  ({info['duration_s']:.1f} s; {info['time_convention']})",
        f"points     {info['n_points']}  ({info['n_valid']} valid, {info['n_saturated']} saturated)",
    ]
    if info["mag_median"] is not None:
        lines.append(
            f"magnitude  {info['mag_min']:.3f} .. {info['mag_max']:.3f}, median {info['mag_median']:.3f}"
            + ("  (sign-corrected)" if info["has_mag_corrected"] else "")
        )
    lines.append(
        f"geometry   range {info['range_km_min']:.0f} .. {info['range_km_max']:.0f} km, "
        f"elevation {info['el_deg_min']:.1f} .. {info['el_deg_max']:.1f} deg"
    )
    reduction = info["reduction"]
    if reduction is not None:
        lines.append(
            f"reduction  A = {reduction['zero_point_mag']:.3f} mag, airmass term {reduction['extinction_term_mag']:+.3f} "
            f"mag per airmass, rms {reduction['rms_mag']:.4f} mag over {reduction['n_points']} points"
            + (
                "; the file ADDED the extinction term (sign error), corrected magnitudes stored"
                if reduction["sign_error"]
                else ""
            )
        )
    if info["tle"]:
        lines.append("TLE        " + "\n           ".join(info["tle"]))
    elif info["omm"]:
        lines.append(f"OMM        {json.dumps(info['omm'])[:100]}")
    lines.append(f"source     {info['source_name']}  ({info['source_format']}, sha256 {info['source_sha256'][:16]}...)")
    lines.append(f"ingested   {info['ingested_utc']}")
    for kind, names in info["results"].items():
        lines.append(f"{kind:<10} {', '.join(names) if names else 'none'}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    try:
        archive = open_archive(args)
        stored = archive.get(args.pass_id)
        results = {kind: archive.result_names(stored.pass_id, kind) for kind in ("periods", "fits")}
    except (ValueError, LookupError, OSError) as error:
        return fail("show", error)
    info = describe(stored, results)
    print(json.dumps(info, indent=1, ensure_ascii=False) if args.json else _text(info))
    if args.plot:
        rsodb.report.save_pass_plot(stored, args.plot)
    return 0
