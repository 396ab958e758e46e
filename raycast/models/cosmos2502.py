"""A COSMOS 2502 (Lotos-S1) look-alike built by code.

After the reference paper's model (../shared/data/models/cosmos2502_lotos.*): a cylinder
3.5 m in diameter and 12 m long along +Z (smooth shading), two 4 m x 7 m solar panels
perpendicular to the tube near its +Z end, reaching out along +-X, and a cross of two
5.5 m x 0.6 m x 0.12 m beams at the -Z end. Materials follow the paper's JSON (green channel):
the tube a Principled dielectric of base colour 0.359, the panel cells Blender Glossy of colour
0.076 and roughness 0.3, panel backs and tube ends a dark Principled (0.064), the cross 0.163.
"""

from __future__ import annotations

from raycast.renderer.brdf import GGX, Principled
from raycast.renderer.scene import Part, Scene

__all__ = ["build", "MATERIALS"]

MATERIALS = {
    "body_1": Principled(base_color=0.3588, roughness=0.5, specular_ior_level=0.5, ior=1.45),
    "body_2": Principled(base_color=0.0637, roughness=0.5, specular_ior_level=0.5, ior=1.45),
    "b_cross": Principled(base_color=0.1626, roughness=0.5, specular_ior_level=0.5, ior=1.45),
    "spb_2": GGX(color=0.0763, roughness=0.3),
}


def build(materials: dict | None = None, segments: int = 48) -> Scene:
    """The COSMOS 2502 look-alike scene.

    Parameters
    ----------
    materials : dict, optional, replacement BRDFs by material name (see :data:`MATERIALS`).
    segments : int, facets around the tube.
    """
    brdfs = {**MATERIALS, **(materials or {})}
    tube = Part.cylinder("tube", 1.75, 12.0, "body_1", segments=segments, cap_material="body_2")
    panels = [
        Part.box(
            f"panel_{side}",
            (4.0, 7.0, 0.19),
            "body_2",
            center_m=(sign * 3.85, 0.0, 5.7),
            face_materials={"+z": "spb_2"},
        )
        for side, sign in (("plus_x", 1.0), ("minus_x", -1.0))
    ]
    cross = [
        Part.box("cross_x", (5.5, 0.6, 0.12), "b_cross", center_m=(0.0, 0.0, -5.92)),
        Part.box("cross_y", (0.6, 5.5, 0.12), "b_cross", center_m=(0.0, 0.0, -5.92)),
    ]
    return Scene.from_parts([tube, *panels, *cross], brdfs, name="cosmos2502")
