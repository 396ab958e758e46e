"""Reading meshes: OBJ (with ``o`` parts, ``usemtl`` groups, ``vn`` normals, .mtl), PLY and glTF.

Each reader returns a :class:`MeshData` (plain arrays plus names); :meth:`raycast.renderer.scene.Scene.from_file`
turns it into a scene with BRDFs. OBJ is parsed here because Open3D drops ``o`` parts and
per-corner normals; PLY and glTF go through Open3D.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ingest.errors import FormatError

__all__ = ["MeshData", "read_mesh", "read_obj", "read_mtl", "read_ply", "read_gltf", "READERS", "triangulate_polygon"]


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
    """Parse a Wavefront .mtl file into ``{name: {"Kd": [r, g, b], "Ni": 1.45, ...}}``.

    Raises
    ------
    FormatError
        A number that does not parse, naming the file and line.
    """
    records: dict = {}
    current = None
    for line_no, line in enumerate(Path(path).read_text(errors="replace").splitlines(), start=1):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        try:
            if tokens[0] == "newmtl":
                current = records.setdefault(" ".join(tokens[1:]), {})
            elif current is not None and tokens[0] in ("Kd", "Ks", "Ka", "Ke"):
                current[tokens[0]] = [float(v) for v in tokens[1:4]]
            elif current is not None and tokens[0] in ("Ns", "Ni", "d"):
                current[tokens[0]] = float(tokens[1])
        except (ValueError, IndexError):
            raise FormatError(path, line_no, f"cannot read {line.strip()!r} as numbers") from None
    return records


def _obj_index(token: str, count: int, what: str) -> int:
    index = int(token)
    resolved = index - 1 if index > 0 else count + index
    if index == 0 or not 0 <= resolved < count:
        plural = {"vertex": "vertices", "normal": "normals"}[what]
        raise ValueError(f"{what} index {index} is outside the {count} {plural} defined so far")
    return resolved


def read_obj(path) -> MeshData:
    """Read a Wavefront OBJ with its ``o``/``g`` parts, ``usemtl`` materials and ``vn`` normals.

    Triangles and normals follow Blender's OBJ importer and its tessellation, so that this
    renderer and Cycles are given the same surface:

    * polygons are triangulated as Blender triangulates faces for rendering
      (`triangulate_polygon`);
    * when the file has any ``vn``, every face is smooth and takes the file's normal at each
      corner (``s`` is then ignored, as Blender's importer ignores it); a corner without one
      takes the automatic normal;
    * without ``vn``, faces after ``s 0``/``s off`` (or before any ``s``) are flat and the others
      smooth, with Blender's automatic vertex normals (face normals weighted by the corner
      angle, over the smooth faces around the vertex).

    Flat corners are NaN in `MeshData.corner_normals`.

    Raises
    ------
    FileNotFoundError
        No such file.
    FormatError
        A line that cannot be read, naming the file and line.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"mesh file {path} does not exist")
    vertices, normals = [], []
    polygons = []  # (vertex ids, normal ids, material id, part id, smooth)
    materials, parts = {}, {}
    material, part, smooth = "default", "default", False
    mtl_records: dict = {}
    for line_no, line in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        key = tokens[0]
        try:
            if key in ("v", "vn"):
                if len(tokens) < 4:
                    raise ValueError(f"{key} needs x y z")
                (vertices if key == "v" else normals).append([float(t) for t in tokens[1:4]])
            elif key in ("o", "g"):
                part = " ".join(tokens[1:]) or "default"
            elif key == "usemtl":
                material = " ".join(tokens[1:]) or "default"
            elif key == "s":
                smooth = len(tokens) > 1 and tokens[1].lower() not in ("0", "off", "null")
            elif key == "mtllib":
                mtl_path = path.parent / " ".join(tokens[1:])
                if mtl_path.is_file():  # Blender's importer only warns about a missing .mtl
                    mtl_records.update(read_mtl(mtl_path))
            elif key == "f":
                if len(tokens) < 4:
                    raise ValueError("a face needs at least 3 corners")
                corner_v, corner_n = [], []
                for token in tokens[1:]:
                    fields = token.split("/")
                    corner_v.append(_obj_index(fields[0], len(vertices), "vertex"))
                    has_normal = len(fields) > 2 and fields[2]
                    corner_n.append(_obj_index(fields[2], len(normals), "normal") if has_normal else -1)
                polygons.append(
                    (
                        corner_v,
                        corner_n,
                        materials.setdefault(material, len(materials)),
                        parts.setdefault(part, len(parts)),
                        smooth,
                    )
                )
        except ValueError as error:
            raise FormatError(path, line_no, str(error)) from None
    if not polygons:
        raise FormatError(path, None, "no faces; an OBJ mesh needs at least one 'f' line")
    vertices_m = np.asarray(vertices, dtype=float)
    normal_array = np.asarray(normals, dtype=float).reshape(-1, 3)
    normal_array = normal_array / np.maximum(np.linalg.norm(normal_array, axis=1, keepdims=True), 1e-300)
    auto = _angle_weighted_vertex_normals(vertices_m, polygons, use_all=len(normals) > 0)
    triangles, corner_normals, tri_mat, tri_part = [], [], [], []
    for corner_v, corner_n, m_id, p_id, smooth in polygons:
        points = vertices_m[corner_v]
        flat = (not normals and not smooth) or _polygon_area(points) < 1e-12
        for tri in triangulate_polygon(points):
            triangles.append([corner_v[k] for k in tri])
            if flat:
                corner_normals.append(np.full((3, 3), np.nan))
            else:
                corner_normals.append(
                    [normal_array[corner_n[k]] if corner_n[k] >= 0 else auto[corner_v[k]] for k in tri]
                )
            tri_mat.append(m_id)
            tri_part.append(p_id)
    return MeshData(
        vertices_m,
        np.asarray(triangles, dtype=np.int64),
        np.asarray(corner_normals, dtype=float),
        np.asarray(tri_mat, dtype=np.int64),
        tuple(materials),
        np.asarray(tri_part, dtype=np.int64),
        tuple(parts),
        mtl_records,
    )


def _newell_normal(points) -> np.ndarray:
    """(3,) the (unnormalised) Newell normal of a polygon's corners (k, 3) in order."""
    nxt = np.roll(points, -1, axis=0)
    return np.array(
        [
            np.sum((points[:, 1] - nxt[:, 1]) * (points[:, 2] + nxt[:, 2])),
            np.sum((points[:, 2] - nxt[:, 2]) * (points[:, 0] + nxt[:, 0])),
            np.sum((points[:, 0] - nxt[:, 0]) * (points[:, 1] + nxt[:, 1])),
        ]
    )


def _polygon_area(points) -> float:
    return 0.5 * float(np.linalg.norm(_newell_normal(points)))


def _angle_weighted_vertex_normals(vertices_m, polygons, use_all: bool) -> np.ndarray:
    """(v, 3) Blender's automatic vertex normals: the unit face normals of the smooth polygons
    around each vertex (every polygon when ``use_all``), weighted by the polygon's angle at it."""
    accum = np.zeros_like(vertices_m)
    for corner_v, _, _, _, smooth in polygons:
        if not (smooth or use_all):
            continue
        points = vertices_m[corner_v]
        normal = _newell_normal(points)
        length = np.linalg.norm(normal)
        if length == 0.0:
            continue
        to_prev = np.roll(points, 1, axis=0) - points
        to_next = np.roll(points, -1, axis=0) - points
        cosine = np.einsum("ij,ij->i", to_prev, to_next) / np.maximum(
            np.linalg.norm(to_prev, axis=1) * np.linalg.norm(to_next, axis=1), 1e-300
        )
        np.add.at(accum, corner_v, np.arccos(np.clip(cosine, -1.0, 1.0))[:, None] * (normal / length))
    length = np.linalg.norm(accum, axis=1, keepdims=True)
    return np.where(length > 0.0, accum / np.where(length > 0.0, length, 1.0), np.nan)


def triangulate_polygon(points) -> list[tuple[int, int, int]]:
    """Triangles (corner indices) of a polygon, as Blender tessellates a face for rendering.

    Triangles are kept as they are; a quad is split along its 0-2 diagonal unless corners 1 and
    3 lie on the same side of it (then along 1-3); larger polygons are ear-clipped in the plane
    of their Newell normal, starting at corner 0 and sweeping back and forth so that convex
    polygons do not become fans (Blender's ``BLI_polyfill_calc``). Each triangle keeps the
    polygon's winding.

    Parameters
    ----------
    points : (k, 3) float
        The corners in order, k >= 3.

    Examples
    --------
    >>> angles = np.arange(5) * 2 * np.pi / 5
    >>> triangulate_polygon(np.column_stack([np.cos(angles), np.sin(angles), np.zeros(5)]))
    [(4, 0, 1), (1, 2, 3), (1, 3, 4)]
    """
    points = np.asarray(points, dtype=float)
    k = len(points)
    if k == 3:
        return [(0, 1, 2)]
    if k == 4:
        first = np.cross(points[1] - points[0], points[2] - points[0])
        third = np.cross(points[3] - points[0], points[2] - points[0])
        return [(0, 1, 3), (1, 2, 3)] if float(first @ third) > 0.0 else [(0, 1, 2), (0, 2, 3)]
    return _ear_clip(_blender_plane_coordinates(points))


def _blender_plane_coordinates(points) -> np.ndarray:
    """(k, 2) float32 coordinates of the corners in the plane of the polygon, in Blender's basis
    (its face normal negated, so a counter-clockwise polygon runs clockwise), so that nearly
    collinear corners are classified as Blender classifies them."""
    normal = _newell_normal(points)
    length = np.linalg.norm(normal)
    axis = (-(normal / length) if length > 0.0 else np.array([0.0, 0.0, -1.0])).astype(np.float32)
    squared = axis[0] * axis[0] + axis[1] * axis[1]
    if squared > np.finfo(np.float32).eps:
        d = np.float32(1.0) / np.sqrt(squared)
        n1 = np.array([axis[1] * d, -axis[0] * d, 0.0], dtype=np.float32)
        n2 = np.array([-axis[2] * n1[1], axis[2] * n1[0], axis[0] * n1[1] - axis[1] * n1[0]], dtype=np.float32)
    else:
        n1 = np.array([-1.0 if axis[2] < 0 else 1.0, 0.0, 0.0], dtype=np.float32)
        n2 = np.array([0.0, 1.0, 0.0], dtype=np.float32)
    corners = np.asarray(points, dtype=np.float32)
    return np.column_stack(
        [
            corners[:, 0] * n1[0] + corners[:, 1] * n1[1] + corners[:, 2] * n1[2],
            corners[:, 0] * n2[0] + corners[:, 1] * n2[1] + corners[:, 2] * n2[2],
        ]
    )


def _side(a, b, c) -> int:
    """Sign (+1, 0, -1) of the doubled area of triangle (c, b, a), in float32 as Blender's polygon
    filler computes it; for a clockwise polygon, +1 at a convex corner b of a -> b -> c."""
    area = (b[0] - c[0]) * (a[1] - c[1]) - (a[0] - c[0]) * (b[1] - c[1])
    return 1 if area > 0 else (0 if area == 0 else -1)


def _ear_clip(xy) -> list[tuple[int, int, int]]:
    """Ear clipping of a clockwise 2-D polygon (k, 2) in Blender's order (see `triangulate_polygon`).

    A corner is convex (+1), tangential (0) or concave (-1); an ear's tip must be convex (or,
    failing any, tangential) with no other non-convex corner inside or on its triangle."""
    n = len(xy)
    nxt, prv = list(range(1, n)) + [0], [n - 1] + list(range(n - 1))
    sign = [_side(xy[prv[i]], xy[i], xy[nxt[i]]) for i in range(n)]
    alive = [True] * n
    head, remaining, reverse, start = 0, n, False, 0
    triangles = []

    def non_convex_inside(tip) -> bool:
        a, b, c = xy[prv[tip]], xy[tip], xy[nxt[tip]]
        for j in range(n):
            if alive[j] and sign[j] != 1 and j not in (prv[tip], tip, nxt[tip]):
                p = xy[j]
                if _side(c, a, p) != -1 and _side(a, b, p) != -1 and _side(b, c, p) != -1:
                    return True
        return False

    def find_tip(first) -> int:
        concave = sum(1 for j in range(n) if alive[j] and sign[j] != 1)
        for accept in (1, 0):
            tip = first
            for _ in range(remaining):
                if concave == 0 or (sign[tip] == accept and not non_convex_inside(tip)):
                    return tip
                tip = prv[tip] if reverse else nxt[tip]
        tip = first
        for _ in range(remaining):
            if sign[tip] != -1:
                return tip
            tip = nxt[tip]
        return tip

    while remaining > 3:
        tip = find_tip(start)
        before, after = prv[tip], nxt[tip]
        triangles.append((before, tip, after))
        alive[tip] = False
        nxt[before], prv[after] = after, before
        if head == tip:
            head = after
        remaining -= 1
        for corner in (before, after):
            if sign[corner] != 1:
                sign[corner] = _side(xy[prv[corner]], xy[corner], xy[nxt[corner]])
        start = prv[before] if reverse else nxt[after]
        if sign[start] != 1:
            start = prv[start] if reverse else nxt[start]
            reverse = not reverse
    triangles.append((head, nxt[head], nxt[nxt[head]]))
    return triangles


def _open3d():
    try:
        # Open3D takes seconds to import (and pulls in Dash); only ray casting needs it.
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
    return MeshData(
        np.concatenate(all_v),
        np.concatenate(all_t),
        np.concatenate(all_n),
        material_index,
        tuple(names),
        np.concatenate(all_p),
        tuple(part_names),
        {"gltf": records},
    )


READERS = {".obj": read_obj, ".ply": read_ply, ".gltf": read_gltf, ".glb": read_gltf}


def read_mesh(path) -> MeshData:
    """Read a mesh with the reader for its suffix (see :data:`READERS`)."""
    suffix = Path(path).suffix.lower()
    if suffix not in READERS:
        raise ValueError(f"mesh {path}: suffix {suffix!r} is not supported; use one of {', '.join(READERS)}")
    return READERS[suffix](path)
