"""The compiled shading (raycast.renderer._shading_kernels) against the BRDFs' numpy ``shade``.

The numpy methods are the reference (tested against analytic values and Blender Cycles
elsewhere); the compiled loops evaluate the same formulas point by point, so the two agree to
rounding: 1e-10 relative (a few float64 operations in another order give 1e-15; the bent
normal's quadratic amplifies that to 5e-12 near its threshold).
"""

import numpy as np
import pytest

from raycast.renderer.brdf import BRDF, GGX, Lambertian, Mix, Principled
from raycast.renderer.rays import orthonormal_basis, sun_fractions
from raycast.renderer.shading import disk_shading, reference_disk_shading, shaded_pairs

BRDFS = [
    Lambertian(0.4),
    GGX(0.7, 0.3),
    GGX(0.7, 0.05, masking="separable"),
    GGX(0.9, 0.4, distribution="MULTI_GGX"),
    Principled(0.3, roughness=0.5, ior=1.45),
    Principled(0.6, metallic=0.5, roughness=0.2, specular_ior_level=0.3),
    Principled(0.8, metallic=1.0, roughness=0.7, distribution="MULTI_GGX"),
    Principled(0.5, metallic=0.3, roughness=0.4, ior=1.6, distribution="MULTI_GGX"),
    Principled(0.5, roughness=0.4, specular_ior_level=0.0),  # F0 = 0: no dielectric lobe
    Mix(Principled(0.3, metallic=0.9, roughness=0.45), GGX(0.9, 0.08), 0.2),
    Mix(Lambertian(0.5), Principled(0.6, roughness=0.3, distribution="MULTI_GGX"), 0.7),
]


def _points(k, seed):
    """Shading normals near turned face normals, views on both sides of the shading normal's
    horizon, and Suns from high to a disk's width below the face's plane."""
    rng = np.random.default_rng(seed)

    def unit(a):
        return a / np.linalg.norm(a, axis=-1, keepdims=True)

    geo = unit(rng.normal(size=(k, 3)))
    normal = unit(geo + 0.4 * rng.normal(size=(k, 3)))
    wo = unit(rng.normal(size=(k, 3)))
    geo *= np.where(np.einsum("ij,ij->i", geo, wo) < 0.0, -1.0, 1.0)[:, None]
    sun = unit(rng.normal(size=(k, 3)))
    # A quarter of the Suns within a degree of the face's plane: the risen-Sun branch.
    near = rng.random(k) < 0.25
    along = unit(sun - np.einsum("ij,ij->i", sun, geo)[:, None] * geo)
    tilt = np.radians(rng.uniform(-0.5, 0.5, k))
    sun[near] = (np.cos(tilt)[:, None] * along + np.sin(tilt)[:, None] * geo)[near]
    # A quarter of the observers near the shading normal's horizon: the bent-normal branch.
    graze = rng.random(k) < 0.25
    wo_along = unit(wo - np.einsum("ij,ij->i", wo, normal)[:, None] * normal)
    wo[graze] = unit(wo_along + 0.02 * rng.normal(size=(k, 3)))[graze]
    geo *= np.where(np.einsum("ij,ij->i", geo, wo) < 0.0, -1.0, 1.0)[:, None]
    sun_u, sun_v = orthonormal_basis(sun)
    return normal, geo, wo, sun, sun_u, sun_v


@pytest.mark.parametrize("brdf", BRDFS, ids=repr)
@pytest.mark.parametrize("n_samples", [1, 7, 24])
@pytest.mark.parametrize("bend", [False, True])
def test_compiled_shading_equals_the_numpy_reference(brdf, n_samples, bend):
    points = _points(4000, seed=n_samples)
    compiled = disk_shading(brdf, n_samples, *points, bend)
    reference = reference_disk_shading(brdf, n_samples, *points, bend)
    assert np.count_nonzero(reference) > 1000  # the points light most of the lobes
    np.testing.assert_allclose(compiled, reference, rtol=1e-10, atol=1e-15)


@pytest.mark.parametrize("disk_share", [False, True])
def test_shaded_pairs_sums_each_pair_into_its_frame(disk_share):
    """Pairs read their frame's vectors and add into it; with ``disk_share`` each is also
    weighted by the share of the solar disk above its face (a quarter of the Suns of
    :func:`_points` are within a degree of the plane, where the share is between 0 and 1)."""
    brdf = Principled(0.4, metallic=0.2, roughness=0.3)
    normal, geo, wo, sun, sun_u, sun_v = _points(600, seed=3)
    # 600 pairs over 5 frames; each frame's vectors are its first pair's.
    frames = np.sort(np.random.default_rng(4).integers(0, 5, 600))
    first = np.searchsorted(frames, np.arange(5))
    per_frame = [a[first] for a in (wo, sun, sun_u, sun_v)]
    area = np.random.default_rng(5).random(600)
    rows = np.flatnonzero(np.arange(600) % 3 != 0)  # a subset, as one material's pairs
    total = np.zeros(5)
    shaded_pairs(brdf, 7, rows, frames, frames, area, normal, geo, *per_frame, True, total, disk_share=disk_share)
    each = reference_disk_shading(brdf, 7, normal, geo, *(a[frames] for a in per_frame), True)
    share = sun_fractions(np.einsum("ij,ij->i", geo, per_frame[1][frames]))
    if disk_share:
        assert np.any((share[rows] > 0.0) & (share[rows] < 1.0))
        each = each * share
    expected = np.bincount(frames[rows], weights=(area * each)[rows], minlength=5)
    assert np.all(expected > 0.0)
    np.testing.assert_allclose(total, expected, rtol=1e-12)


class _Halved(BRDF):
    """A BRDF that only numpy evaluates: half a Lambertian."""

    def shade(self, cos_i, cos_o, cos_io, spec_cos_i=None, spec_cos_o=None):
        return 0.5 * Lambertian(0.4).shade(cos_i, cos_o, cos_io)


def test_a_brdf_without_a_packed_form_is_shaded_by_its_own_numpy_method():
    points = _points(500, seed=6)
    np.testing.assert_allclose(
        disk_shading(_Halved(), 1, *points, False), 0.5 * disk_shading(Lambertian(0.4), 1, *points, False), rtol=1e-10
    )
