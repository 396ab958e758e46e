"""Any mesh can be fitted: a mesh file in the fit configuration, its shape cache kept on disk by
content and reused, articulations, and the published workflow's mesh read from its own file.

Authority for the mesh path: a box written as an OBJ renders as the analytic Lambertian box
(`ConvexFacets.box`, I/E = sum A rho / pi cos i cos e over the faces): a convex body has no
shadows, so the cache is exact on it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ingest import read_file
from raycast.models.box_panels import BUS_SIZE_M
from rsodb.fit import shape_store
from rsodb.fit.config import FitConfig
from rsodb.fit.coverage import window
from rsodb.fit.runner import FitProblem
from rsodb.fit.shape_store import ShapeStore
from rsodb.fit.shapes import mesh_shape
from tests.conftest import MODELS, PROJECT_ROOT, TOPEX_PHV, sun_and_observer_at_pass_phases

BOX_FACES = [(1, 2, 3, 4), (5, 8, 7, 6), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 8, 4), (4, 8, 5, 1)]


def write_box(directory, name="box", size_m=BUS_SIZE_M, albedo=0.2):
    """A box (by default the analytic box shape's) as OBJ + materials JSON, outward faces."""
    x, y, z = (s / 2.0 for s in size_m)
    corners = [(-x, -y, -z), (x, -y, -z), (x, y, -z), (-x, y, -z)]
    corners += [(cx, cy, z) for cx, cy, _ in corners]
    lines = ["o body", "usemtl paint"] + [f"v {x} {y} {z}" for x, y, z in corners]
    # Faces wound counter-clockwise seen from outside (bottom face seen from below, etc.).
    lines += ["f 1 4 3 2", "f 5 6 7 8", "f 1 2 6 5", "f 2 3 7 6", "f 3 4 8 7", "f 4 1 5 8"]
    obj = directory / f"{name}.obj"
    obj.write_text("\n".join(lines) + "\n")
    materials = directory / f"{name}.materials.json"
    materials.write_text(json.dumps({"materials": {"paint": {"blender_node": "Diffuse BSDF", "color": [albedo] * 3}}}))
    return obj, materials


@pytest.fixture(scope="module")
def template():
    return window(read_file(TOPEX_PHV)[0], 0.0, 20.0, bin_size=4)


PRIOR = {"spin_period_s": {"kind": "uniform", "low": 9.5, "high": 10.2}, "jitter_mag": 0.0}
VALUES = {
    "spin_period_s": 9.86,
    "spin_phase_deg": 20.0,
    "precession_period_s": 700.0,
    "precession_phase_deg": 50.0,
    "precession_angle_deg": 30.0,
}


def test_a_box_mesh_file_fits_as_the_analytic_box(tmp_path, template):
    obj, materials = write_box(tmp_path)
    record = {"model": {"mesh": str(obj), "materials": str(materials), "n_sub": 1}, "parameters": PRIOR}
    store = ShapeStore(tmp_path / "shapes")
    mesh_problem = FitProblem.build(template, FitConfig.from_dict(record), store=store)
    box = FitProblem.build(template, FitConfig.from_dict({"model": {"shape": "box", "n_sub": 1}, "parameters": PRIOR}))
    assert mesh_problem.shape == "mesh:box.obj"
    mesh_mag = mesh_problem.posterior.model.magnitudes(VALUES)
    box_mag = box.posterior.model.magnitudes(VALUES)
    # Exact in both up to float32 sums in the cache: 1e-4 mag.
    np.testing.assert_allclose(mesh_mag, box_mag, atol=1e-4)
    assert len(list((tmp_path / "shapes").glob("*.pkl"))) == 1


def test_the_cache_grid_follows_the_length_of_the_fit(tmp_path, template):
    # A fit planning >= 2e6 frame-evaluations (walkers x steps x frames) gets a 64-node grid, a
    # shorter fit the renderer's 32; [model] grid_size overrides both; each grid is its own
    # stored cache.
    obj, materials = write_box(tmp_path)
    store = ShapeStore(tmp_path / "shapes")

    def grid_of(model, n_steps):
        record = {
            "model": {"mesh": str(obj), "materials": str(materials), "n_sub": 1, **model},
            "parameters": PRIOR,
            "sampler": {"n_walkers": 10, "n_steps": n_steps},
        }
        problem = FitProblem.build(template, FitConfig.from_dict(record), store=store)
        return problem.posterior.model.n, problem.posterior.model.brightness.grid_size

    frames, short = grid_of({}, 10)
    steps_64 = -(-2_000_000 // (10 * frames))  # the fewest steps reaching 2e6
    grids = [grid_of({}, steps)[1] for steps in (steps_64 - 1, steps_64)]
    assert (short, *grids) == (32, 32, 64)
    assert grid_of({"grid_size": 16}, steps_64)[1] == 16
    assert len(list((tmp_path / "shapes").glob("*.pkl"))) == 3


def cache_settings_checker(tmp_path, template, obj, materials):
    """``cache_of(model)``: the cache a fit of the box mesh with these [model] settings gets,
    all stored in one shape store (tmp_path / "shapes")."""
    store = ShapeStore(tmp_path / "shapes")

    def cache_of(model):
        # A coarse direction grid: the 0.02 m cut at the fit's own grid (32) takes 100 s to build.
        model = {"mesh": str(obj), "materials": str(materials), "n_sub": 1, "grid_size": 8, **model}
        problem = FitProblem.build(template, FitConfig.from_dict({"model": model, "parameters": PRIOR}), store=store)
        return problem.posterior.model.brightness

    return cache_of


def test_the_element_size_reaches_the_cache_and_its_key(tmp_path, template):
    # [model] element_size_m sets the cache's largest element (a finer cut: more elements) and is
    # part of the stored cache's key; 0 keeps the renderer's default and the default key.
    obj, materials = write_box(tmp_path)
    # A plate above the box shades its top, so the top is cut into elements (a convex body's
    # sides are all exposed and never cut).
    plate = ["o plate", "usemtl paint", "v -0.5 -0.5 1.5", "v 0.5 -0.5 1.5", "v 0.5 0.5 1.5", "v -0.5 0.5 1.5"]
    obj.write_text(obj.read_text() + "\n".join(plate + ["f 9 10 11 12"]) + "\n")
    cache_of = cache_settings_checker(tmp_path, template, obj, materials)
    default, same, finer = cache_of({}), cache_of({"element_size_m": 0.0}), cache_of({"element_size_m": 0.02})
    assert same is default
    assert finer.element_size_m == 0.02 and default.element_size_m > 0.04
    assert finer.n_elements > default.n_elements
    assert len(list((tmp_path / "shapes").glob("*.pkl"))) == 2


def test_the_normal_bins_reach_the_cache_and_its_key(tmp_path, template):
    # [model] normal_bins_per_step sets the cache's shading classes per normal step (1: fewer
    # classes) and is part of the stored cache's key; 0 keeps the renderer's default and key.
    obj, materials = write_box(tmp_path)
    cache_of = cache_settings_checker(tmp_path, template, obj, materials)
    default, same, coarse = cache_of({}), cache_of({"normal_bins_per_step": 0}), cache_of({"normal_bins_per_step": 1})
    assert same is default
    assert (default.normal_bins_per_step, coarse.normal_bins_per_step) == (3.0, 1.0)
    assert len(list((tmp_path / "shapes").glob("*.pkl"))) == 2


def test_the_stored_cache_is_reused_and_keyed_by_content(tmp_path, template, monkeypatch):
    obj, materials = write_box(tmp_path)
    record = {"model": {"mesh": str(obj), "materials": str(materials), "n_sub": 1}, "parameters": PRIOR}
    store = ShapeStore(tmp_path / "shapes")
    FitProblem.build(template, FitConfig.from_dict(record), store=store)
    shape_store._MEMORY.clear()  # as in a new process (a campaign worker)

    def no_build(*args, **kwargs):
        raise AssertionError("the cache was built again")

    monkeypatch.setattr("rsodb.fit.shapes._build_cache", no_build)
    # The same content under another file name: the stored cache, not a new build.
    copy = tmp_path / "copy"
    copy.mkdir()
    other_obj, other_materials = write_box(copy, name="renamed")
    renamed = {"model": {"mesh": str(other_obj), "materials": str(other_materials), "n_sub": 1}, "parameters": PRIOR}
    FitProblem.build(template, FitConfig.from_dict(renamed), store=ShapeStore(tmp_path / "shapes"))
    # Other content (a longer box): another key.
    longer_obj, longer_materials = write_box(copy, name="longer", size_m=(2.0, 1.0, 1.0))
    scene = mesh_shape(obj, materials).build()
    longer = mesh_shape(longer_obj, longer_materials).build()
    assert store.key(scene, {}) != store.key(longer, {}) and store.key(scene, {}) == store.key(scene, {})


def test_articulations_of_a_mesh_are_parameters(tmp_path, template):
    obj, materials = write_box(tmp_path)
    text = (
        obj.read_text() + "o flap\nusemtl paint\nv 0.5 -0.5 1\nv 1.5 -0.5 1\nv 1.5 0.5 1\nv 0.5 0.5 1\nf 9 10 11 12\n"
    )
    obj.write_text(text)
    articulation = {"parameter": "flap_deg", "part": "flap", "axis": [0, 1, 0], "point_m": [0.5, 0, 1], "rest_deg": 0}
    record = {
        # The direct renderer: no articulation grid of caches to build for a test of the wiring.
        "model": {
            "mesh": str(obj),
            "materials": str(materials),
            "articulations": [articulation],
            "n_sub": 1,
            "renderer": "direct",
        },
        "parameters": dict(PRIOR, flap_deg={"kind": "uniform", "low": -30.0, "high": 30.0}),
    }
    problem = FitProblem.build(template, FitConfig.from_dict(record))
    assert "flap_deg" in problem.posterior.space.names
    flat = problem.posterior.model.magnitudes(dict(VALUES, flap_deg=0.0))
    tilted = problem.posterior.model.magnitudes(dict(VALUES, flap_deg=25.0))
    # Samples where no lit face is seen are infinitely faint in both; elsewhere the flap turns
    # and the light curve changes.
    seen = np.isfinite(flat) & np.isfinite(tilted)
    assert seen.sum() > 10 and np.max(np.abs(flat - tilted)[seen]) > 0.01


def test_bad_mesh_configuration_names_the_file(tmp_path, template):
    record = {"model": {"mesh": str(tmp_path / "missing.obj")}, "parameters": PRIOR}
    with pytest.raises(FileNotFoundError, match=r"\[model\] mesh = '.*missing\.obj' does not exist"):
        FitProblem.build(template, FitConfig.from_dict(record))
    with pytest.raises(ValueError, match=r"parameter 'flap' must be a name ending in _deg"):
        FitConfig.from_dict(
            {"model": {"mesh": "x.obj", "articulations": [{"parameter": "flap", "part": "p", "axis": [0, 0, 1]}]}}
        )


def test_the_paper_mesh_is_fitted_from_its_own_file(shared_data):
    config = FitConfig.from_toml(PROJECT_ROOT / "configs" / "cosmos2502_paper.toml")
    # The configuration's relative paths resolve to ../shared/data, the file itself.
    assert config.model.mesh == str((MODELS / "cosmos2502_lotos.obj").resolve())
    assert config.model.materials == str((MODELS / "cosmos2502_lotos.materials.json").resolve())
    assert config.model.spin_axis == "x"
    scene = mesh_shape(config.model.mesh, config.model.materials).build()
    assert scene.n_triangles == 2184 and "spb_2" in scene.material_names
    assert not list(PROJECT_ROOT.rglob("cosmos2502_lotos.obj"))  # never copied into the repository


def test_topex_surface_classes_are_fit_parameters(template):
    # Freed in the configuration, a surface class takes the model's own prior range
    # (raycast.models.topex.SURFACE_PARAMETERS); the others stay fixed at their defaults.
    from raycast.models import topex
    from rsodb.fit.shapes import SurfaceClasses

    record = {
        "model": {"shape": "topex", "attitude": "precessing", "n_sub": 1},
        "parameters": dict(PRIOR, bus_metallic={}, bus_roughness={"kind": "uniform", "low": 0.2, "high": 0.6}),
    }
    problem = FitProblem.build(template, FitConfig.from_dict(record))
    space = problem.posterior.space
    assert {"bus_metallic", "bus_roughness"} <= set(space.names)
    priors = {p.name: p.prior.bounds for p in space.free}
    assert priors["bus_metallic"] == (0.0, 1.0) and priors["bus_roughness"] == (0.2, 0.6)
    assert space.fixed["cells_specular"] == topex.SURFACE_PARAMETERS["cells_specular"].default == 0.5
    model = problem.posterior.model
    assert isinstance(model.brightness, SurfaceClasses)
    values = dict(space.fixed, **VALUES)
    diffuse = model.magnitudes(dict(values, bus_metallic=0.0, bus_roughness=0.35))
    metal = model.magnitudes(dict(values, bus_metallic=1.0, bus_roughness=0.35))
    lit = np.isfinite(diffuse) & np.isfinite(metal)
    assert lit.sum() > 3 and np.max(np.abs(diffuse - metal)[lit]) > 0.1
    # Outside the model's range the body does not exist (zero posterior), not an exception.
    assert np.all(np.isinf(model.magnitudes(dict(values, bus_metallic=1.5, bus_roughness=0.3))))


def test_the_surface_cache_renders_other_surfaces_as_the_direct_renderer():
    # One cache, built for the smoothest bus the prior allows, serves every surface value: at
    # two settings far apart it agrees with the direct (reference) renderer of the model built
    # with those values.
    from raycast.models import topex
    from raycast.renderer.direct import DirectRenderer
    from rsodb.fit.shapes import SHAPES, brightness_for

    free = {"bus_metallic": (0.0, 1.0), "bus_roughness": (0.1, 0.8), "cells_roughness": (0.05, 0.5)}
    cached, names = brightness_for(SHAPES["topex"], free, {"panel_pitch_deg": 12.0}, accuracy_mag=0.01)
    sun, obs = sun_and_observer_at_pass_phases(np.random.default_rng(3), 10)
    for values in ({"bus_metallic": 0.9, "bus_roughness": 0.2, "cells_roughness": 0.08}, {}):
        direct = DirectRenderer(topex.build(**values), 0.05).intensity(sun, obs)
        surfaces = dict(topex.SURFACE_PARAMETERS.items())
        every = {name: values.get(name, spec.default) for name, spec in surfaces.items() if name in free}
        fast = cached.intensity(sun, obs, panel_pitch_deg=12.0, **every)
        error_mag = -2.5 * np.log10(fast / direct)
        # Measured: 0.012 mag RMS for the shiny bus, 0.005 at the defaults.
        assert np.sqrt(np.mean(error_mag**2)) < 0.02, (values, error_mag)
    assert names == ("panel_pitch_deg", "cells_roughness", "bus_metallic", "bus_roughness")


def test_surface_parameters_and_material_scalars_do_not_mix():
    from rsodb.fit.shapes import SHAPES, brightness_for

    with pytest.raises(ValueError, match=r"either the material scalars \['albedo_scale'\] or its surface parameters"):
        brightness_for(SHAPES["topex"], {"albedo_scale": (0.5, 2.0)}, {"bus_metallic": 0.0}, name="topex")
