"""Exposure sub-samples chosen by what the model's own curve needs (rsodb.fit.subsampling).

Authority: the 2 deg rule's curve (`choose_n_sub`, the geometry's safe default) on the real
Uzhhorod photomultiplier pass of COSMOS 2553 (1 s exposures), and exact arithmetic.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ingest import read_file
from raycast.geometry.pass_geometry import choose_n_sub
from rsodb.fit.config import FitConfig
from rsodb.fit.runner import FitProblem
from rsodb.fit.subsampling import SUB_SAMPLE_DRAWS, magnitude_change, sub_samples_needed
from tests.conftest import COSMOS2553_PHC

TOLERANCE_MAG = 0.02


def test_the_change_leaves_out_each_draws_offset_and_its_dark_samples():
    before = np.array([[1.0, 2.0, 3.0, np.inf], [0.0, 0.0, 0.0, 0.0]])
    after = np.array([[1.5, 2.5, 3.8, 5.0], [7.0, 7.0, 7.0, 7.0]])
    # First draw: changes 0.5, 0.5, 0.8 (the dark sample left out), mean 0.6 removed; the second
    # draw moved by a constant, which an offset absorbs.
    assert magnitude_change(before, after) == pytest.approx(math.sqrt(0.06 / 7))
    assert magnitude_change(before[:1], after[:1]) == pytest.approx(math.sqrt(0.02))
    assert magnitude_change(np.full((1, 3), np.inf), np.zeros((1, 3))) == 0.0


def test_doubling_stops_at_the_limit_when_the_curve_never_settles():
    asked = []

    def curves_at(count):
        asked.append(count)
        return np.array([[0.0, float(count), 0.0, -float(count)]])

    assert sub_samples_needed(curves_at, 6, 0.01) == (6, 0.0)
    assert asked == [1, 2, 4, 6]
    asked.clear()
    assert sub_samples_needed(curves_at, 1, 0.01) == (1, 0.0) and asked == [1]
    with pytest.raises(ValueError, match="tolerance"):
        sub_samples_needed(curves_at, 4, 0.0)


@pytest.fixture(scope="module")
def uzhhorod_v(shared_data):
    (observed,) = [p for p in read_file(COSMOS2553_PHC) if p.band == "V"]
    assert observed.exposure_s == pytest.approx(1.0)
    return observed


def problem(observed, shape, period_s, **model):
    record = {
        "name": "sub",
        "model": {"shape": shape, "attitude": "inertial", **model},
        "data": {"duration_s": 40.0},
        "parameters": {"spin_period_s": {"kind": "uniform", "low": period_s, "high": 1.02 * period_s}},
    }
    return FitProblem.build(observed, FitConfig.from_dict(record))


@pytest.mark.parametrize(("shape", "period_s"), [("ellipsoid", 9.6), ("box_panels", 4.8)])
def test_the_measured_count_is_as_good_as_the_2_deg_rule_at_a_fraction_of_its_cost(uzhhorod_v, shape, period_s):
    measured = problem(uzhhorod_v, shape, period_s, sub_tolerance_mag=TOLERANCE_MAG)
    count = measured.posterior.model.geometry.n_sub
    rule = choose_n_sub(uzhhorod_v.exposure_s, period_s)
    assert rule == math.ceil(360 / period_s / 2)  # 19 and 38 sub-samples of a 1 s exposure
    reference = problem(uzhhorod_v, shape, period_s, n_sub=rule)
    space = measured.posterior.space
    thetas = space.sample_prior(np.random.default_rng(1), SUB_SAMPLE_DRAWS)
    curves = [np.array([p.posterior.magnitudes(t) for t in thetas]) for p in (measured, reference)]
    # Other draws than the measurement's, against the rule's own count: within twice the tolerance.
    assert magnitude_change(*curves) < 2 * TOLERANCE_MAG
    # The stored fit says what was chosen, and the pass-wide curves use the same turn per sub-sample.
    assert f"{count} exposure sub-samples" in measured.sub_samples
    assert measured.curve_n_sub() == count
    if shape == "ellipsoid":
        # A smooth convex body's curve: a few low harmonics, a few sub-samples.
        assert count <= 4 < rule
    else:
        # A flat glossy wing glints for a few degrees of a 75 deg turn: it needs many.
        assert 8 <= count < rule
        one = problem(uzhhorod_v, shape, period_s, n_sub=1)
        curves_one = np.array([one.posterior.magnitudes(t) for t in thetas])
        assert magnitude_change(curves_one, curves[1]) > 5 * TOLERANCE_MAG


def test_a_tolerance_and_a_fixed_count_together_are_refused():
    with pytest.raises(ValueError, match="keep one"):
        FitConfig.from_dict({"model": {"n_sub": 2, "sub_tolerance_mag": 0.02}})
    with pytest.raises(ValueError, match="sub_tolerance_mag"):
        FitConfig.from_dict({"model": {"sub_tolerance_mag": -0.1}})


def test_a_slow_smooth_body_keeps_one_sub_sample_and_says_so(uzhhorod_v):
    # 1 s exposures of a 100 s spin turn the body 3.6 deg: the 2 deg rule would take 2 renders.
    measured = problem(uzhhorod_v, "ellipsoid", 100.0, sub_tolerance_mag=TOLERANCE_MAG)
    assert choose_n_sub(uzhhorod_v.exposure_s, 100.0) == 2
    assert measured.posterior.model.geometry.n_sub == 1
    assert measured.sub_samples.startswith("1 exposure sub-sample (3.6 deg of turn each: 0.00")
