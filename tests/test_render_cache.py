"""The fast path (raycast.renderer.cache) against the direct renderer and exact answers."""

import dataclasses
import math

import numpy as np
import pytest

from raycast.geometry.attitude import PrecessingSpin
from raycast.models import topex
from raycast.renderer import cache as cache_module
from raycast.renderer.brdf import GGX, Lambertian
from raycast.renderer.cache import SceneCache, cube_grid_directions, cube_grid_weights
from raycast.renderer.direct import DirectRenderer
from raycast.renderer.methods import render
from raycast.renderer.scene import Articulation, Part, Scene
from rsodb.fit.shape_store import ShapeStore
from rsodb.fit.shapes import brightness_for, mesh_shape
from tests.conftest import MODELS
from tests.render_support import dark_frames_agree, geometry, rms_mag, topex_pass_geometry, unit

# The paper's attitudes (seed paper, TOPEX 2020 and COSMOS 2502 2023 fits), applied along the
# real TOPEX pass of 2024-07-30 seen from Derenivka.
TOPEX_ATTITUDE = PrecessingSpin(period_s=9.86, precession_period_s=689.0, precession_angle_deg=35.0, spin_axis="z")
COSMOS_ATTITUDE = PrecessingSpin(period_s=40.5, precession_period_s=1620.0, precession_angle_deg=7.0, spin_axis="x")
# 40 frames spread over the 464 s pass, one sub-sample each (the comparison is per direction).
FRAMES = slice(0, 2320, 58)


def test_cube_grid_interpolation():
    n = 16
    directions = cube_grid_directions(n)
    index, weight = cube_grid_weights(directions, n)
    # At a grid node the interpolation returns that node (or a duplicate on a face edge).
    picked = np.take_along_axis(index, np.argmax(weight, axis=1)[:, None], axis=1)[:, 0]
    np.testing.assert_allclose(directions[picked], directions, atol=1e-12)
    np.testing.assert_allclose(weight.sum(axis=1), 1.0, rtol=1e-12)
    # A smooth function (the z component) is reproduced to second order in the 5.6 deg spacing.
    rng = np.random.default_rng(2)
    query = unit(rng.normal(size=(2000, 3)))
    index, weight = cube_grid_weights(query, n)
    values = (weight * directions[index][..., 2]).sum(axis=1)
    assert np.abs(values - query[:, 2]).max() < (math.radians(90.0 / n)) ** 2


def test_row_ids_number_rows_as_a_two_dimensional_unique():
    rng = np.random.default_rng(4)
    columns = [
        rng.integers(0, 3, 5000),
        rng.integers(-2_000_000, 2_000_000, 5000) // 400_000,
        rng.integers(-5, 5, 5000),
    ]
    ids, counts = cache_module._row_ids(5000, iter(columns))
    _, expected_ids, expected_counts = np.unique(
        np.column_stack(columns), axis=0, return_inverse=True, return_counts=True
    )
    np.testing.assert_array_equal(ids, expected_ids.reshape(-1))
    np.testing.assert_array_equal(counts, expected_counts)


def test_factorisation_gives_up_only_on_a_residual_that_cannot_reach_its_budget():
    columns = np.arange(1, 25)
    # Halving per doubling of the columns: 4 budgets at 24 columns reach 1 at 96.
    falling = 4.0 * (24.0 / columns)
    assert not cache_module._hopeless(falling, 1.0, 100)
    # Three budgets at 24 columns, falling 10% over the second half: more than 4/3 at 100.
    flat = 3.0 * (24.0 / columns) ** 0.15
    assert cache_module._hopeless(100.0 * flat, 1.0, 100)
    assert not cache_module._hopeless(flat, 1.0, 100)
    assert not cache_module._hopeless(0.2 * flat, 1.0, 100)  # within the budget already


def test_group_basis_is_orthonormal_in_32_bits():
    sketch = np.random.default_rng(5).standard_normal((3000, 40)).astype(np.float32)
    basis = cache_module._orthonormal(sketch.copy())
    assert basis.dtype == np.float32
    assert np.abs(basis.T.astype(float) @ basis - np.eye(40)).max() < 1e-5


def test_finer_elements_only_on_smooth_triangles_of_a_glossy_material():
    parts = [
        Part.cylinder("tube", 0.5, 2.0, "gloss", segments=24, cap_material="gloss"),
        Part.box("bus", (1, 1, 1), "gloss", center_m=(0, 0, 2.0)),
        Part.cylinder("drum", 0.5, 1.0, "matte", segments=24).transformed(offset_m=(0, 0, -2.0)),
    ]
    scene = Scene.from_parts(parts, {"gloss": GGX(0.5, 0.3), "matte": Lambertian(0.5)})
    mesh = scene.posed()
    strip = cache_module._glossy_strip(scene, mesh)
    tube_side = (mesh.part_index == 0) & (np.abs(mesh.face_normals[:, 2]) < 0.5)
    np.testing.assert_array_equal(strip, tube_side)  # not the caps, the box nor the Lambertian drum
    assert not cache_module._glossy_strip(scene.with_brdfs(gloss=GGX(0.5, 0.9)), mesh).any()  # a broad lobe


def test_convex_scene_needs_no_visibility():
    convex = SceneCache.build(Scene.from_parts([Part.box("box", (1, 2, 3), "m")], {"m": Lambertian(0.5)}))
    assert convex.poses[0].factors.shape[1] == 0
    assert convex.n_elements == 6  # one merged element per face
    concave = SceneCache.build(topex.build(), grid_size=8)
    assert concave.poses[0].factors.shape[1] > 0


@pytest.mark.slow
# The paper's COSMOS 2502 model: 0.0067 mag at grid 32 (0.030 before visibility elements and
# shading pieces were cut separately, 0.016 while elements whose bits differ around a direction
# were interpolated instead of cast, 0.0101 while elements partly covered beside the panels took
# their centroid's visibility); with k x k rays per element crossed by a shadow edge (k=2)
# 0.0062. TOPEX: 0.0040 either way.
@pytest.mark.parametrize("model", ["topex", "cosmos2502_paper"])
def test_fast_path_matches_direct_along_real_topex_pass(model, shared_shapes):
    if model == "topex":
        scene, attitude = topex.build(), TOPEX_ATTITUDE
        cache = SceneCache.build(scene, grid_size=32)
    else:
        scene = Scene.from_file(MODELS / "cosmos2502_lotos.obj", materials=MODELS / "cosmos2502_lotos.materials.json")
        attitude = COSMOS_ATTITUDE
        # The build a fit of this mesh makes (SceneCache.build at grid 32, accuracy 0.01 mag),
        # taken from the run's shared store: the docs' paper-mesh fit uses the same cache.
        shape = mesh_shape(MODELS / "cosmos2502_lotos.obj", MODELS / "cosmos2502_lotos.materials.json")
        cache, _ = brightness_for(shape, {}, {}, grid_size=32, store=ShapeStore(shared_shapes))
        assert isinstance(cache, SceneCache) and cache.grid_size == 32
    body = topex_pass_geometry(attitude, frames=FRAMES, exposure_s=0.0)
    sun, obs = body.sun_body[:, 0], body.obs_body[:, 0]
    reference = DirectRenderer(scene, 0.02).intensity(sun, obs)
    # The edge rays are a run-time setting: one build serves both.
    for edge_rays_per_side in (1, 2):
        cached = dataclasses.replace(cache, edge_rays_per_side=edge_rays_per_side).intensity(sun, obs)
        # The target: the fast path within 0.01 mag RMS of the direct renderer (whose own
        # error at 2 cm pixels is ~0.001 mag RMS against 5 mm on these passes), over frames
        # brighter than 1e-3 of the peak; the darker ones agree to 1e-3 of the peak in light.
        assert rms_mag(cached, reference) < 0.01, edge_rays_per_side
        assert dark_frames_agree(cached, reference)


def articulated_scene():
    panel = Part.box("panel", (0.05, 3.0, 1.5), "back", face_materials={"+x": "cells"}).transformed(
        offset_m=(0.0, 2.6, 0.5)
    )
    return Scene.from_parts(
        [Part.box("bus", (1.5, 1.5, 2.0), "paint"), panel],
        {"paint": Lambertian(0.6), "back": Lambertian(0.2), "cells": GGX(0.1, 0.35)},
        articulations=[Articulation("panel", "pitch_deg", (0.0, 1.1, 0.5), (0.0, 1.0, 0.0))],
        parameters={"pitch_deg": 10.0},
    )


def test_elements_partly_covered_by_a_mount_are_quartered(monkeypatch):
    # A 2 m plate under a flat 0.7 m block whose edges cross the plate's 0.25 m elements: seen
    # from near the zenith, those elements are partly covered in every direction, and their
    # centroid alone would count them wholly covered or wholly open (0.012 mag off). Quartered
    # where their quarters disagree, they stay within 0.005 mag of the direct renderer (its own
    # error at 3 mm pixels is below 0.001 mag here).
    import raycast.renderer.cache

    block = Part.box("block", (0.7, 0.7, 0.04), "paint", center_m=(0.13, -0.21, 0.02))
    scene = Scene.from_parts([Part.plate("plate", 2.0, 2.0, "paint"), block], {"paint": Lambertian(0.5)})
    rng = np.random.default_rng(5)
    sun = unit(rng.normal(size=(20, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, 1.0])
    obs = unit(rng.normal(size=(20, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, 1.0])
    reference = DirectRenderer(scene, 0.003).intensity(sun, obs)
    quartered = SceneCache.build(scene, element_size_m=0.25)
    assert rms_mag(quartered.intensity(sun, obs), reference) < 0.005
    monkeypatch.setattr(raycast.renderer.cache, "_SPLIT_FRACTION", 2.0)  # never split
    whole = SceneCache.build(scene, element_size_m=0.25)
    assert whole.n_elements < quartered.n_elements
    assert rms_mag(whole.intensity(sun, obs), reference) > 0.01


def window_in_a_wall(width_m, bottom_m, top_m, elevations_deg):
    """A 3 x 0.3 m floor and a black wall 2.6 m along it with a window ``width_m`` wide between
    heights ``bottom_m`` and ``top_m``; observers at ``elevations_deg`` above the floor (three
    azimuths each), a Sun that lights the floor and not the wall's far side; the direct
    renderer's intensities at 2 mm pixels. Returns (scene, sun, obs, reference)."""

    def slab(name, y0, y1, z0, z1):
        return Part.box(name, (0.02, y1 - y0, z1 - z0), "black", center_m=(2.6, (y0 + y1) / 2, (z0 + z1) / 2))

    wall = [
        slab("left", -0.4, 0.0, 0.0, 0.4),
        slab("right", width_m, 0.46, 0.0, 0.4),
        slab("below", 0.0, width_m, 0.0, bottom_m),
        slab("above", 0.0, width_m, top_m, 0.4),
    ]
    scene = Scene.from_parts(
        [Part.plate("floor", 3.0, 0.3, "paint"), *wall], {"paint": Lambertian(0.5), "black": Lambertian(0.001)}
    )
    elevation, azimuth = (a.ravel() for a in np.meshgrid(np.radians(elevations_deg), np.radians([-0.9, 0.4, 1.1])))
    obs = np.column_stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    sun = np.tile(unit(np.array([-0.3, 0.1, 0.95])), (len(obs), 1))
    return scene, sun, obs, DirectRenderer(scene, 0.002).intensity(sun, obs)


def test_a_window_narrower_than_the_grid_is_seen_through(monkeypatch):
    # A floor seen 2-4 deg above its plane through a 6 cm window in a wall 1-4 m away: the window
    # spans 1-3 deg, less than the 2.8 deg cube map, so the four grid nodes around the observer
    # are blocked for most of the floor that sees out. The bit-held elements' gap nodes
    # (_horizon_gaps) let rays decide; without them the floor is 0.2-2.9 mag too faint.
    import raycast.renderer.cache

    monkeypatch.setattr(raycast.renderer.cache, "_FACTOR_MIN_ELEMENTS", 10**9)  # every element as bits
    scene, sun, obs, reference = window_in_a_wall(0.06, 0.12, 0.18, [2.2, 3.1, 4.3])
    cache = SceneCache.build(scene, element_size_m=0.03)
    assert len(cache.poses[0].gap_word) > 0
    assert rms_mag(cache.intensity(sun, obs), reference) < 0.05
    monkeypatch.setattr(raycast.renderer.cache, "_GAP_RINGS", ())  # no horizon probes: the slit's gap nodes alone
    slits_only = SceneCache.build(scene, element_size_m=0.03)
    assert rms_mag(slits_only.intensity(sun, obs), reference) < 0.05
    monkeypatch.setattr(raycast.renderer.cache, "_slit_gaps", lambda *args: 0)  # no gap nodes at all
    blind = SceneCache.build(scene, element_size_m=0.03)
    assert len(blind.poses[0].gap_word) == 0
    assert rms_mag(blind.intensity(sun, obs), reference) > 0.5


def test_the_gap_search_reaches_as_high_above_the_horizon_on_a_fine_grid(monkeypatch):
    # A window like the test above's, 2 x 3 cm, seen 3.6-5 deg above the floor on a 64-node grid
    # (1.4 deg spacing; the window spans 0.3-1 deg): two grid spacings are 2.8 deg, so the gap
    # search must reach higher than that (_GAP_BAND_MIN_RAD, 5.6 deg) to find the window's gap
    # nodes. The slits' search is off, so the horizon probes alone decide; without the floor on
    # the band the floor stays dark where it sees out only through the window.
    import raycast.renderer.cache

    monkeypatch.setattr(raycast.renderer.cache, "_FACTOR_MIN_ELEMENTS", 10**9)
    monkeypatch.setattr(raycast.renderer.cache, "_slit_gaps", lambda *args: 0)
    scene, sun, obs, reference = window_in_a_wall(0.02, 0.13, 0.16, [3.6, 4.3, 5.0])
    cache = SceneCache.build(scene, element_size_m=0.03, grid_size=64)
    # (3 cm elements seeing out through a 2 cm window: within 0.1 mag of the direct renderer.)
    assert rms_mag(cache.intensity(sun, obs), reference) < 0.1
    monkeypatch.setattr(raycast.renderer.cache, "_GAP_BAND_MIN_RAD", 0.0)  # two grid spacings only
    narrow = SceneCache.build(scene, element_size_m=0.03, grid_size=64)
    assert len(narrow.poses[0].gap_word) < len(cache.poses[0].gap_word)
    assert rms_mag(narrow.intensity(sun, obs), reference) > 0.5


def test_light_through_slits_between_slats_reaches_the_surface_below(monkeypatch):
    # A floor under a panel of six slats 3 cm apart (each its own part, as the paper's COSMOS
    # 2502 panels are built), the Sun near the zenith, the observer 20 deg up beside the panel:
    # from the floor each slit spans ~1 deg, under the 2.8 deg cube map, so the four grid nodes
    # around the Sun are blocked for most of the floor the slits light. The slits' gap nodes
    # (_slit_gaps) let rays decide; without them the floor under the panel stays dark.
    import raycast.renderer.cache

    slats = [Part.box(f"slat{k}", (0.2, 1.2, 0.02), "paint", center_m=(-0.575 + 0.23 * k, 0.0, 1.5)) for k in range(6)]
    scene = Scene.from_parts([Part.plate("floor", 1.4, 1.2, "paint"), *slats], {"paint": Lambertian(0.5)})
    rng = np.random.default_rng(3)
    sun = unit(rng.normal(size=(8, 3)) * [0.1, 0.1, 0.0] + [0.0, 0.0, 1.0])
    elevation = np.radians(20.0 + rng.uniform(-3.0, 3.0, 8))
    obs = np.column_stack([rng.uniform(-0.05, 0.05, 8), np.cos(elevation), np.sin(elevation)])
    obs = unit(obs)
    reference = DirectRenderer(scene, 0.003).intensity(sun, obs)
    cache = SceneCache.build(scene, element_size_m=0.03, grid_size=32)
    assert len(cache.poses[0].gap_word) > 0
    error = rms_mag(cache.intensity(sun, obs), reference)
    monkeypatch.setattr(raycast.renderer.cache, "_slit_gaps", lambda *args: 0)
    blind = SceneCache.build(scene, element_size_m=0.03, grid_size=32)
    blind_error = rms_mag(blind.intensity(sun, obs), reference)
    assert error < 0.015  # 0.0066 measured
    assert blind_error > 0.03  # 0.044 measured


def test_articulation_axis_interpolates_between_poses():
    scene = articulated_scene()
    cache = SceneCache.build(scene, articulation_grid={"pitch_deg": [8.0, 10.0, 12.0]}, grid_size=24)
    rng = np.random.default_rng(9)
    sun = unit(rng.normal(size=(30, 3)) + [2.0, 0.0, 0.5])
    obs = unit(rng.normal(size=(30, 3)) + [2.0, 0.0, 0.5])
    direct = DirectRenderer(scene, 0.01).intensity(sun, obs, pitch_deg=11.0)
    # Linear interpolation between poses 2 deg apart plus the cache's own error: 0.02 mag RMS.
    assert rms_mag(cache.intensity(sun, obs, pitch_deg=11.0), direct) < 0.02
    # The grid nodes themselves are exact poses.
    node = DirectRenderer(scene, 0.01).intensity(sun, obs, pitch_deg=12.0)
    assert rms_mag(cache.intensity(sun, obs, pitch_deg=12.0), node) < 0.01


@pytest.mark.parametrize(
    "m, threads, chunk",
    [(1, 2, 256), (63, 2, 256), (64, 2, 256), (150, 2, 256), (600, 3, 256), (4640, 2, 1024), (300, 1, 256)],
)
def test_frame_batches_cover_the_frames_in_order(m, threads, chunk):
    batches = cache_module._frame_batches(m, threads, chunk)
    assert [b.start for b in batches[1:]] == [b.stop for b in batches[:-1]]  # contiguous, in order
    assert batches[0].start == 0 and batches[-1].stop == m
    sizes = [b.stop - b.start for b in batches]
    assert max(sizes) <= chunk
    # As many batches as threads where each gets enough frames; no more than the chunks need.
    expected = max(-(-m // chunk), min(threads, m // cache_module._MIN_FRAMES_PER_THREAD), 1)
    assert len(batches) == expected


@pytest.mark.parametrize("n_classes, frames", [(1, 1024), (357, 1024), (1528, 686), (57091, 256)])
def test_batches_hold_at_most_a_million_lit_rows_within_bounds(n_classes, frames):
    # TOPEX (357 classes) in batches of 1 024 frames; the paper mesh (1 528) 686; all-Glossy 256.
    assert cache_module._chunk_frames(n_classes) == frames


def test_threads_give_the_one_thread_light_curve(monkeypatch):
    # 300 frames: three batches on two threads (two run together, their rays in one call).
    scene = articulated_scene()
    cache = SceneCache.build(scene, grid_size=16)
    rng = np.random.default_rng(12)
    sun = unit(rng.normal(size=(300, 3)) + [2.0, 0.0, 0.5])
    obs = unit(rng.normal(size=(300, 3)) + [2.0, 0.0, 0.5])
    monkeypatch.setattr(cache_module, "_threads", lambda: 1)
    one = cache.intensity(sun, obs)
    monkeypatch.setattr(cache_module, "_threads", lambda: 2)
    monkeypatch.setattr(cache_module, "_FRAMES_PER_CHUNK", (128, 128))
    assert len(cache_module._frame_batches(300, 2, cache_module._chunk_frames(cache.poses[0].n_classes))) == 3
    np.testing.assert_array_equal(cache.intensity(sun, obs), one)
    assert np.count_nonzero(one) > 250
    origins = cache_module._ray_origins(cache.poses[0], cache_module._subpoint_weights(1))
    frames = cache_module._Frames.of(sun, obs, 16)
    assert len(cache_module._pairs_to_decide(cache.poses[0], frames, origins).rays) > 1000  # rays were merged


def test_a_pool_worker_shades_with_one_thread(monkeypatch):
    from rsodb.pool import SINGLE_THREAD_ENV

    for key, value in SINGLE_THREAD_ENV.items():
        monkeypatch.setenv(key, value)
    assert cache_module._threads() == 1
    # Many batches on one thread run in the caller, not through the pool.
    monkeypatch.setattr(cache_module, "_executor", lambda threads: pytest.fail("the pool was used"))
    scene = articulated_scene()
    cache = SceneCache.build(scene, grid_size=8)
    rng = np.random.default_rng(3)
    sun, obs = unit(rng.normal(size=(600, 3)) + [2.0, 0.0, 0.5]), unit(rng.normal(size=(600, 3)) + [2.0, 0.0, 0.5])
    monkeypatch.setattr(cache_module, "_FRAMES_PER_CHUNK", (256, 256))
    assert len(cache_module._frame_batches(600, 1, cache_module._chunk_frames(cache.poses[0].n_classes))) == 3
    assert np.all(np.isfinite(cache.intensity(sun, obs)))
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert cache_module._threads() >= 1


def test_articulation_errors_name_the_fix():
    scene = articulated_scene()
    single = SceneCache.build(scene, grid_size=8)
    sun = obs = np.array([[1.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"built for pitch_deg=10.0 only; rebuild it with articulation_grid"):
        single.intensity(sun, obs, pitch_deg=11.0)
    ranged = SceneCache.build(scene, articulation_grid={"pitch_deg": [8.0, 12.0]}, grid_size=8)
    with pytest.raises(ValueError, match=r"pitch_deg=20.0 is outside the cached range \[8.0, 12.0\]"):
        ranged.intensity(sun, obs, pitch_deg=20.0)


def test_render_reuses_a_prebuilt_cache():
    scene = topex.build()
    cache = SceneCache.build(scene, grid_size=8)
    rng = np.random.default_rng(4)
    sun, obs = unit(rng.normal(size=(5, 3))), unit(rng.normal(size=(5, 3)))
    model = render(scene, geometry(sun, obs), cache=cache)
    assert model.method == "cached"  # "auto" takes the prebuilt cache
    np.testing.assert_array_equal(model.intensity_m2_sr, cache.intensity(sun, obs))
    assert model.settings["precompute_s"] == cache.precompute_s


@pytest.mark.slow
def test_smooth_glossy_cylinder_glint_matches_direct():
    # A glossy smooth-shaded cylinder: its glint is a line whose width the element normals must
    # resolve; the cache's normal step (half the lobe) keeps it within 0.01 mag of the direct,
    # and its peak within 0.15% (0.13%; 0.095% with no class merged into coarser bins far from
    # the half vector, _COARSE_BIN_RATIO).
    scene = Scene.from_parts([Part.cylinder("tube", 1.0, 4.0, "gloss", segments=32)], {"gloss": GGX(0.5, 0.3)})
    rng = np.random.default_rng(12)
    sun = unit(rng.normal(size=(12, 3)) * [1, 1, 0.3])
    obs = unit(rng.normal(size=(12, 3)) * [1, 1, 0.3])
    reference = DirectRenderer(scene, 0.004).intensity(sun, obs)
    bright = reference > 0.01 * reference.max()
    fine = SceneCache.build(scene)
    # One shading class per normal step instead of three: fewer classes, each still shaded at
    # its lit mean normal, so the error is second order in the bin: within 0.01 mag RMS, but
    # the glint's peak moves from under 0.1% to 0.3% (0.0036 mag).
    coarse = SceneCache.build(scene, normal_bins_per_step=1)
    assert coarse.poses[0].n_classes < fine.poses[0].n_classes / 2
    # The lobe's tail in bins twice as coarse, and its shadow edges to the bits from 2 lobe
    # widths beyond the nearest lobe instead of 4: the peak moves by 0.34% (0.13%).
    tail = SceneCache.build(scene, coarse_bin_ratio=1 / 3, far_lobe_widths=2)
    for cache, peak_share in ((fine, 1.5e-3), (coarse, 5e-3), (tail, 5e-3)):
        cached = cache.intensity(sun, obs)
        assert rms_mag(cached[bright], reference[bright]) < 0.01
        # Frames 1000x fainter than the glint are grazing silhouettes: judged in light, not magnitudes.
        assert np.abs(cached - reference).max() < peak_share * reference.max()
    for bad in (0.5, math.inf, True):
        with pytest.raises(ValueError, match=f"normal_bins_per_step={bad!r} must be a number >= 1"):
            SceneCache.build(scene, normal_bins_per_step=bad)
    for bad in (1.0, -0.1, math.nan, "1/3"):
        with pytest.raises(ValueError, match=f"coarse_bin_ratio={bad!r} must be a number in"):
            SceneCache.build(scene, coarse_bin_ratio=bad)
    for bad in (-1, math.nan, None):
        with pytest.raises(ValueError, match=f"far_lobe_widths={bad!r} must be a number >= 0"):
            SceneCache.build(scene, far_lobe_widths=bad)


def _lit_rows_and_rays(cache, sun, obs):
    """The (frame, class) rows a light curve shades and the exact rays it casts, one batch."""
    pose = cache.poses[0]
    origins = cache_module._ray_origins(pose, cache_module._subpoint_weights(1))
    frames = cache_module._Frames.of(sun, obs, cache.grid_size)
    pairs = cache_module._pairs_to_decide(pose, frames, origins)
    occluded = cache_module._occluded(pose, [pairs.rays], 1)[0]
    return cache_module._lit_classes(pose, frames, cache.grid_size, pairs, occluded, 1)[0], pairs.rays


def glossy_tube_and_wing():
    """A smooth-shaded glossy tube and a glossy flat wing beside it that shadows it, and 60
    frames around the side they share."""
    tube = Part.cylinder("tube", 1.0, 4.0, "gloss", segments=32)
    wing = Part.box("wing", (0.04, 2.5, 3.0), "gloss", center_m=(1.8, 0.0, 0.0))
    scene = Scene.from_parts([tube, wing], {"gloss": GGX(0.6, 0.3)})
    rng = np.random.default_rng(8)
    sun = unit(rng.normal(size=(60, 3)) * [0.6, 1.0, 0.6] + [0.8, 0.0, 0.0])
    obs = unit(rng.normal(size=(60, 3)) * [0.6, 1.0, 0.6] + [0.8, 0.0, 0.0])
    return scene, sun, obs


@pytest.mark.slow
def test_classes_far_from_the_lobe_shade_coarse_and_their_pairs_cast_no_rays():
    # Away from the half vector a GGX lobe's tail varies slowly: classes there are shaded in
    # coarser bins, and mixed pairs there are counted by their bits' interpolation instead of
    # exact rays. Against the cache that does neither (same elements, same bits): a fraction
    # of the rows and rays for a light curve within 0.001 mag RMS and 0.5% of its peak.
    scene, sun, obs = glossy_tube_and_wing()
    settings = dict(grid_size=16, normal_bins_per_step=1, element_size_m=0.3)
    fast = SceneCache.build(scene, **settings)
    exact = SceneCache.build(scene, coarse_bin_ratio=0, far_lobe_widths=math.inf, **settings)
    fast_rows, fast_rays = _lit_rows_and_rays(fast, sun, obs)
    exact_rows, exact_rays = _lit_rows_and_rays(exact, sun, obs)
    assert len(fast_rows) < 0.7 * len(exact_rows)
    assert len(fast_rays) < 0.8 * len(exact_rays)
    assert len(exact_rays) > 2000
    ours, reference = fast.intensity(sun, obs), exact.intensity(sun, obs)
    lit = reference > 1e-3 * reference.max()  # the wing's glints are 100x the tube's frames
    assert np.count_nonzero(lit) > 40
    # 0.0007 mag; 0.0019 if the pairs left without rays counted dark.
    assert rms_mag(ours[lit], reference[lit]) < 0.001
    assert np.abs(ours - reference).max() < 5e-3 * reference.max()


def test_lambertian_elements_always_get_rays():
    # A diffuse base never leaves an element to its bits' interpolation, whatever its normal.
    tube = Part.cylinder("tube", 1.0, 4.0, "paint", segments=16)
    wing = Part.box("wing", (0.04, 2.5, 3.0), "gloss", center_m=(1.8, 0.0, 0.0))
    scene = Scene.from_parts([tube, wing], {"paint": Lambertian(0.5), "gloss": GGX(0.6, 0.3)})
    pose = SceneCache.build(scene, grid_size=16, element_size_m=0.3).poses[0]
    material = pose.target_material[pose.group_class[pose.raw_area.indices]]
    column = np.repeat(np.arange(pose.raw_count), np.diff(pose.raw_area.indptr))
    diffuse = np.zeros(pose.raw_count, dtype=bool)
    diffuse[column[material == scene.material_names.index("paint")]] = True
    assert diffuse.any() and (~diffuse).any()
    assert np.all(pose.element_far[diffuse, 0] == -1.0)
    assert np.all(pose.element_far[~diffuse, 0] > 4.0 * 0.09)


@pytest.mark.parametrize("per_side", [1, 2, 3, 4])
def test_edge_ray_points_cover_the_element_evenly(per_side):
    from raycast.renderer.cache import _subpoint_weights

    weights = _subpoint_weights(per_side)
    # k*k sub-triangle centroids: barycentric, inside, and centred on the element's centroid.
    assert weights.shape == (per_side**2, 3)
    assert np.allclose(weights.sum(axis=1), 1.0) and weights.min() > 0.0
    assert np.allclose(weights.mean(axis=0), 1.0 / 3.0, atol=1e-6)
    assert len(np.unique(np.round(weights, 6), axis=0)) == per_side**2


def test_edge_rays_per_side_is_checked():
    with pytest.raises(ValueError, match="edge_rays_per_side=0 must be an integer in"):
        SceneCache.build(topex.build(), grid_size=8, edge_rays_per_side=0)


def test_build_keeps_its_working_tables_in_pieces():
    # The build holds the rays' findings in the blocks they came in (raycast.renderer.cache._Rows)
    # and cuts shading pieces a block of triangles at a time (_pieces); both must give exactly
    # what one array and one cut of every triangle give.
    from raycast.renderer.cache import _bisect, _pieces, _Rows

    rng = np.random.default_rng(3)
    blocks = [rng.integers(0, 256, size=(n, 5), dtype=np.uint8) for n in (4, 0, 7, 1)]
    rows = _Rows(5)
    for block in blocks:
        rows.append(block)
    whole = np.concatenate(blocks)
    index = rng.integers(0, len(whole), size=30)
    assert len(rows) == 12 and np.array_equal(rows[index], whole[index])

    corners = rng.normal(size=(9, 3, 3))
    normals = unit(rng.normal(size=(27, 3))).reshape(9, 3, 3) + [0.0, 0.0, 2.0]

    def too_big(c, n, owner):
        return np.linalg.norm(c[:, 1] - c[:, 0], axis=1) > 0.4 + 0.01 * owner

    normal, area, parent = _pieces(corners, normals, too_big, chunk=2)
    c, n, p = _bisect(corners, normals, np.arange(9), too_big)
    order, expected_order = (
        np.lexsort((area, parent)),
        np.lexsort((0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1), p)),
    )
    assert len(area) == len(c) > 9
    assert np.array_equal(parent[order], p[expected_order])
    mean = n.mean(axis=1)
    assert np.allclose(normal[order], (mean / np.linalg.norm(mean, axis=1, keepdims=True))[expected_order])
    triangle_area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    assert np.allclose(np.bincount(parent, weights=area), triangle_area)


def test_gap_table_holds_every_pair_once_whatever_the_chunks():
    """The gap searches' pairs (repeated, in batches) become one bit per (node, element) in the
    run time's CSR table, the same when the table is built in chunks that cut nodes' runs."""
    rng = np.random.default_rng(5)
    n_elements, n_directions = 300, 96
    node, element = rng.integers(0, n_directions, 20_000), rng.integers(0, n_elements, 20_000)
    gaps = cache_module._GapPairs(n_elements)
    for batch in np.array_split(np.arange(len(node)), 7):
        gaps.add(node[batch], element[batch])
    expected = np.zeros((n_directions, n_elements), dtype=bool)
    expected[node, element] = True
    for chunk in (64, 1 << 18):
        ptr, word, mask = cache_module._gap_table(gaps.merged(), n_elements, n_directions, chunk=chunk)
        table = np.zeros_like(expected)
        for d in range(n_directions):
            for w, m in zip(word[ptr[d] : ptr[d + 1]], mask[ptr[d] : ptr[d + 1]]):
                bits = np.flatnonzero([(int(m) >> b) & 1 for b in range(64)])
                table[d, 64 * w + bits] = True
        np.testing.assert_array_equal(table, expected)
        assert len(word) == len(np.unique(np.c_[node, element // 64], axis=0))  # one entry per (node, word)
