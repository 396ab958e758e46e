"""Renderers against exact answers: the Lambertian sphere, Lambert and GGX plates, convex facet sums.

Each test runs over both implementations of `raycast.renderer.render` (direct ray casting and
the cached fast path).
"""

from collections import Counter
import math

import numpy as np
import pytest

from raycast.models import topex
from raycast.renderer.brdf import GGX, Lambertian, Principled
from raycast.renderer.direct import DirectRenderer
from raycast.renderer.methods import render
from raycast.renderer.scene import Part, Scene
from tests.conftest import MODELS
from tests.render_support import METHODS, geometry, in_plane, unit

# Pixel sizes for the direct renderer in these tests, chosen so its edge error is well below the
# tolerance: the plate's edge error is ~ (pixel / size)^2 with the R2-shifted grid.
PLATE_PIXEL_M = 0.002


@pytest.fixture(scope="module")
def sphere():
    # Icosphere of 81920 faces: its projected area is 3e-5 below the circle's.
    return Scene.from_parts([Part.sphere("ball", 1.0, "white", subdivisions=6)], {"white": Lambertian(0.5)})


@pytest.mark.parametrize("method", METHODS)
def test_lambertian_sphere_phase_law(sphere, method):
    phase = np.array([0.0, 30.0, 60.0, 90.0, 120.0, 150.0])
    sun, obs = in_plane(np.zeros_like(phase), phase, azimuth_deg=0.0)
    # 2.5 mm rays: the thin crescent at 150 deg then scatters by ~0.1% with the sub-pixel offset
    # (5 mm: up to 0.36%, for the adaptive and the regular grid alike).
    model = render(sphere, geometry(sun, obs), method=method, pixel_size_m=0.0025)
    a = np.radians(phase)
    exact = (2.0 / 3.0) * 1.0**2 * 0.5 * (np.sin(a) + (np.pi - a) * np.cos(a)) / np.pi
    # The tolerance: 0.3% for phase angles 0-150 deg.
    np.testing.assert_allclose(model.intensity_m2_sr, exact, rtol=3e-3)


def plate_scene(brdf):
    return Scene.from_parts([Part.plate("plate", 1.0, 1.0, "m")], {"m": brdf})


@pytest.mark.parametrize("method", METHODS)
def test_lambert_plate_closed_form(method):
    incidence = np.array([0.0, 20.0, 45.0, 70.0, 30.0])
    emergence = np.array([0.0, 35.0, 10.0, 60.0, 50.0])
    sun, obs = in_plane(incidence, emergence, azimuth_deg=123.0)
    model = render(plate_scene(Lambertian(0.6)), geometry(sun, obs), method=method, pixel_size_m=PLATE_PIXEL_M)
    exact = 1.0 * 0.6 * np.cos(np.radians(incidence)) * np.cos(np.radians(emergence)) / np.pi
    # The tolerance for plates: 0.1%.
    np.testing.assert_allclose(model.intensity_m2_sr, exact, rtol=1e-3)


def ggx_closed_form(color, roughness, incidence_deg, emergence_deg, azimuth_deg):
    """Blender's Glossy BSDF times cos(i) cos(e) A for a 1 m^2 plate, written out independently."""
    alpha = roughness**2
    sun, obs = in_plane(incidence_deg, emergence_deg, azimuth_deg)
    h = unit(sun + obs)
    cos_i, cos_o, cos_h = sun[:, 2], obs[:, 2], h[:, 2]
    d = alpha**2 / (np.pi * ((alpha**2 - 1.0) * cos_h**2 + 1.0) ** 2)

    def lam(c):
        return 0.5 * (np.sqrt(1.0 + alpha**2 * (1.0 / c**2 - 1.0)) - 1.0)

    f = color * d / (1.0 + lam(cos_i) + lam(cos_o)) / (4.0 * cos_i * cos_o)
    return f * cos_i * cos_o


@pytest.mark.parametrize("method", METHODS)
def test_ggx_plate_closed_form(method):
    incidence = np.array([30.0, 45.0, 10.0, 60.0])
    emergence = np.array([30.0, 40.0, 15.0, 55.0])
    azimuth = np.array([180.0, 170.0, 180.0, 150.0])
    sun, obs = in_plane(incidence, emergence, azimuth)
    # Roughness 0.3 (the paper's panels): alpha 0.09 is wide enough for one Sun sample.
    model = render(plate_scene(GGX(0.5, 0.3)), geometry(sun, obs), method=method, pixel_size_m=PLATE_PIXEL_M)
    np.testing.assert_allclose(
        model.intensity_m2_sr, ggx_closed_form(0.5, 0.3, incidence, emergence, azimuth), rtol=1e-3
    )


@pytest.mark.parametrize("method", METHODS)
def test_convex_mesh_ray_cast_sum_equals_facet_sum(method):
    rotation = np.linalg.qr(np.random.default_rng(7).normal(size=(3, 3)))[0]
    box = Part.box("box", (1.0, 2.0, 3.0), "white", face_materials={"+x": "foil", "-z": "foil"})
    scene = Scene.from_parts([box.transformed(rotation)], {"white": Lambertian(0.7), "foil": GGX(0.6, 0.4)})
    rng = np.random.default_rng(11)
    sun, obs = unit(rng.normal(size=(8, 3))), unit(rng.normal(size=(8, 3)))
    mesh = scene.posed()
    facet = np.zeros(len(sun))
    for tri in range(len(mesh.areas_m2)):
        n = np.repeat(mesh.face_normals[tri][None], len(sun), axis=0)
        f = mesh.brdfs[mesh.material_index[tri]](sun, obs, n)
        facet += mesh.areas_m2[tri] * f * np.maximum(sun @ n[0], 0.0) * np.maximum(obs @ n[0], 0.0)
    model = render(scene, geometry(sun, obs), method=method, pixel_size_m=0.004)
    # Facets of a convex body neither shadow nor hide each other: the sums agree to the pixel
    # edge error of the direct renderer (< 0.1% at 4 mm on a 1 m x 2 m x 3 m box).
    np.testing.assert_allclose(model.intensity_m2_sr, facet, rtol=1e-3)


@pytest.mark.parametrize("method", METHODS)
def test_repaired_paper_plate_is_a_two_sided_plate(method):
    plate = Scene.from_file(MODELS / "plate_1m.obj", repair=True, default_material=Lambertian(0.8))
    sun, obs = in_plane([25.0, 25.0], [40.0, 40.0], azimuth_deg=90.0)
    sun[1, 2] *= -1.0  # the second frame is seen and lit from below
    obs[1, 2] *= -1.0
    model = render(plate, geometry(sun, obs), method=method, pixel_size_m=PLATE_PIXEL_M)
    exact = 0.8 * math.cos(math.radians(25.0)) * math.cos(math.radians(40.0)) / math.pi
    np.testing.assert_allclose(model.intensity_m2_sr, exact, rtol=1e-3)


def test_pixel_size_from_accuracy_meets_it():
    panel = Part.box("panel", (3.0, 2.0, 0.05), "cells").transformed(offset_m=(0.0, 0.0, 1.8))
    scene = Scene.from_parts(
        [Part.box("bus", (1.5, 1.5, 3.0), "paint"), panel],
        {"paint": Lambertian(0.6), "cells": Principled(0.1, roughness=0.4)},
    )
    rng = np.random.default_rng(3)
    sun = unit(rng.normal(size=(6, 3)) + [0, 0, 1.5])
    obs = unit(rng.normal(size=(6, 3)) + [0, 0, 1.5])
    chosen = DirectRenderer.from_accuracy(scene, sun, obs, accuracy_mag=0.01)
    reference = DirectRenderer(scene, chosen.pixel_size_m / 4.0).intensity(sun, obs)
    error = np.abs(2.5 * np.log10(chosen.intensity(sun, obs) / reference))
    # The requested accuracy, against a grid four times finer.
    assert error.max() < 0.01
    assert chosen.pixel_size_m < 0.2


def test_articulation_parameters_are_applied():
    from raycast.models import topex

    scene = topex.build()
    rng = np.random.default_rng(5)
    sun, obs = unit(rng.normal(size=(3, 3))), unit(rng.normal(size=(3, 3)))
    renderer = DirectRenderer(scene, 0.1)
    moved = renderer.intensity(sun, obs, panel_pitch_deg=40.0)
    np.testing.assert_array_equal(moved, DirectRenderer(topex.build(panel_pitch_deg=40.0), 0.1).intensity(sun, obs))
    assert np.any(np.abs(moved / renderer.intensity(sun, obs) - 1.0) > 0.01)


@pytest.mark.parametrize("method", METHODS)
def test_tilted_shading_normal_keeps_diffuse_light_below_its_horizon(method):
    # A 1 m^2 Lambert plate (face +z) shaded by a uniform normal tilted 40 deg toward +x, observer
    # 60 deg from the face on the -x side: 100 deg from the shading normal, below its horizon.
    # The plate is seen, so I/E = A rho (n_s.s) (n_g.o) / pi, the closed form Blender Cycles
    # returns too (docs/cycles.md, calibration); the old renderer gave 0.
    tilt = math.radians(40.0)
    n_s = np.array([math.sin(tilt), 0.0, math.cos(tilt)])
    corners = Part.plate("plate", 1.0, 1.0, "m").corners_m
    scene = Scene.from_arrays(
        corners, np.broadcast_to(n_s, corners.shape).copy(), np.zeros(2, int), {"m": Lambertian(0.5)}, ["m"]
    )
    sun = unit(np.array([[0.3, 0.1, 1.0]]))
    obs = unit(np.array([[-math.sin(math.radians(60.0)), 0.0, math.cos(math.radians(60.0))]]))
    assert obs[0] @ n_s < 0.0 < obs[0, 2]
    expected = 0.5 * (sun[0] @ n_s) * obs[0, 2] / math.pi
    model = render(scene, geometry(sun, obs), method=method, pixel_size_m=PLATE_PIXEL_M)
    # Direct: edge error of a 2 mm grid on a 1 m plate, < 1e-4 relative; cached: exact sum.
    assert model.intensity_m2_sr[0] == pytest.approx(expected, rel=2e-4)


def test_grid_skips_only_tiles_whose_hits_face_away_from_the_sun(monkeypatch):
    # A bus and a panel lit from behind the observer's side: many tiles hold only faces turned
    # away from the Sun. Skipping them must leave the sum exactly as the full grid's.
    from raycast.renderer import direct

    panel = Part.box("panel", (3.0, 2.0, 0.05), "cells").transformed(offset_m=(0.0, 0.0, 1.8))
    scene = Scene.from_parts(
        [Part.box("bus", (1.5, 1.5, 3.0), "paint"), panel], {"paint": Lambertian(0.6), "cells": GGX(0.5, 0.3)}
    )
    rng = np.random.default_rng(8)
    sun, obs = unit(rng.normal(size=(6, 3))), unit(rng.normal(size=(6, 3)))
    counted = {}
    covered_tiles = direct._covered_tiles

    def recording(*args, every=False):
        args = list(args)
        if every:
            args[-1] = np.ones_like(args[-1])
        tiles = covered_tiles(*args)
        counted["every" if every else "sunward"] = len(tiles[0])
        return tiles

    monkeypatch.setattr(direct, "_covered_tiles", recording)
    skipping = DirectRenderer(scene, 0.02, sampling="grid").intensity(sun, obs)
    monkeypatch.setattr(direct, "_covered_tiles", lambda *args: recording(*args, every=True))
    full = DirectRenderer(scene, 0.02, sampling="grid").intensity(sun, obs)
    np.testing.assert_allclose(skipping, full, rtol=1e-12)
    assert skipping.max() > 0.0
    assert counted["sunward"] < 0.9 * counted["every"]


def _hit_table(renderer, sun, obs, monkeypatch):
    """The light curve, and a Counter of (frame, triangle) over the sunward first hits of the
    regular grid, found by rays (``sampling="grid"``) or by scan conversion (``"raster"``)."""
    from raycast.renderer import _direct_kernels

    recorded = Counter()
    name = "ray_hits" if renderer.sampling == "grid" else "raster_hits"
    finder = getattr(_direct_kernels, name)

    def recording(*args):
        found = finder(*args)
        recorded.update(zip(found[0].tolist(), found[1].tolist()))
        return found

    monkeypatch.setattr(_direct_kernels, name, recording)
    total = renderer.intensity(sun, obs)
    monkeypatch.setattr(_direct_kernels, name, finder)
    sunward = Counter()
    mesh = renderer.scene.posed()
    for (frame, triangle), count in recorded.items():
        normal = mesh.face_normals[triangle] * np.sign(mesh.face_normals[triangle] @ obs[frame])
        if normal @ sun[frame] > 0.0:
            sunward[frame, triangle] += count
    return total, sunward


@pytest.mark.parametrize("model", ["topex", "cosmos2502"])
def test_scan_conversion_finds_the_same_first_hits_as_rays(model, monkeypatch):
    # The raster sampling must be the regular grid, hit for hit: the same triangle at the
    # same pixels (up to a pixel centred on an edge to float32 precision), so the same sum.
    if model == "topex":
        scene = topex.build()
    else:
        scene = Scene.from_file(MODELS / "cosmos2502_lotos.obj", materials=MODELS / "cosmos2502_lotos.materials.json")
    rng = np.random.default_rng(11)
    sun, obs = unit(rng.normal(size=(5, 3))), unit(rng.normal(size=(5, 3)))
    rays, by_rays = _hit_table(DirectRenderer(scene, 0.03, sampling="grid"), sun, obs, monkeypatch)
    raster, by_raster = _hit_table(DirectRenderer(scene, 0.03, sampling="raster"), sun, obs, monkeypatch)
    hits = sum(by_rays.values())
    assert hits > 10_000
    # COSMOS 2502's cross is two boxes whose faces overlap in one plane: there either face is
    # a first hit, so hits are compared per plane.
    mesh = scene.posed()
    plane = np.unique(
        np.round(
            np.column_stack([mesh.face_normals, np.einsum("ij,ij->i", mesh.face_normals, mesh.corners_m[:, 0])]), 6
        ),
        axis=0,
        return_inverse=True,
    )[1].ravel()
    by_plane = [Counter(), Counter()]
    for table, counts in zip((by_rays, by_raster), by_plane):
        for (frame, triangle), count in table.items():
            counts[frame, plane[triangle]] += count
    differing = sum(abs(by_plane[0][key] - by_plane[1][key]) for key in set(by_plane[0]) | set(by_plane[1]))
    assert differing <= 1e-4 * hits
    # Each hit counted as one pixel (no exact-area share, no sampling of small triangles on
    # their own surface), the raster's sum is the grid's.
    from raycast.renderer import _direct_kernels

    flat_sums = _direct_kernels.flat_sums
    monkeypatch.setattr(_direct_kernels, "flat_sums", lambda *args: flat_sums(*args[:-1], np.ones_like(args[-1])))
    monkeypatch.setattr(DirectRenderer, "_sliver_sums", lambda *args: None)
    plain = DirectRenderer(scene, 0.03, sampling="raster").intensity(sun, obs)
    np.testing.assert_allclose(plain, rays, rtol=1e-4)
    assert np.count_nonzero(plain) >= 3
    # With the shares the sums differ, by the pixels' sampling of flat areas only.
    np.testing.assert_allclose(raster, rays, rtol=0.02)


def test_raster_counts_a_flat_face_by_its_exact_area(monkeypatch):
    # A fully visible Lambertian plate (two triangles of 1 m^2): I/E = albedo / pi * A * cos_s *
    # cos_o exactly. Seen face-on or nearly edge-on, the raster's sum is exact at any pixel
    # size: a triangle of at least EXACT_SHARE_MIN_PIXELS of projected area by its hits' shares
    # of that area, a smaller one (here always a sliver: large, seen nearly edge-on) by the
    # points of its own surface, where the pixel centres that fall on it say little (the ray
    # grid's plain count: -100% to +181%).
    from raycast.renderer._direct_kernels import EXACT_SHARE_MIN_PIXELS

    scene = Scene.from_parts([Part.plate("plate", 2.0, 1.0, "paint")], {"paint": Lambertian(0.4)})
    normal = scene.posed().face_normals[0]
    tilt = np.radians([10.0, 80.0, 88.0, 89.0, 89.5, 89.9])
    side = unit(np.cross(normal, [0.3, 0.5, 0.8]))
    obs = np.cos(tilt)[:, None] * normal + np.sin(tilt)[:, None] * side
    sun = np.tile(unit(normal + 0.4 * np.cross(normal, side)), (len(tilt), 1))
    exact = 0.4 / math.pi * 2.0 * (sun @ normal) * np.cos(tilt)
    errors, small = [], []
    for pixel_m in (0.3, 0.07, 0.013):
        raster = DirectRenderer(scene, pixel_m, sampling="raster").intensity(sun, obs)
        grid = DirectRenderer(scene, pixel_m, sampling="grid").intensity(sun, obs)
        np.testing.assert_allclose(raster, exact, rtol=1e-9)
        small.append(1.0 * np.cos(tilt) < EXACT_SHARE_MIN_PIXELS * pixel_m**2)
        errors.append(np.abs(grid / exact - 1.0))
    # Both kinds occur, and the exact area matters: the grid's plain sum misses by a few % on
    # the large ones and by far more on the small ones.
    small = np.concatenate(small)
    errors = np.concatenate(errors)
    assert 0 < small.sum() < len(small)
    assert np.max(errors[~small]) > 0.02
    assert np.max(errors[small]) > 0.2
    # Without the small triangles' own sampling their light is lost: a share of 0 for their hits.
    monkeypatch.setattr(DirectRenderer, "_sliver_sums", lambda *args: None)
    lost = DirectRenderer(scene, 0.3, sampling="raster").intensity(sun, obs)
    edge_on = 1.0 * np.cos(tilt) < EXACT_SHARE_MIN_PIXELS * 0.3**2
    assert np.all(lost[edge_on] == 0.0) and edge_on.any()


def test_raster_samples_a_sliver_for_shadow_and_cover_on_its_own_surface():
    # A 1 m plate seen 88 deg from face-on at 0.2 m pixels: each triangle has 12.5 pixels of
    # area of its own and 0.4 seen, a sliver sampled on its own surface. Sun overhead: a black
    # 2 m plate 1 m above shades all of it, or the half x < 0 when moved aside, and nothing when
    # moved further; a black wall beside it at x = 1 m hides it from the observer.
    materials = {"paint": Lambertian(0.4), "black": Lambertian(0.0)}
    plate = Part.plate("plate", 1.0, 1.0, "paint")
    tilt = math.radians(88.0)
    sun, obs = np.array([[0.0, 0.0, 1.0]]), np.array([[math.sin(tilt), 0.0, math.cos(tilt)]])
    full = 0.4 / math.pi * 1.0 * 1.0 * math.cos(tilt)  # albedo / pi * area * cos_s * cos_o
    wall_rotation = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # normal -> -x

    def seen(*blockers):
        scene = Scene.from_parts([plate, *blockers], materials)
        return DirectRenderer(scene, 0.2, sampling="raster").intensity(sun, obs)[0]

    def roof(x_m):
        return Part.plate("roof", 2.0, 2.0, "black").transformed(offset_m=(x_m, 0.0, 1.0))

    wall = Part.plate("wall", 2.0, 2.0, "black").transformed(wall_rotation, offset_m=(1.0, 0.0, 0.5))
    assert seen(roof(-5.0)) == pytest.approx(full, rel=1e-9)  # roof aside
    assert seen(roof(0.0)) == 0.0  # in its shadow
    assert 0.3 * full < seen(roof(-1.0)) < 0.7 * full  # half in its shadow
    assert seen(wall) == 0.0  # hidden from the observer


def test_scan_conversion_leaves_out_the_inner_sides_of_closed_parts_only():
    # A sheet (open: both sides can be seen) in front of a closed box seen from inside its
    # bounding box's corner: the sheet's far side and the box's outer faces are drawn, the
    # box's inner sides never, and the sum equals the ray-cast grid's.
    sheet = Part.plate("sheet", 1.0, 1.0, "paint").transformed(offset_m=(0.2, 0.0, 1.0))
    scene = Scene.from_parts([Part.box("box", (1.0, 1.0, 1.0), "paint"), sheet], {"paint": Lambertian(0.5)})
    sun = unit(np.array([[0.3, 0.2, 1.0], [0.3, 0.2, -1.0], [1.0, 0.1, 0.1]]))
    obs = unit(np.array([[0.1, -0.4, 1.0], [-0.2, 0.1, -1.0], [0.8, 0.5, 0.2]]))
    rays = DirectRenderer(scene, 0.005, sampling="grid").intensity(sun, obs)
    raster = DirectRenderer(scene, 0.005, sampling="raster").intensity(sun, obs)
    np.testing.assert_allclose(raster, rays, rtol=1e-3)
    assert (raster > 0.0).all()


def test_hits_spared_a_shadow_ray_are_lit(monkeypatch):
    # TOPEX's parts are closed convex boxes (all but the dish): most sunlit hits need no shadow
    # ray. Sparing them must leave the light curve exactly as with every ray cast.
    from raycast.renderer import _direct_kernels

    scene = topex.build()
    rng = np.random.default_rng(3)
    sun, obs = unit(rng.normal(size=(8, 3))), unit(rng.normal(size=(8, 3)))
    asked = []
    need = _direct_kernels.need_shadow_rays

    def recording(*args):
        result = need(*args)
        asked.append((result.sum(), len(result)))
        return result

    monkeypatch.setattr(_direct_kernels, "need_shadow_rays", recording)
    spared = DirectRenderer(scene, 0.03, sampling="raster").intensity(sun, obs)
    monkeypatch.setattr(_direct_kernels, "need_shadow_rays", lambda *args: np.ones(len(args[6]), dtype=bool))
    every = DirectRenderer(scene, 0.03, sampling="raster").intensity(sun, obs)
    np.testing.assert_allclose(spared, every, rtol=1e-12)
    needed, hits = np.sum(asked, axis=0)
    assert needed < 0.6 * hits
    assert np.count_nonzero(spared) >= 4


def test_convex_groups_are_closed_convex_parts():
    from raycast.renderer.direct import convex_groups

    # A box and a sphere are closed and convex; a plate is open; a box with one corner pushed
    # inward is closed but dented. Each triangle outside a convex part is a group of its own.
    box = Part.box("box", (2.0, 1.0, 1.0), "paint")
    corners = box.corners_m.copy()
    corner = np.array([1.0, 0.5, 0.5])
    corners[np.all(np.isclose(corners, corner), axis=2)] = [0.6, 0.2, 0.2]
    dented = Part._flat("dented", corners, box.materials).transformed(offset_m=(0.0, 3.0, 0.0))
    parts = [
        box,
        Part.sphere("ball", 0.5, "paint").transformed(offset_m=(3.0, 0.0, 0.0)),
        Part.plate("sheet", 1.0, 1.0, "paint").transformed(offset_m=(0.0, 0.0, 3.0)),
        dented,
    ]
    mesh = Scene.from_parts(parts, {"paint": Lambertian(0.5)}).posed()
    inner = mesh.inner_sides()
    assert inner[mesh.part_index == 3].any(axis=1).all()  # the dented box is still closed
    group = convex_groups(mesh, inner)
    for part, convex in enumerate((True, True, False, False)):
        tris = np.flatnonzero(mesh.part_index == part)
        if convex:
            assert (group[tris] == part).all()
        else:
            assert len(np.unique(group[tris])) == len(tris) and (group[tris] >= len(parts)).all()


def test_render_scan_converts_small_meshes_and_samples_large_ones_adaptively(monkeypatch):
    from raycast.renderer import methods as render_module

    scene = topex.build()
    rng = np.random.default_rng(4)
    sun, obs = unit(rng.normal(size=(6, 3))), unit(rng.normal(size=(6, 3)))
    small = render(scene, geometry(sun, obs), method="direct", pixel_size_m=0.03)
    monkeypatch.setattr(render_module, "RASTER_MAX_TRIANGLES", scene.n_triangles - 1)
    large = render(scene, geometry(sun, obs), method="direct", pixel_size_m=0.03)
    assert small.settings["sampling"] == "raster" and large.settings["sampling"] == "adaptive"
    np.testing.assert_array_equal(
        small.intensity_m2_sr, DirectRenderer(scene, 0.03, sampling="raster").intensity(sun, obs)
    )
    lit = large.intensity_m2_sr > 0.0
    assert lit.sum() >= 3
    # Two samplings of one integral at 3 cm: within their edge errors (a few pixels' worth,
    # which is much of a frame that shows only a sliver).
    np.testing.assert_allclose(
        small.intensity_m2_sr[lit], large.intensity_m2_sr[lit], rtol=0.02, atol=1e-3 * large.intensity_m2_sr.max()
    )
