"""Helpers shared by the renderer tests: direction pairs and a minimal BodyGeometry."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

METHODS = ("direct", "cached")


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def in_plane(incidence_deg, emergence_deg, azimuth_deg=180.0):
    """Sun and observer unit vectors (m, 3) over a +z normal: Sun at ``incidence`` from the
    normal in the x-z plane, observer at ``emergence`` and ``azimuth`` from the Sun's plane."""
    i = np.radians(np.atleast_1d(incidence_deg).astype(float))
    e = np.radians(np.atleast_1d(emergence_deg).astype(float))
    a = np.radians(np.broadcast_to(azimuth_deg, e.shape).astype(float))
    sun = np.column_stack([np.sin(i), np.zeros_like(i), np.cos(i)])
    obs = np.column_stack([np.sin(e) * np.cos(a), np.sin(e) * np.sin(a), np.cos(e)])
    return sun, obs


def geometry(sun, obs, sunlit=None, range_km=1000.0):
    """A BodyGeometry-like object with k = 1 sub-sample per frame (or (n, k, 3) inputs)."""
    sun = np.asarray(sun, dtype=float)
    obs = np.asarray(obs, dtype=float)
    if sun.ndim == 2:
        sun, obs = sun[:, None, :], obs[:, None, :]
    n, k = sun.shape[:2]
    phase = np.degrees(np.arccos(np.clip(np.einsum("nj,nj->n", sun[:, 0], obs[:, 0]), -1, 1)))
    return SimpleNamespace(
        sun_body=sun,
        obs_body=obs,
        weights=np.full(k, 1.0 / k),
        sunlit=np.ones((n, k)) if sunlit is None else np.asarray(sunlit, dtype=float),
        range_km=np.full(n, range_km),
        phase_angle_deg=phase,
    )


def topex_pass_geometry(attitude, frames=slice(None), exposure_s=None):
    """Body-frame geometry of the real TOPEX pass (2024-07-30, Derenivka) for ``attitude``.

    ``frames`` selects observed rows; ``exposure_s=0`` turns exposure integration off.
    """
    import ingest
    from raycast.geometry.orbit import Satellite
    from raycast.geometry.pass_geometry import PassGeometry
    from tests.conftest import TOPEX_PHV

    observed = ingest.read_file(TOPEX_PHV)[0]
    times = observed.time_utc[frames]
    exposure = observed.exposure_s if exposure_s is None else exposure_s
    pass_geometry = PassGeometry.compute(Satellite.from_tle(observed.tle), observed.site, times, exposure_s=exposure)
    return pass_geometry.body_frame(attitude)


def rms_mag(value, reference, dark_fraction=1e-3):
    """RMS magnitude difference over frames brighter than ``dark_fraction`` of the peak.

    Frames 7.5 mag below the peak are no observation's concern, and one renderer's exact 0
    against another's 1e-5 m^2/sr would count as an infinite error; they are checked in light
    instead (see ``dark_frames_agree``).
    """
    value, reference = np.asarray(value, dtype=float), np.asarray(reference, dtype=float)
    ok = reference > dark_fraction * reference.max()
    return float(np.sqrt(np.mean((2.5 * np.log10(np.maximum(value[ok], 1e-300) / reference[ok])) ** 2)))


def dark_frames_agree(value, reference, dark_fraction=1e-3):
    """The frames left out by :func:`rms_mag` differ by less than that fraction of the peak."""
    value, reference = np.asarray(value, dtype=float), np.asarray(reference, dtype=float)
    dark = reference <= dark_fraction * reference.max()
    return bool(np.all(np.abs(value[dark] - reference[dark]) <= dark_fraction * reference.max()))
