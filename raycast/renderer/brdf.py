"""Bidirectional reflectance distribution functions (BRDFs).

A BRDF is a small immutable object with one method, ``__call__(wi, wo, n) -> (m,)``: the value
of f_r in 1/sr for light arriving from ``wi`` and leaving toward ``wo`` at a surface with shading
normal ``n``. All three are ``(m, 3)`` unit vectors pointing *away* from the surface (``wi``
toward the Sun, ``wo`` toward the observer). Every BRDF returns 0 where ``wi`` or ``wo`` lies
below the shading plane.

Isotropic BRDFs depend on three cosines only, so each class implements
``from_cosines(cos_i, cos_o, cos_io)`` (cos_i = n.wi, cos_o = n.wo, cos_io = wi.wo, any
broadcastable shapes) and ``__call__`` computes them. Renderers evaluate whole (frames, surface
elements) blocks from matrix products of directions and normals this way.

``shade(cos_i, cos_o, cos_io)`` is what the renderers use on smooth-shaded meshes: the same
value, except that diffuse terms are not cut where the observer is below the *shading* normal's
horizon (only ``cos_i > 0`` is required of them; the renderer tests the observer against the
geometric normal). A Lambertian surface's radiance does not depend on the view, and on a
low-poly smooth-shaded mesh the shading normal leans up to tens of degrees from the face:
cutting it there would darken a band of faces the observer does see. Blender Cycles does the
same (docs/cycles.md, calibration table). Specular lobes keep the cut (Cycles bends the normal
instead; see docs/renderer.md).

Implementations
---------------
Lambertian
    f = albedo / pi (Blender's Diffuse BSDF with roughness 0).
GGX
    Blender's Glossy BSDF: f = color * D(h) * G(i, o) / (4 cos i cos o), D the GGX
    (Trowbridge-Reitz) distribution with alpha = roughness**2, no Fresnel. ``masking`` chooses
    the Smith shadowing-masking term: ``"height-correlated"`` 1 / (1 + L(i) + L(o)) as in
    Cycles' ``bsdf_microfacet_eval``, or ``"separable"`` G1(i) G1(o). The two agree within 0.1%
    unless a direction is within ~15 deg of grazing (see docs/renderer.md).
Principled
    A dielectric/metallic layer model after Blender 4+ Principled BSDF (no sheen, coat,
    transmission or subsurface): a GGX specular lobe with the real dielectric Fresnel of
    ``ior`` (rescaled by ``specular_ior_level`` as Blender does), over a Lambertian base
    attenuated by ``1 - E_spec(cos o)``, the specular lobe's directional albedo seen from the
    observer (Cycles' ``closure_layering_weight``); the metallic part is a GGX lobe with Schlick
    Fresnel toward ``base_color``. Single-scattering GGX: Blender's multiscatter energy
    compensation adds < 0.5% of the specular lobe for roughness <= 0.5 and F0 <= 0.05.
    Because the diffuse attenuation depends on the observer side only, this model (like
    Cycles') is not exactly reciprocal.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
import math

import numpy as np

__all__ = [
    "BRDF",
    "Lambertian",
    "GGX",
    "Principled",
    "fresnel_dielectric",
    "ggx_distribution",
    "smith_lambda",
    "directional_albedo",
]

MASKING_MODES = ("height-correlated", "separable")


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def _check_unit_interval(name, value, owner):
    if not (isinstance(value, (int, float)) and math.isfinite(value) and 0.0 <= value <= 1.0):
        raise ValueError(f"{owner}: {name}={value!r} is outside [0, 1]; give a reflectance-like fraction")


def ggx_distribution(cos_nh, alpha):
    """GGX (Trowbridge-Reitz) normal distribution D(h) in 1/sr.

    Parameters
    ----------
    cos_nh : (m,) float, cosine between the normal and the half vector.
    alpha : float, GGX width (Blender: roughness**2).
    """
    alpha2 = alpha * alpha
    c2 = cos_nh * cos_nh
    return alpha2 / (np.pi * (1.0 + (alpha2 - 1.0) * c2) ** 2)


def smith_lambda(cos_n, alpha):
    """Smith Lambda of GGX for a direction at cosine ``cos_n`` to the normal, shape (m,)."""
    c2 = np.clip(cos_n * cos_n, 1e-300, 1.0)
    tan2 = np.maximum(1.0 / c2 - 1.0, 0.0)
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance of a dielectric of relative index ``eta``, shape (m,)."""
    c = np.abs(cos_i)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return np.where(g2 > 0.0, 0.5 * a * a * (1.0 + b * b), 1.0)


def _f0_from_ior(ior):
    return ((ior - 1.0) / (ior + 1.0)) ** 2


class BRDF:
    """Base class: subclasses implement ``__call__(wi, wo, n) -> (m,)`` in 1/sr.

    ``lobe_width_rad`` is the angular half-width of the narrowest specular lobe in half-vector
    space (None for purely diffuse BRDFs); renderers use it to size glint sampling.
    ``lobe_share`` is that lobe's normal-incidence reflectance relative to the whole BRDF's
    (1 for a pure glossy lobe; the Fresnel F0 over F0 plus the diffuse albedo for a dielectric
    Principled): a weak lobe on a diffuse base tolerates coarser normal sampling.
    """

    lobe_width_rad: float | None = None
    lobe_share: float = 1.0

    def __call__(self, wi, wo, n):
        wi, wo, n = np.asarray(wi), np.asarray(wo), np.asarray(n)
        return self.from_cosines(_dot(wi, n), _dot(wo, n), _dot(wi, wo))

    def from_cosines(self, cos_i, cos_o, cos_io):  # pragma: no cover - interface
        """f_r in 1/sr from cos(n, wi), cos(n, wo) and cos(wi, wo) (broadcastable arrays)."""
        raise NotImplementedError

    def shade(self, cos_i, cos_o, cos_io):
        """f_r as the renderers apply it: diffuse terms need only ``cos_i > 0`` (module docstring)."""
        return self.from_cosines(cos_i, cos_o, cos_io)


@dataclass(frozen=True)
class Lambertian(BRDF):
    """Ideal diffuse reflector, f = albedo / pi.

    Parameters
    ----------
    albedo : float in [0, 1], directional-hemispherical reflectance.
    """

    albedo: float

    def __post_init__(self):
        _check_unit_interval("albedo", self.albedo, "Lambertian")

    def from_cosines(self, cos_i, cos_o, cos_io):
        return np.where((cos_i > 0.0) & (cos_o > 0.0), self.albedo / np.pi, 0.0)

    def shade(self, cos_i, cos_o, cos_io):
        return np.where(cos_i > 0.0, self.albedo / np.pi, 0.0)


def _ggx_lobe(ci, co, cos_io, alpha, masking):
    """D G / (4 cos i cos o) and cos(h, wi) for the valid pairs; zero elsewhere.

    With h = (wi + wo) / |wi + wo| and |wi + wo| = sqrt(2 + 2 cos_io):
    n.h = (cos_i + cos_o) / |wi + wo| and h.wi = |wi + wo| / 2.
    """
    valid = (ci > 0.0) & (co > 0.0)
    h_len = np.sqrt(np.maximum(2.0 + 2.0 * cos_io, 0.0))
    cos_nh = np.clip((ci + co) / np.where(h_len > 0.0, h_len, 1.0), 0.0, 1.0)
    cos_hi = np.clip(0.5 * h_len, 0.0, 1.0)
    ci_safe = np.where(valid, ci, 1.0)
    co_safe = np.where(valid, co, 1.0)
    lam_i = smith_lambda(ci_safe, alpha)
    lam_o = smith_lambda(co_safe, alpha)
    if masking == "separable":
        g = 1.0 / ((1.0 + lam_i) * (1.0 + lam_o))
    else:
        g = 1.0 / (1.0 + lam_i + lam_o)
    value = ggx_distribution(cos_nh, alpha) * g / (4.0 * ci_safe * co_safe)
    return np.where(valid, value, 0.0), cos_hi


@dataclass(frozen=True)
class GGX(BRDF):
    """Blender's Glossy BSDF (GGX, no Fresnel): f = color D G / (4 cos i cos o).

    Parameters
    ----------
    color : float in [0, 1], the reflectance Blender calls Color.
    roughness : float in [0, 1], Blender's Roughness; alpha = roughness**2.
    masking : {"height-correlated", "separable"}, the Smith term (see module docstring).
    """

    color: float
    roughness: float
    masking: str = "height-correlated"

    def __post_init__(self):
        _check_unit_interval("color", self.color, "GGX")
        _check_unit_interval("roughness", self.roughness, "GGX")
        if self.roughness < 0.01:
            raise ValueError(
                f"GGX: roughness={self.roughness!r} is below 0.01 (a mirror); the renderer samples "
                "the 0.53 deg Sun disk but not perfect mirrors, so use roughness >= 0.01"
            )
        if self.masking not in MASKING_MODES:
            raise ValueError(f"GGX: masking={self.masking!r} is unknown; use one of {MASKING_MODES}")

    @property
    def alpha(self) -> float:
        return self.roughness**2

    @property
    def lobe_width_rad(self) -> float:
        return self.alpha

    def from_cosines(self, cos_i, cos_o, cos_io):
        value, _ = _ggx_lobe(cos_i, cos_o, cos_io, self.alpha, self.masking)
        return self.color * value


@dataclass(frozen=True)
class Principled(BRDF):
    """Diffuse + dielectric specular + metallic model after Blender's Principled BSDF.

    Parameters
    ----------
    base_color : float in [0, 1], diffuse albedo of the dielectric part, F0 of the metallic part.
    metallic : float in [0, 1], mix between the dielectric and the metallic model.
    roughness : float in [0, 1], alpha = roughness**2 for both specular lobes.
    specular_ior_level : float >= 0, Blender's Specular IOR Level (0.5 keeps the IOR's F0;
        other values scale F0 by ``2 * level``).
    ior : float > 1, index of refraction of the dielectric coating.
    """

    base_color: float
    metallic: float = 0.0
    roughness: float = 0.5
    specular_ior_level: float = 0.5
    ior: float = 1.5
    _albedo_table: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        _check_unit_interval("base_color", self.base_color, "Principled")
        _check_unit_interval("metallic", self.metallic, "Principled")
        _check_unit_interval("roughness", self.roughness, "Principled")
        if self.roughness < 0.01:
            raise ValueError(
                f"Principled: roughness={self.roughness!r} is below 0.01 (a mirror); use roughness >= 0.01"
            )
        if not (math.isfinite(self.specular_ior_level) and 0.0 <= self.specular_ior_level <= 1.0):
            raise ValueError(f"Principled: specular_ior_level={self.specular_ior_level!r} is outside [0, 1]")
        if not (math.isfinite(self.ior) and 1.0 < self.ior < 4.0):
            raise ValueError(f"Principled: ior={self.ior!r} is outside (1, 4); give a dielectric index of refraction")
        object.__setattr__(self, "_albedo_table", _specular_albedo_table(self.alpha, self.f0, self.ior))

    @property
    def alpha(self) -> float:
        return self.roughness**2

    @property
    def lobe_width_rad(self) -> float:
        return self.alpha

    @property
    def lobe_share(self) -> float:
        specular = self.metallic * self.base_color + (1.0 - self.metallic) * self.f0
        total = specular + (1.0 - self.metallic) * self.base_color
        return specular / total if total > 0.0 else 1.0

    @property
    def f0(self) -> float:
        """Normal-incidence reflectance of the dielectric specular lobe."""
        return min(_f0_from_ior(self.ior) * 2.0 * self.specular_ior_level, 1.0)

    def specular(self, wi, wo, n):
        """The dielectric specular lobe alone (reciprocal), shape (m,)."""
        return self._specular(_dot(wi, n), _dot(wo, n), _dot(wi, wo))

    def _specular(self, cos_i, cos_o, cos_io):
        lobe, cos_hi = _ggx_lobe(cos_i, cos_o, cos_io, self.alpha, "height-correlated")
        return lobe * _generalized_fresnel(cos_hi, self.f0, self.ior)

    def diffuse_weight(self, cos_o):
        """1 - E_spec(cos_o): the share of light left to the diffuse base, shape (m,)."""
        grid, albedo = self._albedo_table
        return 1.0 - np.interp(np.clip(cos_o, grid[0], 1.0), grid, albedo)

    def from_cosines(self, cos_i, cos_o, cos_io):
        return self._evaluate(cos_i, cos_o, cos_io, (cos_i > 0.0) & (cos_o > 0.0))

    def shade(self, cos_i, cos_o, cos_io):
        return self._evaluate(cos_i, cos_o, cos_io, cos_i > 0.0)

    def _evaluate(self, ci, co, cos_io, diffuse_valid):
        dielectric = self._specular(ci, co, cos_io) + np.where(
            diffuse_valid, self.diffuse_weight(np.maximum(co, 0.0)) * self.base_color / np.pi, 0.0
        )
        if self.metallic == 0.0:
            return dielectric
        lobe, cos_hi = _ggx_lobe(ci, co, cos_io, self.alpha, "height-correlated")
        schlick = self.base_color + (1.0 - self.base_color) * (1.0 - cos_hi) ** 5
        return (1.0 - self.metallic) * dielectric + self.metallic * lobe * schlick


def _generalized_fresnel(cos_hi, f0, ior):
    """Cycles' generalised Schlick with a negative exponent: the real dielectric curve remapped
    so that normal incidence gives ``f0`` and grazing gives 1."""
    f0_ior = _f0_from_ior(ior)
    s = np.clip((fresnel_dielectric(cos_hi, ior) - f0_ior) / (1.0 - f0_ior), 0.0, 1.0)
    return f0 + (1.0 - f0) * s


@lru_cache(maxsize=64)
def _specular_albedo_table(alpha, f0, ior, n_cos=64):
    """Directional albedo of the Principled specular lobe over cos(o), by quadrature.

    Sampling the half vector with the GGX pdf D(h) cos(h) turns the albedo integral into the
    mean of G F (h.o) / ((h.n) cos o) over a deterministic grid in the GGX CDF, which resolves
    narrow and wide lobes alike.
    """
    cos_grid = np.linspace(0.02, 1.0, n_cos)
    n_t, n_phi = 160, 96
    t = (np.arange(n_t) + 0.5) / n_t
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2.0 * np.pi
    tan_h = alpha * np.sqrt(t / (1.0 - t))
    cos_h = 1.0 / np.sqrt(1.0 + tan_h**2)
    sin_h = tan_h * cos_h
    h = np.stack(
        np.broadcast_arrays(
            sin_h[:, None] * np.cos(phi)[None, :],
            sin_h[:, None] * np.sin(phi)[None, :],
            cos_h[:, None] * np.ones_like(phi)[None, :],
        ),
        axis=-1,
    ).reshape(-1, 3)
    albedo = np.empty(n_cos)
    for index, c in enumerate(cos_grid):
        wo = np.array([math.sqrt(1.0 - c * c), 0.0, c])
        cos_ho = h @ wo
        wi = 2.0 * cos_ho[:, None] * h - wo
        ci = wi[:, 2]
        ok = (ci > 0.0) & (cos_ho > 0.0)
        lam_i = smith_lambda(np.where(ok, ci, 1.0), alpha)
        lam_o = smith_lambda(np.full_like(ci, c), alpha)
        g = 1.0 / (1.0 + lam_i + lam_o)
        fres = _generalized_fresnel(np.clip(cos_ho, 0.0, 1.0), f0, ior)
        weight = g * fres * cos_ho / (h[:, 2] * c)
        albedo[index] = np.mean(np.where(ok, weight, 0.0))
    return cos_grid, albedo


def directional_albedo(brdf, cos_o, n_theta=256, n_phi=128):
    """Directional-hemispherical reflectance of ``brdf`` seen from ``cos_o``, by brute quadrature.

    The integral of f cos(i) over the incident hemisphere, on a midpoint grid uniform in
    cos(i)**2 (so the cosine weight is exact) and in azimuth. Used by the white-furnace test;
    accurate to ~1e-3 for lobes wider than roughness 0.2.

    Parameters
    ----------
    brdf : BRDF
    cos_o : float in (0, 1]
    """
    u = (np.arange(n_theta) + 0.5) / n_theta
    cos_i = np.sqrt(u)
    sin_i = np.sqrt(1.0 - u)
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2.0 * np.pi
    wi = np.stack(
        np.broadcast_arrays(
            sin_i[:, None] * np.cos(phi)[None, :],
            sin_i[:, None] * np.sin(phi)[None, :],
            cos_i[:, None] * np.ones_like(phi)[None, :],
        ),
        axis=-1,
    ).reshape(-1, 3)
    wo = np.broadcast_to([math.sqrt(max(1.0 - cos_o * cos_o, 0.0)), 0.0, cos_o], wi.shape)
    n = np.broadcast_to([0.0, 0.0, 1.0], wi.shape)
    # With u = cos^2 i, d(omega) cos i = 0.5 du dphi, so the integral is pi * mean(f).
    return float(np.pi * np.mean(brdf(wi, wo, n)))
