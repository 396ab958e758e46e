"""Compiled (numba) shading: the BRDFs of :mod:`raycast.renderer.brdf` over the solar disk, one
point at a time.

The numpy methods of the BRDF classes (``shade``) are the reference; this module evaluates the
same formulas point by point, so the renderers' shading makes no (points, disk samples)
temporaries and the fast path sums each lit (frame, class) pair straight into its frame.
tests/test_shading_kernels.py holds the two to 1e-12 on every BRDF, option and shape.

A BRDF reaches the kernels as one float64 array (:meth:`raycast.renderer.brdf.BRDF.packed`):

====  ==========  =========================  ==============================================
slot  Lambertian  GGX                        Principled
====  ==========  =========================  ==============================================
0     0 (kind)    1                          2
1     albedo      color                      base_color
2                 alpha                      alpha
3                 1 if separable masking     metallic
4                 1 if MULTI_GGX             1 if MULTI_GGX
5                 Fms                        F0 of the dielectric lobe
6                                            eta (1: no dielectric lobe)
7                                            F0 of eta
8                                            Fms of the dielectric lobe
9                                            Fms of the metallic lobe
16+               E(mu) at 32 nodes          E(mu) at 32 nodes, then s(mu) at 16 nodes
====  ==========  =========================  ==============================================

A Mix (Blender's Mix Shader) is kind 3 with its fac in slot 1, followed by its two inputs' packed
arrays (:func:`as_packed_mix`); its inputs are never mixes themselves.

E and s are :mod:`raycast.renderer.ggx_tables`' curves at the BRDF's roughness (and eta),
interpolated linearly in mu as np.interp does, so the tables' values are the reference's own.
"""

import math

from numba import njit
import numpy as np

from raycast.renderer.rays import SUN_RADIUS_RAD, risen_sun, sun_fraction

LAMBERTIAN, GGX, PRINCIPLED, MIX = 0, 1, 2, 3
CURVES = 16
E_NODES, S_NODES = 32, 16
# Length of one packed BRDF; a Mix holds its two inputs after its own.
SIZE = CURVES + E_NODES + S_NODES


@njit(cache=True, nogil=True)
def _curve(packed, start, n, mu):
    """Linear interpolation of ``packed[start:start + n]`` at ``mu`` over nodes i / (n - 1), mu
    clamped to [0, 1] (np.interp's rule)."""
    if mu <= 0.0:
        return packed[start]
    if mu >= 1.0:
        return packed[start + n - 1]
    x = mu * (n - 1)
    low = min(int(x), n - 2)
    t = (mu - low / (n - 1)) / (1.0 / (n - 1))
    return packed[start + low] + t * (packed[start + low + 1] - packed[start + low])


@njit(cache=True, nogil=True)
def _scattering(packed, fms, mu):
    """Cycles' multiple-scattering factor 1 + Fms (1 - E) / E at view cosine ``mu``."""
    e = _curve(packed, CURVES, E_NODES, mu)
    return 1.0 + fms * (1.0 - e) / max(e, 1e-6)


@njit(cache=True, nogil=True)
def ggx_lobe(ci, co, cos_io, alpha, separable):
    """D G / (4 cos i cos o) of GGX at one valid pair of cosines (both > 0)."""
    h_len = math.sqrt(max(2.0 + 2.0 * cos_io, 0.0))
    cos_nh = min(max((ci + co) / (h_len if h_len > 0.0 else 1.0), 0.0), 1.0)
    alpha2 = alpha * alpha
    lam_i = smith_lambda(ci, alpha2)
    lam_o = smith_lambda(co, alpha2)
    g = 1.0 / ((1.0 + lam_i) * (1.0 + lam_o)) if separable else 1.0 / (1.0 + lam_i + lam_o)
    d = alpha2 / (math.pi * (1.0 + (alpha2 - 1.0) * cos_nh * cos_nh) ** 2)
    return d * g / (4.0 * ci * co)


@njit(cache=True, nogil=True)
def smith_lambda(cos_n, alpha2):
    """Smith Lambda of GGX at one cosine, ``alpha2`` = alpha**2."""
    c2 = min(max(cos_n * cos_n, 1e-300), 1.0)
    return 0.5 * (math.sqrt(1.0 + alpha2 * max(1.0 / c2 - 1.0, 0.0)) - 1.0)


@njit(cache=True, nogil=True)
def _dielectric_fresnel(c, eta):
    c = abs(c)
    g2 = eta * eta - 1.0 + c * c
    if not g2 > 0.0:
        return 1.0
    g = math.sqrt(g2)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


@njit(cache=True, nogil=True)
def shade(packed, cos_i, cos_o, cos_io, spec_i, spec_o, bent):
    """f_r cos(i) as :meth:`raycast.renderer.brdf.BRDF.shade` gives it, at one point; with
    ``bent`` the specular lobes use the cosines ``spec_i``, ``spec_o`` to the bent normal."""
    if packed[0] != MIX:
        return _shade_one(packed, cos_i, cos_o, cos_io, spec_i, spec_o, bent)
    first = _shade_one(packed[SIZE : 2 * SIZE], cos_i, cos_o, cos_io, spec_i, spec_o, bent)
    second = _shade_one(packed[2 * SIZE :], cos_i, cos_o, cos_io, spec_i, spec_o, bent)
    return (1.0 - packed[1]) * first + packed[1] * second


@njit(cache=True, nogil=True)
def _shade_one(packed, cos_i, cos_o, cos_io, spec_i, spec_o, bent):
    """:func:`shade` of one Lambertian, GGX or Principled BRDF."""
    kind = packed[0]
    if kind == LAMBERTIAN:
        return packed[1] / math.pi * max(cos_i, 0.0)
    if bent:
        ci, co = spec_i, spec_o
        valid = cos_i > 0.0 and spec_i > 0.0 and spec_o > 0.0
    else:
        ci, co = cos_i, cos_o
        valid = cos_i > 0.0 and cos_o > 0.0
    alpha, multi = packed[2], packed[4] != 0.0
    lobe = ggx_lobe(ci, co, cos_io, alpha, kind == GGX and packed[3] != 0.0) if valid else 0.0
    if kind == GGX:
        value = packed[1] * lobe * max(ci, 0.0)
        return value * _scattering(packed, packed[5], co) if multi else value
    base_color, metallic, f0, eta = packed[1], packed[3], packed[5], packed[6]
    mu = min(max(co, 0.0), 1.0)
    cos_hi = min(max(0.5 * math.sqrt(max(2.0 + 2.0 * cos_io, 0.0)), 0.0), 1.0)
    specular, weight = 0.0, 1.0
    if eta != 1.0:
        f0_eta = packed[7]
        s = min(max((_dielectric_fresnel(cos_hi, eta) - f0_eta) / (1.0 - f0_eta), 0.0), 1.0)
        specular = lobe * (f0 + (1.0 - f0) * s)
        albedo = f0 + (1.0 - f0) * _curve(packed, CURVES + E_NODES, S_NODES, mu)
        if multi:
            specular *= _scattering(packed, packed[8], co)
            e = _curve(packed, CURVES, E_NODES, mu)
            albedo *= e + packed[8] * (1.0 - e)
        weight = min(max(1.0 - albedo, 0.0), 1.0)
    base = base_color / math.pi * weight if cos_i > 0.0 else 0.0
    dielectric = specular * max(ci, 0.0) + base * max(cos_i, 0.0)
    if metallic == 0.0:
        return dielectric
    metal = lobe * (base_color + (1.0 - base_color) * (1.0 - cos_hi) ** 5)
    if multi:
        metal *= _scattering(packed, packed[9], co)
    return (1.0 - metallic) * dielectric + metallic * metal * max(ci, 0.0)


@njit(cache=True, nogil=True)
def bent_normal(gx, gy, gz, ox, oy, oz, sx, sy, sz):
    """Cycles' valid-reflection normal of one shading normal s, face normal g and view o
    (:func:`raycast.renderer.brdf.valid_reflection_normal`)."""
    i_z = ox * gx + oy * gy + oz * gz
    cos_sg = sx * gx + sy * gy + sz * gz
    mirror_z = 2.0 * (sx * ox + sy * oy + sz * oz) * cos_sg - i_z
    threshold = min(0.9 * i_z, 0.01)
    if not mirror_z < threshold:
        return sx, sy, sz
    x, y, z = sx - cos_sg * gx, sy - cos_sg * gy, sz - cos_sg * gz
    length = math.sqrt(x * x + y * y + z * z)
    if length > 0.0:
        x, y, z = x / length, y / length, z / length
    else:
        x, y, z = sx, sy, sz
    i_x = ox * x + oy * y + oz * z
    a = i_x * i_x + i_z * i_z
    b = 2.0 * (a + i_z * threshold)
    c = (threshold + i_z) ** 2
    root = math.sqrt(max(b * b - 4.0 * a * c, 0.0))
    n_z2 = 0.25 * (b + root) / a if i_x < 0.0 else 0.25 * (b - root) / a
    along, up = math.sqrt(max(1.0 - n_z2, 0.0)), math.sqrt(max(n_z2, 0.0))
    return along * x + up * gx, along * y + up * gy, along * z + up * gz


@njit(cache=True, nogil=True)
def shaded_pairs(
    packed, offsets, weights, bend, disk_share, rows, frames, into, area, normal, geo, wo, sun, sun_u, sun_v, total
):
    """Add area x :func:`raycast.renderer.shading.disk_shading` of the pairs ``rows`` into
    ``total[into[r]]``: pair ``r`` has ``area[r]``, normals ``normal[r]``, ``geo[r]`` and frame
    ``f = frames[r]``, whose vectors are ``wo[f]``, ``sun[f]``, ``sun_u[f]``, ``sun_v[f]``. With
    ``disk_share`` each value is also multiplied by the share of the solar disk above the face
    (:func:`raycast.renderer.rays.sun_fraction` of ``geo[r] . sun[f]``).

    One loop, all in scalars: a helper taking array rows (views) or the arrays themselves costs
    three times the shading.
    """
    for r in rows:
        f = frames[r]
        nx, ny, nz = normal[r, 0], normal[r, 1], normal[r, 2]
        gx, gy, gz = geo[r, 0], geo[r, 1], geo[r, 2]
        ox, oy, oz = wo[f, 0], wo[f, 1], wo[f, 2]
        cx, cy, cz = risen_sun(gx, gy, gz, sun[f, 0], sun[f, 1], sun[f, 2])
        cos_o = nx * ox + ny * oy + nz * oz
        bx, by, bz = nx, ny, nz
        if bend:
            bx, by, bz = bent_normal(gx, gy, gz, ox, oy, oz, nx, ny, nz)
        spec_o = bx * ox + by * oy + bz * oz
        value = 0.0
        for q in range(len(weights)):
            du, dv = offsets[q, 0], offsets[q, 1]
            wx, wy, wz = cx, cy, cz
            if du != 0.0 or dv != 0.0:
                wx = cx + SUN_RADIUS_RAD * (du * sun_u[f, 0] + dv * sun_v[f, 0])
                wy = cy + SUN_RADIUS_RAD * (du * sun_u[f, 1] + dv * sun_v[f, 1])
                wz = cz + SUN_RADIUS_RAD * (du * sun_u[f, 2] + dv * sun_v[f, 2])
                norm = math.sqrt(wx * wx + wy * wy + wz * wz)
                wx, wy, wz = wx / norm, wy / norm, wz / norm
            cos_i = nx * wx + ny * wy + nz * wz
            cos_io = wx * ox + wy * oy + wz * oz
            spec_i = bx * wx + by * wy + bz * wz
            value += weights[q] * shade(packed, cos_i, cos_o, cos_io, spec_i, spec_o, bend)
        if disk_share:
            value *= sun_fraction(gx * sun[f, 0] + gy * sun[f, 1] + gz * sun[f, 2])
        total[into[r]] += area[r] * value


def as_packed_mix(fac, first, second):
    """A packed Mix: its own slots (kind, fac), then its two inputs' packed arrays."""
    head = np.zeros(SIZE)
    head[0], head[1] = MIX, fac
    return np.concatenate([head, first, second])


def as_packed(lobe_curves, head):
    """A packed BRDF (module docstring): ``head`` (the slots before the curves) and its curves."""
    packed = np.zeros(SIZE)
    packed[: len(head)] = head
    for start, curve in zip((CURVES, CURVES + E_NODES), lobe_curves):
        packed[start : start + len(curve)] = curve
    return packed
