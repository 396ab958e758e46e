"""The glint map's geometry: body directions about a spin axis, and the directions the model's
surfaces face (exact for the flat faces of the TOPEX model built from its published sizes)."""

from __future__ import annotations

import numpy as np
import pytest

from raycast.models import topex
from rsodb.fit.conventions import azimuth_elevation
from rsodb.fit.plots import _surface_directions


@pytest.mark.parametrize(
    "vector, axis, expected",
    [
        ((1.0, 0.0, 0.0), 2, (0.0, 0.0)),
        ((0.0, 2.0, 2.0), 2, (90.0, 45.0)),
        ((-1.0, -1.0, -np.sqrt(2.0)), 2, (225.0, -45.0)),
        # About body x the azimuth counts from +y toward +z (cyclic order), as bisector_azimuth does.
        ((0.0, 0.0, 1.0), 0, (90.0, 0.0)),
        ((1.0, 0.0, 0.0), 0, (0.0, 90.0)),
        # A direction as the axis: body z tilted 30 deg toward +x; the body z axis then lies 60 deg
        # above that axis's equator.
        ((0.0, 0.0, 1.0), (0.5, 0.0, np.sqrt(3.0) / 2.0), (180.0, 60.0)),
    ],
)
def test_azimuth_elevation_of_known_directions(vector, axis, expected):
    azimuth, elevation = azimuth_elevation(np.array([vector]), axis)
    assert azimuth[0] % 360.0 == pytest.approx(expected[0] % 360.0, abs=1e-9)
    assert elevation[0] == pytest.approx(expected[1], abs=1e-9)


def _area_at(cells, azimuth, elevation, tolerance_deg=1.5):
    az, el, area = cells
    near = (np.abs((az - azimuth + 180.0) % 360.0 - 180.0) <= tolerance_deg) & (np.abs(el - elevation) <= tolerance_deg)
    return float(area[near].sum())


@pytest.mark.parametrize("pitch_deg", [12.0, -14.0])
def test_topex_surfaces_face_where_the_model_says(pitch_deg):
    scene = topex.build(panel_pitch_deg=pitch_deg)
    cells = _surface_directions(scene, {"panel_pitch_deg": pitch_deg}, 2)
    areas = topex.BUS_FACE_AREAS_M2
    # The bus's +x face (a y-z face) and its +y face (an x-z face), in the spin equator.
    assert _area_at(cells["bus"], 0.0, 0.0) == pytest.approx(areas["yz"], rel=1e-6)
    assert _area_at(cells["bus"], 90.0, 0.0) == pytest.approx(areas["xz"], rel=1e-6)
    # The cells face +x turned about +y by the pitch: their normal (cos p, 0, -sin p) stands
    # at elevation -p, and the whole array's area is there.
    length, width = topex.ARRAY_SIZE_M
    assert _area_at(cells["solar_cells"], 0.0, -pitch_deg) == pytest.approx(length * width, rel=1e-6)
    assert _area_at(cells["solar_cells"], 0.0, pitch_deg) == 0.0


def test_the_louvered_topex_puts_its_louvers_and_nadir_face_where_its_docs_say():
    scene = topex.build(louvers=True)
    cells = _surface_directions(scene, {}, 2)
    side = topex.LOUVER_SIZE_M**2
    # One louver per side wall, its normal leaning LOUVER_OPEN_DEG toward +z at the wall's azimuth.
    for azimuth in (0.0, 90.0, 180.0, 270.0):
        assert _area_at(cells["louvers"], azimuth, topex.LOUVER_OPEN_DEG) == pytest.approx(side, rel=1e-6)
    assert cells["louvers"][2].sum() == pytest.approx(4 * side, rel=1e-6)
    assert _area_at(cells["nadir"], 0.0, 90.0, tolerance_deg=1.0) == pytest.approx(
        topex.BUS_FACE_AREAS_M2["xy"], rel=1e-6
    )
    assert _area_at(cells["bus"], 0.0, 90.0, tolerance_deg=1.0) == 0.0
    # The plain model is unchanged: no louvers, the nadir face is bus.
    plain = _surface_directions(topex.build(), {}, 2)
    assert "louvers" not in plain and "nadir" not in plain


def test_louvered_surfaces_share_the_bus_finish_and_check_their_ranges():
    brdfs = topex.louvered_surface_brdfs(nadir_albedo=0.7, bus_metallic=0.6, bus_roughness=0.3, louver_reflectance=0.2)
    assert (brdfs["nadir"].base_color, brdfs["nadir"].metallic, brdfs["nadir"].roughness) == (0.7, 0.6, 0.3)
    assert brdfs["louvers"].color == 0.2
    assert brdfs["louvers"].roughness == topex.LOUVERED_SURFACE_PARAMETERS["louver_roughness"].default
    assert brdfs["bus"].metallic == 0.6
    with pytest.raises(ValueError, match=r"louver_reflectance=1\.5 is outside its range \[0\.0, 1\.0\]"):
        topex.louvered_surface_brdfs(louver_reflectance=1.5)
    with pytest.raises(ValueError, match="unknown TOPEX surface parameter"):
        topex.surface_brdfs(nadir_albedo=0.5)
