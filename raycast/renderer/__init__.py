"""Synthetic light curves: scenes, mesh and material readers, BRDFs, the direct renderer and its fast path.

`render(scene, body_geometry, method="auto")` is the entry point; `DirectRenderer` is the
reference and `SceneCache` the fast path a fit calls at every step. See docs/renderer.md.
"""

from raycast.renderer.brdf import BRDF, GGX, Lambertian, Principled
from raycast.renderer.cache import SceneCache
from raycast.renderer.direct import DirectRenderer
from raycast.renderer.materials import read_materials_json
from raycast.renderer.meshio import read_mesh
from raycast.renderer.methods import METHODS, LightCurveModel, render
from raycast.renderer.photometry import REFERENCE_RANGE_KM, magnitude, solar_magnitude
from raycast.renderer.scene import Articulation, Part, Scene

__all__ = [
    "BRDF",
    "GGX",
    "Lambertian",
    "Principled",
    "SceneCache",
    "DirectRenderer",
    "read_materials_json",
    "read_mesh",
    "METHODS",
    "LightCurveModel",
    "render",
    "REFERENCE_RANGE_KM",
    "magnitude",
    "solar_magnitude",
    "Articulation",
    "Part",
    "Scene",
]
