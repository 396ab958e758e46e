"""Materials: from sidecar JSON records (and .mtl fallbacks) to BRDF objects.

The sidecar JSON (``model.materials.json``, see ../shared/data/models) maps material names to
records naming the Blender node they came from:

``{"blender_node": "Glossy BSDF", "color": [r, g, b], "roughness": 0.3}``
    -> :class:`raycast.renderer.brdf.GGX`
``{"blender_node": "Principled BSDF", "base_color": [r, g, b], "metallic": 0, "roughness": 0.5,
"specular_ior_level": 0.5, "ior": 1.45}``
    -> :class:`raycast.renderer.brdf.Principled` (``ior`` optional: see below)
``{"blender_node": "Diffuse BSDF", "color": [r, g, b]}``
    -> :class:`raycast.renderer.brdf.Lambertian`
``{"blender_node": "Mix Shader", "fac": 0.2, "shaders": [record, record]}``
    -> :class:`raycast.renderer.brdf.Mix` of two of the records above, ``(1 - fac) first + fac second``

Glossy and Principled records may name Blender's microfacet ``distribution``: ``"GGX"`` (the
default here, single scattering) or ``"MULTI_GGX"`` (Blender 5's default for new nodes).

Colours are Blender's linear RGB. A light curve is rendered in one band, so each colour is
reduced to one number by a *channel*: ``"green"`` for V (the default; the green primary of
linear sRGB peaks near 545 nm, the V band near 550 nm), ``"blue"`` for B, ``"red"`` for R and I,
or ``"mean"``. :data:`BAND_CHANNELS` holds that mapping.

The Principled IOR: the JSON may give ``ior``; when it does not, the ``Ni`` of the same
material in the OBJ's .mtl is used (Blender's OBJ exporter writes the Principled node's IOR
there), and without either Blender's default 1.5.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from ingest.errors import FormatError
from raycast.renderer.brdf import BRDF, GGX, Lambertian, Mix, Principled

__all__ = ["CHANNELS", "BAND_CHANNELS", "brdf_from_record", "read_materials_json", "brdf_from_mtl", "channel_for_band"]

CHANNELS = {"red": 0, "green": 1, "blue": 2}
BAND_CHANNELS = {"B": "blue", "V": "green", "R": "red", "I": "red"}


def channel_for_band(band: str) -> str:
    """The RGB channel that stands for ``band`` (see :data:`BAND_CHANNELS`)."""
    key = str(band).strip().upper()
    if key not in BAND_CHANNELS:
        raise ValueError(f"band {band!r} has no colour channel; use one of {', '.join(BAND_CHANNELS)}")
    return BAND_CHANNELS[key]


def _reduce_color(value, channel: str, where: str) -> float:
    if isinstance(value, (int, float)):
        return float(value)
    if not isinstance(value, (list, tuple)) or len(value) < 3:
        raise ValueError(f"{where}: colour {value!r} is not a number or an [r, g, b] list")
    rgb = [float(v) for v in value[:3]]
    if channel == "mean":
        return sum(rgb) / 3.0
    if channel not in CHANNELS:
        raise ValueError(f"channel {channel!r} is unknown; use one of {', '.join(CHANNELS)} or 'mean'")
    return rgb[CHANNELS[channel]]


def brdf_from_record(name: str, record: dict, channel: str = "green", mtl_ior: float | None = None) -> BRDF:
    """Build the BRDF described by one sidecar-JSON material record.

    Parameters
    ----------
    name : str, the material name (for error messages).
    record : dict, the JSON record (keys in the module docstring).
    channel : str, ``"red"``, ``"green"``, ``"blue"`` or ``"mean"``.
    mtl_ior : float, optional, the .mtl ``Ni`` of this material (Principled IOR fallback).
    """
    node = str(record.get("blender_node", "")).strip().lower()
    where = f"material {name!r}"
    try:
        if node in ("glossy bsdf", "glossy", "ggx"):
            return GGX(
                color=_reduce_color(record["color"], channel, where),
                roughness=float(record["roughness"]),
                masking=record.get("masking", "height-correlated"),
                distribution=record.get("distribution", "GGX"),
            )
        if node in ("principled bsdf", "principled"):
            ior = record.get("ior", mtl_ior if mtl_ior is not None and mtl_ior > 1.0 else 1.5)
            return Principled(
                base_color=_reduce_color(record["base_color"], channel, where),
                metallic=float(record.get("metallic", 0.0)),
                roughness=float(record.get("roughness", 0.5)),
                specular_ior_level=float(record.get("specular_ior_level", 0.5)),
                ior=float(ior),
                distribution=record.get("distribution", "GGX"),
            )
        if node in ("diffuse bsdf", "diffuse", "lambertian"):
            return Lambertian(albedo=_reduce_color(record["color"], channel, where))
        if node in ("mix shader", "mix"):
            shaders = record["shaders"]
            if not isinstance(shaders, list) or len(shaders) != 2 or not all(isinstance(r, dict) for r in shaders):
                raise ValueError(f"shaders={shaders!r} is not a list of two node records")
            first, second = (brdf_from_record(name, r, channel, mtl_ior) for r in shaders)
            return Mix(first, second, float(record["fac"]))
    except KeyError as missing:
        raise ValueError(f"{where}: record {record!r} lacks the key {missing}; add it to the materials JSON") from None
    except (TypeError, ValueError) as error:
        message = str(error)
        raise ValueError(message if message.startswith(where) else f"{where}: {message}") from None
    raise ValueError(
        f"{where}: blender_node {record.get('blender_node')!r} is not supported; use "
        "'Glossy BSDF', 'Principled BSDF', 'Diffuse BSDF' or 'Mix Shader'"
    )


def read_materials_json(path) -> dict:
    """Read a sidecar materials JSON; returns ``{name: record}``."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"materials file {path} does not exist; pass the sidecar .materials.json") from None
    except json.JSONDecodeError as error:
        raise FormatError(path, error.lineno, f"not valid JSON ({error.msg})") from None
    materials = data.get("materials") if isinstance(data, dict) else None
    if not isinstance(materials, dict):
        raise FormatError(path, None, 'no "materials" object; give {"materials": {name: entry, ...}}')
    return materials


def brdf_from_mtl(name: str, mtl_record: dict, channel: str = "green") -> BRDF:
    """Fallback when no sidecar JSON names a material: Lambertian with the .mtl diffuse ``Kd``."""
    kd = mtl_record.get("Kd")
    if kd is None:
        raise ValueError(
            f"material {name!r} has neither a sidecar JSON record nor a .mtl Kd; add it to the materials JSON"
        )
    albedo = _reduce_color(kd, channel, f"material {name!r}")
    if not math.isfinite(albedo):
        raise ValueError(f"material {name!r}: Kd {kd!r} is not finite")
    return Lambertian(albedo=min(max(albedo, 0.0), 1.0))
