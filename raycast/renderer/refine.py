"""Adaptive refinement of the direct renderer's orthographic ray grid (a quadtree per frame).

With a directional Sun, an orthographic view and flat shading, the radiance is constant over
every lit (or shadowed) piece of a flat face: a regular grid spends almost all its rays inside
such pieces, where one sample would do, and gets its error only from the pixels an edge
crosses. This sampler casts rays at the corners of coarse cells and splits a cell in four,
down to ``pixel_size_m``, only where something may change inside it:

* its four corners do not show the same *surface class* (nothing hit; one flat face, i.e.
  coplanar triangles of one material and part; or one smooth-shaded surface), each with the
  same Sun visibility;
* on a smooth-shaded surface, the estimate from the cell's four corners and the one from its
  nine-point stencil (its children's corners) differ by more than ``smooth_tolerance`` (the
  shading normal turns across the cell): adaptive cubature with the trapezoidal rule;
* a *feature edge* passes through it (an edge between two surface classes, an open boundary,
  or a silhouette seen from the observer), or the *shadow* of an edge that is a silhouette
  seen from the Sun: a part or a shadow narrower than the cell need not touch any corner
  (a boom seen from the side, a panel seen nearly edge-on, the shadow of a mast).

Flat cells that pass are one flat piece whose radiance the corners give exactly; smooth ones
are summed with the nine-point rule; the cells at ``pixel_size_m`` sum their
corner mean, a point-sampled estimate like the regular grid's. The ray count grows with the
length of the edges in view, not with the footprint's area, so at equal edge resolution (and
equal error) it needs several times fewer rays than the regular grid.

Feature edges mark cells down to four finest cells across; below that the corner tests
alone decide (a part narrower than that covers at most a few finest pixels). The shadow of an
edge is marked where rays from points along it, cast away from the Sun, land.
"""

from __future__ import annotations

import math

import numpy as np

from raycast.renderer import _direct_kernels

__all__ = ["surface_classes", "coarse_levels", "EdgeTopology", "AdaptiveSampler"]

_FRAMES_PER_CHUNK = 16
# Finest cells across the footprint beyond which the sampler refuses (a float32 ray origin
# resolves about 1e-7 of the mesh size anyway).
_MAX_CELLS_ACROSS = 1 << 21
# Mark grids larger than this (cells per chunk) are kept as sorted keys instead.
_MAX_DENSE_MARKS = 1 << 25
# Feature edges mark cells of at least this many finest cells across.
_MARK_MIN_CELLS = 4


def surface_classes(mesh, smooth):
    """(t,) int: triangles with the same class show one radiance over a flat piece.

    Flat triangles are classed by material, part and plane (normal and offset rounded to 1e-6
    of the mesh size); smooth-shaded ones by material and part only (their radiance varies and
    is checked by value).
    """
    scale = max(mesh.radius_m, 1.0)
    normals = np.round(mesh.face_normals / 1e-6)
    offsets = np.round(np.einsum("ij,ij->i", mesh.corners_m[:, 0], mesh.face_normals) / (1e-6 * scale))
    flat_key = np.column_stack([np.zeros(len(normals)), mesh.material_index, mesh.part_index, normals, offsets])
    smooth_key = np.column_stack(
        [np.ones(len(normals)), mesh.material_index, mesh.part_index, np.zeros((len(normals), 4))]
    )
    key = np.where(smooth[:, None], smooth_key, flat_key).astype(np.int64)
    _, classes = np.unique(key, axis=0, return_inverse=True)
    return classes.reshape(-1)


def coarse_levels(mesh, pixel_size_m, cells_across=24):
    """How many times the coarse cells (about ``cells_across`` over the mesh's diameter) are
    halved to reach ``pixel_size_m``."""
    coarse_m = 2.0 * mesh.radius_m / cells_across
    if coarse_m <= pixel_size_m:
        return 0
    return int(math.ceil(math.log2(coarse_m / pixel_size_m)))


class EdgeTopology:
    """The mesh's edges and the triangles on either side, for finding feature edges.

    Attributes
    ----------
    ends : (e, 2, 3) float, edge end points.
    face_a, face_b : (e,) int, the triangles sharing the edge (``face_b`` -1 on an open boundary).
    crease : (e,) bool, the two sides are different surface classes, or the edge is not
        shared by exactly two triangles.
    closed_a, closed_b : (e,) bool, the triangle belongs to a closed part (its back is never seen).
    """

    def __init__(self, mesh, classes):
        corners = mesh.corners_m
        extent = max(mesh.radius_m, 1.0)
        _, vertex_id = np.unique(np.round(corners.reshape(-1, 3) / (1e-7 * extent)), axis=0, return_inverse=True)
        vertex_id = vertex_id.reshape(-1, 3)
        pairs = np.concatenate([vertex_id[:, [0, 1]], vertex_id[:, [1, 2]], vertex_id[:, [2, 0]]])
        ends = np.concatenate([corners[:, [0, 1]], corners[:, [1, 2]], corners[:, [2, 0]]])
        faces = np.tile(np.arange(len(corners)), 3)
        pairs.sort(axis=1)
        _, edge, counts = np.unique(pairs, axis=0, return_inverse=True, return_counts=True)
        edge = edge.reshape(-1)
        order = np.argsort(edge, kind="stable")
        first = np.r_[0, np.cumsum(counts)[:-1]]
        self.ends = ends[order[first]]
        self.face_a = faces[order[first]]
        self.face_b = np.where(counts >= 2, faces[order[np.minimum(first + 1, len(order) - 1)]], -1)
        self.crease = (counts != 2) | (classes[self.face_a] != classes[np.maximum(self.face_b, 0)])
        closed = mesh.inner_sides().any(axis=1)
        self.closed_a = closed[self.face_a]
        self.closed_b = np.where(self.face_b >= 0, closed[np.maximum(self.face_b, 0)], False)
        self.normal_a = mesh.face_normals[self.face_a]
        self.normal_b = mesh.face_normals[np.maximum(self.face_b, 0)]
        self.open = self.face_b < 0

    def seen_features(self, obs_body):
        """(m, e) bool: edges that can outline something seen from each observer direction."""
        front_a = obs_body @ self.normal_a.T > 0.0
        front_b = obs_body @ self.normal_b.T > 0.0
        # A face of a closed part is seen from its front only; an open surface from both sides.
        seen_a = front_a | ~self.closed_a
        seen_b = (front_b | ~self.closed_b) & ~self.open
        silhouette = front_a != front_b
        return self.open | (self.crease & (seen_a | seen_b)) | (silhouette & (seen_a | seen_b))

    def sun_silhouettes(self, sun_body):
        """(m, e) bool: edges whose shadow is an outline of a shadow for each Sun direction."""
        lit_a = sun_body @ self.normal_a.T > 0.0
        lit_b = sun_body @ self.normal_b.T > 0.0
        return self.open | (lit_a != lit_b) | (self.crease & ~(self.closed_a & self.closed_b))


class AdaptiveSampler:
    """The quadtree over the frames of one :meth:`raycast.renderer.direct.DirectRenderer.intensity` call.

    Parameters
    ----------
    mesh : PosedMesh
    raycaster : open3d RaycastingScene of ``mesh``.
    shade : callable ``shade(frames, prim, uv, points, sun_body, obs_body, flat_table) -> (values, lit)``,
        the radiance of hits and whether the Sun reaches them.
    flat_radiance : callable ``flat_radiance(sun_body, obs_body) -> (m, t)``, the radiance of
        flat-shaded triangles per frame (``flat_table`` above).
    classes : (t,) int, from :func:`surface_classes`.
    smooth : (t,) bool, smooth-shaded triangles.
    edges : EdgeTopology
    pixel_size_m : float, the finest cell.
    levels : int, halvings from the coarse cell to ``pixel_size_m``.
    smooth_tolerance : float, a smooth-shaded cell is not split further when splitting it
        changed its estimate by at most this fraction.
    """

    def __init__(
        self, mesh, raycaster, shade, flat_radiance, classes, smooth, edges, pixel_size_m, levels, smooth_tolerance=1e-3
    ):
        self.mesh, self.raycaster, self.shade, self.flat_radiance = mesh, raycaster, shade, flat_radiance
        self.classes, self.edges = classes, edges
        self.h, self.levels, self.smooth_tolerance = pixel_size_m, levels, smooth_tolerance
        self._smooth_flags = np.zeros(classes.max() + 2, dtype=bool)
        self._smooth_flags[classes[smooth]] = True
        self.n_rays = 0

    def intensity(self, sun_body, obs_body, u, v, start_u, start_v):
        """I/E (m,) for the frames; frame f's lattice starts at (start_u[f], start_v[f]) in the
        plane spanned by (u[f], v[f]), perpendicular to ``obs_body[f]``."""
        across = 2.0 * self.mesh.radius_m / self.h
        if across > _MAX_CELLS_ACROSS:
            raise ValueError(
                f"pixel_size_m={self.h!r} makes more than {_MAX_CELLS_ACROSS} pixels across the "
                f"{2.0 * self.mesh.radius_m:.3g} m footprint; give a larger pixel size"
            )
        result = np.zeros(len(sun_body))
        for begin in range(0, len(sun_body), _FRAMES_PER_CHUNK):
            sl = slice(begin, begin + _FRAMES_PER_CHUNK)
            result[sl] = self._chunk(sun_body[sl], obs_body[sl], u[sl], v[sl], start_u[sl], start_v[sl])
        return result

    # ------------------------------------------------------------------ one chunk of frames
    def _chunk(self, sun, obs, u, v, start_u, start_v):
        mesh, h, levels = self.mesh, self.h, self.levels
        m = len(sun)
        step = 1 << levels
        self._frame = (sun, obs, u, v, start_u, start_v)
        self._flat_table = self.flat_radiance(sun, obs)
        # Ray origin of lattice point (0, 0) and the steps of one finest cell, per frame; the
        # origins lie outside the mesh's bounding sphere.
        base = mesh.center_m + start_u[:, None] * u + start_v[:, None] * v + (mesh.radius_m + 1.0) * obs
        self._rays = tuple(np.ascontiguousarray(a.T, dtype=np.float32) for a in (base, h * u, h * v, -obs))
        rel = mesh.vertices_m - mesh.center_m
        n_u = np.floor(((rel @ u.T).max(axis=0) - start_u) / (h * step)).astype(np.int64) + 1
        n_v = np.floor(((rel @ v.T).max(axis=0) - start_v) / (h * step)).astype(np.int64) + 1
        size_u, size_v = int(n_u.max()), int(n_v.max())
        marks = self._marks(sun, obs, u, v, start_u, start_v, size_u, size_v)
        # Level 0: every corner of every coarse cell in each frame's footprint box.
        frame, ci, cj = np.nonzero(
            (np.arange(size_u)[None, :, None] < n_u[:, None, None])
            & (np.arange(size_v)[None, None, :] < n_v[:, None, None])
        )
        lattice = np.zeros((m, size_u + 1, size_v + 1), dtype=bool)
        for di in (0, 1):
            for dj in (0, 1):
                lattice[frame, ci + di, cj + dj] = True
        lf, li, lj = np.nonzero(lattice)
        lattice_cls, lattice_val = self._evaluate(lf, li * step, lj * step)
        index = np.zeros(lattice.shape, dtype=np.int64)
        index[lf, li, lj] = np.arange(len(lf))
        corner = np.stack([index[frame, ci + di, cj + dj] for di, dj in ((0, 0), (1, 0), (0, 1), (1, 1))])
        # Corner classes and values are (4, cells): corners (0, 0), (1, 0), (0, 1), (1, 1).
        cls, val = lattice_cls[corner], lattice_val[corner]
        result = np.zeros(m)
        for level in range(levels + 1):
            size = step >> level
            area = (size * h) ** 2
            first = cls[0]
            same = (cls[1] == first) & (cls[2] == first) & (cls[3] == first)
            if level in marks:
                same &= ~marks[level].holds(frame, ci, cj)
            smooth = self._smooth_flags[first >> 1] & (first >= 0)
            done = same & ~smooth
            if level == levels:
                done[:] = True
            mean = 0.25 * (val[0] + val[1] + val[2] + val[3])
            result += np.bincount(frame[done], weights=area * mean[done], minlength=m)
            split = ~done
            if not split.any():
                break
            parent_frame = frame[split]
            frame, ci, cj, cls, val, refined, new_same = self._split(
                parent_frame, ci[split], cj[split], cls[:, split], val[:, split], size
            )
            # A smooth cell is done when splitting it changes its trapezoidal estimate by at most
            # smooth_tolerance (the refined estimate's own error is about a third of that).
            candidate = (same & smooth)[split] & new_same
            accept = candidate & (np.abs(refined - mean[split]) <= self.smooth_tolerance * np.abs(refined))
            if accept.any():
                result += np.bincount(parent_frame[accept], weights=area * refined[accept], minlength=m)
                keep = np.tile(~accept, 4)
                frame, ci, cj, cls, val = frame[keep], ci[keep], cj[keep], cls[:, keep], val[:, keep]
        return result

    def _split(self, frame, ci, cj, cls, val, size):
        """Children of cells (in units of ``size`` finest cells) and their (4, children) corners,
        with each cell's composite trapezoidal estimate over its children and whether its five
        new points show the class of its first corner.

        The five new lattice points of each cell (edge midpoints and centre) are cast; a
        midpoint shared by two split neighbours is cast twice (cheaper than finding it).
        """
        half = size // 2
        n = len(frame)
        # The 3 x 3 stencil of each cell, in half-cell steps (a, b); flat index 3 a + b.
        new_ab = ((1, 0), (0, 1), (1, 1), (2, 1), (1, 2))
        fi = np.concatenate([ci * size + a * half for a, _ in new_ab])
        fj = np.concatenate([cj * size + b * half for _, b in new_ab])
        new_cls, new_val = self._evaluate(np.tile(frame, len(new_ab)), fi, fj)
        stencil_cls = np.empty((9, n), dtype=np.int64)
        stencil_val = np.empty((9, n))
        for k, (a, b) in enumerate(((0, 0), (2, 0), (0, 2), (2, 2))):
            stencil_cls[3 * a + b], stencil_val[3 * a + b] = cls[k], val[k]
        stencil_cls[[3 * a + b for a, b in new_ab]] = new_cls.reshape(len(new_ab), n)
        stencil_val[[3 * a + b for a, b in new_ab]] = new_val.reshape(len(new_ab), n)
        # Children (0, 0), (1, 0), (0, 1), (1, 1), each child-major in the output; corner k of
        # child (ca, cb) is stencil point (ca + da, cb + db).
        corners = [
            [3 * (ca + da) + (cb + db) for ca, cb in ((0, 0), (1, 0), (0, 1), (1, 1))]
            for da, db in ((0, 0), (1, 0), (0, 1), (1, 1))
        ]
        child_cls = stencil_cls[corners].reshape(4, 4 * n)
        child_val = stencil_val[corners].reshape(4, 4 * n)
        child_i = np.concatenate([2 * ci + ca for ca in (0, 1, 0, 1)])
        child_j = np.concatenate([2 * cj + cb for cb in (0, 0, 1, 1)])
        # The composite trapezoidal rule over the four children (weights 1, 2, 4 over 16).
        refined = (
            stencil_val[[0, 2, 6, 8]].sum(axis=0) + 2.0 * stencil_val[[1, 3, 5, 7]].sum(axis=0) + 4.0 * stencil_val[4]
        ) / 16.0
        new_same = (new_cls == np.tile(cls[0], len(new_ab))).reshape(len(new_ab), n).all(axis=0)
        return np.tile(frame, 4), child_i, child_j, child_cls, child_val, refined, new_same

    def _evaluate(self, frame, i, j):
        """Cast and shade lattice points (finest-cell coordinates); returns (class, value).

        The class is -1 for a miss, else ``2 * surface class + lit``.
        """
        sun, obs = self._frame[:2]
        base, step_u, step_v, backward = self._rays
        rays = _direct_kernels.lattice_rays(
            base, step_u, step_v, backward, frame, i.astype(np.float32), j.astype(np.float32)
        )
        hits = self.raycaster.cast_rays(rays)
        self.n_rays += len(rays)
        hit, prim, uv, points = _direct_kernels.ray_hits(
            rays,
            hits["t_hit"].numpy(),
            hits["primitive_ids"].numpy(),
            hits["primitive_uvs"].numpy(),
            np.arange(len(rays)),
            1,
        )
        cls = np.full(len(frame), -1, dtype=np.int64)
        value = np.zeros(len(frame))
        if len(hit):
            value[hit], lit = self.shade(frame[hit], prim, uv, points, sun, obs, self._flat_table)
            cls[hit] = 2 * self.classes[prim] + lit
        return cls, value

    # ------------------------------------------------------------------ marks
    def _marks(self, sun, obs, u, v, start_u, start_v, size_u, size_v):
        """{level: (m, cells_u, cells_v) bool} cells crossed by a feature edge or an edge's shadow."""
        edges, h, levels = self.edges, self.h, self.levels
        marked_levels = [lv for lv in range(levels) if (1 << (levels - lv)) >= _MARK_MIN_CELLS]
        if not marked_levels or len(edges.ends) == 0:
            return {}
        # Points every two finest cells along the edges serve every marked level.
        spacing_m = 0.5 * h * (1 << (levels - marked_levels[-1]))
        frame, points = _points_along(edges.ends, edges.seen_features(obs), spacing_m)
        shadow_frame, shadow_origin = _points_along(edges.ends, edges.sun_silhouettes(sun), spacing_m)
        if len(shadow_frame):
            offset = 1e-4 * max(self.mesh.radius_m, 1.0)
            away = -sun[shadow_frame]
            origins = shadow_origin + offset * away
            rays = np.concatenate([origins, away], axis=1).astype(np.float32)
            t_hit = self.raycaster.cast_rays(rays)["t_hit"].numpy()
            self.n_rays += len(rays)
            landed = np.isfinite(t_hit)
            frame = np.concatenate([frame, shadow_frame[landed]])
            points = np.concatenate([points, origins[landed] + t_hit[landed, None] * away[landed]])
        rel = points - self.mesh.center_m
        fu = (np.einsum("ij,ij->i", rel, u[frame]) - start_u[frame]) / h
        fv = (np.einsum("ij,ij->i", rel, v[frame]) - start_v[frame]) / h
        marks = {}
        for level in marked_levels:
            size = 1 << (levels - level)
            cu, cv = np.floor(fu / size).astype(np.int64), np.floor(fv / size).astype(np.int64)
            shape = (len(sun), size_u << level, size_v << level)
            inside = (cu >= 0) & (cv >= 0) & (cu < shape[1]) & (cv < shape[2])
            marks[level] = _CellSet(shape, frame[inside], cu[inside], cv[inside])
        return marks


class _CellSet:
    """A set of (frame, i, j) cells: a dense boolean grid, or sorted keys when that is large."""

    def __init__(self, shape, frame, i, j):
        self.shape = shape
        if shape[0] * shape[1] * shape[2] <= _MAX_DENSE_MARKS:
            self.grid = np.zeros(shape, dtype=bool)
            self.grid[frame, i, j] = True
        else:
            self.grid = None
            self.keys = np.unique(self._key(frame, i, j))

    def _key(self, frame, i, j):
        return (frame * self.shape[1] + i) * self.shape[2] + j

    def holds(self, frame, i, j):
        """(n,) bool: the cells are in the set."""
        if self.grid is not None:
            return self.grid[frame, i, j]
        key = self._key(frame, i, j)
        where = np.minimum(np.searchsorted(self.keys, key), max(len(self.keys) - 1, 0))
        return (self.keys[where] == key) if len(self.keys) else np.zeros(len(key), dtype=bool)


def _points_along(ends, selected, spacing_m):
    """Points at most ``spacing_m`` apart along the selected edges of each frame.

    Parameters
    ----------
    ends : (e, 2, 3) float, edge end points.
    selected : (m, e) bool
    spacing_m : float

    Returns
    -------
    frame : (p,) int, points : (p, 3) float
    """
    frame, edge = np.nonzero(selected)
    if len(frame) == 0:
        return frame, np.zeros((0, 3))
    length = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    count = np.ceil(length[edge] / spacing_m).astype(np.int64) + 1
    owner = np.repeat(np.arange(len(edge)), count)
    position = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
    t = position / np.maximum(count[owner] - 1, 1)
    e = edge[owner]
    return frame[owner], ends[e, 0] + t[:, None] * (ends[e, 1] - ends[e, 0])
