"""Ray-casting pieces shared by the direct renderer and the fast path: the Open3D scene, the
solar disk's quadrature and the part of it above a face, and the check of the direction arrays
both take."""

from __future__ import annotations

import math

from numba import njit
import numpy as np

__all__ = [
    "SUN_RADIUS_RAD",
    "SUN_RADIUS_SINE",
    "sun_fraction",
    "sun_fractions",
    "risen_sun",
    "risen_suns",
    "orthonormal_basis",
    "sun_disk_rule",
    "sun_disk_directions",
    "sun_samples_for",
    "open3d_scene",
    "check_directions",
]

# Mean angular radius of the solar disk seen from the Earth: 0.533 deg / 2.
SUN_RADIUS_RAD = math.radians(0.533 / 2.0)
SUN_RADIUS_SINE = math.sin(SUN_RADIUS_RAD)

# Helper axes for the pixel grid, deliberately not aligned with body axes: a grid aligned with
# the edges of an axis-aligned box would count whole rows of pixels centred on its edges.
_HELPERS = np.array([[0.2672612, 0.5345225, 0.8017837], [0.8728716, -0.4364358, 0.2182179]])


def orthonormal_basis(directions):
    """Two unit vectors (m, 3) each perpendicular to ``directions`` (m, 3) and to each other."""
    d = np.asarray(directions, dtype=float)
    helper = np.where((np.abs(d @ _HELPERS[0]) < 0.9)[:, None], _HELPERS[0], _HELPERS[1])
    u = np.cross(helper, d)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(d, u)
    return u, v


def sun_disk_rule(n_samples):
    """A quadrature rule for the average over the solar disk.

    Returns offsets (q, 2) in units of the disk radius and weights (q,) summing to 1:
    1 point (the centre); 7 points (Stroud's degree-5 rule: the centre with weight 1/4 and six
    points at radius sqrt(2/3) with 1/8 each); or for more, a polar product rule (Gauss-Legendre
    in r**2 with 3 nodes, 8 equally spaced azimuths per ring, 24 points, exact to degree 5 and
    symmetric, so no first-order bias on a lobe's flank).
    """
    if n_samples == 1:
        return np.zeros((1, 2)), np.ones(1)
    if n_samples == 7:
        angle = np.arange(6) * np.pi / 3.0
        ring = math.sqrt(2.0 / 3.0) * np.column_stack([np.cos(angle), np.sin(angle)])
        return np.vstack([[0.0, 0.0], ring]), np.r_[0.25, np.full(6, 0.125)]
    nodes, weights = np.polynomial.legendre.leggauss(3)
    radius = np.sqrt((nodes + 1.0) / 2.0)
    offsets, rule_weights = [], []
    for ring, (r, w) in enumerate(zip(radius, weights)):
        angle = (np.arange(8) + 0.5 * ring) * np.pi / 4.0
        offsets.append(r * np.column_stack([np.cos(angle), np.sin(angle)]))
        rule_weights.append(np.full(8, w / 2.0 / 8.0))
    return np.vstack(offsets), np.concatenate(rule_weights)


def sun_disk_directions(sun, n_samples):
    """Directions to the points of :func:`sun_disk_rule` around each ``sun`` (m, 3).

    Returns
    -------
    directions : (q, m, 3) float, unit vectors.
    weights : (q,) float, summing to 1.
    """
    sun = np.asarray(sun, dtype=float)
    offsets, weights = sun_disk_rule(n_samples)
    if len(weights) == 1:
        return sun[None], weights
    u, v = orthonormal_basis(sun)
    directions = sun[None] + SUN_RADIUS_RAD * (
        offsets[:, 0, None, None] * u[None] + offsets[:, 1, None, None] * v[None]
    )
    return directions / np.linalg.norm(directions, axis=2, keepdims=True), weights


@njit(cache=True, nogil=True)
def sun_fraction(cos_s):
    """Fraction of the solar disk above a face's plane, ``cos_s`` the cosine between the Sun's
    centre and the face's normal (a scalar; :func:`sun_fractions` for arrays).

    A face grazed by the Sun is lit by the part of the disk above its plane, and Cycles samples
    that disk: within 0.27 deg of the plane the light a face gets goes smoothly to zero instead
    of stopping at the centre. On smooth-shaded faces the shading normal can lean toward the
    Sun by tens of degrees there, so the disk's edge decides whole bands of light.
    """
    if cos_s >= SUN_RADIUS_SINE:
        return 1.0
    if cos_s <= -SUN_RADIUS_SINE:
        return 0.0
    x = math.asin(cos_s) / SUN_RADIUS_RAD
    x = min(max(x, -1.0), 1.0)
    return 1.0 - (math.acos(x) - x * math.sqrt(1.0 - x * x)) / math.pi


def sun_fractions(cos_s):
    """:func:`sun_fraction` of an array of cosines, same shape."""
    cos_s = np.asarray(cos_s, dtype=float)
    x = np.clip(np.arcsin(np.clip(cos_s, -1.0, 1.0)) / SUN_RADIUS_RAD, -1.0, 1.0)
    return 1.0 - (np.arccos(x) - x * np.sqrt(1.0 - x * x)) / np.pi


@njit(cache=True, nogil=True)
def risen_sun(nx, ny, nz, sx, sy, sz):
    """Where the light of the solar disk above a face's plane comes from, for a face of unit
    normal n and the Sun's centre s: s itself when the whole disk is above the plane, else the
    centroid of the part that is (its elevation ``r (x + 2 (1 - x**2)**1.5 / (3 pi f))``, x the
    centre's elevation in disk radii r and f :func:`sun_fraction`). A Lambertian face's light
    is then exactly ``f`` times that of a Sun at the centroid (the cosine is linear in the
    direction), and shadow rays toward it sample the light the face gets, not the set part."""
    c = nx * sx + ny * sy + nz * sz
    if c >= SUN_RADIUS_SINE:
        return sx, sy, sz
    x = min(max(math.asin(max(c, -1.0)) / SUN_RADIUS_RAD, -1.0), 1.0)
    fraction = sun_fraction(c)
    lift = 1.0 if fraction < 1e-12 else 2.0 * (1.0 - x * x) ** 1.5 / (3.0 * math.pi * fraction)
    elevation = SUN_RADIUS_RAD * (x + min(lift, 1.0 - x))
    px, py, pz = sx - c * nx, sy - c * ny, sz - c * nz
    norm = math.sqrt(px * px + py * py + pz * pz)
    if norm == 0.0:
        return sx, sy, sz
    ce, se = math.cos(elevation) / norm, math.sin(elevation)
    return ce * px + se * nx, ce * py + se * ny, ce * pz + se * nz


@njit(cache=True, nogil=True)
def risen_suns(normals, suns):
    """:func:`risen_sun` of (k, 3) face normals and (k, 3) Sun directions, (k, 3)."""
    out = np.empty_like(suns)
    for k in range(len(suns)):
        out[k, 0], out[k, 1], out[k, 2] = risen_sun(
            normals[k, 0], normals[k, 1], normals[k, 2], suns[k, 0], suns[k, 1], suns[k, 2]
        )
    return out


def open3d_scene(mesh):
    """An Open3D RaycastingScene of a mesh's triangle soup (``mesh.vertices_m``, 3 rows per triangle)."""
    # Open3D takes seconds to import (and pulls in Dash); only ray casting needs it.
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    vertices = mesh.vertices_m.astype(np.float32)
    triangles = np.arange(len(vertices), dtype=np.uint32).reshape(-1, 3)
    scene.add_triangles(vertices, triangles)
    return scene


def sun_samples_for(brdf, accuracy_mag):
    """Solar-disk samples the BRDF ``brdf`` needs for ``accuracy_mag``.

    Averaging a specular lobe of width alpha over the solar disk lowers its peak by about
    r_sun**2 / (4 alpha**2) (second order in the disk radius), and only at the glint's peak.
    One sample (the disk centre) is kept while that is below a fifth of the accuracy (Glossy
    roughness 0.3 at 0.005 mag: 0.0007 mag at the peak, at a seventh of the 7-point rule's cost);
    otherwise the 7-point rule of :func:`sun_disk_rule`, or its 24-point rule when the effect
    exceeds ten times the accuracy.
    """
    if brdf is None or not brdf.lobe_width_rad:
        return 1
    relative_effect = SUN_RADIUS_RAD**2 / (4.0 * brdf.lobe_width_rad**2)
    tolerance = accuracy_mag / 1.0857
    if relative_effect < 0.2 * tolerance:
        return 1
    return 7 if relative_effect < 10.0 * tolerance else 24


def check_directions(sun_body, obs_body):
    """Validate (m, 3) unit vectors toward the Sun and the observer; returns them as float arrays."""
    sun = np.asarray(sun_body, dtype=float)
    obs = np.asarray(obs_body, dtype=float)
    for name, value in (("sun_body", sun), ("obs_body", obs)):
        if value.ndim != 2 or value.shape[1] != 3:
            raise ValueError(f"{name} has shape {value.shape}; expected (m, 3) unit vectors")
        if not np.all(np.isfinite(value)):
            raise ValueError(f"{name} contains non-finite values; check the geometry")
        norms = np.linalg.norm(value, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-6):
            worst = float(norms[np.argmax(np.abs(norms - 1.0))])
            raise ValueError(f"{name} holds a vector of length {worst:.6g}; give unit vectors")
    if sun.shape != obs.shape:
        raise ValueError(f"sun_body {sun.shape} and obs_body {obs.shape} must have the same shape")
    return sun, obs
