"""GGX albedo tables as Blender Cycles defines them, computed here by quadrature.

Cycles weighs the Principled BSDF's diffuse layer and compensates multiple scattering with
three tables of the GGX microfacet lobe (docs/renderer.md, "BRDFs and Blender"). This module
computes the same integrals on the same grids and reads them the same way (separable linear
interpolation, coordinates clamped to [0, 1]), so that the project's BRDFs weigh their layers
as Cycles does, table error included. Nothing is copied from Blender: each node is an integral
evaluated on first use by a deterministic quadrature over half vectors.

* :func:`ggx_albedo` E(r, mu): directional albedo of GGX (Fresnel 1, height-correlated masking)
  seen at cos(view) = mu; grid 32 x 32 over roughness r and mu.
* :func:`ggx_average_albedo` E_avg(r) = integral of 2 mu E(r, mu) over mu; 32 nodes.
* :func:`dielectric_fresnel_mean` s(r, mu, eta): the mean over the visible normals (the VNDF
  measure, G1 of the view only; directions below the surface count as 0) of
  ``clamp((F(h.v, eta) - F0) / (1 - F0), 0, 1)``, F the dielectric Fresnel; grid 16 x 16 x 16
  over r, mu and z = ((eta - 1) / (eta + 1)) ** 0.5 (so F0 = z**4).

Grid node i of n stands for the value i / (n - 1) of its coordinate, clamped to [1e-4, 1]
(roughness, mu) or [1e-4, 0.99] (z), as in Cycles' precomputation.

A node costs 0.3-0.5 s of quadrature, and a Principled material needs four to eight: each
computed node is kept on disk, in ``$RSODB_CACHE_DIR`` (default ``~/.cache/rsodb``) under
``ggx_tables/<SHA-256 of this module's source>/``, so a changed quadrature computes anew and
a fresh process (a fit's workers, the CLI) reads what an earlier one computed.
"""

from __future__ import annotations

from functools import cache, wraps
import hashlib
import math
import os
from pathlib import Path
import tempfile

import numpy as np

__all__ = ["ggx_albedo", "ggx_average_albedo", "dielectric_fresnel_mean", "dielectric_fresnel", "fresnel_mean_fit"]

_E_SIZE = 32
_S_SIZE = 16
# Half vectors per integral: stratified in the GGX distribution's CDF (t) and in azimuth.
_N_T, _N_PHI = 384, 192
# Gauss-Legendre nodes over mu for E_avg.
_N_MU_AVG = 48


def dielectric_fresnel(cos_i, eta):
    """Unpolarised Fresnel reflectance of a dielectric of relative index ``eta``, shape of ``cos_i``."""
    c = np.abs(cos_i)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return np.where(g2 > 0.0, 0.5 * a * a * (1.0 + b * b), 1.0)


def fresnel_mean_fit(eta):
    """Kulla and Conty's fit of the hemispherical mean 2 int F(c, eta) c dc, as Cycles uses it."""
    if eta < 1.0:
        return 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607))
    return (eta - 1.0) / (4.08567 + 1.00071 * eta)


def _node(index, size, low, high):
    return min(max(index / (size - 1), low), high)


def _half_vectors(alpha):
    """(k, 3) half vectors stratified by the density D(h) cos(h) of GGX with width ``alpha``."""
    t = (np.arange(_N_T) + 0.5) / _N_T
    phi = (np.arange(_N_PHI) + 0.5) / _N_PHI * 2.0 * np.pi
    tan_h = alpha * np.sqrt(t / (1.0 - t))
    cos_h = 1.0 / np.sqrt(1.0 + tan_h**2)
    sin_h = tan_h * cos_h
    return np.stack(
        [
            (sin_h[:, None] * np.cos(phi)[None, :]).ravel(),
            (sin_h[:, None] * np.sin(phi)[None, :]).ravel(),
            np.repeat(cos_h, _N_PHI),
        ],
        axis=1,
    )


def smith_lambda(cos_n, alpha):
    """Smith Lambda of GGX for a direction at cosine ``cos_n`` to the normal, shape (m,)."""
    c2 = np.clip(cos_n * cos_n, 1e-300, 1.0)
    tan2 = np.maximum(1.0 / c2 - 1.0, 0.0)
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def _hemisphere_means(roughness, mu, fresnel=None):
    """Means over half vectors h ~ D(h) cos(h) for the view at cosine ``mu``: the albedo
    integrand G2 (h.v) / (mu cos h) and, with ``fresnel`` (a function of h.v), the VNDF
    integrand G1(v) (h.v) / (mu cos h) * fresnel(h.v); both zero where the mirrored direction
    is below the surface."""
    alpha = roughness * roughness
    h = _half_vectors(alpha)
    view = np.array([math.sqrt(max(1.0 - mu * mu, 0.0)), 0.0, mu])
    cos_hv = h @ view
    cos_l = 2.0 * cos_hv * h[:, 2] - mu
    ok = (cos_hv > 0.0) & (cos_l > 0.0)
    lam_v = smith_lambda(np.array(mu), alpha)
    jacobian = np.where(ok, cos_hv / (mu * h[:, 2]), 0.0)
    if fresnel is None:
        lam_l = smith_lambda(np.where(ok, cos_l, 1.0), alpha)
        return float(np.mean(jacobian / (1.0 + lam_v + lam_l)))
    return float(np.mean(jacobian / (1.0 + lam_v) * fresnel(np.clip(cos_hv, 0.0, 1.0))))


def _table_dir():
    root = Path(os.environ.get("RSODB_CACHE_DIR", Path.home() / ".cache" / "rsodb"))
    return root / "ggx_tables" / hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]


def _stored(compute):
    """Keep each node ``compute(*indices)`` in memory and on disk (module docstring)."""

    @cache
    @wraps(compute)
    def node(*indices):
        path = _table_dir() / f"{compute.__name__.strip('_')}-{'-'.join(map(str, indices))}.npy"
        try:
            return np.load(path)
        except (OSError, ValueError):
            pass  # not computed yet, or damaged (by something else: writes are atomic): computed anew
        value = np.asarray(compute(*indices), dtype=float)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".tmp", delete=False) as handle:
                np.save(handle, value)
            os.replace(handle.name, path)  # readers never see half a file
        except OSError:
            pass  # a read-only cache directory costs time, not correctness
        return value

    return node


@_stored
def _e_column(rough_index):
    """(32,) E at one roughness node over the mu nodes."""
    roughness = _node(rough_index, _E_SIZE, 1e-4, 1.0)
    return np.array(
        [_hemisphere_means(roughness, _node(j, _E_SIZE, 1e-4, 1.0)) for j in range(_E_SIZE)], dtype=float
    ).clip(0.0, 1.0)


@_stored
def _e_average(rough_index):
    roughness = _node(rough_index, _E_SIZE, 1e-4, 1.0)
    nodes, weights = np.polynomial.legendre.leggauss(_N_MU_AVG)
    mus = 0.5 * (nodes + 1.0)
    values = np.array([_hemisphere_means(roughness, mu) for mu in mus])
    return float(np.clip(np.sum(0.5 * weights * 2.0 * mus * values), 0.0, 1.0))


@_stored
def _s_column(rough_index, z_index):
    """(16,) s at one (roughness, z) node over the mu nodes."""
    roughness = _node(rough_index, _S_SIZE, 1e-4, 1.0)
    z = _node(z_index, _S_SIZE, 1e-4, 0.99)
    f0 = z**4
    sqrt_f0 = math.sqrt(min(max(f0, 0.0), 0.99))
    eta = (1.0 + sqrt_f0) / (1.0 - sqrt_f0)

    def remapped(cos_hv):
        return np.clip((dielectric_fresnel(cos_hv, eta) - f0) / (1.0 - f0), 0.0, 1.0)

    return np.array(
        [_hemisphere_means(roughness, _node(j, _S_SIZE, 1e-4, 1.0), remapped) for j in range(_S_SIZE)],
        dtype=float,
    ).clip(0.0, 1.0)


def _position(value, size):
    """Lower node, upper node and weight of ``value`` (clamped to [0, 1]) on a grid of ``size``."""
    x = np.clip(value, 0.0, 1.0) * (size - 1)
    low = np.minimum(np.floor(x).astype(np.int64), size - 1)
    high = np.minimum(low + 1, size - 1)
    return low, high, x - low


def _interpolate_mu(column, mu):
    """Linear interpolation of a column over its mu nodes, mu clamped to [0, 1] (as np.interp does)."""
    return np.interp(mu, np.linspace(0.0, 1.0, len(column)), column)


@cache
def _e_curve(roughness):
    """(32,) E over the mu nodes at ``roughness``: the two roughness columns mixed once, so a
    call interpolates over mu only (linear interpolation is linear in the nodes' values)."""
    low, high, t = _position(roughness, _E_SIZE)
    curve = (1.0 - t) * _e_column(int(low))
    if t > 0.0:
        curve = curve + t * _e_column(int(high))
    return curve


@cache
def _s_curve(roughness, z):
    """(16,) s over the mu nodes at (``roughness``, ``z``), mixed as :func:`_e_curve`."""
    r_low, r_high, r_t = _position(roughness, _S_SIZE)
    z_low, z_high, z_t = _position(z, _S_SIZE)
    curve = np.zeros(_S_SIZE)
    for r_index, r_weight in ((r_low, 1.0 - r_t), (r_high, r_t)):
        for z_index, z_weight in ((z_low, 1.0 - z_t), (z_high, z_t)):
            if r_weight * z_weight > 0.0:
                curve = curve + r_weight * z_weight * _s_column(int(r_index), int(z_index))
    return curve


def ggx_albedo(roughness, mu):
    """E(roughness, mu): directional albedo of GGX (Fresnel 1) at view cosine ``mu`` (array)."""
    return _interpolate_mu(_e_curve(float(roughness)), np.asarray(mu, dtype=float))


def ggx_average_albedo(roughness):
    """E_avg(roughness): E averaged over the hemisphere with weight 2 mu."""
    low, high, t = _position(float(roughness), _E_SIZE)
    value = (1.0 - t) * _e_average(int(low))
    if t > 0.0:
        value += t * _e_average(int(high))
    return float(value)


def dielectric_fresnel_mean(roughness, mu, eta):
    """s(roughness, mu, eta): the VNDF mean of the remapped dielectric Fresnel (module docstring)."""
    z = math.sqrt(abs((eta - 1.0) / (eta + 1.0)))
    return _interpolate_mu(_s_curve(float(roughness), z), np.asarray(mu, dtype=float))
