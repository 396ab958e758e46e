"""Bidirectional reflectance distribution functions (BRDFs), as Blender Cycles evaluates its BSDFs.

A BRDF is a small immutable object with one method, ``__call__(wi, wo, n) -> (m,)``: the value
of f_r in 1/sr for light arriving from ``wi`` and leaving toward ``wo`` at a surface with shading
normal ``n``. All three are ``(m, 3)`` unit vectors pointing *away* from the surface (``wi``
toward the Sun, ``wo`` toward the observer). Every BRDF returns 0 where ``wi`` or ``wo`` lies
below the shading plane.

Isotropic BRDFs depend on three cosines only, so each class implements
``from_cosines(cos_i, cos_o, cos_io)`` (cos_i = n.wi, cos_o = n.wo, cos_io = wi.wo, any
broadcastable shapes) and ``__call__`` computes them. Renderers evaluate whole (frames, surface
elements) blocks from matrix products of directions and normals this way.

``shade(cos_i, cos_o, cos_io, spec_cos_i, spec_cos_o)`` is what the renderers use: f_r times the
cosine of incidence, with shading normals treated as Cycles treats them (docs/renderer.md,
"Shading normals"). Diffuse terms use the shading normal's cosine of incidence and are not cut
where the observer is below the shading normal's horizon (the hit proves the observer sees the
face). Specular lobes are evaluated about the normal whose cosines ``spec_cos_i``,
``spec_cos_o`` give: Cycles' valid-reflection normal (:func:`valid_reflection_normal`), bent
from the shading normal toward the face until the view's mirror direction clears the surface;
without them, about the shading normal, cut below its horizon (the stricter treatment).

Implementations
---------------
Lambertian
    f = albedo / pi (Blender's Diffuse BSDF with roughness 0).
GGX
    Blender's Glossy BSDF: f = color * D(h) * G(i, o) / (4 cos i cos o), D the GGX
    (Trowbridge-Reitz) distribution with alpha = roughness**2, no Fresnel. ``masking`` chooses
    the Smith shadowing-masking term: ``"height-correlated"`` 1 / (1 + L(i) + L(o)) as in
    Cycles' ``bsdf_microfacet_eval``, or ``"separable"`` G1(i) G1(o). ``distribution="MULTI_GGX"``
    adds Cycles' multiple-scattering energy compensation (a factor of the view direction).
Principled
    Blender's Principled BSDF without sheen, coat, transmission or subsurface, layered as
    Cycles layers it: a metallic GGX lobe (Schlick Fresnel toward ``base_color``) with weight
    ``metallic``; over the rest a dielectric GGX lobe with the real Fresnel curve of ``ior``
    (F0 rescaled by ``specular_ior_level`` as Blender does), and under it a Lambertian base
    weighted by ``1 - d(mu) (F0 + (1 - F0) s(mu))``: Cycles' albedo estimate of the specular
    lobe at the view cosine mu, from tables of GGX integrals (:mod:`raycast.renderer.ggx_tables`),
    with d the multiple-scattering factor (1 for plain GGX). Because the weight depends on the
    view only, this model (like Cycles') is not exactly reciprocal.
Mix
    Blender's Mix Shader: (1 - fac) first + fac second, of two of the BRDFs above. A surface
    whose area is partly one finish and partly another (a bus of blankets with smooth radiator
    panels among them, each part smaller than a pixel) reflects as this weighted sum.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
import math

from numba import njit, vectorize
import numpy as np

from raycast.renderer import _shading_kernels
from raycast.renderer.ggx_tables import (
    dielectric_fresnel,
    dielectric_fresnel_mean,
    fresnel_mean_fit,
    ggx_albedo,
    ggx_average_albedo,
    smith_lambda,
)

__all__ = [
    "BRDF",
    "Lambertian",
    "GGX",
    "Principled",
    "Mix",
    "DISTRIBUTIONS",
    "fresnel_dielectric",
    "ggx_distribution",
    "smith_lambda",
    "valid_reflection_normal",
    "directional_albedo",
]

MASKING_MODES = ("height-correlated", "separable")
# Blender's names of the microfacet distributions modelled here.
DISTRIBUTIONS = ("GGX", "MULTI_GGX")

fresnel_dielectric = dielectric_fresnel
# The view cosines of the tables' nodes: a table read there gives the node's value.
_E_NODES = np.linspace(0.0, 1.0, _shading_kernels.E_NODES)
_S_NODES = np.linspace(0.0, 1.0, _shading_kernels.S_NODES)
# Packed BRDFs kept for reuse (the renderers ask once per material and batch of frames). Bounded:
# a fit that frees a BRDF parameter makes a new BRDF at every evaluation.
_PACKED_KEPT = 256


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def _check_unit_interval(name, value, owner):
    if not (isinstance(value, (int, float)) and math.isfinite(value) and 0.0 <= value <= 1.0):
        raise ValueError(f"{owner}: {name}={value!r} is outside [0, 1]; give a reflectance-like fraction")


def _check_distribution(value, owner):
    if value not in DISTRIBUTIONS:
        raise ValueError(f"{owner}: distribution={value!r} is unknown; use one of {DISTRIBUTIONS}")


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


def _f0_from_ior(ior):
    return ((ior - 1.0) / (ior + 1.0)) ** 2


def valid_reflection_normal(n_geo, wo, n_shade):
    """Cycles' valid-reflection normal (``ensure_valid_specular_reflection``), shape (m, 3).

    Where the mirror image of the view ``wo`` about the shading normal ``n_shade`` lies less
    than ``t = min(0.9 n_geo.wo, 0.01)`` above the face (normal ``n_geo``, turned toward the
    observer), the normal is turned toward ``n_geo`` in the plane of the two, just enough that
    the mirror image is exactly ``t`` above the face; elsewhere it is ``n_shade`` unchanged.
    Specular lobes on smooth-shaded faces are evaluated about this normal.

    Parameters
    ----------
    n_geo, wo, n_shade : (m, 3) float unit vectors; ``n_geo.wo >= 0``.
    """
    out = np.array(n_shade, dtype=np.result_type(n_shade, np.float32), copy=True)
    _bend_normals(
        np.ascontiguousarray(n_geo, dtype=float), np.ascontiguousarray(wo, dtype=float), np.asarray(n_shade, float), out
    )
    return out


@njit(cache=True, nogil=True)
def _bend_normals(n_geo, wo, n_shade, out):
    """Write the valid-reflection normal into ``out`` (:func:`raycast.renderer._shading_kernels.bent_normal`)."""
    for k in range(len(out)):
        out[k, 0], out[k, 1], out[k, 2] = _shading_kernels.bent_normal(
            n_geo[k, 0],
            n_geo[k, 1],
            n_geo[k, 2],
            wo[k, 0],
            wo[k, 1],
            wo[k, 2],
            n_shade[k, 0],
            n_shade[k, 1],
            n_shade[k, 2],
        )


class BRDF:
    """Base class: subclasses implement ``from_cosines`` (f_r in 1/sr) and ``shade``.

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

    def shade(self, cos_i, cos_o, cos_io, spec_cos_i=None, spec_cos_o=None):  # pragma: no cover - interface
        """f_r cos(i) as the renderers apply it (module docstring).

        Parameters
        ----------
        cos_i, cos_o : cosines of the Sun and the observer to the shading normal.
        cos_io : cosine between the Sun and the observer.
        spec_cos_i, spec_cos_o : optional, the same to the normal specular lobes are evaluated
            about (:func:`valid_reflection_normal`); None evaluates them about the shading
            normal, cut below its horizon.
        """
        raise NotImplementedError

    def packed(self):
        """This BRDF as the compiled shading reads it (:mod:`raycast.renderer._shading_kernels`),
        a float64 array; None for a BRDF that only numpy evaluates (the renderers then call
        :meth:`shade`)."""
        return None


def _specular_cosines(cos_i, cos_o, spec_cos_i, spec_cos_o):
    """The cosines a specular lobe is evaluated with, and where it may be non-zero.

    With a bent normal, light must also be above the shading normal's horizon (Cycles rejects
    light that the bent and the shading normal see on different sides: its bump shadowing term).
    """
    if spec_cos_i is None:
        return cos_i, cos_o, (cos_i > 0.0) & (cos_o > 0.0)
    return spec_cos_i, spec_cos_o, (cos_i > 0.0) & (spec_cos_i > 0.0) & (spec_cos_o > 0.0)


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

    def shade(self, cos_i, cos_o, cos_io, spec_cos_i=None, spec_cos_o=None):
        return self.albedo / np.pi * np.maximum(cos_i, 0.0)

    def packed(self):
        return _shading_kernels.as_packed((), (_shading_kernels.LAMBERTIAN, self.albedo))


def _ggx_lobe(ci, co, cos_io, alpha, masking, valid=None):
    """D G / (4 cos i cos o) and cos(h, wi) for the valid pairs; zero elsewhere.

    With h = (wi + wo) / |wi + wo| and |wi + wo| = sqrt(2 + 2 cos_io):
    n.h = (cos_i + cos_o) / |wi + wo| and h.wi = |wi + wo| / 2.
    """
    if valid is None:
        valid = (ci > 0.0) & (co > 0.0)
    cos_hi = np.clip(0.5 * np.sqrt(np.maximum(2.0 + 2.0 * np.asarray(cos_io, dtype=float), 0.0)), 0.0, 1.0)
    return _ggx_lobe_value(ci, co, cos_io, valid, float(alpha), masking == "separable"), cos_hi


@vectorize(cache=True, nopython=True)
def _ggx_lobe_value(ci, co, cos_io, valid, alpha, separable):
    """:func:`_ggx_lobe`'s value at one point (a ufunc: one pass, no temporaries)."""
    return _shading_kernels.ggx_lobe(ci, co, cos_io, alpha, separable) if valid else 0.0


@dataclass(frozen=True)
class _MultipleScattering:
    """Cycles' energy compensation of a GGX lobe whose mean single-scattering Fresnel is ``fss``.

    The lobe is multiplied by ``1 + Fms (1 - E) / E`` with E the GGX albedo at the view cosine
    and Fms = fss E_avg / (1 - fss (1 - E_avg)) (Kulla and Conty, as ``microfacet_ggx_preserve_energy``);
    ``darkening`` is what Cycles multiplies the closure's weight by, E + Fms (1 - E).
    """

    roughness: float
    fss: float

    @property
    def fms(self):
        e_avg = ggx_average_albedo(self.roughness)
        return self.fss * e_avg / (1.0 - self.fss * (1.0 - e_avg))

    def factor(self, mu):
        e = ggx_albedo(self.roughness, mu)
        return 1.0 + self.fms * (1.0 - e) / np.maximum(e, 1e-6)

    def darkening(self, mu):
        e = ggx_albedo(self.roughness, mu)
        return e + self.fms * (1.0 - e)


@dataclass(frozen=True)
class GGX(BRDF):
    """Blender's Glossy BSDF (GGX, no Fresnel): f = color D G / (4 cos i cos o).

    Parameters
    ----------
    color : float in [0, 1], the reflectance Blender calls Color.
    roughness : float in [0, 1], Blender's Roughness; alpha = roughness**2.
    masking : {"height-correlated", "separable"}, the Smith term (see module docstring).
    distribution : {"GGX", "MULTI_GGX"}, Blender's distribution: single scattering, or with
        Cycles' multiple-scattering energy compensation (Blender 5's default for new nodes).
    """

    color: float
    roughness: float
    masking: str = "height-correlated"
    distribution: str = "GGX"

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
        _check_distribution(self.distribution, "GGX")
        if self.distribution == "MULTI_GGX" and self.masking != "height-correlated":
            raise ValueError("GGX: distribution='MULTI_GGX' compensates the height-correlated masking only")

    @property
    def alpha(self) -> float:
        return self.roughness**2

    @property
    def lobe_width_rad(self) -> float:
        return self.alpha

    def _scattering(self, cos_o):
        if self.distribution == "GGX":
            return 1.0
        return _MultipleScattering(self.roughness, self.color).factor(cos_o)

    def from_cosines(self, cos_i, cos_o, cos_io):
        value, _ = _ggx_lobe(cos_i, cos_o, cos_io, self.alpha, self.masking)
        return self.color * value * self._scattering(cos_o)

    def shade(self, cos_i, cos_o, cos_io, spec_cos_i=None, spec_cos_o=None):
        ci, co, valid = _specular_cosines(cos_i, cos_o, spec_cos_i, spec_cos_o)
        value, _ = _ggx_lobe(ci, co, cos_io, self.alpha, self.masking, valid)
        return self.color * value * np.maximum(ci, 0.0) * self._scattering(co)

    @lru_cache(maxsize=_PACKED_KEPT)
    def packed(self):
        multi = self.distribution == "MULTI_GGX"
        head = (_shading_kernels.GGX, self.color, self.alpha, self.masking == "separable", multi)
        if not multi:
            return _shading_kernels.as_packed((), head)
        scattering = _MultipleScattering(self.roughness, self.color)
        return _shading_kernels.as_packed((ggx_albedo(self.roughness, _E_NODES),), (*head, scattering.fms))


@dataclass(frozen=True)
class Principled(BRDF):
    """Diffuse + dielectric specular + metallic model after Blender's Principled BSDF.

    Parameters
    ----------
    base_color : float in [0, 1], diffuse albedo of the dielectric part, F0 of the metallic part.
    metallic : float in [0, 1], mix between the dielectric and the metallic model.
    roughness : float in [0, 1], alpha = roughness**2 for both specular lobes.
    specular_ior_level : float in [0, 1], Blender's Specular IOR Level (0.5 keeps the IOR's F0;
        other values scale F0 by ``2 * level`` and take the IOR of that F0, as Cycles does).
    ior : float > 1, index of refraction of the dielectric coating.
    distribution : {"GGX", "MULTI_GGX"}, as for :class:`GGX`; with "MULTI_GGX" both lobes are
        energy-compensated and the diffuse base loses what the compensated lobe gains.
    """

    base_color: float
    metallic: float = 0.0
    roughness: float = 0.5
    specular_ior_level: float = 0.5
    ior: float = 1.5
    distribution: str = "GGX"

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
        _check_distribution(self.distribution, "Principled")

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

    @property
    def eta(self) -> float:
        """The index of refraction whose Fresnel curve the specular lobe follows (Cycles'
        ``ior_from_F0`` of :attr:`f0` when ``specular_ior_level`` is not 0.5); 1 means no lobe."""
        if self.specular_ior_level == 0.5:
            return self.ior
        root = math.sqrt(min(max(self.f0, 0.0), 0.99))
        return (1.0 + root) / (1.0 - root)

    def _fresnel(self, cos_hi):
        """Cycles' generalised Schlick with a negative exponent: the dielectric curve of
        :attr:`eta`, remapped so that normal incidence gives :attr:`f0` and grazing 1."""
        f0_eta = _f0_from_ior(self.eta)
        s = np.clip((dielectric_fresnel(cos_hi, self.eta) - f0_eta) / (1.0 - f0_eta), 0.0, 1.0)
        return self.f0 + (1.0 - self.f0) * s

    def _dielectric_scattering(self):
        f0_eta = _f0_from_ior(self.eta)
        mean = min(max((fresnel_mean_fit(self.eta) - f0_eta) / (1.0 - f0_eta), 0.0), 1.0)
        return _MultipleScattering(self.roughness, self.f0 + (1.0 - self.f0) * mean)

    def specular(self, wi, wo, n):
        """The dielectric specular lobe alone, shape (m,)."""
        ci, co = _dot(wi, n), _dot(wo, n)
        return self._specular(ci, co, _dot(wi, wo), (ci > 0.0) & (co > 0.0))

    def _specular(self, ci, co, cos_io, valid):
        if self.eta == 1.0:
            return np.zeros(np.broadcast(ci, co, cos_io).shape)
        lobe, cos_hi = _ggx_lobe(ci, co, cos_io, self.alpha, "height-correlated", valid)
        value = lobe * self._fresnel(cos_hi)
        if self.distribution == "MULTI_GGX":
            value = value * self._dielectric_scattering().factor(co)
        return value

    def diffuse_weight(self, cos_o):
        """The diffuse base's weight at view cosine ``cos_o`` (to the specular lobe's normal):
        ``1 - d (F0 + (1 - F0) s)``, Cycles' ``closure_layering_weight`` of its albedo estimate
        of the specular lobe, shape of ``cos_o``."""
        cos_o = np.asarray(cos_o)
        if self.eta == 1.0:
            return np.ones(cos_o.shape)
        albedo = self.f0 + (1.0 - self.f0) * dielectric_fresnel_mean(self.roughness, cos_o, self.eta)
        if self.distribution == "MULTI_GGX":
            albedo = albedo * self._dielectric_scattering().darkening(cos_o)
        return np.clip(1.0 - albedo, 0.0, 1.0)

    def from_cosines(self, cos_i, cos_o, cos_io):
        valid = (cos_i > 0.0) & (cos_o > 0.0)
        return self._evaluate(cos_i, cos_io, cos_i, cos_o, valid, np.where(valid, 1.0, 0.0))

    def shade(self, cos_i, cos_o, cos_io, spec_cos_i=None, spec_cos_o=None):
        ci, co, valid = _specular_cosines(cos_i, cos_o, spec_cos_i, spec_cos_o)
        return self._evaluate(cos_i, cos_io, ci, co, valid, np.maximum(cos_i, 0.0), np.maximum(ci, 0.0))

    def _evaluate(self, cos_i, cos_io, ci, co, valid, diffuse_cosine, specular_cosine=1.0):
        """(1 - m) (specular + weighted base) + m metallic, each lobe times its cosine factor."""
        base = np.where(cos_i > 0.0, self.base_color / np.pi, 0.0) * self.diffuse_weight(np.clip(co, 0.0, 1.0))
        dielectric = self._specular(ci, co, cos_io, valid) * specular_cosine + base * diffuse_cosine
        if self.metallic == 0.0:
            return dielectric
        lobe, cos_hi = _ggx_lobe(ci, co, cos_io, self.alpha, "height-correlated", valid)
        metal = lobe * (self.base_color + (1.0 - self.base_color) * (1.0 - cos_hi) ** 5)
        if self.distribution == "MULTI_GGX":
            metal = metal * _MultipleScattering(
                self.roughness, self.base_color + (1.0 - self.base_color) / 21.0
            ).factor(co)
        return (1.0 - self.metallic) * dielectric + self.metallic * metal * specular_cosine

    @lru_cache(maxsize=_PACKED_KEPT)
    def packed(self):
        multi = self.distribution == "MULTI_GGX"
        # Only a MULTI_GGX lobe reads the energy-compensation tables (they cost quadrature on first use).
        fms = (0.0, 0.0)
        if multi:
            metal = _MultipleScattering(self.roughness, self.base_color + (1.0 - self.base_color) / 21.0)
            fms = (self._dielectric_scattering().fms, metal.fms)
        head = (
            _shading_kernels.PRINCIPLED,
            self.base_color,
            self.alpha,
            self.metallic,
            multi,
            self.f0,
            self.eta,
            _f0_from_ior(self.eta),
            *fms,
        )
        curves = (
            ggx_albedo(self.roughness, _E_NODES) if multi else (),
            dielectric_fresnel_mean(self.roughness, _S_NODES, self.eta) if self.eta != 1.0 else (),
        )
        return _shading_kernels.as_packed(curves, head)


@dataclass(frozen=True)
class Mix(BRDF):
    """Blender's Mix Shader: ``(1 - fac) first + fac second``.

    Parameters
    ----------
    first, second : Lambertian, GGX or Principled, the node's upper and lower shader inputs.
    fac : float in [0, 1], the node's Fac: the share of ``second``.

    The lobe a renderer samples for is the narrowest of the two whatever ``fac`` is (a fit that
    frees ``fac`` builds its cache once, at any value), and its :attr:`lobe_share` is the larger
    of its lobed inputs' (``fac`` does not dilute it).
    """

    first: BRDF
    second: BRDF
    fac: float

    def __post_init__(self):
        for name in ("first", "second"):
            value = getattr(self, name)
            if not isinstance(value, (Lambertian, GGX, Principled)):
                raise TypeError(f"Mix: {name}={value!r} must be a Lambertian, GGX or Principled BRDF")
        _check_unit_interval("fac", self.fac, "Mix")

    @property
    def lobe_width_rad(self) -> float | None:
        widths = [b.lobe_width_rad for b in (self.first, self.second) if b.lobe_width_rad]
        return min(widths) if widths else None

    @property
    def lobe_share(self) -> float:
        lobed = [b.lobe_share for b in (self.first, self.second) if b.lobe_width_rad]
        return max(lobed) if lobed else 1.0

    def from_cosines(self, cos_i, cos_o, cos_io):
        return (1.0 - self.fac) * self.first.from_cosines(cos_i, cos_o, cos_io) + self.fac * self.second.from_cosines(
            cos_i, cos_o, cos_io
        )

    def shade(self, cos_i, cos_o, cos_io, spec_cos_i=None, spec_cos_o=None):
        cosines = (cos_i, cos_o, cos_io, spec_cos_i, spec_cos_o)
        return (1.0 - self.fac) * self.first.shade(*cosines) + self.fac * self.second.shade(*cosines)

    @lru_cache(maxsize=_PACKED_KEPT)
    def packed(self):
        return _shading_kernels.as_packed_mix(self.fac, self.first.packed(), self.second.packed())


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
