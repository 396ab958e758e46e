"""The forward model: a pass, a shape and an attitude model -> synthetic magnitudes.

Work is split by how often it changes:

- once per pass: the inertial geometry (`raycast.geometry.PassGeometry`: Sun and observer
  directions, local orbital frames, Earth shadow, per exposure sub-sample), and the shape's
  fast brightness function (`raycast.renderer.cache`, or the analytic `ConvexFacets` below);
- once per MCMC step: the attitude model built from the parameters, the body-frame directions
  (``geometry.body_frame(attitude)``, one batched matrix product) and the brightness function
  on those ``n * k`` direction pairs, averaged over each exposure and weighted by the sunlit
  fraction, then converted to magnitudes (`raycast.renderer.photometry`).

Attitude families (``ATTITUDES``) turn named parameters into a `raycast.geometry.attitude` model. The
phases are defined at a reference epoch ``epoch_s`` (seconds after the pass's first sample,
by default the pass mid-time), not at the first sample: over a pass of N spin cycles the
phase at the start is correlated with the period N times more strongly than the phase at the
middle, which slows the sampler for nothing.

`ConvexFacets` is an exact, cheap brightness function for convex bodies with Lambertian
facets (no facet can shadow or hide another): ``I/E = sum_f A_f rho_f / pi max(0, n_f.s)
max(0, n_f.o)``. It is a legitimate model of its own (a box or prism for an object without a
detailed model) and the fast double the tests use.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
import math
from types import MappingProxyType
from typing import Any

import numpy as np

from raycast.geometry.attitude import InertialSpin, PrecessingSpin, TorqueFree
from raycast.renderer.photometry import magnitude, solar_magnitude
from raycast.renderer.scene import icosphere

__all__ = ["ConvexFacets", "SpinStateModel", "AttitudeFamily", "ATTITUDES", "EpochShifted", "make_attitude"]


# -- brightness: an analytic convex body ---------------------------------------------------
@dataclass(frozen=True, eq=False)
class ConvexFacets:
    """Brightness of a convex body of flat Lambertian facets, in closed form.

    Parameters
    ----------
    normals : (f, 3) float
        Outward unit normals, body frame.
    areas_m2 : (f,) float
        Facet areas, m^2.
    albedo : (f,) float
        Lambertian reflectance of each facet, 0..1.
    """

    normals: np.ndarray
    areas_m2: np.ndarray
    albedo: np.ndarray

    parameters = ()

    def __post_init__(self):
        normals = np.array(self.normals, dtype=float)
        if normals.ndim != 2 or normals.shape[1] != 3:
            raise ValueError(f"normals must have shape (f, 3), got {normals.shape}")
        length = np.linalg.norm(normals, axis=1)
        if np.any(np.abs(length - 1) > 1e-6):
            raise ValueError("normals must be unit vectors; normalise them first")
        areas = np.broadcast_to(np.array(self.areas_m2, dtype=float), length.shape).copy()
        albedo = np.broadcast_to(np.array(self.albedo, dtype=float), length.shape).copy()
        if np.any(areas < 0) or np.any((albedo < 0) | (albedo > 1)):
            raise ValueError("facet areas must be >= 0 and albedos within 0..1")
        for name, value in (("normals", normals), ("areas_m2", areas), ("albedo", albedo)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "_weight", areas * albedo / math.pi)

    def intensity(self, sun_body: np.ndarray, obs_body: np.ndarray) -> np.ndarray:
        """I/E in m^2/sr for direction pairs.

        Parameters
        ----------
        sun_body, obs_body : (m, 3) float
            Unit vectors toward the Sun and the observer, body frame.

        Returns
        -------
        (m,) float
        """
        cos_i = np.maximum(sun_body @ self.normals.T, 0.0)
        cos_e = np.maximum(obs_body @ self.normals.T, 0.0)
        return (cos_i * cos_e) @ self._weight

    @classmethod
    def box(cls, size_m=(1.0, 1.0, 2.0), albedo: float = 0.2) -> ConvexFacets:
        """A rectangular box centred on the origin, edges along the body axes.

        Parameters
        ----------
        size_m : (3,) float
            Edge lengths along body x, y, z, metres.
        albedo : float
            Reflectance of every face.
        """
        x, y, z = (float(s) for s in size_m)
        normals = np.vstack([np.eye(3), -np.eye(3)])
        areas = np.array([y * z, x * z, x * y] * 2)
        return cls(normals, areas, albedo)

    @classmethod
    def ellipsoid(cls, semi_axes_m=(1.0, 0.5, 0.35), subdivisions: int = 3, albedo: float = 0.2) -> ConvexFacets:
        """A triaxial ellipsoid as a convex polyhedron (a scaled, subdivided icosahedron).

        Its facet normals cover every direction, so it is never dark while lit at a phase
        angle below 180 deg, and an elongated one (longest axis along body x) spinning about
        body z tumbles end over end with a strong, smooth modulation.

        Parameters
        ----------
        semi_axes_m : (3,) float
            Semi-axes along body x, y, z, metres.
        subdivisions : int
            Times each icosahedron face is split in four (20 * 4**subdivisions facets).
        albedo : float
            Reflectance of every facet.
        """
        if not (isinstance(subdivisions, int) and 0 <= subdivisions <= 6):
            raise ValueError(f"subdivisions={subdivisions!r} must be a whole number 0..6")
        vertices, faces = icosphere(subdivisions)
        vertices = vertices * np.asarray(semi_axes_m, dtype=float)
        corners = vertices[faces]
        cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        area2 = np.linalg.norm(cross, axis=1)
        return cls(cross / area2[:, None], 0.5 * area2, albedo)


# -- attitude families -------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class EpochShifted:
    """An attitude model whose time origin is moved to `epoch_s`.

    ``orientation(t_s) = attitude.orientation(t_s - epoch_s)``: the wrapped model's phases
    are then the phases at `epoch_s`.
    """

    attitude: Any
    epoch_s: float

    def orientation(self, t_s, lvlh_gcrs=None):
        return self.attitude.orientation(np.asarray(t_s) - self.epoch_s, lvlh_gcrs)

    @property
    def spin_direction_body(self):
        """The wrapped model's spin axis in body coordinates (AttributeError where it has none)."""
        return self.attitude.spin_direction_body


@dataclass(frozen=True)
class AttitudeFamily:
    """A named way of turning parameters into an attitude model.

    Attributes
    ----------
    parameters : tuple of str
        Parameter names it reads.
    settings : tuple of str
        Names of non-fitted options it accepts (e.g. ``spin_axis``).
    build : callable
        ``build(values, **settings) -> attitude`` (a module-level function, so models pickle).
    supports : callable
        ``supports(values) -> bool``: False where the values describe no physical body (the
        posterior is zero there).
    description : str
    """

    parameters: tuple[str, ...]
    settings: tuple[str, ...]
    build: Callable
    supports: Callable
    description: str


def _always(values) -> bool:
    return True


def _precessing(values, spin_axis="z"):
    return PrecessingSpin(
        period_s=values["spin_period_s"],
        phase_deg=values["spin_phase_deg"],
        precession_period_s=values["precession_period_s"],
        precession_phase_deg=values["precession_phase_deg"],
        precession_angle_deg=values["precession_angle_deg"],
        spin_axis=spin_axis,
    )


def _inertial(values, spin_axis="z"):
    # Both inertial families: the tilted one's values hold the tilt, the other's leave it at 0.
    return InertialSpin(
        pole_ra_deg=values["pole_ra_deg"],
        pole_dec_deg=values["pole_dec_deg"],
        period_s=values["spin_period_s"],
        phase_deg=values["spin_phase_deg"],
        spin_axis=spin_axis,
        axis_tilt_deg=values.get("axis_tilt_deg", 0.0),
        axis_tilt_azimuth_deg=values.get("axis_tilt_azimuth_deg", 0.0),
    )


def _torque_free_inertia(values) -> tuple[float, float, float]:
    return 1.0, values["inertia_ratio_2"], values["inertia_ratio_3"]


def _torque_free_supports(values) -> bool:
    # A real rigid body: no principal moment exceeds the sum of the other two.
    moments = sorted(_torque_free_inertia(values))
    return moments[0] > 0 and moments[2] <= moments[0] + moments[1]


def _torque_free(values):
    polar, azimuth = math.radians(values["omega_polar_deg"]), math.radians(values["omega_azimuth_deg"])
    rate = 2 * math.pi / values["spin_period_s"]
    omega = rate * np.array([math.sin(polar) * math.cos(azimuth), math.sin(polar) * math.sin(azimuth), math.cos(polar)])
    return TorqueFree.from_angular_momentum(
        _torque_free_inertia(values), omega, values["pole_ra_deg"], values["pole_dec_deg"], values["spin_phase_deg"]
    )


ATTITUDES: Mapping[str, AttitudeFamily] = MappingProxyType(
    {
        "precessing": AttitudeFamily(
            ("spin_period_s", "spin_phase_deg", "precession_period_s", "precession_phase_deg", "precession_angle_deg"),
            ("spin_axis",),
            _precessing,
            _always,
            "the published model (raycast.geometry.attitude.PrecessingSpin): spin about a body axis, that axis "
            "precessing on a cone about nadir (the satellite-to-Earth-centre direction)",
        ),
        "inertial": AttitudeFamily(
            ("spin_period_s", "spin_phase_deg", "pole_ra_deg", "pole_dec_deg"),
            ("spin_axis",),
            _inertial,
            _always,
            "spin about a body axis fixed in inertial space (raycast.geometry.attitude.InertialSpin, pole RA/Dec in GCRS)",
        ),
        "inertial_tilted": AttitudeFamily(
            (
                "spin_period_s",
                "spin_phase_deg",
                "pole_ra_deg",
                "pole_dec_deg",
                "axis_tilt_deg",
                "axis_tilt_azimuth_deg",
            ),
            ("spin_axis",),
            _inertial,
            _always,
            "spin fixed in inertial space about a body direction tilted from a body axis (InertialSpin with "
            "axis_tilt_deg): a body spinning steadily about a principal axis of inertia that is none of its "
            "model's axes",
        ),
        "torque_free": AttitudeFamily(
            (
                "spin_period_s",
                "spin_phase_deg",
                "pole_ra_deg",
                "pole_dec_deg",
                "inertia_ratio_2",
                "inertia_ratio_3",
                "omega_polar_deg",
                "omega_azimuth_deg",
            ),
            (),
            _torque_free,
            _torque_free_supports,
            "a rigid body tumbling freely (raycast.geometry.attitude.TorqueFree): principal moments (1, I2/I1, I3/I1) "
            "along body x, y, z; angular velocity at the epoch of magnitude 2 pi / spin_period_s in the "
            "body direction (omega_polar_deg from +z, omega_azimuth_deg from +x toward +y); angular "
            "momentum toward (pole_ra_deg, pole_dec_deg); spin_phase_deg about it",
        ),
    }
)


def make_attitude(family: str, values: Mapping[str, float], settings: Mapping | None = None, epoch_s: float = 0.0):
    """The attitude model of a family at parameter values, phases at `epoch_s`.

    Parameters
    ----------
    family : str
        A key of `ATTITUDES`.
    values : mapping of str to float
        At least the family's parameters (`AttitudeFamily.parameters`).
    settings : mapping, optional
        The family's settings, e.g. ``{"spin_axis": "x"}``.
    epoch_s : float
        Reference time of the phases, seconds after the time origin of the geometry it is used
        with (a fit's: its window's mid-time).
    """
    if family not in ATTITUDES:
        raise ValueError(f"unknown attitude model {family!r}; use one of {', '.join(ATTITUDES)}")
    spec = ATTITUDES[family]
    missing = [name for name in spec.parameters if name not in values]
    if missing:
        raise ValueError(
            f"the {family} attitude needs {', '.join(missing)}; give every one of {', '.join(spec.parameters)}"
        )
    unknown = sorted(set(settings or {}) - set(spec.settings))
    if unknown:
        raise ValueError(
            f"attitude model {family!r} has no settings {unknown}; it accepts {', '.join(spec.settings) or 'none'}"
        )
    return EpochShifted(spec.build(values, **dict(settings or {})), float(epoch_s))


# -- the forward model -----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class SpinStateModel:
    """Synthetic magnitudes of one pass for a set of parameter values.

    Parameters
    ----------
    geometry : raycast.geometry.PassGeometry
        The pass's inertial geometry at the observed times (computed once).
    brightness : object
        ``intensity(sun_body (m, 3), obs_body (m, 3), **parameters) -> (m,)`` I/E in m^2/sr:
        a `raycast.renderer.cache` fast path, a direct renderer, or `ConvexFacets`.
    attitude : str
        A key of `ATTITUDES`.
    attitude_settings : mapping
        Options of that family, e.g. ``{"spin_axis": "z"}``.
    brightness_parameters : tuple of str
        Parameters passed by name to ``brightness.intensity`` (e.g. ``panel_pitch_deg``).
    band : str
        Photometric band of the observations.
    reference_range_km : float or None
        Range the observed magnitudes are reduced to (1000 km for ccd_phot's standard
        magnitudes), or None to predict magnitudes at the true range.
    epoch_s : float or None
        Reference time of the phases, seconds after the first sample; None = pass mid-time.
    """

    geometry: Any
    brightness: Any
    attitude: str = "precessing"
    attitude_settings: Mapping[str, Any] = field(default_factory=dict)
    brightness_parameters: tuple[str, ...] = ()
    band: str = "V"
    reference_range_km: float | None = 1000.0
    epoch_s: float | None = None

    def __post_init__(self):
        if self.attitude not in ATTITUDES:
            raise ValueError(f"unknown attitude model {self.attitude!r}; use one of {', '.join(ATTITUDES)}")
        family = ATTITUDES[self.attitude]
        unknown = sorted(set(self.attitude_settings) - set(family.settings))
        if unknown:
            raise ValueError(
                f"attitude model {self.attitude!r} has no settings {unknown}; "
                f"it accepts {', '.join(family.settings) or 'none'}"
            )
        if self.epoch_s is None:
            object.__setattr__(self, "epoch_s", float(0.5 * (self.geometry.t_s[0] + self.geometry.t_s[-1])))
        object.__setattr__(self, "attitude_settings", MappingProxyType(dict(self.attitude_settings)))
        object.__setattr__(self, "brightness_parameters", tuple(self.brightness_parameters))

        solar_magnitude(self.band)  # fail now, not at the first step, for a band without a solar magnitude

    def __reduce__(self):
        # The element set inside the geometry (an sgp4 Satrec) does not pickle and is not
        # needed once the geometry is computed: process-pool workers get the geometry without it.
        geometry = replace(self.geometry, satellite=None)
        return _rebuild_model, (
            geometry,
            self.brightness,
            self.attitude,
            dict(self.attitude_settings),
            self.brightness_parameters,
            self.band,
            self.reference_range_km,
            self.epoch_s,
        )

    @property
    def epoch_utc(self) -> np.datetime64:
        """The reference epoch of the phases, UTC."""
        return self.geometry.time_utc[0] + np.timedelta64(int(round(self.epoch_s * 1e9)), "ns")

    def on(self, geometry) -> SpinStateModel:
        """The same model on other times (`geometry`), its phases still referred to `epoch_utc`."""
        epoch_s = float((self.epoch_utc - geometry.time_utc[0]) / np.timedelta64(1, "s"))
        return replace(self, geometry=geometry, epoch_s=epoch_s)

    @property
    def parameters(self) -> tuple[str, ...]:
        """Every parameter name the model reads."""
        return ATTITUDES[self.attitude].parameters + self.brightness_parameters

    @property
    def n(self) -> int:
        return self.geometry.n

    def attitude_model(self, values: Mapping[str, float]):
        """The attitude for these values, phases referred to `epoch_s`."""
        return EpochShifted(ATTITUDES[self.attitude].build(values, **self.attitude_settings), self.epoch_s)

    def supports(self, values: Mapping[str, float]) -> bool:
        """False where the values describe no physical body (impossible inertia ratios, albedo > 1)."""
        brightness_supports = getattr(self.brightness, "supports", None)
        return bool(ATTITUDES[self.attitude].supports(values)) and (
            brightness_supports is None or bool(brightness_supports(values))
        )

    def intensity(self, values: Mapping[str, float]) -> np.ndarray:
        """(n,) I/E in m^2/sr, averaged over each exposure, Earth shadow applied."""
        body = self.geometry.body_frame(self.attitude_model(values))
        n, k = body.sunlit.shape
        kwargs = {name: values[name] for name in self.brightness_parameters}
        per_sub = self.brightness.intensity(
            body.sun_body.reshape(n * k, 3), body.obs_body.reshape(n * k, 3), **kwargs
        ).reshape(n, k)
        return (per_sub * body.sunlit) @ body.weights

    def magnitudes(self, values: Mapping[str, float]) -> np.ndarray:
        """(n,) magnitudes in the pass's band (at `reference_range_km` when set); +inf where dark."""
        if not self.supports(values):
            return np.full(self.n, np.inf)
        range_km = self.geometry.range_km if self.reference_range_km is None else self.reference_range_km
        return magnitude(self.intensity(values), range_km, self.band)


def _rebuild_model(
    geometry, brightness, attitude, attitude_settings, brightness_parameters, band, reference_range_km, epoch_s
):
    return SpinStateModel(
        geometry, brightness, attitude, attitude_settings, brightness_parameters, band, reference_range_km, epoch_s
    )
