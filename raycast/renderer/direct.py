"""The reference renderer: orthographic ray casting with shadow rays (Open3D RaycastingScene).

For each direction pair (Sun ``s``, observer ``o``, body frame) a regular grid of parallel rays
with spacing ``pixel_size_m`` covers the mesh's footprint seen from ``o``. Every hit adds

    f_r(s, o, n_s) * max(n_s . s, 0) * [n_g . s > 0] * V(x, s) * pixel_size_m**2

(f_r as :meth:`raycast.renderer.brdf.BRDF.shade` applies it: diffuse terms do not test ``o`` against
the shading normal; the hit itself proves the observer sees the face)

where ``n_g`` is the geometric normal of the hit triangle turned toward the observer (surfaces
are two-sided), ``n_s`` the shading normal interpolated from the corner normals at the hit's
barycentric coordinates (turned to ``n_g``'s side) and ``V`` the Sun visibility from a shadow
ray toward the centre of the Sun. The sum is I/E in m^2/sr. For materials with narrow specular
lobes the BRDF is averaged over points of the 0.533 deg solar disk (a symmetric quadrature rule;
how many points is chosen per material by :func:`sun_samples_for`), which gives glints their true angular width.
The shadow ray is not spread over the disk: the penumbra it would blur is 0.0093 rad times the
distance to the occluder, under 1 cm on a body of 10 m, far below any pixel size used here.

With ``sampling="raster"`` the same grid's first hits are found by scan conversion with a
depth test instead of rays (the same hits; see :meth:`DirectRenderer._raster`), and the hits of
a flat-shaded triangle of at least a few pixels' projected area count as the lit-and-seen
fraction of its exact projected area: the fraction of the pixel centres it covers that it wins
and that are sunlit. A face seen nearly edge-on, a strip narrower than a pixel, then adds its
true area, where the plain sum adds a whole pixel per centre that happens to fall on it (TOPEX
along the real pass: 0.0058 -> 0.0022 mag RMS at 2 cm, docs/renderer.md). A smaller flat
triangle (``_direct_kernels.EXACT_SHARE_MIN_PIXELS``) that is a sliver, large but seen nearly
edge-on, which can fall between the centres, is sampled on its own surface: its exact projected
area times the fraction of its points that rays find seen and lit
(:meth:`DirectRenderer._sliver_sums`; TOPEX at 4.5 cm: 0.0083 -> 0.0042).

The pixel grid of each direction pair is shifted by a low-discrepancy (R2) sub-pixel offset, so
edge errors of successive frames do not repeat; the result is deterministic.

:meth:`DirectRenderer.from_accuracy` chooses the pixel size for a requested accuracy in
magnitudes by refining a pilot subset of the frames until two successive resolutions agree.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import partial
import math

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from raycast.renderer import _direct_kernels
from raycast.renderer.rays import (
    SUN_RADIUS_SINE,
    check_directions,
    open3d_scene,
    orthonormal_basis,
    sun_samples_for,
)
from raycast.renderer.refine import AdaptiveSampler, EdgeTopology, coarse_levels, surface_classes
from raycast.renderer.scene import Scene
from raycast.renderer.shading import shaded_pairs

__all__ = ["DirectRenderer", "AccuracyOutOfReach", "SAMPLINGS", "convex_groups"]

SAMPLINGS = ("adaptive", "grid", "raster")

_PLASTIC = 1.32471795724474602596
_MAX_RAYS_PER_BATCH = 1_500_000
# A flat triangle in the raster under EXACT_SHARE_MIN_PIXELS of projected area but not of its own,
# with at most this fraction of it projected (seen within 14.5 deg of edge-on), is a sliver
# (sliver_areas), sampled at the centroids of SLIVER_SUBDIVISION squared equal parts of it
# (DirectRenderer._sliver_sums; 2 cost TOPEX 0.0051 instead of 0.0043 mag at 6 cm pixels).
# Sampling costs 18 rays a sliver where a pixel count costs its few pixels: `python
# bench/raster_slivers.py` measures both on TOPEX and on a finely cut flat-shaded sphere.
SLIVER_COSINE = 0.25
SLIVER_SUBDIVISION = 3
_TILE = 8


class AccuracyOutOfReach(ValueError):
    """The requested accuracy needs more rays per frame than allowed (a glint or shadow edge
    narrower than the finest sampling)."""


def sliver_areas(own_pixels, smooth):
    """(t,) float, the projected area in pixels at or under which each triangle is a sliver in
    the raster: ``SLIVER_COSINE`` of its own area ``own_pixels`` for a flat triangle of at least
    ``EXACT_SHARE_MIN_PIXELS`` of it, 0 (never) for the others (``smooth`` (t,) bool: smooth-shaded
    hits are shaded one by one, with no share). The raster takes a triangle under
    ``EXACT_SHARE_MIN_PIXELS`` of projected area for a sliver when it is also under this."""
    large = ~smooth & (own_pixels >= _direct_kernels.EXACT_SHARE_MIN_PIXELS)
    return np.where(large, SLIVER_COSINE * own_pixels, 0.0)


@dataclass(frozen=True, eq=False)
class DirectRenderer:
    """Reference ray-cast renderer of one scene.

    Parameters
    ----------
    scene : Scene
    pixel_size_m : float, spacing of the orthographic ray grid.
    sun_samples : int, optional, points of the solar disk per BRDF evaluation for every
        material; default per material from ``accuracy_mag`` (:func:`sun_samples_for`).
    accuracy_mag : float, the accuracy the solar-disk sampling is chosen for.
    sampling : {"adaptive", "grid", "raster"}
        ``"adaptive"`` (default): rays at the corners of coarse cells, split down to
        ``pixel_size_m`` only where an edge, a shadow or a shading change may lie inside
        (:mod:`raycast.renderer.refine`); ``"grid"``: every pixel of the regular grid, the plain reference
        the adaptive sampler is tested against; ``"raster"``: the same grid with its first hits
        found by scan conversion with a depth test (:func:`raycast.renderer._direct_kernels.raster_hits`)
        instead of rays, hit for hit the grid's, the hits of flat triangles of a few pixels or
        more counted as fractions of their exact projected areas, with shadow rays only where
        another part can shade: the fastest for meshes of up to a few thousand triangles.
    """

    scene: Scene
    pixel_size_m: float
    sun_samples: int | None = None
    accuracy_mag: float = 0.005
    sampling: str = "adaptive"
    _state: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self):
        if not isinstance(self.scene, Scene):
            raise TypeError(f"scene must be a raycast.renderer.scene.Scene, not {type(self.scene).__name__}")
        if not (math.isfinite(self.pixel_size_m) and self.pixel_size_m > 0.0):
            raise ValueError(f"pixel_size_m={self.pixel_size_m!r} must be a positive number of metres")
        if self.sun_samples is not None and not (
            isinstance(self.sun_samples, (int, np.integer)) and self.sun_samples >= 1
        ):
            raise ValueError(f"sun_samples={self.sun_samples!r} must be a positive integer")
        if self.sampling not in SAMPLINGS:
            raise ValueError(f"sampling={self.sampling!r} is unknown; use one of {', '.join(map(repr, SAMPLINGS))}")

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_accuracy(
        cls,
        scene,
        sun_body,
        obs_body,
        accuracy_mag=0.005,
        n_pilot=8,
        max_pixels_per_frame=4_000_000,
        sun_samples=None,
        sampling="adaptive",
    ) -> DirectRenderer:
        """A renderer whose pixel size meets ``accuracy_mag`` on these directions.

        The frames are rendered once on a coarse grid; a pilot set (the brightest half and an
        even spread of the rest, ``n_pilot`` in all) is then rendered at pixel sizes halving
        from the coarse one until two successive results differ by less than
        ``accuracy_mag`` (max over the pilot frames); the finer one is kept. The error of a
        regular grid falls at least linearly with pixel size, so the kept grid's error is at
        most that last difference.

        Raises
        ------
        AccuracyOutOfReach
            When the accuracy needs more than ``max_pixels_per_frame`` rays per frame.
        """
        sun_body, obs_body = check_directions(sun_body, obs_body)
        if not (math.isfinite(accuracy_mag) and accuracy_mag > 0.0):
            raise ValueError(f"accuracy_mag={accuracy_mag!r} must be a positive number of magnitudes")
        mesh = scene.posed()
        footprint = 2.0 * mesh.radius_m
        pixel = footprint / 48.0
        coarse = cls(scene, pixel, sun_samples, accuracy_mag, sampling).intensity(sun_body, obs_body)
        lit = np.flatnonzero(coarse > 0.0)
        if len(lit) == 0:
            return cls(scene, pixel, sun_samples, accuracy_mag, sampling)
        brightest = lit[np.argsort(coarse[lit])[::-1][: n_pilot // 2]]
        spread = lit[np.linspace(0, len(lit) - 1, n_pilot - len(brightest)).astype(int)]
        pilot = np.unique(np.concatenate([brightest, spread]))
        previous = cls(scene, pixel, sun_samples, accuracy_mag, sampling).intensity(sun_body[pilot], obs_body[pilot])
        change = math.inf
        while True:
            pixel /= 2.0
            if (footprint / pixel) ** 2 > max_pixels_per_frame:
                reached = f"{change:.3g} mag" if math.isfinite(change) else "a change in which frames are lit"
                relax = (
                    f"relax accuracy_mag to at least {max(change, accuracy_mag):.2g}"
                    if math.isfinite(change)
                    else "relax accuracy_mag"
                )
                raise AccuracyOutOfReach(
                    f"accuracy_mag={accuracy_mag} is out of reach for {scene.name} within max_pixels_per_frame="
                    f"{max_pixels_per_frame}: at {2 * pixel:.3g} m pixels two successive pixel sizes still differ by "
                    f"{reached} (a glint or shadow edge narrower than the sampling); {relax}, raise "
                    f"max_pixels_per_frame to at least "
                    f"{math.ceil((footprint / pixel) ** 2)} for one more halving, or give pixel_size_m directly"
                )
            current = cls(scene, pixel, sun_samples, accuracy_mag, sampling).intensity(sun_body[pilot], obs_body[pilot])
            both = (current > 0.0) & (previous > 0.0)
            change = math.inf
            if np.array_equal(current > 0.0, previous > 0.0):
                change = np.abs(2.5 * np.log10(current[both] / previous[both])).max() if both.any() else 0.0
                if change < accuracy_mag:
                    return cls(scene, pixel, sun_samples, accuracy_mag, sampling)
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
        sun_body, obs_body = check_directions(sun_body, obs_body)
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
        pu, pv = _products(rel, u), _products(rel, v)
        h = self.pixel_size_m
        frame = np.arange(len(sun_body))
        offset_u = (0.5 + (frame + 1) / _PLASTIC) % 1.0
        offset_v = (0.5 + (frame + 1) / _PLASTIC**2) % 1.0
        start_u = pu.min(axis=0) - offset_u * h
        start_v = pv.min(axis=0) - offset_v * h
        if self.sampling == "adaptive":
            return self._sampler().intensity(sun_body, obs_body, u, v, start_u, start_v)
        n_u = np.floor((pu.max(axis=0) - start_u) / h).astype(np.int64) + 1
        n_v = np.floor((pv.max(axis=0) - start_v) / h).astype(np.int64) + 1
        cos_o, cos_s = _products(mesh.face_normals, obs_body), _products(mesh.face_normals, sun_body)
        # A seen side faces the Sun while any of the solar disk is above its plane.
        sunward = np.where(cos_o < 0.0, -cos_s, cos_s) > -SUN_RADIUS_SINE
        if self.sampling == "raster":
            return self._raster(mesh, scene, sun_body, obs_body, pu, pv, start_u, start_v, n_u, n_v, cos_o, sunward)
        # Empty-space skipping: the grid is cut into tiles of TILE x TILE pixels and only tiles
        # touched by the projected bounding box of some triangle whose seen side faces the Sun
        # are cast. A ray elsewhere misses or ends on a side turned away from the Sun, which adds
        # nothing: the sum is that of the full grid. (On COSMOS 2502 only a sixth of the hits
        # are on sunward sides.)
        tiles_u = (n_u + _TILE - 1) // _TILE
        tiles_v = (n_v + _TILE - 1) // _TILE
        tile_frame, tile_iu, tile_iv = _covered_tiles(
            mesh, pu, pv, start_u, start_v, h * _TILE, tiles_u, tiles_v, sunward
        )
        base = center + (start_u + 0.5 * h)[:, None] * u + (start_v + 0.5 * h)[:, None] * v + (radius + 1.0) * obs_body
        step_u, step_v = h * u, h * v
        # Ray origin of each tile's first pixel (raycast.renderer._direct_kernels.tile_rays steps across the tile).
        tile_origin = (
            base[tile_frame]
            + (_TILE * tile_iu)[:, None] * step_u[tile_frame]
            + (_TILE * tile_iv)[:, None] * step_v[tile_frame]
        ).astype(np.float32)
        step_u32, step_v32 = step_u.astype(np.float32), step_v.astype(np.float32)
        backward = (-obs_body).astype(np.float32)
        tiles_per_batch = max(1, _MAX_RAYS_PER_BATCH // _TILE**2)
        for begin in range(0, len(tile_frame), tiles_per_batch):
            sl = slice(begin, begin + tiles_per_batch)
            owner = tile_frame[sl]
            rays = _direct_kernels.tile_rays(tile_origin[sl], owner, step_u32, step_v32, backward, _TILE)
            hits = scene.cast_rays(rays)
            frames, prim, uv, points = _direct_kernels.ray_hits(
                rays,
                hits["t_hit"].numpy(),
                hits["primitive_ids"].numpy(),
                hits["primitive_uvs"].numpy(),
                owner,
                _TILE**2,
            )
            if len(frames) == 0:
                continue
            contribution, _ = self._shade(mesh, scene, frames, prim, uv, points, sun_body, obs_body)
            result += np.bincount(frames, weights=contribution, minlength=len(result))
        return result * h * h

    def _raster(self, mesh, scene, sun_body, obs_body, pu, pv, start_u, start_v, n_u, n_v, cos_o, sunward):
        """The regular grid's sum with first hits found by scan conversion
        (:func:`raycast.renderer._direct_kernels.raster_hits`) instead of rays, flat-shaded hits
        weighted by their triangle's exact projected area over the pixel centres it covers
        (:func:`raycast.renderer._direct_kernels.flat_sums`), and shadow rays only for hits
        something of another convex group can shade
        (:func:`raycast.renderer._direct_kernels.need_shadow_rays`)."""
        h = self.pixel_size_m
        inner, smooth = self._state["inner"], self._state["smooth"]
        drawn = ~np.where(cos_o >= 0.0, inner[:, :1], inner[:, 1:])
        depth = _products(mesh.vertices_m - mesh.center_m, obs_body)
        result = np.zeros(len(sun_body))
        # Hits on flat-shaded triangles take their radiance from a table per (frame, triangle).
        flat_table = self._flat_radiance(sun_body, obs_body, np.flatnonzero(~smooth))
        offset = 1e-4 * max(mesh.radius_m, 1.0)
        corners = mesh.corners_m
        sliver_below = sliver_areas(mesh.areas_m2 / (h * h), smooth)
        # Sorting out the hits that need no shadow ray pays where closed convex parts hold most
        # of the surface (TOPEX: 70% of the rays saved); on open meshes nearly every hit needs one.
        if "groups" not in self._state:
            groups = convex_groups(mesh, inner)
            convex_share = mesh.areas_m2[groups <= mesh.part_index.max()].sum() / max(mesh.areas_m2.sum(), 1e-300)
            self._state["groups"] = groups if convex_share >= 0.5 else None
        groups = self._state["groups"]
        sun_u, sun_v = orthonormal_basis(sun_body)
        cell = max(4.0 * h, mesh.radius_m / 64.0)
        # Frames in batches of at most _MAX_RAYS_PER_BATCH pixels (the hit buffers' size).
        pixels = np.cumsum(n_u * n_v)
        begin = 0
        while begin < len(sun_body):
            end = max(
                begin + 1,
                int(
                    np.searchsorted(pixels, pixels[begin] - n_u[begin] * n_v[begin] + _MAX_RAYS_PER_BATCH, side="right")
                ),
            )
            frames, prim, uv, shadow_rays, share, *slivers = _direct_kernels.raster_hits(
                corners,
                pu,
                pv,
                depth,
                start_u,
                start_v,
                h,
                n_u,
                n_v,
                np.arange(begin, end),
                drawn,
                sunward,
                mesh.face_normals,
                obs_body,
                sun_body,
                offset,
                sliver_below,
            )
            begin = end
            self._sliver_sums(mesh, scene, *slivers, sun_body, obs_body, offset, flat_table, result)
            if len(frames) == 0:
                continue
            if groups is None:  # every hit casts its ray
                blocked = scene.test_occlusions(shadow_rays).numpy()
            else:
                # Shadow rays only where something of another group rises above the hit.
                need = _direct_kernels.need_shadow_rays(
                    corners, groups, sun_body, sun_u, sun_v, cell, frames, prim, shadow_rays
                )
                blocked = np.zeros(len(frames), dtype=bool)
                if need.any():
                    blocked[need] = scene.test_occlusions(shadow_rays[need]).numpy()
            rest = _direct_kernels.flat_sums(frames, prim, blocked, smooth, flat_table, result, share)
            if len(rest):
                frames, prim, normals, geo_normals = _direct_kernels.smooth_hits(
                    rest, frames, prim, uv, mesh.face_normals, cos_o, mesh.corner_normals
                )
                self._radiance(
                    mesh.material_index[prim],
                    normals,
                    frames,
                    sun_body,
                    obs_body,
                    geo_normals,
                    into=frames,
                    total=result,
                )
        return result * h * h

    def _sliver_sums(self, mesh, scene, frames, prim, pixels, sun_body, obs_body, offset, flat_table, out):
        """Add the flat-shaded slivers of :func:`raycast.renderer._direct_kernels.raster_hits`
        (under ``EXACT_SHARE_MIN_PIXELS`` of projected area, not of their own) to ``out[frame]``,
        in pixels: each one's table radiance times its exact projected area ``pixels`` times the
        fraction of the points of its surface (:data:`SLIVER_SUBDIVISION` squared) that are both
        seen and lit (:func:`raycast.renderer._direct_kernels.sliver_rays`). A strip that thin
        can fall between the pixel centres, so its hits say little of it; its own surface says
        how much of it is seen and lit. ``offset``: how far above its surface the rays start."""
        if len(frames) == 0:
            return
        n = SLIVER_SUBDIVISION
        rays = _direct_kernels.sliver_rays(
            mesh.corners_m, mesh.face_normals, obs_body, sun_body, frames, prim, offset, n
        )
        open_ = ~scene.test_occlusions(rays).numpy().reshape(len(frames), n * n, 2).any(axis=2)
        out += np.bincount(frames, weights=flat_table[frames, prim] * pixels * open_.mean(axis=1), minlength=len(out))

    def _sampler(self):
        mesh, scene = self._prepared()
        smooth = self._state["smooth"]
        if "classes" not in self._state:
            self._state["classes"] = surface_classes(mesh, smooth)
            self._state["edges"] = EdgeTopology(mesh, self._state["classes"])
        return AdaptiveSampler(
            mesh,
            scene,
            partial(self._shade, mesh, scene),
            self._flat_radiance,
            self._state["classes"],
            smooth,
            self._state["edges"],
            self.pixel_size_m,
            coarse_levels(mesh, self.pixel_size_m),
            smooth_tolerance=self.accuracy_mag / 1.0857 / 3.0,
        )

    def _shade(self, mesh, scene, frames, prim, uv, points, sun_body, obs_body, flat_table=None):
        """Per-hit f cos V, averaged over the Sun samples, and whether the Sun reaches the hit;
        two arrays of shape (hits,). ``flat_table`` (:meth:`_flat_radiance` of these frames)
        gives flat-shaded hits their radiance by look-up."""
        total = np.zeros(len(frames))
        reached = np.zeros(len(frames), dtype=bool)
        normals, lit, rays = _direct_kernels.sunward_hits(
            frames, prim, points, mesh.face_normals, sun_body, obs_body, 1e-4 * max(mesh.radius_m, 1.0)
        )
        if len(lit) == 0:
            return total, reached
        lit = lit[~scene.test_occlusions(rays).numpy()]
        reached[lit] = True
        smooth = self._state["smooth"][prim[lit]]
        if flat_table is not None:
            flat = lit[~smooth]
            total[flat] = flat_table[frames[flat], prim[flat]]
            lit, smooth = lit[smooth], smooth[smooth]
        # Only smooth-shaded triangles need the barycentric interpolation of corner normals.
        geo_normals = normals[lit]
        _direct_kernels.interpolated_normals(normals, lit[smooth], prim, uv, mesh.corner_normals)
        total[lit] = self._radiance(
            mesh.material_index[prim[lit]], normals[lit], frames[lit], sun_body, obs_body, geo_normals
        )
        return total, reached

    def _radiance(
        self, materials, normals, frames, sun_body, obs_body, geo_normals, smooth=True, into=None, total=None
    ):
        """Per hit f(s, o, n) cos(i) over the solar disk (:func:`raycast.renderer.shading.shaded_pairs`)
        times the share of the disk above the face (:func:`raycast.renderer.rays.sun_fraction`),
        (k,) for (k,) materials, (k, 3) shading normals, (k, 3) face normals turned toward the
        observer and (k,) frames of the (m, 3) Sun and observer directions. On ``smooth`` hits
        specular lobes are evaluated about the valid-reflection normal when the scene says so
        (``Scene.specular_normals``). With ``into`` (k,) and ``total``, each hit is added into
        ``total[into]`` instead (a frame's sum without a (k,) array per frame vector)."""
        mesh = self._state["mesh"]
        bend = smooth and self.scene.specular_normals == "cycles"
        sun_u, sun_v = orthonormal_basis(sun_body)
        if into is None:
            into, total = np.arange(len(materials)), np.zeros(len(materials))
        per_hit = [np.ascontiguousarray(a, dtype=float) for a in (np.ones(len(materials)), normals, geo_normals)]
        for material in np.unique(materials):
            shaded_pairs(
                mesh.brdfs[material],
                self._state["sun_samples"][material],
                np.flatnonzero(materials == material),
                frames,
                into,
                *per_hit,
                obs_body,
                sun_body,
                sun_u,
                sun_v,
                bend,
                total,
                disk_share=True,
            )
        return total

    def _flat_radiance(self, sun_body, obs_body, triangles=None):
        """(m, t) radiance of every triangle, flat-shaded with its face normal turned toward
        the observer, lit as much as its face is: what a flat triangle's hits share within a frame.
        With ``triangles`` (indices) only their columns are filled; the rest are zero."""
        mesh = self._state["mesh"]
        m, t = len(sun_body), len(mesh.face_normals)
        columns = np.arange(t) if triangles is None else np.asarray(triangles)
        normals = np.broadcast_to(mesh.face_normals[columns], (m, len(columns), 3))
        facing = np.where(np.einsum("mtj,mj->mt", normals, obs_body) < 0.0, -1.0, 1.0)
        normals = (normals * facing[..., None]).reshape(-1, 3)
        frames = np.repeat(np.arange(m), len(columns))
        values = self._radiance(
            np.tile(mesh.material_index[columns], m), normals, frames, sun_body, obs_body, normals, smooth=False
        )
        table = np.zeros((m, t))
        table[:, columns] = values.reshape(m, len(columns))
        return table

    def image(self, sun_body, obs_body):
        """What a camera looking along ``-obs_body`` sees: radiance per unit irradiance, 1/sr.

        Parameters
        ----------
        sun_body, obs_body : (3,) float, one direction pair.

        Returns
        -------
        (rows, columns) float image; its sum times ``pixel_size_m**2`` is :meth:`intensity`
        (up to the sub-pixel offset). Rows run along the grid's second axis.
        """
        sun, obs = check_directions(np.atleast_2d(sun_body), np.atleast_2d(obs_body))
        mesh, scene = self._prepared()
        u, v = orthonormal_basis(obs)
        rel = mesh.vertices_m - mesh.center_m
        pu, pv = rel @ u[0], rel @ v[0]
        h = self.pixel_size_m
        cu = np.arange(pu.min() - h, pu.max() + h, h)
        cv = np.arange(pv.min() - h, pv.max() + h, h)
        grid_u, grid_v = np.meshgrid(cu, cv)
        origins = (
            mesh.center_m + grid_u.reshape(-1, 1) * u[0] + grid_v.reshape(-1, 1) * v[0] + (mesh.radius_m + 1.0) * obs[0]
        )
        rays = np.concatenate([origins, np.broadcast_to(-obs[0], origins.shape)], axis=1).astype(np.float32)
        hits = scene.cast_rays(rays)
        t_hit = hits["t_hit"].numpy()
        hit = np.flatnonzero(np.isfinite(t_hit))
        radiance = np.zeros(len(rays))
        if len(hit):
            frames = np.zeros(len(hit), dtype=np.int64)
            points = rays[hit, :3] + t_hit[hit, None] * rays[hit, 3:]
            radiance[hit], _ = self._shade(
                mesh,
                scene,
                frames,
                hits["primitive_ids"].numpy()[hit].astype(np.int64),
                hits["primitive_uvs"].numpy()[hit],
                points,
                sun,
                obs,
            )
        return radiance.reshape(grid_u.shape)

    def _prepared(self):
        if "mesh" not in self._state:
            mesh = self.scene.posed()
            self._state["mesh"] = mesh
            self._state["raycaster"] = open3d_scene(mesh)
            spread = np.abs(mesh.corner_normals - mesh.face_normals[:, None, :]).max(axis=(1, 2))
            self._state["smooth"] = spread > 1e-9
            self._state["inner"] = mesh.inner_sides()
            self._state["sun_samples"] = tuple(
                sun_samples_for(b, self.accuracy_mag) if self.sun_samples is None else int(self.sun_samples)
                for b in mesh.brdfs
            )
        return self._state["mesh"], self._state["raycaster"]


def convex_groups(mesh, inner):
    """(t,) int: each triangle's group for :func:`raycast.renderer._direct_kernels.need_shadow_rays`,
    its part's index when the part is closed and convex, otherwise a group of its own.

    A closed part is convex when it encloses its convex hull's volume: its solid lies inside
    the hull, so equal volumes leave no room for a dent. The tolerance, 1e-4 of the volume,
    admits the rounding of vertices written to a file (3e-6 on a box of the paper's COSMOS 2502
    model) and no dent deep enough to shade anything. ``inner`` is
    :meth:`raycast.renderer.scene.PosedMesh.inner_sides`.
    """
    n_tri = len(mesh.part_index)
    group = np.arange(n_tri) + (int(mesh.part_index.max()) + 1 if n_tri else 0)
    for part in np.unique(mesh.part_index):
        tris = np.flatnonzero(mesh.part_index == part)
        if not inner[tris].any(axis=1).all():
            continue
        corners = mesh.corners_m[tris]
        volume = abs(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum()) / 6.0
        try:
            hull = ConvexHull(corners.reshape(-1, 3))
        except QhullError:  # flat or degenerate: no volume to be convex about
            continue
        if abs(hull.volume - volume) <= 1e-4 * hull.volume:
            group[tris] = part
    return group


def _covered_tiles(mesh, pu, pv, start_u, start_v, tile_m, tiles_u, tiles_v, selected):
    """Tiles of each frame's grid touched by the projected bounding box of a selected triangle.

    Parameters
    ----------
    pu, pv : (3 t, m) float, projected vertex coordinates per frame.
    start_u, start_v : (m,) float, grid origin per frame.
    tile_m : float, tile side.
    tiles_u, tiles_v : (m,) int, tiles per frame along each axis.
    selected : (t, m) bool, the triangles whose boxes count in each frame.

    Returns
    -------
    frame, iu, iv : (k,) int arrays, one entry per covered tile.
    """
    m = pu.shape[1]
    tri_u = pu.reshape(-1, 3, m)
    tri_v = pv.reshape(-1, 3, m)
    lo_u = np.floor((tri_u.min(axis=1) - start_u) / tile_m).astype(np.int64)
    hi_u = np.floor((tri_u.max(axis=1) - start_u) / tile_m).astype(np.int64)
    lo_v = np.floor((tri_v.min(axis=1) - start_v) / tile_m).astype(np.int64)
    hi_v = np.floor((tri_v.max(axis=1) - start_v) / tile_m).astype(np.int64)
    size_u, size_v = int(tiles_u.max()) + 1, int(tiles_v.max()) + 1
    lo_u, hi_u = np.clip(lo_u, 0, size_u - 1), np.clip(hi_u + 1, 0, size_u)
    lo_v, hi_v = np.clip(lo_v, 0, size_v - 1), np.clip(hi_v + 1, 0, size_v)
    # A 2-D difference array per frame: +1/-1 at the box corners, then cumulative sums.
    cover = np.zeros((m, size_u + 1, size_v + 1), dtype=np.int32)
    frame = np.broadcast_to(np.arange(m), lo_u.shape)[selected]
    for du, dv, sign in ((lo_u, lo_v, 1), (hi_u, lo_v, -1), (lo_u, hi_v, -1), (hi_u, hi_v, 1)):
        np.add.at(cover, (frame, du[selected], dv[selected]), sign)
    cover = cover.cumsum(axis=1).cumsum(axis=2)[:, :size_u, :size_v]
    inside = (np.arange(size_u)[None, :, None] < tiles_u[:, None, None]) & (
        np.arange(size_v)[None, None, :] < tiles_v[:, None, None]
    )
    return np.nonzero((cover > 0) & inside)


def _products(vectors, directions):
    """(n, m) dot products of (n, 3) ``vectors`` with (m, 3) ``directions``.

    Written out rather than as a matrix product: for these sizes a threaded BLAS would hand the
    product to worker threads that then spin, burning as much CPU time again as the whole
    light curve's own work (measured with OpenBLAS on 2 cores).
    """
    return np.einsum("ij,mj->im", vectors, directions)
