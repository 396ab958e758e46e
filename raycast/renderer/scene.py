"""Shapes: triangle meshes with smooth-shading normals, named parts, materials and articulations.

A :class:`Scene` is immutable. It holds its triangles in the rest pose, one BRDF per material,
a part name per triangle, and :class:`Articulation` s (a named part rotated about an axis by a
named parameter, e.g. TOPEX's ``panel_pitch_deg``). ``scene.with_parameters(panel_pitch_deg=20)``
returns a new scene; ``scene.posed()`` returns the :class:`PosedMesh` the renderers ray-cast.

Surfaces are two-sided, as in Blender: a triangle seen from behind is shaded with its normals
flipped toward the viewer. So open meshes and inconsistently wound (flipped) faces render as
their geometry says. Two kinds of degenerate input are handled at construction:

* zero-area triangles carry no area and cannot be hit; they are dropped and listed in ``notes``;
* overlapping coplanar triangles (e.g. a zero-thickness plate exported as two faces with
  opposite normals, like ../shared/data/models/plate_1m.obj) within one part make "which
  face was hit" ambiguous and would count the area twice. They are refused unless ``repair=True``, which keeps one face of each set as
  a two-sided surface. (Blender Cycles renders such a plate black: each face shadows its twin.)

Code-built parts come from :class:`Part` constructors (``box``, ``cylinder``, ``plate``,
``dish``, ``sphere``), assembled with :meth:`Scene.from_parts`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
import math
from pathlib import Path

import numpy as np

from raycast.renderer import materials as materials_module
from raycast.renderer.brdf import BRDF
from raycast.renderer.meshio import read_mesh

__all__ = ["Articulation", "Part", "Scene", "PosedMesh", "icosphere", "SPECULAR_NORMALS"]

SPECULAR_NORMALS = ("cycles", "strict")


def _unit(v, axis=-1):
    length = np.linalg.norm(v, axis=axis, keepdims=True)
    return v / np.where(length > 0.0, length, 1.0)


def icosphere(subdivisions):
    """A subdivided icosahedron: vertices (v, 3) on the unit sphere and outward-wound faces (f, 3).

    Each subdivision splits every face in four at its edges' midpoints, pushed onto the sphere:
    20 * 4**subdivisions faces.
    """
    t = (1 + 5**0.5) / 2
    vertices = _unit(
        [
            [-1, t, 0],
            [1, t, 0],
            [-1, -t, 0],
            [1, -t, 0],
            [0, -1, t],
            [0, 1, t],
            [0, -1, -t],
            [0, 1, -t],
            [t, 0, -1],
            [t, 0, 1],
            [-t, 0, -1],
            [-t, 0, 1],
        ]
    )
    faces = np.array(
        [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ]
    )
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        unique_edges, inverse = np.unique(edges, axis=0, return_inverse=True)
        midpoint = len(vertices) + inverse.reshape(3, -1).T
        vertices = np.vstack([vertices, _unit(vertices[unique_edges].mean(axis=1))])
        a, b, c = faces.T
        ab, bc, ca = midpoint.T
        faces = np.concatenate([np.stack(tri, axis=1) for tri in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))])
    return vertices, faces


def _rotation_matrix(axis, angle_rad):
    """Rodrigues rotation matrix about the unit ``axis``, shape (3, 3)."""
    x, y, z = axis
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    t = 1.0 - c
    return np.array(
        [
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
        ]
    )


@dataclass(frozen=True)
class Articulation:
    """A named part rotated about an axis by a named parameter.

    The part is stored at ``rest_deg``; a parameter value v rotates it by ``v - rest_deg``
    degrees about the axis through ``axis_point_m`` along ``axis`` (right-hand rule).
    """

    part: str
    parameter: str
    axis_point_m: tuple
    axis: tuple
    rest_deg: float = 0.0

    def __post_init__(self):
        axis = np.asarray(self.axis, dtype=float)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) == 0.0:
            raise ValueError(f"articulation {self.parameter!r}: axis={self.axis!r} must be a non-zero 3-vector")
        object.__setattr__(self, "axis", tuple(float(a) for a in axis / np.linalg.norm(axis)))
        object.__setattr__(self, "axis_point_m", tuple(float(a) for a in self.axis_point_m))


@dataclass(frozen=True, eq=False)
class Part:
    """A named piece of a code-built model: triangles, corner normals, one material per triangle.

    Attributes
    ----------
    name : str
    corners_m : (t, 3, 3) float, triangle corners in metres (counter-clockwise from the front).
    corner_normals : (t, 3, 3) float, shading normals at the corners.
    materials : tuple of str, the material name of each triangle.
    """

    name: str
    corners_m: np.ndarray
    corner_normals: np.ndarray
    materials: tuple

    def transformed(self, rotation=None, offset_m=(0.0, 0.0, 0.0)) -> Part:
        """The part rotated by ``rotation`` (3, 3; default none) then moved by ``offset_m``."""
        rotation = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
        return replace(
            self,
            corners_m=self.corners_m @ rotation.T + np.asarray(offset_m, dtype=float),
            corner_normals=self.corner_normals @ rotation.T,
        )

    @classmethod
    def _flat(cls, name, corners, materials):
        normals = _unit(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
        return cls(name, corners, np.repeat(normals[:, None, :], 3, axis=1), tuple(materials))

    @classmethod
    def box(cls, name, size_m, material, center_m=(0.0, 0.0, 0.0), face_materials=None) -> Part:
        """An axis-aligned box with outward faces; ``face_materials`` maps "+x", "-x", ... to names."""
        half = np.asarray(size_m, dtype=float) / 2.0
        corners, mats = [], []
        for axis in range(3):
            for sign in (1.0, -1.0):
                u, v = (axis + 1) % 3, (axis + 2) % 3
                quad = []
                for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                    p = np.zeros(3)
                    p[axis] = sign * half[axis]
                    p[u] = a * half[u]
                    p[v] = b * half[v]
                    quad.append(p)
                if sign < 0:
                    quad = quad[::-1]
                key = ("+" if sign > 0 else "-") + "xyz"[axis]
                face_material = (face_materials or {}).get(key, material)
                corners += [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
                mats += [face_material, face_material]
        return cls._flat(name, np.asarray(corners) + np.asarray(center_m, dtype=float), mats)

    @classmethod
    def plate(cls, name, width_m, height_m, material) -> Part:
        """A zero-thickness rectangle in the z = 0 plane, normal +z, centred on the origin.

        It renders two-sided (both faces in ``material``); for different materials on the two
        faces use a thin :meth:`box` with ``face_materials``.
        """
        w, h = width_m / 2.0, height_m / 2.0
        quad = np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])
        return cls._flat(
            name, np.asarray([[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]), [material, material]
        )

    @classmethod
    def cylinder(cls, name, radius_m, length_m, material, segments=48, cap_material=None) -> Part:
        """A closed cylinder along z centred on the origin: smooth side normals, flat caps."""
        phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
        ring = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1)
        z0, z1 = -length_m / 2.0, length_m / 2.0
        corners, normals, mats = [], [], []
        for k in range(segments):
            a0, a1 = ring[k] * radius_m, ring[k + 1] * radius_m
            n0, n1 = ring[k], ring[k + 1]
            p = [a0 + [0, 0, z0], a1 + [0, 0, z0], a1 + [0, 0, z1], a0 + [0, 0, z1]]
            corners += [[p[0], p[1], p[2]], [p[0], p[2], p[3]]]
            normals += [[n0, n1, n1], [n0, n1, n0]]
            mats += [material, material]
        cap = cap_material or material
        for z, sign in ((z1, 1.0), (z0, -1.0)):
            centre = np.array([0.0, 0.0, z])
            for k in range(segments):
                a0, a1 = ring[k] * radius_m + [0, 0, z], ring[k + 1] * radius_m + [0, 0, z]
                tri = [centre, a0, a1] if sign > 0 else [centre, a1, a0]
                corners.append(tri)
                normals.append([[0.0, 0.0, sign]] * 3)
                mats.append(cap)
        return cls(name, np.asarray(corners), np.asarray(normals, dtype=float), tuple(mats))

    @classmethod
    def dish(cls, name, diameter_m, depth_m, material, rings=8, segments=32) -> Part:
        """A paraboloid dish (zero thickness) opening toward +z, vertex at the origin, smooth normals."""
        radius = diameter_m / 2.0
        k = depth_m / radius**2
        r = np.linspace(0.0, radius, rings + 1)
        phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
        rr, pp = np.meshgrid(r, phi, indexing="ij")
        points = np.stack([rr * np.cos(pp), rr * np.sin(pp), k * rr**2], axis=-1)
        normals = _unit(np.stack([-2 * k * rr * np.cos(pp), -2 * k * rr * np.sin(pp), np.ones_like(rr)], axis=-1))
        corners, corner_normals = [], []
        for i in range(rings):
            for j in range(segments):
                quad = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
                for tri in ((quad[0], quad[1], quad[2]), (quad[0], quad[2], quad[3])):
                    corners.append([points[a] for a in tri])
                    corner_normals.append([normals[a] for a in tri])
        return cls(name, np.asarray(corners), np.asarray(corner_normals), (material,) * len(corners))

    @classmethod
    def sphere(cls, name, radius_m, material, subdivisions=4) -> Part:
        """An icosphere with vertices on the sphere and exact (radial) smooth normals."""
        vertices, faces = icosphere(subdivisions)
        tris = vertices[faces]
        return cls(name, tris * radius_m, tris.copy(), (material,) * len(tris))


@dataclass(frozen=True, eq=False)
class PosedMesh:
    """The triangles of a scene at given articulation parameters, ready for ray casting.

    Attributes
    ----------
    corners_m : (t, 3, 3) float
    face_normals : (t, 3) float, unit geometric normals from the winding.
    corner_normals : (t, 3, 3) float, unit shading normals at the corners.
    areas_m2 : (t,) float
    material_index : (t,) int, index into ``brdfs``.
    part_index : (t,) int
    brdfs : tuple of BRDF
    """

    corners_m: np.ndarray
    face_normals: np.ndarray
    corner_normals: np.ndarray
    areas_m2: np.ndarray
    material_index: np.ndarray
    part_index: np.ndarray
    brdfs: tuple

    @property
    def vertices_m(self) -> np.ndarray:
        """(3 t, 3) float: the corners as a vertex array (triangle k uses rows 3k..3k+2)."""
        return self.corners_m.reshape(-1, 3)

    def inner_sides(self) -> np.ndarray:
        """(t, 2) bool: True for a triangle side (+ then - normal) that faces the inside of a
        closed, consistently wound part, which no outside ray can reach."""
        inner = np.zeros((len(self.corners_m), 2), dtype=bool)
        extent = float(np.ptp(self.vertices_m, axis=0).max()) or 1.0
        for part in np.unique(self.part_index):
            tris = np.flatnonzero(self.part_index == part)
            corners = self.corners_m[tris]
            _, vertex_id = np.unique(np.round(corners.reshape(-1, 3) / (1e-7 * extent)), axis=0, return_inverse=True)
            vertex_id = vertex_id.reshape(-1, 3)
            edges = np.concatenate([vertex_id[:, [0, 1]], vertex_id[:, [1, 2]], vertex_id[:, [2, 0]]])
            forward = {tuple(e) for e in edges.tolist()}
            closed = len(forward) == len(edges) and all((b, a) in forward for a, b in forward)
            if not closed:
                continue
            volume = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0
            inner[tris, 1 if volume > 0.0 else 0] = True
        return inner

    @property
    def center_m(self) -> np.ndarray:
        return 0.5 * (self.vertices_m.min(axis=0) + self.vertices_m.max(axis=0))

    @property
    def radius_m(self) -> float:
        """Radius of a sphere about ``center_m`` that holds every vertex."""
        return float(np.linalg.norm(self.vertices_m - self.center_m, axis=1).max())


@dataclass(frozen=True, eq=False)
class Scene:
    """An immutable renderable model. Build with :meth:`from_file`, :meth:`from_parts` or
    :meth:`from_arrays`.

    Attributes
    ----------
    corners_m : (t, 3, 3) float, triangle corners in the rest pose, body frame, metres.
    corner_normals : (t, 3, 3) float, unit shading normals.
    material_index : (t,) int, index into ``material_names`` / ``brdfs``.
    material_names : tuple of str
    brdfs : tuple of BRDF
    part_index : (t,) int, index into ``part_names``.
    part_names : tuple of str
    articulations : tuple of Articulation
    parameters : mapping of articulation parameter name to its current value (degrees).
    notes : tuple of str, what construction changed (dropped faces, repairs).
    name : str
    specular_normals : {"cycles", "strict"}
        How specular lobes treat smooth shading normals. ``"cycles"`` (default): about the
        valid-reflection normal, bent from the shading normal toward the face until the view's
        mirror direction clears the surface, as Blender Cycles does
        (:func:`raycast.renderer.brdf.valid_reflection_normal`); ``"strict"``: about the shading
        normal, with no specular light where the observer is below its horizon.
    """

    corners_m: np.ndarray
    corner_normals: np.ndarray
    material_index: np.ndarray
    material_names: tuple
    brdfs: tuple
    part_index: np.ndarray
    part_names: tuple
    articulations: tuple = ()
    parameters: Mapping = field(default_factory=dict)
    notes: tuple = ()
    name: str = "scene"
    specular_normals: str = "cycles"

    def __post_init__(self):
        if self.specular_normals not in SPECULAR_NORMALS:
            raise ValueError(
                f"{self.name}: specular_normals={self.specular_normals!r} is unknown; use one of {SPECULAR_NORMALS}"
            )

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_arrays(
        cls,
        corners_m,
        corner_normals,
        material_index,
        brdfs: Mapping[str, BRDF],
        material_names,
        part_index=None,
        part_names=("body",),
        articulations=(),
        parameters=None,
        repair=False,
        name="scene",
    ) -> Scene:
        """Validate and assemble a scene from per-triangle arrays (the one validating constructor).

        Parameters
        ----------
        corners_m : (t, 3, 3) float
        corner_normals : (t, 3, 3) float, NaN rows mean "use the face normal".
        material_index : (t,) int into ``material_names``.
        brdfs : mapping of material name to BRDF; every used name must be present.
        material_names : sequence of str
        part_index : (t,) int into ``part_names`` (default: one part).
        articulations : sequence of Articulation
        parameters : mapping of parameter name to value; defaults to each articulation's rest.
        repair : bool, keep one face of each set of coincident faces instead of refusing them.
        """
        corners = np.array(corners_m, dtype=float)
        if corners.ndim != 3 or corners.shape[1:] != (3, 3) or len(corners) == 0:
            raise ValueError(f"{name}: corners_m has shape {corners.shape}; expected (t, 3, 3) with t > 0")
        if not np.all(np.isfinite(corners)):
            raise ValueError(f"{name}: some vertex coordinates are not finite; fix the mesh")
        normals = np.array(corner_normals, dtype=float).reshape(corners.shape)
        material_index = np.asarray(material_index, dtype=np.int64)
        part_index = (
            np.zeros(len(corners), dtype=np.int64) if part_index is None else np.asarray(part_index, dtype=np.int64)
        )
        material_names = tuple(material_names)
        part_names = tuple(part_names)
        used = sorted({material_names[i] for i in np.unique(material_index)})
        missing = [m for m in used if m not in brdfs]
        if missing:
            raise ValueError(
                f"{name}: no BRDF for material(s) {', '.join(map(repr, missing))}; "
                "add them to the materials JSON or the brdfs mapping"
            )
        notes = []
        cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        areas = 0.5 * np.linalg.norm(cross, axis=1)
        extent = float(np.ptp(corners.reshape(-1, 3), axis=0).max()) or 1.0
        degenerate = areas <= 1e-12 * extent**2
        if degenerate.all():
            raise ValueError(f"{name}: every triangle has zero area; the mesh has no surface to render")
        if degenerate.any():
            notes.append(f"dropped {int(degenerate.sum())} zero-area triangle(s)")
        keep = ~degenerate
        twins = _coincident_sets(corners, keep, extent, part_index)
        if twins:
            if not repair:
                listed = "; ".join("faces " + ", ".join(map(str, group)) for group in twins[:3])
                raise ValueError(
                    f"{name}: {len(twins)} set(s) of overlapping coplanar triangles ({listed}) make the "
                    "surface ambiguous (a zero-thickness plate exported as two faces?); pass repair=True "
                    "to keep one face of each set as a two-sided surface"
                )
            for group in twins:
                keep[list(group[1:])] = False
            notes.append(f"merged {len(twins)} set(s) of overlapping coplanar triangles into two-sided faces")
        corners, normals = corners[keep], normals[keep]
        material_index, part_index = material_index[keep], part_index[keep]
        face_normals = _unit(cross[keep])
        bad = ~np.all(np.isfinite(normals), axis=2) | (np.linalg.norm(np.nan_to_num(normals), axis=2) < 1e-9)
        normals = np.where(bad[..., None], face_normals[:, None, :], normals)
        normals = _unit(normals)
        articulations = tuple(articulations)
        for art in articulations:
            if art.part not in part_names:
                raise ValueError(
                    f"{name}: articulation {art.parameter!r} names part {art.part!r}, which is not one of {part_names}"
                )
        values = {a.parameter: float(a.rest_deg) for a in articulations}
        values.update({k: float(v) for k, v in (parameters or {}).items()})
        brdf_tuple = tuple(brdfs[m] if m in brdfs else None for m in material_names)
        return cls(
            corners,
            normals,
            material_index,
            material_names,
            brdf_tuple,
            part_index,
            part_names,
            articulations,
            values,
            tuple(notes),
            name,
        )

    @classmethod
    def from_parts(cls, parts, brdfs: Mapping[str, BRDF], articulations=(), parameters=None, name="scene") -> Scene:
        """Assemble a scene from :class:`Part` s and a material-name -> BRDF mapping."""
        material_names = tuple(brdfs)
        lookup = {m: i for i, m in enumerate(material_names)}
        missing = sorted({m for p in parts for m in p.materials if m not in lookup})
        if missing:
            raise ValueError(f"{name}: no BRDF for material(s) {', '.join(map(repr, missing))}")
        corners = np.concatenate([p.corners_m for p in parts])
        normals = np.concatenate([p.corner_normals for p in parts])
        materials = np.concatenate([[lookup[m] for m in p.materials] for p in parts])
        part_index = np.concatenate([np.full(len(p.corners_m), i) for i, p in enumerate(parts)])
        return cls.from_arrays(
            corners,
            normals,
            materials,
            brdfs,
            material_names,
            part_index,
            tuple(p.name for p in parts),
            articulations,
            parameters,
            name=name,
        )

    @classmethod
    def from_file(
        cls,
        path,
        materials=None,
        channel: str = "green",
        default_material: BRDF | None = None,
        repair: bool = False,
        articulations=(),
        parameters=None,
    ) -> Scene:
        """Read a mesh (OBJ, PLY, glTF) and its materials.

        Parameters
        ----------
        path : str or Path, the mesh file.
        materials : str or Path, optional, the sidecar ``.materials.json``. Materials it does not
            name fall back to glTF PBR values, then to the .mtl ``Kd`` as a Lambertian, then to
            ``default_material``.
        channel : str, colour channel standing for the band (see :mod:`raycast.renderer.materials`).
        default_material : BRDF, optional, for materials described nowhere.
        repair : bool, see :meth:`from_arrays`.
        articulations, parameters : see :meth:`from_arrays`.
        """
        path = Path(path)
        data = read_mesh(path)
        records = materials_module.read_materials_json(materials) if materials is not None else {}
        gltf_records = data.material_records.get("gltf", {})
        brdfs = {}
        for name in data.material_names:
            mtl = data.material_records.get(name, {})
            if name in records:
                brdfs[name] = materials_module.brdf_from_record(name, records[name], channel, mtl.get("Ni"))
            elif name in gltf_records:
                brdfs[name] = materials_module.brdf_from_record(name, gltf_records[name], channel)
            elif "Kd" in mtl:
                brdfs[name] = materials_module.brdf_from_mtl(name, mtl, channel)
            elif default_material is not None:
                brdfs[name] = default_material
        corners = data.vertices_m[data.triangles]
        return cls.from_arrays(
            corners,
            data.corner_normals,
            data.material_index,
            brdfs,
            data.material_names,
            data.part_index,
            data.part_names,
            articulations,
            parameters,
            repair,
            name=path.name,
        )

    # ------------------------------------------------------------------ operations
    def with_parameters(self, **values) -> Scene:
        """A new scene with articulation parameters set, e.g. ``panel_pitch_deg=20``."""
        known = {a.parameter for a in self.articulations}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(
                f"{self.name}: unknown articulation parameter(s) {unknown}; this scene has {sorted(known) or 'none'}"
            )
        for key, value in values.items():
            if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value)):
                raise ValueError(f"{self.name}: {key}={value!r} must be a finite number of degrees")
        return replace(self, parameters={**self.parameters, **{k: float(v) for k, v in values.items()}})

    def with_specular_normals(self, mode: str) -> Scene:
        """A new scene whose specular lobes treat shading normals as ``mode`` says
        (``"cycles"`` or ``"strict"``, see the class docstring)."""
        return replace(self, specular_normals=mode)

    def with_brdfs(self, **brdfs) -> Scene:
        """A new scene with some materials' BRDFs replaced (``body_1=Lambertian(0.5)``)."""
        unknown = sorted(set(brdfs) - set(self.material_names))
        if unknown:
            raise ValueError(f"{self.name}: unknown material(s) {unknown}; materials are {self.material_names}")
        return replace(self, brdfs=tuple(brdfs.get(n, b) for n, b in zip(self.material_names, self.brdfs)))

    def posed(self) -> PosedMesh:
        """The triangles at the current parameters."""
        corners = self.corners_m.copy()
        normals = self.corner_normals.copy()
        for art in self.articulations:
            angle = math.radians(self.parameters[art.parameter] - art.rest_deg)
            if angle == 0.0:
                continue
            rotation = _rotation_matrix(art.axis, angle)
            mask = self.part_index == self.part_names.index(art.part)
            pivot = np.asarray(art.axis_point_m)
            corners[mask] = (corners[mask] - pivot) @ rotation.T + pivot
            normals[mask] = normals[mask] @ rotation.T
        cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        return PosedMesh(
            corners,
            _unit(cross),
            normals,
            0.5 * np.linalg.norm(cross, axis=1),
            self.material_index,
            self.part_index,
            self.brdfs,
        )

    @property
    def area_m2(self) -> float:
        """Total one-sided surface area."""
        cross = np.cross(self.corners_m[:, 1] - self.corners_m[:, 0], self.corners_m[:, 2] - self.corners_m[:, 0])
        return float(0.5 * np.linalg.norm(cross, axis=1).sum())

    @property
    def n_triangles(self) -> int:
        return len(self.corners_m)

    def __repr__(self):
        return (
            f"Scene({self.name!r}, {self.n_triangles} triangles, parts={list(self.part_names)}, "
            f"materials={list(self.material_names)}, parameters={dict(self.parameters)})"
        )


def _coincident_sets(corners, keep, extent, part_index):
    """Groups of kept triangles that overlap coplanar (same plane, either facing) triangles of
    the same part. (Faces of different parts that touch, like two boxes bolted together, are
    assembly contacts and hide each other; they are left alone.)

    Returns a list of index tuples: the first triangle of each group is the one kept by a
    repair, the others overlap it. Overlap is tested at three interior points of each
    triangle (near its corners), so partly overlapping triangulations of the same face are
    caught, not only identical triangles.
    """
    indices = np.flatnonzero(keep)
    tri = corners[indices]
    normal = _unit(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]))
    # Canonical sign so that opposite-facing faces of one plane share a key.
    lead = np.take_along_axis(normal, np.argmax(np.abs(normal), axis=1)[:, None], axis=1)
    canon = normal * np.sign(lead)
    offset = np.einsum("ij,ij->i", canon, tri[:, 0])
    key = np.column_stack([part_index[indices], np.round(canon * 1e5), np.round(offset / (1e-5 * extent))]).astype(
        np.int64
    )
    _, plane_id = np.unique(key, axis=0, return_inverse=True)
    plane_id = plane_id.reshape(-1)
    groups = {}
    weights = np.array([[0.8, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8]])
    for plane in np.flatnonzero(np.bincount(plane_id) > 1):
        members = np.flatnonzero(plane_id == plane)
        axis_u = _unit(tri[members[0], 1] - tri[members[0], 0])
        axis_v = np.cross(canon[members[0]], axis_u)
        flat = np.stack([tri[members] @ axis_u, tri[members] @ axis_v], axis=-1)  # (k, 3, 2)
        probes = np.einsum("pc,kcd->kpd", weights, flat)  # (k, 3, 2)
        kept = []
        for local, index in enumerate(members):
            hit = next((other for other in kept if _inside(flat[other], probes[local], 1e-9 * extent)), None)
            if hit is None:
                kept.append(local)
            else:
                groups.setdefault(int(indices[members[hit]]), []).append(int(indices[index]))
    return [(first, *rest) for first, rest in sorted(groups.items())]


def _inside(triangle_2d, points_2d, margin):
    """True if any of ``points_2d`` (p, 2) lies strictly inside ``triangle_2d`` (3, 2)."""
    a, b, c = triangle_2d

    def side(p, q, r):
        return (q[0] - p[0]) * (r[:, 1] - p[1]) - (q[1] - p[1]) * (r[:, 0] - p[0])

    d1, d2, d3 = side(a, b, points_2d), side(b, c, points_2d), side(c, a, points_2d)
    inside = ((d1 > margin) & (d2 > margin) & (d3 > margin)) | ((d1 < -margin) & (d2 < -margin) & (d3 < -margin))
    return bool(inside.any())
