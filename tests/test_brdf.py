"""BRDFs: closed forms, reciprocity, energy conservation (white furnace), validation."""

import math

import numpy as np
import pytest

from raycast.renderer import ggx_tables
from raycast.renderer.brdf import (
    GGX,
    Lambertian,
    Mix,
    Principled,
    directional_albedo,
    fresnel_dielectric,
    valid_reflection_normal,
)
from tests.render_support import unit

RNG = np.random.default_rng(20260730)


def random_hemisphere(m):
    v = RNG.normal(size=(m, 3))
    v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


RECIPROCAL = [
    Lambertian(0.7),
    GGX(0.6, 0.3),
    GGX(0.6, 0.3, masking="separable"),
    GGX(1.0, 0.8),
    Principled(base_color=0.0, roughness=0.5),
    Principled(base_color=0.8, metallic=1.0, roughness=0.4),
    Mix(Lambertian(0.3), GGX(0.9, 0.1), 0.25),
]


@pytest.mark.parametrize("brdf", RECIPROCAL, ids=repr)
def test_reciprocity(brdf):
    wi, wo = random_hemisphere(500), random_hemisphere(500)
    n = np.tile([0.0, 0.0, 1.0], (500, 1))
    # Exchanging light and view must give the same value to rounding (1e-12 relative).
    np.testing.assert_allclose(brdf(wi, wo, n), brdf(wo, wi, n), rtol=1e-12, atol=0)


def test_principled_is_not_reciprocal_like_cycles():
    """The diffuse layer is attenuated by the specular albedo seen from the observer only."""
    brdf = Principled(base_color=0.8, roughness=0.5)
    n = np.array([[0.0, 0.0, 1.0]])
    wi = np.array([[math.sin(1.3), 0.0, math.cos(1.3)]])
    wo = np.array([[0.0, 0.0, 1.0]])
    assert abs(brdf(wi, wo, n)[0] / brdf(wo, wi, n)[0] - 1.0) > 1e-3


@pytest.mark.parametrize(
    "brdf",
    [
        Lambertian(1.0),
        GGX(1.0, 0.3),
        GGX(1.0, 0.6),
        GGX(1.0, 1.0),
        Principled(1.0, roughness=0.5),
        Principled(1.0, metallic=1.0, roughness=0.5),
        Mix(Lambertian(1.0), GGX(1.0, 0.3), 0.4),
    ],
    ids=repr,
)
@pytest.mark.parametrize("cos_o", [1.0, 0.7, 0.3])
def test_white_furnace(brdf, cos_o):
    # A white surface reflects at most what it receives (the quadrature is good to ~2e-3),
    albedo = directional_albedo(brdf, cos_o, n_theta=768, n_phi=384)
    assert albedo <= 1.0 + 3e-3
    # and a lobe that lost its normalisation would fall far below (single-scatter GGX keeps > 0.3).
    assert albedo > 0.3


def test_lambertian_albedo_is_exact():
    # Lambert integrates to its albedo exactly; the quadrature of a constant is exact to rounding.
    assert directional_albedo(Lambertian(0.37), 0.6) == pytest.approx(0.37, rel=1e-12)


def test_principled_white_base_conserves_energy():
    # Diffuse weight (1 - E_spec) plus the specular albedo E_spec is 1 for a white base.
    albedo = directional_albedo(Principled(1.0, roughness=0.5, ior=1.45), 0.8, n_theta=768, n_phi=384)
    assert albedo == pytest.approx(1.0, abs=5e-3)


@pytest.mark.parametrize("masking", ["height-correlated", "separable"])
def test_ggx_closed_form_at_mirror_geometry(masking):
    # Sun and observer at 30 deg on opposite sides: h = n, D = 1 / (pi alpha^2).
    color, roughness = 0.42, 0.3
    alpha = roughness**2
    t = math.radians(30.0)
    wi = np.array([[math.sin(t), 0.0, math.cos(t)]])
    wo = np.array([[-math.sin(t), 0.0, math.cos(t)]])
    lam = 0.5 * (math.sqrt(1.0 + alpha**2 * math.tan(t) ** 2) - 1.0)
    g = 1.0 / (1.0 + 2.0 * lam) if masking == "height-correlated" else 1.0 / (1.0 + lam) ** 2
    expected = color * (1.0 / (math.pi * alpha**2)) * g / (4.0 * math.cos(t) ** 2)
    value = GGX(color, roughness, masking=masking)(wi, wo, np.array([[0.0, 0.0, 1.0]]))[0]
    assert value == pytest.approx(expected, rel=1e-12)


def test_ggx_masking_forms_agree_away_from_grazing():
    # Difference of the two Smith forms is Lambda_i Lambda_o / ...: < 0.1% below 60 deg.
    sun = np.array([[math.sin(1.0), 0.0, math.cos(1.0)]])
    obs = np.array([[-math.sin(0.8), 0.1, math.cos(0.8)]])
    obs /= np.linalg.norm(obs)
    n = np.array([[0.0, 0.0, 1.0]])
    a = GGX(0.5, 0.3)(sun, obs, n)[0]
    b = GGX(0.5, 0.3, masking="separable")(sun, obs, n)[0]
    assert a / b - 1.0 == pytest.approx(0.0, abs=1e-3)


def test_below_horizon_is_zero():
    n = np.array([[0.0, 0.0, 1.0]] * 2)
    wi = np.array([[0.0, 0.6, -0.8], [0.0, 0.6, 0.8]])
    wo = np.array([[0.0, -0.6, 0.8], [0.0, -0.6, -0.8]])
    for brdf in (Lambertian(0.5), GGX(0.5, 0.3), Principled(0.5)):
        assert np.all(brdf(wi, wo, n) == 0.0)


def test_fresnel_and_f0():
    # ((n - 1) / (n + 1))^2 = 0.04 at n = 1.5; grazing incidence reflects everything.
    assert fresnel_dielectric(np.array([1.0]), 1.5)[0] == pytest.approx(0.04, rel=1e-12)
    assert fresnel_dielectric(np.array([1e-9]), 1.5)[0] == pytest.approx(1.0, abs=1e-6)
    assert Principled(0.5, ior=1.5).f0 == pytest.approx(0.04)
    assert Principled(0.5, ior=1.5, specular_ior_level=0.25).f0 == pytest.approx(0.02)


def test_principled_diffuse_weight_is_cycles_layering_weight():
    # Cycles weighs the base by 1 - (F0 + (1 - F0) s(mu)), s the VNDF mean of the remapped
    # Fresnel curve (raycast.renderer.ggx_tables), read at the view cosine. At normal view the
    # rough lobe takes about F0 (0.034 at IOR 1.45); grazing views see much more specular.
    brdf = Principled(0.5, roughness=0.5, ior=1.45)
    weights = brdf.diffuse_weight(np.array([1.0, 0.5, 0.1]))
    assert 0.95 < weights[0] < 0.97
    assert weights[0] > weights[1] > weights[2] > 0.7
    f0 = brdf.f0
    s = ggx_tables.dielectric_fresnel_mean(0.5, np.array([0.18]), 1.45)
    assert brdf.diffuse_weight(np.array([0.18]))[0] == pytest.approx(1.0 - (f0 + (1.0 - f0) * s[0]), rel=1e-12)
    # Multiple scattering darkens the estimate by E + Fms (1 - E) < 1: a little more base.
    multi = Principled(0.5, roughness=0.5, ior=1.45, distribution="MULTI_GGX")
    assert (multi.diffuse_weight(np.array([1.0, 0.5, 0.1])) > weights).all()


def test_specular_ior_level_takes_the_ior_of_the_scaled_f0():
    # Cycles: F0 *= 2 level, then eta = ior_from_F0(F0); the lobe follows that eta's Fresnel curve.
    brdf = Principled(0.5, ior=1.5, specular_ior_level=0.25)
    assert brdf.f0 == pytest.approx(0.02)
    assert ((brdf.eta - 1.0) / (brdf.eta + 1.0)) ** 2 == pytest.approx(0.02, rel=1e-12)
    c = np.array([0.9, 0.5, 0.1])
    np.testing.assert_allclose(brdf._fresnel(c), fresnel_dielectric(c, brdf.eta), rtol=1e-12)


def test_ggx_tables_reproduce_cycles_integrals():
    # Node values Cycles' precomputation gives (Monte Carlo, 2**23-2**26 samples each; read from
    # its baked tables for docs/cycles.md): E(16/31, 1) 0.903873, E(1, 1) 0.306853,
    # E(16/31, 16/31) 0.847421, E_avg(16/31) 0.870874, E_avg(1) 0.409137,
    # s(8/15, 8/15, z 7/15) 0.034703. Our quadrature of the same integrals agrees to 1e-4
    # (Cycles' own sampling noise is of that order).
    assert ggx_tables.ggx_albedo(16 / 31, 1.0) == pytest.approx(0.903873, abs=1e-4)
    assert ggx_tables.ggx_albedo(1.0, 1.0) == pytest.approx(0.306853, abs=1e-4)
    assert ggx_tables.ggx_albedo(16 / 31, 16 / 31) == pytest.approx(0.847421, abs=1e-4)
    assert ggx_tables.ggx_average_albedo(16 / 31) == pytest.approx(0.870874, abs=1e-4)
    assert ggx_tables.ggx_average_albedo(1.0) == pytest.approx(0.409137, abs=1e-4)
    eta = (1 + (7 / 15) ** 2) / (1 - (7 / 15) ** 2)
    assert ggx_tables.dielectric_fresnel_mean(8 / 15, 8 / 15, eta) == pytest.approx(0.034703, abs=1e-4)


def test_ggx_table_nodes_are_kept_on_disk_and_read_back(tmp_path, monkeypatch):
    monkeypatch.setenv("RSODB_CACHE_DIR", str(tmp_path))
    stored = ggx_tables._s_column.__wrapped__  # the disk layer, without this process's memory
    quadrature = stored.__wrapped__
    first = stored(3, 4)
    files = list(tmp_path.glob("ggx_tables/*/s_column-3-4.npy"))
    assert len(files) == 1
    # Read back bit for bit, and equal to the quadrature itself.
    np.testing.assert_array_equal(stored(3, 4), first)
    np.testing.assert_array_equal(first, quadrature(3, 4))
    # The directory is named by the module source's hash: a changed quadrature computes anew.
    assert files[0].parent.name == ggx_tables._table_dir().name
    # A damaged node file is computed again and replaced, never read as numbers.
    files[0].write_bytes(b"\x93NUMPY garbage")
    np.testing.assert_array_equal(stored(3, 4), first)
    np.testing.assert_array_equal(np.load(files[0]), first)


def test_mixed_table_nodes_interpolate_as_the_separate_nodes():
    """Mixing the roughness (and z) nodes once per material equals interpolating each node's
    column over mu and mixing the results (interpolation is linear in the node values)."""
    mu = np.linspace(-0.1, 1.1, 57)
    for roughness in (0.3, 0.5, 16 / 31):
        low, high, t = ggx_tables._position(roughness, 32)
        separate = (1 - t) * ggx_tables._interpolate_mu(ggx_tables._e_column(int(low)), mu) + t * (
            ggx_tables._interpolate_mu(ggx_tables._e_column(int(high)), mu)
        )
        np.testing.assert_allclose(ggx_tables.ggx_albedo(roughness, mu), separate, rtol=1e-12, atol=1e-15)


def test_valid_reflection_normal_lifts_the_mirror_direction_to_the_threshold():
    rng = np.random.default_rng(11)
    m = 400
    n_geo = np.tile([0.0, 0.0, 1.0], (m, 1))
    wo = unit(rng.normal(size=(m, 3)) * [1, 1, 0.3] + [0, 0, 0.05])
    wo[:, 2] = np.abs(wo[:, 2])
    n_shade = unit(rng.normal(size=(m, 3)) * [0.8, 0.8, 0.3] + [0, 0, 1.0])
    bent = valid_reflection_normal(n_geo, wo, n_shade)
    mirror = 2.0 * np.einsum("ij,ij->i", bent, wo)[:, None] * bent - wo
    threshold = np.minimum(0.9 * wo[:, 2], 0.01)
    moved = np.abs(bent - n_shade).max(axis=1) > 0
    assert 20 < moved.sum() < m
    # Where the mirror direction of the shading normal cleared the threshold nothing changes;
    # elsewhere the bent normal is a unit vector in the plane of the two normals whose mirror
    # direction is exactly at the threshold (Cycles' ensure_valid_specular_reflection).
    before = 2.0 * np.einsum("ij,ij->i", n_shade, wo)[:, None] * n_shade - wo
    assert (before[~moved, 2] >= threshold[~moved]).all() and (before[moved, 2] < threshold[moved]).all()
    np.testing.assert_allclose(np.linalg.norm(bent, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(mirror[moved, 2], threshold[moved], atol=1e-9)
    plane = np.cross(n_shade[moved], n_geo[moved])
    np.testing.assert_allclose(np.einsum("ij,ij->i", plane, bent[moved]), 0.0, atol=1e-12)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: GGX(0.5, 1.5), "roughness=1.5 is outside [0, 1]"),
        (lambda: GGX(0.5, 0.001), "roughness=0.001 is below 0.01"),
        (lambda: GGX(0.5, 0.3, masking="smith"), "masking='smith' is unknown"),
        (lambda: Lambertian(-0.1), "albedo=-0.1 is outside [0, 1]"),
        (lambda: Principled(0.5, ior=0.9), "ior=0.9 is outside (1, 4)"),
        (lambda: Mix(Lambertian(0.5), GGX(0.5, 0.3), 1.2), "Mix: fac=1.2 is outside [0, 1]"),
    ],
)
def test_validation_messages(make, message):
    with pytest.raises(
        ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[").replace("]", r"\]")
    ):
        make()


def test_shade_keeps_diffuse_light_below_the_shading_horizon():
    # cos_o < 0: the observer is below the shading normal's horizon (a smooth-shaded face it
    # still sees). The BRDF itself is 0 there; shade() (f cos i) keeps the view-independent
    # diffuse terms and, without a bent normal, cuts the specular lobes (the strict treatment).
    cos_i, cos_o, cos_io = np.array([0.8]), np.array([-0.1]), np.array([-0.2])
    lambert = Lambertian(0.5)
    assert lambert.from_cosines(cos_i, cos_o, cos_io)[0] == 0.0
    assert lambert.shade(cos_i, cos_o, cos_io)[0] == pytest.approx(0.5 / np.pi * 0.8, rel=1e-15)
    assert GGX(0.5, 0.3).shade(cos_i, cos_o, cos_io)[0] == 0.0
    principled = Principled(0.4, roughness=0.5)
    # Only the diffuse base is left, weighted at the table's grazing end.
    expected = principled.diffuse_weight(np.array([0.0]))[0] * 0.4 / np.pi * 0.8
    assert principled.shade(cos_i, cos_o, cos_io)[0] == pytest.approx(expected, rel=1e-12)
    # With a bent normal the lobe is evaluated about it, unless the light is below the shading
    # normal's horizon (Cycles' bump shadowing term).
    bent = GGX(0.5, 0.3).shade(cos_i, cos_o, cos_io, np.array([0.6]), np.array([0.05]))[0]
    assert bent == pytest.approx(GGX(0.5, 0.3).from_cosines(0.6, 0.05, -0.2) * 0.6, rel=1e-12)
    assert GGX(0.5, 0.3).shade(-cos_i, cos_o, cos_io, np.array([0.6]), np.array([0.05]))[0] == 0.0
    # Above both horizons shade() is the BRDF times cos i.
    rng = np.random.default_rng(3)
    n = np.broadcast_to([0.0, 0.0, 1.0], (50, 3))
    wi = unit(rng.normal(size=(50, 3)) + [0, 0, 1.5])
    wo = unit(rng.normal(size=(50, 3)) + [0, 0, 1.5])
    for brdf in (lambert, GGX(0.5, 0.3), principled, GGX(0.5, 0.3, distribution="MULTI_GGX")):
        ci, co, cio = (np.einsum("ij,ij->i", a, b) for a, b in ((wi, n), (wo, n), (wi, wo)))
        both = (ci > 0) & (co > 0)
        np.testing.assert_allclose(brdf.shade(ci, co, cio)[both], (brdf(wi, wo, n) * ci)[both], rtol=1e-13)


def test_mix_is_blenders_mix_shader_of_its_two_inputs():
    """Fac 0 is the first input, fac 1 the second, and between them the weighted sum, in both
    the plain value and the renderers' shading (a swapped fac or a dropped input fails)."""
    first, second = Principled(0.3, metallic=0.9, roughness=0.45), GGX(0.9, 0.08)
    wi, wo = random_hemisphere(400), random_hemisphere(400)
    n = np.tile([0.0, 0.0, 1.0], (400, 1))
    a, b = first(wi, wo, n), second(wi, wo, n)
    for fac in (0.0, 0.3, 1.0):
        np.testing.assert_allclose(Mix(first, second, fac)(wi, wo, n), (1 - fac) * a + fac * b, rtol=1e-12)
    ci, co, cio = wi[:, 2], wo[:, 2], np.einsum("ij,ij->i", wi, wo)
    mixed = Mix(first, second, 0.3).shade(ci, co, cio)
    np.testing.assert_allclose(mixed, 0.7 * first.shade(ci, co, cio) + 0.3 * second.shade(ci, co, cio), rtol=1e-12)
    # The renderers sample for the narrower lobe whatever the fac.
    assert Mix(first, second, 0.0).lobe_width_rad == pytest.approx(0.08**2)
    assert Mix(Lambertian(0.2), Lambertian(0.5), 0.5).lobe_width_rad is None


def test_mix_inputs_must_be_single_brdfs():
    inner = Mix(Lambertian(0.5), GGX(0.5, 0.3), 0.5)
    with pytest.raises(TypeError, match="Mix: second=.* must be a Lambertian, GGX or Principled BRDF"):
        Mix(Lambertian(0.5), inner, 0.5)
