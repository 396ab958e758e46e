"""Synodic (apparent) and sidereal (inertial) spin periods: the phase-angle-bisector correction.

A light curve repeats when the body presents the same face to the Sun and the observer
together. For an unresolved body that geometry is summarised, to first order, by the
phase-angle bisector (PAB): the unit vector along ``sun_dir + obs_dir`` seen from the object
(Harris et al. 1984, Icarus 57, 251; the "PAB approximation" of asteroid light-curve work).
If the PAB turns about the spin axis at an angular rate ``omega`` (rad/s, counted positive in
the sense of the spin), the body must turn further to show the PAB the same face, so::

    1 / P_syn = 1 / P_sid - omega / (2 pi)          (1)

For a satellite the PAB moves fast (the observer's line of sight sweeps the sky during a
pass): TOPEX at 1300 km moves its PAB by ~0.1-0.3 deg/s, a 0.3-0.8 % period shift at 10 s,
larger than the measurement error of a single pass.

With the spin axis known, ``omega`` is the mean rate of the PAB's azimuth about the axis
(`azimuth_rate_rad_s`). With the axis unknown - the usual case when the period is measured -
both the sense and the projection are unknown. We then assume the PAB stays near the spin
equator (the classical approximation), take ``|omega|`` as the PAB's mean angular speed
(`bisector_rate_rad_s`: arc length along its path over the duration), and report the two
sidereal periods of (1) for prograde (``+|omega|``) and retrograde (``-|omega|``) motion;
the true sidereal period lies between them when the approximation holds. The synodic period
is what the light curve measures and is always stored as measured.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

__all__ = [
    "phase_angle_bisector",
    "bisector_rate_rad_s",
    "azimuth_rate_rad_s",
    "sidereal_period_s",
    "SynodicCorrection",
]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def phase_angle_bisector(sun_dir, obs_dir) -> np.ndarray:
    """Unit phase-angle bisector.

    Parameters
    ----------
    sun_dir, obs_dir : (..., 3) float
        Unit vectors from the object toward the Sun and toward the observer.

    Returns
    -------
    (..., 3) float
        ``(sun_dir + obs_dir) / |sun_dir + obs_dir|``.
    """
    return _unit(np.asarray(sun_dir, dtype=float) + np.asarray(obs_dir, dtype=float))


def bisector_rate_rad_s(t_s, bisector) -> float:
    """Mean angular speed of the bisector: length of its path on the sphere over the duration.

    Parameters
    ----------
    t_s : (n,) float
        Times, seconds, increasing.
    bisector : (n, 3) float
        Unit vectors.

    Returns
    -------
    float
        rad/s.
    """
    b = np.asarray(bisector, dtype=float)
    dots = np.clip(np.einsum("ij,ij->i", b[:-1], b[1:]), -1.0, 1.0)
    cross = np.linalg.norm(np.cross(b[:-1], b[1:]), axis=-1)
    arc = np.arctan2(cross, dots).sum()  # atan2 stays accurate for tiny steps
    return float(arc / (t_s[-1] - t_s[0]))


def azimuth_rate_rad_s(t_s, bisector, spin_axis) -> float:
    """Mean rate of the bisector's azimuth about a spin axis (right-handed, rad/s).

    Parameters
    ----------
    t_s : (n,) float
    bisector : (n, 3) float
        Unit vectors, same frame as `spin_axis`.
    spin_axis : (3,) float
        The spin axis (need not be normalised); the spin is right-handed about it.

    Returns
    -------
    float
        Unwrapped azimuth change over the duration, rad/s; positive when the bisector turns in
        the sense of the spin. Undefined (large) when the bisector passes near the axis.
    """
    s = _unit(np.asarray(spin_axis, dtype=float))
    e1 = _unit(np.cross(s, [1.0, 0.0, 0.0]) if abs(s[0]) < 0.9 else np.cross(s, [0.0, 1.0, 0.0]))
    e2 = np.cross(s, e1)
    b = np.asarray(bisector, dtype=float)
    azimuth = np.unwrap(np.arctan2(b @ e2, b @ e1))
    return float((azimuth[-1] - azimuth[0]) / (t_s[-1] - t_s[0]))


def sidereal_period_s(synodic_period_s, omega_rad_s):
    """Sidereal period from the synodic one, relation (1) of this module.

    Parameters
    ----------
    synodic_period_s : float or array
    omega_rad_s : float or array
        Rate of the bisector about the spin axis, positive in the sense of the spin.

    Returns
    -------
    float or array
        ``1 / (1 / P_syn + omega / 2 pi)``.

    Examples
    --------
    >>> round(sidereal_period_s(10.0, 2 * math.pi / 1000.0), 6)    # PAB turns once per 1000 s
    9.90099
    """
    return 1.0 / (1.0 / np.asarray(synodic_period_s, dtype=float) + np.asarray(omega_rad_s) / (2 * math.pi))


@dataclass(frozen=True)
class SynodicCorrection:
    """The PAB correction of one pass.

    Attributes
    ----------
    synodic_period_s : float
        The measured (apparent) period.
    bisector_rate_deg_s : float
        Mean angular speed of the PAB over the pass.
    bisector_arc_deg : float
        Length of the PAB's path over the pass.
    sidereal_prograde_s : float
        Sidereal period if the PAB turns with the spin (``omega = +rate``): shorter than synodic.
    sidereal_retrograde_s : float
        Sidereal period if it turns against the spin (``omega = -rate``): longer than synodic.
    """

    synodic_period_s: float
    bisector_rate_deg_s: float
    bisector_arc_deg: float
    sidereal_prograde_s: float
    sidereal_retrograde_s: float

    @property
    def max_correction_s(self) -> float:
        """Largest ``|P_sid - P_syn|`` allowed by the unknown sense of rotation."""
        return max(
            abs(self.sidereal_prograde_s - self.synodic_period_s),
            abs(self.sidereal_retrograde_s - self.synodic_period_s),
        )

    @classmethod
    def from_directions(cls, synodic_period_s: float, t_s, sun_dir, obs_dir) -> SynodicCorrection:
        """The correction from Sun and observer directions over the pass.

        Parameters
        ----------
        synodic_period_s : float
        t_s : (n,) float
            Times, seconds, increasing, n >= 2.
        sun_dir, obs_dir : (n, 3) float
            Unit vectors from the object to the Sun and to the observer, inertial frame.
        """
        t_s = np.asarray(t_s, dtype=float)
        bisector = phase_angle_bisector(sun_dir, obs_dir)
        rate = bisector_rate_rad_s(t_s, bisector)
        return cls(
            synodic_period_s=float(synodic_period_s),
            bisector_rate_deg_s=math.degrees(rate),
            bisector_arc_deg=math.degrees(rate * (t_s[-1] - t_s[0])),
            sidereal_prograde_s=float(sidereal_period_s(synodic_period_s, rate)),
            sidereal_retrograde_s=float(sidereal_period_s(synodic_period_s, -rate)),
        )

    @classmethod
    def from_geometry(cls, synodic_period_s: float, geometry) -> SynodicCorrection:
        """The correction from a `raycast.geometry.PassGeometry` (its exposure-weighted directions)."""
        sun = np.einsum("nkj,k->nj", geometry.sun_gcrs, geometry.weights)
        obs = np.einsum("nkj,k->nj", geometry.obs_gcrs, geometry.weights)
        return cls.from_directions(synodic_period_s, geometry.t_s, _unit(sun), _unit(obs))

    def to_dict(self) -> dict:
        return {
            "synodic_period_s": self.synodic_period_s,
            "bisector_rate_deg_s": self.bisector_rate_deg_s,
            "bisector_arc_deg": self.bisector_arc_deg,
            "sidereal_prograde_s": self.sidereal_prograde_s,
            "sidereal_retrograde_s": self.sidereal_retrograde_s,
        }
