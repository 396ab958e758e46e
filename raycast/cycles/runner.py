"""Blender Cycles renders of the same scene the ray caster renders: the authority it is checked against.

`render_cycles` builds a Cycles scene from a `CyclesMesh` (triangles, per-corner shading normals,
one BSDF per material as in the project's materials JSON), then for each frame points a Sun lamp
(strength = irradiance, disk 0.53 deg) along ``-sun_body`` and an orthographic camera along
``-obs_body`` framing the projected footprint, renders direct light only with a box pixel filter
into 32-bit float OpenEXR, and sums radiance times pixel area over irradiance: I/E in m^2/sr,
the quantity `raycast.renderer` returns.

Cycles (pip package ``bpy``, the optional ``cycles`` extra) runs in a child process by default,
so its bundled Embree/TBB/OpenImageIO never meet Open3D's in one address space; nothing here
imports ``bpy`` until a render is asked for.

Example
-------
>>> from raycast.cycles import CyclesMesh, CyclesSettings, render_cycles   # doctest: +SKIP
>>> mesh = CyclesMesh.from_obj(MODELS / "cosmos2502_lotos.obj",
...                            MODELS / "cosmos2502_lotos.materials.json")   # doctest: +SKIP
>>> result = render_cycles(mesh, sun_body, obs_body, CyclesSettings(samples=64))  # doctest: +SKIP
>>> result.intensity_m2_sr, result.noise_rel, result.seconds_per_frame  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
import importlib.util
import json
import math
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time
from types import MappingProxyType

import numpy as np
from tqdm.auto import tqdm

from raycast.renderer.brdf import GGX, Lambertian, Mix, Principled
from raycast.renderer.materials import read_materials_json
from raycast.renderer.meshio import read_obj

__all__ = [
    "CyclesMesh",
    "ObjImport",
    "CyclesSettings",
    "CyclesResult",
    "NoiseStudy",
    "render_cycles",
    "measure_noise",
    "MATERIAL_FIELDS",
    "material_entry",
]

INSTALL_HINT = "install the 'cycles' extra (pip install -e '.[cycles]') to render with Blender Cycles"

# Per BSDF node: (required fields, optional fields with the value used when absent). Optional
# defaults are Blender's own, except the microfacet distribution: single-scatter GGX, the
# closed form the project's BRDFs implement (Blender 4+ defaults to multiscatter GGX).
MATERIAL_FIELDS = {
    "Diffuse BSDF": (("color",), {"roughness": 0.0}),
    "Glossy BSDF": (("color", "roughness"), {"distribution": "GGX"}),
    "Principled BSDF": (
        ("base_color", "metallic", "roughness", "specular_ior_level"),
        {"ior": 1.5, "distribution": "GGX"},
    ),
    # (1 - fac) shaders[0] + fac shaders[1]; each of the two is an entry of the nodes above.
    "Mix Shader": (("fac", "shaders"), {}),
}
_DISTRIBUTIONS = {
    "Glossy BSDF": ("GGX", "MULTI_GGX", "BECKMANN", "ASHIKHMIN_SHIRLEY"),
    "Principled BSDF": ("GGX", "MULTI_GGX"),
}
# Colour channel standing for the band, named as in raycast.renderer.materials ("green" for V).
_CHANNELS = {"red": 0, "green": 1, "blue": 2}


# --------------------------------------------------------------------------------------------
# The mesh


@dataclass(frozen=True, eq=False)
class CyclesMesh:
    """Triangles, shading normals and materials: what both renderers are given.

    Build it with `from_obj` or `from_arrays`; the fields are read-only arrays.

    Attributes
    ----------
    vertices_m : (V, 3) float
        Vertex positions in the body (mesh) frame, metres.
    triangles : (T, 3) int
        Vertex indices of each triangle, counter-clockwise seen from the side its normal faces.
    material_index : (T,) int
        Index into `materials` of each triangle.
    materials : tuple of mapping
        Read-only entries in the form of the materials JSON (``{"blender_node": "Glossy BSDF", "color":
        [r, g, b], "roughness": 0.3}``); see `MATERIAL_FIELDS` for each node's fields.
    corner_normals : (T, 3, 3) float or None
        Unit shading normal at each corner of each triangle; None shades every face flat with its
        geometric normal. A triangle whose three corner normals equal its geometric normal is
        rendered flat, as Blender renders a face with smooth shading off.
    material_names : tuple of str
        A name per material (the OBJ's ``usemtl`` names, or ``material0``, ...).
    """

    vertices_m: np.ndarray
    triangles: np.ndarray
    material_index: np.ndarray
    materials: tuple
    corner_normals: np.ndarray | None = None
    material_names: tuple = field(default=())

    def __post_init__(self):
        vertices = _finite_array(self.vertices_m, "vertices_m", (None, 3), float)
        if len(vertices) < 3:
            raise ValueError(f"vertices_m has {len(vertices)} vertices; a mesh needs at least 3")
        triangles = _finite_array(self.triangles, "triangles", (None, 3), np.int64)
        if len(triangles) == 0:
            raise ValueError("triangles is empty; give at least one (T, 3) vertex-index triangle")
        if triangles.min() < 0 or triangles.max() >= len(vertices):
            raise ValueError(
                f"triangles refer to vertex {int(triangles.min())}..{int(triangles.max())} but "
                f"there are {len(vertices)} vertices; use 0-based indices below {len(vertices)}"
            )
        materials = tuple(
            MappingProxyType(_checked_material(entry, index)) for index, entry in enumerate(self.materials)
        )
        if not materials:
            raise ValueError("materials is empty; give at least one materials-JSON entry")
        material_index = _finite_array(self.material_index, "material_index", (len(triangles),), np.int64)
        if material_index.min() < 0 or material_index.max() >= len(materials):
            raise ValueError(
                f"material_index holds {int(material_index.min())}..{int(material_index.max())} but "
                f"there are {len(materials)} materials; index into the materials list"
            )
        names = tuple(self.material_names) or tuple(f"material{i}" for i in range(len(materials)))
        if len(names) != len(materials):
            raise ValueError(
                f"material_names has {len(names)} names for {len(materials)} materials; give one per material"
            )
        normals = None
        if self.corner_normals is not None:
            normals = _finite_array(self.corner_normals, "corner_normals", (len(triangles), 3, 3), float)
            length = np.linalg.norm(normals, axis=2, keepdims=True)
            if (length < 1e-9).any():
                raise ValueError(
                    "corner_normals contains a zero-length normal; give unit shading normals or None for flat shading"
                )
            normals = normals / length
        for name, value in (
            ("vertices_m", vertices),
            ("triangles", triangles),
            ("material_index", material_index),
            ("corner_normals", normals),
            ("materials", materials),
            ("material_names", names),
        ):
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
            object.__setattr__(self, name, value)

    # ---- constructors ----

    @classmethod
    def from_arrays(
        cls,
        vertices_m,
        triangles,
        materials,
        material_index=None,
        vertex_normals=None,
        corner_normals=None,
        material_names=(),
    ) -> CyclesMesh:
        """A mesh from arrays, with smooth shading from per-vertex or per-corner normals.

        Parameters
        ----------
        vertices_m : (V, 3) float
            Vertex positions, metres.
        triangles : (T, 3) int
            0-based vertex indices.
        materials : sequence of dict
            Materials-JSON entries.
        material_index : (T,) int or None
            Material of each triangle; None means material 0 everywhere.
        vertex_normals : (V, 3) float or None
            Shading normal per vertex (each corner takes its vertex's normal).
        corner_normals : (T, 3, 3) float or None
            Shading normal per triangle corner. Give at most one of the two; none means flat.
        material_names : sequence of str
            Optional names of the materials.
        """
        if vertex_normals is not None and corner_normals is not None:
            raise ValueError("both vertex_normals and corner_normals were given; pass only one of them")
        triangles = np.asarray(triangles)
        if material_index is None:
            material_index = np.zeros(len(triangles), dtype=np.int64)
        if vertex_normals is not None:
            vertex_normals = _finite_array(vertex_normals, "vertex_normals", (len(np.asarray(vertices_m)), 3), float)
            corner_normals = vertex_normals[_finite_array(triangles, "triangles", (None, 3), np.int64)]
        return cls(
            vertices_m=vertices_m,
            triangles=triangles,
            material_index=material_index,
            materials=tuple(materials),
            corner_normals=corner_normals,
            material_names=tuple(material_names),
        )

    @classmethod
    def from_obj(cls, path, materials_json) -> CyclesMesh:
        """Read a Wavefront OBJ and its materials sidecar JSON.

        Triangles and normals are the renderer's (`raycast.renderer.meshio.read_obj`, which follows
        Blender's importer and tessellation), so both renderers see the same surface. Every
        ``usemtl`` name must have an entry under ``"materials"`` in the JSON. A Principled entry without
        ``ior`` takes the material's ``Ni`` from the OBJ's ``mtllib`` (Blender's exporter writes
        the Principled IOR there) when it is above 1, as `raycast.renderer.materials` does; else 1.5.

        Parameters
        ----------
        path : str or Path
            The ``.obj`` file (Blender axes: Z up; metres).
        materials_json : str or Path
            JSON file with ``{"materials": {name: entry, ...}}`` as in
            ``cosmos2502_lotos.materials.json``.
        """
        table = read_materials_json(materials_json)
        mesh = read_obj(path)
        unknown = [name for name in mesh.material_names if name not in table]
        if unknown:
            raise ValueError(
                f'material {unknown[0]!r} used in {path} has no entry in {materials_json}; add it under "materials"'
            )
        materials = [
            _with_mtl_ior(table[name], mesh.material_records.get(name, {}).get("Ni", 0.0))
            for name in mesh.material_names
        ]
        flat = np.isnan(mesh.corner_normals).any(axis=2, keepdims=True)
        geometric = np.broadcast_to(
            _geometric_normals(mesh.vertices_m, mesh.triangles)[:, None, :], flat.shape[:2] + (3,)
        )
        return cls(
            vertices_m=mesh.vertices_m,
            triangles=mesh.triangles,
            material_index=mesh.material_index,
            materials=tuple(materials),
            corner_normals=np.where(flat, geometric, mesh.corner_normals),
            material_names=tuple(mesh.material_names),
        )

    @classmethod
    def from_scene(cls, scene) -> CyclesMesh:
        """The posed triangles, shading normals and BRDFs of a `raycast.renderer.scene.Scene`.

        Each BRDF becomes the Blender node it models, with its parameters (grey colours: a
        scene's BRDFs hold one colour channel), so both renderers are given the same surface.
        """
        posed = scene.posed()
        return cls(
            vertices_m=posed.vertices_m,
            triangles=np.arange(len(posed.vertices_m)).reshape(-1, 3),
            material_index=posed.material_index,
            materials=tuple(material_entry(brdf) for brdf in scene.brdfs),
            corner_normals=posed.corner_normals,
            material_names=scene.material_names,
        )

    # ---- operations returning new meshes ----

    def with_material(self, entry: Mapping) -> CyclesMesh:
        """The same geometry and normals with one material on every triangle."""
        return CyclesMesh(
            vertices_m=self.vertices_m,
            triangles=self.triangles,
            material_index=np.zeros(len(self.triangles), dtype=np.int64),
            materials=(entry,),
            corner_normals=self.corner_normals,
            material_names=("all",),
        )

    def with_flat_shading(self) -> CyclesMesh:
        """The same mesh with every face shaded by its geometric normal."""
        return CyclesMesh(
            vertices_m=self.vertices_m,
            triangles=self.triangles,
            material_index=self.material_index,
            materials=self.materials,
            corner_normals=None,
            material_names=self.material_names,
        )

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    def job(self) -> dict:
        """The arrays a render job takes."""
        job = {
            "vertices_m": self.vertices_m,
            "triangles": self.triangles,
            "material_index": self.material_index,
            "materials_json": np.array(json.dumps([dict(entry) for entry in self.materials])),
        }
        if self.corner_normals is not None:
            job["corner_normals"] = self.corner_normals
        return job


@dataclass(frozen=True, eq=False)
class ObjImport:
    """An OBJ file as Blender's own OBJ importer reads it (``forward_axis="Y", up_axis="Z"``:
    the file is in Blender's axes), with a materials-JSON entry per ``usemtl`` name: the scene
    is then Blender's, its triangulation of polygons and its shading normals included, not
    the project's reading of the file (`CyclesMesh.from_obj`).

    Attributes
    ----------
    path : Path
    materials : tuple of (name, entry) pairs
    """

    path: Path
    materials: tuple

    @classmethod
    def from_files(cls, path, materials_json) -> ObjImport:
        """The OBJ at ``path`` with the entries of its ``usemtl`` names in ``materials_json``."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"OBJ file {path} does not exist; give the path of a Wavefront .obj")
        table = read_materials_json(materials_json)
        names = list(dict.fromkeys(read_obj(path).material_names))
        unknown = [name for name in names if name not in table]
        if unknown:
            raise ValueError(
                f'material {unknown[0]!r} used in {path} has no entry in {materials_json}; add it under "materials"'
            )
        return cls(path, tuple((name, _checked_material(table[name], name)) for name in names))

    def job(self) -> dict:
        return {
            "obj_path": np.array(str(self.path.resolve())),
            "materials_json": np.array(json.dumps([entry for _, entry in self.materials])),
            "material_names_json": np.array(json.dumps([name for name, _ in self.materials])),
        }


def _with_mtl_ior(entry, mtl_ior):
    """A copy of a materials-JSON entry whose Principled nodes (a Mix Shader's too) without an
    ``ior`` take the .mtl's ``Ni``, as :func:`raycast.renderer.materials.brdf_from_record` does."""
    entry = dict(entry)
    if entry.get("blender_node") == "Mix Shader" and isinstance(entry.get("shaders"), list):
        entry["shaders"] = [
            _with_mtl_ior(shader, mtl_ior) if isinstance(shader, Mapping) else shader for shader in entry["shaders"]
        ]
    elif entry.get("blender_node") == "Principled BSDF" and "ior" not in entry and mtl_ior > 1.0:
        entry["ior"] = mtl_ior
    return entry


def material_entry(brdf) -> dict:
    """The materials-JSON entry of the Blender node a `raycast.renderer.brdf` BRDF models."""
    if isinstance(brdf, Lambertian):
        return {"blender_node": "Diffuse BSDF", "color": [brdf.albedo] * 3}
    if isinstance(brdf, GGX):
        return {
            "blender_node": "Glossy BSDF",
            "color": [brdf.color] * 3,
            "roughness": brdf.roughness,
            "distribution": brdf.distribution,
        }
    if isinstance(brdf, Principled):
        return {
            "blender_node": "Principled BSDF",
            "base_color": [brdf.base_color] * 3,
            "metallic": brdf.metallic,
            "roughness": brdf.roughness,
            "specular_ior_level": brdf.specular_ior_level,
            "ior": brdf.ior,
            "distribution": brdf.distribution,
        }
    if isinstance(brdf, Mix):
        return {
            "blender_node": "Mix Shader",
            "fac": brdf.fac,
            "shaders": [material_entry(brdf.first), material_entry(brdf.second)],
        }
    raise TypeError(f"{brdf!r} models no Blender node; give Lambertian, GGX, Principled or Mix BRDFs")


def _finite_array(value, name, shape, dtype):
    """`value` as a fresh array of `shape` (None = any length) and `dtype`, or a ValueError."""
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} is not numeric; give a {_shape_text(shape)} array of numbers") from None
    if array.ndim != len(shape) or any(want is not None and got != want for got, want in zip(array.shape, shape)):
        raise ValueError(f"{name} has shape {array.shape}; give a {_shape_text(shape)} array")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} contains NaN or infinite values; give finite numbers")
    if dtype is not float:
        if (array != np.round(array)).any():
            raise ValueError(f"{name} contains non-integer values; give integer indices")
        return array.astype(dtype)
    return array


def _shape_text(shape):
    sizes = ["n" if size is None else str(size) for size in shape]
    return "(" + ", ".join(sizes) + ("," if len(sizes) == 1 else "") + ")"


def _checked_material(entry, index):
    """A plain-dict copy of a materials-JSON entry, with defaults filled in, or a ValueError."""
    if not isinstance(entry, Mapping):
        raise ValueError(f"material {index} is {type(entry).__name__}; give a dict like the materials JSON entries")
    kind = entry.get("blender_node")
    if kind not in MATERIAL_FIELDS:
        raise ValueError(f"material {index} has blender_node={kind!r}; use one of {', '.join(sorted(MATERIAL_FIELDS))}")
    required, optional = MATERIAL_FIELDS[kind]
    keys = {key for key in entry if not key.startswith("_") and key != "blender_node"}
    missing = [key for key in required if key not in keys]
    if missing:
        raise ValueError(f"material {index} ({kind}) lacks {missing[0]!r}; give it in the entry")
    extra = sorted(keys - set(required) - set(optional))
    if extra:
        raise ValueError(
            f"material {index} ({kind}) has unknown field {extra[0]!r}; allowed fields are "
            f"{', '.join(required + tuple(optional))}"
        )
    checked = {"blender_node": kind, **optional}
    for key in keys:
        value = entry[key]
        if key in ("color", "base_color"):
            color = np.asarray(value, dtype=float) if _is_numeric_sequence(value) else np.full(1, np.nan)
            if color.shape != (3,) or not np.isfinite(color).all() or (color < 0).any() or (color > 1).any():
                raise ValueError(
                    f"material {index} ({kind}) has {key}={value!r}; give three linear RGB values in [0, 1]"
                )
            checked[key] = tuple(float(c) for c in color)
        elif key == "shaders":
            if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 2:
                raise ValueError(f"material {index} ({kind}) has shaders={value!r}; give a list of two node entries")
            inner = [_checked_material(shader, f"{index}.shaders[{k}]") for k, shader in enumerate(value)]
            nested = [k for k, shader in enumerate(inner) if shader["blender_node"] == "Mix Shader"]
            if nested:
                raise ValueError(f"material {index}.shaders[{nested[0]}] is a Mix Shader; mix two BSDF nodes")
            checked[key] = inner
        elif key == "distribution":
            if value not in _DISTRIBUTIONS[kind]:
                raise ValueError(
                    f"material {index} ({kind}) has distribution={value!r}; use one of {', '.join(_DISTRIBUTIONS[kind])}"
                )
            checked[key] = value
        else:
            low, high = (1.0, 10.0) if key == "ior" else (0.0, 1.0)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
                raise ValueError(f"material {index} ({kind}) has {key}={value!r}; give a number in [{low}, {high}]")
            checked[key] = float(value)
    return checked


def _is_numeric_sequence(value):
    return (
        isinstance(value, (Sequence, np.ndarray))
        and not isinstance(value, str)
        and all(isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool) for v in value)
    )


def _geometric_normals(vertices, triangles):
    """(T, 3) unit normals from the winding; zero-area triangles get +Z (they are never hit)."""
    corners = vertices[triangles]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    return np.where(length > 0, normal / np.where(length > 0, length, 1.0), [0.0, 0.0, 1.0])


# --------------------------------------------------------------------------------------------
# Settings and results


@dataclass(frozen=True)
class CyclesSettings:
    """How Cycles renders each frame.

    Parameters
    ----------
    samples : int
        Camera samples per pixel (direct light only: each sample is one camera ray and one
        shadow ray toward a point of the Sun's disk).
    resolution : int or None
        Pixels across the larger side of each frame's projected footprint (pixels are square;
        the other side gets as many as it needs). None uses `DEFAULT_RESOLUTION_PX`. The
        estimate is unbiased at any resolution (box filter); resolution and samples both trade
        noise for time.
    seed : int
        Cycles' sampling seed. Renders with the same seed and settings are identical.
    sun_angle_deg : float
        Angular diameter of the Sun lamp's disk.
    threads : int or None
        CPU threads for Cycles; None uses all cores.
    channel : {"green", "red", "blue", "mean"}
        Which RGB channel of the rendered I/E becomes `CyclesResult.intensity_m2_sr` (all three
        are kept in `intensity_rgb_m2_sr`); the names and the default (green for the V band)
        are those of `raycast.renderer.materials`. I/E is linear in the material colours, so a channel
        equals a render whose colours are that channel's values, and "mean" one with the mean.
    noise_passes : int
        Split `samples` over this many renders with distinct seeds per frame (`samples` must be a
        multiple). With 2 or more, `CyclesResult.noise_rel` estimates each frame's relative
        sampling error from their spread, at the cost of the extra per-render overhead.
    process : {"subprocess", "in_process"}
        Run Blender in a child process (default; isolates Blender's bundled libraries and any
        crash) or in this one (saves ~1 s of start-up; resets bpy's current scene).
    terminator_geometry_offset, terminator_shading_offset : float in [0, 1]
        The mesh object's shadow terminator offsets (Blender's ``Object.shadow_terminator_*``).
        0 (the default here) renders the mesh as it is; Blender's own defaults are 0.1 and 0,
        with which shadow rays leave low-poly smooth-shaded faces as if from the smooth surface
        they stand for (docs/cycles.md, "How a frame is rendered").
    """

    samples: int = 64
    resolution: int | None = None
    seed: int = 0
    sun_angle_deg: float = 0.53
    threads: int | None = None
    channel: str = "green"
    noise_passes: int = 1
    process: str = "subprocess"
    terminator_geometry_offset: float = 0.0
    terminator_shading_offset: float = 0.0

    DEFAULT_RESOLUTION_PX = 128

    def __post_init__(self):
        for name, value, low, high in (
            ("samples", self.samples, 1, 1 << 20),
            ("seed", self.seed, 0, (1 << 31) - 1),
            ("noise_passes", self.noise_passes, 1, 64),
        ):
            if not _is_int(value) or not low <= value <= high:
                raise ValueError(f"CyclesSettings {name}={value!r}; give an integer in [{low}, {high}]")
        if self.resolution is not None and (not _is_int(self.resolution) or not 4 <= self.resolution <= 16384):
            raise ValueError(f"CyclesSettings resolution={self.resolution!r}; give None or an integer in [4, 16384]")
        if self.threads is not None and (not _is_int(self.threads) or not 1 <= self.threads <= 1024):
            raise ValueError(f"CyclesSettings threads={self.threads!r}; give None (all cores) or a positive integer")
        if (
            isinstance(self.sun_angle_deg, bool)
            or not isinstance(self.sun_angle_deg, (int, float))
            or not (0.0 <= self.sun_angle_deg <= 10.0)
        ):
            raise ValueError(
                f"CyclesSettings sun_angle_deg={self.sun_angle_deg!r}; give degrees in [0, 10] (the Sun is 0.53)"
            )
        for name in ("terminator_geometry_offset", "terminator_shading_offset"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
                raise ValueError(
                    f"CyclesSettings {name}={value!r}; give a number in [0, 1] (0 renders the mesh as it is)"
                )
        if self.channel not in ("mean", *_CHANNELS):
            raise ValueError(f"CyclesSettings channel={self.channel!r}; use 'green', 'red', 'blue' or 'mean'")
        if self.samples % self.noise_passes:
            raise ValueError(
                f"CyclesSettings samples={self.samples} is not a multiple of noise_passes={self.noise_passes}; "
                "make samples divisible by noise_passes"
            )
        if self.process not in _RUNNERS:
            raise ValueError(f"CyclesSettings process={self.process!r}; use one of {', '.join(_RUNNERS)}")

    @property
    def resolution_px(self) -> int:
        """The resolution actually used."""
        return self.DEFAULT_RESOLUTION_PX if self.resolution is None else self.resolution


def _is_int(value):
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


@dataclass(frozen=True, eq=False)
class CyclesResult:
    """I/E per frame rendered by Cycles, with its timing and sampling-noise estimate.

    Attributes
    ----------
    intensity_m2_sr : (m,) float
        Reflected intensity per unit solar irradiance, m^2/sr, in the channel of
        ``settings.channel`` (the mean over ``noise_passes`` renders).
    intensity_rgb_m2_sr : (m, 3) float
        The same in R, G and B.
    noise_rel : (m,) float or None
        Estimated relative standard error of `intensity_m2_sr` per frame (std of the passes over
        sqrt(passes), over the mean); None unless ``settings.noise_passes >= 2``. One frame's
        estimate has only passes - 1 degrees of freedom; `noise_rel_rms` pools the frames.
    frame_seconds : (m,) float
        Wall time of each frame's renders and read-back.
    frame_cpu_seconds : (m,) float
        CPU time (all of Blender's threads) of the same; less sensitive than wall time to other
        work on the machine.
    seconds_total : float
        Wall time of the whole call, including Blender start-up and scene construction.
    resolution_px : (m, 2) int
        Film size (x, y) of each frame.
    pixel_size_m : (m,) float
        Side of a pixel on the object, metres.
    settings : CyclesSettings
    """

    intensity_m2_sr: np.ndarray
    intensity_rgb_m2_sr: np.ndarray
    noise_rel: np.ndarray | None
    frame_seconds: np.ndarray
    frame_cpu_seconds: np.ndarray
    seconds_total: float
    resolution_px: np.ndarray
    pixel_size_m: np.ndarray
    settings: CyclesSettings

    @property
    def seconds_per_frame(self) -> float:
        """Mean wall time per frame, scene construction excluded."""
        return float(self.frame_seconds.mean())

    @property
    def cpu_seconds_per_frame(self) -> float:
        """Mean CPU time per frame over all threads, scene construction excluded."""
        return float(self.frame_cpu_seconds.mean())

    @property
    def seconds_setup(self) -> float:
        """Wall time outside the frames: Blender start-up, scene construction, data transfer."""
        return float(self.seconds_total - self.frame_seconds.sum())

    @property
    def noise_rel_rms(self) -> float | None:
        """Relative standard error pooled over the frames with light (RMS of `noise_rel`)."""
        if self.noise_rel is None:
            return None
        lit = np.isfinite(self.noise_rel)
        return float(np.sqrt(np.mean(self.noise_rel[lit] ** 2))) if lit.any() else float("nan")


@dataclass(frozen=True, eq=False)
class NoiseStudy:
    """Cycles' sampling noise versus samples per pixel, from renders with independent seeds.

    Attributes
    ----------
    samples : (k,) int
        Samples per pixel of each row.
    intensity_m2_sr : (k, s, m) float
        I/E for each samples count, seed and frame.
    seconds_per_frame : (k,) float
        Mean wall time of one frame's render at each samples count.
    cpu_seconds_per_frame : (k,) float
        Mean CPU time (all threads) of the same.
    settings : CyclesSettings
        The settings shared by all renders (their `samples` and `seed` are replaced).
    """

    samples: np.ndarray
    intensity_m2_sr: np.ndarray
    seconds_per_frame: np.ndarray
    cpu_seconds_per_frame: np.ndarray
    settings: CyclesSettings

    @property
    def rel_std(self) -> np.ndarray:
        """(k, m) relative standard deviation of one render over seeds (NaN for unlit frames)."""
        mean = self.intensity_m2_sr.mean(axis=1)
        std = self.intensity_m2_sr.std(axis=1, ddof=1)
        return np.divide(std, mean, out=np.full_like(mean, np.nan), where=mean > 0)

    @property
    def rel_std_rms(self) -> np.ndarray:
        """(k,) `rel_std` pooled (RMS) over the lit frames."""
        rel = self.rel_std
        return np.sqrt(np.nanmean(rel**2, axis=1))

    def to_markdown(self) -> str:
        """A Markdown table: samples, pooled relative std, wall and CPU seconds per frame."""
        rows = [
            "| samples/px | relative std of one frame (RMS over frames) | s/frame (wall) | s/frame (CPU) |",
            "|---:|---:|---:|---:|",
        ]
        for samples, rel, wall, cpu in zip(
            self.samples, self.rel_std_rms, self.seconds_per_frame, self.cpu_seconds_per_frame
        ):
            rows.append(f"| {samples} | {rel:.2e} | {wall:.3f} | {cpu:.3f} |")
        return "\n".join(rows)


# --------------------------------------------------------------------------------------------
# Rendering


def render_cycles(mesh, sun_body, obs_body, settings=None, progress=True) -> CyclesResult:
    """Render I/E per frame with Blender Cycles, direct light only.

    Parameters
    ----------
    mesh : CyclesMesh or ObjImport
        The scene, in the body frame.
    sun_body : (m, 3) float
        Unit vectors from the object toward the Sun, body frame.
    obs_body : (m, 3) float
        Unit vectors from the object toward the observer, body frame.
    settings : CyclesSettings or None
        None means ``CyclesSettings()``.
    progress : bool
        Show a progress bar over the frames.

    Returns
    -------
    CyclesResult
    """
    settings = CyclesSettings() if settings is None else settings
    if not isinstance(settings, CyclesSettings):
        raise TypeError(f"settings is {type(settings).__name__}; give a CyclesSettings")
    samples = settings.samples // settings.noise_passes
    passes = [(samples, settings.seed * settings.noise_passes + k) for k in range(settings.noise_passes)]
    start = time.perf_counter()
    output = _run(mesh, sun_body, obs_body, settings, passes, progress)
    seconds_total = time.perf_counter() - start

    rgb_passes = output["intensity_rgb_m2_sr"]  # (p, m, 3)
    channel_passes = _channel(rgb_passes, settings.channel)
    intensity = channel_passes.mean(axis=0)
    noise_rel = None
    if settings.noise_passes >= 2:
        standard_error = channel_passes.std(axis=0, ddof=1) / math.sqrt(settings.noise_passes)
        noise_rel = np.divide(standard_error, intensity, out=np.full_like(intensity, np.nan), where=intensity > 0)
    return CyclesResult(
        intensity_m2_sr=intensity,
        intensity_rgb_m2_sr=rgb_passes.mean(axis=0),
        noise_rel=noise_rel,
        frame_seconds=output["frame_seconds"].sum(axis=0),
        frame_cpu_seconds=output["frame_cpu_seconds"].sum(axis=0),
        seconds_total=seconds_total,
        resolution_px=output["resolution_px"],
        pixel_size_m=output["pixel_size_m"],
        settings=settings,
    )


def measure_noise(mesh, sun_body, obs_body, samples=(16, 64, 256), seeds=4, settings=None, progress=True) -> NoiseStudy:
    """Measure Cycles' per-frame sampling noise against samples per pixel.

    Every frame is rendered once per samples count and seed (0 .. seeds - 1) in one Blender
    session; the spread over seeds is the noise of one render.

    Parameters
    ----------
    mesh : CyclesMesh
    sun_body, obs_body : (m, 3) float
        Unit vectors toward the Sun and the observer, body frame.
    samples : sequence of int
        Samples per pixel to compare.
    seeds : int
        Independent renders per samples count (at least 2).
    settings : CyclesSettings or None
        Resolution, Sun disk, threads, channel and process; its samples and seed are ignored.
    progress : bool
        Show a progress bar over the frames.
    """
    settings = CyclesSettings() if settings is None else settings
    if not isinstance(settings, CyclesSettings):
        raise TypeError(f"settings is {type(settings).__name__}; give a CyclesSettings")
    counts = list(samples)
    if not counts or not all(_is_int(count) and count >= 1 for count in counts):
        raise ValueError(f"samples={samples!r}; give a non-empty sequence of positive integers (samples per pixel)")
    if not _is_int(seeds) or seeds < 2:
        raise ValueError(f"seeds={seeds!r}; give an integer of at least 2 to measure a spread")
    passes = [(count, seed) for count in counts for seed in range(seeds)]
    output = _run(mesh, sun_body, obs_body, settings, passes, progress)
    rgb = output["intensity_rgb_m2_sr"]
    channel = _channel(rgb, settings.channel)
    seconds = output["frame_seconds"].reshape(len(counts), seeds, -1).mean(axis=(1, 2))
    cpu_seconds = output["frame_cpu_seconds"].reshape(len(counts), seeds, -1).mean(axis=(1, 2))
    return NoiseStudy(
        samples=np.asarray(counts),
        intensity_m2_sr=channel.reshape(len(counts), seeds, -1),
        seconds_per_frame=seconds,
        cpu_seconds_per_frame=cpu_seconds,
        settings=settings,
    )


def _channel(rgb, channel):
    """(...,) one channel (or the mean) of (..., 3) RGB values."""
    return rgb.mean(axis=-1) if channel == "mean" else rgb[..., _CHANNELS[channel]]


def _run(mesh, sun_body, obs_body, settings, passes, progress):
    """Validate the inputs, build the job and hand it to the runner `settings.process` names."""
    if not isinstance(mesh, (CyclesMesh, ObjImport)):
        raise TypeError(
            f"mesh is {type(mesh).__name__}; give a CyclesMesh (CyclesMesh.from_obj or from_arrays) or an ObjImport"
        )
    sun = _unit_directions(sun_body, "sun_body")
    obs = _unit_directions(obs_body, "obs_body")
    if len(sun) != len(obs):
        raise ValueError(f"sun_body has {len(sun)} frames but obs_body has {len(obs)}; give one of each per frame")
    if not _bpy_available():
        raise ModuleNotFoundError(f"bpy (Blender as a Python module) is not installed; {INSTALL_HINT}")
    job = {
        **mesh.job(),
        "sun_body": sun,
        "obs_body": obs,
        "passes": np.asarray(passes, dtype=np.int64).reshape(-1, 2),
        "resolution_px": np.int64(settings.resolution_px),
        "sun_angle_deg": np.float64(settings.sun_angle_deg),
        "threads": np.int64(settings.threads or 0),
        "terminator_geometry_offset": np.float64(settings.terminator_geometry_offset),
        "terminator_shading_offset": np.float64(settings.terminator_shading_offset),
    }
    with tqdm(total=len(sun), desc="Cycles", unit="frame", disable=not progress) as bar:
        return _RUNNERS[settings.process](job, lambda frame: bar.update(1))


def _unit_directions(value, name):
    directions = _finite_array(value, name, (None, 3), float)
    if len(directions) == 0:
        raise ValueError(f"{name} has no frames; give an (m, 3) array with m >= 1")
    norm = np.linalg.norm(directions, axis=1)
    worst = int(np.argmax(np.abs(norm - 1.0)))
    if abs(norm[worst] - 1.0) > 1e-6:
        raise ValueError(f"{name}[{worst}] has length {norm[worst]:.6g}; give unit vectors (divide by their norm)")
    return directions / norm[:, None]


def _bpy_available():
    if "bpy" in sys.modules:
        return sys.modules["bpy"] is not None
    return importlib.util.find_spec("bpy") is not None


def _run_in_process(job, on_frame):
    # The worker imports bpy, the optional 'cycles' extra.
    from raycast.cycles import _worker

    # Blender reports every saved frame on the C-level stdout; keep the caller's console clean.
    sys.stdout.flush()
    saved_stdout = os.dup(1)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            return _worker.render_job(job, on_frame=on_frame)
    finally:
        os.dup2(saved_stdout, 1)
        os.close(saved_stdout)


def _run_subprocess(job, on_frame):
    """Run the worker module in a child Python; progress arrives as ``frame N`` lines on its stdout."""
    package_root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [package_root, env.get("PYTHONPATH")]))
    with tempfile.TemporaryDirectory(prefix="rsodb-cycles-job-") as scratch:
        job_path, out_path, log_path = (Path(scratch) / name for name in ("job.npz", "out.npz", "blender.log"))
        np.savez(job_path, **job)
        with open(log_path, "w") as log:
            child = subprocess.Popen(
                [sys.executable, "-m", "raycast.cycles._worker", str(job_path), str(out_path)],
                stdout=subprocess.PIPE,
                stderr=log,
                text=True,
                env=env,
            )
            try:
                for line in child.stdout:
                    if line.startswith("frame "):
                        on_frame(int(line.split()[1]))
                status = child.wait()
            finally:
                if child.poll() is None:
                    child.kill()
                    child.wait()
        if status != 0 or not out_path.exists():
            tail = " | ".join(log_path.read_text(errors="replace").strip().splitlines()[-8:])
            raise RuntimeError(f"Blender Cycles exited with status {status}; its last output: {tail}")
        with np.load(out_path, allow_pickle=False) as stored:
            return {key: stored[key] for key in stored.files}


_RUNNERS = {"subprocess": _run_subprocess, "in_process": _run_in_process}
