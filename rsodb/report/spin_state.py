"""A fitted spin state in words and table rows: the spin period in each convention, the axis
(precession cone or inertial pole) and every other parameter, each with its 16-84% interval.

>>> interval(9.8237, 9.8221, 9.8260)
'9.824 -0.0016 +0.0023'
"""

from __future__ import annotations

import math

from rsodb.fit.conventions import fit_conventions
from rsodb.fit.parameters import describe

__all__ = ["interval", "spin_state_rows", "axis_text", "convention_interval"]

# The quantities a reader looks for first, in this order; the rest follow as fitted.
_FIRST = (
    "spin_period_s",
    "precession_period_s",
    "precession_angle_deg",
    "pole_ra_deg",
    "pole_dec_deg",
)


def interval(median: float, p16: float, p84: float, digits: int = 4) -> str:
    """``median -lower +upper`` with `digits` significant digits on the median."""
    if not all(math.isfinite(v) for v in (median, p16, p84)):
        return "-"
    return f"{median:.{digits}g} -{median - p16:.2g} +{p84 - median:.2g}"


def convention_interval(fit, convention: str) -> str:
    """The spin period in one convention (`rsodb.fit.conventions`) as an interval, or '-' (also
    for ``convention=None``)."""
    value = fit_conventions(fit).get(convention)
    return "-" if value is None else interval(value["median"], value["p16"], value["p84"], digits=6)


def _parameter(fit, name: str):
    """(median, p16, p84) of a free parameter, (value, value, value) of a fixed one, or None."""
    if name in fit.names:
        i = fit.names.index(name)
        return fit.median[i], fit.p16[i], fit.p84[i]
    if name in fit.space.fixed:
        value = float(fit.space.fixed[name])
        return value, value, value
    return None


def axis_text(fit) -> str:
    """The spin axis in a few words: the precession cone, an inertial pole, or '-'."""
    parts = []
    for name, label, unit in (
        ("precession_period_s", "P_pr", "s"),
        ("precession_angle_deg", "cone", "deg"),
        ("pole_ra_deg", "pole RA", "deg"),
        ("pole_dec_deg", "Dec", "deg"),
        ("axis_tilt_deg", "tilted", "deg"),
    ):
        value = _parameter(fit, name)
        if value is not None:
            fixed = name not in fit.names
            parts.append(
                f"{label} {value[0]:.4g}{' (fixed)' if fixed else ' +-' + format(0.5 * (value[2] - value[1]), '.2g')} {unit}"
            )
    return ", ".join(parts) or "-"


def spin_state_rows(fit) -> list[tuple[str, str, str, str]]:
    """(quantity, median -/+ 16-84%, unit, meaning) of every parameter, then the spin period in
    each convention the fit computed."""
    names = [n for n in _FIRST if n in fit.names or n in fit.space.fixed]
    names += [n for n in fit.names if n not in names]
    names += [n for n in fit.space.fixed if n not in names]
    rows = []
    for name in names:
        known = describe(name)
        median, low, high = _parameter(fit, name)
        value = interval(median, low, high, digits=6) if name in fit.names else f"{median:.6g} (fixed)"
        rows.append((name, value, known.unit, known.description))
    spin = dict(getattr(fit, "spin_periods", {}) or {})
    definitions = spin.get("definitions", {})
    for convention in spin.get("conventions", {}):
        rows.append(
            (f"spin period ({convention})", convention_interval(fit, convention), "s", definitions.get(convention, ""))
        )
    return rows
