"""Where rendering gets hard: grazing geometry, high phase, narrow glints, penumbra, degenerate
meshes and bad input. Each gives finite correct output or a clear error, over both methods."""

import math
import warnings

import numpy as np
import pytest

from raycast.renderer import methods
from raycast.renderer.brdf import GGX, Lambertian
from raycast.renderer.direct import AccuracyOutOfReach, DirectRenderer
from raycast.renderer.methods import GlintUndersampledWarning, render
from raycast.renderer.scene import Part, Scene
from tests.conftest import MODELS
from tests.render_support import METHODS, geometry, in_plane, unit


def plate(brdf=None):
    brdf = Lambertian(0.6) if brdf is None else brdf
    return Scene.from_parts([Part.plate("plate", 1.0, 1.0, "m")], {"m": brdf})


def disk_mean_cosine(elevation_deg, n=4000):
    """Mean of max(sin(elevation), 0) over the uniform 0.533 deg solar disk whose centre is
    ``elevation_deg`` above a plane: midpoint rule over the disk's height (exact to ~1e-7)."""
    radius = math.radians(0.533 / 2.0)
    y = (np.arange(n) + 0.5) / n * 2.0 - 1.0  # across the disk, in radii
    chord = np.sqrt(1.0 - y**2)
    height = np.sin(np.maximum(math.radians(elevation_deg) + radius * y, 0.0))
    return float(np.sum(chord * height) / np.sum(chord))


@pytest.mark.parametrize("method", METHODS)
def test_grazing_sun_gives_the_tiny_closed_form_value(method):
    # The Sun's centre 1, 0.1 and 0.01 deg above the plate and 0.1, 0.25 deg below it: from
    # 0.27 deg above (the disk's radius) part of the disk is below the plane and only the part
    # above lights the plate, as when Cycles samples the disk.
    incidence = np.array([89.0, 89.9, 89.99, 90.1, 90.25])
    sun, obs = in_plane(incidence, np.full(5, 20.0), azimuth_deg=90.0)
    model = render(plate(), geometry(sun, obs), method=method, pixel_size_m=0.002)
    irradiance = np.array([disk_mean_cosine(90.0 - i) for i in incidence])
    exact = 0.6 * irradiance * math.cos(math.radians(20.0)) / math.pi
    assert np.all(np.isfinite(model.intensity_m2_sr))
    # Shaded from the centroid of the disk's lit part, a flat face gets the exact mean: 1e-3
    # leaves room for rounding of the tiny values (measured within 2e-4).
    np.testing.assert_allclose(model.intensity_m2_sr, exact, rtol=1e-3)


@pytest.mark.parametrize("method", METHODS)
def test_grazing_view_of_a_glossy_plate(method):
    # Seen 85 deg from the normal the plate projects to 8.7 cm; a GGX forward glint there is
    # large per unit projected area. The automatic resolution still meets 0.01 mag.
    sun, obs = in_plane(np.array([80.0]), np.array([85.0]), azimuth_deg=180.0)
    scene = plate(GGX(0.5, 0.4))
    model = render(scene, geometry(sun, obs), method=method, accuracy_mag=0.01)
    n = np.array([[0.0, 0.0, 1.0]])
    exact = scene.brdfs[0](sun, obs, n) * sun[:, 2] * obs[:, 2]
    assert abs(2.5 * math.log10(model.intensity_m2_sr[0] / exact[0])) < 0.01


@pytest.mark.parametrize("method", METHODS)
def test_edge_on_and_back_lit_frames_are_exactly_dark(method):
    # Observer in the plate's plane (projected area 0); Sun behind a closed box from the observer.
    box = Scene.from_parts([Part.box("box", (1.0, 1.0, 1.0), "m")], {"m": Lambertian(0.6)})
    model = render(plate(), geometry(*in_plane(np.array([30.0]), np.array([90.0]))), method=method, pixel_size_m=0.01)
    # cos(90 deg) is 6e-17 in floating point: dark to rounding.
    assert 0.0 <= model.intensity_m2_sr[0] < 1e-15
    dark = render(
        box, geometry(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, -1.0]])), method=method, pixel_size_m=0.01
    )
    assert dark.intensity_m2_sr[0] == 0.0
    assert dark.mag[0] == np.inf  # documented: dark frames have infinite magnitude


@pytest.fixture(scope="module")
def sphere():
    return Scene.from_parts([Part.sphere("ball", 1.0, "white", subdivisions=6)], {"white": Lambertian(0.5)})


@pytest.mark.parametrize("method", METHODS)
def test_phase_above_150_deg(sphere, method):
    phase = np.array([160.0, 170.0, 180.0])
    sun, obs = in_plane(np.zeros(3), phase, azimuth_deg=0.0)
    model = render(sphere, geometry(sun, obs), method=method, pixel_size_m=0.004)
    a = np.radians(phase)
    exact = (2.0 / 3.0) * 0.5 * (np.sin(a) + (np.pi - a) * np.cos(a)) / np.pi
    # The crescent is 6% (160 deg) and 1.5% (170 deg) of the radius wide; the faceted limb and
    # terminator then cost 1% and 4% (measured with 81920 facets): finite and close, not exact.
    assert model.intensity_m2_sr[0] == pytest.approx(exact[0], rel=0.01)
    assert model.intensity_m2_sr[1] == pytest.approx(exact[1], rel=0.04)
    # At 180 deg the limb seen from the observer is lit only by the part of the 0.53 deg solar
    # disk that rises above it, at grazing incidence and exit: dark to rounding (1e-22 in the fast
    # path), not necessarily exactly zero.
    assert 0.0 <= model.intensity_m2_sr[2] < 1e-15


def test_undersampled_glint_warns_with_the_fix():
    scene = plate(GGX(0.3, 0.1))  # alpha = 0.01 rad: a 0.6 deg glint
    t = np.linspace(-0.1, 0.1, 4)  # four sub-samples of a 0.2 s exposure at 36 deg/s
    angle = np.radians(20.0 + 36.0 * t)
    sun = np.stack([np.sin(angle), 0 * angle, np.cos(angle)], axis=-1)[None]
    obs = np.stack([-np.sin(np.radians(20.0)) + 0 * angle, 0 * angle, np.cos(np.radians(20.0)) + 0 * angle], axis=-1)[
        None
    ]
    with pytest.warns(
        GlintUndersampledWarning,
        match=r"glint of material 'm' is 0\.57 deg wide; compute the geometry with n_sub >= \d+",
    ):
        render(scene, geometry(sun, obs), method="cached")
    fine = np.linspace(-0.1, 0.1, 40)
    angle = np.radians(20.0 + 36.0 * fine)
    sun = np.stack([np.sin(angle), 0 * angle, np.cos(angle)], axis=-1)[None]
    obs = np.repeat(obs[:, :1], 40, axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", GlintUndersampledWarning)
        render(scene, geometry(sun, obs), method="cached")


@pytest.mark.parametrize("method", METHODS)
def test_penumbra_scales_and_umbra_skips(method):
    sun, obs = in_plane(np.array([30.0, 30.0, 30.0]), np.array([40.0, 40.0, 40.0]), azimuth_deg=150.0)
    model = render(plate(), geometry(sun, obs, sunlit=[[1.0], [0.37], [0.0]]), method=method, pixel_size_m=0.004)
    full = model.intensity_m2_sr[0]
    # Exact for the cache; the direct renderer shifts each frame's pixel grid, so the two frames
    # differ by the plate's pixel edge error (< 0.1% at 4 mm).
    assert model.intensity_m2_sr[1] == pytest.approx(0.37 * full, rel=1e-3)
    assert model.intensity_m2_sr[2] == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
def test_flipped_normals_and_open_meshes(method):
    box = Part.box("box", (1.0, 2.0, 3.0), "m")
    corners = box.corners_m.copy()
    corners[::3] = corners[::3, ::-1]  # reverse the winding of every third triangle
    flipped = Scene.from_arrays(
        corners, np.full_like(corners, np.nan), np.zeros(12, int), {"m": Lambertian(0.5)}, ["m"]
    )
    good = Scene.from_parts([box], {"m": Lambertian(0.5)})
    open_box = Scene.from_arrays(
        box.corners_m[2:], box.corner_normals[2:], np.zeros(10, int), {"m": Lambertian(0.5)}, ["m"]
    )  # the +x face removed: looking inside
    rng = np.random.default_rng(8)
    sun, obs = unit(rng.normal(size=(6, 3))), unit(rng.normal(size=(6, 3)))
    sun[:, 0], obs[:, 0] = np.abs(sun[:, 0]), np.abs(obs[:, 0])  # lit and seen through the opening
    kwargs = dict(method=method, pixel_size_m=0.005)
    reference = render(good, geometry(sun, obs), **kwargs).intensity_m2_sr
    # Surfaces are two-sided: reversed windings change nothing (pixel edge error < 0.1%).
    np.testing.assert_allclose(render(flipped, geometry(sun, obs), **kwargs).intensity_m2_sr, reference, rtol=1e-3)
    inside = render(open_box, geometry(sun, obs), **kwargs).intensity_m2_sr
    assert np.all(np.isfinite(inside)) and np.all(inside >= 0.0) and inside.max() > 0.05


def test_open_box_inner_walls_cache_equals_direct():
    box = Part.box("box", (1.0, 2.0, 3.0), "m")
    open_box = Scene.from_arrays(
        box.corners_m[2:], box.corner_normals[2:], np.zeros(10, int), {"m": Lambertian(0.5)}, ["m"]
    )
    rng = np.random.default_rng(8)
    sun, obs = unit(rng.normal(size=(6, 3)) + [2, 0, 0]), unit(rng.normal(size=(6, 3)) + [2, 0, 0])
    direct = render(open_box, geometry(sun, obs), method="direct", pixel_size_m=0.005).intensity_m2_sr
    cached = render(open_box, geometry(sun, obs), method="cached").intensity_m2_sr
    # Inner walls shadow each other; the cache's interpolated visibility moves shadow edges by a
    # fraction of an element, which costs at most 1% of the brightest frame's light here.
    assert np.abs(cached - direct).max() < 0.01 * direct.max()


def test_overlapping_faces_are_refused_with_the_fix():
    with pytest.raises(ValueError, match="pass repair=True to keep one face of each set as a two-sided surface"):
        Scene.from_file(MODELS / "plate_1m.obj")


@pytest.mark.parametrize(
    "bad, message",
    [
        (dict(sun=np.array([[0.0, 0.0, 2.0]])), "sun_body must hold finite unit vectors"),
        (dict(sun=np.array([[np.nan, 0.0, 1.0]])), "sun_body must hold finite unit vectors"),
        (dict(weights=np.array([0.5])), r"weights has shape \(1,\) and sum 0.5"),
        (dict(sunlit=np.array([[1.5]])), r"sunlit has shape \(1, 1\); expected \(1, 1\) fractions in \[0, 1\]"),
    ],
)
def test_bad_geometry_messages(bad, message):
    g = geometry(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]]))
    if "sun" in bad:
        g.sun_body = bad["sun"][:, None, :]
    if "weights" in bad:
        g.weights = bad["weights"]
    if "sunlit" in bad:
        g.sunlit = bad["sunlit"]
    with pytest.raises(ValueError, match=message):
        render(plate(), g, method="direct", pixel_size_m=0.01)


def test_unknown_method_and_geometry_type():
    g = geometry(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]]))
    with pytest.raises(ValueError, match="method='fast' is unknown"):
        render(plate(), g, method="fast")
    with pytest.raises(TypeError, match="geometry lacks 'sun_body'"):
        render(plate(), object())


def test_accuracy_out_of_reach_is_a_clear_error():
    # A glossy smooth cylinder's glint line at 1e-4 mag needs rays far finer than allowed.
    scene = Scene.from_parts([Part.cylinder("tube", 1.0, 4.0, "gloss", segments=16)], {"gloss": GGX(0.5, 0.05)})
    sun = unit(np.array([[1.0, 0.2, 0.1]]))
    obs = unit(np.array([[0.3, 1.0, 0.1]]))
    with pytest.raises(
        ValueError,
        match=r"accuracy_mag=0.0001 is out of reach for .* within max_pixels_per_frame=200000: "
        r"at [0-9.e-]+ m pixels two successive pixel sizes still differ by [0-9.e-]+ mag .*relax "
        r"accuracy_mag to at least [0-9.e-]+, raise max_pixels_per_frame to at least [0-9]+ for one "
        r"more halving, or give pixel_size_m directly",
    ):
        DirectRenderer.from_accuracy(scene, sun, obs, accuracy_mag=1e-4, max_pixels_per_frame=200_000)


def test_auto_falls_back_to_the_cache_when_the_direct_accuracy_is_out_of_reach(monkeypatch):
    def out_of_reach(*arguments):
        raise AccuracyOutOfReach("accuracy_mag=0.005 is out of reach for plate")

    plate = Scene.from_parts([Part.box("plate", (1.0, 1.0, 0.01), "m")], {"m": Lambertian(0.5)})
    sun = obs = unit(np.array([[0.0, 0.2, 1.0], [0.1, 0.0, 1.0]]))
    monkeypatch.setitem(methods.METHODS, "direct", out_of_reach)
    with pytest.warns(RuntimeWarning, match="out of reach for plate; rendering with the cached method instead"):
        model = render(plate, geometry(sun, obs))  # 2 directions: "auto" picks direct first
    assert model.method == "cached" and np.all(model.intensity_m2_sr > 0.0)
    with pytest.raises(AccuracyOutOfReach):
        render(plate, geometry(sun, obs), method="direct")  # asked for by name: the error stands
