"""An orbit from an observation file's own Az/El/Range columns, for passes without elements.

Some files carry no TLE or OMM (the Uzhhorod photometer's ``.phc`` files), but every row has
the topocentric azimuth, elevation and range the writer computed for it. Those columns fix
the satellite's position at every observed time; `ObservedTrack` turns them into a smooth
orbit arc that `raycast.geometry.PassGeometry` propagates like an element set, inside the
observed span only:

1. each row's apparent elevation loses its refraction (the writers used PyEphem, 1010 mbar,
   15 C: `raycast.geometry.refraction.true_elevation_deg`), and (Az, El, Range) becomes an
   Earth-fixed position from the site the columns were computed for (a ``.phc`` file's
   columns are for Derenivka although the photometer is at Uzhhorod; its header says so);
2. the Earth-fixed positions are rotated into GCRS at each row's time, where an orbit is a
   smooth curve;
3. each GCRS coordinate is fitted with a Chebyshev series over the span (the lowest degree,
   3..12, whose residual RMS is within 10% of the degree-12 fit's), with rows deviating by
   more than 5 robust sigma from the first fit set aside; the velocity is the series'
   derivative.

The columns are written to 0.001 deg and 1 m, i.e. ~50 m at 3000 km; the fit averages that
down. On the TOPEX file of 2024-07-30, which also carries its TLE, the track lies a median
68 m from SGP4's positions over the 464 s pass and its lines of sight agree with SGP4's to
arc-seconds (tests/test_track.py; docs/geometry.md).

A track is good where it was observed: `gcrs_state_km` refuses times more than
`MARGIN_FRACTION` of the span, plus `MARGIN_S`, plus half an exposure outside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ingest.site import PRESETS, Site

__all__ = ["ObservedTrack", "MARGIN_S", "MARGIN_FRACTION", "MAX_TRACK_RMS_KM", "track_site"]

MARGIN_S = 2.0
MARGIN_FRACTION = 0.05
MAX_TRACK_RMS_KM = 1.0  # a track rougher than this is not an orbit (damaged columns)
_MIN_ROWS = 10
_MAX_DEGREE = 12
_DEGREE_TOLERANCE = 1.10
_CLIP_SIGMA = 5.0
_MEDIAN_3D = 1.5382  # median of a 3-D Gaussian vector's length, in units of its per-axis sigma


def track_site(observed) -> Site:
    """The site a pass's Az/El/Range columns were computed for.

    A reader that knows the columns were computed elsewhere says so in the header's
    ``az_el_range_site`` ("Derenivka: ..."); otherwise they are for the pass's own site.
    """
    note = str(dict(getattr(observed, "header", {}) or {}).get("az_el_range_site", ""))
    name = note.split(":", 1)[0].strip().lower()
    return PRESETS.get(name, observed.site) if name else observed.site


@dataclass(frozen=True, eq=False)
class ObservedTrack:
    """A satellite's GCRS orbit arc fitted to an observation file's Az/El/Range columns.

    Build it with `raycast.geometry.pass_geometry.track_of(pass)` (or `fit`); it is immutable.

    Attributes
    ----------
    name : str
        Object name.
    norad : int
        NORAD catalogue number.
    epoch_utc : numpy.datetime64
        The track's time origin (its first row), UTC.
    span_s : (2,) float
        First and last fitted row, seconds after `epoch_utc`.
    coefficients : (3, degree + 1) float
        Chebyshev coefficients of GCRS x, y, z (km) over `span_s` mapped to [-1, 1].
    rms_km : float
        Residual RMS of the fitted rows, km (3-D).
    n_rows, n_clipped : int
        Rows fitted, and rows set aside as outliers.
    site : Site
        The site the columns were computed for.
    margin_s : float
        How far outside `span_s` the track may be used, seconds.
    """

    name: str
    norad: int
    epoch_utc: np.datetime64
    span_s: np.ndarray
    coefficients: np.ndarray
    rms_km: float
    n_rows: int
    n_clipped: int
    site: Site
    margin_s: float = MARGIN_S

    tle = None
    omm = None

    def __post_init__(self):
        for value in (self.span_s, self.coefficients):
            value.setflags(write=False)

    # -- construction --------------------------------------------------------------------
    @classmethod
    def fit(
        cls,
        time_utc: np.ndarray,
        gcrs_km: np.ndarray,
        site: Site,
        name: str = "",
        norad: int = 0,
        label: str = "the track",
        exposure_s: float = 0.0,
    ) -> ObservedTrack:
        """Fit a track to (n,) sorted times and (3, n) GCRS positions, km.

        `raycast.geometry.pass_geometry.track_of(pass)` builds the positions from a pass's
        Az/El/range columns and calls this.

        Parameters
        ----------
        time_utc : (n,) datetime64[ns]
        gcrs_km : (3, n) float
        site : Site
            The site the positions were computed from (recorded).
        name, norad : str, int
            The object.
        label : str
            Names the pass in errors.
        exposure_s : float
            The rows' exposure: the track reaches half of it beyond the span (exposure sub-samples).

        Raises
        ------
        ValueError
            With too few rows, no time span, or positions that are not a smooth orbit.
        """
        times = np.asarray(time_utc, dtype="datetime64[ns]")
        if times.size < _MIN_ROWS:
            raise ValueError(
                f"{label} has {times.size} rows with Az, El and range (at least {_MIN_ROWS} are needed "
                "for a track), and no orbital elements: it has no geometry; give elements with "
                "'rsodb elements add TLE_FILE'"
            )
        epoch = times[0]
        t_s = (times - epoch) / np.timedelta64(1, "s")
        span = np.array([t_s[0], t_s[-1]])
        if span[1] - span[0] <= 0.0:
            raise ValueError(f"{label}: its Az/El/range rows span no time, so they give no track")
        keep = np.ones(t_s.shape, dtype=bool)
        coefficients, residual = _fit(t_s, gcrs_km, span, keep)
        # Per-axis sigma from the median 3-D residual (1.538 sigma for Gaussian errors), at least 1 m.
        sigma = max(float(np.median(residual)) / _MEDIAN_3D, 1e-3)
        clipped = residual <= _CLIP_SIGMA * sigma
        if int(clipped.sum()) >= _MIN_ROWS and not clipped.all():
            keep = clipped
            coefficients, residual = _fit(t_s, gcrs_km, span, keep)
        rms = float(np.sqrt(np.mean(residual[keep] ** 2)))
        if rms > MAX_TRACK_RMS_KM:
            raise ValueError(
                f"{label}: its Az/El/range columns do not describe a smooth orbit (residual RMS {rms:.2f} km "
                f"against <= {MAX_TRACK_RMS_KM} km); check the columns, or give elements with 'rsodb elements add'"
            )
        return cls(
            name=name or f"NORAD {norad}",
            norad=int(norad),
            epoch_utc=epoch,
            span_s=span,
            coefficients=coefficients,
            rms_km=rms,
            n_rows=int(keep.sum()),
            n_clipped=int((~keep).sum()),
            site=site,
            margin_s=MARGIN_S + MARGIN_FRACTION * float(span[1] - span[0]) + 0.5 * max(exposure_s, 0.0),
        )

    # -- propagation ---------------------------------------------------------------------
    @property
    def degree(self) -> int:
        return self.coefficients.shape[1] - 1

    @property
    def description(self) -> str:
        """One line saying where the geometry came from."""
        return (
            f"track fitted to the file's Az/El/range columns (computed for {self.site.name}): "
            f"{self.n_rows} rows over {self.span_s[1] - self.span_s[0]:.0f} s, Chebyshev degree {self.degree}, "
            f"residual RMS {self.rms_km * 1000:.0f} m"
            + (f", {self.n_clipped} rows set aside as outliers" if self.n_clipped else "")
        )

    def gcrs_state_km(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(3, m) GCRS position (km) and velocity (km/s) at (m,) datetime64[ns] times.

        Raises
        ------
        ValueError
            For times outside the observed span (plus its margin).
        """
        t_s = (np.asarray(times, dtype="datetime64[ns]") - self.epoch_utc) / np.timedelta64(1, "s")
        first, last = self.span_s
        outside = (t_s < first - self.margin_s) | (t_s > last + self.margin_s)
        if np.any(outside):
            bad = np.asarray(times)[np.flatnonzero(outside)[0]]
            raise ValueError(
                f"{self.name} (NORAD {self.norad}) has no orbital elements, only a track fitted to its file's "
                f"Az/El/range columns from {self.epoch_utc + _ns(first)} to {self.epoch_utc + _ns(last)}; "
                f"{bad} lies outside it (a track is good only where it was observed)"
            )
        half = 0.5 * (last - first)
        x = (t_s - 0.5 * (first + last)) / half
        position = np.array([np.polynomial.chebyshev.chebval(x, c) for c in self.coefficients])
        velocity = np.array(
            [np.polynomial.chebyshev.chebval(x, np.polynomial.chebyshev.chebder(c)) / half for c in self.coefficients]
        )
        return position.reshape(3, -1), velocity.reshape(3, -1)


def _ns(seconds: float) -> np.timedelta64:
    return np.timedelta64(int(round(seconds * 1e9)), "ns")


def _fit(t_s: np.ndarray, gcrs: np.ndarray, span: np.ndarray, keep: np.ndarray):
    """Chebyshev coefficients (3, d + 1) of the lowest adequate degree, and every row's 3-D residual."""
    half = 0.5 * (span[1] - span[0])
    x = (t_s - 0.5 * (span[0] + span[1])) / half
    most = min(_MAX_DEGREE, int(keep.sum()) - 2)

    def fitted(degree):
        coefficients = np.array([np.polynomial.chebyshev.chebfit(x[keep], row[keep], degree) for row in gcrs])
        model = np.array([np.polynomial.chebyshev.chebval(x, c) for c in coefficients])
        residual = np.sqrt(np.sum((gcrs - model) ** 2, axis=0))
        return coefficients, residual, float(np.sqrt(np.mean(residual[keep] ** 2)))

    best = fitted(most)
    for degree in range(min(3, most), most):
        candidate = fitted(degree)
        if candidate[2] <= _DEGREE_TOLERANCE * best[2]:
            return candidate[0], candidate[1]
    return best[0], best[1]
