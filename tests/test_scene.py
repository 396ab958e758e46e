"""Scenes: mesh readers, materials, parts, articulations, degenerate meshes; photometry."""

import math

import numpy as np
import pytest

from raycast.models import cosmos2502, topex
from raycast.renderer import photometry
from raycast.renderer.brdf import GGX, Lambertian, Principled
from raycast.renderer.scene import Part, Scene
from tests.conftest import MODELS

PAPER_OBJ = MODELS / "cosmos2502_lotos.obj"
PAPER_JSON = MODELS / "cosmos2502_lotos.materials.json"
PLATE_OBJ = MODELS / "plate_1m.obj"


@pytest.fixture(scope="module")
def paper():
    return Scene.from_file(PAPER_OBJ, materials=PAPER_JSON)


def test_paper_model_parts_materials_and_normals(paper):
    # The file has 2184 triangles (all faces are triangles) in five `o` parts.
    assert paper.n_triangles == 2184
    assert set(paper.part_names) == {"Sat_cross_1", "Sat_cross_2", "Sat_sp1", "Sat_sp2", "Sat_tube"}
    brdf = dict(zip(paper.material_names, paper.brdfs))
    assert brdf["spb_2"] == GGX(color=0.0763, roughness=0.3)  # the JSON's green channel
    # Principled IOR comes from the .mtl Ni (1.45): F0 = (0.45 / 2.45)^2.
    assert isinstance(brdf["body_1"], Principled)
    assert brdf["body_1"].base_color == 0.3588 and brdf["body_1"].ior == 1.45
    assert brdf["body_1"].f0 == pytest.approx((0.45 / 2.45) ** 2, rel=1e-12)
    # The tube is smooth-shaded: corner normals differ from face normals by up to half a facet.
    tube = paper.part_index == paper.part_names.index("Sat_tube")
    mesh = paper.posed()
    spread = np.einsum("tcj,tj->tc", mesh.corner_normals[tube], mesh.face_normals[tube]).min()
    assert spread < math.cos(math.radians(2.0))
    flat = ~tube
    assert np.allclose(np.einsum("tcj,tj->tc", mesh.corner_normals[flat], mesh.face_normals[flat]), 1.0, atol=1e-6)


def test_channel_selects_band_colour():
    blue = Scene.from_file(PAPER_OBJ, materials=PAPER_JSON, channel="blue")
    assert dict(zip(blue.material_names, blue.brdfs))["spb_2"].color == 0.1750


def test_plate_with_overlapping_faces_is_refused_then_repaired():
    with pytest.raises(ValueError, match=r"overlapping coplanar triangles .* pass repair=True"):
        Scene.from_file(PLATE_OBJ)
    plate = Scene.from_file(PLATE_OBJ, repair=True)
    # Two triangles of the 1 m x 1 m face remain; the four zero-area sides are dropped.
    assert plate.n_triangles == 2
    assert plate.area_m2 == pytest.approx(1.0, rel=1e-12)
    assert any("zero-area" in note for note in plate.notes)
    assert any("overlapping coplanar" in note for note in plate.notes)


def test_zero_area_triangles_are_dropped():
    box = Part.box("box", (1.0, 2.0, 3.0), "m")
    sliver = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]])
    scene = Scene.from_arrays(
        np.concatenate([box.corners_m, sliver]),
        np.concatenate([box.corner_normals, np.full((1, 3, 3), np.nan)]),
        np.zeros(13, dtype=int),
        {"m": Lambertian(0.5)},
        ["m"],
    )
    assert scene.n_triangles == 12
    assert scene.area_m2 == pytest.approx(2 * (2 + 6 + 3), rel=1e-12)
    assert scene.notes == ("dropped 1 zero-area triangle(s)",)


def test_missing_material_message():
    with pytest.raises(ValueError, match="no BRDF for material\\(s\\) 'paint'"):
        Scene.from_parts([Part.box("box", (1, 1, 1), "paint")], {"other": Lambertian(0.5)})


@pytest.mark.parametrize("suffix", [".ply", ".gltf"])
def test_ply_and_gltf_through_open3d(tmp_path, suffix):
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh.create_box(1.0, 2.0, 3.0)
    mesh.compute_vertex_normals()
    path = tmp_path / f"box{suffix}"
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    scene = Scene.from_file(path, default_material=Lambertian(0.4))
    assert scene.n_triangles == 12
    assert scene.area_m2 == pytest.approx(22.0, rel=1e-6)


def test_unknown_suffix_message(tmp_path):
    path = tmp_path / "shape.stl"
    path.write_text("solid")
    with pytest.raises(ValueError, match="suffix '.stl' is not supported"):
        Scene.from_file(path)


def test_obj_parse_error_names_line(tmp_path):
    path = tmp_path / "bad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    with pytest.raises(ValueError, match=r"bad.obj:4: vertex index 7 is outside the 3 vertices defined so far"):
        Scene.from_file(path, default_material=Lambertian(0.5))


def test_topex_dimensions_and_articulation():
    scene = topex.build()
    assert scene.parameters == {"panel_pitch_deg": 12.0}
    cells = scene.material_index == scene.material_names.index("solar_cells")
    mesh = scene.posed()
    # The cell face is the 8.89 m x 3.30 m array (datasheet size).
    assert mesh.areas_m2[cells].sum() == pytest.approx(8.89 * 3.30, rel=1e-12)
    for pitch in (0.0, 12.0, 40.0):
        normal = scene.with_parameters(panel_pitch_deg=pitch).posed().face_normals[cells][0]
        # Rotation of +x about +y by the pitch: (cos p, 0, -sin p).
        p = math.radians(pitch)
        np.testing.assert_allclose(normal, [math.cos(p), 0.0, -math.sin(p)], atol=1e-12)
    # The bus is the IDS macro-model's box: faces of 8.32, 8.18 and 4.71 m^2.
    bus = scene.part_index == scene.part_names.index("bus")
    normals = mesh.face_normals[bus]
    for axis, area in ((2, 8.32), (1, 8.18), (0, 4.71)):
        assert mesh.areas_m2[bus][normals[:, axis] > 0.5].sum() == pytest.approx(area, rel=1e-12)
    # Extent at pitch 0: the bus's 3.80 m along x; along y half the bus, the 1 m yoke and the
    # 8.89 m array on one side and half the bus on the other; along z the 3.30 m array (+-1.65)
    # and, below the zenith face, the 2.6 m boom and the 0.2 m deep 1.3 m dish.
    extent = np.ptp(topex.build(panel_pitch_deg=0.0).corners_m.reshape(-1, 3), axis=0)
    x_m, y_m, z_m = topex.BUS_SIZE_M
    np.testing.assert_allclose(extent, [x_m, y_m + 1.0 + 8.89, 1.65 + z_m / 2 + 2.6 + 0.2], atol=1e-9)
    assert (round(x_m, 2), round(y_m, 2), round(z_m, 2)) == (3.80, 2.19, 2.15)


def test_topex_surface_parameters_change_only_their_class():
    base, shiny = topex.surface_brdfs(), topex.surface_brdfs(cells_roughness=0.3, bus_albedo=0.7)
    assert base["solar_cells"].roughness == 0.15 and shiny["solar_cells"].roughness == 0.3
    assert shiny["bus"].base_color == 0.7 and shiny["array_back"] == base["array_back"]
    with pytest.raises(ValueError, match=r"cells_specular=2.0 is outside its range \[0.5, 1.0\]"):
        topex.surface_brdfs(cells_specular=2.0)
    with pytest.raises(ValueError, match=r"unknown TOPEX surface parameter\(s\) \['gloss'\]"):
        topex.build(gloss=0.1)


def test_topex_dish_albedo_scales_only_the_dishes_light():
    # Seen and lit from nadir (+z) the altimeter dish shows: its light is linear in
    # antenna_albedo, the boom keeps its paint, and the rest of the scene does not move.
    from raycast.renderer.direct import DirectRenderer

    brdfs = topex.surface_brdfs(antenna_albedo=0.05)
    assert brdfs["antenna"].albedo == 0.05 and brdfs["boom"].albedo == topex.ANTENNA_ALBEDO
    sun = np.array([[0.2, 0.1, 1.0], [0.0, 0.3, 1.0]])
    obs = np.array([[-0.1, 0.2, 1.0], [0.3, -0.2, 1.0]])
    sun, obs = (v / np.linalg.norm(v, axis=1, keepdims=True) for v in (sun, obs))
    light = [DirectRenderer(topex.build(antenna_albedo=a), 0.05).intensity(sun, obs) for a in (0.05, 0.45, 0.85)]
    step = light[1] - light[0]
    assert np.all(step > 0.02 * light[1])
    np.testing.assert_allclose(light[2] - light[1], step, rtol=1e-9)


def test_articulation_parameter_validation():
    with pytest.raises(ValueError, match=r"unknown articulation parameter\(s\) \['pitch'\]"):
        topex.build().with_parameters(pitch=3.0)
    with pytest.raises(ValueError, match="panel_pitch_deg=nan must be a finite number"):
        topex.build().with_parameters(panel_pitch_deg=float("nan"))


def test_cosmos_lookalike_matches_paper_size(paper):
    look = cosmos2502.build()
    tube = look.part_index == look.part_names.index("tube")
    # Cylinder 3.5 m x 12 m: side area pi d L within the 48-gon's 0.3% deficit, plus two caps.
    side = np.pi * 3.5 * 12.0 + 2 * np.pi * 1.75**2
    area = look.posed().areas_m2[tube].sum()
    assert area == pytest.approx(side, rel=4e-3)
    assert np.ptp(look.corners_m[..., 2]) == pytest.approx(np.ptp(paper.corners_m[..., 2]), abs=0.3)


def test_photometry_magnitudes():
    # I/E = 0.5/pi m^2/sr at 1000 km: m = -26.76 - 2.5 log10(0.159155 / 1e12).
    expected = -26.76 - 2.5 * math.log10(0.5 / math.pi / 1e12)
    assert photometry.magnitude(0.5 / math.pi, 1000.0, "V") == pytest.approx(expected, abs=1e-12)
    # Inverse, and the 5 log10 range law.
    assert photometry.intensity_from_magnitude(expected, 1000.0) == pytest.approx(0.5 / math.pi, rel=1e-12)
    assert photometry.magnitude(1.0, 2000.0) - photometry.magnitude(1.0, 1000.0) == pytest.approx(5 * math.log10(2))
    assert photometry.magnitude(0.0, 1000.0) == np.inf
    assert set(photometry.SOLAR_MAGNITUDE_SOURCES) == set(photometry.SOLAR_MAGNITUDES)
    with pytest.raises(ValueError, match="band 'U' has no solar magnitude"):
        photometry.magnitude(1.0, 1000.0, "U")


def test_mix_shader_record_reads_as_a_mix_of_its_two_nodes():
    from raycast.cycles.runner import material_entry
    from raycast.renderer.brdf import GGX, Mix, Principled
    from raycast.renderer.materials import brdf_from_record

    record = {
        "blender_node": "Mix Shader",
        "fac": 0.25,
        "shaders": [
            {"blender_node": "Principled BSDF", "base_color": [0.1, 0.3, 0.5], "metallic": 0.9, "roughness": 0.45},
            {"blender_node": "Glossy BSDF", "color": [0.9, 0.9, 0.9], "roughness": 0.08},
        ],
    }
    brdf = brdf_from_record("bus", record, channel="blue")
    assert brdf == Mix(Principled(0.5, metallic=0.9, roughness=0.45), GGX(0.9, 0.08), 0.25)
    # The Cycles entry of the BRDF reads back as the same BRDF.
    assert brdf_from_record("bus", material_entry(brdf)) == brdf
    with pytest.raises(ValueError, match="material 'bus': shaders=.* is not a list of two node records"):
        brdf_from_record("bus", {**record, "shaders": record["shaders"][:1]})
    with pytest.raises(ValueError, match="material 'bus': Mix: second=.* must be a Lambertian"):
        brdf_from_record("bus", {**record, "shaders": [record["shaders"][0], record]})
