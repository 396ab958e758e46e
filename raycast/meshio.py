"""Reading meshes: OBJ (with ``o`` parts, ``usemtl`` groups, ``vn`` normals, .mtl), PLY and glTF.

Each reader returns a :class:`MeshData` (plain arrays plus names); :meth:`raycast.scene.Scene.from_file`
turns it into a scene with BRDFs. OBJ is parsed here because Open3D drops ``o`` parts and
per-corner normals; PLY and glTF go through Open3D.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["MeshData", "read_mesh", "read_obj", "read_mtl", "read_ply", "read_gltf", "READERS"]


@dataclass(frozen=True, eq=False)
class MeshData:
    """A triangle mesh as read from a file.

    Attributes
    ----------
    vertices_m : (v, 3) float, vertex positions in metres.
    triangles : (t, 3) int, vertex indices, counter-clockwise seen from the front.
    corner_normals : (t, 3, 3) float, shading normal at each triangle corner (NaN where the
        file gives none: the scene then uses the face normal).
    material_index : (t,) int, index into ``material_names``.
    material_names : tuple of str.
    part_index : (t,) int, index into ``part_names``.
    part_names : tuple of str.
    material_records : dict, extra per-material data from the file (.mtl fields, glTF PBR values).
    """

    vertices_m: np.ndarray
    triangles: np.ndarray
    corner_normals: np.ndarray
    material_index: np.ndarray
    material_names: tuple
    part_index: np.ndarray
    part_names: tuple
    material_records: dict


def read_mtl(path) -> dict:
    """Parse a Wavefront .mtl file into ``{name: {"Kd": [r, g, b], "Ni": 1.45, ...}}``."""
    records: dict = {}
    current = None
    for line in Path(path).read_text(errors="replace").splitlines():
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        if tokens[0] == "newmtl":
            current = records.setdefault(" ".join(tokens[1:]), {})
        elif current is not None and tokens[0] in ("Kd", "Ks", "Ka", "Ke"):
            current[tokens[0]] = [float(v) for v in tokens[1:4]]
        elif current is not None and tokens[0] in ("Ns", "Ni", "d"):
            current[tokens[0]] = float(tokens[1])
    return records


def _obj_index(token: str, count: int, path, line_no: int) -> int:
    index = int(token)
    resolved = index - 1 if index > 0 else count + index
    if not 0 <= resolved < count:
        raise ValueError(f"{path}:{line_no}: index {index} is out of range (1..{count}); the OBJ file is corrupt")
    return resolved


def read_obj(path) -> MeshData:
    """Read a Wavefront OBJ with its ``o``/``g`` parts, ``usemtl`` materials and ``vn`` normals.

    Polygons are split into triangle fans. Faces after ``s 1`` without ``vn`` get smooth normals
    (area-weighted vertex averages within the smoothing group); faces without either get
    the face normal.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file {path} does not exist")
    vertices, normals = [], []
    tri_v, tri_n, tri_mat, tri_part, tri_smooth = [], [], [], [], []
    materials, parts = {}, {}
    material, part, smooth = "default", "default", 0
    mtl_records: dict = {}
    for line_no, line in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        key = tokens[0]
        try:
            if key == "v":
                vertices.append([float(t) for t in tokens[1:4]])
            elif key == "vn":
                normals.append([float(t) for t in tokens[1:4]])
            elif key in ("o", "g"):
                part = " ".join(tokens[1:]) or "default"
            elif key == "usemtl":
                material = " ".join(tokens[1:]) or "default"
            elif key == "s":
                smooth = 0 if tokens[1].lower() in ("0", "off") else int(tokens[1])
            elif key == "mtllib":
                mtl_path = path.parent / " ".join(tokens[1:])
                if mtl_path.is_file():
                    mtl_records.update(read_mtl(mtl_path))
            elif key == "f":
                corners = []
                for token in tokens[1:]:
                    fields = token.split("/")
                    v = _obj_index(fields[0], len(vertices), path, line_no)
                    n = (_obj_index(fields[2], len(normals), path, line_no)
                         if len(fields) > 2 and fields[2] else -1)
                    corners.append((v, n))
                if len(corners) < 3:
                    raise ValueError(f"{path}:{line_no}: a face needs at least 3 corners")
                m_id = materials.setdefault(material, len(materials))
                p_id = parts.setdefault(part, len(parts))
                for k in range(1, len(corners) - 1):
                    fan = (corners[0], corners[k], corners[k + 1])
                    tri_v.append([c[0] for c in fan])
                    tri_n.append([c[1] for c in fan])
                    tri_mat.append(m_id)
                    tri_part.append(p_id)
                    tri_smooth.append(smooth)
        except (ValueError, IndexError) as error:
            if str(error).startswith(str(path)):
                raise
            raise ValueError(f"{path}:{line_no}: cannot parse {line.strip()!r} ({error})") from None
    if not tri_v:
        raise ValueError(f"{path}: no faces found; is this an OBJ mesh?")
    vertices_m = np.asarray(vertices, dtype=float)
    triangles = np.asarray(tri_v, dtype=np.int64)
    normal_ids = np.asarray(tri_n, dtype=np.int64)
    corner_normals = np.full(triangles.shape + (3,), np.nan)
    if normals:
        normal_array = np.asarray(normals, dtype=float)
        has = normal_ids >= 0
        corner_normals[has] = normal_array[normal_ids[has]]
    smooth_groups = np.asarray(tri_smooth)
    missing = np.isnan(corner_normals[..., 0]).any(axis=1) & (smooth_groups != 0)
    if missing.any():
        corner_normals[missing] = _smooth_vertex_normals(vertices_m, triangles, smooth_groups)[missing]
    return MeshData(vertices_m, triangles, corner_normals, np.asarray(tri_mat), tuple(materials),
                    np.asarray(tri_part), tuple(parts), mtl_records)


def _smooth_vertex_normals(vertices_m, triangles, groups):
    """(t, 3, 3) area-weighted vertex normals averaged within each smoothing group."""
    corners = vertices_m[triangles]
    area_normals = 0.5 * np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    result = np.full(triangles.shape + (3,), np.nan)
    for group in np.unique(groups[groups != 0]):
        in_group = groups == group
        accum = np.zeros_like(vertices_m)
        for corner in range(3):
            np.add.at(accum, triangles[in_group, corner], area_normals[in_group])
        length = np.linalg.norm(accum, axis=1, keepdims=True)
        unit = accum / np.where(length > 0.0, length, 1.0)
        result[in_group] = unit[triangles[in_group]]
    return result


def _open3d():
    try:
        import open3d as o3d
    except ImportError:  # pragma: no cover - open3d is a core dependency
        raise ImportError("reading PLY and glTF needs open3d; pip install open3d") from None
    return o3d


def _legacy_mesh_arrays(mesh):
    vertices = np.asarray(mesh.vertices, dtype=float)
    triangles = np.asarray(mesh.triangles, dtype=np.int64)
    if mesh.has_vertex_normals():
        corner_normals = np.asarray(mesh.vertex_normals, dtype=float)[triangles]
    else:
        corner_normals = np.full(triangles.shape + (3,), np.nan)
    return vertices, triangles, corner_normals


def read_ply(path) -> MeshData:
    """Read a PLY mesh through Open3D: one part, one material named ``"default"``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file {path} does not exist")
    mesh = _open3d().io.read_triangle_mesh(str(path))
    vertices, triangles, corner_normals = _legacy_mesh_arrays(mesh)
    if len(triangles) == 0:
        raise ValueError(f"{path}: no triangles read; is this a PLY triangle mesh?")
    zeros = np.zeros(len(triangles), dtype=np.int64)
    return MeshData(vertices, triangles, corner_normals, zeros, ("default",), zeros, (path.stem,), {})


def read_gltf(path) -> MeshData:
    """Read a glTF/GLB model through Open3D: each mesh is a part; PBR materials become records
    ``{"blender_node": "Principled BSDF", "base_color", "metallic", "roughness"}``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file {path} does not exist")
    model = _open3d().io.read_triangle_model(str(path))
    all_v, all_t, all_n, all_m, all_p = [], [], [], [], []
    offset = 0
    part_names = []
    for part_id, info in enumerate(model.meshes):
        vertices, triangles, corner_normals = _legacy_mesh_arrays(info.mesh)
        all_v.append(vertices)
        all_t.append(triangles + offset)
        all_n.append(corner_normals)
        all_m.append(np.full(len(triangles), info.material_idx, dtype=np.int64))
        all_p.append(np.full(len(triangles), part_id, dtype=np.int64))
        part_names.append(info.mesh_name or f"mesh{part_id}")
        offset += len(vertices)
    if not all_t or sum(len(t) for t in all_t) == 0:
        raise ValueError(f"{path}: no triangles read; is this a glTF model?")
    names, records = [], {}
    for index, material in enumerate(model.materials):
        name = getattr(material, "name", "") or f"material{index}"
        names.append(name)
        color = getattr(material, "base_color", None)
        records[name] = {
            "blender_node": "Principled BSDF",
            "base_color": [float(c) for c in (color[:3] if color is not None else (0.8, 0.8, 0.8))],
            "metallic": float(getattr(material, "base_metallic", 0.0)),
            "roughness": float(getattr(material, "base_roughness", 0.5)),
        }
    material_index = np.concatenate(all_m)
    if not names:
        names, material_index = ["default"], np.zeros_like(material_index)
    return MeshData(np.concatenate(all_v), np.concatenate(all_t), np.concatenate(all_n),
                    material_index, tuple(names), np.concatenate(all_p), tuple(part_names),
                    {"gltf": records})


READERS = {".obj": read_obj, ".ply": read_ply, ".gltf": read_gltf, ".glb": read_gltf}


def read_mesh(path) -> MeshData:
    """Read a mesh with the reader for its suffix (see :data:`READERS`)."""
    suffix = Path(path).suffix.lower()
    if suffix not in READERS:
        raise ValueError(f"mesh {path}: suffix {suffix!r} is not supported; use one of {', '.join(READERS)}")
    return READERS[suffix](path)
