"""A generic satellite for objects without a model of their own: a box with two solar-panel wings.

The "box with panels" rung of the model ladder (rsodb.campaign.ladder, docs/real_passes.md),
between the analytic box and an object's own model. Its bus is the analytic box rung's box
(`BUS_SIZE_M`, the bounding box of the analytic ellipsoid), so the two rungs differ only by the
wings: what panels add to a box is their glint and the shadows between them and the bus, which
need the renderer (an analytic convex body has neither).

Body frame: the bus's edges along x (longest), y and z; the fits' attitude families spin the body
about z, so the bus tumbles end over end. The wings leave the bus along +y and -y, each
`WING_SIZE_M` (span along y, width along z) at `WING_GAP_M` from the bus (their yokes are left
out); at ``panel_pitch_deg = 0`` their cells face +x and their backs -x, and the pitch turns both
about +y (right hand). With cells on one side only, the body looks the same only after a whole
turn: its light curve repeats once per spin.

Surface classes (`SURFACE_PARAMETERS`): the solar array's cells and back
(`raycast.models.surfaces.SOLAR_ARRAY_PARAMETERS`) and the bus's diffuse albedo; every size is
fixed, since the absolute brightness is fitted as an offset and only the proportions of the
light matter.
"""

from __future__ import annotations

from raycast.models.surfaces import SOLAR_ARRAY_PARAMETERS, SurfaceParameter, checked_surfaces, solar_array_brdfs
from raycast.renderer.brdf import Lambertian
from raycast.renderer.scene import Articulation, Part, Scene

__all__ = [
    "build",
    "surface_brdfs",
    "SURFACE_PARAMETERS",
    "BUS_ALBEDO",
    "BUS_SIZE_M",
    "WING_SIZE_M",
    "WING_GAP_M",
    "WING_THICKNESS_M",
]

# The analytic box rung's box: the bounding box of the analytic ellipsoid (semi-axes 1 x 0.5 x 0.35 m).
BUS_SIZE_M = (2.0, 1.0, 0.7)
# Each wing: 2.5 m along y by 1.0 m along z, so that the two wings (5 m^2) outweigh the bus's
# largest face (2 m^2), as on most satellites with deployed arrays.
WING_SIZE_M = (2.5, 1.0)
WING_GAP_M = 0.3
WING_THICKNESS_M = 0.03

BUS_ALBEDO = SurfaceParameter(
    0.4,
    0.02,
    0.9,
    "bus: diffuse (Lambertian) albedo",
    "from black Kapton (about 0.05) to white paint and bare aluminium (0.8-0.9): H.M. Rodriguez et al., "
    "AMOS 2007; Willison & Bedard, AMOS",
)
# In the order of TOPEX's: the cells, the bus, the array's back.
SURFACE_PARAMETERS = {
    "cells_specular": SOLAR_ARRAY_PARAMETERS["cells_specular"],
    "cells_roughness": SOLAR_ARRAY_PARAMETERS["cells_roughness"],
    "bus_albedo": BUS_ALBEDO,
    "back_albedo": SOLAR_ARRAY_PARAMETERS["back_albedo"],
}


def surface_brdfs(**values) -> dict:
    """The BRDF of every material of the model for given surface parameters.

    Parameters
    ----------
    **values : float
        Any of `SURFACE_PARAMETERS` (the rest take their defaults).
    """
    p = checked_surfaces(values, SURFACE_PARAMETERS, "box_panels")
    return {"bus": Lambertian(albedo=p["bus_albedo"]), **solar_array_brdfs(p)}


def build(panel_pitch_deg: float = 0.0, **surface) -> Scene:
    """The box-with-panels scene.

    Parameters
    ----------
    panel_pitch_deg : float
        The wings' pitch about body +y (the articulation parameter); at 0 the cells face +x.
    **surface : float
        Surface parameters (`SURFACE_PARAMETERS`); the rest take their defaults.
    """
    span, width = WING_SIZE_M
    parts = [Part.box("bus", BUS_SIZE_M, "bus")]
    articulations = []
    for side, sign in (("+y", 1.0), ("-y", -1.0)):
        centre_y = sign * (BUS_SIZE_M[1] / 2.0 + WING_GAP_M + span / 2.0)
        name = f"wing{side}"
        parts.append(
            Part.box(
                name,
                (WING_THICKNESS_M, span, width),
                "array_back",
                center_m=(0.0, centre_y, 0.0),
                face_materials={"+x": "solar_cells"},
            )
        )
        articulations.append(
            Articulation(part=name, parameter="panel_pitch_deg", axis_point_m=(0.0, 0.0, 0.0), axis=(0.0, 1.0, 0.0))
        )
    return Scene.from_parts(
        parts,
        surface_brdfs(**surface),
        articulations=articulations,
        parameters={"panel_pitch_deg": float(panel_pitch_deg)},
        name="box_panels",
    )
