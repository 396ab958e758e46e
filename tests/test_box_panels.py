"""The ladder's generic shapes: the analytic box and ellipsoid repeat every half turn (as the
ladder's period prior assumes), and the box with panels (`raycast.models.box_panels`) renders as
the analytic box plus its wings.

Authorities: exact Lambertian sums (I = sum A rho / pi cos i cos e over unshadowed faces) at
geometries where nothing is shadowed, and the direct renderer for the cached one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from raycast.models import box_panels
from raycast.renderer.direct import DirectRenderer
from rsodb.campaign.ladder import HALF_TURN_SYMMETRIC
from rsodb.fit.shapes import SHAPES, brightness_for
from tests.conftest import sun_and_observer_at_pass_phases
from tests.render_support import rms_mag


def _about_z(vector, angles_rad):
    """`vector` seen from a body turned by each angle about +z (the fits' spin axis)."""
    c, s = np.cos(-angles_rad), np.sin(-angles_rad)
    x, y, z = vector
    return np.column_stack([c * x - s * y, s * x + c * y, np.full_like(angles_rad, z)])


def _turn_geometry():
    sun = np.array([0.6, 0.2, 0.5])
    obs = np.array([0.1, 0.7, 0.4])
    angles = np.deg2rad(np.arange(0.0, 360.0, 1.0))
    return _about_z(sun / np.linalg.norm(sun), angles), _about_z(obs / np.linalg.norm(obs), angles)


@pytest.mark.parametrize("name", sorted(HALF_TURN_SYMMETRIC))
def test_half_turn_symmetric_shapes_repeat_every_half_turn_and_not_every_quarter(name):
    # The ladder doubles these shapes' period prior; a body that repeated every quarter turn (a
    # square box about its long axis) would make its light curve at twice the data's frequency.
    body = SHAPES[name].build()
    sun, obs = _turn_geometry()
    light = body.intensity(sun, obs)
    half = np.max(np.abs(light - np.roll(light, 180))) / light.max()
    quarter = np.max(np.abs(light - np.roll(light, 90))) / light.max()
    assert half < 1e-12
    assert quarter > 0.05


def test_the_box_with_panels_repeats_only_after_a_whole_turn():
    # Cells on one side of the wings: not half-turn symmetric, so the ladder keeps its period prior.
    assert "box_panels" not in HALF_TURN_SYMMETRIC
    sun, obs = _turn_geometry()
    light = DirectRenderer(box_panels.build(), 0.05).intensity(sun, obs)
    assert np.max(np.abs(light - np.roll(light, 180))) / light.max() > 0.3


def test_seen_from_behind_the_wings_it_is_the_box_plus_the_wings_backs():
    # Sun and observer both on -x: every face turned to them is lit, seen and unshadowed, at
    # normal incidence: I = (A_bus_face bus_albedo + A_backs back_albedo) / pi.
    bus_albedo, back_albedo = 0.3, 0.6
    scene = box_panels.build(bus_albedo=bus_albedo, back_albedo=back_albedo)
    minus_x = np.array([[-1.0, 0.0, 0.0]])
    light = DirectRenderer(scene, 0.05).intensity(minus_x, minus_x)
    x_m, y_m, z_m = box_panels.BUS_SIZE_M
    span, width = box_panels.WING_SIZE_M
    expected = (y_m * z_m * bus_albedo + 2 * span * width * back_albedo) / math.pi
    # The direct renderer rasterises at 5 cm pixels: measured 0.13% off.
    assert light[0] == pytest.approx(expected, rel=0.01)
    # The analytic box rung's box is the bus: the same face of it alone.
    box = SHAPES["box"].build()
    assert box.intensity(minus_x, minus_x)[0] == pytest.approx(y_m * z_m * 0.2 / math.pi, rel=1e-9)


def test_the_bus_shades_the_far_wing_as_its_shadow_says():
    # Pitched 90 deg, the wings lie flat (backs facing +z) beside the bus, whose top stands 0.35 m
    # above them. Sun low from +y (tan elevation 0.15), observer overhead: the bus's shadow
    # covers the -y wing from its inner edge to 0.335 / 0.15 m beyond the bus's -y face; every
    # lit face seen is Lambertian: I = sum A rho / pi cos i over the unshadowed parts, exactly.
    back_albedo, bus_albedo = 0.8, 0.4
    scene = box_panels.build(panel_pitch_deg=90.0, back_albedo=back_albedo, bus_albedo=bus_albedo)
    sun = np.array([[0.0, 1.0, 0.15]]) / math.hypot(1.0, 0.15)
    overhead = np.array([[0.0, 0.0, 1.0]])
    light = DirectRenderer(scene, 0.02).intensity(sun, overhead)[0]
    x_m, y_m, z_m = box_panels.BUS_SIZE_M
    span, width = box_panels.WING_SIZE_M
    back_top = box_panels.WING_THICKNESS_M / 2.0
    shadow_end = y_m / 2.0 + (z_m / 2.0 - back_top) / 0.15
    shaded = (shadow_end - (y_m / 2.0 + box_panels.WING_GAP_M)) / span
    cos_i = sun[0, 2]
    wing = span * width * back_albedo / math.pi * cos_i
    bus_top = x_m * y_m * bus_albedo / math.pi * cos_i
    assert 0.7 < shaded < 0.8
    assert light == pytest.approx(bus_top + wing * (2.0 - shaded), rel=0.01)


def test_the_cache_of_the_box_with_panels_renders_other_surfaces_as_the_direct_renderer():
    free = {"cells_roughness": (0.05, 0.5), "bus_albedo": (0.02, 0.9), "back_albedo": (0.05, 0.8)}
    cached, names = brightness_for(SHAPES["box_panels"], free, {"panel_pitch_deg": 0.0}, accuracy_mag=0.01)
    assert names == ("panel_pitch_deg", "cells_roughness", "bus_albedo", "back_albedo")
    sun, obs = sun_and_observer_at_pass_phases(np.random.default_rng(5), 40)
    for values in ({"cells_roughness": 0.08, "bus_albedo": 0.1, "back_albedo": 0.7}, {}):
        # 2 cm pixels: at 5 cm the reference itself is 0.018 mag RMS off on the narrow glints.
        direct = DirectRenderer(box_panels.build(**values), 0.02).intensity(sun, obs)
        surfaces = {name: values.get(name, box_panels.SURFACE_PARAMETERS[name].default) for name in free}
        fast = cached.intensity(sun, obs, panel_pitch_deg=0.0, **surfaces)
        # Measured: 0.0046 mag RMS (max 0.016) with glossy cells, 0.0045 (0.013) at the defaults.
        assert rms_mag(fast, direct, dark_fraction=1e-4) < 0.01, values


def test_surface_parameters_outside_their_range_name_the_model():
    with pytest.raises(ValueError, match=r"box_panels surface parameter bus_albedo=1.5 is outside its range"):
        box_panels.build(bus_albedo=1.5)
    with pytest.raises(ValueError, match=r"unknown box_panels surface parameter\(s\) \['gloss'\]"):
        box_panels.surface_brdfs(gloss=0.2)


def test_a_stored_fit_replays_after_its_model_reorders_its_surface_parameters(tmp_path, monkeypatch):
    # A fit's parameters are stored in the order its model listed them; a later version of the
    # model that lists the same parameters in another order must still replay the fit, by name.
    from dataclasses import replace

    from rsodb.archive import Archive
    from rsodb.cli import main
    from rsodb.fit import predict_fit, shapes
    from rsodb.fit.config import FitConfig
    from rsodb.fit.runner import FitProblem
    from tests.conftest import COSMOS2553_JD_PHV

    archive = Archive(tmp_path / "archive", create=True)
    archive.ingest([COSMOS2553_JD_PHV], progress=False)
    (summary,) = archive.passes(norad=51511)
    config = tmp_path / "tiny.toml"
    config.write_text(
        """name = "tiny"
band_draws = 5
[model]
shape = "box_panels"
attitude = "inertial"
n_sub = 1
[data]
duration_s = 20.0
[parameters]
spin_period_s = { kind = "uniform", low = 4.8, high = 4.9 }
cells_roughness = {}
back_albedo = {}
jitter_mag = { kind = "uniform", low = 0.0, high = 1.0 }
[sampler]
n_walkers = 16
n_steps = 4
init = "prior"
"""
    )
    archive_dir = str(archive.path)
    assert main(["fit", summary.pass_id, "--archive", archive_dir, "--config", str(config), "--quiet"]) == 0
    before = predict_fit(archive, summary.pass_id, "tiny", draws=3)
    stored = before.result.names
    assert stored.index("cells_roughness") < stored.index("back_albedo")

    shape = shapes.SHAPES["box_panels"]
    reordered = dict(reversed(list(shape.surfaces.items())))
    monkeypatch.setattr(shapes, "SHAPES", {**shapes.SHAPES, "box_panels": replace(shape, surfaces=reordered)})
    record = {key: value for key, value in before.result.config.items() if key != "shape"}
    rebuilt = FitProblem.build(archive.get(summary.pass_id), FitConfig.from_dict(record)).posterior.space.names
    assert rebuilt != stored and set(rebuilt) == set(stored)
    after = predict_fit(archive, summary.pass_id, "tiny", draws=3)
    np.testing.assert_allclose(after.samples.mag_model, before.samples.mag_model, atol=1e-9)
