"""The direct renderer's compiled loops against the same steps written out in numpy."""

import numpy as np

from raycast.renderer import _direct_kernels


def _unit(a):
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def test_sunward_hits_turn_normals_to_the_observer_and_keep_those_facing_the_sun():
    rng = np.random.default_rng(1)
    n_hits, n_frames, n_tri = 200, 4, 9
    frames, prim = rng.integers(0, n_frames, n_hits), rng.integers(0, n_tri, n_hits)
    points = rng.normal(size=(n_hits, 3)).astype(np.float32)
    face_normals = _unit(rng.normal(size=(n_tri, 3)))
    sun, obs = _unit(rng.normal(size=(n_frames, 3))), _unit(rng.normal(size=(n_frames, 3)))
    normals, lit, rays = _direct_kernels.sunward_hits(frames, prim, points, face_normals, sun, obs, 1e-3)
    turned = (
        face_normals[prim] * np.where(np.einsum("ij,ij->i", face_normals[prim], obs[frames]) < 0, -1.0, 1.0)[:, None]
    )
    np.testing.assert_array_equal(normals, turned)
    expected_lit = np.flatnonzero(np.einsum("ij,ij->i", turned, sun[frames]) > 0.0)
    np.testing.assert_array_equal(lit, expected_lit)
    assert 0 < len(lit) < n_hits
    np.testing.assert_allclose(rays[:, :3], points[lit] + 1e-3 * turned[lit], atol=1e-6)
    np.testing.assert_allclose(rays[:, 3:], sun[frames[lit]], atol=1e-7)


def test_interpolated_normals_mix_the_corners_on_the_seen_side():
    corner_normals = _unit(np.array([[[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]]]))
    uv = np.array([[0.0, 0.0], [0.5, 0.25], [0.2, 0.2]], dtype=np.float32)
    normals = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])  # the third seen from below
    prim = np.zeros(3, dtype=np.int64)
    _direct_kernels.interpolated_normals(normals, np.array([1, 2]), prim, uv, corner_normals)
    np.testing.assert_array_equal(normals[0], [0.0, 0.0, 1.0])  # not in the rows: untouched
    for row, sign in ((1, 1.0), (2, -1.0)):
        a, b = uv[row]
        mix = (1 - a - b) * corner_normals[0, 0] + a * corner_normals[0, 1] + b * corner_normals[0, 2]
        np.testing.assert_allclose(normals[row], sign * _unit(mix), rtol=1e-6)


def test_tile_rays_and_their_hits():
    origin = np.array([[1.0, 2.0, 3.0]], dtype=np.float32)
    step_u = np.array([[0.1, 0.0, 0.0]], dtype=np.float32)
    step_v = np.array([[0.0, 0.2, 0.0]], dtype=np.float32)
    backward = np.array([[0.0, 0.0, -1.0]], dtype=np.float32)
    rays = _direct_kernels.tile_rays(origin, np.array([0]), step_u, step_v, backward, 2)
    np.testing.assert_allclose(
        rays[:, :3], [[1.0, 2.0, 3.0], [1.0, 2.2, 3.0], [1.1, 2.0, 3.0], [1.1, 2.2, 3.0]], rtol=1e-6
    )
    t_hit = np.array([np.inf, 2.0, np.inf, 0.5], dtype=np.float32)
    frames, prim, uv, points = _direct_kernels.ray_hits(
        rays,
        t_hit,
        np.array([7, 8, 9, 10], dtype=np.uint32),
        np.arange(8, dtype=np.float32).reshape(4, 2),
        np.array([5]),
        4,
    )
    np.testing.assert_array_equal(frames, [5, 5])
    np.testing.assert_array_equal(prim, [8, 10])
    np.testing.assert_array_equal(uv, [[2, 3], [6, 7]])
    np.testing.assert_allclose(points, [[1.0, 2.2, 1.0], [1.1, 2.2, 2.5]], rtol=1e-6)
    # Each ray its own owner (as the adaptive sampler asks): the owners are the hit rays.
    hit, prim, _, end = _direct_kernels.ray_hits(
        rays, t_hit, np.array([7, 8, 9, 10], dtype=np.uint32), np.zeros((4, 2), dtype=np.float32), np.arange(4), 1
    )
    np.testing.assert_array_equal(hit, [1, 3])
    np.testing.assert_array_equal(prim, [8, 10])
    np.testing.assert_allclose(end, points, rtol=1e-6)


def test_flat_sums_add_unblocked_flat_hits_and_return_the_smooth_ones():
    frames = np.array([0, 0, 1, 1, 1, 2])
    prim = np.array([0, 1, 0, 2, 1, 0])
    blocked = np.array([False, False, True, False, False, False])
    smooth = np.array([False, True, False])
    table = np.arange(9, dtype=float).reshape(3, 3) + 1.0
    out = np.full(3, 0.5)
    share = np.array([1.0, 9.0, 9.0, 0.5, 9.0, 2.0])
    rest = _direct_kernels.flat_sums(frames, prim, blocked, smooth, table, out, share)
    # Flat, unblocked, times their share: (0, 0) -> 1 x 1, (1, 2) -> 6 x 0.5, (2, 0) -> 7 x 2;
    # the blocked (1, 0) and the smooth hits add nothing.
    np.testing.assert_array_equal(out, [1.5, 3.5, 14.5])
    np.testing.assert_array_equal(rest, [1, 4])


def _box_corners(low, high):
    """(12, 3, 3) corners of an axis-aligned box's triangles (winding irrelevant here)."""
    lo, hi = np.asarray(low, float), np.asarray(high, float)
    corners = []
    for axis in range(3):
        a, b = [x for x in range(3) if x != axis]
        for level in (lo[axis], hi[axis]):
            quad = []
            for da, db in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = np.empty(3)
                p[axis], p[a], p[b] = level, (lo[a], hi[a])[da], (lo[b], hi[b])[db]
                quad.append(p)
            corners += [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
    return np.array(corners)


def test_smooth_hits_are_the_numpy_gathers_of_the_hits_they_name():
    rng = np.random.default_rng(7)
    n_hits, n_frames, n_tri = 300, 5, 11
    frames, prim = rng.integers(0, n_frames, n_hits), rng.integers(0, n_tri, n_hits)
    uv = rng.uniform(0.0, 0.5, size=(n_hits, 2)).astype(np.float32)
    face_normals = _unit(rng.normal(size=(n_tri, 3)))
    corner_normals = _unit(face_normals[:, None, :] + 0.3 * rng.normal(size=(n_tri, 3, 3)))
    obs = _unit(rng.normal(size=(n_frames, 3)))
    cos_o = face_normals @ obs.T
    rest = np.sort(rng.choice(n_hits, 120, replace=False))
    got_frames, got_prim, normals, geo = _direct_kernels.smooth_hits(
        rest, frames, prim, uv, face_normals, cos_o, corner_normals
    )
    np.testing.assert_array_equal(got_frames, frames[rest])
    np.testing.assert_array_equal(got_prim, prim[rest])
    turned = face_normals[prim[rest]] * np.where(cos_o[prim[rest], frames[rest]] < 0.0, -1.0, 1.0)[:, None]
    np.testing.assert_array_equal(geo, turned)
    assert (geo[:, None, :] @ obs[frames[rest], :, None]).min() > 0.0  # all toward the observer
    expected = turned.copy()
    _direct_kernels.interpolated_normals(expected, np.arange(len(rest)), prim[rest], uv[rest], corner_normals)
    np.testing.assert_allclose(normals, expected, rtol=0, atol=1e-15)
    assert np.einsum("ij,ij->i", normals, geo).min() > 0.0  # each on its face's seen side


def test_need_shadow_rays_only_under_another_group():
    # A 4 x 4 m block (group 0) with a 1 x 1 m plate (group 1) hovering 1 m above its left
    # half; the Sun straight above. Hits on the block's top under the plate need a shadow ray;
    # hits elsewhere on the top, and on the plate itself, are lit for certain.
    block = _box_corners([-2, -2, -1], [2, 2, 0])
    plate = _box_corners([-1.5, -0.5, 1.0], [-0.5, 0.5, 1.05])
    corners = np.concatenate([block, plate])
    group = np.r_[np.zeros(12, int), np.ones(12, int)]
    sun = np.array([[0.0, 0.0, 1.0]])
    axis_u, axis_v = np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])
    top_of_block = 2 * 2 + 1  # the +z face of the block: triangles 10 and 11 (axis 2, upper level)
    side_of_block = 2 * 0 + 1  # the +x face: triangles 2 and 3
    points = np.array([[-1.0, 0.0, 0.0], [1.5, 1.5, 0.0], [-1.0, 0.0, 1.05], [-1.0, 1.2, 0.0], [2.0, 1.5, -0.5]])
    prim = np.array([top_of_block, top_of_block, 23, top_of_block, 2 * side_of_block])
    rays = np.concatenate([points + [0, 0, 1e-4], np.broadcast_to(sun, points.shape)], axis=1).astype(np.float32)
    need = _direct_kernels.need_shadow_rays(corners, group, sun, axis_u, axis_v, 0.25, np.zeros(5, int), prim, rays)
    # Under the plate: yes; far corner: no; on the plate: no; 0.7 m beside the plate, two cells
    # off: no; on the block's side below its own top: no (a convex part shades none of itself).
    np.testing.assert_array_equal(need, [True, False, False, False, False])
    # Were the block not one convex group but triangles of their own, its top would count.
    group[:12] = np.arange(2, 14)
    need = _direct_kernels.need_shadow_rays(corners, group, sun, axis_u, axis_v, 0.25, np.zeros(5, int), prim, rays)
    np.testing.assert_array_equal(need, [True, False, False, False, True])
