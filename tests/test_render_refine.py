"""The direct renderer's adaptive sampling (raycast.renderer.refine) against its regular grid.

The regular grid with small pixels is the plain reference: the same rays, cast everywhere.
The adaptive sampler must give the same light curve with far fewer rays, including for the
cases its shortcuts could miss: parts and shadows narrower than its coarse cells, smooth
shading, and the real models along the real TOPEX pass.
"""

import numpy as np
import pytest

from raycast.geometry.attitude import PrecessingSpin
from raycast.models import topex
from raycast.renderer.brdf import GGX, Lambertian
from raycast.renderer.direct import DirectRenderer
from raycast.renderer.rays import orthonormal_basis
from raycast.renderer.refine import coarse_levels
from raycast.renderer.scene import Part, Scene
from tests.conftest import MODELS
from tests.render_support import rms_mag, topex_pass_geometry, unit


def rod_over_plate():
    """A 4 x 4 m plate with a 4 cm rod 0.5 m in front of it: both the rod and its shadow are
    far narrower than the sampler's coarse cells (about 0.24 m here)."""
    plate = Part.box("plate", (4.0, 4.0, 0.02), "paint")
    rod = Part.box("rod", (0.04, 3.6, 0.04), "metal").transformed(offset_m=(0.3, 0.0, 0.5))
    return Scene.from_parts([plate, rod], {"paint": Lambertian(0.5), "metal": Lambertian(0.9)})


def directions():
    rng = np.random.default_rng(5)
    sun = unit(rng.normal(size=(12, 3)) * [0.5, 0.5, 0.2] + [0.0, 0.0, 1.0])
    obs = unit(rng.normal(size=(12, 3)) * [0.5, 0.5, 0.2] + [0.0, 0.0, 1.0])
    return sun, obs


def test_narrow_part_and_shadow_match_the_grid():
    scene = rod_over_plate()
    sun, obs = directions()
    grid = DirectRenderer(scene, 0.004, sampling="grid").intensity(sun, obs)
    adaptive = DirectRenderer(scene, 0.004).intensity(sun, obs)
    assert coarse_levels(scene.posed(), 0.004) >= 5  # coarse cells of >= 0.128 m: 3x the rod
    # Both estimate the same integral with 4 mm rays; their edge errors are ~1e-3 of a frame
    # (the rod's 4 cm edges are 10 pixels wide), far below the rod's own 1.5-3% share.
    np.testing.assert_allclose(adaptive, grid, rtol=1.5e-3)


def test_marks_kept_as_keys_give_the_same_result(monkeypatch):
    import raycast.renderer.refine as refine

    scene = rod_over_plate()
    sun, obs = directions()
    dense = DirectRenderer(scene, 0.004).intensity(sun, obs)
    monkeypatch.setattr(refine, "_MAX_DENSE_MARKS", 0)
    np.testing.assert_array_equal(DirectRenderer(scene, 0.004).intensity(sun, obs), dense)


def test_without_edge_marks_the_narrow_rod_would_be_missed(monkeypatch):
    """The marks are what finds the rod: switched off, cells straddle it unseen."""
    import raycast.renderer.refine as refine

    scene = rod_over_plate()
    sun, obs = directions()
    grid = DirectRenderer(scene, 0.004, sampling="grid").intensity(sun, obs)
    monkeypatch.setattr(refine, "_MARK_MIN_CELLS", 1 << 30)
    unmarked = DirectRenderer(scene, 0.004).intensity(sun, obs)
    assert np.abs(unmarked / grid - 1.0).max() > 3e-3


def test_flat_box_needs_few_rays_and_is_exact_inside():
    """Over a box's faces the corners give the exact radiance: the result converges like the
    regular grid's while casting a small fraction of its rays."""
    scene = Scene.from_parts([Part.box("box", (2.0, 1.0, 3.0), "m")], {"m": GGX(0.4, 0.4)})
    sun, obs = directions()
    renderer = DirectRenderer(scene, 0.003)
    mesh, raycaster = renderer._prepared()
    sampler = renderer._sampler()
    u, v = orthonormal_basis(obs)
    rel = mesh.vertices_m - mesh.center_m
    sampler.intensity(sun, obs, u, v, (rel @ u.T).min(axis=0) - 1e-3, (rel @ v.T).min(axis=0) - 1e-3)
    grid_rays = len(sun) * (2.0 * mesh.radius_m / 0.003) ** 2 * np.pi / 4.0
    assert sampler.n_rays < 0.05 * grid_rays
    facets = DirectRenderer(scene, 0.0015, sampling="grid").intensity(sun, obs)
    np.testing.assert_allclose(renderer.intensity(sun, obs), facets, rtol=1e-3)


def test_smooth_sphere_is_summed_to_the_requested_accuracy():
    sphere = Scene.from_parts([Part.sphere("ball", 1.0, "white", subdivisions=5)], {"white": Lambertian(0.5)})
    sun = np.array([[0.0, 0.0, 1.0], [np.sin(0.6), 0.0, np.cos(0.6)]])
    obs = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    grid = DirectRenderer(sphere, 0.002, sampling="grid").intensity(sun, obs)
    for accuracy in (0.005, 0.0005):
        adaptive = DirectRenderer(sphere, 0.004, accuracy_mag=accuracy).intensity(sun, obs)
        # The nine-point acceptance keeps each smooth cell within accuracy/3 (relative), plus
        # the limb's lattice error at 4 mm (~2e-4).
        np.testing.assert_allclose(adaptive, grid, rtol=accuracy / 1.0857 / 3.0 + 3e-4)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["topex", "cosmos2502_paper"])
def test_adaptive_matches_grid_along_real_topex_pass(model):
    if model == "topex":
        scene = topex.build()
        attitude = PrecessingSpin(period_s=9.86, precession_period_s=689.0, precession_angle_deg=35.0, spin_axis="z")
    else:
        scene = Scene.from_file(MODELS / "cosmos2502_lotos.obj", materials=MODELS / "cosmos2502_lotos.materials.json")
        attitude = PrecessingSpin(period_s=40.5, precession_period_s=1620.0, precession_angle_deg=7.0, spin_axis="x")
    body = topex_pass_geometry(attitude, frames=slice(0, 2320, 116), exposure_s=0.0)
    sun, obs = body.sun_body[:, 0], body.obs_body[:, 0]
    grid = DirectRenderer(scene, 0.006, sampling="grid").intensity(sun, obs)
    adaptive = DirectRenderer(scene, 0.006).intensity(sun, obs)
    # Same pixel size, same integral: they differ by the two samplings' edge errors at 6 mm
    # (~0.001 mag RMS each on these models) and the smooth tolerance (0.0015 at most).
    assert rms_mag(adaptive, grid) < 0.003


def test_sampling_is_checked():
    with pytest.raises(ValueError, match=r"sampling='random' is unknown; use one of 'adaptive', 'grid', 'raster'"):
        DirectRenderer(rod_over_plate(), 0.01, sampling="random")


def test_sampler_refuses_a_lattice_beyond_its_coordinates():
    scene = rod_over_plate()
    sun, obs = directions()
    with pytest.raises(ValueError, match=r"pixel_size_m=1e-07 makes more than"):
        DirectRenderer(scene, 1e-7).intensity(sun[:1], obs[:1])
