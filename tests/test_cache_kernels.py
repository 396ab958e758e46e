"""The fast path's compiled bit loops against the same sums written out in numpy."""

import numpy as np
from scipy import sparse

from raycast.renderer import _cache_kernels
from raycast.renderer.rays import SUN_RADIUS_SINE, sun_fractions


def _case(seed, n_elements, n_frames, n_directions=40, n_groups=7, density=0.7):
    rng = np.random.default_rng(seed)
    bits = rng.random((n_directions, n_elements)) < density
    sun_nodes = rng.integers(0, n_directions, (n_frames, 4))
    obs_nodes = rng.integers(0, n_directions, (n_frames, 4))
    sun = rng.normal(size=(n_frames, 3)).astype(np.float32)
    obs = rng.normal(size=(n_frames, 3)).astype(np.float32)
    normals = rng.normal(size=(n_elements, 3)).astype(np.float32)
    # Each element has pieces in one or two groups.
    rows = rng.integers(0, n_groups, 2 * n_elements)
    cols = np.repeat(np.arange(n_elements), 2)
    keep = rng.random(2 * n_elements) < 0.75
    keep[::2] = True
    area = sparse.csc_matrix(
        (rng.random(int(keep.sum())).astype(np.float32) + 0.1, (rows[keep], cols[keep])), shape=(n_groups, n_elements)
    )
    area.sum_duplicates()
    return bits, sun_nodes, obs_nodes, sun, obs, normals, area


def _numpy_reference(bits, sun_nodes, obs_nodes, sun, obs, normals, area):
    sun_all, sun_any = bits[sun_nodes].all(axis=1), bits[sun_nodes].any(axis=1)  # (m, e)
    obs_all, obs_any = bits[obs_nodes].all(axis=1), bits[obs_nodes].any(axis=1)
    both = sun_all & obs_all
    out = (area @ both.T.astype(np.float64)).T
    # Facing the Sun while any of its disk is above the element's plane, and facing the observer.
    facing = (sun @ normals.T > -SUN_RADIUS_SINE) & (obs @ normals.T > 0.0)
    mixed = sun_any & obs_any & ~both & facing
    frames, elements = np.nonzero(mixed)
    need = (~sun_all[frames, elements]).astype(np.uint8) | ((~obs_all[frames, elements]).astype(np.uint8) << 1)
    return out, frames, elements, need


def _run(case):
    """(m, g) agreed area and the mixed pairs, from the compiled loop."""
    bits, sun_nodes, obs_nodes, sun, obs, normals, area = case
    out = np.zeros((len(sun), area.shape[0]), dtype=np.float32)
    pairs = _cache_kernels.agreed_weight(
        out,
        _cache_kernels.pack_words(bits),
        sun_nodes,
        obs_nodes,
        sun,
        obs,
        normals,
        area.indptr,
        area.indices,
        area.data,
    )
    return (out, *pairs)


def test_agreed_area_and_mixed_pairs_match_numpy():
    # 130 elements: three words, the last one partly filled (its padding bits must stay clear).
    case = _case(1, n_elements=130, n_frames=25)
    out, frames, elements, need = _run(case)
    ref_out, ref_frames, ref_elements, ref_need = _numpy_reference(*case)
    np.testing.assert_allclose(out, ref_out, rtol=1e-5)
    assert out.sum() > 0.0
    order = np.lexsort((elements, frames))
    np.testing.assert_array_equal(frames[order], ref_frames)
    np.testing.assert_array_equal(elements[order], ref_elements)
    np.testing.assert_array_equal(need[order], ref_need)
    assert set(np.unique(need)) == {1, 2, 3}


def test_mixed_pairs_beyond_the_first_guess_are_all_returned_and_nothing_added_twice():
    # Dense half-set bits: far more mixed pairs than the first guess (4096) holds.
    case = _case(2, n_elements=1000, n_frames=60, density=0.5)
    out, frames, elements, _ = _run(case)
    ref_out, ref_frames, ref_elements, _ = _numpy_reference(*case)
    assert len(ref_frames) > 4096
    order = np.lexsort((elements, frames))
    np.testing.assert_array_equal(frames[order], ref_frames)
    np.testing.assert_array_equal(elements[order], ref_elements)
    np.testing.assert_allclose(out, ref_out, rtol=1e-5)


def test_pairs_add_their_value_times_area_to_each_group():
    case = _case(3, n_elements=70, n_frames=5)
    area = case[-1]
    out = np.zeros((5, area.shape[0]), dtype=np.float32)
    frames, elements = np.array([0, 0, 4]), np.array([3, 69, 3])
    values = np.array([0.5, 1.0, 0.25], dtype=np.float32)
    _cache_kernels.add_pairs(out, frames, elements, values, area.indptr, area.indices, area.data)
    dense = area.toarray()
    expected = np.zeros_like(out)
    for f, e, v in zip(frames, elements, values):
        expected[f] += v * dense[:, e]
    np.testing.assert_allclose(out, expected, rtol=1e-6)


def test_rays_and_open_fractions_follow_the_pairs_needs():
    origins = np.arange(4 * 2 * 3, dtype=np.float32).reshape(4, 2, 3)  # 4 elements, 2 points each
    sun = np.array([[1, 0, 0], [0, 1, 0]], dtype=np.float32)
    obs = np.array([[0, 0, 1], [0, -1, 0]], dtype=np.float32)
    need = np.array([1, 2, 3], dtype=np.uint8)
    frames, elements = np.array([0, 1, 1]), np.array([3, 0, 2])
    # Element normals well above both Suns' planes: the rays go to the Sun itself.
    normals = np.tile(np.array([0.6, 0.8, 0.0], dtype=np.float32), (4, 1))
    rays = _cache_kernels.pair_rays(need, frames, elements, origins, normals, sun, obs)
    # Toward the Sun: pairs 0 and 2; then toward the observer: pairs 1 and 2; two points each.
    expected = [(3, sun[0]), (3, sun[0]), (2, sun[1]), (2, sun[1]), (0, obs[1]), (0, obs[1]), (2, obs[1]), (2, obs[1])]
    point = [0, 1] * 4
    for row, ((e, d), j) in enumerate(zip(expected, point)):
        np.testing.assert_array_equal(rays[row, :3], origins[e, j])
        np.testing.assert_array_equal(rays[row, 3:], d)
    occluded = np.array([True, False, False, False, False, True, True, True])
    np.testing.assert_allclose(_cache_kernels.open_fraction(need, occluded, 2), [0.5, 0.5, 0.0])


def test_class_sums_gate_and_weight_by_the_geometric_normal():
    rng = np.random.default_rng(4)
    n_groups, m, n_classes = 30, 12, 5
    weight = rng.normal(size=(n_groups, m)).astype(np.float32)  # some negative: counted as zero
    unit = lambda a: (a / np.linalg.norm(a, axis=1, keepdims=True)).astype(np.float32)
    normal_geo, normal_shade = unit(rng.normal(size=(n_groups, 3))), unit(rng.normal(size=(n_groups, 3)))
    group_class = rng.integers(0, n_classes, n_groups).astype(np.int32)
    sun, obs = unit(rng.normal(size=(m, 3))), unit(rng.normal(size=(m, 3)))
    area, normal, geo = _cache_kernels.class_sums(
        np.ascontiguousarray(weight.T), normal_geo, normal_shade, group_class, sun, obs, n_classes
    )
    cos_o, cos_s = normal_geo @ obs.T, normal_geo @ sun.T
    gated = np.maximum(weight, 0.0) * np.where(cos_o > 0, cos_o, 0.0) * sun_fractions(cos_s)
    one_hot = np.eye(n_classes)[group_class].T  # (c, g)
    np.testing.assert_allclose(area, (one_hot @ gated).T, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(normal, np.einsum("cg,gm,gk->mck", one_hot, gated, normal_shade), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(geo, np.einsum("cg,gm,gk->mck", one_hot, gated, normal_geo), rtol=1e-5, atol=1e-6)
    assert (area > 0).sum() > 5
