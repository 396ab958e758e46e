"""Observing sites: a named point on the WGS84 ellipsoid.

A `Site` is plain data (no skyfield objects), so the ingest package can attach it to a pass
without importing the geometry machinery. `Site.itrs_km` (its Earth-fixed position) and
`Site.enu_itrs` (its local east/north/up axes) are all `raycast.geometry` needs from it.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

__all__ = ["Site", "DERENIVKA", "UZHHOROD", "PRESETS", "WGS84_A_KM", "WGS84_F"]

# WGS84 ellipsoid: equatorial radius and flattening.
WGS84_A_KM = 6378.137
WGS84_F = 1.0 / 298.257223563


@dataclass(frozen=True)
class Site:
    """A ground station.

    Parameters
    ----------
    name : str
        Human-readable name, e.g. ``"Derenivka"``.
    lat_deg : float
        Geodetic latitude on WGS84, degrees north.
    lon_deg : float
        Longitude, degrees east.
    elevation_m : float
        Height above the WGS84 ellipsoid, metres.
    """

    name: str
    lat_deg: float
    lon_deg: float
    elevation_m: float

    def __post_init__(self):
        for field, value, low, high in (
            ("lat_deg", self.lat_deg, -90.0, 90.0),
            ("lon_deg", self.lon_deg, -180.0, 360.0),
            ("elevation_m", self.elevation_m, -500.0, 9000.0),
        ):
            if not isinstance(value, (int, float)) or not math.isfinite(value) or not low <= value <= high:
                raise ValueError(
                    f"site {self.name!r}: {field}={value!r} is outside [{low}, {high}]; "
                    "give geodetic degrees and metres"
                )

    @classmethod
    def preset(cls, name: str) -> Site:
        """Return a known site by case-insensitive name (``derenivka``, ``uzhhorod``)."""
        key = name.strip().lower()
        if key not in PRESETS:
            raise KeyError(f"unknown site {name!r}; known sites: {', '.join(sorted(PRESETS))}")
        return PRESETS[key]

    @classmethod
    def from_text(cls, text: str) -> Site:
        """A preset site name or ``LAT,LON,H`` (geodetic degrees and metres), as a command line gives it."""
        parts = text.split(",")
        if len(parts) == 1:
            return cls.preset(text)
        try:
            lat, lon, height = (float(p) for p in parts)
        except ValueError:
            raise ValueError(
                f"site {text!r} is neither a known site (derenivka, uzhhorod) nor LAT,LON,H; give e.g. 48.56,22.45,200"
            ) from None
        return cls(f"{lat:.4f},{lon:.4f}", lat, lon, height)

    @property
    def key(self) -> str:
        """Lower-case identifier usable in file and pass names."""
        return "".join(c for c in self.name.lower() if c.isalnum()) or "site"

    @property
    def itrs_km(self) -> np.ndarray:
        """(3,) float: the site's Earth-fixed (ITRS) position on the WGS84 ellipsoid, km.

        Examples
        --------
        >>> Site("pole", 90.0, 0.0, 0.0).itrs_km.round(3).tolist()
        [0.0, 0.0, 6356.752]
        """
        lat, lon = math.radians(self.lat_deg), math.radians(self.lon_deg)
        e2 = WGS84_F * (2.0 - WGS84_F)
        n_km = WGS84_A_KM / math.sqrt(1.0 - e2 * math.sin(lat) ** 2)
        h_km = self.elevation_m / 1000.0
        return np.array(
            [
                (n_km + h_km) * math.cos(lat) * math.cos(lon),
                (n_km + h_km) * math.cos(lat) * math.sin(lon),
                (n_km * (1.0 - e2) + h_km) * math.sin(lat),
            ]
        )

    @property
    def enu_itrs(self) -> np.ndarray:
        """(3, 3) float: the local East, North, Up unit vectors (columns) in ITRS.

        Up is the ellipsoid normal (geodetic vertical), so ``enu_itrs.T @ v`` gives a vector's
        east, north and up components, from which azimuth (from north through east) and
        geodetic elevation follow.
        """
        lat, lon = math.radians(self.lat_deg), math.radians(self.lon_deg)
        sin_lat, cos_lat, sin_lon, cos_lon = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
        return np.array(
            [
                [-sin_lon, -sin_lat * cos_lon, cos_lat * cos_lon],
                [cos_lon, -sin_lat * sin_lon, cos_lat * sin_lon],
                [0.0, cos_lat, sin_lat],
            ]
        )


# Derenivka: the coordinates written by ccd_phot in every SITE_* header of the lab's files.
DERENIVKA = Site("Derenivka", 48.5635505, 22.453751, 231.1325)
# Uzhhorod station of the Laboratory of Space Research (MPC code 061): 48 deg 37' 53.9" N,
# 22 deg 17' 57" E, 183 m.
UZHHOROD = Site("Uzhhorod", 48.631639, 22.29917, 183.0)

PRESETS = {"derenivka": DERENIVKA, "uzhhorod": UZHHOROD}
