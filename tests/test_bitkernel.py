"""The fast path's compiled bit loops against the same sums written out in numpy."""

import numpy as np
from scipy import sparse

from raycast import _bitkernel


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
    area = sparse.csc_matrix((rng.random(int(keep.sum())).astype(np.float32) + 0.1, (rows[keep], cols[keep])),
                             shape=(n_groups, n_elements))
    area.sum_duplicates()
    return bits, sun_nodes, obs_nodes, sun, obs, normals, area


def _numpy_reference(bits, sun_nodes, obs_nodes, sun, obs, normals, area):
    sun_all, sun_any = bits[sun_nodes].all(axis=1), bits[sun_nodes].any(axis=1)   # (m, e)
    obs_all, obs_any = bits[obs_nodes].all(axis=1), bits[obs_nodes].any(axis=1)
    both = sun_all & obs_all
    out = (area @ both.T.astype(np.float64)).T
    facing = (sun @ normals.T > 0.0) & (obs @ normals.T > 0.0)
    mixed = sun_any & obs_any & ~both & facing
    frames, elements = np.nonzero(mixed)
    need = (~sun_all[frames, elements]).astype(np.uint8) | ((~obs_all[frames, elements]).astype(np.uint8) << 1)
    return out, frames, elements, need


def _run(case):
    bits, sun_nodes, obs_nodes, sun, obs, normals, area = case
    return _bitkernel.agreed_weight(_bitkernel.pack_words(bits), sun_nodes, obs_nodes, sun, obs, normals,
                                    area.indptr, area.indices, area.data, area.shape[0])


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


def test_mixed_pairs_beyond_the_first_guess_are_all_returned():
    # Dense half-set bits: far more mixed pairs than the first guess (4096) holds.
    case = _case(2, n_elements=1000, n_frames=60, density=0.5)
    _, frames, elements, _ = _run(case)
    _, ref_frames, _, _ = _numpy_reference(*case)
    assert len(ref_frames) > 4096
    assert len(frames) == len(ref_frames)


def test_pairs_add_their_value_times_area_to_each_group():
    case = _case(3, n_elements=70, n_frames=5)
    area = case[-1]
    out = np.zeros((5, area.shape[0]), dtype=np.float32)
    frames, elements = np.array([0, 0, 4]), np.array([3, 69, 3])
    values = np.array([0.5, 1.0, 0.25], dtype=np.float32)
    _bitkernel.add_pairs(out, frames, elements, values, area.indptr, area.indices, area.data)
    dense = area.toarray()
    expected = np.zeros_like(out)
    for f, e, v in zip(frames, elements, values):
        expected[f] += v * dense[:, e]
    np.testing.assert_allclose(out, expected, rtol=1e-6)
