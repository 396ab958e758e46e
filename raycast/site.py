"""Observing sites: a named point on the WGS84 ellipsoid.

A `Site` is plain data (no skyfield objects), so the ingest package can attach it to a pass
without importing the geometry machinery. `raycast.geometry` turns it into a skyfield
topocentre when it needs one.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

__all__ = ["Site", "DERENIVKA", "UZHHOROD", "PRESETS"]


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
    def preset(cls, name: str) -> "Site":
        """Return a known site by case-insensitive name (``derenivka``, ``uzhhorod``)."""
        key = name.strip().lower()
        if key not in PRESETS:
            raise KeyError(f"unknown site {name!r}; known sites: {', '.join(sorted(PRESETS))}")
        return PRESETS[key]

    @property
    def key(self) -> str:
        """Lower-case identifier usable in file and pass names."""
        return "".join(c for c in self.name.lower() if c.isalnum()) or "site"


# Derenivka: the coordinates written by ccd_phot in every SITE_* header of the lab's files.
DERENIVKA = Site("Derenivka", 48.5635505, 22.453751, 231.1325)
# Uzhhorod station of the Laboratory of Space Research (MPC code 061): 48 deg 37' 53.9" N,
# 22 deg 17' 57" E, 183 m.
UZHHOROD = Site("Uzhhorod", 48.631639, 22.29917, 183.0)

PRESETS = {"derenivka": DERENIVKA, "uzhhorod": UZHHOROD}
