"""The period of an observed pass: its light curve, the period search and the synodic correction."""

from __future__ import annotations

from dataclasses import replace
import math

from raycast.geometry import PassGeometry, Satellite
from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.search import PeriodResult, PeriodSettings, find_period
from rsodb.periods.synodic import SynodicCorrection

__all__ = ["analyse_pass"]


def analyse_pass(pass_, settings: PeriodSettings | None = None, *, geometry: bool = True) -> PeriodResult:
    """`find_period` on a pass, with the pass geometry for the synodic correction when possible.

    Parameters
    ----------
    pass_ : ingest.observation.Pass or rsodb.archive.StoredPass
    settings : PeriodSettings, optional
    geometry : bool
        Compute the geometry from the pass's TLE/OMM (`raycast.geometry.PassGeometry.from_pass`).
        A pass without elements gets no sidereal period, and the result says why.

    Returns
    -------
    PeriodResult
    """
    lc = LightCurve.from_pass(pass_)
    result = find_period(lc, settings=settings)
    if not geometry or not math.isfinite(result.best_period_s):
        return result if geometry else replace(result, synodic_note="geometry not requested")
    try:
        pass_geometry = PassGeometry.from_pass(pass_, n_sub=1)
    except (ValueError, TypeError) as error:
        return replace(result, synodic_note=f"no geometry: {error}")
    # Without elements the geometry is a track fitted to the file's Az/El/range columns: say so.
    note = "" if isinstance(pass_geometry.satellite, Satellite) else f"geometry: {pass_geometry.satellite.description}"
    return replace(
        result, synodic=SynodicCorrection.from_geometry(result.best_period_s, pass_geometry), synodic_note=note
    )
