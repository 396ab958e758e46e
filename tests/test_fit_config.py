"""Fit configuration (TOML): the documented example parses, defaults, priors, error messages,
and the `rsodb fit` command on a synthetic archive."""

from __future__ import annotations

import json
import pickle
import re

import numpy as np
import pytest

from rsodb.fit.config import FitConfig
from rsodb.fit.priors import BoundedNormal, Uniform
from tests.conftest import PROJECT_ROOT


class FakePeriods:
    """Stands in for a stored PeriodResult: its verdict and `prior_interval_s` are used."""

    best_period_s = 9.86
    has_period = True
    pass_id = "fake"

    def prior_interval_s(self, width_frac=0.01, frame="sidereal", force=False):
        return 9.86 * (1 - width_frac), 9.86 * (1 + width_frac)


def documented_example() -> str:
    text = (PROJECT_ROOT / "docs" / "fitting.md").read_text()
    start = text.index("```toml\n", text.index("<!-- fit-config-example -->")) + len("```toml\n")
    return text[start : text.index("\n```", start)]


def test_the_documented_example_parses_to_what_it_says(tmp_path):
    path = tmp_path / "fit.toml"
    path.write_text(documented_example())
    config = FitConfig.from_toml(path)
    assert config.discard == 250 and config.sampler.n_walkers == 20 and config.model.shape == "auto"
    space = config.parameter_space({"panel_pitch_deg": 12.0}, FakePeriods())
    assert space.names == (
        "spin_period_s",
        "spin_phase_deg",
        "precession_period_s",
        "precession_phase_deg",
        "precession_angle_deg",
        "jitter_mag",
    )
    assert space.fixed == {"panel_pitch_deg": 12.0}
    priors = dict(zip(space.names, (p.prior for p in space.free)))
    assert priors["precession_angle_deg"] == BoundedNormal(35.0, 10.0, 0.0, 90.0)
    assert priors["spin_period_s"] == Uniform(9.86 * 0.99, 9.86 * 1.01)
    assert priors["jitter_mag"] == Uniform(0.0, 0.5)


def test_defaults_and_overrides():
    config = FitConfig()
    space = config.parameter_space({}, FakePeriods())
    assert len(space.names) == 6 and not space.fixed
    narrowed = FitConfig.from_dict(
        {
            "parameters": {
                "spin_period_s": {"from": "periods", "width": 0.05, "multiple": 2},
                "jitter_mag": 0.0,
                "precession_angle_deg": 35.0,
            }
        }
    )
    space = narrowed.parameter_space({}, FakePeriods())
    low, high = space.free[space.names.index("spin_period_s")].prior.bounds
    np.testing.assert_allclose([low, high], [2 * 9.86 * 0.95, 2 * 9.86 * 1.05], rtol=1e-14)
    assert space.fixed == {"jitter_mag": 0.0, "precession_angle_deg": 35.0}
    # normalised likelihood: no jitter parameter by default
    assert (
        "jitter_mag"
        not in FitConfig.from_dict({"likelihood": {"kind": "normalised"}}).parameter_space({}, FakePeriods()).names
    )
    assert pickle.loads(pickle.dumps(narrowed)).to_dict() == narrowed.to_dict()
    assert config.replace(sampler={"n_steps": 7}).sampler.n_steps == 7 and config.sampler.n_steps == 500
    # A correlated model error adds its amplitude as a free parameter (prior 0-0.05 mag).
    assert "model_error_mag" not in space.names + tuple(space.fixed)
    correlated = FitConfig.from_dict({"likelihood": {"correlation_time_s": 2.5}})
    error = correlated.parameter_space({}, FakePeriods()).free[-1]
    assert error.name == "model_error_mag" and error.prior.bounds == (0.0, 0.05)
    # So does the model's flux error (a fraction of its brightest sample, prior 0-0.02).
    assert "model_flux_error" not in space.names + tuple(space.fixed)
    flux = FitConfig.from_dict({"likelihood": {"flux_error": True}})
    error = flux.parameter_space({}, FakePeriods()).free[-1]
    assert error.name == "model_flux_error" and error.prior.bounds == (0.0, 0.02)
    assert FitConfig.from_dict(flux.to_dict()).likelihood.flux_error is True


@pytest.mark.parametrize(
    "record, message",
    [
        ({"modle": {}}, r"fit configuration \[top level\] has unknown keys \['modle'\]"),
        (
            {"model": {"shape": "sphere"}},
            r"\[model\] shape='sphere' is not auto or one of topex, topex_louvered, cosmos2502, box, box_panels, ellipsoid, lopsided",
        ),
        (
            {"model": {"attitude": "wobble"}},
            r"\[model\] attitude='wobble' is not one of precessing, inertial, inertial_tilted, torque_free",
        ),
        (
            {"likelihood": {"correlation_time_s": -2}},
            r"\[likelihood\] correlation_time_s=-2 must be seconds >= 0 \(0: no correlated model error\)",
        ),
        (
            {"likelihood": {"kind": "normalised", "correlation_time_s": 2}},
            r"\[likelihood\] correlation_time_s needs kind = 'gaussian', not 'normalised'",
        ),
        ({"likelihood": {"flux_error": "yes"}}, r"\[likelihood\] flux_error='yes' must be true or false"),
        (
            {"likelihood": {"kind": "normalised", "flux_error": True}},
            r"\[likelihood\] flux_error needs kind = 'gaussian', not 'normalised'",
        ),
        ({"data": {"stride": 2}}, r"\[data\] stride is gone: a fixed stride strobes a periodic light curve"),
        ({"data": {"windows": -1}}, r"\[data\] windows=-1 must be 0 \(chosen\) or a whole number >= 1"),
        ({"model": {"materials": "x.json"}}, r"materials and articulations describe a mesh file: give mesh = PATH"),
        ({"model": {"shape": "topex", "mesh": "x.obj"}}, r"gives both shape='topex' and mesh='x.obj'; keep one"),
        (
            {"model": {"grid_size": 2}},
            r"\[model\] grid_size=2 must be 0 \(chosen from the fit's planned work\) or a whole number 4..256",
        ),
        (
            {"model": {"element_size_m": -0.1}},
            r"\[model\] element_size_m=-0.1 must be 0 \(the renderer's default\) or a size in metres",
        ),
        ({"model": {"element_size_m": "fine"}}, r"\[model\] element_size_m='fine' must be 0"),
        # TOML's true is a Python int: a boolean where a number belongs is a mistake, not 1
        ({"model": {"element_size_m": True}}, r"\[model\] element_size_m=True must be 0"),
        ({"model": {"n_sub": True}}, r"\[model\] n_sub=True must be a whole number 0..64"),
        # half a bin per normal step would smear a glint (0.026 mag on the all-Glossy mesh)
        ({"model": {"normal_bins_per_step": 0.5}}, r"\[model\] normal_bins_per_step=0.5 must be 0 \(the renderer's"),
        ({"model": {"normal_bins_per_step": True}}, r"\[model\] normal_bins_per_step=True must be 0"),
        ({"model": {"normal_bins_per_step": float("inf")}}, r"\[model\] normal_bins_per_step=inf must be 0"),
        ({"data": {"max_points": True}}, r"\[data\] max_points=True must be 0 \(no limit\)"),
        ({"data": {"duration_s": False}}, r"\[data\] duration_s=False must be a number >= 0"),
        ({"likelihood": {"correlation_time_s": True}}, r"\[likelihood\] correlation_time_s=True must be seconds"),
        ({"sampler": {"n_walker": 4}}, r"\[sampler\] has unknown keys \['n_walker'\]"),
        ({"sampler": {"time_limit_s": True}}, r"sampler setting time_limit_s=True must be seconds >= 0"),
        ({"sampler": {"seed": False}}, r"sampler setting seed=False must be a non-negative integer"),
        ({"sampler": {"processes": True}}, r"sampler setting processes=True must be 0 \(all cores\)"),
        ({"parameters": {"spin_rate": 1.0}}, r"\[parameters\] unknown parameter 'spin_rate'; known parameters"),
        (
            {"parameters": {"precession_angle_deg": {"kind": "uniform", "low": 0}}},
            r"prior of precession_angle_deg: uniform needs high",
        ),
        (
            {"parameters": {"spin_phase_deg": {"kind": "uniform", "low": 0, "high": 90}}},
            r"spin_phase_deg wraps every 360 deg but its prior covers \[0, 90\]",
        ),
        ({"parameters": {"jitter_mag": {"from": "periods"}}}, r"only spin_period_s can take its prior from"),
    ],
)
def test_configuration_errors_name_the_bad_value(record, message):
    with pytest.raises(ValueError, match=message):
        FitConfig.from_dict(record)


def test_file_errors_and_missing_period(tmp_path):
    with pytest.raises(FileNotFoundError, match="fit configuration .*nope.toml does not exist"):
        FitConfig.from_toml(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[model\nshape = 1")
    with pytest.raises(ValueError, match=re.escape(f"{bad}: not valid TOML")):
        FitConfig.from_toml(bad)
    with pytest.raises(
        ValueError,
        match="takes its prior from the stored period but the pass has none; run 'rsodb periods' on it first",
    ):
        FitConfig().parameter_space({})


def test_fit_command_fits_a_stored_pass_and_prints_json(tmp_path, capsys):
    from ingest import read_file
    from rsodb.archive import Archive
    from rsodb.cli import main
    from rsodb.fit.coverage import inject, window
    from rsodb.fit.runner import FitProblem
    from tests.conftest import TOPEX_PHV

    template = window(read_file(TOPEX_PHV)[0], 0.0, 20.0, bin_size=4)
    record = {
        "model": {"shape": "ellipsoid", "n_sub": 1},
        "parameters": {"spin_period_s": {"kind": "uniform", "low": 9.5, "high": 10.2}},
        "sampler": {"n_walkers": 12, "n_steps": 30, "search_maxiter": 5, "search_popsize": 5},
    }
    model = FitProblem.build(template, FitConfig.from_dict(record)).posterior.model
    truth = {
        "spin_period_s": 9.86,
        "spin_phase_deg": 100.0,
        "precession_period_s": 700.0,
        "precession_phase_deg": 180.0,
        "precession_angle_deg": 35.0,
    }
    archive = Archive(tmp_path / "archive")
    archive.add([inject(template, model, truth, noise_mag=0.02, rng=np.random.default_rng(1))])
    pass_id = archive.passes()[0].pass_id
    toml = tmp_path / "fit.toml"
    toml.write_text(
        '[model]\nshape = "ellipsoid"\nn_sub = 1\n[parameters]\n'
        'spin_period_s = { kind = "uniform", low = 9.5, high = 10.2 }\n'
        "[sampler]\nn_walkers = 12\nsearch_maxiter = 5\nsearch_popsize = 5\n"
    )
    status = main(
        [
            "fit",
            pass_id[:14],
            "--archive",
            str(archive.path),
            "--config",
            str(toml),
            "--steps",
            "30",
            "--name",
            "cli",
            "--json",
            "--plots",
            str(tmp_path / "plots"),
        ]
    )
    out = json.loads(capsys.readouterr().out)
    assert status == 0 and out["pass_id"] == pass_id and out["n_steps"] == 30 and out["name"] == "cli"
    assert set(out["parameters"]) == {
        "spin_period_s",
        "spin_phase_deg",
        "precession_period_s",
        "precession_phase_deg",
        "precession_angle_deg",
        "jitter_mag",
    }
    assert archive.result_names(pass_id, "fits") == ["cli"]
    assert sorted(out["plots"]) == ["corner", "lightcurve", "trace"]

    # Without a stored period the default prior cannot be built: a one-line error, status 2.
    assert main(["fit", pass_id, "--archive", str(archive.path), "--steps", "5"]) == 2
    assert "rsodb fit: error: spin_period_s takes its prior from the stored period" in capsys.readouterr().err
    # An absurd step count is refused before any work, not met as an overflow mid-run.
    assert main(["fit", pass_id, "--archive", str(archive.path), "--steps", str(10**20)]) == 2
    assert "n_steps=100000000000000000000 must be a whole number from 1 to 1e+09" in capsys.readouterr().err


def test_a_weak_stored_period_names_the_force_flag_and_the_flag_works():
    """Every fix an error suggests is a real flag: a weak stored period says --force, and
    `rsodb fit --force` sets force = true on the period prior."""
    import argparse

    from rsodb.cli import build_parser
    from rsodb.cli.fit import config_from_args

    class WeakPeriods(FakePeriods):
        has_period = False
        verdict = "too short"
        reason = "2.1 cycles over the pass"
        label = "fake"

        def prior_interval_s(self, width_frac=0.01, frame="sidereal", force=False):
            assert force, "the prior of a weak period is asked for only with force"
            return super().prior_interval_s(width_frac, frame)

    with pytest.raises(ValueError, match=r"verdict 'too short' .* use that period anyway with --force"):
        FitConfig().parameter_space({}, WeakPeriods())
    parser = build_parser()
    args = parser.parse_args(["fit", "22076", "--archive", "a", "--force"])
    assert isinstance(args, argparse.Namespace) and args.force
    space = config_from_args(args).parameter_space({}, WeakPeriods())
    low, high = space.bounds[space.names.index("spin_period_s")]
    assert (low, high) == pytest.approx((9.86 * 0.99, 9.86 * 1.01))


def test_force_with_a_fit_that_gives_its_own_spin_period_prior_says_so(tmp_path):
    from rsodb.cli import build_parser
    from rsodb.cli.fit import config_from_args

    own = tmp_path / "own.toml"
    own.write_text('[parameters]\nspin_period_s = { kind = "uniform", low = 9.0, high = 11.0 }\n')
    args = build_parser().parse_args(["fit", "22076", "--archive", "a", "--force", "--config", str(own)])
    with pytest.raises(ValueError, match="--force lets a weak stored period set the spin-period prior, but this fit"):
        config_from_args(args)
