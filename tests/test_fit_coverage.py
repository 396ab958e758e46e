"""Injection-recovery coverage, reduced: truths drawn from the fit's prior, rendered and fitted
with the same model; the 16-84% intervals must hold the truth about 68% of the time.

The full study (20+ truths, the published five parameters plus jitter, the TOPEX model) is
bench/fit_coverage.py; this test keeps the cost under ~2 minutes: the analytic `lopsided`
body (no rotational symmetry, so no phase is ambiguous), four free parameters (spin period and
phase, precession phase and cone angle; precession period fixed), 10 truths.
"""

from __future__ import annotations

import numpy as np
import pytest

from ingest import read_file
from rsodb.fit.config import FitConfig
from rsodb.fit.coverage import coverage_bounds, coverage_study, window
from tests.conftest import TOPEX_PHV

N_TRUTHS = 10
CONFIG = {
    "name": "coverage",
    "model": {"shape": "lopsided", "n_sub": 1},
    "parameters": {
        "spin_period_s": {"kind": "uniform", "low": 9.76, "high": 9.96},
        "precession_period_s": 700.0,
        "jitter_mag": 0.0,
    },
    # Walkers start around the search's best point (the settled start) and move with the default
    # DE moves. Started from the search's final population instead (init "population"), walkers
    # sitting in separate local modes accepted ~2% of proposals and stayed where they started.
    "sampler": {"n_walkers": 16, "n_steps": 800, "search_popsize": 10, "search_maxiter": 60, "init": "search"},
}


@pytest.mark.slow
def test_68_percent_intervals_hold_the_truth_about_68_percent_of_the_time(tmp_path):
    template = window(read_file(TOPEX_PHV)[0], 0.0, 30.0, bin_size=4)
    recoveries = coverage_study(
        template,
        FitConfig.from_dict(CONFIG),
        range(N_TRUTHS),
        noise_mag=0.02,
        chain_dir=tmp_path,
        processes=2,
        progress=False,
    )
    covered = np.array([list(r.covered.values()) for r in recoveries])
    assert covered.shape == (N_TRUTHS, 4)
    # For a calibrated posterior each of the 40 intervals holds its truth with probability 0.68:
    # the count is binomial (truths are independent; the four intervals of one truth are not,
    # which widens the spread a little). Its 3-sigma band is 0.68 +- 3 sqrt(0.68 * 0.32 / 40),
    # i.e. 0.46-0.90; a sampler stuck in its starting ball (intervals far too narrow) or in a
    # wrong mode lands well below it.
    low, high = coverage_bounds(covered.size)
    assert low <= covered.mean() <= high, f"pooled coverage {covered.mean():.2f} outside {low:.2f}-{high:.2f}"
    # No parameter may be covered in fewer than 3 of 10 truths (P = 0.003 for p = 0.68).
    assert covered.sum(axis=0).min() >= 3, covered.sum(axis=0)


class _PhaseModel:
    """Magnitudes of a body whose light curve repeats `order` times per turn of its spin phase."""

    def __init__(self, order: int):
        self.order = order
        self.t = np.linspace(0.0, 60.0, 300)

    def magnitudes(self, values):
        angle = np.radians(values["spin_phase_deg"]) + 2 * np.pi * self.t / 40.0
        return 0.5 * np.cos(self.order * angle) + 0.2 * np.cos(self.order * 2 * angle)


@pytest.mark.parametrize(("order", "turn"), [(1, None), (2, 180.0), (3, 120.0), (4, 90.0)])
def test_look_alike_turn_is_the_bodys_symmetry(order, turn):
    from rsodb.fit.coverage import look_alike_turns

    turns = look_alike_turns(_PhaseModel(order), {"spin_phase_deg": 37.0}, ["spin_phase_deg"], 0.005)
    assert turns.get("spin_phase_deg") == turn


def test_a_posterior_at_the_look_alike_phase_covers_the_truth():
    from types import SimpleNamespace

    from rsodb.fit.coverage import _scores

    rng = np.random.default_rng(3)
    # Half the draws at the truth turned by 180 deg, half at the truth: both are the same state.
    draws = np.concatenate([190.0 + 3.0 * rng.standard_normal(2000), 10.0 + 3.0 * rng.standard_normal(2000)])
    draws = np.mod(draws, 360.0)[:, None]
    space = SimpleNamespace(free=[SimpleNamespace(name="spin_phase_deg", period=360.0, prior=SimpleNamespace(low=0.0))])
    low, mid, high = np.percentile(draws[:, 0], [16, 50, 84])
    result = SimpleNamespace(samples=draws, median=[mid], p16=[low], p84=[high])
    truth = {"spin_phase_deg": 10.0}

    median, p16, p84, covered, quantile, bias = _scores(space, result, truth, {"spin_phase_deg": 180.0})
    assert abs(median["spin_phase_deg"] - 10.0) < 0.5
    assert p84["spin_phase_deg"] - p16["spin_phase_deg"] == pytest.approx(6.0, rel=0.1)
    assert covered["spin_phase_deg"] and 0.3 < quantile["spin_phase_deg"] < 0.7 and abs(bias["spin_phase_deg"]) < 0.3

    # Scored modulo the full turn, the bimodal posterior's 16-84% interval spans half the circle.
    median, p16, p84, *_ = _scores(space, result, truth, {})
    assert p84["spin_phase_deg"] - p16["spin_phase_deg"] > 150.0


def test_look_alike_turns_of_a_fit_read_the_truth_over_the_median():
    from rsodb.fit.coverage import _values_at_truth, _wrapped, look_alike_turns
    from rsodb.fit.parameters import ParameterSpace

    config = FitConfig.from_dict(
        {"model": {"shape": "box"}, "parameters": {"spin_period_s": {"kind": "uniform", "low": 10.0, "high": 15.0}}}
    )
    space = config.parameter_space({})
    names = space.names
    assert "spin_phase_deg" in names and "spin_period_s" in names
    median = np.array([space.free[i].prior.low + 1.0 for i in range(len(names))])
    truth = {"spin_period_s": 12.5, "spin_phase_deg": 37.0}
    values = _values_at_truth(space, median, truth)
    assert values["spin_period_s"] == 12.5 and values["spin_phase_deg"] == 37.0
    other = next(n for n in names if n not in truth)
    assert values[other] == median[names.index(other)]
    assert set(space.fixed) <= set(values) and isinstance(space, ParameterSpace)
    assert _wrapped(space, truth) == ["spin_phase_deg"]
    turns = look_alike_turns(_PhaseModel(2), values, _wrapped(space, truth), 0.005)
    assert turns == {"spin_phase_deg": 180.0}


def test_cycles_fit_configuration_takes_any_callers_settings():
    """The Cycles passes are drawn from the configuration's priors before any sampler settings
    exist, and bench/fit.py passes only its own: both must make a valid configuration."""
    import argparse

    from bench.fit_coverage import PAPER_OBJ, command_line, cycles_config, forward_model_text

    bare = FitConfig.from_dict(cycles_config("x"))
    assert bare.parameter_space({}).names[:3] == ("spin_period_s", "spin_phase_deg", "precession_period_s")
    assert bare.sampler.n_steps == command_line().parse_args([]).steps == 1500
    from_fit_bench = argparse.Namespace(walkers=20, steps=500, until_converged=True, time_limit_s=60.0, n_sub=2)
    config = cycles_config("z", from_fit_bench)
    assert config["model"] == {
        "mesh": str(PAPER_OBJ),
        "materials": str(PAPER_OBJ.with_suffix(".materials.json")),
        "spin_axis": "z",
        "n_sub": 1,
    }
    parsed = FitConfig.from_dict(config)
    assert (parsed.sampler.n_walkers, parsed.sampler.n_steps, parsed.sampler.until_converged) == (20, 500, True)
    # The fit's cache settings reach the model only when asked (the default keys, and so the
    # stored caches' keys, stay as they were).
    finer = FitConfig.from_dict(cycles_config("x", command_line().parse_args(["--cache-grid-size", "96"])))
    assert (finer.model.grid_size, finer.model.accuracy_mag) == (96, 0.01)
    sharper = FitConfig.from_dict(cycles_config("x", command_line().parse_args(["--cache-accuracy-mag", "0.005"])))
    assert (sharper.model.grid_size, sharper.model.accuracy_mag) == (0, 0.005)
    smaller = FitConfig.from_dict(cycles_config("x", command_line().parse_args(["--cache-element-size-m", "0.146"])))
    assert (smaller.model.element_size_m, finer.model.element_size_m) == (0.146, 0.0)
    coarser = FitConfig.from_dict(cycles_config("x", command_line().parse_args(["--cache-normal-bins", "1"])))
    assert (coarser.model.normal_bins_per_step, finer.model.normal_bins_per_step) == (1.0, 0.0)
    assert "shading classes of 1 a normal step" in forward_model_text(
        command_line().parse_args(["--cache-normal-bins", "1"])
    )
    # So do the likelihood's model-error terms.
    plain = FitConfig.from_dict(cycles_config("x", command_line().parse_args([])))
    assert not plain.likelihood.flux_error and plain.likelihood.correlation_time_s == 0
    flux = FitConfig.from_dict(cycles_config("x", command_line().parse_args(["--flux-error"])))
    assert flux.likelihood.flux_error and flux.likelihood.correlation_time_s == 0


def test_a_cycles_record_names_its_forward_model_and_no_local_directory():
    """A coverage figure depends on the fit's cache settings, so its record says them; the passes'
    directory is this machine's, so the recorded command leaves it out."""
    from bench.fit_coverage import command_line, forward_model_text
    from bench.record import portable

    argv = [
        "--cycles",
        "--passes-dir",
        "/tmp/x",
        "--cache-element-size-m",
        "0.146",
        "--passes-dir=/tmp/y",
        "--journal-only",
        "--truths",
        "10",
    ]
    assert portable(argv) == ["--cycles", "--cache-element-size-m", "0.146", "--truths", "10"]
    assert forward_model_text(command_line().parse_args([])) == ""
    text = forward_model_text(command_line().parse_args(["--cache-element-size-m", "0.146", "--flux-error"]))
    assert text == " with surface elements up to 146 mm (`[model] element_size_m`), a model error in flux"


def test_noisy_cycles_frames_are_rendered_again_with_more_samples():
    """Glint frames whose Cycles noise stays high get a second round; quiet frames none."""
    from dataclasses import dataclass
    import types

    from bench.fit_coverage import CYCLES_NOISE_LIMIT_MAG, CYCLES_REFINE, refine_noisy_frames

    @dataclass(frozen=True)
    class Settings:
        samples: int

    # Noise falls as 1/sqrt(samples) from these frames' 16-sample values (mag).
    start = np.array([0.001, 0.004, 0.012, 0.2])
    asked = []

    def render(sun, obs, settings):
        asked.append((len(sun), settings.samples))
        frames = [int(round(v)) for v in sun[:, 0]]
        noise_mag = start[frames] * np.sqrt(16 / settings.samples)
        return types.SimpleNamespace(
            intensity_m2_sr=np.full(len(frames), 2.0), noise_rel=noise_mag / (2.5 / np.log(10))
        )

    index = np.arange(4, dtype=float)[:, None, None] * np.ones((4, 1, 3))
    body = types.SimpleNamespace(sun_body=index, obs_body=index, sunlit=np.ones((4, 1)))
    intensity, noise, refined = refine_noisy_frames(None, body, Settings(16), np.ones(4), start.copy(), render)
    # Frames 2 and 3 are above the limit at 16 and at 64 samples; 0 and 1 never are.
    assert asked == [(2, 16 * CYCLES_REFINE), (2, 16 * CYCLES_REFINE**2)]
    assert refined == {str(16 * CYCLES_REFINE): 2, str(16 * CYCLES_REFINE**2): 2}
    np.testing.assert_allclose(noise, [0.001, 0.004, 0.003, 0.05])
    np.testing.assert_array_equal(intensity, [1.0, 1.0, 2.0, 2.0])
    assert noise[3] > CYCLES_NOISE_LIMIT_MAG  # what is left is reported, not hidden


def test_correlation_time_of_an_ar1_series():
    from bench.fit_coverage import correlation_time_s

    rng = np.random.default_rng(8)
    a = np.exp(-0.2 / 3.0)  # 5 fps, a 3 s correlation time
    series = np.zeros(20000)
    for i in range(1, series.size):
        series[i] = a * series[i - 1] + rng.normal()
    assert correlation_time_s(series, 0.2) == pytest.approx(3.0, abs=0.4)
    assert correlation_time_s(rng.normal(size=5000), 0.2) == pytest.approx(0.2)
