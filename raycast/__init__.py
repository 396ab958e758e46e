"""The physical scene: orbit and observer geometry, attitude, shapes, BRDFs and the renderer.

Two halves that do not import each other: `raycast.geometry` (orbit, site, Sun, attitude: the
body-frame Sun and observer directions of every frame) and `raycast.renderer` (scenes, BRDFs,
the direct renderer and its fast path); `raycast.cycles` compares with Blender Cycles and
`raycast.models` holds models built by code. raycast never imports rsodb.

>>> import raycast
>>> geometry = raycast.PassGeometry.from_pass(observed_pass)                     # doctest: +SKIP
>>> body = geometry.body_frame(raycast.PrecessingSpin(period_s=9.5))             # doctest: +SKIP
>>> model = raycast.render(raycast.models.topex.build(), body, band="V")         # doctest: +SKIP
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submodules=["geometry", "renderer", "cycles", "models"],
    submod_attrs={
        "geometry": ["Satellite", "PassGeometry", "BodyGeometry", "PrecessingSpin", "InertialSpin", "TorqueFree"],
        "renderer": [
            "Scene",
            "render",
            "LightCurveModel",
            "DirectRenderer",
            "SceneCache",
            "Lambertian",
            "GGX",
            "Principled",
            "magnitude",
        ],
    },
)
