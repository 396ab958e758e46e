"""Joint fits of several passes (`rsodb.fit.joint`): the joint posterior is the sum of the
passes' own, its parameters map onto each pass's exactly, the period trend stays inside every
pass's prior, and the command fits, resumes and draws."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from ingest import read_file
from rsodb.archive import Archive
from rsodb.cli import main
from rsodb.fit.config import FitConfig
from rsodb.fit.coverage import inject, window
from rsodb.fit.joint import TREND, JointProblem, joint_space
from rsodb.fit.parameters import Parameter, ParameterSpace, describe
from rsodb.fit.priors import Uniform
from rsodb.fit.runner import FitProblem
from tests.conftest import TOPEX_PHV

FIT = {
    "name": "joint",
    "model": {"shape": "ellipsoid", "attitude": "inertial", "n_sub": 1},
    "parameters": {"spin_period_s": {"kind": "uniform", "low": 9.5, "high": 10.2}},
    "sampler": {"n_walkers": 16, "n_steps": 60, "search_maxiter": 6, "search_popsize": 5, "seed": 1},
}
TRUTH = {"spin_period_s": 9.86, "spin_phase_deg": 100.0, "pole_ra_deg": 40.0, "pole_dec_deg": 30.0}


@pytest.fixture(scope="module")
def two_windows(tmp_path_factory):
    """Two 30 s windows of the TOPEX pass, 300 s apart, with the ellipsoid's inertial spin injected."""
    observed = read_file(TOPEX_PHV)[0]
    config = FitConfig.from_dict(FIT)
    passes = []
    for k, start_s in enumerate((0.0, 300.0)):
        template = window(observed, start_s, 30.0, bin_size=4)
        model = FitProblem.build(template, config).posterior.model
        passes.append(inject(template, model, TRUTH, noise_mag=0.02, rng=np.random.default_rng(k)))
    archive = Archive(tmp_path_factory.mktemp("joint") / "archive")
    archive.add(passes)
    return archive, [row.pass_id for row in archive.summaries(22076)]


def test_per_pass_names_describe_their_pass():
    known = describe("spin_phase_deg@2")
    assert known.label == "phi@2" and known.period == 360.0 and known.description.endswith("of pass 2")
    with pytest.raises(ValueError, match="unknown parameter 'spin_phase_deg@0'"):
        describe("spin_phase_deg@0")
    assert describe(TREND).unit == "s/day"


def test_the_trend_keeps_every_pass_inside_its_period_prior():
    def space(low, high):
        return ParameterSpace((Parameter("spin_period_s", Uniform(low, high)), Parameter.default("spin_phase_deg")))

    joint = joint_space([space(9.8, 10.2), space(10.3, 10.7)], [0.0, 10.0], trend=True)
    assert joint.names == ("spin_period_s", TREND, "spin_phase_deg@1", "spin_phase_deg@2")
    rate = joint.free[1].prior
    assert (rate.low, rate.high) == pytest.approx(((10.3 - 10.2) / 10, (10.7 - 9.8) / 10))
    # Simultaneous passes (two bands of one pass): no trend to fit.
    assert TREND not in joint_space([space(9.8, 10.2), space(9.9, 10.3)], [0.0, 0.0], trend=True).names
    with pytest.raises(ValueError, match="do not overlap"):
        joint_space([space(9.8, 10.2), space(10.3, 10.7)], [0.0, 10.0], trend=False)
    with pytest.raises(ValueError, match="one configuration"):
        joint_space([space(9.8, 10.2), ParameterSpace((Parameter("spin_period_s", Uniform(9, 11)),))], [0, 1], True)


def test_the_joint_posterior_is_the_sum_of_the_passes(two_windows):
    archive, ids = two_windows
    observed = [archive.get(p) for p in ids]
    config = FitConfig.from_dict(FIT)
    problem = JointProblem.build(observed, config, trend=True)
    posterior = problem.posterior
    assert posterior.space.names == (
        "spin_period_s",
        TREND,
        "spin_phase_deg@1",
        "spin_phase_deg@2",
        "pole_ra_deg",
        "pole_dec_deg",
        "jitter_mag@1",
        "jitter_mag@2",
    )
    days = posterior.days[1]
    assert days == pytest.approx(300.0 / 86400.0, rel=1e-3)
    singles = [FitProblem.build(o, config).posterior for o in observed]
    rng = np.random.default_rng(5)
    checked = 0
    for theta in posterior.space.sample_prior(rng, 40):
        values = posterior.space.values(theta)
        period_2 = values["spin_period_s"] + values[TREND] * days
        own = [posterior.pass_theta(theta, k) for k in range(2)]
        assert own[1][0] == pytest.approx(period_2)  # the trend moves pass 2's period
        assert own[1][1] == values["spin_phase_deg@2"] and own[0][2] == values["pole_ra_deg"]
        if not 9.5 <= period_2 <= 10.2:
            assert posterior(theta) == -math.inf  # outside pass 2's own prior
            continue
        # ln p = joint prior + pass 2's period prior (uniform over 0.7 s) + both log-likelihoods.
        log_likes = [single(theta_k) - single.space.log_prior(theta_k) for single, theta_k in zip(singles, own)]
        expected = posterior.space.log_prior(theta) + math.log(1 / 0.7) + sum(log_likes)
        assert posterior(theta) == pytest.approx(expected, rel=1e-12, abs=1e-9)
        checked += 1
    assert checked >= 5


def test_one_pass_joint_posterior_equals_its_own(two_windows):
    archive, ids = two_windows
    observed = archive.get(ids[0])
    config = FitConfig.from_dict(FIT)
    joint = JointProblem.build([observed], config).posterior
    single = FitProblem.build(observed, config).posterior
    for theta in joint.space.sample_prior(np.random.default_rng(2), 10):
        assert joint(theta) == pytest.approx(single(joint.pass_theta(theta, 0)), rel=1e-12)


def test_joint_fits_refuse_what_cannot_be_shared(two_windows):
    archive, ids = two_windows
    observed = [archive.get(p) for p in ids]
    torque_free = FitConfig.from_dict(dict(FIT, model={"shape": "ellipsoid", "attitude": "torque_free", "n_sub": 1}))
    with pytest.raises(ValueError, match="cannot be shared between passes"):
        JointProblem.build(observed, torque_free)
    with pytest.raises(ValueError, match="a pass is given twice"):
        JointProblem.build([observed[0], observed[0]], FitConfig.from_dict(FIT))
    assert main(["fit-joint", ids[0], "--archive", str(archive.path)]) == 2


@pytest.mark.slow
def test_the_command_fits_resumes_and_draws(two_windows, tmp_path, capsys):
    archive, ids = two_windows
    config = tmp_path / "joint.toml"
    config.write_text(
        'name = "joint"\n[model]\nshape = "ellipsoid"\nattitude = "inertial"\nn_sub = 1\n'
        '[parameters]\nspin_period_s = { kind = "uniform", low = 9.5, high = 10.2 }\n'
        "[sampler]\nn_walkers = 16\nn_steps = 60\nsearch_maxiter = 6\nsearch_popsize = 5\nseed = 1\n"
    )
    args = ["fit-joint", *ids, "--archive", str(archive.path), "--config", str(config), "--no-trend"]
    assert main([*args, "--json", "--plot", str(tmp_path / "joint.png")]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["trend"] is False and TREND not in record["parameters"]
    assert [item["pass_id"] for item in record["passes"]] == ids
    # The best sample of a 60-step chain already follows both windows (noise 0.02 mag; the
    # magnitudes scatter by 0.3-0.4 mag about their mean; measured 0.033 and 0.099 mag).
    for item, pass_id in zip(record["passes"], ids):
        mag = archive.get(pass_id).mag
        assert item["rms_mag"] < min(0.15, 0.5 * np.std(mag)) and item["n_window"] > 30
    assert (tmp_path / "joint.png").stat().st_size > 10_000
    assert (archive.path / "joint").is_dir()
    # The same command again continues the stored chain (nothing left to run at 60 steps).
    assert main([*args, "--steps", "80", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "16 walkers x 80 steps" in out and "one spin period" in out
