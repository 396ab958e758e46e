"""Surface classes of code-built models: a free reflectance parameter, its prior range and source.

A model built by code (`raycast.models.topex`, `raycast.models.box_panels`) names a few surface
classes, each with few parameters, so that a fit can learn them; each parameter carries its
default, the range a fit's prior takes and where that range comes from.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from raycast.renderer.brdf import Lambertian, Principled

__all__ = ["SurfaceParameter", "checked_surfaces", "SOLAR_ARRAY_PARAMETERS", "solar_array_brdfs", "CELLS_DIFFUSE"]

# The solar cells' dark diffuse layer under the cover glass (fixed, not fitted).
CELLS_DIFFUSE = 0.05


@dataclass(frozen=True)
class SurfaceParameter:
    """A free reflectance parameter of one surface class, with its prior range and source."""

    default: float
    low: float
    high: float
    meaning: str
    source: str


def checked_surfaces(values, table, model: str) -> dict:
    """Every parameter of `table` (defaults for those not given), each checked against its range.

    Parameters
    ----------
    values : mapping of str to float
        The parameters given.
    table : mapping of str to SurfaceParameter
        The model's surface parameters.
    model : str
        The model's name, for the error messages.
    """
    unknown = sorted(set(values) - set(table))
    if unknown:
        raise ValueError(f"unknown {model} surface parameter(s) {unknown}; known: {', '.join(table)}")
    p = {name: float(values.get(name, spec.default)) for name, spec in table.items()}
    for name, value in p.items():
        spec = table[name]
        if not (math.isfinite(value) and spec.low <= value <= spec.high):
            raise ValueError(
                f"{model} surface parameter {name}={value!r} is outside its range [{spec.low}, {spec.high}]"
            )
    return p


# A solar array's two sides, on any satellite: the cells' cover glass and the array's back.
SOLAR_ARRAY_PARAMETERS = {
    "cells_specular": SurfaceParameter(
        0.5,
        0.5,
        1.0,
        "solar cells: Specular IOR Level of the cover glass (F0 = 0.08 x level at IOR 1.5)",
        "first-surface specular reflectance of cells 0.04-0.125 (Space Solar Power Review 1(3), 1980)",
    ),
    "cells_roughness": SurfaceParameter(
        0.15,
        0.05,
        0.5,
        "solar cells: roughness of the specular lobe (alpha = roughness^2)",
        "a narrow main specular peak (Small, Butler & Marciniak 2021, Opt. Express 29, 35501)",
    ),
    "back_albedo": SurfaceParameter(
        0.5,
        0.05,
        0.8,
        "solar-array back: diffuse albedo",
        "Kapton array substrate, diffuse 0.67 new (Space Solar Power Review 1(3), 1980), darker with age",
    ),
}


def solar_array_brdfs(p) -> dict:
    """The BRDFs of a solar array's ``solar_cells`` and ``array_back`` materials from checked
    parameter values `p` (`SOLAR_ARRAY_PARAMETERS` among them)."""
    return {
        "solar_cells": Principled(
            base_color=CELLS_DIFFUSE, roughness=p["cells_roughness"], specular_ior_level=p["cells_specular"]
        ),
        "array_back": Lambertian(albedo=p["back_albedo"]),
    }
