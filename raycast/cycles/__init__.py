"""Blender Cycles on the same scene and directions as the renderer: the authority it is checked against.

Needs the optional ``cycles`` extra (Blender's ``bpy``); without it the functions say how to
install it. See docs/cycles.md.
"""

from raycast.cycles.runner import (
    CyclesMesh,
    CyclesResult,
    CyclesSettings,
    NoiseStudy,
    ObjImport,
    measure_noise,
    render_cycles,
)

__all__ = ["CyclesMesh", "CyclesResult", "CyclesSettings", "NoiseStudy", "ObjImport", "measure_noise", "render_cycles"]
