"""The fast path's compiled loops against the same sums written out in numpy."""

import numpy as np
import pytest
from scipy import sparse

from raycast.renderer import _cache_kernels
from raycast.renderer.cache import cube_grid_directions, cube_grid_weights
from raycast.renderer.rays import SUN_RADIUS_SINE, sun_fractions


def _case(seed, n_elements, n_frames, n_directions=40, n_groups=7, density=0.7, straddling=None):
    """Random bits, nodes, directions and normals; elements with pieces in one or two groups:
    random ones, or (a ``straddling`` fraction given) runs of elements in group order, as the
    cache orders them, that fraction of them with a second piece in the next group."""
    rng = np.random.default_rng(seed)
    bits = rng.random((n_directions, n_elements)) < density
    sun_nodes = rng.integers(0, n_directions, (n_frames, 4))
    obs_nodes = rng.integers(0, n_directions, (n_frames, 4))
    sun = rng.normal(size=(n_frames, 3)).astype(np.float32)
    obs = rng.normal(size=(n_frames, 3)).astype(np.float32)
    normals = rng.normal(size=(n_elements, 3)).astype(np.float32)
    rows = rng.integers(0, n_groups, 2 * n_elements)
    cols = np.repeat(np.arange(n_elements), 2)
    keep = rng.random(2 * n_elements) < 0.75
    if straddling is not None:
        rows[::2] = np.sort(rng.integers(0, n_groups, n_elements))
        rows[1::2] = np.minimum(rows[::2] + 1, n_groups - 1)
        keep[1::2] = rng.random(n_elements) < straddling
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


def _pairs(case):
    bits, sun_nodes, obs_nodes, sun, obs, normals, _ = case
    return _cache_kernels.mixed_pairs(_cache_kernels.pack_words(bits), sun_nodes, obs_nodes, sun, obs, normals)


def test_mixed_pairs_match_numpy():
    # 130 elements: three words, the last one partly filled (its padding bits must stay clear).
    case = _case(1, n_elements=130, n_frames=25)
    frames, elements, need = _pairs(case)
    _, ref_frames, ref_elements, ref_need = _numpy_reference(*case)
    assert np.all(np.diff(frames) >= 0)  # in frame order, as lit_classes reads them
    order = np.lexsort((elements, frames))
    np.testing.assert_array_equal(frames[order], ref_frames)
    np.testing.assert_array_equal(elements[order], ref_elements)
    np.testing.assert_array_equal(need[order], ref_need)
    assert set(np.unique(need)) == {1, 2, 3}


def test_mixed_pairs_beyond_the_first_guess_are_all_returned():
    # Dense half-set bits: far more mixed pairs than the first guess (4096) holds.
    case = _case(2, n_elements=1000, n_frames=60, density=0.5)
    frames, elements, _ = _pairs(case)
    _, ref_frames, ref_elements, _ = _numpy_reference(*case)
    assert len(ref_frames) > 4096
    order = np.lexsort((elements, frames))
    np.testing.assert_array_equal(frames[order], ref_frames)
    np.testing.assert_array_equal(elements[order], ref_elements)


def _unit(a):
    return (a / np.linalg.norm(a, axis=1, keepdims=True)).astype(np.float32)


def test_byte_areas_sum_the_set_elements_of_bytes_in_one_group():
    case = _case(3, n_elements=300, n_frames=1, straddling=0.1)
    area = case[-1]
    n_words = -(-300 // 64)
    byte_slot, byte_group, byte_area = _cache_kernels.byte_areas(area.indptr, area.indices, area.data, n_words)
    assert byte_slot.shape == (8 * n_words,) and len(byte_area) == np.count_nonzero(byte_slot >= 0)
    element_area = np.r_[np.asarray(area.sum(axis=0)).ravel(), np.zeros(8 * 8 * n_words - 300)]
    groups = [set(area.indices[area.indptr[e] : area.indptr[e + 1]]) if e < 300 else set() for e in range(64 * n_words)]
    values = np.arange(256)
    bits = (values[:, None] >> np.arange(8)) & 1  # (256, 8)
    for b in range(8 * n_words):
        in_byte = set().union(*groups[8 * b : 8 * b + 8])
        assert (byte_slot[b] >= 0) == (len(in_byte) == 1), b
        if byte_slot[b] >= 0:
            assert byte_group[b] == in_byte.pop()
            np.testing.assert_allclose(byte_area[byte_slot[b]], bits @ element_area[8 * b : 8 * b + 8], rtol=1e-6)
    # Both kinds occur: runs of one group, and bytes where a group ends or an element straddles two.
    assert 0 < np.count_nonzero(byte_slot >= 0) < 8 * n_words - 1


@pytest.mark.parametrize(
    "n_extra, n_groups, n_classes, straddling, coarse",
    [
        (0, 7, 4, None, False),
        (3, 7, 4, None, False),
        (3, 150, 20, None, False),
        (0, 7, 4, 0.1, False),
        (1, 2, 2, 0.0, False),
        (3, 150, 20, None, True),
    ],
)
def test_lit_classes_sum_gated_group_areas_into_sorted_classes(n_extra, n_groups, n_classes, straddling, coarse):
    """Agreed bits, the mixed pairs' open fractions, exposed areas and factorised weights, gated
    by each group's geometric normal and summed into its class, against the same in numpy.
    150 groups span three words of the kernel's bitmap of groups with area. With elements in
    long runs of one group, some words are read a byte at a time from :func:`byte_areas`' tables.
    With coarse levels, a class whose nominal normal is far from the frame's half vector is
    summed into its coarse class instead (two levels: pairs, then fours of classes)."""
    case = _case(5, n_elements=130, n_frames=25, n_groups=n_groups, straddling=straddling)
    bits, sun_nodes, obs_nodes, _, _, normals, area = case
    rng = np.random.default_rng(6)
    m = len(sun_nodes)
    sun, obs = _unit(rng.normal(size=(m, 3))), _unit(rng.normal(size=(m, 3)))
    # Normals in the xy plane and every third Sun close to it: groups lit by part of the disk.
    sun[::3] = _unit(np.c_[2e-3 * rng.normal(size=(len(sun[::3]), 2)), np.ones(len(sun[::3]))])
    normal_geo = _unit(np.c_[rng.normal(size=(n_groups, 2)), np.zeros(n_groups)])
    normal_shade = _unit(normal_geo + 0.3 * rng.normal(size=(n_groups, 3)))
    group_class = np.sort(rng.integers(0, n_classes, n_groups)).astype(np.int32)
    area_exposed = np.where(rng.random(n_groups) < 0.5, rng.random(n_groups), 0.0).astype(np.float32)
    extra_groups = rng.choice(n_groups, n_extra, replace=False).astype(np.int64)
    extra = rng.random((m, n_extra)).astype(np.float32)
    frames, elements, need = _cache_kernels.mixed_pairs(
        _cache_kernels.pack_words(bits), sun_nodes, obs_nodes, sun, obs, normals
    )
    open_ = rng.choice([0.0, 0.5, 1.0], len(frames)).astype(np.float32)
    tables = _cache_kernels.byte_areas(area.indptr, area.indices, area.data, -(-len(normals) // 64))
    by_bytes = (tables[0].reshape(-1, 8) >= 0).all(axis=1)[:2]  # (the last word is part padding)
    assert by_bytes.any() == (straddling == 0.0)
    class_normal = _unit(rng.normal(size=(n_classes, 3))).astype(np.float32)
    classes = np.arange(n_classes)
    if coarse:
        first_four = n_classes + -(-n_classes // 2)
        class_target = np.stack([n_classes + classes // 2, first_four + classes // 4]).astype(np.int32)
        n_targets = first_four + -(-n_classes // 4)
        coarse_cos = np.array([[0.5, -0.2]])
    else:
        class_target, n_targets, coarse_cos = np.zeros((0, n_classes), np.int32), n_classes, np.zeros((1, 0))
    arguments = (
        _cache_kernels.pack_words(bits),
        sun_nodes,
        obs_nodes,
        area.indptr,
        area.indices,
        area.data,
        *tables,
        frames,
        elements,
        open_,
        area_exposed,
        extra,
        extra_groups,
        normal_geo,
        normal_shade,
        group_class,
        sun,
        obs,
        n_classes,
        class_normal,
        np.zeros(n_targets, dtype=np.int32),
        coarse_cos,
        class_target,
        n_targets,
    )
    out = _cache_kernels.lit_classes(*arguments)
    # Into buffers that must grow, then into the same buffers again: the same rows.
    rows = _cache_kernels.RowBuffers(4)
    for _ in range(2):
        for got, expected in zip(_cache_kernels.lit_classes(*arguments, rows=rows), out):
            np.testing.assert_array_equal(got, expected)
    assert len(rows.arrays[0]) >= len(out[0]) > 4
    both = bits[sun_nodes].all(axis=1) & bits[obs_nodes].all(axis=1)  # (m, e)
    weight = (area @ both.T.astype(np.float64)).T + area_exposed
    pair_value = np.zeros(both.shape)
    np.add.at(pair_value, (frames, elements), open_)
    weight += (area @ pair_value.T).T
    weight[:, extra_groups] += extra
    cos_o, cos_s = obs @ normal_geo.T, sun @ normal_geo.T
    gated = weight * np.where(cos_o > 0, cos_o, 0.0) * sun_fractions(cos_s)  # (m, g)
    # Each frame's class -> its class or coarse class (levels by the cosine to the half vector).
    cos_h = _unit(sun + obs) @ class_normal.T  # (m, c)
    level = sum((cos_h < coarse_cos[0, k]).astype(int) for k in range(coarse_cos.shape[1])) + np.zeros(cos_h.shape, int)
    target = np.where(level == 0, classes, np.r_[[classes], class_target][level, classes])
    assert not coarse or 0 < np.count_nonzero(level) < level.size
    one_hot = np.eye(n_targets)[target[:, group_class]]  # (m, g, t)
    ref_area = np.einsum("mg,mgt->mt", gated, one_hot)
    lit = np.nonzero(ref_area > 0)
    unit = lambda a: a / np.linalg.norm(a, axis=-1, keepdims=True)
    ref_normal = unit(np.einsum("mg,mgt,gk->mtk", gated, one_hot, normal_shade))[lit]
    ref_geo = unit(np.einsum("mg,mgt,gk->mtk", gated, one_hot, normal_geo))[lit]
    got_frames, got_classes, got_area, got_normal, got_geo = out
    # Rows come in frame order, a frame's own classes before its coarse ones in the order first met.
    order = np.lexsort((got_classes, got_frames))
    got_frames, got_classes, got_area, got_normal, got_geo = (a[order] for a in out)
    np.testing.assert_array_equal(got_frames, lit[0])
    np.testing.assert_array_equal(got_classes, lit[1])
    assert not coarse or np.any(got_classes >= n_classes)
    # float32 inputs summed in float64: agreement to float32 rounding.
    np.testing.assert_allclose(got_area, ref_area[lit], rtol=1e-5)
    np.testing.assert_allclose(got_normal, ref_normal, atol=1e-5)
    np.testing.assert_allclose(got_geo, ref_geo, atol=1e-5)
    assert 0 < len(got_frames) < m * n_classes
    np.testing.assert_array_equal(out[0], np.sort(out[0]))
    assert np.any((sun_fractions(cos_s) > 0) & (sun_fractions(cos_s) < 1))


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
    blend = np.full(3, -1.0, dtype=np.float32)
    np.testing.assert_allclose(_cache_kernels.open_fraction(need, occluded, 2, blend), [0.5, 0.5, 0.0])
    # A pair left to its bits' interpolation (far_pairs: need 0, no rays) takes its blend.
    need[1], blend[1] = 0, 0.25
    occluded = np.delete(occluded, [4, 5])  # pair 1's observer rays are not cast
    np.testing.assert_allclose(_cache_kernels.open_fraction(need, occluded, 2, blend), [0.5, 0.25, 0.0])


def test_nearest_lobes_and_far_pairs_against_numpy():
    """The nearest lobed class to each half vector (facing the Sun and the observer), and the
    pairs whose element lies further than its reach beyond it: no ray, its bits' bilinear
    interpolation instead."""
    rng = np.random.default_rng(21)
    m, n_classes, n_elements = 30, 200, 100
    sun, obs = _unit(rng.normal(size=(m, 3))), _unit(rng.normal(size=(m, 3)))
    class_normal = _unit(rng.normal(size=(n_classes, 3))).astype(np.float32)
    lobed = rng.random(n_classes) < 0.7
    nearest = _cache_kernels.nearest_lobes(class_normal, lobed, sun, obs)
    half = _unit(sun + obs)
    facing = (sun @ class_normal.T > 0) & (obs @ class_normal.T > 0) & lobed
    cos_h = np.where(facing, half @ class_normal.T, -1.0)
    np.testing.assert_allclose(nearest, np.arccos(cos_h.max(axis=1)), atol=1e-5)
    bits = rng.random((6 * 5 * 5, n_elements)) < 0.6
    directions = cube_grid_directions(4)
    assert len(directions) == len(bits)
    (sun_nodes, sun_w), (obs_nodes, obs_w) = (cube_grid_weights(d, 4) for d in (sun, obs))
    sun_nodes, obs_nodes = sun_nodes.astype(np.int64), obs_nodes.astype(np.int64)
    frames = np.repeat(np.arange(m), 20)
    elements = rng.integers(0, n_elements, len(frames))
    need = rng.integers(1, 4, len(frames)).astype(np.uint8)
    element_normal = _unit(rng.normal(size=(n_elements, 3))).astype(np.float32)
    reach = np.where(rng.random(n_elements) < 0.8, rng.uniform(0.0, 1.0, n_elements), -1.0)
    far = np.column_stack([reach, np.cos(reach), np.sin(reach)]).astype(np.float32)
    kept, blend = _cache_kernels.far_pairs(
        need,
        frames,
        elements,
        _cache_kernels.pack_words(bits),
        sun_nodes,
        sun_w,
        obs_nodes,
        obs_w,
        element_normal,
        far,
        sun,
        obs,
        nearest,
    )
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", element_normal[elements], half[frames]), -1, 1))
    skipped = (reach[elements] >= 0) & (angle > reach[elements] + nearest[frames] + 1e-4)
    kept_too = (reach[elements] < 0) | (angle < reach[elements] + nearest[frames] - 1e-4)
    assert 0.2 < skipped.mean() < 0.8
    assert np.all(blend[skipped] >= 0) and np.all(kept[skipped] == 0)
    np.testing.assert_array_equal(blend[kept_too], -1.0)
    np.testing.assert_array_equal(kept[kept_too], need[kept_too])
    toward_sun = (sun_w[frames] * bits[sun_nodes[frames], elements[:, None]]).sum(axis=1)
    toward_obs = (obs_w[frames] * bits[obs_nodes[frames], elements[:, None]]).sum(axis=1)
    np.testing.assert_allclose(blend[skipped], (toward_sun * toward_obs)[skipped], atol=1e-6)


def test_lowest_bit_is_the_index_of_the_lowest_set_bit():
    from raycast.renderer._cache_kernels import _lowest_bit

    rng = np.random.default_rng(11)
    for position in range(64):
        above = rng.integers(0, 2**63, dtype=np.uint64) << np.uint64(position)  # bits at and above it
        word = (above | np.uint64(1 << position)) & ~np.uint64((1 << position) - 1)
        assert _lowest_bit(np.uint64(1 << position)) == position
        assert _lowest_bit(word) == position


def test_cube_cell_is_the_first_node_cube_grid_weights_gives():
    from raycast.renderer.cache import cube_grid_weights

    rng = np.random.default_rng(4)
    directions = rng.normal(size=(2000, 3))
    directions[:40] = np.eye(3)[rng.integers(0, 3, 40)] * rng.choice([-1.0, 1.0], (40, 1))  # face centres
    for n in (4, 32, 64):
        index, _ = cube_grid_weights(directions / np.linalg.norm(directions, axis=1, keepdims=True), n)
        cells = [_cache_kernels._cube_cell(x, y, z, n) for x, y, z in directions]
        np.testing.assert_array_equal(cells, index[:, 0])


def test_merged_by_frame_is_the_stable_sort_of_both():
    # Each frame's pairs of the first triple, then those of the second: what a stable argsort
    # of the two joined gives, including frames only one of them has and empty triples.
    rng = np.random.default_rng(5)
    first = (np.sort(rng.integers(0, 40, 300)), rng.integers(0, 10**6, 300), rng.integers(1, 4, 300).astype(np.uint8))
    second = (np.sort(rng.integers(10, 60, 200)), rng.integers(0, 10**6, 200), rng.integers(1, 4, 200).astype(np.uint8))
    empty = tuple(a[:0] for a in first)
    for a, b in ((first, second), (second, first), (first, empty), (empty, second)):
        order = np.argsort(np.r_[a[0], b[0]], kind="stable")
        expected = [np.r_[x, y][order] for x, y in zip(a, b)]
        for got, want in zip(_cache_kernels.merged_by_frame(a, b), expected):
            np.testing.assert_array_equal(got, want)
            assert got.dtype == want.dtype
