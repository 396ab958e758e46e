"""TOPEX/Poseidon (NORAD 22076), a plausible shape and material model built by code.

Dimensions (public sources; the layout below is ours, within their stated sizes):

* Spacecraft envelope 5.5 m x 2.8 m x 6.6 m including the instrument module; launch mass
  2400 kg (NASA/JPL TOPEX/Poseidon mission fact sheet; ESA eoPortal "TOPEX/Poseidon").
* Single-wing solar array of 8.89 m x 3.30 m on a boom, rotating about the boom (pitch) axis
  (eoPortal; Kucharski et al. 2017, GRL 44, "Spin rate of TOPEX/Poseidon"). The reference paper
  fitted a pitch near 12 deg, the default here.
* A 1.5 m high-gain (TDRSS) antenna dish on a mast at the top of the bus (eoPortal).

Uncertainties: the split between the multimission bus and the instrument module, the boom
length (1.5 m here), the mast height (1 m) and the dish's position are not in the sources and
are guesses of +-0.5 m; surface finishes are generic (MLI blankets as glossy foil, solar cells
as dark glossy glass, radiators as white diffuse paint).

Body frame: +Z is the long (former yaw) axis, the high-gain antenna at +Z; the solar-array boom
leaves the bus along +Y; at ``panel_pitch_deg = 0`` the cells face +X, and the pitch rotates
the array about the boom axis (+Y, right-hand rule).
"""

from __future__ import annotations

import numpy as np

from raycast.renderer.brdf import GGX, Lambertian
from raycast.renderer.scene import Articulation, Part, Scene

__all__ = ["build", "MATERIALS", "ARRAY_SIZE_M", "ENVELOPE_M"]

ENVELOPE_M = (5.5, 2.8, 6.6)
ARRAY_SIZE_M = (8.89, 3.30)
BOOM_LENGTH_M = 1.5
ARRAY_THICKNESS_M = 0.03

MATERIALS = {
    "mli_foil": GGX(color=0.45, roughness=0.35),
    "radiator": Lambertian(albedo=0.80),
    "solar_cells": GGX(color=0.08, roughness=0.15),
    "array_back": Lambertian(albedo=0.15),
    "antenna": Lambertian(albedo=0.70),
    "boom": Lambertian(albedo=0.50),
}


def build(panel_pitch_deg: float = 12.0, materials: dict | None = None) -> Scene:
    """The TOPEX/Poseidon scene.

    Parameters
    ----------
    panel_pitch_deg : float, solar-array pitch about the boom axis (articulation parameter).
    materials : dict, optional, replacement BRDFs by material name (see :data:`MATERIALS`).
    """
    brdfs = {**MATERIALS, **(materials or {})}
    width_x, depth_y, height_z = ENVELOPE_M
    # Instrument module (lower, full width) and multimission bus (upper, narrower).
    module = Part.box(
        "instrument_module",
        (width_x, depth_y, 3.4),
        "mli_foil",
        center_m=(0.0, 0.0, -1.6),
        face_materials={"+x": "radiator"},
    )
    bus = Part.box(
        "bus", (2.8, depth_y, 3.2), "mli_foil", center_m=(-1.35, 0.0, 1.7), face_materials={"-x": "radiator"}
    )
    mast = Part.box("mast", (0.15, 0.15, 1.0), "boom", center_m=(-1.35, 0.0, 3.3 + 0.5))
    dish = Part.dish("antenna", 1.5, 0.25, "antenna").transformed(offset_m=(-1.35, 0.0, 4.3))
    boom_root = np.array([-1.35, depth_y / 2.0, 2.4])
    boom = Part.box("boom", (0.1, BOOM_LENGTH_M, 0.1), "boom", center_m=boom_root + [0.0, BOOM_LENGTH_M / 2.0, 0.0])
    length, width = ARRAY_SIZE_M
    array = Part.box(
        "solar_array",
        (ARRAY_THICKNESS_M, length, width),
        "array_back",
        center_m=boom_root + [0.0, BOOM_LENGTH_M + length / 2.0, 0.0],
        face_materials={"+x": "solar_cells"},
    )
    articulation = Articulation(
        part="solar_array",
        parameter="panel_pitch_deg",
        axis_point_m=tuple(boom_root),
        axis=(0.0, 1.0, 0.0),
        rest_deg=0.0,
    )
    return Scene.from_parts(
        [module, bus, mast, dish, boom, array],
        brdfs,
        articulations=[articulation],
        parameters={"panel_pitch_deg": panel_pitch_deg},
        name="topex",
    )
