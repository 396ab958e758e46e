"""bench/convex_bound.py's free convex body: at the true attitude, facets along a convex body's
own normals reproduce its light curve exactly, and a wrong pole leaves a misfit."""

from __future__ import annotations

from pathlib import Path
import sys

import numpy as np
import pytest

from ingest import read_file
from rsodb.fit.curves import geometry_at
from rsodb.fit.model import ConvexFacets, SpinStateModel
from tests.conftest import TOPEX_PHV

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def test_a_convex_bodys_own_facets_fit_its_curve_and_a_wrong_pole_does_not():
    from bench.convex_bound import ConvexBound, fibonacci_sphere

    observed = read_file(TOPEX_PHV)[0]
    box = ConvexFacets(ConvexFacets.box().normals, [2.0, 1.0, 0.5, 1.5, 0.3, 0.8], 0.3)
    truth = {"spin_period_s": 9.5, "spin_phase_deg": 40.0, "pole_ra_deg": 147.0, "pole_dec_deg": -59.0}
    geometry = geometry_at(observed, observed.time_utc, observed.exposure_s, 1, None)
    mags = SpinStateModel(geometry, box, "inertial").magnitudes(truth)
    synthetic = observed.replace(mag_corrected=mags)
    bound = ConvexBound(synthetic, "inertial", box.normals)
    everything = bound.usable
    assert bound.rms(truth, everything, everything) < 1e-6
    design = bound.design(truth)
    # The Lambertian columns take the box's own areas x albedo times one photometric factor (the
    # magnitudes' zero point), the lobes none; the -z face is never lit and seen on this pass,
    # so nothing sets its area.
    areas = bound.fit_areas(design, everything)
    shown = design[:, :6].max(axis=0) > 0
    assert list(shown) == [True] * 5 + [False]
    ratio = areas[:5] / (box.areas_m2 * box.albedo)[:5]
    assert ratio == pytest.approx(np.full(5, ratio[0]), rel=1e-6)
    assert np.all(areas[6:] < 1e-9 * areas[:6].max())
    # Held out: areas fitted on the first 70% predict the rest exactly at the true attitude.
    cut = np.arange(len(observed)) < int(0.7 * len(observed))
    assert bound.rms(truth, everything & cut, everything & ~cut) < 1e-6
    # A pole 40 deg away cannot be made up by the areas.
    assert bound.rms(truth | {"pole_dec_deg": -19.0}, everything, everything) > 0.1
    assert fibonacci_sphere(100).shape == (100, 3)
    assert np.allclose(np.linalg.norm(fibonacci_sphere(7), axis=1), 1.0)


def test_the_torque_free_search_starts_from_the_same_motion_as_the_inertial_best():
    from bench.convex_bound import CLIP_MAG, ConvexBound, as_torque_free, fibonacci_sphere

    observed = read_file(TOPEX_PHV)[0]
    facets = fibonacci_sphere(30)
    inertial, tumbling = ConvexBound(observed, "inertial", facets), ConvexBound(observed, "torque_free", facets)
    values = {"spin_period_s": 9.49, "spin_phase_deg": 75.0, "pole_ra_deg": 139.0, "pole_dec_deg": -65.0}
    everything = inertial.usable
    same = as_torque_free(values)
    assert tumbling.rms(same, everything, everything) == pytest.approx(
        inertial.rms(values, everything, everything), abs=1e-9
    )
    # The frames themselves agree, not only the fitted residual.
    body_i = inertial.geometry.body_frame(inertial.model.attitude_model(values))
    body_t = tumbling.geometry.body_frame(tumbling.model.attitude_model(same))
    assert np.abs(body_i.sun_body - body_t.sun_body).max() < 1e-9
    # Tilting the angular velocity off the principal axis is another motion: another fit.
    wobbling = same | {"omega_polar_deg": 20.0}
    assert abs(tumbling.rms(wobbling, everything, everything) - tumbling.rms(same, everything, everything)) > 0.01
    # Moments no rigid body has (one larger than the other two together) are refused.
    assert tumbling.rms(same | {"inertia_ratio_3": 4.0}, everything, everything) == CLIP_MAG


def test_areas_refitted_at_a_found_attitude_score_each_part_as_the_search_did():
    from bench.convex_bound import ConvexBound, fibonacci_sphere, refitted

    observed = read_file(TOPEX_PHV)[0]
    coarse, fine = (
        ConvexBound(observed, "inertial", fibonacci_sphere(20)),
        ConvexBound(observed, "inertial", fibonacci_sphere(80)),
    )
    everything = coarse.usable
    cut = np.arange(len(observed)) < int(0.7 * len(observed))
    train, held = everything & cut, everything & ~cut
    found = {
        "whole": {"spin_period_s": 9.49, "spin_phase_deg": 75.0, "pole_ra_deg": 139.0, "pole_dec_deg": -65.0},
        "train": {"spin_period_s": 9.50, "spin_phase_deg": 10.0, "pole_ra_deg": 200.0, "pole_dec_deg": -40.0},
    }
    same = refitted(coarse, found, everything, train, held)
    assert same["whole_rms"] == pytest.approx(coarse.rms(found["whole"], everything, everything), abs=1e-12)
    assert same["train_rms"] == pytest.approx(coarse.rms(found["train"], train, train), abs=1e-12)
    # Held out: the training part's attitude and areas, scored on the rest.
    assert same["heldout_rms"] == pytest.approx(coarse.rms(found["train"], train, held), abs=1e-12)
    assert same["heldout_rms"] != pytest.approx(coarse.rms(found["whole"], train, held), abs=1e-3)
    # Four times the facets fit the same pass at the same attitude more closely.
    finer = refitted(fine, found, everything, train, held)
    assert finer["whole_rms"] < same["whole_rms"] - 0.02
    # Without a held-out part only the whole pass is scored.
    assert set(refitted(coarse, found, everything)) == {"whole_rms", "whole"}


def test_a_ridge_damps_the_areas_and_costs_fit():
    from bench.convex_bound import ConvexBound, fibonacci_sphere

    observed = read_file(TOPEX_PHV)[0]
    values = {"spin_period_s": 9.49, "spin_phase_deg": 75.0, "pole_ra_deg": 139.0, "pole_dec_deg": -65.0}
    plain, damped = (ConvexBound(observed, "inertial", fibonacci_sphere(40), ridge=r) for r in (0.0, 0.1))
    everything = plain.usable
    design = plain.design(values)
    free, shrunk = plain.fit_areas(design, everything), damped.fit_areas(design, everything)
    assert np.all(shrunk >= 0.0)
    assert np.linalg.norm(shrunk) < 0.9 * np.linalg.norm(free)
    assert damped.rms(values, everything, everything) > plain.rms(values, everything, everything) + 0.01
