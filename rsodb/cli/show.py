"""``rsodb show PASS [--archive DIR]``: everything the archive knows about one pass."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from raycast.geometry.pass_geometry import COLUMNS_AGREE_DEG, columns_offset_deg
import rsodb
from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run", "describe"]

EXAMPLE = """\
example:
  rsodb show 22076-20240730T212240 --archive archive
  rsodb show 22076-20240730T212240 --archive archive --json
  rsodb show 22076-20240730T212240 --archive archive --plot topex.png

PASS is a pass id from 'rsodb ls' or a unique beginning of one. The text lists the stored
results with their values (period, error, verdict; a fit's parameters), the rows the reader set
aside and the warnings about the file; --json gives all of it.
"""

# Rows set aside, and rows of a result's table, that the text lists; --json gives all of them.
_ROWS_SHOWN = 20
# Result values shown first (when a result has them), then the others in name order.
_FIRST_KEYS = ("best_period_s", "uncertainty_s", "verdict", "reason", "n_cycles", "converged", "reduced_chi2")
# Result attributes that are bookkeeping, not values.
_HIDDEN_KEYS = {"stored_utc", "result_type", "schema", "schema_version", "kind", "pass_id", "name"}


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "show",
        help="show one pass: object, site, times, photometry, reduction, orbit, source, results",
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
    return rsodb.archive.utc_text(t) + "Z"


def describe(stored, results: dict[str, dict[str, dict]], duplicates=()) -> dict:
    """JSON-ready description of a stored pass (no per-sample arrays; see ``rsodb export``).

    Parameters
    ----------
    stored : StoredPass
    results : dict
        ``{kind: {name: values}}`` as `Archive.result_values` gives them.
    duplicates : sequence of DuplicateSource
    """
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
        "range_km_min": _finite(np.nanmin(stored.range_km)) if np.isfinite(stored.range_km).any() else None,
        "range_km_max": _finite(np.nanmax(stored.range_km)) if np.isfinite(stored.range_km).any() else None,
        "el_deg_min": _finite(np.nanmin(stored.el_deg)) if np.isfinite(stored.el_deg).any() else None,
        "el_deg_max": _finite(np.nanmax(stored.el_deg)) if np.isfinite(stored.el_deg).any() else None,
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
        "omm": dict(stored.omm) if stored.omm else None,
        "elements_source": dict(stored.elements_source)
        if stored.elements_source
        else ("file header" if stored.tle or stored.omm else None),
        "columns_vs_elements_deg": _columns_offset(stored),
        "source_name": stored.source_name,
        "source_sha256": stored.source_sha256,
        "source_format": stored.source_format,
        "duplicate_sources": [
            {
                "source_name": item.source_name,
                "sha256": item.sha256,
                "ingested_utc": item.ingested_utc,
                "note": item.note,
            }
            for item in duplicates
        ],
        "warnings": [warning.to_dict() for warning in stored.warnings],
        "rows_set_aside": [problem.to_dict() for problem in stored.row_problems],
        "results": results,
    }


def _finite(value) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def _number(value) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def _result_lines(kind: str, name: str, values: dict) -> list[str]:
    stored = values.get("stored_utc", "")
    lines = [f"{kind:<10} {name}" + (f"  (stored {stored})" if stored else "")]
    first = [key for key in _FIRST_KEYS if key in values]
    rest = sorted(
        key
        for key, value in values.items()
        if key not in first and key not in _HIDDEN_KEYS and not isinstance(value, (list, dict))
    )
    tables = {
        key: value for key, value in values.items() if isinstance(value, list) and value and isinstance(value[0], dict)
    }
    lines += [f"             {key:<24} {_number(values[key])}" for key in first]
    if "summary" in tables:  # a fit's parameters, right after its verdict
        lines += _table_lines("summary", tables.pop("summary"))
    lines += [f"             {key:<24} {_number(values[key])}" for key in rest]
    for key, rows in tables.items():
        lines += _table_lines(key, rows)
    return lines


def _table_lines(key: str, rows: list[dict]) -> list[str]:
    """A result's table, its columns as wide as their widest cell; long tables only counted."""
    if len(rows) > _ROWS_SHOWN:
        return [f"             {key}: {len(rows)} rows (--json lists them)"]
    columns = list(rows[0])
    cells = [[_number(row[column]) for column in columns] for row in rows]
    widths = [max(len(column), *(len(row[i]) for row in cells)) for i, column in enumerate(columns)]
    text = [isinstance(rows[0][column], str) for column in columns]  # left-aligned; numbers right
    lines = [f"             {key}:"]
    for row in [columns, *cells]:
        lines.append(
            "               "
            + "  ".join(
                cell.ljust(width) if left else cell.rjust(width) for cell, width, left in zip(row, widths, text)
            ).rstrip()
        )
    return lines


def _columns_offset(stored) -> dict | None:
    """How far the file's own Az/El lines of sight lie from its elements' (None: nothing to compare)."""
    try:
        offset = columns_offset_deg(stored)
    except ValueError:  # elements SGP4 cannot propagate to the pass: said where the geometry is used
        return None
    return None if offset is None else {"median": offset[0], "max": offset[1]}


def _text(info: dict) -> str:
    site = info["site"]
    state = "current" if info["superseded_by"] is None else f"superseded by {info['superseded_by']}"
    lines = [
        f"pass       {info['pass_id']}  (version {info['version']}, {state}"
        + (f", replaces {info['supersedes']})" if info["supersedes"] else ")"),
        f"object     {info['norad']} {info['name'] or '(no name)'}"
        + (f"  COSPAR {info['cospar']}" if info["cospar"] else ""),
        f"site       {site['name']}  ({site['lat_deg']:.5f} N, {site['lon_deg']:.5f} E, {site['elevation_m']:.0f} m)",
        f"band       {info['band']}   exposure {info['exposure_s']:g} s",
        f"time       {info['start_utc']} .. {info['end_utc']}  ({info['duration_s']:.1f} s; {info['time_convention']})",
        f"points     {info['n_points']}  ({info['n_valid']} valid, {info['n_saturated']} saturated"
        + (f", {len(info['rows_set_aside'])} rows of the file set aside)" if info["rows_set_aside"] else ")"),
    ]
    if info["mag_median"] is not None:
        lines.append(
            f"magnitude  {info['mag_min']:.3f} .. {info['mag_max']:.3f}, median {info['mag_median']:.3f}"
            + ("  (sign-corrected)" if info["has_mag_corrected"] else "")
        )
    if info["range_km_min"] is not None and info["el_deg_min"] is not None:
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
    else:
        lines.append(
            "orbit      no elements: the geometry is a track fitted to the file's Az/El/range columns, "
            "good within the pass; add elements with 'rsodb elements add FILE'"
        )
    offset = info["columns_vs_elements_deg"]
    if offset is not None:
        if offset["median"] <= COLUMNS_AGREE_DEG:
            lines.append(
                f"columns    the file's Az/El agree with the elements: {offset['median']:.4f} deg median, "
                f"{offset['max']:.4f} deg at most"
            )
        else:
            lines.append(
                f"columns    the file's Az/El DISAGREE with the elements by {offset['median']:.2f} deg (median; "
                f"{offset['max']:.2f} at most): they were not computed from this orbit; the geometry uses the elements"
            )
    source = info["elements_source"]
    if isinstance(source, dict):
        lines.append(
            f"elements   from {source.get('file')} ({source.get('where')}), epoch {source.get('epoch_utc')}, "
            f"{source.get('age_days', float('nan')):.1f} days from the pass"
        )
    lines.append(f"source     {info['source_name']}  ({info['source_format']}, sha256 {info['source_sha256'][:16]}...)")
    for item in info["duplicate_sources"]:
        lines.append(
            f"duplicate  {item['source_name']}  (sha256 {item['sha256'][:16]}..., {item['ingested_utc']})"
            + (f": {item['note']}" if item["note"] else "")
        )
    lines.append(f"ingested   {info['ingested_utc']}")
    for warning in info["warnings"]:
        where = f"line {warning['line']}: " if warning["line"] is not None else ""
        lines.append(f"warning    {where}{warning['reason']}")
    rows = info["rows_set_aside"]
    if rows:
        lines.append(f"set aside  {len(rows)} row(s) of {info['source_name']}:")
        for row in rows[:_ROWS_SHOWN]:
            lines.append(f"             line {row['line']}: {row['reason']}")
            lines.append(f"               {row['text'].strip()[:120]}")
        if len(rows) > _ROWS_SHOWN:
            lines.append(f"             ... and {len(rows) - _ROWS_SHOWN} more (--json lists them all)")
    for kind, named in info["results"].items():
        if not named:
            lines.append(f"{kind:<10} none")
        for name, values in named.items():
            lines.extend(_result_lines(kind, name, values))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    try:
        archive = open_archive(args)
        stored = archive.get(args.pass_id)
        results = {
            kind: {
                name: archive.result_values(stored.pass_id, kind, name)
                for name in archive.result_names(stored.pass_id, kind)
            }
            for kind in ("periods", "fits")
        }
        duplicates = archive.duplicate_sources(stored.pass_id)
    except (ValueError, LookupError, OSError) as error:
        return fail("show", error)
    info = describe(stored, results, duplicates)
    print(json.dumps(info, indent=1, ensure_ascii=False) if args.json else _text(info))
    if args.plot:
        rsodb.report.save_pass_plot(stored, args.plot)
    return 0
