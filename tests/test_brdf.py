"""BRDFs: closed forms, reciprocity, energy conservation (white furnace), validation."""

import math

import numpy as np
import pytest

from raycast.renderer.brdf import GGX, Lambertian, Principled, directional_albedo, fresnel_dielectric
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


def test_principled_diffuse_weight_from_specular_albedo():
    # Dielectric F0 = 0.034: at normal view the rough specular lobe takes about F0 of the light
    # (Fresnel rises off-specular, masking takes some back), so the diffuse weight lies in
    # (0.95, 0.98); grazing views see much more specular.
    brdf = Principled(0.5, roughness=0.5, ior=1.45)
    weights = brdf.diffuse_weight(np.array([1.0, 0.5, 0.1]))
    assert 0.95 < weights[0] < 0.98
    assert weights[0] > weights[1] > weights[2] > 0.5


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: GGX(0.5, 1.5), "roughness=1.5 is outside [0, 1]"),
        (lambda: GGX(0.5, 0.001), "roughness=0.001 is below 0.01"),
        (lambda: GGX(0.5, 0.3, masking="smith"), "masking='smith' is unknown"),
        (lambda: Lambertian(-0.1), "albedo=-0.1 is outside [0, 1]"),
        (lambda: Principled(0.5, ior=0.9), "ior=0.9 is outside (1, 4)"),
    ],
)
def test_validation_messages(make, message):
    with pytest.raises(
        ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[").replace("]", r"\]")
    ):
        make()


def test_shade_keeps_diffuse_light_below_the_shading_horizon():
    # cos_o < 0: the observer is below the shading normal's horizon (a smooth-shaded face it
    # still sees). The BRDF itself is 0 there; shade() keeps the view-independent diffuse terms
    # exactly and cuts the specular lobes.
    cos_i, cos_o, cos_io = np.array([0.8]), np.array([-0.1]), np.array([-0.2])
    lambert = Lambertian(0.5)
    assert lambert.from_cosines(cos_i, cos_o, cos_io)[0] == 0.0
    assert lambert.shade(cos_i, cos_o, cos_io)[0] == pytest.approx(0.5 / np.pi, rel=1e-15)
    assert GGX(0.5, 0.3).shade(cos_i, cos_o, cos_io)[0] == 0.0
    principled = Principled(0.4, roughness=0.5)
    # Only the diffuse base is left, attenuated by the specular albedo at the table's grazing end.
    expected = principled.diffuse_weight(np.array([0.0]))[0] * 0.4 / np.pi
    assert principled.shade(cos_i, cos_o, cos_io)[0] == pytest.approx(expected, rel=1e-12)
    # Above both horizons shade() is the BRDF (to the last bit).
    rng = np.random.default_rng(3)
    n = np.broadcast_to([0.0, 0.0, 1.0], (50, 3))
    wi = unit(rng.normal(size=(50, 3)) + [0, 0, 1.5])
    wo = unit(rng.normal(size=(50, 3)) + [0, 0, 1.5])
    for brdf in (lambert, GGX(0.5, 0.3), principled):
        ci, co, cio = (np.einsum("ij,ij->i", a, b) for a, b in ((wi, n), (wo, n), (wi, wo)))
        np.testing.assert_array_equal(
            brdf.shade(ci, co, cio)[(ci > 0) & (co > 0)], brdf(wi, wo, n)[(ci > 0) & (co > 0)]
        )
