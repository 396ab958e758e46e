"""The OBJ reader triangulates polygons as Blender does, checked against Blender itself."""

import numpy as np
import pytest

from raycast.renderer.meshio import read_obj, triangulate_polygon


def random_polygons(rng, count):
    """Regular, convex-random and star-shaped (concave) polygons of 4-40 corners, some slightly
    warped out of their plane, each in a random orientation."""
    polygons = []
    for case in range(count):
        k = int(rng.integers(4, 40))
        angle = np.sort(rng.uniform(0, 2 * np.pi, k)) if case % 3 else np.arange(k) * 2 * np.pi / k
        radius = rng.uniform(0.3, 1.0, k) if case % 2 else np.ones(k)
        warp = rng.normal(0, 0.02, k) if case % 5 == 0 else np.zeros(k)
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        points = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), warp]) @ rotation.T
        polygons.append(points + [3.0 * case, 0.0, 0.0])
    return polygons


def test_regular_polygons_are_not_fans():
    hexagon = np.column_stack([np.cos(np.arange(6) * np.pi / 3), np.sin(np.arange(6) * np.pi / 3), np.zeros(6)])
    assert triangulate_polygon(hexagon) == [(5, 0, 1), (1, 2, 3), (3, 4, 5), (1, 3, 5)]


def test_a_concave_quad_is_split_along_the_diagonal_inside_it():
    dart = np.array([[0.0, 0.0, 0.0], [1.0, 0.2, 0.0], [0.0, 1.0, 0.0], [0.3, 0.3, 0.0]])  # corner 3 inside
    assert triangulate_polygon(dart) == [(0, 1, 3), (1, 2, 3)]


def test_every_polygon_is_covered_once(tmp_path):
    # The triangles of a planar polygon cover exactly its area (no overlaps, no gaps).
    for points in random_polygons(np.random.default_rng(7), 40):
        points[:, 2] = 0.0 if np.ptp(points[:, 2]) < 1e-9 else points[:, 2]
        triangles = np.asarray(triangulate_polygon(points))
        assert len(triangles) == len(points) - 2
        normal = np.cross(
            points[triangles[:, 1]] - points[triangles[:, 0]], points[triangles[:, 2]] - points[triangles[:, 0]]
        )
        polygon_normal = sum(np.cross(points[i], points[(i + 1) % len(points)]) for i in range(len(points)))
        # Same winding as the polygon, areas summing to its area (to rounding, 1e-9 relative).
        assert np.all(normal @ polygon_normal > 0)
        assert 0.5 * np.linalg.norm(normal.sum(axis=0)) == pytest.approx(0.5 * np.linalg.norm(polygon_normal), rel=1e-9)


@pytest.mark.cycles
def test_triangles_match_blenders_tessellation(tmp_path):
    bpy = pytest.importorskip("bpy")
    polygons = random_polygons(np.random.default_rng(3), 150)
    lines, starts = [], []
    for points in polygons:
        starts.append(sum(len(p) for p in polygons[: len(starts)]))
        lines += [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in points]
    for start, points in zip(starts, polygons):
        lines.append("f " + " ".join(str(start + i + 1) for i in range(len(points))))
    path = tmp_path / "polygons.obj"
    path.write_text("\n".join(lines) + "\n")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.obj_import(filepath=str(path), forward_axis="Y", up_axis="Z")
    mesh = bpy.context.scene.objects[0].data
    blender = {}
    for triangle in mesh.loop_triangles:
        corners = tuple(mesh.loops[loop].vertex_index for loop in triangle.loops)
        blender.setdefault(triangle.polygon_index, set()).add(corners)
    ours = read_obj(path)
    assert len(blender) == len(polygons)
    first = 0
    for index, points in enumerate(polygons):
        count = len(points) - 2
        assert {tuple(t) for t in ours.triangles[first : first + count].tolist()} == blender[index], index
        first += count
