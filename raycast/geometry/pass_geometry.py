"""Pass geometry: where the satellite, the observer and the Sun are, as arrays over time.

`PassGeometry.compute` (or `PassGeometry.from_pass`) gives every frame's geometry in one
vectorised call: SGP4 positions, Earth orientation and the apparent Sun interpolated from
skyfield nodes, topocentric Az/El with refraction, range, phase angle, Earth shadow, the local
orbital frame and exposure sub-samples. docs/geometry.md states every frame, convention and
approximation, with the measured errors against skyfield.

Examples
--------
>>> import numpy as np
>>> from raycast.geometry.orbit import Satellite
>>> from ingest.site import DERENIVKA
>>> from raycast.geometry import PassGeometry
>>> sat = Satellite.from_tle([
...     "1 22076U 92052A   24212.51246405 -.00000054  00000-0  29042-4 0  9994",
...     "2 22076  66.0414 118.8147 0008045 267.5347 265.0431 12.81066660495523"])
>>> times = np.datetime64("2024-07-30T21:22:40.008849") + np.arange(3) * np.timedelta64(200, "ms")
>>> geometry = PassGeometry.compute(sat, DERENIVKA, times, exposure_s=0.2)
>>> geometry.sun_gcrs.shape, geometry.weights.tolist()
((3, 4, 3), [0.25, 0.25, 0.25, 0.25])
>>> geometry.el_refracted_deg.round(2).tolist()
[16.84, 16.85, 16.86]
"""

from __future__ import annotations

from dataclasses import dataclass, fields
import math

import numpy as np
from sgp4.api import SGP4_ERRORS
from skyfield.framelib import itrs
from skyfield.sgp4lib import TEME

from ingest.site import Site
from raycast.geometry import ephemeris
from raycast.geometry.orbit import Satellite
from raycast.geometry.refraction import apparent_elevation_deg, true_elevation_deg
from raycast.geometry.rotations import rot_z
from raycast.geometry.shadow import sunlit_fraction
from raycast.geometry.track import ObservedTrack, track_site

__all__ = [
    "PassGeometry",
    "BodyGeometry",
    "DEFAULT_SPIN_PERIOD_S",
    "MAX_SUBSAMPLE_TURN_DEG",
    "MAX_N_SUB",
    "NODE_SPACING_S",
    "choose_n_sub",
    "orbit_of",
    "orbit_problem",
    "track_of",
    "columns_offset_deg",
    "COLUMNS_AGREE_DEG",
]

DEFAULT_SPIN_PERIOD_S = 10.0
MAX_SUBSAMPLE_TURN_DEG = 2.0
MAX_N_SUB = 64
NODE_SPACING_S = 60.0

_UNIX_EPOCH_JD = 2440587.5
_J2000_JD = 2451545.0
_TT_MINUS_TAI_S = 32.184
_ERA_AT_J2000_TURNS = 0.7790572732640  # IAU 2000 Earth rotation angle, turns
_ERA_RATE_EXCESS = 0.00273781191135448  # turns per UT1 day beyond one
_ERA_RATE_RAD_S = 2.0 * math.pi * (1.0 + _ERA_RATE_EXCESS) / 86400.0
# Times must lie inside DE421 (1899-07-29 .. 2053-10-09) and the UTC leap-second era.
_FIRST_TIME = np.datetime64("1972-01-01", "ns")
_LAST_TIME = np.datetime64("2053-10-01", "ns")


def choose_n_sub(
    exposure_s: float, spin_period_s: float | None = None, max_turn_deg: float = MAX_SUBSAMPLE_TURN_DEG
) -> int:
    """Number of exposure sub-samples so the body turns at most `max_turn_deg` (2) per sub-sample.

    Parameters
    ----------
    exposure_s : float
        Exposure time, seconds (0 gives 1).
    spin_period_s : float, optional
        Expected spin period (its sign is ignored); `DEFAULT_SPIN_PERIOD_S` when None.
    max_turn_deg : float
        Largest turn per sub-sample, degrees.

    Returns
    -------
    int
        ``ceil(360 * exposure_s / (|spin_period_s| * max_turn_deg))`` within
        [1, `MAX_N_SUB`].

    Examples
    --------
    >>> choose_n_sub(0.2), choose_n_sub(0.1), choose_n_sub(1.0, spin_period_s=40.0), choose_n_sub(0.0)
    (4, 2, 5, 1)
    """
    period = DEFAULT_SPIN_PERIOD_S if spin_period_s is None else abs(float(spin_period_s))
    if exposure_s <= 0.0 or not math.isfinite(period) or period == 0.0:
        return 1
    turn_deg = 360.0 * exposure_s / period
    # Round away float noise: 0.1 s at 9 s turns exactly 4 deg, i.e. 2 slices, not 2.0000000000000004.
    return int(min(max(math.ceil(round(turn_deg / max_turn_deg, 9)), 1), MAX_N_SUB))


@dataclass(frozen=True, eq=False)
class BodyGeometry:
    """Sun and observer directions in the satellite's body frame: all the renderer needs.

    Attributes
    ----------
    sun_body : (n, k, 3) float
        Unit vectors from the satellite toward the Sun, body frame, per exposure sub-sample.
    obs_body : (n, k, 3) float
        Unit vectors from the satellite toward the observer, body frame.
    weights : (k,) float
        Exposure weights of the sub-samples, summing to 1.
    sunlit : (n, k) float
        Visible fraction of the solar disk (Earth shadow) per sub-sample.
    range_km : (n,) float
        Observer-satellite distance at the observed times, km.
    phase_angle_deg : (n,) float
        Sun-satellite-observer angle at the observed times, degrees.
    """

    sun_body: np.ndarray
    obs_body: np.ndarray
    weights: np.ndarray
    sunlit: np.ndarray
    range_km: np.ndarray
    phase_angle_deg: np.ndarray

    def __post_init__(self):
        _freeze(self)


@dataclass(frozen=True, eq=False)
class PassGeometry:
    """Geometry of one pass over one site, per observed time and per exposure sub-sample.

    Build it with `compute` (or `from_pass`); it is immutable. ``n`` observed times,
    ``k`` sub-samples per exposure.

    Attributes
    ----------
    satellite : Satellite or ObservedTrack
        The propagated element set, or the track fitted to the file's own Az/El/range columns
        (`orbit_of`).
    site : Site
        The observer.
    exposure_s : float
        Exposure time the sub-samples span, seconds.
    time_utc : (n,) datetime64[ns]
        Observed (mid-exposure) times, UTC.
    t_s : (n,) float
        Seconds since ``time_utc[0]``.
    sat_gcrs_km, sat_itrs_km : (n, 3) float
        Satellite position, geocentric, in GCRS and ITRS, km.
    az_deg : (n,) float
        Topocentric azimuth, from north through east, degrees in [0, 360).
    el_deg : (n,) float
        Geometric topocentric elevation, degrees.
    el_refracted_deg : (n,) float
        Apparent elevation with PyEphem's refraction (1010 mbar, 15 C), degrees.
    range_km : (n,) float
        Observer-satellite distance, km.
    range_rate_km_s : (n,) float
        Time derivative of the range, km/s (positive when receding).
    phase_angle_deg : (n,) float
        Angle at the satellite between the Sun and the observer, degrees.
    airmass : (n,) float
        Plane-parallel airmass 1 / sin(el_refracted) (the reduction's X = 1 / cos z); NaN at
        or below the horizon.
    sunlit_fraction : (n,) float
        Visible fraction of the solar disk, 0 (umbra) .. 1 (`raycast.geometry.shadow`).
    sub_t_s : (n, k) float
        Sub-sample times, seconds since ``time_utc[0]``.
    sun_gcrs : (n, k, 3) float
        Unit vectors from the satellite toward the Sun, GCRS.
    obs_gcrs : (n, k, 3) float
        Unit vectors from the satellite toward the observer, GCRS.
    lvlh_gcrs : (n, k, 3, 3) float
        Local orbital frame, columns x (along-track), y (-orbit normal), z (nadir) in GCRS
        (see the module docstring).
    sub_sunlit : (n, k) float
        Visible fraction of the solar disk per sub-sample.
    weights : (k,) float
        Sub-sample weights (1 / k each), summing to 1.
    """

    satellite: Satellite
    site: Site
    exposure_s: float
    time_utc: np.ndarray
    t_s: np.ndarray
    sat_gcrs_km: np.ndarray
    sat_itrs_km: np.ndarray
    az_deg: np.ndarray
    el_deg: np.ndarray
    el_refracted_deg: np.ndarray
    range_km: np.ndarray
    range_rate_km_s: np.ndarray
    phase_angle_deg: np.ndarray
    airmass: np.ndarray
    sunlit_fraction: np.ndarray
    sub_t_s: np.ndarray
    sun_gcrs: np.ndarray
    obs_gcrs: np.ndarray
    lvlh_gcrs: np.ndarray
    sub_sunlit: np.ndarray
    weights: np.ndarray

    def __post_init__(self):
        _freeze(self)

    # -- construction --------------------------------------------------------------------
    @classmethod
    def compute(
        cls,
        satellite: Satellite,
        site: Site,
        time_utc,
        exposure_s: float = 0.0,
        n_sub: int | None = None,
        spin_period_s: float | None = None,
    ) -> PassGeometry:
        """Compute the geometry of a pass for all times in one vectorised call.

        Parameters
        ----------
        satellite : Satellite or ObservedTrack
            The element set to propagate, or a track fitted to a file's Az/El/range columns.
        site : Site
            The observer.
        time_utc : (n,) datetime64 or astropy.time.Time
            Observed times, UTC, mid-exposure.
        exposure_s : float or astropy Quantity
            Exposure time, seconds; 0 disables exposure integration (k = 1).
        n_sub : int, optional
            Sub-samples per exposure; chosen by `choose_n_sub` from `exposure_s` and
            `spin_period_s` when None.
        spin_period_s : float or astropy Quantity, optional
            Expected spin period, used only to choose `n_sub` (default 10 s).

        Returns
        -------
        PassGeometry

        Raises
        ------
        TypeError, ValueError
            For arguments of the wrong kind or out of range, and for times at which SGP4
            fails (e.g. after the object decayed).
        """
        if not isinstance(satellite, (Satellite, ObservedTrack)):
            raise TypeError(
                f"satellite must be a raycast.geometry.orbit.Satellite or a raycast.geometry.track.ObservedTrack, "
                f"got {type(satellite).__name__}; build one with Satellite.from_tle(lines) or Satellite.from_omm(record)"
            )
        if not isinstance(site, Site):
            raise TypeError(
                f"site must be a ingest.site.Site, got {type(site).__name__}; use e.g. ingest.site.DERENIVKA"
            )
        times = _as_utc_ns(time_utc)
        exposure_s = _as_seconds(exposure_s)
        if not (math.isfinite(exposure_s) and exposure_s >= 0.0):
            raise ValueError(f"exposure_s={exposure_s!r} must be a finite number of seconds >= 0")
        if spin_period_s is not None:
            spin_period_s = _as_seconds(spin_period_s)
            if spin_period_s == 0.0 or math.isnan(spin_period_s):
                raise ValueError(f"spin_period_s={spin_period_s!r} must be a non-zero number of seconds or None")
        if n_sub is None:
            k = choose_n_sub(exposure_s, spin_period_s)
        elif isinstance(n_sub, (int, np.integer)) and not isinstance(n_sub, bool) and 1 <= n_sub <= 4096:
            k = int(n_sub)
        else:
            raise ValueError(f"n_sub={n_sub!r} must be a whole number from 1 to 4096, or None to choose it")
        if exposure_s == 0.0:
            k = 1  # all sub-samples would coincide
        return _compute(satellite, site, times, exposure_s, k)

    @classmethod
    def from_pass(
        cls, observed, n_sub: int | None = None, spin_period_s: float | None = None, samples=None
    ) -> PassGeometry:
        """Geometry at the observed times of a pass, from its orbit (`orbit_of`).

        Parameters
        ----------
        observed : ingest.observation.Pass
            Any object with ``tle`` or ``omm``, ``site``, ``time_utc`` and ``exposure_s``.
        n_sub, spin_period_s
            As in `compute`.
        samples : (m,) int or (n,) bool, optional
            Only these samples of the pass (indices or a mask); default all.

        Returns
        -------
        PassGeometry
        """
        times = observed.time_utc if samples is None else observed.time_utc[np.asarray(samples)]
        return cls.compute(
            orbit_of(observed), observed.site, times, observed.exposure_s, n_sub=n_sub, spin_period_s=spin_period_s
        )

    # -- views ---------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of observed times."""
        return self.t_s.shape[0]

    @property
    def n_sub(self) -> int:
        """Sub-samples per exposure, k."""
        return self.weights.shape[0]

    def body_frame(self, attitude) -> BodyGeometry:
        """Sun and observer directions in the body frame of an attitude model.

        Parameters
        ----------
        attitude : object with ``orientation(t_s, lvlh_gcrs=None) -> (..., 3, 3)``
            Body-to-GCRS rotations (see `raycast.geometry.attitude`); called once with `sub_t_s`
            and `lvlh_gcrs`.

        Returns
        -------
        BodyGeometry
        """
        rotation = attitude.orientation(self.sub_t_s, self.lvlh_gcrs)
        if np.shape(rotation) != self.lvlh_gcrs.shape:
            raise ValueError(
                f"{type(attitude).__name__}.orientation returned shape {np.shape(rotation)}, "
                f"expected {self.lvlh_gcrs.shape}; it must give one 3x3 rotation per time"
            )
        # v_body = R^T v_gcrs for every sub-sample: one batched product per direction.
        sun_body = np.einsum("...ji,...j->...i", rotation, self.sun_gcrs)
        obs_body = np.einsum("...ji,...j->...i", rotation, self.obs_gcrs)
        return BodyGeometry(sun_body, obs_body, self.weights, self.sub_sunlit, self.range_km, self.phase_angle_deg)

    def to_pandas(self):
        """The per-time columns as a ``pandas.DataFrame`` indexed by ``time_utc``."""
        # pandas costs about half a second to import; only this conversion needs it.
        import pandas as pd

        columns = [
            "t_s",
            "az_deg",
            "el_deg",
            "el_refracted_deg",
            "range_km",
            "range_rate_km_s",
            "phase_angle_deg",
            "airmass",
            "sunlit_fraction",
        ]
        return pd.DataFrame(
            {name: getattr(self, name) for name in columns}, index=pd.DatetimeIndex(self.time_utc, name="time_utc")
        )


def orbit_of(observed) -> Satellite | ObservedTrack:
    """The orbit a pass's geometry comes from: its TLE or OMM, else its own Az/El/range columns.

    Parameters
    ----------
    observed : ingest.observation.Pass or rsodb.archive.StoredPass
        Any object with ``tle`` or ``omm``, or with ``time_utc``, ``az_deg``, ``el_deg``,
        ``range_km``, ``site`` and ``norad`` (`track_of`).

    Raises
    ------
    ValueError
        When the pass has neither elements nor usable Az/El/range columns.
    """
    if getattr(observed, "tle", None):
        return Satellite.from_tle(observed.tle)
    if getattr(observed, "omm", None):
        return Satellite.from_omm(observed.omm)
    if getattr(observed, "az_deg", None) is None:
        name = getattr(observed, "pass_id", None) or getattr(observed, "source_name", observed)
        raise ValueError(
            f"pass {name!r} carries no orbital elements (neither a TLE nor an OMM record) and no Az/El/range "
            "columns, so it has no geometry: add elements with 'rsodb elements add TLE_FILE', or build a "
            "Satellite and call PassGeometry.compute"
        )
    return track_of(observed)


def orbit_problem(observed) -> str:
    """Why a pass has no orbit (`orbit_of` fails), or "" when it has one."""
    try:
        orbit_of(observed)
    except ValueError as error:
        return str(error)
    return ""


def _line_of_sight(az_deg: np.ndarray, el_deg: np.ndarray) -> np.ndarray:
    """(3, n) east, north, up unit vectors toward azimuths (from north through east) and elevations."""
    a, e = np.radians(az_deg), np.radians(el_deg)
    return np.array([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)])


def track_of(observed) -> ObservedTrack:
    """The track (`raycast.geometry.track.ObservedTrack`) of a pass's own Az/El/range columns.

    Rows with a non-finite column are skipped; the elevation loses PyEphem's refraction (the
    lab's writers include it); the columns are taken for the site they were computed for
    (`track_site`) and rotated into GCRS at each row's time.

    Raises
    ------
    ValueError
        With too few usable rows, or columns that are not a smooth orbit.
    """
    label = getattr(observed, "pass_id", None) or getattr(observed, "source_name", "") or "the pass"
    times = np.asarray(observed.time_utc, dtype="datetime64[ns]")
    az, el, rg = (np.asarray(a, dtype=float) for a in (observed.az_deg, observed.el_deg, observed.range_km))
    usable = np.isfinite(az) & np.isfinite(el) & np.isfinite(rg) & (rg > 0.0) & ~np.isnat(times)
    order = np.flatnonzero(usable)[np.argsort(times[usable], kind="stable")]
    times, az, el, rg = times[order], az[order], el[order], rg[order]
    site = track_site(observed)
    if times.size:
        enu = _line_of_sight(az, true_elevation_deg(el)) * rg
        gcrs = _EarthFrames.at(times).itrs_to_gcrs(site.itrs_km[:, None] + site.enu_itrs @ enu)
    else:
        gcrs = np.zeros((3, 0))
    return ObservedTrack.fit(
        times,
        gcrs,
        site,
        name=str(getattr(observed, "name", "") or f"NORAD {observed.norad}"),
        norad=int(observed.norad),
        label=str(label),
        exposure_s=float(getattr(observed, "exposure_s", 0.0) or 0.0),
    )


# Lines of sight of a file's columns and of its elements further apart than this (median) mean
# the columns were not computed from that orbit (PyEphem from the same TLE: ~0.002 deg).
COLUMNS_AGREE_DEG = 0.1


def columns_offset_deg(observed) -> tuple[float, float] | None:
    """(median, max) angle, degrees, between the lines of sight of a pass's own Az/El columns and
    those of its orbital elements at the same times; None without elements or columns.

    The columns are taken for the site they were computed for (`raycast.geometry.track.track_site`)
    with PyEphem's refraction removed. The lab's writers compute them from the header TLE, so a
    median above `COLUMNS_AGREE_DEG` says they describe another orbit (the geometry uses the
    elements).
    """
    if not (getattr(observed, "tle", None) or getattr(observed, "omm", None)):
        return None
    az, el = np.asarray(observed.az_deg, dtype=float), np.asarray(observed.el_deg, dtype=float)
    usable = np.isfinite(az) & np.isfinite(el)
    if not usable.any():
        return None
    geometry = PassGeometry.compute(orbit_of(observed), track_site(observed), observed.time_utc[usable], 0.0, n_sub=1)
    columns = _line_of_sight(az[usable], true_elevation_deg(el[usable]))
    cosine = np.clip(np.sum(columns * _line_of_sight(geometry.az_deg, geometry.el_deg), axis=0), -1.0, 1.0)
    angle = np.degrees(np.arccos(cosine))
    return float(np.median(angle)), float(angle.max())


# -- the computation ----------------------------------------------------------------------
def _compute(satellite: Satellite, site: Site, times: np.ndarray, exposure_s: float, k: int) -> PassGeometry:
    n = times.shape[0]
    offsets_s = exposure_s * ((np.arange(k) + 0.5) / k - 0.5) if k > 1 else np.zeros(1)
    offsets_ns = np.round(offsets_s * 1e9).astype("int64")
    if k == 1:
        every = times  # the sub-sample is the observed time itself
    else:
        every = np.concatenate([times, (times[:, None] + offsets_ns.astype("timedelta64[ns]")).ravel()])
    state = _state_at(satellite, site, every)

    def observed(a):
        return a[:n]

    def per_sub(a):
        start = 0 if k == 1 else n
        return a[start : start + n * k].reshape((n, k) + a.shape[1:])

    t0 = times[0]
    t_s = (times - t0) / np.timedelta64(1, "s")
    el_deg = observed(state["el_deg"])
    el_refracted = apparent_elevation_deg(el_deg)
    with np.errstate(divide="ignore", invalid="ignore"):
        airmass = np.where(el_refracted > 0.0, 1.0 / np.sin(np.radians(el_refracted)), np.nan)
    sun_dir, obs_dir = state["sun_dir"], state["obs_dir"]
    phase_deg = np.degrees(np.arccos(np.clip(np.sum(observed(sun_dir) * observed(obs_dir), axis=-1), -1.0, 1.0)))
    return PassGeometry(
        satellite=satellite,
        site=site,
        exposure_s=exposure_s,
        time_utc=times,
        t_s=t_s,
        sat_gcrs_km=observed(state["sat_gcrs_km"]),
        sat_itrs_km=observed(state["sat_itrs_km"]),
        az_deg=observed(state["az_deg"]),
        el_deg=el_deg,
        el_refracted_deg=el_refracted,
        range_km=observed(state["range_km"]),
        range_rate_km_s=observed(state["range_rate_km_s"]),
        phase_angle_deg=phase_deg,
        airmass=airmass,
        sunlit_fraction=observed(state["sunlit"]),
        sub_t_s=t_s[:, None] + offsets_ns[None, :] / 1e9,
        sun_gcrs=per_sub(sun_dir),
        obs_gcrs=per_sub(obs_dir),
        lvlh_gcrs=per_sub(state["lvlh_gcrs"]),
        sub_sunlit=per_sub(state["sunlit"]),
        weights=np.full(k, 1.0 / k),
    )


def _state_at(satellite: Satellite, site: Site, times: np.ndarray) -> dict:
    """Everything geometric at (m,) times; vectors come back as (m, 3), frames as (m, 3, 3).

    Inside, vectors are (3, m) component rows and matrices (3, 3, m), so that every
    rotation is nine multiply-adds over contiguous rows.
    """
    frames = _EarthFrames.at(times)
    if isinstance(satellite, ObservedTrack):
        sat_gcrs, vel_gcrs = satellite.gcrs_state_km(times)
    else:
        r_teme, v_teme, error = satellite.teme_km(frames.jd_utc_whole, frames.jd_utc_fraction)
        if np.any(error):
            first = int(np.flatnonzero(error)[0])
            raise ValueError(
                f"SGP4 cannot propagate {satellite.name} (NORAD {satellite.norad}) to {times[first]}: "
                f"{SGP4_ERRORS[int(error[first])]}; use an element set closer to the observation"
            )
        sat_gcrs = _apply(frames.teme_to_gcrs, r_teme.T)
        vel_gcrs = _apply(frames.teme_to_gcrs, v_teme.T)
    sat_itrs = frames.gcrs_to_itrs(sat_gcrs)
    sun_itrs = frames.gcrs_to_itrs(frames.sun_gcrs_km)

    site_itrs = site.itrs_km[:, None]
    site_gcrs = frames.itrs_to_gcrs(site_itrs)
    # The site turns with the Earth about the ITRS z axis, which in GCRS is Q's last row.
    site_vel_gcrs = _ERA_RATE_RAD_S * _cross(frames.q[2], site_gcrs)

    east, north, up = site.enu_itrs.T @ (sat_itrs - site_itrs)
    az_deg = np.degrees(np.arctan2(east, north)) % 360.0
    el_deg = np.degrees(np.arctan2(up, np.hypot(east, north)))

    los = sat_gcrs - site_gcrs
    range_km = np.sqrt(np.einsum("im,im->m", los, los))
    range_rate = np.einsum("im,im->m", los, vel_gcrs - site_vel_gcrs) / range_km
    to_sun = frames.sun_gcrs_km - sat_gcrs
    rows = np.ascontiguousarray  # (m, 3) C-ordered for the renderer's batched products
    return {
        "sat_gcrs_km": rows(sat_gcrs.T),
        "sat_itrs_km": rows(sat_itrs.T),
        "az_deg": az_deg,
        "el_deg": el_deg,
        "range_km": range_km,
        "range_rate_km_s": range_rate,
        "sun_dir": rows((to_sun / np.sqrt(np.einsum("im,im->m", to_sun, to_sun))).T),
        "obs_dir": rows((-los / range_km).T),
        "sunlit": sunlit_fraction(sat_itrs.T, sun_itrs.T),
        "lvlh_gcrs": _lvlh(sat_gcrs, vel_gcrs),
    }


def _lvlh(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(m, 3, 3) LVLH frames from (3, m) r, v: columns x = y cross z, y = -orbit normal, z = nadir."""
    z = -r / np.sqrt(np.einsum("im,im->m", r, r))
    h = _cross(r, v)
    y = -h / np.sqrt(np.einsum("im,im->m", h, h))
    x = _cross(y, z)
    return np.stack([x.T, y.T, z.T], axis=-1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of (3, m) component rows."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _apply(matrices: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Batched matrix @ vector on component rows: (3, 3, m), (3, m) -> (3, m)."""
    return matrices[:, 0] * vectors[0] + matrices[:, 1] * vectors[1] + matrices[:, 2] * vectors[2]


class _EarthFrames:
    """Earth orientation, time scales and the Sun at (m,) UTC times.

    Slowly varying quantities come from skyfield at nodes `NODE_SPACING_S` apart, linearly
    interpolated; the Earth rotation angle is computed exactly at every time. Matrices are
    (3, 3, m), vectors (3, m).
    """

    def __init__(self, jd_utc_whole, jd_utc_fraction, teme_to_gcrs, q, era_rad, sun_gcrs_km):
        self.jd_utc_whole = jd_utc_whole
        self.jd_utc_fraction = jd_utc_fraction
        self.teme_to_gcrs = teme_to_gcrs
        self.q = q
        self.cos_era = np.cos(era_rad)
        self.sin_era = np.sin(era_rad)
        self.sun_gcrs_km = sun_gcrs_km

    @classmethod
    def at(cls, times: np.ndarray) -> _EarthFrames:
        ts = ephemeris.timescale()
        day = times.min().astype("datetime64[D]")
        ref_jd = _UNIX_EPOCH_JD + float(day.astype("int64"))  # midnight UTC, an exact x.5
        utc_s = (times - day) / np.timedelta64(1, "s")  # seconds of UTC since that midnight

        # Slow quantities are interpolated on the TT axis, which has no leap seconds. Nodes sit
        # at both ends of every grid cell that holds a time: a dense pass gets a regular grid,
        # times scattered over years get two nodes each.
        tt_s = utc_s + _tt_minus_utc_s(ts, ref_jd, utc_s)  # TT seconds since the TT date ref_jd
        first_s = float(tt_s.min())
        position = (tt_s - first_s) / NODE_SPACING_S
        cell = np.floor(position).astype("int64")
        cells = np.unique(cell)
        node_cells = np.union1d(cells, cells + 1)
        n_nodes = node_cells.shape[0]
        node_tt_s = first_s + NODE_SPACING_S * node_cells
        t = ts.tt_jd(np.full(n_nodes, ref_jd), node_tt_s / 86400.0)

        delta_t_s = np.asarray(t.delta_t, dtype=float)
        to_itrs = itrs.rotation_at(t)  # (3, 3, nodes): Rz(-GAST) N P B
        q = np.einsum("nij,jkn->ikn", rot_z(_era_rad(ref_jd, node_tt_s - delta_t_s)), to_itrs)
        teme_to_gcrs = TEME.rotation_at(t).transpose(1, 0, 2)
        sun = _apparent_sun_km(t)

        # All slowly varying quantities as rows of one table: (9 + 9 + 3 + 1, nodes), with the
        # slope of each node's cell beside it.
        table = np.concatenate([teme_to_gcrs.reshape(9, n_nodes), q.reshape(9, n_nodes), sun, delta_t_s[None]])
        slope = np.diff(table, axis=1, append=table[:, -1:])
        index = np.searchsorted(node_cells, cell)  # the node opening each time's cell
        values = table[:, index] + slope[:, index] * (position - cell)
        m = times.shape[0]
        ut1_s = tt_s - values[21]
        return cls(
            jd_utc_whole=np.full(m, ref_jd),
            jd_utc_fraction=utc_s / 86400.0,
            teme_to_gcrs=values[0:9].reshape(3, 3, m),
            q=values[9:18].reshape(3, 3, m),
            era_rad=_era_rad(ref_jd, ut1_s),
            sun_gcrs_km=values[18:21],
        )

    def gcrs_to_itrs(self, v: np.ndarray) -> np.ndarray:
        """(3, m) GCRS -> ITRS: Rz(-ERA) Q v."""
        w = _apply(self.q, v)
        c, s = self.cos_era, self.sin_era
        return np.array([c * w[0] + s * w[1], c * w[1] - s * w[0], w[2]])

    def itrs_to_gcrs(self, v: np.ndarray) -> np.ndarray:
        """(3, m) or (3, 1) ITRS -> (3, m) GCRS: Q^T Rz(ERA) v."""
        c, s = self.cos_era, self.sin_era
        w = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], np.broadcast_to(v[2], c.shape)])
        return _apply(self.q.transpose(1, 0, 2), w)


def _apparent_sun_km(t) -> np.ndarray:
    """(3, nodes) geocentric apparent Sun, GCRS, km: light-time corrected DE421 position with the
    annual aberration u' = u + v/c - (u . v/c) u (first order; it differs from skyfield's full
    ``apparent()``, which also bends light past Jupiter and Saturn, by 3e-11 rad, at half the cost)."""
    planets = ephemeris.planets()
    earth = planets["earth"].at(t)
    position = earth.observe(planets["sun"]).position.km
    distance = np.sqrt(np.einsum("in,in->n", position, position))
    u = position / distance
    beta = earth.velocity.km_per_s / 299_792.458
    apparent = u + beta - u * np.einsum("in,in->n", u, beta)
    return apparent * (distance / np.sqrt(np.einsum("in,in->n", apparent, apparent)))


def _tt_minus_utc_s(ts, ref_jd: float, utc_s: np.ndarray) -> np.ndarray:
    """TT - UTC in seconds at UTC seconds since ref_jd (leap seconds looked up per time)."""
    jd = ref_jd + utc_s / 86400.0
    index = np.searchsorted(ts.leap_dates, jd, side="right") - 1
    return ts.leap_offsets[np.maximum(index, 0)] + _TT_MINUS_TAI_S


def _era_rad(ref_jd: float, ut1_s: np.ndarray) -> np.ndarray:
    """Earth rotation angle (IAU 2000) at UT1 seconds since the UT1 date ref_jd, radians."""
    days = ref_jd - _J2000_JD  # exact: ref_jd is a half-integer
    fraction = ut1_s / 86400.0
    turns = _ERA_AT_J2000_TURNS + _ERA_RATE_EXCESS * (days + fraction) + (days % 1.0) + fraction
    return 2.0 * math.pi * (turns % 1.0)


def _as_utc_ns(time_utc) -> np.ndarray:
    """Validate observed times once and return them as (n,) datetime64[ns]."""
    if hasattr(time_utc, "to_value") and hasattr(time_utc, "utc"):  # astropy Time
        time_utc = time_utc.utc.to_value("datetime64")
    times = np.asarray(time_utc)
    if times.dtype.kind != "M":
        raise TypeError(
            f"time_utc must be numpy datetime64 (UTC) or astropy Time, got dtype {times.dtype}; "
            "convert with numpy.asarray(times, dtype='datetime64[ns]')"
        )
    times = np.atleast_1d(times.astype("datetime64[ns]"))
    if times.ndim != 1 or times.shape[0] == 0:
        raise ValueError(f"time_utc must be a non-empty 1-D array of times, got shape {times.shape}")
    if np.any(np.isnat(times)):
        raise ValueError(f"time_utc has {int(np.isnat(times).sum())} NaT values; drop them before computing geometry")
    if times.min() < _FIRST_TIME or times.max() >= _LAST_TIME:
        raise ValueError(
            f"time_utc spans {times.min()} .. {times.max()}, outside 1972-01-01 .. 2053-10-01 "
            "(the DE421 ephemeris and the leap-second table); give times inside that range"
        )
    return times


def _as_seconds(value) -> float:
    """A float of seconds from a number or an astropy time Quantity (converted once, here)."""
    if hasattr(value, "to_value"):
        return float(value.to_value("s"))
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(
            f"{value!r} is not a number of seconds; give a float or an astropy Quantity in time units"
        ) from None


def _freeze(obj) -> None:
    """Make every array attribute of a frozen dataclass read-only."""
    for f in fields(obj):
        value = getattr(obj, f.name)
        if isinstance(value, np.ndarray) and value.flags.writeable:
            value.setflags(write=False)
