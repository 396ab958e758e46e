"""Blender Cycles as the authority: its conventions checked against closed forms, then the paper's model.

Every render here is direct light only, box filter, float output (see raycast/cycles/runner.py). The
tolerances come from Cycles' sampling noise measured at the settings used (docs/cycles.md): at
64 samples/px and 128 px a plate's I/E scatters by 1e-5 .. 1e-4 relative between seeds, a
sphere's by up to 1e-3 at phase 150 deg.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from raycast.cycles.runner import CyclesMesh, CyclesSettings, measure_noise, render_cycles
from raycast.renderer.scene import icosphere
from tests.conftest import MODELS, PROJECT_ROOT

SUN_ANGLE_DEG = 0.53
PLATE_VERTICES = [[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]]
PLATE_TRIANGLES = [[0, 1, 2], [0, 2, 3]]
PLATE_AREA_M2 = 1.0
COSMOS_OBJ = MODELS / "cosmos2502_lotos.obj"
COSMOS_MATERIALS = MODELS / "cosmos2502_lotos.materials.json"
PLATE_OBJ = MODELS / "plate_1m.obj"


# ---------------------------------------------------------------------------------------------
# Closed forms


def unit(vectors):
    vectors = np.asarray(vectors, dtype=float)
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def sun_disk(sun, angle_deg=SUN_ANGLE_DEG, n_radial=16, n_azimuth=32):
    """Quadrature over a uniform disk of directions around each of `sun` (m, 3).

    Returns directions (m, q, 3) and weights (q,) summing to 1: Gauss-Legendre in the area
    fraction (r / radius)^2, midpoint in azimuth. Exact to ~1e-9 for the smooth integrands here.
    """
    radius = np.radians(angle_deg) / 2
    nodes, weights = np.polynomial.legendre.leggauss(n_radial)
    area_fraction, weights = (nodes + 1) / 2, weights / 2
    r = radius * np.sqrt(area_fraction)
    phi = (np.arange(n_azimuth) + 0.5) * 2 * np.pi / n_azimuth
    helper = np.where(np.abs(sun[:, :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    a = unit(np.cross(sun, helper))
    b = np.cross(sun, a)
    offset = np.cos(phi)[None, :, None] * a[:, None, :] + np.sin(phi)[None, :, None] * b[:, None, :]
    directions = (
        np.cos(r)[None, :, None, None] * sun[:, None, None, :] + np.sin(r)[None, :, None, None] * offset[:, None, :, :]
    )
    return directions.reshape(len(sun), -1, 3), np.repeat(weights, n_azimuth) / n_azimuth


def ggx_brdf(wi, wo, alpha, masking="height-correlated"):
    """GGX microfacet BRDF with unit reflectance and no Fresnel, surface normal +Z.

    ``masking="height-correlated"``: G = 1 / (1 + Lambda(i) + Lambda(o)) (Heitz 2014);
    ``"separable"``: G = G1(i) G1(o) = 1 / ((1 + Lambda(i)) (1 + Lambda(o))).
    """
    h = unit(wi + wo)
    cos_i, cos_o, cos_h = wi[..., 2], wo[..., 2], h[..., 2]
    d = alpha**2 / (np.pi * (cos_h**2 * (alpha**2 - 1) + 1) ** 2)

    def smith_lambda(c):
        return (np.sqrt(1 + alpha**2 * (1 - c**2) / c**2) - 1) / 2

    if masking == "height-correlated":
        g = 1 / (1 + smith_lambda(cos_i) + smith_lambda(cos_o))
    else:
        g = 1 / ((1 + smith_lambda(cos_i)) * (1 + smith_lambda(cos_o)))
    return d * g / (4 * cos_i * cos_o)


def glossy_plate_intensity(sun, obs, reflectance, roughness, masking="height-correlated"):
    """(m,) I/E of a 1 m^2 GGX plate facing +Z, averaged over the Sun's disk."""
    directions, weights = sun_disk(sun)
    f = ggx_brdf(directions, obs[:, None, :], roughness**2, masking)
    return PLATE_AREA_M2 * reflectance * (f * directions[..., 2]) @ weights * obs[:, 2]


def lambert_plate_intensity(sun, obs, albedo, normal=(0.0, 0.0, 1.0)):
    """(m,) I/E of a 1 m^2 Lambert plate in the XY plane shaded with `normal`: A rho cos i cos e / pi."""
    cos_i = np.clip(sun @ unit(normal), 0, None)
    return PLATE_AREA_M2 * albedo * cos_i * obs[:, 2] / np.pi


def convex_lambert_facet_sum(vertices, faces, albedo, sun, obs):
    """(m,) exact I/E of a convex Lambert polyhedron: sum of A rho <cos i>_disk cos e / pi over facets."""
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = np.linalg.norm(cross, axis=1) / 2
    normal = cross / (2 * area[:, None])
    directions, weights = sun_disk(sun)
    irradiance = np.einsum("tk,mqk->mtq", normal, directions).clip(0) @ weights  # (m, T)
    cos_e = (obs @ normal.T).clip(0)
    return (irradiance * cos_e) @ area * albedo / np.pi


def lambert_sphere_law(radius_m, albedo, phase_rad):
    """I/E of a Lambert sphere: (2/3) r^2 rho [sin a + (pi - a) cos a] / pi."""
    return 2 / 3 * radius_m**2 * albedo * (np.sin(phase_rad) + (np.pi - phase_rad) * np.cos(phase_rad)) / np.pi


def plate(material, **normals):
    return CyclesMesh.from_arrays(PLATE_VERTICES, PLATE_TRIANGLES, [material], **normals)


# Directions over the upper hemisphere, from near-normal to grazing (cos down to 0.2).
PLATE_SUN = unit([[0.3, 0.2, 1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.3, 0.6], [1.0, 0.0, 0.3], [0.2, 1.0, 0.3]])
PLATE_OBS = unit(
    [[-0.2, -0.1, 1.0], [0.05, 0.0, 1.0], [0.0, 1.0, 0.2], [-1.0, -0.2, 0.4], [-1.0, 0.0, 0.3], [0.2, -1.0, 0.25]]
)
PLATE_SETTINGS = CyclesSettings(samples=64, resolution=64, seed=3, noise_passes=2)


# ---------------------------------------------------------------------------------------------
# The API without Blender


def test_import_needs_no_bpy():
    code = "import sys; sys.modules['bpy'] = None; import raycast.cycles; print('ok')"
    run = subprocess.run([sys.executable, "-c", code], cwd=PROJECT_ROOT, capture_output=True, text=True)
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr


def test_render_without_bpy_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "bpy", None)
    mesh = plate({"blender_node": "Diffuse BSDF", "color": [0.5, 0.5, 0.5]})
    with pytest.raises(ModuleNotFoundError, match="install the 'cycles' extra"):
        render_cycles(mesh, PLATE_SUN[:1], PLATE_OBS[:1])


@pytest.mark.parametrize(
    "material, message",
    [
        ({"blender_node": "Emission", "color": [1, 1, 1]}, "blender_node='Emission'; use one of Diffuse BSDF"),
        ({"blender_node": "Glossy BSDF", "color": [0.5, 0.5, 0.5]}, "lacks 'roughness'"),
        ({"blender_node": "Diffuse BSDF", "color": [0.5, 0.5, 0.5], "metallic": 0.0}, "unknown field 'metallic'"),
        ({"blender_node": "Diffuse BSDF", "color": [0.5, 1.5, 0.5]}, "three linear RGB values in [0, 1]"),
        (
            {"blender_node": "Glossy BSDF", "color": [0.5] * 3, "roughness": 2},
            "roughness=2; give a number in [0.0, 1.0]",
        ),
        (
            {"blender_node": "Glossy BSDF", "color": [0.5] * 3, "roughness": 0.3, "distribution": "PHONG"},
            "distribution='PHONG'; use one of GGX",
        ),
        (
            {"blender_node": "Mix Shader", "fac": 0.5, "shaders": [{"blender_node": "Diffuse BSDF", "color": [1] * 3}]},
            "shaders=[{'blender_node': 'Diffuse BSDF', 'color': [1, 1, 1]}]; give a list of two node entries",
        ),
        (
            {
                "blender_node": "Mix Shader",
                "fac": 0.5,
                "shaders": [{"blender_node": "Diffuse BSDF", "color": [1] * 3}, {"blender_node": "Glossy BSDF"}],
            },
            "material 0.shaders[1] (Glossy BSDF) lacks 'color'",
        ),
        (
            {
                "blender_node": "Mix Shader",
                "fac": 1.5,
                "shaders": [{"blender_node": "Diffuse BSDF", "color": [1] * 3}] * 2,
            },
            "fac=1.5; give a number in [0.0, 1.0]",
        ),
    ],
)
def test_bad_materials_are_refused(material, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        plate(material)


def test_bad_geometry_is_refused():
    diffuse = {"blender_node": "Diffuse BSDF", "color": [0.5, 0.5, 0.5]}
    with pytest.raises(ValueError, match="refer to vertex 0..4 but there are 4 vertices"):
        CyclesMesh.from_arrays(PLATE_VERTICES, [[0, 1, 4]], [diffuse])
    with pytest.raises(ValueError, match="material_index holds 0..1 but there are 1 materials"):
        CyclesMesh.from_arrays(PLATE_VERTICES, PLATE_TRIANGLES, [diffuse], material_index=[0, 1])
    with pytest.raises(ValueError, match=r"vertex_normals has shape \(3, 3\); give a \(4, 3\) array"):
        CyclesMesh.from_arrays(PLATE_VERTICES, PLATE_TRIANGLES, [diffuse], vertex_normals=np.eye(3))
    mesh = plate(diffuse)
    with pytest.raises(ValueError, match=r"sun_body\[1\] has length 2; give unit vectors"):
        render_cycles(mesh, [[0, 0, 1], [0, 0, 2]], [[0, 0, 1], [0, 0, 1]])
    with pytest.raises(ValueError, match="sun_body has 2 frames but obs_body has 1"):
        render_cycles(mesh, [[0, 0, 1], [0, 0, 1]], [[0, 0, 1]])
    with pytest.raises(TypeError, match="give a CyclesMesh"):
        render_cycles({"vertices": PLATE_VERTICES}, [[0, 0, 1]], [[0, 0, 1]])


def test_bad_settings_are_refused():
    mesh = plate({"blender_node": "Diffuse BSDF", "color": [0.5, 0.5, 0.5]})
    with pytest.raises(ValueError, match="seeds=1; give an integer of at least 2"):
        measure_noise(mesh, PLATE_SUN[:1], PLATE_OBS[:1], seeds=1)
    with pytest.raises(ValueError, match=re.escape("samples=(16, 0); give a non-empty sequence of positive integers")):
        measure_noise(mesh, PLATE_SUN[:1], PLATE_OBS[:1], samples=(16, 0))
    with pytest.raises(ValueError, match="samples=60 is not a multiple of noise_passes=8"):
        CyclesSettings(samples=60, noise_passes=8)
    with pytest.raises(ValueError, match="process='gpu'; use one of subprocess, in_process"):
        CyclesSettings(process="gpu")
    with pytest.raises(ValueError, match="channel='v'; use 'green', 'red', 'blue' or 'mean'"):
        CyclesSettings(channel="v")


def test_obj_errors_name_file_and_line(tmp_path):
    materials = tmp_path / "m.json"
    materials.write_text(json.dumps({"materials": {"grey": {"blender_node": "Diffuse BSDF", "color": [0.5] * 3}}}))
    no_material = tmp_path / "a.obj"
    no_material.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match="material 'default' used in .*a.obj has no entry in"):
        CyclesMesh.from_obj(no_material, materials)
    bad_index = tmp_path / "b.obj"
    bad_index.write_text("v 0 0 0\nv 1 0 0\nusemtl grey\nf 1 2 3\n")
    with pytest.raises(ValueError, match=r"b\.obj:4: vertex index 3 is outside the 2 vertices defined so far"):
        CyclesMesh.from_obj(bad_index, materials)
    unknown = tmp_path / "c.obj"
    unknown.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl shiny\nf 1 2 3\n")
    with pytest.raises(ValueError, match="material 'shiny' used in .*c.obj has no entry in"):
        CyclesMesh.from_obj(unknown, materials)


def test_obj_reader_takes_the_files_normals_everywhere_and_splits_polygons_as_blender(tmp_path):
    # Two quads with tilted vn, the second after "s off", and a pentagon: with vn in the file,
    # Blender's importer ignores "s" (every face smooth with the file's normals, checked
    # against bpy), splits quads along 0-2 and ear-clips the pentagon as (4,0,1),(1,2,3),(1,3,4).
    obj = tmp_path / "q.obj"
    obj.write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\nv 0.5 1.5 1\nvn 0.6 0 0.8\n"
        "usemtl grey\ns 1\nf 1//1 2//1 3//1 4//1\ns off\nf 5//1 6//1 7//1 8//1\nf 5//1 6//1 7//1 9//1 8//1\n"
    )
    materials = tmp_path / "m.json"
    materials.write_text(json.dumps({"materials": {"grey": {"blender_node": "Diffuse BSDF", "color": [0.5] * 3}}}))
    mesh = CyclesMesh.from_obj(obj, materials)
    np.testing.assert_array_equal(
        mesh.triangles, [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [7, 4, 5], [5, 6, 8], [5, 8, 7]]
    )
    # vn is given to 1 decimal and unit already.
    np.testing.assert_allclose(mesh.corner_normals, np.broadcast_to([0.6, 0, 0.8], (7, 3, 3)), atol=1e-12)


# ---------------------------------------------------------------------------------------------
# The same triangles and normals as Blender's own OBJ importer


@pytest.mark.cycles
@pytest.mark.parametrize("model", ["cosmos2502_lotos", "plate_1m"])
def test_obj_reader_matches_blenders_importer(model, tmp_path):
    bpy = pytest.importorskip("bpy")
    materials = COSMOS_MATERIALS
    if model == "plate_1m":
        materials = tmp_path / "plate.json"
        materials.write_text(
            json.dumps({"materials": {"Material": {"blender_node": "Diffuse BSDF", "color": [0.8] * 3}}})
        )
    ours = CyclesMesh.from_obj(MODELS / f"{model}.obj", materials)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    # The files are in Blender's own axes (Z up): import without the Y-up conversion.
    bpy.ops.wm.obj_import(filepath=str(MODELS / f"{model}.obj"), forward_axis="Y", up_axis="Z")
    rows = []
    for obj in bpy.context.scene.objects:
        mesh = obj.data
        mesh.calc_loop_triangles()
        positions = np.array([vertex.co for vertex in mesh.vertices])
        normals = np.array([corner.vector for corner in mesh.corner_normals])
        for tri in mesh.loop_triangles:
            rows.append(np.hstack([positions[list(tri.vertices)], normals[list(tri.loops)]]))
    theirs = np.array(rows)

    def canonical(corners):  # (T, 3, 6) -> rows sorted so both orders of triangles and corners agree
        corners = np.array([tri[np.lexsort(np.round(tri, 3).T[::-1])] for tri in corners]).reshape(len(corners), -1)
        return corners[np.lexsort(np.round(corners, 3).T[::-1])]

    mine = canonical(np.concatenate([ours.vertices_m[ours.triangles], ours.corner_normals], axis=2))
    blender = canonical(theirs)
    assert mine.shape == blender.shape
    # positions are the same floats; vn are written with 4 decimals, so normals agree to ~1e-4
    np.testing.assert_allclose(
        mine[:, [0, 1, 2, 6, 7, 8, 12, 13, 14]], blender[:, [0, 1, 2, 6, 7, 8, 12, 13, 14]], atol=1e-6
    )
    np.testing.assert_allclose(mine, blender, atol=5e-4)


# ---------------------------------------------------------------------------------------------
# Calibration against closed forms


@pytest.mark.cycles
def test_lambert_plate_matches_closed_form_per_channel():
    albedo = np.array([0.2, 0.5, 0.8])
    result = render_cycles(
        plate({"blender_node": "Diffuse BSDF", "color": albedo.tolist()}),
        PLATE_SUN,
        PLATE_OBS,
        PLATE_SETTINGS,
        progress=False,
    )
    expected = lambert_plate_intensity(PLATE_SUN, PLATE_OBS, 1.0)[:, None] * albedo
    # 1e-3: the project's plate criterion; the measured noise here is ~1e-5 .. 1e-4 (docs/cycles.md)
    np.testing.assert_allclose(result.intensity_rgb_m2_sr, expected, rtol=1e-3)
    np.testing.assert_allclose(result.intensity_m2_sr, expected[:, 1], rtol=1e-3)  # green by default
    assert result.noise_rel.max() < 1e-3
    assert result.intensity_m2_sr.shape == (6,) and result.frame_seconds.shape == (6,)
    assert 0 < result.seconds_per_frame and 0 < result.seconds_setup < result.seconds_total
    # square pixels covering the 1 m plate seen face-on, with a margin of one pixel per side
    np.testing.assert_array_equal(result.resolution_px[1], [66, 66])
    np.testing.assert_allclose(result.pixel_size_m[1], 1.0 / 64, rtol=1e-3)


@pytest.mark.cycles
@pytest.mark.parametrize("roughness", [0.3, 0.6])
def test_glossy_plate_matches_ggx_with_height_correlated_masking(roughness):
    reflectance = 0.8
    material = {"blender_node": "Glossy BSDF", "color": [reflectance] * 3, "roughness": roughness}
    result = render_cycles(plate(material), PLATE_SUN, PLATE_OBS, PLATE_SETTINGS, progress=False)
    expected = glossy_plate_intensity(PLATE_SUN, PLATE_OBS, reflectance, roughness)
    # 1e-3: the project's plate criterion; Cycles' scatter here is <= 1e-4 (docs/cycles.md)
    np.testing.assert_allclose(result.intensity_m2_sr, expected, rtol=1e-3)
    if roughness == 0.6:
        # Cycles does not use the separable G1(i) G1(o): at the two grazing frames that form is
        # 5-7% low, fifty times the tolerance above.
        separable = glossy_plate_intensity(PLATE_SUN, PLATE_OBS, reflectance, roughness, masking="separable")
        assert (result.intensity_m2_sr[4:] / separable[4:] - 1).min() > 0.03


@pytest.mark.cycles
def test_principled_limits_reduce_to_lambert_and_ggx():
    # metallic 1 with white base colour: Fresnel is 1, leaving the Glossy GGX form;
    # dielectric with specular IOR level 0: no specular lobe, leaving Lambert.
    metal = {
        "blender_node": "Principled BSDF",
        "base_color": [1, 1, 1],
        "metallic": 1.0,
        "roughness": 0.4,
        "specular_ior_level": 0.5,
    }
    matte = {
        "blender_node": "Principled BSDF",
        "base_color": [0.5] * 3,
        "metallic": 0.0,
        "roughness": 0.5,
        "specular_ior_level": 0.0,
    }
    mesh = CyclesMesh.from_arrays(
        PLATE_VERTICES + [[x + 3, y, z] for x, y, z in PLATE_VERTICES],
        PLATE_TRIANGLES + [[a + 4, b + 4, c + 4] for a, b, c in PLATE_TRIANGLES],
        [metal, matte],
        material_index=[0, 0, 1, 1],
    )
    metal_only = render_cycles(mesh.with_material(metal), PLATE_SUN[:3], PLATE_OBS[:3], PLATE_SETTINGS, progress=False)
    both = render_cycles(mesh, PLATE_SUN[:3], PLATE_OBS[:3], PLATE_SETTINGS, progress=False)
    metal_expected = 2 * glossy_plate_intensity(PLATE_SUN[:3], PLATE_OBS[:3], 1.0, 0.4)
    np.testing.assert_allclose(metal_only.intensity_m2_sr, metal_expected, rtol=1e-3)  # plate criterion
    both_expected = metal_expected / 2 + lambert_plate_intensity(PLATE_SUN[:3], PLATE_OBS[:3], 0.5)
    np.testing.assert_allclose(both.intensity_m2_sr, both_expected, rtol=1e-3)


@pytest.mark.cycles
def test_mix_shader_is_the_weighted_sum_of_its_inputs():
    """Blender's Mix Shader as the project's Mix reads it: (1 - fac) first + fac second."""
    fac = 0.3
    material = {
        "blender_node": "Mix Shader",
        "fac": fac,
        "shaders": [
            {"blender_node": "Diffuse BSDF", "color": [0.5] * 3},
            {"blender_node": "Glossy BSDF", "color": [0.8] * 3, "roughness": 0.3},
        ],
    }
    result = render_cycles(plate(material), PLATE_SUN, PLATE_OBS, PLATE_SETTINGS, progress=False)
    expected = (1 - fac) * lambert_plate_intensity(PLATE_SUN, PLATE_OBS, 0.5) + fac * glossy_plate_intensity(
        PLATE_SUN, PLATE_OBS, 0.8, 0.3
    )
    np.testing.assert_allclose(result.intensity_m2_sr, expected, rtol=1e-3)  # plate criterion
    # The fac really took effect: the glossy share alone moves these frames by far more.
    swapped = fac * lambert_plate_intensity(PLATE_SUN, PLATE_OBS, 0.5) + (1 - fac) * glossy_plate_intensity(
        PLATE_SUN, PLATE_OBS, 0.8, 0.3
    )
    assert np.abs(swapped / expected - 1).max() > 0.1


@pytest.mark.cycles
def test_corner_normals_shade_as_given():
    # A flat plate whose shading normals all lean 16.7 deg toward +X: Cycles lights it by the
    # tilted normal while its projected area stays that of the flat plate. In the last two frames
    # the observer is below the tilted normal's horizon but above the plate: Cycles' Diffuse BSDF
    # still reflects (only the geometric side is checked), and its Glossy BSDF bends the normal
    # until the view's mirror direction clears the surface instead of returning nothing.
    tilted = unit([0.3, 0.0, 1.0])
    sun = unit([[0.3, 0.2, 1.0], [0.5, 0.0, 1.0], [-0.2, 0.0, 1.0], [0.3, 0.2, 1.0], [0.5, 0.0, 1.0]])
    obs = unit([[-0.2, -0.1, 1.0], [0.0, 1.0, 0.2], [0.2, 0.3, 1.0], [-1.0, 0.0, 0.2], [-1.0, 0.1, 0.25]])
    assert (obs[3:] @ tilted < 0).all() and (obs[:3] @ tilted > 0).all()
    normals = {"vertex_normals": np.tile(tilted, (4, 1))}
    diffuse = render_cycles(
        plate({"blender_node": "Diffuse BSDF", "color": [0.5] * 3}, **normals), sun, obs, PLATE_SETTINGS, progress=False
    )
    expected = lambert_plate_intensity(sun, obs, 0.5, normal=tilted)
    np.testing.assert_allclose(diffuse.intensity_m2_sr, expected, rtol=1e-3)  # plate criterion
    flat = lambert_plate_intensity(sun, obs, 0.5)
    assert np.abs(expected / flat - 1).min() > 0.02  # the test can tell the two apart

    glossy = render_cycles(
        plate({"blender_node": "Glossy BSDF", "color": [0.5] * 3, "roughness": 0.6}, **normals),
        sun[3:],
        obs[3:],
        PLATE_SETTINGS,
        progress=False,
    )
    # a BRDF evaluated with the tilted normal is 0 here; Cycles returns about half the Lambert value
    assert (glossy.intensity_m2_sr > 0.3 * expected[3:]).all()
    # ... which is the GGX lobe about Cycles' valid-reflection normal (the tilted normal turned
    # toward the face until the view's mirror image is 0.01 above it), as the project's BRDFs
    # shade it: A f cos(i) cos(e) with the cosines to that normal (1%: Cycles' noise at these
    # settings is ~1e-3, the solar disk changes a roughness-0.6 lobe by ~1e-5).
    from raycast.renderer.brdf import GGX, valid_reflection_normal

    s, o = sun[3:], obs[3:]
    z = np.tile([0.0, 0.0, 1.0], (2, 1))
    bent = valid_reflection_normal(z, o, np.tile(tilted, (2, 1)))
    shade = GGX(0.5, 0.6).shade(s @ tilted, o @ tilted, np.sum(s * o, axis=1), np.sum(bent * s, 1), np.sum(bent * o, 1))
    np.testing.assert_allclose(glossy.intensity_m2_sr, PLATE_AREA_M2 * shade * o[:, 2], rtol=0.01)


@pytest.mark.cycles
@pytest.mark.slow
def test_lambert_sphere_matches_facet_sum_and_phase_law():
    vertices, faces = icosphere(5)  # 20480 facets; faceting lowers I/E by 0.03% .. 0.13%
    albedo = 0.5
    phase_rad = np.radians([0.0, 30.0, 60.0, 90.0, 120.0, 150.0])
    sun = np.stack([np.sin(phase_rad), np.zeros_like(phase_rad), np.cos(phase_rad)], axis=1)
    obs = np.tile([0.0, 0.0, 1.0], (len(phase_rad), 1))
    mesh = CyclesMesh.from_arrays(vertices, faces, [{"blender_node": "Diffuse BSDF", "color": [albedo] * 3}])
    result = render_cycles(mesh, sun, obs, CyclesSettings(samples=64, resolution=128, noise_passes=2), progress=False)
    facets = convex_lambert_facet_sum(vertices, faces, albedo, sun, obs)
    # 1e-3 up to 120 deg; 3e-3 at 150 deg where only a thin crescent is lit and Cycles' relative
    # scatter at 64 samples/px, 128 px reaches ~1e-3 (docs/cycles.md)
    np.testing.assert_allclose(result.intensity_m2_sr[:5], facets[:5], rtol=1e-3)
    np.testing.assert_allclose(result.intensity_m2_sr[5], facets[5], rtol=3e-3)
    # the project's sphere criterion: 0.3% from the analytic law over 0-150 deg
    np.testing.assert_allclose(result.intensity_m2_sr, lambert_sphere_law(1.0, albedo, phase_rad), rtol=3e-3)


@pytest.mark.cycles
def test_both_runners_give_the_same_floats():
    mesh = plate({"blender_node": "Glossy BSDF", "color": [0.8] * 3, "roughness": 0.3})
    results = [
        render_cycles(
            mesh,
            PLATE_SUN[:2],
            PLATE_OBS[:2],
            CyclesSettings(samples=8, resolution=32, process=process),
            progress=False,
        )
        for process in ("subprocess", "in_process")
    ]
    np.testing.assert_array_equal(results[0].intensity_rgb_m2_sr, results[1].intensity_rgb_m2_sr)
    assert results[0].noise_rel is None and results[0].noise_rel_rms is None
    # a different seed is an independent render: same value within noise, not the same floats
    other = render_cycles(
        mesh, PLATE_SUN[:2], PLATE_OBS[:2], CyclesSettings(samples=8, resolution=32, seed=1), progress=False
    )
    assert not np.array_equal(other.intensity_m2_sr, results[0].intensity_m2_sr)
    np.testing.assert_allclose(
        other.intensity_m2_sr, results[0].intensity_m2_sr, rtol=1e-2
    )  # ~1e-3 noise at 8 spp, 32 px


# ---------------------------------------------------------------------------------------------
# Sampling noise


@pytest.mark.cycles
def test_noise_falls_with_samples_and_seeds_average_to_the_closed_form():
    material = {"blender_node": "Glossy BSDF", "color": [0.8] * 3, "roughness": 0.3}
    study = measure_noise(
        plate(material),
        PLATE_SUN[:3],
        PLATE_OBS[:3],
        samples=(4, 32),
        seeds=4,
        settings=CyclesSettings(resolution=64),
        progress=False,
    )
    assert study.intensity_m2_sr.shape == (2, 4, 3)
    # stratified sampling: 8x the samples cuts the scatter by at least sqrt(8) ~ 2.8; ask for 2
    assert study.rel_std_rms[1] < study.rel_std_rms[0] / 2
    expected = glossy_plate_intensity(PLATE_SUN[:3], PLATE_OBS[:3], 0.8, 0.3)
    mean = study.intensity_m2_sr[0].mean(axis=0)
    standard_error = study.intensity_m2_sr[0].std(axis=0, ddof=1) / 2
    # unbiased even at 4 samples/px (sample 0, always at the pixel centre, is skipped): the seed
    # mean is within 5 standard errors plus the quadrature's 1e-6 of the closed form
    assert (np.abs(mean - expected) < 5 * standard_error + 1e-6 * expected).all()
    assert "| 32 |" in study.to_markdown()


# ---------------------------------------------------------------------------------------------
# The paper's model and the degenerate plate


@pytest.fixture(scope="module")
def cosmos():
    return CyclesMesh.from_obj(COSMOS_OBJ, COSMOS_MATERIALS)


def cosmos_directions():
    """Four frames with the bisector normal to the tube axis (body Z) and four random ones."""
    azimuth = np.radians([17.0, 40.0, 63.0, 100.0])
    bisector = np.stack([np.cos(azimuth), np.sin(azimuth), np.zeros_like(azimuth)], axis=1)
    half_phase = np.radians(20.0)
    sun = unit(np.cos(half_phase) * bisector + np.sin(half_phase) * np.array([0.0, 0.0, 1.0]))
    obs = unit(np.cos(half_phase) * bisector - np.sin(half_phase) * np.array([0.0, 0.0, 1.0]))
    rng = np.random.default_rng(1)
    sun_random = unit(rng.normal(size=(4, 3)))
    obs_random = unit(sun_random + 0.7 * rng.normal(size=(4, 3)))
    return np.vstack([sun, sun_random]), np.vstack([obs, obs_random])


@pytest.mark.cycles
def test_cosmos_model_reads_with_its_smooth_normals(cosmos):
    assert cosmos.n_triangles == 2184
    assert set(cosmos.material_names) == {"b_cross", "spb_2", "body_2", "spb_2.001", "body_2.001", "body_1"}
    # the Principled surfaces take the IOR the .mtl records (Ni 1.45), as raycast.renderer.materials does
    body = cosmos.materials[cosmos.material_names.index("body_1")]
    assert body["blender_node"] == "Principled BSDF" and body["ior"] == 1.45
    # the tube ("s 1") carries vn that differ from its facets; the flat ("s 0") panels and
    # crosses carry their facet normals as vn (Blender's importer takes vn wherever the file has
    # them), printed to 4 decimals: 1e-4 per component turns them by < 1.7e-4 rad, 1 - cos < 1.5e-8
    corners = cosmos.vertices_m[cosmos.triangles]
    facet = unit(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
    deviation = 1 - np.einsum("tk,tck->tc", facet, cosmos.corner_normals).min(axis=1)
    tube = cosmos.material_index == cosmos.material_names.index("body_1")
    assert (deviation[tube] > 0.01).sum() > 1000
    flat_parts = np.isin(
        cosmos.material_index, [cosmos.material_names.index(name) for name in ("b_cross", "spb_2", "spb_2.001")]
    )
    assert deviation[flat_parts].max() < 1.5e-8


@pytest.mark.cycles
@pytest.mark.slow
def test_cosmos_renders_are_reciprocal_and_use_smooth_normals(cosmos):
    """Helmholtz reciprocity: with a reciprocal BRDF and flat shading, swapping Sun and observer
    leaves I/E unchanged, shadows and occlusion included. It holds for the concave paper model only
    if Cycles' visibility and framing are right in both directions. (Shading normals that differ
    from the facets break it: the light comes in by the shading normal, the projected area goes
    out by the facet normal.)"""
    sun, obs = cosmos_directions()
    settings = CyclesSettings(samples=32, resolution=128, noise_passes=2)
    diffuse = cosmos.with_flat_shading().with_material({"blender_node": "Diffuse BSDF", "color": [0.5] * 3})
    forward = render_cycles(diffuse, sun, obs, settings, progress=False)
    backward = render_cycles(diffuse, obs, sun, settings, progress=False)
    # 2e-3: a few times the measured scatter (<= 8e-4 per frame at these settings) plus the Sun
    # disk, which blurs the lit side but not the viewed side (~1e-4)
    np.testing.assert_allclose(forward.intensity_m2_sr, backward.intensity_m2_sr, rtol=2e-3)

    glossy = cosmos.with_material({"blender_node": "Glossy BSDF", "color": [0.5] * 3, "roughness": 0.3})
    smooth = render_cycles(glossy, sun, obs, settings, progress=False)
    flat = render_cycles(glossy.with_flat_shading(), sun, obs, settings, progress=False)
    # flat facets move the tube's glint: the all-glossy model changes by magnitudes, not noise
    delta_mag = 2.5 * np.log10(smooth.intensity_m2_sr / flat.intensity_m2_sr)
    assert np.abs(delta_mag).max() > 1.0

    paper = render_cycles(cosmos, sun, obs, settings, progress=False)
    assert np.isfinite(paper.intensity_m2_sr).all() and (paper.intensity_m2_sr > 0).all()
    # rendered in-process, the same seed gives the same floats
    same = render_cycles(
        cosmos,
        sun[:2],
        obs[:2],
        CyclesSettings(samples=32, resolution=128, noise_passes=2, process="in_process"),
        progress=False,
    )
    np.testing.assert_array_equal(same.intensity_rgb_m2_sr, paper.intensity_rgb_m2_sr[:2])


@pytest.mark.cycles
def test_degenerate_plate_obj_renders_black(tmp_path):
    """plate_1m.obj: two coincident faces with opposite normals plus four zero-area sides.
    Whichever face a camera ray hits, the shadow ray toward the Sun starts on its twin and is
    blocked, so Cycles returns (almost) nothing; a clean two-triangle plate is fully lit."""
    materials = tmp_path / "plate.json"
    materials.write_text(json.dumps({"materials": {"Material": {"blender_node": "Diffuse BSDF", "color": [0.8] * 3}}}))
    degenerate = CyclesMesh.from_obj(PLATE_OBJ, materials)
    sun, obs = PLATE_SUN[:3], PLATE_OBS[:3]
    sun_below = sun * [1, 1, -1]
    obs_below = obs * [1, 1, -1]
    result = render_cycles(
        degenerate,
        np.vstack([sun, sun_below]),
        np.vstack([obs, obs_below]),
        CyclesSettings(samples=16, resolution=64),
        progress=False,
    )
    lit = np.concatenate([lambert_plate_intensity(sun, obs, 0.8)] * 2)
    # "black": below 1% of what the same plate without the twin face reflects
    assert (result.intensity_m2_sr < 0.01 * lit).all()


# ---------------------------------------------------------------------------------------------
# The project's direct renderer against Cycles


def _bus_panel_tank():
    """A 1 x 1 x 2 m box, a 2 x 1 m plate beside it and a smooth 0.8 m x 1.5 m cylinder:
    flat and smooth shading, and shadows of the parts on each other at some of the directions."""
    from raycast.renderer.scene import Part

    to_xz = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    return [
        Part.box("bus", (1.0, 1.0, 2.0), "skin"),
        Part.plate("panel", 2.0, 1.0, "skin").transformed(to_xz, (1.8, 0.0, 0.3)),
        Part.cylinder("tank", 0.4, 1.5, "skin", segments=48).transformed(np.eye(3), (-1.2, 0.0, 0.0)),
    ]


@pytest.mark.cycles
@pytest.mark.slow
@pytest.mark.parametrize("label", ["diffuse", "glossy"])
def test_direct_renderer_agrees_with_cycles(label):
    from raycast.geometry.pass_geometry import BodyGeometry
    from raycast.renderer.brdf import GGX, Lambertian
    from raycast.renderer.methods import render
    from raycast.renderer.scene import Scene

    entry, brdf = {
        "diffuse": ({"blender_node": "Diffuse BSDF", "color": [0.5] * 3}, Lambertian(0.5)),
        "glossy": ({"blender_node": "Glossy BSDF", "color": [0.5] * 3, "roughness": 0.3}, GGX(0.5, 0.3)),
    }[label]
    scene = Scene.from_parts(_bus_panel_tank(), {"skin": brdf})
    posed = scene.posed()
    n_triangles = len(posed.corners_m)
    mesh = CyclesMesh.from_arrays(
        posed.vertices_m, np.arange(3 * n_triangles).reshape(-1, 3), [entry], corner_normals=posed.corner_normals
    )
    sun = unit([[1.0, 0.4, 0.3], [0.2, 1.0, 0.3], [0.9, -0.3, -0.2], [0.1, -1.0, 0.6]])
    obs = unit([[0.7, 1.0, 0.1], [1.0, 0.5, 0.6], [0.6, 0.5, 0.3], [-0.3, -1.0, 0.2]])
    n = len(sun)
    geometry = BodyGeometry(
        sun_body=sun[:, None, :],
        obs_body=obs[:, None, :],
        weights=np.ones(1),
        sunlit=np.ones((n, 1)),
        range_km=np.full(n, 1000.0),
        phase_angle_deg=np.zeros(n),
    )
    direct = render(scene, geometry, method="direct", pixel_size_m=0.005)
    cycles = render_cycles(mesh, sun, obs, CyclesSettings(samples=64, resolution=128, noise_passes=2), progress=False)
    # 0.005 mag: the project's accuracy target for the direct renderer, whose edge error at
    # 0.005 m pixels on this 4 m scene is ~0.1-0.3% (halving the pixel moves it by that much);
    # plus 3 sigma of Cycles' noise (the two-pass estimate, floored at the 1e-4 measured for such
    # scenes at these settings, docs/cycles.md; 1.0857 converts relative error to magnitudes).
    sigma_mag = 1.0857 * np.maximum(cycles.noise_rel, 1e-4)
    delta_mag = 2.5 * np.log10(direct.intensity_m2_sr / cycles.intensity_m2_sr)
    assert (np.abs(delta_mag) <= 0.005 + 3 * sigma_mag).all(), delta_mag
