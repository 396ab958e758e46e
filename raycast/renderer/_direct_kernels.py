"""Compiled (numba) loops of the direct renderer (raycast.renderer.direct, raycast.renderer.refine).

Ray set-up, hit compaction, sunward hits with their shadow rays and smooth-normal
interpolation: one pass per batch of rays instead of a dozen (n, 3) gathers.
"""

from numba import njit
import numpy as np

from raycast.renderer._cache_kernels import grown
from raycast.renderer.rays import SUN_RADIUS_SINE, risen_sun

# A triangle's hits count as shares of its exact projected area (raster_hits) only when that
# area is at least this many pixels: then some pixel centre falls on it whatever the grid's
# offset (a compact triangle surely; a strip of 8 pixels' area covers 8 centres on average,
# none with odds of about e**-8), so the share's bias is negligible. A smaller triangle can fall
# between the centres, and a share would then drop its light in some frames and inflate it in
# others, on average too little. Where it is that small because it is seen nearly edge-on (its
# own area at least this many pixels, at most a given fraction of it seen: a sliver, a strip
# whose pixel centres say little of it), a flat one is sampled on its own surface instead
# (sliver_rays; the rule is raycast.renderer.direct.sliver_areas'), its hits counting nothing.
# Another small triangle counts a pixel per hit, which is right on average (and the tiles of a
# finely cut surface sum as the surface does).
EXACT_SHARE_MIN_PIXELS = 8.0


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
    """Hits on a face turned toward the Sun (some of its disk above the face's plane), and
    their shadow rays (toward the part of the disk above the plane: :func:`raycast.renderer.rays.risen_sun`).

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
        if nx * sun[f, 0] + ny * sun[f, 1] + nz * sun[f, 2] > -SUN_RADIUS_SINE:
            lit[count] = n
            count += 1
    rays = np.empty((count, 6), dtype=np.float32)
    for k in range(count):
        n, f = lit[k], frames[lit[k]]
        direction = risen_sun(normals[n, 0], normals[n, 1], normals[n, 2], sun[f, 0], sun[f, 1], sun[f, 2])
        for x in range(3):
            rays[k, x] = points[n, x] + offset * normals[n, x]
            rays[k, 3 + x] = direction[x]
    return normals, lit[:count], rays


@njit(cache=True, nogil=True, inline="always")
def _corner_mix(corner_normals, t, a, b, sx, sy, sz):
    """Triangle t's corner normals mixed at barycentric (a, b), normalised and turned to the
    side of (sx, sy, sz)."""
    c = 1.0 - a - b
    x = c * corner_normals[t, 0, 0] + a * corner_normals[t, 1, 0] + b * corner_normals[t, 2, 0]
    y = c * corner_normals[t, 0, 1] + a * corner_normals[t, 1, 1] + b * corner_normals[t, 2, 1]
    z = c * corner_normals[t, 0, 2] + a * corner_normals[t, 1, 2] + b * corner_normals[t, 2, 2]
    norm = np.sqrt(x * x + y * y + z * z)
    if x * sx + y * sy + z * sz < 0.0:
        norm = -norm
    return x / norm, y / norm, z / norm


@njit(cache=True, nogil=True)
def interpolated_normals(normals, rows, prim, uv, corner_normals):
    """Replace ``normals[rows]`` by the barycentric mix of their triangle's corner normals,
    normalised and turned to the side of the normal it replaces (in place)."""
    for n in rows:
        x, y, z = _corner_mix(corner_normals, prim[n], uv[n, 0], uv[n, 1], normals[n, 0], normals[n, 1], normals[n, 2])
        normals[n, 0], normals[n, 1], normals[n, 2] = x, y, z


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


@njit(cache=True, nogil=True)
def raster_hits(
    corners,
    pu,
    pv,
    depth,
    start_u,
    start_v,
    h,
    n_u,
    n_v,
    frames,
    drawn,
    sunward,
    face_normals,
    obs,
    sun,
    offset,
    sliver_below,
):
    """First hits of the orthographic ray grid by scan conversion, kept where the hit side
    faces the Sun, each with the share of its triangle's exact projected area it stands for.

    Pixel (i, j) of frame f is the ray through ``(start_u[f] + (i + 1/2) h, start_v[f] +
    (j + 1/2) h)`` in the image plane; every triangle with ``drawn[t, f]`` is scan-converted
    onto that lattice with a depth test (``depth``: distance toward the observer, nearest
    wins), which finds the same triangle a ray cast along the grid finds first. Only the
    window of pixels that sunward triangles cover is drawn: elsewhere no hit adds light.

    Parameters
    ----------
    corners : (t, 3, 3) float, triangle corners (body frame).
    pu, pv, depth : (3 t, m) float, corner coordinates along the image axes and toward the observer.
    start_u, start_v : (m,) float; h : float; n_u, n_v : (m,) int, pixels per frame and axis.
    frames : (k,) int, the frames to render.
    drawn : (t, m) bool, triangles that can be seen (not an inner side of a closed part).
    sunward : (t, m) bool, triangles whose seen side faces the Sun.
    face_normals : (t, 3) float; obs, sun : (m, 3) float, unit vectors.
    offset : float, how far above the surface shadow rays start.
    sliver_below : (t,) float, pixels of projected area at or under which a triangle is a sliver
        (0 where it never is; raycast.renderer.direct.sliver_areas).

    Returns
    -------
    owners, prim : (k,) int64, frame and triangle of each kept hit.
    uv : (k, 2) float32, barycentric (u, v).
    shadow_rays : (k, 6) float32, from ``offset`` above the hit (along the face normal turned
        toward the observer) toward the Sun (the part of its disk above the face's plane).
    share : (k,) float64, the triangle's exact projected area in pixels (h**2) divided by the
        number of pixel centres it covers before the depth test: what each of its hits stands
        for when the hits of a flat triangle count as the lit and seen fraction of its whole
        area (:func:`flat_sums`). Near 1 on a large face seen face-on, far from it on a face seen
        nearly edge-on, whose thin strip the pixel centres cover by chance. For triangles under
        ``EXACT_SHARE_MIN_PIXELS`` of projected area: 0 for slivers (listed in ``sliver_*``), 1
        for the others.
    sliver_frames, sliver_prim : (s,) int64, the frames and slivers drawn and sunward: a
        projected area above 0, under ``EXACT_SHARE_MIN_PIXELS`` and at most ``sliver_below``.
    sliver_pixels : (s,) float64, their exact projected areas in pixels.
    """
    n_tri = len(corners)
    window = np.zeros((len(frames), 4), dtype=np.int64)
    capacity, largest = 0, 0
    for k in range(len(frames)):
        f = frames[k]
        lo_u, hi_u, lo_v, hi_v = np.inf, -np.inf, np.inf, -np.inf
        for t in range(n_tri):
            if sunward[t, f] and drawn[t, f]:
                for c in range(3):
                    lo_u, hi_u = min(lo_u, pu[3 * t + c, f]), max(hi_u, pu[3 * t + c, f])
                    lo_v, hi_v = min(lo_v, pv[3 * t + c, f]), max(hi_v, pv[3 * t + c, f])
        if lo_u > hi_u:
            continue
        window[k, 0] = max(int(np.ceil((lo_u - start_u[f]) / h - 0.5)), 0)
        window[k, 1] = min(int(np.floor((hi_u - start_u[f]) / h - 0.5)), n_u[f] - 1) + 1
        window[k, 2] = max(int(np.ceil((lo_v - start_v[f]) / h - 0.5)), 0)
        window[k, 3] = min(int(np.floor((hi_v - start_v[f]) / h - 0.5)), n_v[f] - 1) + 1
        size = max(window[k, 1] - window[k, 0], 0) * max(window[k, 3] - window[k, 2], 0)
        capacity += size
        largest = max(largest, size)
    owners = np.empty(capacity, dtype=np.int64)
    prim = np.empty(capacity, dtype=np.int64)
    uv = np.empty((capacity, 2), dtype=np.float32)
    shadow_rays = np.empty((capacity, 6), dtype=np.float32)
    share = np.empty(capacity)
    # Per triangle, in the frame being drawn: its projected area and covered pixel centres.
    exact, covered = np.zeros(n_tri), np.zeros(n_tri)
    sliver_frames = np.empty(64, dtype=np.int64)
    sliver_prim = np.empty(64, dtype=np.int64)
    sliver_pixels = np.empty(64)
    n_slivers = 0
    nearest = np.empty(largest, dtype=np.float32)
    winner = np.empty(largest, dtype=np.int32)
    xs, ys = np.empty(3), np.empty(3)
    count = 0
    for k in range(len(frames)):
        f = frames[k]
        i0, i1, j0, j1 = window[k, 0], window[k, 1], window[k, 2], window[k, 3]
        width, rows = i1 - i0, j1 - j0
        if width <= 0 or rows <= 0:
            continue
        nearest[: width * rows] = -np.inf
        winner[: width * rows] = -1
        for t in range(n_tri):
            if not drawn[t, f]:
                continue
            # Lattice coordinates within the window: pixel (i, j) of the window at (i, j).
            for c in range(3):
                xs[c] = (pu[3 * t + c, f] - start_u[f]) / h - 0.5 - i0
                ys[c] = (pv[3 * t + c, f] - start_v[f]) / h - 0.5 - j0
            area = (xs[1] - xs[0]) * (ys[2] - ys[0]) - (xs[2] - xs[0]) * (ys[1] - ys[0])
            exact[t], covered[t] = 0.5 * abs(area), 0.0
            if area == 0.0:
                continue
            d0, d1, d2 = depth[3 * t, f], depth[3 * t + 1, f], depth[3 * t + 2, f]
            low = max(int(np.ceil(min(ys[0], ys[1], ys[2]))), 0)
            high = min(int(np.floor(max(ys[0], ys[1], ys[2]))), rows - 1)
            for j in range(low, high + 1):
                left, right = np.inf, -np.inf
                for c in range(3):
                    y0, y1 = ys[c], ys[(c + 1) % 3]
                    if (y0 - j) * (y1 - j) > 0.0:
                        continue
                    if y0 == y1:
                        left = min(left, xs[c], xs[(c + 1) % 3])
                        right = max(right, xs[c], xs[(c + 1) % 3])
                    else:
                        x = xs[c] + (j - y0) * (xs[(c + 1) % 3] - xs[c]) / (y1 - y0)
                        left, right = min(left, x), max(right, x)
                first = max(int(np.ceil(left)), 0)
                last = min(int(np.floor(right)), width - 1)
                if first > last:
                    continue
                covered[t] += last - first + 1
                # Barycentric (a, b) and depth are linear along the row.
                a = ((first - xs[0]) * (ys[2] - ys[0]) - (xs[2] - xs[0]) * (j - ys[0])) / area
                b = ((xs[1] - xs[0]) * (j - ys[0]) - (first - xs[0]) * (ys[1] - ys[0])) / area
                da, db = (ys[2] - ys[0]) / area, -(ys[1] - ys[0]) / area
                z = d0 + a * (d1 - d0) + b * (d2 - d0)
                dz = da * (d1 - d0) + db * (d2 - d0)
                row = j * width
                for i in range(first, last + 1):
                    if z > nearest[row + i]:
                        nearest[row + i] = z
                        winner[row + i] = t
                    z += dz
        for t in range(n_tri):
            if (
                drawn[t, f]
                and sunward[t, f]
                and 0.0 < exact[t] < EXACT_SHARE_MIN_PIXELS
                and exact[t] <= sliver_below[t]
            ):
                if n_slivers == len(sliver_prim):
                    sliver_frames = grown(sliver_frames, 2 * n_slivers, n_slivers)
                    sliver_prim = grown(sliver_prim, 2 * n_slivers, n_slivers)
                    sliver_pixels = grown(sliver_pixels, 2 * n_slivers, n_slivers)
                sliver_frames[n_slivers], sliver_prim[n_slivers], sliver_pixels[n_slivers] = f, t, exact[t]
                n_slivers += 1
        for pixel in range(width * rows):
            t = winner[pixel]
            if t < 0 or not sunward[t, f]:
                continue
            j, i = pixel // width, pixel % width
            at_u = (i + i0 + 0.5) * h + start_u[f]
            at_v = (j + j0 + 0.5) * h + start_v[f]
            for c in range(3):
                xs[c] = pu[3 * t + c, f]
                ys[c] = pv[3 * t + c, f]
            area = (xs[1] - xs[0]) * (ys[2] - ys[0]) - (xs[2] - xs[0]) * (ys[1] - ys[0])
            a = ((at_u - xs[0]) * (ys[2] - ys[0]) - (xs[2] - xs[0]) * (at_v - ys[0])) / area
            b = ((xs[1] - xs[0]) * (at_v - ys[0]) - (at_u - xs[0]) * (ys[1] - ys[0])) / area
            a, b = min(max(a, 0.0), 1.0), min(max(b, 0.0), 1.0)
            if a + b > 1.0:
                total = a + b
                a, b = a / total, b / total
            owners[count], prim[count] = f, t
            uv[count, 0], uv[count, 1] = a, b
            # (The pixel it won is one it covers: covered[t] >= 1.)
            if exact[t] >= EXACT_SHARE_MIN_PIXELS:
                share[count] = exact[t] / covered[t]
            else:
                share[count] = 0.0 if exact[t] <= sliver_below[t] else 1.0
            side = 1.0
            if face_normals[t, 0] * obs[f, 0] + face_normals[t, 1] * obs[f, 1] + face_normals[t, 2] * obs[f, 2] < 0.0:
                side = -1.0
            direction = risen_sun(
                side * face_normals[t, 0],
                side * face_normals[t, 1],
                side * face_normals[t, 2],
                sun[f, 0],
                sun[f, 1],
                sun[f, 2],
            )
            for x in range(3):
                shadow_rays[count, x] = (
                    (1.0 - a - b) * corners[t, 0, x]
                    + a * corners[t, 1, x]
                    + b * corners[t, 2, x]
                    + offset * side * face_normals[t, x]
                )
                shadow_rays[count, 3 + x] = direction[x]
            count += 1
    return (
        owners[:count],
        prim[:count],
        uv[:count],
        shadow_rays[:count],
        share[:count],
        sliver_frames[:n_slivers],
        sliver_prim[:n_slivers],
        sliver_pixels[:n_slivers],
    )


@njit(cache=True, nogil=True)
def sliver_rays(corners, face_normals, obs, sun, frames, prim, offset, n):
    """(2 s n**2, 6) float32 rays that sample s slivers on their own surface: from the
    centroids of the n**2 equal triangles of each one's n-fold subdivision, ``offset`` above it
    (along the face normal turned toward the observer), a ray toward the observer and one toward
    the Sun (the part of its disk above the face's plane), in that order, point after point.
    A point is seen where its first ray is not blocked and lit where its second is not."""
    per = n * n
    rays = np.empty((2 * len(frames) * per, 6), dtype=np.float32)
    row = 0
    for k in range(len(frames)):
        f, t = frames[k], prim[k]
        side = 1.0
        if face_normals[t, 0] * obs[f, 0] + face_normals[t, 1] * obs[f, 1] + face_normals[t, 2] * obs[f, 2] < 0.0:
            side = -1.0
        nx, ny, nz = side * face_normals[t, 0], side * face_normals[t, 1], side * face_normals[t, 2]
        toward_sun = risen_sun(nx, ny, nz, sun[f, 0], sun[f, 1], sun[f, 2])
        for i in range(n):
            for j in range(n - i):
                # The subdivision's upward triangle at (i, j), then the downward one beside it.
                for shift in (1.0 / 3.0, 2.0 / 3.0):
                    if shift > 0.5 and i + j == n - 1:
                        continue
                    a, b = (i + shift) / n, (j + shift) / n
                    for x in range(3):
                        point = (1.0 - a - b) * corners[t, 0, x] + a * corners[t, 1, x] + b * corners[t, 2, x]
                        point += offset * side * face_normals[t, x]
                        rays[row, x] = point
                        rays[row + 1, x] = point
                        rays[row, 3 + x] = obs[f, x]
                        rays[row + 1, 3 + x] = toward_sun[x]
                    row += 2
    return rays


@njit(cache=True, nogil=True)
def flat_sums(frames, prim, blocked, smooth, flat_table, out, share):
    """Add the table radiance ``flat_table[frame, triangle]`` of every unblocked hit on a
    flat-shaded triangle, times its ``share`` (:func:`raster_hits`), to ``out[frame]`` (in
    place); return the unblocked smooth-shaded hits."""
    rest = np.empty(len(frames), dtype=np.int64)
    count = 0
    for n in range(len(frames)):
        if blocked[n]:
            continue
        t = prim[n]
        if smooth[t]:
            rest[count] = n
            count += 1
        else:
            out[frames[n]] += flat_table[frames[n], t] * share[n]
    return rest[:count]


@njit(cache=True, nogil=True)
def smooth_hits(rest, frames, prim, uv, face_normals, cos_o, corner_normals):
    """The hits ``rest`` (of :func:`flat_sums`) on smooth-shaded triangles, ready to shade:
    their frames and triangles, their shading normals (the barycentric mix of the triangle's
    corner normals, :func:`_corner_mix`) and their face normals, both turned toward
    the observer (``cos_o`` (t, m): face normal . observer). One pass instead of numpy's
    gathers and copies of (k, 3) arrays."""
    k = len(rest)
    out_frames = np.empty(k, dtype=np.int64)
    out_prim = np.empty(k, dtype=np.int64)
    normals = np.empty((k, 3))
    geo = np.empty((k, 3))
    for r in range(k):
        n = rest[r]
        f, t = frames[n], prim[n]
        out_frames[r], out_prim[r] = f, t
        side = -1.0 if cos_o[t, f] < 0.0 else 1.0
        gx, gy, gz = side * face_normals[t, 0], side * face_normals[t, 1], side * face_normals[t, 2]
        geo[r, 0], geo[r, 1], geo[r, 2] = gx, gy, gz
        x, y, z = _corner_mix(corner_normals, t, uv[n, 0], uv[n, 1], gx, gy, gz)
        normals[r, 0], normals[r, 1], normals[r, 2] = x, y, z
    return out_frames, out_prim, normals, geo


@njit(cache=True, nogil=True)
def need_shadow_rays(corners, group, sun, axis_u, axis_v, cell, owners, prim, shadow_rays):
    """(k,) bool: which hits' shadow rays can meet something; the others are lit for certain.

    Per frame the triangles are binned, seen from the Sun, into square cells of side ``cell``
    (each into every cell its bounding box touches) and every cell keeps the highest point
    toward the Sun of the two highest *groups* in it: a group is a closed convex part (which
    cannot shade its own sunlit side) or a single triangle. A hit whose own cell holds nothing
    of another group above the hit cannot be shaded: its shadow ray would leave the cell's
    column only above all of it.

    Parameters
    ----------
    corners : (t, 3, 3) float, triangle corners (body frame).
    group : (t,) int, each triangle's group.
    sun, axis_u, axis_v : (m, 3) float, the Sun and two axes across it, per frame.
    cell : float, cell side (m).
    owners, prim : (k,) int, frame (ascending) and triangle of each hit.
    shadow_rays : (k, 6) float32, the hits' shadow rays (origin, direction).
    """
    need = np.ones(len(owners), dtype=np.bool_)
    n_tri = len(corners)
    low_u, low_v = np.empty(n_tri), np.empty(n_tri)
    high_u, high_v, top = np.empty(n_tri), np.empty(n_tri), np.empty(n_tri)
    first = 0
    while first < len(owners):
        f = owners[first]
        last = first
        while last < len(owners) and owners[last] == f:
            last += 1
        min_u, min_v, max_u, max_v = np.inf, np.inf, -np.inf, -np.inf
        for t in range(n_tri):
            low_u[t], low_v[t], high_u[t], high_v[t], top[t] = np.inf, np.inf, -np.inf, -np.inf, -np.inf
            for c in range(3):
                pu = corners[t, c, 0] * axis_u[f, 0] + corners[t, c, 1] * axis_u[f, 1] + corners[t, c, 2] * axis_u[f, 2]
                pv = corners[t, c, 0] * axis_v[f, 0] + corners[t, c, 1] * axis_v[f, 1] + corners[t, c, 2] * axis_v[f, 2]
                ps = corners[t, c, 0] * sun[f, 0] + corners[t, c, 1] * sun[f, 1] + corners[t, c, 2] * sun[f, 2]
                low_u[t], high_u[t] = min(low_u[t], pu), max(high_u[t], pu)
                low_v[t], high_v[t] = min(low_v[t], pv), max(high_v[t], pv)
                top[t] = max(top[t], ps)
            min_u, max_u = min(min_u, low_u[t]), max(max_u, high_u[t])
            min_v, max_v = min(min_v, low_v[t]), max(max_v, high_v[t])
        n_u = int((max_u - min_u) / cell) + 1
        n_v = int((max_v - min_v) / cell) + 1
        first_top = np.full(n_u * n_v, -np.inf)
        first_group = np.full(n_u * n_v, -1, dtype=np.int64)
        second_top = np.full(n_u * n_v, -np.inf)
        for t in range(n_tri):
            g, z = group[t], top[t]
            for i in range(int((low_u[t] - min_u) / cell), int((high_u[t] - min_u) / cell) + 1):
                for j in range(int((low_v[t] - min_v) / cell), int((high_v[t] - min_v) / cell) + 1):
                    k = i * n_v + j
                    if g == first_group[k]:
                        first_top[k] = max(first_top[k], z)
                    elif z > first_top[k]:
                        second_top[k] = first_top[k]
                        first_top[k], first_group[k] = z, g
                    else:
                        second_top[k] = max(second_top[k], z)
        for n in range(first, last):
            x, y, w = shadow_rays[n, 0], shadow_rays[n, 1], shadow_rays[n, 2]
            pu = x * axis_u[f, 0] + y * axis_u[f, 1] + w * axis_u[f, 2]
            pv = x * axis_v[f, 0] + y * axis_v[f, 1] + w * axis_v[f, 2]
            ps = x * sun[f, 0] + y * sun[f, 1] + w * sun[f, 2]
            i, j = int((pu - min_u) / cell), int((pv - min_v) / cell)
            if i < 0 or j < 0 or i >= n_u or j >= n_v:
                continue
            k = i * n_v + j
            other = second_top[k] if first_group[k] == group[prim[n]] else first_top[k]
            need[n] = other > ps
        first = last
    return need
