"""Attitude models: body-to-GCRS rotations as arrays over time.

Each model is an immutable object with one method, ``orientation(t_s, lvlh_gcrs=None) ->
(..., 3, 3)``, the rotations R with ``v_gcrs = R @ v_body`` at seconds ``t_s`` since the pass's
first observed time: `PrecessingSpin` (the seed paper's, bound to the orbit), `InertialSpin`
(IAU pole and prime meridian) and `TorqueFree` (Euler's equations). docs/geometry.md states the
angle conventions and draws them (docs/img/attitude_conventions.png).

Examples
--------
>>> import numpy as np
>>> from raycast.geometry.attitude import InertialSpin
>>> spin = InertialSpin(pole_ra_deg=0.0, pole_dec_deg=90.0, period_s=8.0)
>>> spin.orientation(np.array([0.0, 2.0]))[:, :, 0].round(12).tolist()  # body x in GCRS
[[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]
"""

from __future__ import annotations

from dataclasses import dataclass
import functools
import math

import numpy as np
from scipy.integrate import odeint

from raycast.geometry.rotations import rot_z

__all__ = [
    "PrecessingSpin",
    "InertialSpin",
    "TorqueFree",
    "ATTITUDE_MODELS",
    "build",
    "SPIN_AXES",
]

SPIN_AXES = ("x", "y", "z")
# Column order that relabels spin-frame columns (s1, s2, s3) as body columns (x, y, z).
_BODY_FROM_SPIN_COLUMNS = {"z": [0, 1, 2], "x": [2, 0, 1], "y": [1, 2, 0]}


# -- shared validation and rotation helpers -----------------------------------------------
def _check_period(owner: str, name: str, value) -> float:
    value = float(value)
    if value == 0.0 or math.isnan(value):
        raise ValueError(f"{owner}: {name}={value!r} must be a non-zero number of seconds (numpy.inf for none)")
    return value


def _check_angle(owner: str, name: str, value) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{owner}: {name}={value!r} must be a finite angle in degrees")
    return value


def _check_axis(owner: str, axis) -> str:
    if axis not in SPIN_AXES:
        raise ValueError(f"{owner}: spin_axis={axis!r} must be one of 'x', 'y', 'z'")
    return axis


def _angle_rad(phase_deg: float, period_s: float, t_s: np.ndarray) -> np.ndarray:
    """phase + 2 pi t / period, radians (period inf: constant)."""
    return math.radians(phase_deg) + (2.0 * math.pi / period_s) * t_s


def _zyz(phi: np.ndarray, theta: float, psi: np.ndarray) -> np.ndarray:
    """(..., 3, 3) Rz(phi) @ Ry(theta) @ Rz(psi) in closed form."""
    cf, sf, cp, sp = np.cos(phi), np.sin(phi), np.cos(psi), np.sin(psi)
    ct, st = math.cos(theta), math.sin(theta)
    out = np.empty(np.broadcast_shapes(np.shape(phi), np.shape(psi)) + (3, 3))
    out[..., 0, 0] = cf * ct * cp - sf * sp
    out[..., 0, 1] = -cf * ct * sp - sf * cp
    out[..., 0, 2] = cf * st
    out[..., 1, 0] = sf * ct * cp + cf * sp
    out[..., 1, 1] = -sf * ct * sp + cf * cp
    out[..., 1, 2] = sf * st
    out[..., 2, 0] = -st * cp
    out[..., 2, 1] = st * sp
    out[..., 2, 2] = ct
    return out


def _tilt(tilt_deg: float, azimuth_deg: float) -> np.ndarray:
    """(3, 3) Rz(a) @ Ry(-t) @ Rz(-a), in the spin frame's body-fixed coordinates: the body
    direction (sin t cos a, sin t sin a, cos t) turned onto the spin axis +z."""
    a, t = math.radians(azimuth_deg), math.radians(tilt_deg)
    return rot_z(a) @ _zyz(0.0, -t, -a)


def _spin_direction_body(spin_axis: str, tilt_deg: float = 0.0, azimuth_deg: float = 0.0) -> np.ndarray:
    """(3,) body coordinates of the spin frame's +z: the spin-frame direction (sin t cos a,
    sin t sin a, cos t) that :func:`_tilt` turns onto +z, its columns relabelled as body axes."""
    t, a = math.radians(tilt_deg), math.radians(azimuth_deg)
    spin = np.array([math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t)])
    return spin[_BODY_FROM_SPIN_COLUMNS[spin_axis]]


def _pole_frame(ra_deg: float, dec_deg: float) -> np.ndarray:
    """(3, 3) Rz(ra + 90) @ Rx(90 - dec): columns node, (pole x node), pole in GCRS."""
    ra, dec = math.radians(ra_deg), math.radians(dec_deg)
    node = np.array([-math.sin(ra), math.cos(ra), 0.0])
    pole = np.array([math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])
    return np.stack([node, np.cross(pole, node), pole], axis=-1)


# -- the seed paper's model -----------------------------------------------------------------
@dataclass(frozen=True)
class PrecessingSpin:
    """Spin about a body axis whose direction precesses on a cone around nadir (seed paper).

    Parameters
    ----------
    period_s : float
        Spin period about the spin axis, relative to the precessing frame, seconds.
    phase_deg : float
        Spin angle psi at ``t_s = 0``.
    precession_period_s : float
        Period of the spin axis around nadir, relative to the LVLH frame (inf: fixed).
    precession_phase_deg : float
        Azimuth phi of the spin axis around nadir at ``t_s = 0``, from LVLH +x toward +y.
    precession_angle_deg : float
        Half-angle theta of the precession cone (angle between spin axis and nadir), 0..180.
    spin_axis : {"x", "y", "z"}
        Body axis that spins (the seed paper: TOPEX "z", COSMOS 2502 end over end "x").

    Examples
    --------
    >>> import numpy as np
    >>> lvlh = np.eye(3)[None]
    >>> m = PrecessingSpin(period_s=10.0, precession_angle_deg=30.0)
    >>> m.orientation(np.zeros(1), lvlh)[0, :, 2].round(6).tolist()  # body z (spin axis) in LVLH
    [0.5, 0.0, 0.866025]
    """

    period_s: float
    phase_deg: float = 0.0
    precession_period_s: float = math.inf
    precession_phase_deg: float = 0.0
    precession_angle_deg: float = 0.0
    spin_axis: str = "z"

    def __post_init__(self):
        owner = "PrecessingSpin"
        object.__setattr__(self, "period_s", _check_period(owner, "period_s", self.period_s))
        object.__setattr__(
            self, "precession_period_s", _check_period(owner, "precession_period_s", self.precession_period_s)
        )
        for name in ("phase_deg", "precession_phase_deg", "precession_angle_deg"):
            object.__setattr__(self, name, _check_angle(owner, name, getattr(self, name)))
        if not 0.0 <= self.precession_angle_deg <= 180.0:
            raise ValueError(f"PrecessingSpin: precession_angle_deg={self.precession_angle_deg!r} must lie in [0, 180]")
        _check_axis(owner, self.spin_axis)

    def orientation(self, t_s, lvlh_gcrs=None) -> np.ndarray:
        """Body-to-GCRS rotations.

        Parameters
        ----------
        t_s : (...) float
            Seconds since the pass's first observed time.
        lvlh_gcrs : (..., 3, 3) float
            Local orbital frames at those times (required).

        Returns
        -------
        (..., 3, 3) float
        """
        t = np.asarray(t_s, dtype=float)
        if lvlh_gcrs is None:
            raise ValueError(
                "PrecessingSpin needs lvlh_gcrs (the local orbital frames at t_s); "
                "call geometry.body_frame(model) or pass PassGeometry.lvlh_gcrs"
            )
        lvlh = np.asarray(lvlh_gcrs, dtype=float)
        if lvlh.shape != t.shape + (3, 3):
            raise ValueError(
                f"lvlh_gcrs has shape {lvlh.shape} but t_s has shape {t.shape}; expected {t.shape + (3, 3)}"
            )
        phi = _angle_rad(self.precession_phase_deg, self.precession_period_s, t)
        psi = _angle_rad(self.phase_deg, self.period_s, t)
        spin_to_lvlh = _zyz(phi, math.radians(self.precession_angle_deg), psi)
        return np.matmul(lvlh, spin_to_lvlh)[..., _BODY_FROM_SPIN_COLUMNS[self.spin_axis]]

    @property
    def spin_direction_body(self) -> np.ndarray:
        """(3,) the spin axis in body coordinates: the body axis `spin_axis`."""
        return _spin_direction_body(self.spin_axis)


# -- inertially fixed spin axis ------------------------------------------------------------
@dataclass(frozen=True)
class InertialSpin:
    """Uniform spin about a body axis fixed in inertial space (IAU rotation convention).

    Parameters
    ----------
    pole_ra_deg, pole_dec_deg : float
        Right ascension and declination (GCRS) of the spin axis.
    period_s : float
        Spin period, seconds (negative: retrograde about the pole).
    phase_deg : float
        Angle W at ``t_s = 0`` from the node (``z x pole``) to the reference axis.
    spin_axis : {"x", "y", "z"}
        Body axis that spins, or from which the spin axis is tilted.
    axis_tilt_deg : float
        Angle between the spin axis and the body axis `spin_axis`, 0..180 (a body spinning
        steadily about a principal axis of inertia that is none of its mesh's axes).
    axis_tilt_azimuth_deg : float
        Direction of that tilt about `spin_axis`, from the next body axis in cyclic order (x for
        "z", y for "x", z for "y") toward the one after it: the spin axis in body coordinates
        is (sin t cos a, sin t sin a, cos t) in those three axes.
    """

    pole_ra_deg: float
    pole_dec_deg: float
    period_s: float
    phase_deg: float = 0.0
    spin_axis: str = "z"
    axis_tilt_deg: float = 0.0
    axis_tilt_azimuth_deg: float = 0.0

    def __post_init__(self):
        owner = "InertialSpin"
        object.__setattr__(self, "period_s", _check_period(owner, "period_s", self.period_s))
        for name in ("pole_ra_deg", "pole_dec_deg", "phase_deg", "axis_tilt_deg", "axis_tilt_azimuth_deg"):
            object.__setattr__(self, name, _check_angle(owner, name, getattr(self, name)))
        if not -90.0 <= self.pole_dec_deg <= 90.0:
            raise ValueError(f"InertialSpin: pole_dec_deg={self.pole_dec_deg!r} must lie in [-90, 90]")
        if not 0.0 <= self.axis_tilt_deg <= 180.0:
            raise ValueError(f"InertialSpin: axis_tilt_deg={self.axis_tilt_deg!r} must lie in [0, 180]")
        _check_axis(owner, self.spin_axis)

    def orientation(self, t_s, lvlh_gcrs=None) -> np.ndarray:
        """Body-to-GCRS rotations; `lvlh_gcrs` is accepted and ignored.

        Parameters
        ----------
        t_s : (...) float
            Seconds since the pass's first observed time.

        Returns
        -------
        (..., 3, 3) float
        """
        t = np.asarray(t_s, dtype=float)
        spin = rot_z(_angle_rad(self.phase_deg, self.period_s, t))
        if self.axis_tilt_deg != 0.0:
            spin = np.matmul(spin, _tilt(self.axis_tilt_deg, self.axis_tilt_azimuth_deg))
        return np.matmul(_pole_frame(self.pole_ra_deg, self.pole_dec_deg), spin)[
            ..., _BODY_FROM_SPIN_COLUMNS[self.spin_axis]
        ]

    @property
    def spin_direction_body(self) -> np.ndarray:
        """(3,) the spin axis in body coordinates (the body direction that stays on the pole):
        `spin_axis`, leaned by `axis_tilt_deg` toward `axis_tilt_azimuth_deg`."""
        return _spin_direction_body(self.spin_axis, self.axis_tilt_deg, self.axis_tilt_azimuth_deg)


# -- torque-free rigid body -----------------------------------------------------------------
@dataclass(frozen=True)
class TorqueFree:
    """A rigid body tumbling freely: Euler's equations plus quaternion kinematics, integrated.

    Parameters
    ----------
    inertia_kg_m2 : (3,) float
        Principal moments of inertia about body x, y, z (any common unit: only ratios matter).
        They must be positive and satisfy the triangle inequalities of a real body.
    omega0_rad_s : (3,) float
        Angular velocity at ``t_s = 0`` in body axes, rad/s.
    rotation0 : (3, 3) float
        Body-to-GCRS rotation at ``t_s = 0`` (orthonormal, determinant +1).

    Notes
    -----
    Rotational energy ``omega . I omega / 2`` and the GCRS angular momentum ``R I omega`` are
    conserved to ~1e-10 relative over 1e4 s at the integrator's tolerance (tested).
    `from_angular_momentum` builds ``rotation0`` from the direction of the angular momentum.
    """

    inertia_kg_m2: tuple
    omega0_rad_s: tuple
    rotation0: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

    def __post_init__(self):
        inertia = np.asarray(self.inertia_kg_m2, dtype=float)
        omega = np.asarray(self.omega0_rad_s, dtype=float)
        rotation = np.asarray(self.rotation0, dtype=float)
        if inertia.shape != (3,) or not np.all(np.isfinite(inertia)) or np.any(inertia <= 0):
            raise ValueError(f"TorqueFree: inertia_kg_m2={self.inertia_kg_m2!r} must be three positive moments")
        largest = int(np.argmax(inertia))
        if inertia[largest] > inertia.sum() - inertia[largest] + 1e-12 * inertia.sum():
            raise ValueError(
                f"TorqueFree: inertia_kg_m2={self.inertia_kg_m2!r} breaks the triangle inequality "
                "(no moment may exceed the sum of the other two); check the moments"
            )
        if omega.shape != (3,) or not np.all(np.isfinite(omega)):
            raise ValueError(f"TorqueFree: omega0_rad_s={self.omega0_rad_s!r} must be three finite rates in rad/s")
        if (
            rotation.shape != (3, 3)
            or not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-9)
            or np.linalg.det(rotation) < 0
        ):
            raise ValueError("TorqueFree: rotation0 must be a 3x3 rotation matrix (orthonormal, det +1)")
        object.__setattr__(self, "inertia_kg_m2", tuple(inertia.tolist()))
        object.__setattr__(self, "omega0_rad_s", tuple(omega.tolist()))
        object.__setattr__(self, "rotation0", tuple(map(tuple, rotation.tolist())))

    @classmethod
    def from_angular_momentum(
        cls, inertia_kg_m2, omega0_rad_s, pole_ra_deg: float, pole_dec_deg: float, phase_deg: float = 0.0
    ) -> TorqueFree:
        """Orient the body at ``t_s = 0`` so its angular momentum points to (ra, dec).

        The body-frame angular momentum ``h = I omega0`` is sent to the GCRS pole (ra, dec);
        ``phase_deg`` turns the body about that axis, measured like `InertialSpin`'s W for the
        body direction ``normalise(z_body x h)`` (or ``x_body`` when h is along z).

        Parameters
        ----------
        inertia_kg_m2, omega0_rad_s : (3,) float
            As in the class.
        pole_ra_deg, pole_dec_deg : float
            Direction of the (conserved) angular momentum in GCRS.
        phase_deg : float
            Rotation about the angular momentum at ``t_s = 0``.

        Returns
        -------
        TorqueFree
        """
        h = np.asarray(inertia_kg_m2, dtype=float) * np.asarray(omega0_rad_s, dtype=float)
        norm = np.linalg.norm(h)
        if not norm > 0:
            raise ValueError(
                "TorqueFree.from_angular_momentum: omega0_rad_s is zero, so there is no angular momentum to orient"
            )
        h = h / norm
        first = np.cross([0.0, 0.0, 1.0], h)
        first = first / np.linalg.norm(first) if np.linalg.norm(first) > 1e-9 else np.array([1.0, 0.0, 0.0])
        h_frame = np.stack([first, np.cross(h, first), h], axis=-1)  # body coordinates
        rotation0 = (
            _pole_frame(
                _check_angle("TorqueFree", "pole_ra_deg", pole_ra_deg),
                _check_angle("TorqueFree", "pole_dec_deg", pole_dec_deg),
            )
            @ rot_z(math.radians(_check_angle("TorqueFree", "phase_deg", phase_deg)))
            @ h_frame.T
        )
        return cls(inertia_kg_m2, omega0_rad_s, rotation0)

    def orientation(self, t_s, lvlh_gcrs=None) -> np.ndarray:
        """Body-to-GCRS rotations; `lvlh_gcrs` is accepted and ignored.

        Parameters
        ----------
        t_s : (...) float
            Seconds since the pass's first observed time.

        Returns
        -------
        (..., 3, 3) float
        """
        t = np.asarray(t_s, dtype=float)
        quaternion = self._state(t)[..., 3:]
        return _quaternion_matrix(quaternion / np.linalg.norm(quaternion, axis=-1, keepdims=True))

    def angular_velocity_body(self, t_s) -> np.ndarray:
        """(..., 3) angular velocity in body axes at the given times, rad/s."""
        return self._state(np.asarray(t_s, dtype=float))[..., :3]

    def _state(self, t: np.ndarray) -> np.ndarray:
        """(..., 7) integrated state (omega, quaternion) at times t."""
        if not np.all(np.isfinite(t)):
            raise ValueError("TorqueFree: t_s must be finite seconds")
        flat = t.ravel()
        out = np.empty((flat.size, 7))
        for direction, chosen in ((1.0, flat >= 0.0), (-1.0, flat < 0.0)):
            if np.any(chosen):
                elapsed, inverse = np.unique(direction * flat[chosen], return_inverse=True)
                states = _trajectory(
                    self.inertia_kg_m2, self.omega0_rad_s, self.rotation0, direction, elapsed.tobytes()
                )
                out[chosen] = states[inverse]
        return out.reshape(t.shape + (7,))


@functools.lru_cache(maxsize=16)
def _trajectory(inertia: tuple, omega0: tuple, rotation0: tuple, direction: float, elapsed_bytes: bytes):
    """(m, 7) states at the sorted elapsed times |t| (float64 bytes) in one time direction.

    LSODA (scipy's odeint: Adams-Moulton of order up to 12 on this non-stiff problem) at
    rtol = atol = 1e-13.
    """
    elapsed = np.frombuffer(elapsed_bytes, dtype=float)
    i1, i2, i3 = inertia
    a1, a2, a3 = (i2 - i3) / i1, (i3 - i1) / i2, (i1 - i2) / i3
    half = 0.5 * direction

    def rates(y, _t):
        w1, w2, w3, q0, q1, q2, q3 = y
        return (
            direction * a1 * w2 * w3,
            direction * a2 * w3 * w1,
            direction * a3 * w1 * w2,
            half * (-q1 * w1 - q2 * w2 - q3 * w3),
            half * (q0 * w1 + q2 * w3 - q3 * w2),
            half * (q0 * w2 + q3 * w1 - q1 * w3),
            half * (q0 * w3 + q1 * w2 - q2 * w1),
        )

    y0 = np.concatenate([omega0, _matrix_quaternion(np.asarray(rotation0))])
    grid = np.concatenate([[0.0], elapsed]) if elapsed[0] > 0.0 else elapsed
    states, info = odeint(rates, y0, grid, rtol=1e-13, atol=1e-13, mxstep=10**7, full_output=True)
    if info["message"] != "Integration successful.":
        raise RuntimeError(f"TorqueFree integration failed: {info['message']}")
    states = states[grid.size - elapsed.size :]
    states.setflags(write=False)
    return states


def _quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices of unit quaternions (..., 4), scalar first."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    out = np.empty(q.shape[:-1] + (3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - w * z)
    out[..., 0, 2] = 2 * (x * z + w * y)
    out[..., 1, 0] = 2 * (x * y + w * z)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - w * x)
    out[..., 2, 0] = 2 * (x * z - w * y)
    out[..., 2, 1] = 2 * (y * z + w * x)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def _matrix_quaternion(m: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,), scalar first, of a rotation matrix (Shepperd's method)."""
    trace = np.trace(m)
    candidates = [trace, m[0, 0], m[1, 1], m[2, 2]]
    k = int(np.argmax(candidates))
    if k == 0:
        w = 0.5 * math.sqrt(1 + trace)
        q = [w, (m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w), (m[1, 0] - m[0, 1]) / (4 * w)]
    elif k == 1:
        x = 0.5 * math.sqrt(1 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / (4 * x), x, (m[0, 1] + m[1, 0]) / (4 * x), (m[0, 2] + m[2, 0]) / (4 * x)]
    elif k == 2:
        y = 0.5 * math.sqrt(1 - m[0, 0] + m[1, 1] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / (4 * y), (m[0, 1] + m[1, 0]) / (4 * y), y, (m[1, 2] + m[2, 1]) / (4 * y)]
    else:
        z = 0.5 * math.sqrt(1 - m[0, 0] - m[1, 1] + m[2, 2])
        q = [(m[1, 0] - m[0, 1]) / (4 * z), (m[0, 2] + m[2, 0]) / (4 * z), (m[1, 2] + m[2, 1]) / (4 * z), z]
    q = np.asarray(q)
    return q / np.linalg.norm(q)


# -- one entry point ------------------------------------------------------------------------
ATTITUDE_MODELS = {
    "precessing": PrecessingSpin,
    "inertial": InertialSpin,
    "torque_free": TorqueFree,
}


def build(name: str, **parameters):
    """Build an attitude model by name from `ATTITUDE_MODELS`.

    Parameters
    ----------
    name : {"precessing", "inertial", "torque_free"}
        Which model.
    **parameters
        The model's constructor arguments.

    Returns
    -------
    PrecessingSpin or InertialSpin or TorqueFree

    Examples
    --------
    >>> build("precessing", period_s=9.86, precession_period_s=689.0, precession_angle_deg=35.0)
    PrecessingSpin(period_s=9.86, phase_deg=0.0, precession_period_s=689.0, precession_phase_deg=0.0, precession_angle_deg=35.0, spin_axis='z')
    """
    if name not in ATTITUDE_MODELS:
        raise ValueError(f"unknown attitude model {name!r}; choose one of {', '.join(ATTITUDE_MODELS)}")
    return ATTITUDE_MODELS[name](**parameters)
