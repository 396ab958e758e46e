"""TOPEX/Poseidon (NORAD 22076) from published dimensions and layout, with fittable surface classes.

docs/models.md gives the source of every dimension and every prior, and says what is assumed.
Body frame (the mission's): +z yaw (nadir in normal operations; the axis TOPEX spins about
today), +y pitch (the solar-array axis), +x roll. The array leaves the bus along -y (port side);
at ``panel_pitch_deg = 0`` its cells face +x, and the pitch turns it about +y (right hand).
"""

from __future__ import annotations

import math

import numpy as np

from raycast.models.surfaces import SOLAR_ARRAY_PARAMETERS, SurfaceParameter, checked_surfaces, solar_array_brdfs
from raycast.renderer.brdf import GGX, Lambertian, Principled
from raycast.renderer.scene import Articulation, Part, Scene

__all__ = [
    "build",
    "surface_brdfs",
    "louvered_surface_brdfs",
    "SurfaceParameter",
    "SURFACE_PARAMETERS",
    "LOUVERED_SURFACE_PARAMETERS",
    "LOUVER_SIZE_M",
    "LOUVER_OPEN_DEG",
    "BUS_SIZE_M",
    "BUS_FACE_AREAS_M2",
    "ARRAY_SIZE_M",
    "ALTIMETER_DIAMETER_M",
    "HGA_DIAMETER_M",
    "HGA_BOOM_M",
    "YOKE_M",
]

# The IDS radiation-pressure macro-model's box (Cerri et al., as used by Sagnieres, Sharf &
# Deleflie 2020): faces of 8.32 (x-y), 8.18 (x-z) and 4.71 (y-z) m^2; the edges follow.
BUS_FACE_AREAS_M2 = {"xy": 8.32, "xz": 8.18, "yz": 4.71}
_X = math.sqrt(BUS_FACE_AREAS_M2["xy"] * BUS_FACE_AREAS_M2["xz"] / BUS_FACE_AREAS_M2["yz"])
BUS_SIZE_M = (_X, BUS_FACE_AREAS_M2["xy"] / _X, BUS_FACE_AREAS_M2["xz"] / _X)
# Single wing, 8.89 m x 3.30 m (JPL "Perspectives on an Ocean Planet"), pitching about body y
# through the bus (Sagnieres et al. 2020).
ARRAY_SIZE_M = (8.89, 3.30)
ARRAY_THICKNESS_M = 0.04
# Gap between the bus's -y face and the array's inner edge: not published (the yoke); assumed.
YOKE_M = 1.0
# Radar altimeter dish on the nadir face (AVISO, TOPEX altimeter): 1.5 m.
ALTIMETER_DIAMETER_M = 1.5
ALTIMETER_DEPTH_M = 0.25
# TDRSS high-gain antenna: 1.3 m dish on a 2.6 m boom on the zenith side (JPL, HGA page).
HGA_DIAMETER_M = 1.3
HGA_DEPTH_M = 0.2
HGA_BOOM_M = 2.6


# Fixed parts of the surface classes (not fitted; the cells' dark diffuse layer is
# raycast.models.surfaces.CELLS_DIFFUSE): the dielectric specular level of the bus, and the
# antenna boom's white paint (the dishes' default, and their fixed value before antenna_albedo
# was a parameter).
BUS_SPECULAR = 0.5
ANTENNA_ALBEDO = 0.7


SURFACE_PARAMETERS = {
    "cells_specular": SOLAR_ARRAY_PARAMETERS["cells_specular"],
    "cells_roughness": SOLAR_ARRAY_PARAMETERS["cells_roughness"],
    "bus_albedo": SurfaceParameter(
        0.4,
        0.02,
        0.9,
        "bus (MLI blankets, aluminium instrument module): base colour, the diffuse albedo of its "
        "dielectric part and the reflectance of its metallic part",
        "from black Kapton (about 0.05) to white paint and bare aluminium (0.8-0.9): MLI and aluminium "
        "panels, Rodriguez et al., AMOS 2007; Willison & Bedard, AMOS",
    ),
    "bus_metallic": SurfaceParameter(
        0.0,
        0.0,
        1.0,
        "bus: metallic fraction, the share of its area that reflects like a metal (aluminised MLI foil), "
        "a conductor lobe in place of the diffuse layer",
        "MLI outer layers are often aluminised or foil, the instrument module's louvers bare metal "
        "(JPL, instrument module page); the share on TOPEX is not published, hence 0-1",
    ),
    "bus_roughness": SurfaceParameter(
        0.35,
        0.1,
        0.8,
        "bus: roughness of its glossy lobes (alpha = roughness^2); wrinkled MLI spreads the glint",
        "crinkled MLI reflects in a lobe tens of degrees wide (Rodriguez et al., AMOS 2007)",
    ),
    "back_albedo": SOLAR_ARRAY_PARAMETERS["back_albedo"],
    "antenna_albedo": SurfaceParameter(
        ANTENNA_ALBEDO,
        0.05,
        0.9,
        "the altimeter's and the high-gain antenna's dishes: diffuse albedo",
        "the dishes' finish on TOPEX is not published; reflectors are painted white (0.7-0.9) or covered by a "
        "black Kapton sunshield (about 0.05), the range of Rodriguez et al., AMOS 2007",
    ),
}
# The louvered variant (`build(louvers=True)`): the instrument module's walls carry thermal-control
# louvers ("thermal control louvers in the IM walls open and close", JPL, "TOPEX/Poseidon:
# Perspectives on an Ocean Planet", Instrument Module page), polished blades that reflect like
# mirrors; their number, size and place on TOPEX are not published. Assumed: one louver of
# LOUVER_SIZE_M square at the middle of each side wall, its blades (one flat plate here) turned
# LOUVER_OPEN_DEG about the wall's horizontal axis so that their normal leans toward +z. The
# angle is read from the residuals of the 2024-07-30 pass (docs/real_passes.md, its glint map):
# the glints that the box cannot make fall where the Sun-observer bisector stands 12-15 deg above
# the spin equator at three walls' azimuths. The nadir (+z) face, which carries the altimeter and
# the radiometer, gets its own reflectance.
LOUVER_SIZE_M = 1.0
LOUVER_OPEN_DEG = 13.0
LOUVERED_SURFACE_PARAMETERS = {
    **SURFACE_PARAMETERS,
    "nadir_albedo": SurfaceParameter(
        0.4,
        0.02,
        0.9,
        "bus nadir (+z) face: base colour, as bus_albedo for the other faces (metallic fraction and roughness shared)",
        "as bus_albedo: black Kapton to white paint and bare aluminium (Rodriguez et al., AMOS 2007)",
    ),
    "louver_reflectance": SurfaceParameter(
        0.3,
        0.0,
        1.0,
        f"louvers: reflectance of a {LOUVER_SIZE_M:g} m square mirror-like plate per wall (area x reflectance is "
        "what the light measures; the louvers' real area is not published)",
        "louver blades are polished metal, and polished aluminium reflects about 0.9 of visible light; closed "
        "blades overlap and shade each other, hence 0-1",
    ),
    "louver_roughness": SurfaceParameter(
        0.2,
        0.05,
        0.5,
        "louvers: roughness of their glossy lobe (alpha = roughness^2)",
        "as cells_roughness: from a polished mirror's narrow lobe to a worn blade's broad one",
    ),
}


def surface_brdfs(**values) -> dict:
    """The BRDF of every material of the model for given surface parameters.

    Parameters
    ----------
    **values : float
        Any of `SURFACE_PARAMETERS` (the rest take their defaults).

    Returns
    -------
    dict of str to BRDF
        Keyed by the model's material names.
    """
    p = checked_surfaces(values, SURFACE_PARAMETERS, "TOPEX")
    array = solar_array_brdfs(p)
    return {
        "solar_cells": array["solar_cells"],
        "bus": Principled(
            base_color=p["bus_albedo"],
            metallic=p["bus_metallic"],
            roughness=p["bus_roughness"],
            specular_ior_level=BUS_SPECULAR,
        ),
        "array_back": array["array_back"],
        "antenna": Lambertian(albedo=p["antenna_albedo"]),
        "boom": Lambertian(albedo=ANTENNA_ALBEDO),
    }


def louvered_surface_brdfs(**values) -> dict:
    """`surface_brdfs` of the louvered variant: the nadir face and the louvers added.

    Parameters
    ----------
    **values : float
        Any of `LOUVERED_SURFACE_PARAMETERS` (the rest take their defaults).
    """
    p = checked_surfaces(values, LOUVERED_SURFACE_PARAMETERS, "TOPEX")
    brdfs = surface_brdfs(**{name: p[name] for name in SURFACE_PARAMETERS})
    brdfs["nadir"] = Principled(
        base_color=p["nadir_albedo"],
        metallic=p["bus_metallic"],
        roughness=p["bus_roughness"],
        specular_ior_level=BUS_SPECULAR,
    )
    brdfs["louvers"] = GGX(color=p["louver_reflectance"], roughness=p["louver_roughness"])
    return brdfs


def _louvers(bus_size_m) -> list:
    """One louver plate in front of each side wall, its normal leaning LOUVER_OPEN_DEG toward +z."""
    tilt = math.radians(LOUVER_OPEN_DEG)
    up = np.array([0.0, 0.0, 1.0])
    plates = []
    for name, outward, half in (
        ("+x", (1.0, 0.0, 0.0), bus_size_m[0] / 2.0),
        ("-x", (-1.0, 0.0, 0.0), bus_size_m[0] / 2.0),
        ("+y", (0.0, 1.0, 0.0), bus_size_m[1] / 2.0),
        ("-y", (0.0, -1.0, 0.0), bus_size_m[1] / 2.0),
    ):
        wall = np.array(outward)
        across = np.cross(up, wall)
        normal = math.cos(tilt) * wall + math.sin(tilt) * up
        # The plate's own axes (x across the wall, y up the blade, z its normal) in body axes.
        rotation = np.column_stack([across, np.cross(normal, across), normal])
        # Clear of the wall: the tilted plate's lower edge stands 2 cm in front of it.
        stand_off = half + LOUVER_SIZE_M / 2.0 * math.sin(tilt) + 0.02
        plate = Part.plate(f"louver{name}", LOUVER_SIZE_M, LOUVER_SIZE_M, "louvers")
        plates.append(plate.transformed(rotation=rotation, offset_m=wall * stand_off))
    return plates


def build(panel_pitch_deg: float = 12.0, louvers: bool = False, **surface) -> Scene:
    """The TOPEX/Poseidon scene.

    Parameters
    ----------
    panel_pitch_deg : float
        Solar-array pitch about body +y (the articulation parameter); the published fits put the
        array normal 10-12 deg from body x.
    louvers : bool
        The louvered variant: a louver on each side wall and the nadir face's own reflectance
        (`LOUVERED_SURFACE_PARAMETERS`, `louvered_surface_brdfs`).
    **surface : float
        Surface parameters (`SURFACE_PARAMETERS`, or `LOUVERED_SURFACE_PARAMETERS` with
        `louvers`); the rest take their defaults.
    """
    x_m, y_m, z_m = BUS_SIZE_M
    bus = Part.box("bus", BUS_SIZE_M, "bus", face_materials={"+z": "nadir"} if louvers else None)
    altimeter = Part.dish("altimeter", ALTIMETER_DIAMETER_M, ALTIMETER_DEPTH_M, "antenna").transformed(
        offset_m=(0.0, 0.0, z_m / 2.0)
    )
    boom = Part.box("hga_boom", (0.08, 0.08, HGA_BOOM_M), "boom", center_m=(0.0, 0.0, -z_m / 2.0 - HGA_BOOM_M / 2.0))
    # The dish opens toward -z (zenith, toward TDRSS): the +z-opening dish turned about x.
    flip = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
    hga = Part.dish("hga", HGA_DIAMETER_M, HGA_DEPTH_M, "antenna").transformed(
        rotation=flip, offset_m=(0.0, 0.0, -z_m / 2.0 - HGA_BOOM_M)
    )
    length, width = ARRAY_SIZE_M
    inner = -y_m / 2.0 - YOKE_M
    yoke = Part.box("yoke", (0.1, YOKE_M, 0.1), "boom", center_m=(0.0, -y_m / 2.0 - YOKE_M / 2.0, 0.0))
    array = Part.box(
        "solar_array",
        (ARRAY_THICKNESS_M, length, width),
        "array_back",
        center_m=(0.0, inner - length / 2.0, 0.0),
        face_materials={"+x": "solar_cells"},
    )
    articulation = Articulation(
        part="solar_array",
        parameter="panel_pitch_deg",
        axis_point_m=(0.0, 0.0, 0.0),
        axis=(0.0, 1.0, 0.0),
        rest_deg=0.0,
    )
    parts = [bus, altimeter, boom, hga, yoke, array]
    return Scene.from_parts(
        parts + _louvers(BUS_SIZE_M) if louvers else parts,
        louvered_surface_brdfs(**surface) if louvers else surface_brdfs(**surface),
        articulations=[articulation],
        parameters={"panel_pitch_deg": panel_pitch_deg},
        name="topex_louvered" if louvers else "topex",
    )
