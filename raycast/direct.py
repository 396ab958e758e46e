"""The reference renderer: orthographic ray casting with shadow rays (Open3D RaycastingScene).

For each direction pair (Sun ``s``, observer ``o``, body frame) a regular grid of parallel rays
with spacing ``pixel_size_m`` covers the mesh's footprint seen from ``o``. Every hit adds

    f_r(s, o, n_s) * max(n_s . s, 0) * [n_g . s > 0] * V(x, s) * pixel_size_m**2

where ``n_g`` is the geometric normal of the hit triangle turned toward the observer (surfaces
are two-sided), ``n_s`` the shading normal interpolated from the corner normals at the hit's
barycentric coordinates (turned to ``n_g``'s side) and ``V`` the Sun visibility from a shadow
ray. The sum is I/E in m^2/sr. With ``sun_samples > 1`` the BRDF and the shadow ray are
averaged over that many points of the 0.533 deg solar disk (a Vogel spiral), which gives glints
of smooth materials their true angular width.

The pixel grid of each direction pair is shifted by a low-discrepancy (R2) sub-pixel offset, so
edge errors of successive frames do not repeat; the result is deterministic.

:meth:`DirectRenderer.from_accuracy` chooses the pixel size for a requested accuracy in
magnitudes by refining a pilot subset of the frames until two successive resolutions agree.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import math

import numpy as np

from raycast.scene import Scene

__all__ = ["DirectRenderer", "SUN_RADIUS_RAD", "sun_disk_directions", "orthonormal_basis"]

# Mean angular radius of the solar disk seen from the Earth: 0.533 deg / 2.
SUN_RADIUS_RAD = math.radians(0.533 / 2.0)
_PLASTIC = 1.32471795724474602596
_MAX_RAYS_PER_BATCH = 1_500_000


def orthonormal_basis(directions):
    """Two unit vectors (m, 3) each perpendicular to ``directions`` (m, 3) and to each other."""
    d = np.asarray(directions, dtype=float)
    helper = np.where((np.abs(d[:, 2]) < 0.9)[:, None], [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(helper, d)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(d, u)
    return u, v


def sun_disk_directions(sun, n_samples):
    """Directions to ``n_samples`` equal-area points of the solar disk around each ``sun`` (m, 3).

    Returns (q, m, 3) unit vectors (a Vogel spiral of q = ``n_samples`` points; q = 1 is the
    disk centre).
    """
    sun = np.asarray(sun, dtype=float)
    if n_samples == 1:
        return sun[None]
    k = np.arange(n_samples) + 0.5
    radius = SUN_RADIUS_RAD * np.sqrt(k / n_samples)
    angle = k * math.pi * (3.0 - math.sqrt(5.0))
    u, v = orthonormal_basis(sun)
    offsets = (radius * np.cos(angle))[:, None, None] * u + (radius * np.sin(angle))[:, None, None] * v
    directions = sun[None] + offsets
    return directions / np.linalg.norm(directions, axis=2, keepdims=True)


def _open3d_scene(mesh):
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    vertices = mesh.vertices_m.astype(np.float32)
    triangles = np.arange(len(vertices), dtype=np.uint32).reshape(-1, 3)
    scene.add_triangles(vertices, triangles)
    return scene


@dataclass(frozen=True, eq=False)
class DirectRenderer:
    """Reference ray-cast renderer of one scene.

    Parameters
    ----------
    scene : Scene
    pixel_size_m : float, spacing of the orthographic ray grid.
    sun_samples : int, points of the solar disk per shadow ray and BRDF evaluation.
    """

    scene: Scene
    pixel_size_m: float
    sun_samples: int = 1
    _state: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self):
        if not isinstance(self.scene, Scene):
            raise TypeError(f"scene must be a raycast.scene.Scene, not {type(self.scene).__name__}")
        if not (math.isfinite(self.pixel_size_m) and self.pixel_size_m > 0.0):
            raise ValueError(f"pixel_size_m={self.pixel_size_m!r} must be a positive number of metres")
        if not (isinstance(self.sun_samples, (int, np.integer)) and self.sun_samples >= 1):
            raise ValueError(f"sun_samples={self.sun_samples!r} must be a positive integer")

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_accuracy(cls, scene, sun_body, obs_body, accuracy_mag=0.005, n_pilot=8,
                      max_pixels_per_frame=4_000_000, sun_samples=None) -> "DirectRenderer":
        """A renderer whose pixel size meets ``accuracy_mag`` on these directions.

        The frames are rendered once on a coarse grid; a pilot set (the brightest half and an
        even spread of the rest, ``n_pilot`` in all) is then rendered at pixel sizes halving
        from the coarse one until two successive results differ by less than
        ``accuracy_mag`` (max over the pilot frames); the finer one is kept. The error of a
        regular grid falls at least linearly with pixel size, so the kept grid's error is at
        most that last difference. ``sun_samples=None`` chooses 1 when the narrowest specular
        lobe is so wide that averaging over the solar disk changes its peak by less than a
        tenth of the accuracy (relative change ~ r_sun**2 / (4 alpha**2)), else 19.

        Raises
        ------
        ValueError
            When the accuracy needs more than ``max_pixels_per_frame`` rays per frame.
        """
        sun_body, obs_body = _check_directions(sun_body, obs_body)
        if not (math.isfinite(accuracy_mag) and accuracy_mag > 0.0):
            raise ValueError(f"accuracy_mag={accuracy_mag!r} must be a positive number of magnitudes")
        if sun_samples is None:
            sun_samples = sun_samples_for(scene, accuracy_mag)
        mesh = scene.posed()
        footprint = 2.0 * mesh.radius_m
        pixel = footprint / 48.0
        coarse = cls(scene, pixel, sun_samples).intensity(sun_body, obs_body)
        lit = np.flatnonzero(coarse > 0.0)
        if len(lit) == 0:
            return cls(scene, pixel, sun_samples)
        brightest = lit[np.argsort(coarse[lit])[::-1][: n_pilot // 2]]
        spread = lit[np.linspace(0, len(lit) - 1, n_pilot - len(brightest)).astype(int)]
        pilot = np.unique(np.concatenate([brightest, spread]))
        previous = cls(scene, pixel, sun_samples).intensity(sun_body[pilot], obs_body[pilot])
        while True:
            pixel /= 2.0
            if (footprint / pixel) ** 2 > max_pixels_per_frame:
                raise ValueError(
                    f"accuracy_mag={accuracy_mag} needs rays finer than {2 * pixel:.3g} m "
                    f"(more than max_pixels_per_frame={max_pixels_per_frame}) for {scene.name}: a glint or "
                    "shadow edge is narrower than the sampling; relax accuracy_mag or raise max_pixels_per_frame")
            current = cls(scene, pixel, sun_samples).intensity(sun_body[pilot], obs_body[pilot])
            both = (current > 0.0) & (previous > 0.0)
            if np.array_equal(current > 0.0, previous > 0.0):
                change = np.abs(2.5 * np.log10(current[both] / previous[both])).max() if both.any() else 0.0
                if change < accuracy_mag:
                    return cls(scene, pixel, sun_samples)
            previous = current

    # ---------------------------------------------------------------- rendering
    def intensity(self, sun_body, obs_body, **parameters):
        """I/E in m^2/sr for each direction pair.

        Parameters
        ----------
        sun_body : (m, 3) float, unit vectors toward the Sun, body frame.
        obs_body : (m, 3) float, unit vectors toward the observer, body frame.
        **parameters : articulation parameters (degrees), e.g. ``panel_pitch_deg=12``.

        Returns
        -------
        (m,) float
        """
        sun_body, obs_body = _check_directions(sun_body, obs_body)
        if parameters:
            renderer = replace(self, scene=self.scene.with_parameters(**parameters))
            return renderer.intensity(sun_body, obs_body)
        mesh, scene = self._prepared()
        result = np.zeros(len(sun_body))
        if len(sun_body) == 0:
            return result
        center, radius = mesh.center_m, mesh.radius_m
        u, v = orthonormal_basis(obs_body)
        rel = mesh.vertices_m - center
        pu, pv = rel @ u.T, rel @ v.T
        h = self.pixel_size_m
        frame = np.arange(len(sun_body))
        offset_u = (0.5 + frame / _PLASTIC) % 1.0
        offset_v = (0.5 + frame / _PLASTIC ** 2) % 1.0
        start_u = pu.min(axis=0) - offset_u * h
        start_v = pv.min(axis=0) - offset_v * h
        n_u = np.floor((pu.max(axis=0) - start_u) / h).astype(np.int64) + 1
        n_v = np.floor((pv.max(axis=0) - start_v) / h).astype(np.int64) + 1
        counts = n_u * n_v
        sun_dirs = sun_disk_directions(sun_body, self.sun_samples)
        for batch in _batches(counts, _MAX_RAYS_PER_BATCH):
            frames = np.repeat(batch, counts[batch])
            first = np.repeat(np.cumsum(counts[batch]) - counts[batch], counts[batch])
            local = np.arange(len(frames)) - first
            iu, iv = local % n_u[frames], local // n_u[frames]
            cu = start_u[frames] + (iu + 0.5) * h
            cv = start_v[frames] + (iv + 0.5) * h
            origins = center + cu[:, None] * u[frames] + cv[:, None] * v[frames] + (radius + 1.0) * obs_body[frames]
            rays = np.concatenate([origins, -obs_body[frames]], axis=1).astype(np.float32)
            hits = scene.cast_rays(rays)
            t_hit = hits["t_hit"].numpy()
            hit = np.isfinite(t_hit)
            if not hit.any():
                continue
            frames = frames[hit]
            prim = hits["primitive_ids"].numpy()[hit].astype(np.int64)
            uv = hits["primitive_uvs"].numpy()[hit].astype(float)
            points = origins[hit] - t_hit[hit, None].astype(float) * obs_body[frames]
            contribution = self._shade(mesh, scene, frames, prim, uv, points, sun_dirs, obs_body)
            result += np.bincount(frames, weights=contribution, minlength=len(result))
        return result * h * h

    def _shade(self, mesh, scene, frames, prim, uv, points, sun_dirs, obs_body):
        """Per-hit f cos V, averaged over the Sun samples, shape (hits,)."""
        wo = obs_body[frames]
        n_geo = mesh.face_normals[prim]
        facing = np.sign(np.einsum("ij,ij->i", n_geo, wo))
        facing[facing == 0.0] = 1.0
        n_geo = n_geo * facing[:, None]
        bary = np.column_stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]])
        n_shade = np.einsum("ic,icj->ij", bary, mesh.corner_normals[prim])
        n_shade /= np.linalg.norm(n_shade, axis=1, keepdims=True)
        n_shade *= np.where(np.einsum("ij,ij->i", n_shade, n_geo) < 0.0, -1.0, 1.0)[:, None]
        offset = 1e-4 * max(mesh.radius_m, 1.0)
        materials = mesh.material_index[prim]
        total = np.zeros(len(frames))
        for sun_dir in sun_dirs:
            wi = sun_dir[frames]
            cos_geo = np.einsum("ij,ij->i", n_geo, wi)
            cos_shade = np.einsum("ij,ij->i", n_shade, wi)
            lit = np.flatnonzero((cos_geo > 0.0) & (cos_shade > 0.0))
            if len(lit) == 0:
                continue
            shadow_rays = np.concatenate([points[lit] + offset * n_geo[lit], wi[lit]], axis=1).astype(np.float32)
            visible = ~scene.test_occlusions(shadow_rays).numpy()
            lit = lit[visible]
            value = np.zeros(len(lit))
            for material in np.unique(materials[lit]):
                sel = materials[lit] == material
                idx = lit[sel]
                value[sel] = mesh.brdfs[material](wi[idx], wo[idx], n_shade[idx]) * cos_shade[idx]
            total[lit] += value
        return total / len(sun_dirs)

    def _prepared(self):
        if "mesh" not in self._state:
            mesh = self.scene.posed()
            self._state["mesh"] = mesh
            self._state["raycaster"] = _open3d_scene(mesh)
        return self._state["mesh"], self._state["raycaster"]


def sun_samples_for(scene, accuracy_mag):
    """Solar-disk samples needed for ``accuracy_mag`` given the scene's narrowest lobe."""
    widths = [b.lobe_width_rad for b in scene.brdfs if b is not None and b.lobe_width_rad]
    if not widths:
        return 1
    relative_effect = SUN_RADIUS_RAD ** 2 / (4.0 * min(widths) ** 2)
    return 1 if relative_effect < 0.1 * accuracy_mag / 1.0857 else 19


def _batches(counts, max_rays):
    """Split frame indices into consecutive batches of at most ``max_rays`` rays (>= 1 frame)."""
    batches, current, total = [], [], 0
    for index, count in enumerate(counts):
        if current and total + count > max_rays:
            batches.append(np.asarray(current))
            current, total = [], 0
        current.append(index)
        total += count
    if current:
        batches.append(np.asarray(current))
    return batches


def _check_directions(sun_body, obs_body):
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
