"""Shapes a fit can use, and how their brightness function is built once per fit.

``SHAPES`` maps a name to a built-in `Shape`; `mesh_shape` makes a `Shape` of any mesh file
(OBJ, PLY, glTF) with its materials JSON and articulations, and `resolve_shape` picks one from a
fit's ``[model]`` section. A `Shape` says how to build the `raycast.renderer.scene.Scene` (or,
for the analytic bodies, a `ConvexFacets`), which articulation parameters it has and their
default values. `brightness_for` turns a shape and the fit's free parameters into the object the
forward model calls at every step, ``intensity(sun_body, obs_body, **parameters)``:

``renderer="cached"`` (default)
    `raycast.renderer.cache.SceneCache`, built once per (scene content, settings) and kept by a
    `rsodb.fit.shape_store.ShapeStore` (on disk beside the archive for archived passes). A free
    articulation parameter (e.g. TOPEX's ``panel_pitch_deg``) gets an articulation grid over its
    prior's range; a fixed one is baked into the scene.
``renderer="direct"``
    `raycast.renderer.direct.DirectRenderer`: the slow reference, for checks.

A model's surface parameters (`Shape.surfaces`, e.g. TOPEX's ``bus_metallic``) work the same way:
`SurfaceClasses` builds the materials from them at each call (``Shape.surface_brdfs``), and the
cache is built with every free roughness at the smoothest value its prior allows.

Material scalars (``albedo_scale``, ``roughness``) are not parameters of the cache: the cache
holds geometry and visibility, and evaluates each material's BRDF at run time. `MaterialScalars`
therefore swaps the scene's BRDFs for rescaled copies (``Scene.with_brdfs``) before each call,
which changes no precomputed table. The cache's glint sampling (element size along smooth
normals, solar-disk samples) is chosen from the smoothest roughness the prior allows.

The built-in models built by code approximate real objects (``topex``: TOPEX/Poseidon from its
published dimensions; ``cosmos2502``: a look-alike of the published workflow's COSMOS 2502 mesh; docs/fitting.md
says how far each is from its original) or stand for none (``box_panels``: the generic satellite,
a box with two solar-panel wings); to fit the published workflow's own model, give its
mesh file (``[model] mesh``, see configs/cosmos2502_paper.toml).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
import functools
import math
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from raycast.models import box_panels, cosmos2502, topex
from raycast.renderer.brdf import GGX, Lambertian, Principled
from raycast.renderer.cache import SceneCache
from raycast.renderer.direct import DirectRenderer
from raycast.renderer.rays import sun_samples_for
from raycast.renderer.scene import Articulation, Scene
from rsodb.fit.model import ConvexFacets
from rsodb.fit.shape_store import ShapeStore

__all__ = [
    "Shape",
    "SHAPES",
    "AUTO_SHAPES",
    "MATERIAL_PARAMETERS",
    "MaterialScalars",
    "SurfaceClasses",
    "brightness_for",
    "cache_grid_size",
    "mesh_shape",
    "resolve_shape",
    "articulation_from_dict",
    "shape_for_norad",
]

MATERIAL_PARAMETERS = ("albedo_scale", "roughness")
# Articulation grid points per degree of a free articulation's prior range (at least 3).
_GRID_PER_DEG = 0.5
# The cache's cube-map resolution: the renderer's default, and the finer one of fits planning
# at least FINE_GRID_FRAME_EVALUATIONS (walkers x steps x frames an evaluation).
CACHE_GRID_SIZE = 32
FINE_CACHE_GRID_SIZE = 64
FINE_GRID_FRAME_EVALUATIONS = 2_000_000


def cache_grid_size(frame_evaluations: float) -> int:
    """The cube-map resolution of a fit's cache, for a sampler planning ``frame_evaluations``
    (walkers x steps x the frames, exposure sub-samples included, of one evaluation).

    The exact shadow rays that decide the pairs near a shadow edge fall as 1/N with the
    resolution N; the build's rays grow as N^2. Measured on one core (docs/fitting.md): from
    N = 32 to 64 an evaluation of the whole TOPEX pass (4640 frames) takes 123 -> 79 ms for
    3 -> 11 s of build, the paper's COSMOS 2502 mesh on 600 frames 79 -> 55 ms for 29 -> 100
    s: the finer grid repays its build from about 1.8e6 frame-evaluations on the paper mesh.
    N = 96 saved nothing on the TOPEX pass: its exact rays cost 15 ms less, reading the 66 MB
    table (30 MB at 64, within the 32 MB cache of this machine's processor) 14 ms more.
    """
    return FINE_CACHE_GRID_SIZE if frame_evaluations >= FINE_GRID_FRAME_EVALUATIONS else CACHE_GRID_SIZE


@dataclass(frozen=True)
class Shape:
    """A model a fit can use.

    Attributes
    ----------
    build : callable
        ``build() -> Scene`` (or ``ConvexFacets`` when `analytic`); a module-level function or a
        ``functools.partial`` of one, so shapes pickle.
    articulations : mapping of str to float
        Articulation parameters and their default (fixed) values.
    analytic : bool
        True for closed-form convex bodies, which need no renderer.
    description : str
    surfaces : mapping of str to SurfaceParameter
        The model's surface-class parameters (default, prior range, meaning, source; e.g.
        `raycast.models.topex.SURFACE_PARAMETERS`), fixed at their defaults unless a fit frees them.
    surface_brdfs : callable, optional
        ``surface_brdfs(**values) -> {material: BRDF}`` for those parameters (a module-level
        function, so shapes pickle).
    """

    build: Callable
    articulations: Mapping[str, float]
    analytic: bool
    description: str
    surfaces: Mapping[str, Any] = field(default_factory=dict)
    surface_brdfs: Callable | None = None

    @property
    def surface_defaults(self) -> dict[str, float]:
        """Every surface parameter at its default value."""
        return {name: float(spec.default) for name, spec in self.surfaces.items()}


def _topex():
    return topex.build()


def _topex_louvered():
    return topex.build(louvers=True)


def _cosmos2502():
    return cosmos2502.build()


def _box():
    return ConvexFacets.box(box_panels.BUS_SIZE_M, albedo=0.2)


def _box_panels():
    return box_panels.build()


def _ellipsoid():
    return ConvexFacets.ellipsoid((1.0, 0.5, 0.35), subdivisions=2, albedo=0.2)


def _lopsided():
    body = ConvexFacets.ellipsoid((1.0, 0.5, 0.35), subdivisions=2, albedo=0.2)
    # Bright +x half, dark -x half, brighter still where +y: no rotation maps the body onto itself.
    albedo = np.where(body.normals[:, 0] > 0, 0.3, 0.1) + np.where(body.normals[:, 1] > 0, 0.1, 0.0)
    return ConvexFacets(body.normals, body.areas_m2, albedo)


SHAPES: Mapping[str, Shape] = MappingProxyType(
    {
        "topex": Shape(
            _topex,
            {"panel_pitch_deg": 12.0},
            False,
            "TOPEX/Poseidon approximated by code from its published dimensions (raycast.models.topex): bus, "
            "instrument module, solar array (pitch 12 deg per the published fit), antennas; layout and "
            "finishes are guesses within the published sizes; its surface classes are fit parameters "
            "(raycast.models.topex.SURFACE_PARAMETERS)",
            topex.SURFACE_PARAMETERS,
            topex.surface_brdfs,
        ),
        "topex_louvered": Shape(
            _topex_louvered,
            {"panel_pitch_deg": 12.0},
            False,
            "the topex model with a thermal louver on each instrument-module wall, its blades leaning "
            f"{topex.LOUVER_OPEN_DEG:g} deg toward nadir, and a nadir face of its own reflectance (raycast.models.topex, build(louvers=True)); "
            "the louvers' size, place and angle are assumed (docs/models.md)",
            topex.LOUVERED_SURFACE_PARAMETERS,
            topex.louvered_surface_brdfs,
        ),
        "cosmos2502": Shape(
            _cosmos2502,
            {},
            False,
            "a look-alike of the published workflow's COSMOS 2502 (Lotos-S1) mesh built by code "
            "(raycast.models.cosmos2502): cylinder, two panels, cross; not that mesh, whose file a fit takes "
            "with [model] mesh (configs/cosmos2502_paper.toml)",
        ),
        "box": Shape(
            _box,
            {},
            True,
            "a 2 x 1 x 0.7 m Lambertian box, its longest edge along body x, albedo 0.2 (analytic; the "
            "analytic ellipsoid's bounding box: spinning about z it tumbles end over end and repeats every half turn)",
        ),
        "box_panels": Shape(
            _box_panels,
            {"panel_pitch_deg": 0.0},
            False,
            "the box with two solar-panel wings along body y, cells facing +x at pitch 0 (raycast.models.box_panels): "
            "the generic satellite for objects without a model; its surface classes are fit parameters",
            box_panels.SURFACE_PARAMETERS,
            box_panels.surface_brdfs,
        ),
        "ellipsoid": Shape(
            _ellipsoid,
            {},
            True,
            "a Lambertian triaxial ellipsoid, semi-axes 1 x 0.5 x 0.35 m along body x, y, z, albedo 0.2, "
            "320 facets (analytic; the generic shape for objects without a model: spinning about z "
            "it tumbles end over end)",
        ),
        "lopsided": Shape(
            _lopsided,
            {},
            True,
            "the ellipsoid with albedo 0.4 / 0.3 / 0.2 / 0.1 on its +x+y / +x-y / -x+y / -x-y quarters: "
            "no rotational symmetry, so every phase is observable (for calibration studies)",
        ),
    }
)

# Objects whose model the project has, by NORAD number.
AUTO_SHAPES: Mapping[int, str] = MappingProxyType({22076: "topex", 40358: "cosmos2502"})
ARTICULATION_KEYS = ("parameter", "part", "axis", "point_m", "rest_deg")


def shape_for_norad(norad: int, fallback: str | None = "ellipsoid") -> str:
    """The shape name for an object: its own model when known, else `fallback`."""
    if norad in AUTO_SHAPES:
        return AUTO_SHAPES[norad]
    if fallback is None:
        raise ValueError(
            f"no model of NORAD {norad} is known (known: {', '.join(f'{k} {v}' for k, v in AUTO_SHAPES.items())}); "
            f"name a shape in the fit configuration ([model] shape = one of {', '.join(SHAPES)}, or mesh = PATH)"
        )
    return fallback


def articulation_from_dict(record: Mapping, where: str = "[model] articulations") -> Articulation:
    """An `Articulation` from its configuration form.

    ``{parameter = "panel_pitch_deg", part = "Sat_sp1", axis = [1, 0, 0], point_m = [0, 0, 5],
    rest_deg = 0}``: the part (an OBJ object or group name) turns about the axis through the point
    by the parameter's value minus ``rest_deg``.
    """
    unknown = sorted(set(record) - set(ARTICULATION_KEYS))
    missing = [k for k in ("parameter", "part", "axis") if k not in record]
    if unknown or missing:
        raise ValueError(
            f"{where}: an articulation needs parameter, part and axis (optional point_m, rest_deg); "
            f"got {sorted(record)}"
        )
    name = record["parameter"]
    if not (isinstance(name, str) and name.endswith("_deg") and name.isidentifier()):
        raise ValueError(f"{where}: parameter {name!r} must be a name ending in _deg, e.g. 'panel_pitch_deg'")
    return Articulation(
        part=str(record["part"]),
        parameter=name,
        axis_point_m=tuple(record.get("point_m", (0.0, 0.0, 0.0))),
        axis=tuple(record["axis"]),
        rest_deg=float(record.get("rest_deg", 0.0)),
    )


def _mesh_scene(path: str, materials: str | None, articulations: tuple, repair: bool) -> Scene:
    return Scene.from_file(
        path,
        materials=materials,
        articulations=tuple(articulation_from_dict(a) for a in articulations),
        repair=repair,
    )


def mesh_shape(path, materials=None, articulations: Sequence[Mapping] = (), repair: bool = False) -> Shape:
    """A `Shape` read from a mesh file with its materials JSON.

    Parameters
    ----------
    path : str or Path
        OBJ (with ``usemtl`` groups and ``vn`` shading normals), PLY or glTF.
    materials : str or Path, optional
        The sidecar materials JSON (BSDF per material); without it an OBJ's ``.mtl`` colours are
        read as Lambertian.
    articulations : sequence of mapping
        Articulated parts in the configuration form (`articulation_from_dict`).
    repair : bool
        Keep one face of each set of coincident faces (a zero-thickness plate) instead of refusing.
    """
    path = Path(path)
    for what, file in (("mesh", path), ("materials", materials)):
        if file is not None and not Path(file).is_file():
            raise FileNotFoundError(
                f"[model] {what} = {str(file)!r} does not exist; give the path of the "
                + ("OBJ, PLY or glTF file" if what == "mesh" else "materials JSON")
            )
    records = tuple(dict(a) for a in articulations)
    parsed = [articulation_from_dict(a) for a in records]
    build = functools.partial(
        _mesh_scene, str(path.resolve()), None if materials is None else str(Path(materials).resolve()), records, repair
    )
    return Shape(
        build,
        {a.parameter: a.rest_deg for a in parsed},
        False,
        f"the mesh {path.name}"
        + (f" with the materials {Path(materials).name}" if materials else "")
        + (f", articulated by {', '.join(a.parameter for a in parsed)}" if parsed else ""),
    )


def resolve_shape(model, norad: int) -> tuple[str, Shape]:
    """(name, Shape) of a ``[model]`` section (a `ModelConfig`) for an object.

    A mesh file wins; otherwise the named shape, or for ``auto`` the object's own model
    (`AUTO_SHAPES`) or the generic ellipsoid.
    """
    if model.mesh:
        shape = mesh_shape(model.mesh, model.materials or None, model.articulations, model.repair_mesh)
        return f"mesh:{Path(model.mesh).name}", shape
    name = shape_for_norad(norad) if model.shape == "auto" else model.shape
    return name, SHAPES[name]


def _rescaled_brdf(brdf, albedo_scale: float, roughness: float | None):
    if isinstance(brdf, Lambertian):
        return replace(brdf, albedo=brdf.albedo * albedo_scale)
    if isinstance(brdf, GGX):
        return replace(
            brdf, color=brdf.color * albedo_scale, roughness=brdf.roughness if roughness is None else roughness
        )
    if isinstance(brdf, Principled):
        return replace(
            brdf,
            base_color=brdf.base_color * albedo_scale,
            roughness=brdf.roughness if roughness is None else roughness,
        )
    raise TypeError(f"cannot rescale a {type(brdf).__name__} BRDF; fix albedo_scale and roughness for this shape")


def _max_reflectance(brdf) -> float:
    return float(max(getattr(brdf, name, 0.0) for name in ("albedo", "color", "base_color")))


@dataclass(frozen=True, eq=False)
class MaterialScalars:
    """A renderer whose scene's materials are rescaled at each call.

    Parameters
    ----------
    renderer : SceneCache or DirectRenderer
        Anything with ``scene`` and ``intensity(sun_body, obs_body, **articulation)``.
    parameters : tuple of str
        Which of ``albedo_scale`` (factor on every reflectance) and ``roughness`` (replaces
        every glossy roughness) are passed at run time.
    """

    renderer: Any
    parameters: tuple[str, ...]

    def supports(self, values: Mapping[str, float]) -> bool:
        """False where a reflectance would exceed 1 or the roughness leave [0.01, 1]."""
        scale = values.get("albedo_scale", 1.0)
        brightest = max(_max_reflectance(b) for b in self.renderer.scene.brdfs if b is not None)
        roughness = values.get("roughness", 0.5)
        return 0 <= scale * brightest <= 1 and 0.01 <= roughness <= 1

    def intensity(self, sun_body, obs_body, albedo_scale: float = 1.0, roughness: float | None = None, **articulation):
        scene = self.renderer.scene
        brdfs = {
            name: _rescaled_brdf(brdf, albedo_scale, roughness)
            for name, brdf in zip(scene.material_names, scene.brdfs)
            if brdf is not None
        }
        renderer = replace(self.renderer, scene=scene.with_brdfs(**brdfs))
        return renderer.intensity(sun_body, obs_body, **articulation)


@dataclass(frozen=True, eq=False)
class SurfaceClasses:
    """A renderer whose scene's materials come from a model's surface parameters at each call.

    Parameters
    ----------
    renderer : SceneCache or DirectRenderer
        Anything with ``scene`` and ``intensity(sun_body, obs_body, **articulation)``.
    surface_brdfs : callable
        ``surface_brdfs(**values) -> {material: BRDF}`` (`Shape.surface_brdfs`).
    surfaces : mapping of str to SurfaceParameter
        The parameters and their ranges (`Shape.surfaces`).
    """

    renderer: Any
    surface_brdfs: Callable
    surfaces: Mapping[str, Any]

    def supports(self, values: Mapping[str, float]) -> bool:
        """False where a surface parameter leaves its physical range."""
        return all(spec.low <= values.get(name, spec.default) <= spec.high for name, spec in self.surfaces.items())

    def intensity(self, sun_body, obs_body, **parameters):
        surface = {name: parameters.pop(name) for name in self.surfaces if name in parameters}
        renderer = replace(self.renderer, scene=self.renderer.scene.with_brdfs(**self.surface_brdfs(**surface)))
        return renderer.intensity(sun_body, obs_body, **parameters)


def _sharpest_surfaces(shape: Shape, free_bounds: Mapping, fixed: Mapping) -> dict[str, float]:
    """Surface values for building a cache: fixed ones as given, free roughnesses at the smoothest
    their prior allows (the narrowest lobe sets the glint sampling), the rest at their defaults."""
    values = {}
    for name, spec in shape.surfaces.items():
        if name in fixed:
            values[name] = float(fixed[name])
        elif name in free_bounds and name.endswith("roughness"):
            values[name] = max(float(free_bounds[name][0]), spec.low)
        else:
            values[name] = float(spec.default)
    return values


def _build_cache(
    scene,
    grid: tuple,
    smoothest_roughness: float | None,
    accuracy_mag: float,
    grid_size: int,
    progress: bool,
    element_size_m: float = 0.0,
    normal_bins_per_step: float = 0.0,
):
    options = {"grid_size": grid_size}
    if element_size_m:
        options["element_size_m"] = element_size_m
    if normal_bins_per_step:
        options["normal_bins_per_step"] = normal_bins_per_step
    if smoothest_roughness is not None:
        smooth = scene.with_brdfs(
            **{
                n: _rescaled_brdf(b, 1.0, smoothest_roughness)
                for n, b in zip(scene.material_names, scene.brdfs)
                if b is not None
            }
        )
        alpha = smoothest_roughness**2
        options |= {
            "normal_step_deg": float(np.clip(math.degrees(alpha) / 2.0, 0.5, 3.0)),
            # The solar-disk samples of the sharpest lobe the prior allows, for every material.
            "sun_samples": max(sun_samples_for(b, accuracy_mag) for b in smooth.brdfs),
        }
    articulation_grid = {name: list(values) for name, values in grid} or None
    return SceneCache.build(
        scene, accuracy_mag=accuracy_mag, articulation_grid=articulation_grid, progress=progress, **options
    )


def brightness_for(
    shape: Shape,
    free_bounds: Mapping[str, tuple[float, float]],
    fixed: Mapping[str, float],
    *,
    renderer: str = "cached",
    accuracy_mag: float = 0.01,
    grid_size: int = CACHE_GRID_SIZE,
    element_size_m: float = 0.0,
    normal_bins_per_step: float = 0.0,
    pixel_size_m: float = 0.05,
    progress: bool = False,
    store: ShapeStore | None = None,
    name: str = "shape",
):
    """The brightness function of a shape for a fit.

    Parameters
    ----------
    shape : Shape
        A value of `SHAPES`, or `mesh_shape(...)`.
    free_bounds : mapping of str to (low, high)
        Prior ranges of the free brightness parameters (articulations, material scalars, surface
        parameters).
    fixed : mapping of str to float
        Values of the fixed brightness parameters.
    renderer : {"cached", "direct"}
        Fast path or reference renderer (ignored by analytic shapes).
    accuracy_mag : float
        Accuracy asked of the cache.
    grid_size : int
        The cache's cube-map resolution (:func:`cache_grid_size`).
    element_size_m : float
        The cache's largest element on shadowable sides (0: its default, the mesh radius / 30).
    normal_bins_per_step : float
        The cache's shading classes per normal step (0: its default, 3).
    pixel_size_m : float
        Ray spacing of the direct renderer.
    progress : bool
        Progress bar while the cache is built.
    store : ShapeStore, optional
        Where built caches are kept (default: this process's memory only).
    name : str
        The shape's name, for messages.

    Returns
    -------
    (brightness, parameters)
        The object with ``intensity(sun_body, obs_body, **parameters)`` and the names of the
        parameters the forward model must pass to it (every articulation of the shape, free
        or fixed, and the material scalars in use).
    """
    allowed = set(shape.articulations) | set(MATERIAL_PARAMETERS) | set(shape.surfaces)
    names = set(free_bounds) | set(fixed)
    unknown = sorted(names - allowed)
    if unknown:
        raise ValueError(f"shape {name!r} has no parameters {unknown}; it has {', '.join(sorted(allowed))}")
    materials = tuple(n for n in MATERIAL_PARAMETERS if n in names)
    surfaces = tuple(n for n in shape.surfaces if n in names)
    if materials and surfaces:
        raise ValueError(
            f"shape {name!r}: give either the material scalars {list(materials)} or its surface parameters "
            f"{list(surfaces)}, not both (the surface parameters set every material)"
        )
    articulation_free = {n: b for n, b in free_bounds.items() if n in shape.articulations}
    articulation_fixed = {
        n: float(fixed.get(n, default)) for n, default in shape.articulations.items() if n not in articulation_free
    }
    if shape.analytic:
        if materials:
            raise ValueError(f"shape {name!r} is analytic and has no material parameters; remove {list(materials)}")
        return shape.build(), ()
    scene = shape.build()
    if articulation_fixed:
        scene = scene.with_parameters(**articulation_fixed)
    if surfaces:
        scene = scene.with_brdfs(**shape.surface_brdfs(**_sharpest_surfaces(shape, free_bounds, fixed)))
    if renderer == "cached":
        grid = tuple(
            (n, tuple(np.linspace(low, high, max(3, int(math.ceil((high - low) * _GRID_PER_DEG)) + 1))))
            for n, (low, high) in sorted(articulation_free.items())
        )
        smoothest = None
        if "roughness" in free_bounds:
            smoothest = float(free_bounds["roughness"][0])
        elif "roughness" in fixed:
            smoothest = float(fixed["roughness"])
        settings = {"grid": grid, "smoothest_roughness": smoothest, "accuracy_mag": float(accuracy_mag)}
        if grid_size != CACHE_GRID_SIZE:
            # Only a finer grid enters the key, so caches stored before it was a setting stay found.
            settings["grid_size"] = int(grid_size)
        if element_size_m:
            settings["element_size_m"] = float(element_size_m)  # the same: only when given
        if normal_bins_per_step:
            settings["normal_bins_per_step"] = float(normal_bins_per_step)
        build = functools.partial(
            _build_cache,
            scene,
            grid,
            smoothest,
            float(accuracy_mag),
            int(grid_size),
            progress,
            float(element_size_m),
            float(normal_bins_per_step),
        )
        base = (store or ShapeStore()).get(scene, settings, build)
    elif renderer == "direct":
        base = DirectRenderer(scene, pixel_size_m, 1)
    else:
        raise ValueError(f"renderer={renderer!r} must be 'cached' or 'direct'")
    # Fixed articulations are passed too (the cache checks them against the scene it was built for).
    parameters = tuple(sorted(shape.articulations)) + materials + surfaces
    if materials:
        return MaterialScalars(base, materials), parameters
    if surfaces:
        return SurfaceClasses(base, shape.surface_brdfs, {n: shape.surfaces[n] for n in surfaces}), parameters
    return base, parameters
