"""The fitted spin period in each of the conventions it is quoted in.

A spin period is a rotation rate about the body's spin axis *relative to some frame*, and the
frames differ by a few per cent for a precessing satellite (docs/fitting.md, "Which spin
period?", draws them):

``parameter``
    The fitted ``spin_period_s``: for the ``precessing`` family, the rate of the spin angle psi,
    relative to the *precessing* frame (the frame that carries the spin axis round its cone,
    the project's and the seed paper's convention); for ``inertial``, relative to inertial space.
``orbit_frame``
    Relative to the local orbital frame, which does not precess: ``1 / P_orb = 1 / P + cos(theta)
    / P_pr`` for the precessing family (the spin-axis component of the precession rate; for
    P = 40.5 s, P_pr = 1620 s, theta = 7 deg the rates differ by 2.5%).
``inertial``
    Relative to inertial space (sidereal): the orbit frame's own rotation (one turn per orbit)
    projected on the spin axis is added.
``light_curve``
    The period at which the model's light curve repeats (synodic): relative to the phase-angle
    bisector, which the observer's motion turns during a pass; its mean rate over the window.
``periodogram``
    The period the project's period search (`rsodb.periods.find_period`, with the stored
    search's settings) finds in the model's own light curve at the pass's usable samples: what
    the stored period is, so the two compare like with like. It differs from ``light_curve``
    where the bisector turns unevenly over the pass: a periodogram weighs each part of the pass
    by the signal it holds, the mean rate each second alike (on the real TOPEX pass of
    2024-07-30, 9.4830 s against 9.4842 s for the ladder's topex-inertial rung). It needs no spin axis, so a tumbling body has it too.

Each is computed from the fitted attitude itself, not from a formula per family: on a time grid
over the fitted window (`STEPS_PER_CYCLE` steps per cycle of the fastest spin) the rotation
from one step to the next (exact axis-angle of ``R_i^T R_(i+1)``) is projected on the spin axis
in body coordinates (the body axis ``spin_axis``, or for ``inertial_tilted`` the body direction
leaned from it that stays on the pole) and summed; for ``light_curve`` the bisector's azimuth
about that axis is unwrapped.
Posterior draws give each convention's median and 16/84 percentiles.
"""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
from scipy.spatial.transform import Rotation

from rsodb.fit.curves import geometry_at
from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.search import find_period

__all__ = [
    "CONVENTIONS",
    "PERIODOGRAM_DRAWS",
    "comparable_convention",
    "fit_conventions",
    "periodogram_period",
    "spin_periods",
    "rates_hz",
    "angle_steps_about",
    "bisector_azimuth",
    "azimuth_elevation",
]

CONVENTIONS = {
    "parameter": "the fitted spin_period_s (precessing: relative to the precessing frame; inertial: sidereal)",
    "orbit_frame": "relative to the local orbital frame (not precessing): 1/P_orb = 1/P + cos(theta)/P_pr",
    "inertial": "relative to inertial space (sidereal): the orbit frame's rotation about the spin axis added",
    "light_curve": "the light curve's repeat period (synodic: relative to the Sun-observer bisector)",
    "periodogram": "the period search's period of the model's light curve at the pass's samples (compare with the stored period)",
}
# Posterior draws whose model light curves are period-searched (each costs one light curve at
# the pass's samples and one search, ~0.12 s on the whole TOPEX pass). 24 drew the 16-84% range
# of the whole-TOPEX-pass fit 35% narrower than 120 draws did (4.2 against 2.6 sigma from the
# data's period); 64 keep it within ~10%.
PERIODOGRAM_DRAWS = 64
# A period within 15% of a power-of-2 multiple of another counts as that harmonic: a short fit's
# draws scatter by several per cent (37-40 s on the main job's COSMOS 2502 quick fit), while a
# third harmonic (3x, 3/2x, 3/4x) is 33% from the nearest power of 2 (2^0.415).
_OCTAVE_TOLERANCE = math.log2(1.15)
STEPS_PER_CYCLE = 24
_MAX_STEPS = 20_000
_AXES = {"x": 0, "y": 1, "z": 2}


def _about(axis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, e1, e2): the unit spin direction in body coordinates and a right-handed basis of its
    equator (u = e1 x e2). ``axis`` is a body axis index or a (3,) direction; e1 is the body axis
    after the one nearest to u, made perpendicular to it, so for a body axis e1, e2 are the next
    two in cyclic order (x -> y, z)."""
    eye = np.eye(3)
    u = eye[int(axis)] if isinstance(axis, (int, np.integer)) else np.asarray(axis, dtype=float)
    u = u / np.linalg.norm(u)
    hint = eye[(int(np.argmax(np.abs(u))) + 1) % 3]
    e1 = hint - (hint @ u) * u
    e1 /= np.linalg.norm(e1)
    return u, e1, np.cross(u, e1)


def angle_steps_about(rotations: np.ndarray, axis) -> np.ndarray:
    """(n-1,) rotation angle (rad) about a body direction between consecutive (n, 3, 3)
    body-to-frame rotations: the axis-angle vector of ``R_i^T R_(i+1)`` projected on it.
    ``axis``: a body axis index or a (3,) direction in body coordinates."""
    step = np.einsum("nji,njk->nik", rotations[:-1], rotations[1:])
    return Rotation.from_matrix(step).as_rotvec() @ _about(axis)[0]


def bisector_azimuth(rotations: np.ndarray, geometry, axis) -> np.ndarray:
    """(n,) unwrapped azimuth (rad) of the Sun-observer bisector about a body direction, right-handed.

    Parameters
    ----------
    rotations : (n, 3, 3) float
        Body-to-GCRS rotations at the geometry's times.
    geometry : PassGeometry
        One sub-sample per time.
    axis : int or (3,) float
        0, 1, 2 for body x, y, z, or a direction in body coordinates (a tilted spin axis).
    """
    bisector = np.einsum("nji,nj->ni", rotations, geometry.sun_gcrs[:, 0] + geometry.obs_gcrs[:, 0])
    _, first, second = _about(axis)
    return np.unwrap(np.arctan2(bisector @ second, bisector @ first))


def azimuth_elevation(vectors: np.ndarray, axis) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth (0-360 deg, right-handed about `axis`) and elevation (deg toward `axis`) of body vectors.

    The azimuth is counted in the axis's equator from the same first direction as
    `bisector_azimuth` (for body z: from +x toward +y).

    Parameters
    ----------
    vectors : (n, 3) float
        Directions in body coordinates (need not be unit).
    axis : int or (3,) float
        0, 1, 2 for body x, y, z, or a direction in body coordinates.
    """
    up, first, second = _about(axis)
    v = np.asarray(vectors, dtype=float)
    v = v / np.linalg.norm(v, axis=-1, keepdims=True)
    azimuth = np.degrees(np.arctan2(v @ second, v @ first)) % 360.0
    return azimuth, np.degrees(np.arcsin(np.clip(v @ up, -1.0, 1.0)))


def rates_hz(model, values, geometry, axis: str) -> dict[str, float]:
    """Mean rotation rates (turns per second) about the spin axis in each convention.

    Parameters
    ----------
    model : SpinStateModel
    values : mapping
        Parameter values.
    geometry : PassGeometry
        A fine time grid over the window, one sub-sample per time.
    axis : {"x", "y", "z"}
        The family's body spin axis; where the attitude leans the spin axis away from it
        (``inertial_tilted``), the rates are about the leaning axis (its ``spin_direction_body``).
    """
    attitude = model.on(geometry).attitude_model(values)
    k = getattr(attitude, "spin_direction_body", _AXES[axis])
    lvlh = geometry.lvlh_gcrs[:, 0]
    rotations = attitude.orientation(geometry.t_s, lvlh)
    span = float(geometry.t_s[-1] - geometry.t_s[0])
    inertial = float(np.sum(angle_steps_about(rotations, k))) / span
    relative = np.einsum("nji,njk->nik", lvlh, rotations)
    orbit = float(np.sum(angle_steps_about(relative, k))) / span
    azimuth = bisector_azimuth(rotations, geometry, k)
    light = -float(azimuth[-1] - azimuth[0]) / span
    turn = 2 * math.pi
    return {"orbit_frame": orbit / turn, "inertial": inertial / turn, "light_curve": light / turn}


def fit_conventions(fit) -> dict:
    """The spin period's conventions a fit result stored (``{name: {median, p16, p84, ...}}``),
    {} for a fit without them."""
    return dict(getattr(fit, "spin_periods", {}) or {}).get("conventions", {})


def comparable_convention(conventions) -> str | None:
    """The convention to compare with the stored period search: ``periodogram`` where a fit has
    it, else ``light_curve`` (fits stored before it); None when it has neither (a tumbling body's
    older fit)."""
    return next((name for name in ("periodogram", "light_curve") if name in conventions), None)


def periodogram_period(
    model, space, draws, observed, n_sub: int, fastest_period_s: float, settings=None
) -> dict | None:
    """The ``periodogram`` convention: the period search run on the model's light curve, per draw.

    Parameters
    ----------
    model : SpinStateModel
        The fitted forward model (its epoch is kept).
    space : ParameterSpace
    draws : (d, ndim) float
        Posterior draws (`PERIODOGRAM_DRAWS` are plenty).
    observed : Pass
        The pass: the model is evaluated at its usable samples (`LightCurve.from_pass`, those
        the stored search used) with its exposure, and searched with its errors.
    n_sub : int
        Exposure sub-samples of the model's light curve.
    fastest_period_s : float
        The prior's fastest spin (for the geometry's sub-sampling when `n_sub` is 0).
    settings : PeriodSettings, optional
        The stored search's settings (default: the search's own).

    Returns
    -------
    dict or None
        ``{median, p16, p84, share}`` over the draws whose curve gave a period; None when none
        did. A short pass's model curve can repeat almost as well at half the turn, so the
        search finds P in some draws and P/2 in others: every draw is brought to the multiple
        (a power of 2 apart) that most draws found, and ``share`` says how many found it; a
        period no power of 2 from the others (a third harmonic) stays as found.
    """
    data = LightCurve.from_pass(observed)
    times = observed.start_utc + (data.t_s * 1e9).round().astype("int64").astype("timedelta64[ns]")
    on_samples = model.on(geometry_at(observed, times, observed.exposure_s, n_sub or None, fastest_period_s))
    found = []
    for theta in np.asarray(draws, dtype=float):
        with np.errstate(divide="ignore"):
            mag = on_samples.magnitudes(space.values(theta))
        lit = np.isfinite(mag)  # a dark sample (the body in shadow) has no magnitude
        if lit.sum() < 2:
            continue
        curve = replace(data, t_s=data.t_s[lit], mag=mag[lit], mag_err=data.mag_err[lit])
        period = find_period(curve, settings=settings).best_period_s
        if math.isfinite(period):
            found.append(period)
    if not found:
        return None
    found = np.array(found)
    aligned, share = _to_modal_octave(found)
    return _summary(aligned) | {"share": share}


def _to_modal_octave(found: np.ndarray) -> tuple[np.ndarray, float]:
    """`found` periods brought to the power-of-2 multiple (P, P/2, 2P, ...) that most of them are
    at, and the share that is there. Octaves are counted from the found period with the most
    others a power of 2 away (within `_OCTAVE_TOLERANCE`); a period that is none of them stays as
    found: scaled, it would land on a wrong value."""
    # (n, n): the octaves of every found period from every other (n is a few dozen draws).
    octaves = np.log2(found[None, :] / found[:, None])
    harmonic_pairs = np.abs(octaves - np.round(octaves)) < _OCTAVE_TOLERANCE
    reference = int(np.argmax(harmonic_pairs.sum(axis=1)))
    harmonic = harmonic_pairs[reference]
    octave = np.round(octaves[reference]).astype(int)
    values, counts = np.unique(octave[harmonic], return_counts=True)
    modal = values[np.argmax(counts)]
    aligned = np.where(harmonic, found * 2.0 ** (modal - octave), found)
    return aligned, float(counts.max() / found.size)


def _summary(periods: np.ndarray) -> dict:
    p16, median, p84 = np.percentile(periods, [16, 50, 84])
    return {"median": float(median), "p16": float(p16), "p84": float(p84)}


def spin_periods(model, space, draws, observed, window_time_utc, attitude: str, axis: str, periods=None) -> dict:
    """The spin period in every convention, over posterior draws.

    Parameters
    ----------
    model : SpinStateModel
        The fitted forward model (any times; its epoch is kept).
    space : ParameterSpace
    draws : (d, ndim) float
        Posterior draws (a few hundred are plenty).
    observed : Pass
        For the orbit and site.
    window_time_utc : (2,) datetime64
        First and last sample of the fitted window.
    attitude : str
        The attitude family.
    axis : str
        The body spin axis (precessing, inertial).
    periods : PeriodResult, optional
        The stored period, quoted beside the light-curve convention.

    Returns
    -------
    dict
        ``{"attitude", "spin_axis", "definitions", "conventions": {name: {median, p16, p84}},
        "periodogram_period_s", "periodogram_uncertainty_s"}``; ``conventions`` holds only
        ``parameter`` for a tumbling (torque-free) body, whose spin axis moves in the body.
    """
    draws = np.asarray(draws, dtype=float)
    values = [space.values(theta) for theta in draws]
    parameter = np.array([v["spin_period_s"] for v in values])
    record = {
        "attitude": attitude,
        "spin_axis": axis if attitude != "torque_free" else None,
        "definitions": dict(CONVENTIONS),
        "conventions": {"parameter": _summary(parameter)},
        "periodogram_period_s": None,
        "periodogram_uncertainty_s": None,
    }
    if periods is not None and math.isfinite(periods.best_period_s):
        record["periodogram_period_s"] = float(periods.best_period_s)
        record["periodogram_uncertainty_s"] = float(periods.uncertainty_s)
    if attitude == "torque_free":
        return record
    start, end = (np.datetime64(t, "ns") for t in window_time_utc)
    span_s = float((end - start) / np.timedelta64(1, "s"))
    fastest = float(np.min(np.abs(parameter)))
    count = int(min(_MAX_STEPS, max(16, math.ceil(span_s / fastest * STEPS_PER_CYCLE) + 1)))
    times = start + (np.linspace(0.0, span_s, count) * 1e9).round().astype("int64").astype("timedelta64[ns]")
    geometry = geometry_at(observed, times, 0.0, 1, None)
    rates = [rates_hz(model, v, geometry, axis) for v in values]
    for name in ("orbit_frame", "inertial", "light_curve"):
        record["conventions"][name] = _summary(np.array([1.0 / r[name] for r in rates]))
    return record
