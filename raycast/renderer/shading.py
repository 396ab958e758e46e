"""What a surface point reflects per unit solar irradiance: the BRDF over the solar disk, with
shading normals treated as Blender Cycles treats them.

:func:`disk_shading` is shared by the direct renderer (per hit) and the fast path (per shading
class and frame): f_r(s, o) cos(i) averaged over a quadrature of the Sun's disk
(:func:`raycast.renderer.rays.sun_disk_rule`), where

* specular lobes on smooth-shaded surfaces are evaluated about the valid-reflection normal
  (:func:`raycast.renderer.brdf.valid_reflection_normal`) unless the scene asks for the stricter
  treatment (``Scene.specular_normals``);
* a Sun whose disk is partly below the face's plane lights it from the centroid of the part
  above (:func:`raycast.renderer.rays.risen_sun`); the share of the disk above the plane
  (:func:`raycast.renderer.rays.sun_fraction`) is the caller's to apply, with the face's other
  gates.

The BRDFs of :mod:`raycast.renderer.brdf` are evaluated by compiled loops
(:mod:`raycast.renderer._shading_kernels`, 5-10x faster, no temporaries); a BRDF without a
packed form, and :func:`reference_disk_shading` always, go through its numpy ``shade``.
"""

from __future__ import annotations

import numpy as np

from raycast.renderer import _shading_kernels
from raycast.renderer.brdf import valid_reflection_normal
from raycast.renderer.rays import SUN_RADIUS_RAD, risen_suns, sun_disk_rule, sun_fractions

__all__ = ["disk_shading", "reference_disk_shading", "shaded_pairs"]


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def disk_shading(brdf, n_samples, normal, geo, wo, sun, sun_u, sun_v, bend):
    """f(s, o, n) cos(i) (:meth:`raycast.renderer.brdf.BRDF.shade`) averaged over the solar disk.

    Parameters
    ----------
    brdf : BRDF
    n_samples : int, points of the disk quadrature (1, 7 or 24).
    normal : (k, 3) float, unit shading normals.
    geo : (k, 3) float, unit face normals turned toward the observer.
    wo, sun : (k, 3) float, unit vectors toward the observer and the Sun's centre.
    sun_u, sun_v : (k, 3) float, two unit vectors across each ``sun`` (the disk's axes).
    bend : bool, evaluate specular lobes about the valid-reflection normal.

    Returns
    -------
    (k,) float
    """
    # Each point is a pair of its own frame, added into its own slot.
    points = np.arange(len(normal))
    out = np.zeros(len(normal))
    shaded_pairs(
        brdf, n_samples, points, points, points, np.ones(len(normal)), normal, geo, wo, sun, sun_u, sun_v, bend, out
    )
    return out


def shaded_pairs(
    brdf, n_samples, rows, frames, into, area, normal, geo, obs, sun, sun_u, sun_v, bend, total, disk_share=False
):
    """Add ``area`` x :func:`disk_shading` of the pairs ``rows`` into ``total[into]``.

    Parameters
    ----------
    brdf, n_samples, bend : as :func:`disk_shading`.
    rows : (r,) int64, the pairs to shade (indices into the per-pair arrays).
    frames : (k,) int64, each pair's frame (the row of the per-frame vectors it is seen with).
    into : (k,) int64, where in ``total`` each pair's value is added (its frame, or its own slot).
    area : (k,) float, each pair's weight.
    normal, geo : (k, 3) float, each pair's shading and turned face normal.
    obs, sun, sun_u, sun_v : (m, 3) float, per frame, as ``wo``, ``sun``, ``sun_u``, ``sun_v``.
    total : float array, added to in place.
    disk_share : bool, also multiply by the share of the solar disk above each face
        (:func:`raycast.renderer.rays.sun_fraction`; the direct renderer's hits; the fast path's
        areas already hold it).
    """
    packed = brdf.packed()
    if packed is None:
        f = frames[rows]
        shading = reference_disk_shading(
            brdf, n_samples, normal[rows], geo[rows], obs[f], sun[f], sun_u[f], sun_v[f], bend
        )
        if disk_share:
            shading *= sun_fractions(np.einsum("ij,ij->i", geo[rows], sun[f]))
        total += np.bincount(into[rows], weights=area[rows] * shading, minlength=len(total))
        return
    offsets, weights = sun_disk_rule(n_samples)
    per_pair = (np.ascontiguousarray(a, dtype=float) for a in (area, normal, geo, obs, sun, sun_u, sun_v))
    _shading_kernels.shaded_pairs(
        packed, offsets, weights, bool(bend), bool(disk_share), rows, frames, into, *per_pair, total
    )


def reference_disk_shading(brdf, n_samples, normal, geo, wo, sun, sun_u, sun_v, bend):
    """:func:`disk_shading` through the BRDF's numpy ``shade``: the reference of the compiled loops."""
    centre = risen_suns(np.ascontiguousarray(geo, dtype=float), np.ascontiguousarray(sun, dtype=float))
    cos_o = _dot(normal, wo)
    spec_normal, spec_o = None, None
    if bend and brdf.lobe_width_rad:
        spec_normal = valid_reflection_normal(geo, wo, normal)
        spec_o = _dot(spec_normal, wo)
    offsets, weights = sun_disk_rule(n_samples)
    total = np.zeros(len(normal))
    for (du, dv), weight in zip(offsets, weights):
        wi = centre
        if du or dv:
            wi = centre + SUN_RADIUS_RAD * (du * sun_u + dv * sun_v)
            wi /= np.linalg.norm(wi, axis=1, keepdims=True)
        spec_i = None if spec_normal is None else _dot(spec_normal, wi)
        total += weight * brdf.shade(_dot(normal, wi), cos_o, _dot(wi, wo), spec_i, spec_o)
    return total
