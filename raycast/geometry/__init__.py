"""Orbit and observer geometry of a pass: elements, Sun, site, refraction, Earth shadow, attitude.

One call gives every frame's geometry (`PassGeometry.compute` or `PassGeometry.from_pass`);
`PassGeometry.body_frame(attitude)` turns it into the body-frame directions the renderer needs.
See docs/geometry.md.
"""

from raycast.geometry import ephemeris
from raycast.geometry.attitude import ATTITUDE_MODELS, SPIN_AXES, InertialSpin, PrecessingSpin, TorqueFree
from raycast.geometry.orbit import Satellite
from raycast.geometry.pass_geometry import BodyGeometry, PassGeometry, choose_n_sub, orbit_of, track_of
from raycast.geometry.refraction import apparent_elevation_deg, true_elevation_deg
from raycast.geometry.shadow import sunlit_fraction
from raycast.geometry.track import ObservedTrack

__all__ = [
    "ephemeris",
    "ATTITUDE_MODELS",
    "SPIN_AXES",
    "InertialSpin",
    "PrecessingSpin",
    "TorqueFree",
    "Satellite",
    "BodyGeometry",
    "PassGeometry",
    "choose_n_sub",
    "orbit_of",
    "track_of",
    "ObservedTrack",
    "apparent_elevation_deg",
    "true_elevation_deg",
    "sunlit_fraction",
]
