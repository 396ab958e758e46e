"""Compiled (numba) loops of the direct renderer (raycast.direct, raycast.refine).

Ray set-up, hit compaction, sunward hits with their shadow rays and smooth-normal
interpolation: one pass per batch of rays instead of a dozen (n, 3) gathers.
"""

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def tile_rays(tile_origin, owner, step_u, step_v, backward, tile):
    """(k tile**2, 6) float32 orthographic rays of k tiles: pixel (i, j) of tile n starts at
    ``tile_origin[n] + i step_u[f] + j step_v[f]`` and runs along ``backward[f]``, f = owner[n]."""
    rays = np.empty((len(owner) * tile * tile, 6), dtype=np.float32)
    row = 0
    for n in range(len(owner)):
        f = owner[n]
        for i in range(tile):
            for j in range(tile):
                for x in range(3):
                    rays[row, x] = tile_origin[n, x] + i * step_u[f, x] + j * step_v[f, x]
                    rays[row, 3 + x] = backward[f, x]
                row += 1
    return rays


@njit(cache=True, nogil=True)
def ray_hits(rays, t_hit, prim_ids, uvs, owner, rays_per_owner):
    """The rays that hit (finite ``t_hit``): their owners (``owner[r // rays_per_owner]`` for
    ray r: a tile's frame, or with ``owner = arange`` and 1 the ray's own index), triangles,
    barycentric (u, v) and (h, 3) float32 end points."""
    count = 0
    for r in range(len(t_hit)):
        if np.isfinite(t_hit[r]):
            count += 1
    owners = np.empty(count, dtype=np.int64)
    prim = np.empty(count, dtype=np.int64)
    uv = np.empty((count, 2), dtype=np.float32)
    points = np.empty((count, 3), dtype=np.float32)
    n = 0
    for r in range(len(t_hit)):
        t = t_hit[r]
        if not np.isfinite(t):
            continue
        owners[n] = owner[r // rays_per_owner]
        prim[n] = prim_ids[r]
        uv[n, 0], uv[n, 1] = uvs[r, 0], uvs[r, 1]
        for x in range(3):
            points[n, x] = rays[r, x] + t * rays[r, 3 + x]
        n += 1
    return owners, prim, uv, points


@njit(cache=True, nogil=True)
def sunward_hits(frames, prim, points, face_normals, sun, obs, offset):
    """Hits on a face turned toward the Sun, and their shadow rays.

    The face normal is turned toward the observer (either side of a face may be seen).

    Returns
    -------
    normals : (h, 3) float64 face normals, turned toward the observer.
    lit : (k,) int64, hits whose turned normal faces the Sun.
    rays : (k, 6) float32 shadow rays from ``offset`` above each toward the Sun.
    """
    n_hits = len(frames)
    normals = np.empty((n_hits, 3))
    lit = np.empty(n_hits, dtype=np.int64)
    count = 0
    for n in range(n_hits):
        f, t = frames[n], prim[n]
        nx, ny, nz = face_normals[t, 0], face_normals[t, 1], face_normals[t, 2]
        if nx * obs[f, 0] + ny * obs[f, 1] + nz * obs[f, 2] < 0.0:
            nx, ny, nz = -nx, -ny, -nz
        normals[n, 0], normals[n, 1], normals[n, 2] = nx, ny, nz
        if nx * sun[f, 0] + ny * sun[f, 1] + nz * sun[f, 2] > 0.0:
            lit[count] = n
            count += 1
    rays = np.empty((count, 6), dtype=np.float32)
    for k in range(count):
        n, f = lit[k], frames[lit[k]]
        for x in range(3):
            rays[k, x] = points[n, x] + offset * normals[n, x]
            rays[k, 3 + x] = sun[f, x]
    return normals, lit[:count], rays


@njit(cache=True, nogil=True)
def interpolated_normals(normals, rows, prim, uv, corner_normals):
    """Replace ``normals[rows]`` by the barycentric mix of their triangle's corner normals,
    normalised and turned to the side of the normal it replaces (in place)."""
    for n in rows:
        t = prim[n]
        a, b = uv[n, 0], uv[n, 1]
        c = 1.0 - a - b
        x = c * corner_normals[t, 0, 0] + a * corner_normals[t, 1, 0] + b * corner_normals[t, 2, 0]
        y = c * corner_normals[t, 0, 1] + a * corner_normals[t, 1, 1] + b * corner_normals[t, 2, 1]
        z = c * corner_normals[t, 0, 2] + a * corner_normals[t, 1, 2] + b * corner_normals[t, 2, 2]
        norm = np.sqrt(x * x + y * y + z * z)
        if x * normals[n, 0] + y * normals[n, 1] + z * normals[n, 2] < 0.0:
            norm = -norm
        normals[n, 0], normals[n, 1], normals[n, 2] = x / norm, y / norm, z / norm


@njit(cache=True, nogil=True)
def lattice_rays(base, step_u, step_v, backward, frame, i, j):
    """(n, 6) float32 rays at lattice points (i, j) of their frames: from
    ``base[:, f] + i step_u[:, f] + j step_v[:, f]`` along ``backward[:, f]`` ((3, m) tables)."""
    rays = np.empty((len(frame), 6), dtype=np.float32)
    for n in range(len(frame)):
        f = frame[n]
        for x in range(3):
            rays[n, x] = base[x, f] + i[n] * step_u[x, f] + j[n] * step_v[x, f]
            rays[n, 3 + x] = backward[x, f]
    return rays
