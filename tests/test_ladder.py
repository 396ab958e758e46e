"""The model ladder: rung configurations, the choice by held-out RMS, the configuration file's
errors, the command line, and (slow) a ladder on an injected pass whose true shape is known."""

from __future__ import annotations

from dataclasses import replace
import json

import numpy as np
import pytest

from ingest import read_file
from rsodb.archive import Archive
from rsodb.campaign.ladder import (
    LadderPlan,
    LadderResult,
    LadderSettings,
    NaiveForecast,
    Rung,
    RungScore,
    choose_rung,
    naive_forecast,
    run_ladder,
    score_ladder,
    seasonal_naive,
)
from rsodb.cli import main
from rsodb.fit.config import FitConfig
from rsodb.fit.coverage import inject, window
from rsodb.fit.runner import FitProblem
from rsodb.report.ladder_report import build_ladder_report, scores_table
from tests.conftest import PROJECT_ROOT, TOPEX_PHV

PLAN = {
    "ladder": {
        "name": "lad",
        "train_fraction": 0.7,
        "rungs": [{"shape": "ellipsoid", "attitude": "inertial"}, {"shape": "box", "attitude": "inertial"}],
    },
    "fit": {
        "model": {"n_sub": 1},
        "parameters": {"spin_period_s": {"kind": "uniform", "low": 9.7, "high": 10.0}},
        "sampler": {"n_walkers": 12, "n_steps": 60, "search_maxiter": 15, "search_popsize": 8, "seed": 2},
    },
    "objects": {"22076": {"rungs": [{"shape": "ellipsoid", "attitude": "precessing"}]}},
}


def _score(rung: str, n_parameters: int, rms: float) -> RungScore:
    shape, attitude = rung.split("-")
    return RungScore(rung, shape, attitude, f"lad.{rung}", "ok", n_parameters, rms, rms, n_heldout=200)


def test_symmetric_shapes_double_the_period_prior_and_fit_the_first_part():
    base = FitConfig.from_dict({"parameters": {"spin_period_s": {"from": "periods", "width": 0.03}}})
    ellipsoid = Rung("ellipsoid", "precessing").config(base, "lad", 120.0)
    topex = Rung("topex", "precessing").config(base, "lad", 120.0)
    # The ellipsoid looks the same after half a turn: its spin period is twice the light curve's.
    assert ellipsoid.parameters["spin_period_s"]["multiple"] == 2.0
    assert topex.parameters["spin_period_s"].get("multiple", 1.0) == 1.0
    assert ellipsoid.name == "lad.ellipsoid-precessing" and ellipsoid.model.shape == "ellipsoid"
    assert (ellipsoid.data.start_s, ellipsoid.data.duration_s) == (0.0, 120.0)
    assert topex.parameters["spin_period_s"]["width"] == 0.03


def test_a_rung_frees_surface_parameters_with_walkers_and_time_to_match():
    base = FitConfig.from_dict({"sampler": {"n_walkers": 16, "time_limit_s": 240}})
    record = {
        "shape": "topex",
        "attitude": "inertial",
        "parameters": {name: {} for name in ("bus_albedo", "bus_metallic", "bus_roughness")},
        "sampler": {"time_limit_s": 900},
    }
    rung = Rung.from_dict(record).config(base, "lad", 120.0)
    # 4 attitude parameters, 3 surface parameters and the jitter: more than twice 8 walkers.
    assert rung.sampler.n_walkers == 18 and rung.sampler.time_limit_s == 900
    assert rung.parameters["bus_metallic"] == {}
    plain = Rung("topex", "inertial").config(base, "lad", 120.0)
    assert plain.sampler.n_walkers == 16 and plain.sampler.time_limit_s == 240
    with pytest.raises(ValueError, match=r"optional parameters, sampler"):
        Rung.from_dict({"shape": "topex", "attitude": "inertial", "walkers": 3})


def test_the_simplest_rung_within_the_margin_is_chosen():
    rng = np.random.default_rng(0)
    noise = rng.normal(0.0, 0.5, 400)
    settings = LadderSettings(rungs=(), margin_floor_mag=0.02, bootstrap=200)
    simple, detailed = _score("ellipsoid-inertial", 5, 0.5), _score("box-precessing", 6, 0.49)
    # Residuals 1% apart everywhere: the difference (0.005 mag) is below the 0.02 mag floor.
    residuals = {simple.rung: noise, detailed.rung: 0.99 * noise}
    scores, chosen, best = choose_rung([simple, detailed], residuals, 20, settings)
    assert (chosen, best) == ("ellipsoid-inertial", "box-precessing")
    # The same residuals scaled the same way resample to the same difference: no spread.
    assert scores[0].heldout_se_mag == pytest.approx(0.0, abs=0.01)

    much_better = _score("box-precessing", 6, 0.25)
    residuals = {simple.rung: noise, much_better.rung: 0.5 * noise}
    _, chosen, best = choose_rung([simple, much_better], residuals, 20, settings)
    assert chosen == best == "box-precessing"


def test_a_noisy_difference_widens_the_margin_beyond_the_floor():
    rng = np.random.default_rng(1)
    settings = LadderSettings(rungs=(), margin_floor_mag=0.0, bootstrap=300)
    # 40 held-out samples of independent noise, RMS 0.52 against 0.50: with no floor, only the
    # bootstrap's standard error can keep the simpler rung.
    a, b = rng.normal(0, 0.5, 40), rng.normal(0, 0.5, 40)
    a *= 0.52 / np.sqrt(np.mean(a**2))
    b *= 0.50 / np.sqrt(np.mean(b**2))
    simple, detailed = _score("ellipsoid-inertial", 5, 0.52), _score("box-inertial", 5, 0.50)
    scores, chosen, _ = choose_rung([simple, detailed], {simple.rung: a, detailed.rung: b}, 1, settings)
    # Independent residuals: var(RMS) ~ sigma^2 / (2 n) each, so the difference has a standard error
    # ~ sigma / sqrt(n) = 0.5 / sqrt(40) = 0.08 mag; the bootstrap lands within a factor of two of it.
    assert 0.04 < scores[0].heldout_se_mag < 0.16
    assert chosen == "ellipsoid-inertial"


def test_failed_rungs_are_skipped_and_nothing_scored_chooses_nothing():
    settings = LadderSettings(rungs=())
    failed = RungScore("box-inertial", "box", "inertial", "lad.box-inertial", "failed: ValueError: no TLE")
    ok = _score("ellipsoid-precessing", 6, 0.4)
    _, chosen, best = choose_rung([failed, ok], {ok.rung: np.full(50, 0.4)}, 5, settings)
    assert chosen == best == "ellipsoid-precessing"
    assert choose_rung([failed], {}, 5, settings)[1:] == ("", "")


def test_a_rung_dark_where_the_object_was_seen_says_so_and_is_not_chosen():
    from types import SimpleNamespace

    from rsodb.campaign.ladder import _score as score_rung
    from rsodb.report.ladder_report import scores_figure

    n = 100
    time_utc = np.datetime64("2025-01-30T17:00:00", "ms") + np.arange(n) * np.timedelta64(100, "ms")
    observed = SimpleNamespace(
        time_utc=time_utc,
        valid=np.ones(n, bool),
        saturated=np.zeros(n, bool),
        best_mag=np.full(n, 5.0),
        mag_err=np.full(n, 0.01),
    )
    residuals = np.full(n, 0.3)
    residuals[95:] = np.inf  # the model's flat faces all turned from the observer at the end
    result = SimpleNamespace(
        time_utc=time_utc,
        in_window=np.arange(n) < 70,
        residuals_mag=residuals,
        spin_periods={},
        names=("spin_period_s", "jitter_mag"),
        n_window=70,
        reduced_chi2=1.0,
        converged=False,
        verdict="",
        elapsed_s=1.0,
    )
    rung = Rung("box", "inertial")
    score, _ = score_rung(rung, "lad.box-inertial", result, observed)
    assert score.status == "model dark at 5 held-out samples" and not score.ok
    assert score.train_rms_mag == pytest.approx(0.3)
    ok = _score("ellipsoid-inertial", 5, 0.8)
    _, chosen, best = choose_rung([score, ok], {ok.rung: np.full(30, 0.8)}, 5, LadderSettings(rungs=()))
    assert chosen == best == "ellipsoid-inertial"
    ladder = LadderResult("p", "lad", (score, ok), chosen, best, 0.02)
    texts = [t.get_text() for t in scores_figure(ladder).axes[0].texts]
    assert texts == ["dark"]


def test_the_no_model_forecast_repeats_the_last_training_cycle():
    # A curve periodic at 7 s is forecast to its interpolation error at the right lag and
    # badly at a wrong one.
    t = np.arange(0.0, 100.0, 0.1)
    mag = np.sin(2 * np.pi * t / 7) + 0.3 * np.sin(4 * np.pi * t / 7 + 1)
    train = t < 70.0
    right = mag[~train] - seasonal_naive(t, mag, train, t[~train], 7.0)
    wrong = mag[~train] - seasonal_naive(t, mag, train, t[~train], 7.5)
    assert np.sqrt(np.mean(right**2)) < 0.01 < 0.3 < np.sqrt(np.mean(wrong**2))


def test_the_no_model_forecast_doubles_a_half_period_on_the_training_window_only():
    # Two unequal halves: the search's 7 s is half the repeat; the end of the training window
    # says so and the lag becomes 14 s.
    t = np.arange(0.0, 140.0, 0.1)
    train, heldout = t < 100.0, t >= 100.0
    halves = np.sin(2 * np.pi * t / 7) + 0.4 * np.sin(2 * np.pi * t / 14)
    lag, residuals = naive_forecast(t, halves, train, heldout, 7.0)
    assert lag == 14.0 and np.sqrt(np.mean(residuals**2)) < 0.01
    # Periodic at 7 s with a growing amplitude: the most recent cycle forecasts best, so 7 s stays.
    growing = (1 + t / 50) * np.sin(2 * np.pi * t / 7)
    lag, residuals = naive_forecast(t, growing, train, heldout, 7.0)
    assert lag == 7.0
    # A forecast cannot use the held-out samples: changing them leaves the lag as it was.
    changed = growing.copy()
    changed[heldout] = np.sin(2 * np.pi * t[heldout] / 14)
    assert naive_forecast(t, changed, train, heldout, 7.0)[0] == 7.0


def test_the_ladder_says_how_the_best_rung_compares_with_no_model():
    scores = (_score("ellipsoid-inertial", 5, 0.40), _score("box-inertial", 5, 0.55))
    ladder = LadderResult("p", "lad", scores, "ellipsoid-inertial", "ellipsoid-inertial", 0.02, "", None)
    assert "no model" not in ladder.table()
    worse = replace(ladder, naive=NaiveForecast(9.48, 0.30, 0.02, 200))
    assert "predicts 0.100 mag worse (+-0.020)" in worse.naive_text() and worse.naive_text() in worse.table()
    assert "0.050 mag better" in replace(ladder, naive=NaiveForecast(9.48, 0.45, 0.02, 200)).naive_text()
    assert worse.to_dict()["naive"]["heldout_rms_mag"] == 0.30
    # The report's table ends with it as a row: no parameters, its held-out RMS minus the best's.
    row = scores_table(worse).rows[-1]
    assert row[0].startswith("no model") and row[1:5] == ("0", "-", "0.300", "-0.100")


@pytest.mark.parametrize(
    ("record", "message"),
    [
        ({"ladder": {"rungs": [{"shape": "cube", "attitude": "inertial"}]}}, "shape='cube' is not one of"),
        ({"ladder": {"rungs": [{"shape": "box"}]}}, "a ladder rung needs shape and attitude"),
        ({"ladder": {"train_fraction": 1.0}}, "train_fraction=1.0 must be within 0.2..0.95"),
        ({"ladder": {"margin": 0.1}}, "[ladder] has unknown keys ['margin']"),
        ({"objects": {"topex": {}}}, "[objects.topex] must be a NORAD number"),
        ({"fits": {}}, "unknown sections ['fits']"),
    ],
)
def test_bad_configurations_say_what_to_fix(record, message):
    with pytest.raises(ValueError) as error:
        LadderPlan.from_dict(record)
    assert message in str(error.value)


def test_the_real_passes_configurations_read():
    plan = LadderPlan.from_toml(PROJECT_ROOT / "configs" / "real_passes.toml")
    names = [r.name for r in plan.rungs_for(22076)]
    assert "topex-precessing" in names and "topex_louvered-inertial" in names and names[0] == "ellipsoid-inertial"
    assert plan.base_for(44517).parameters["spin_period_s"]["force"] is True
    # Every rung's exposure sub-samples are measured at the ladder's margin floor (not fixed at one).
    for norad in (22076, 44517, 51511):
        base = plan.base_for(norad).model
        assert (base.n_sub, base.sub_tolerance_mag) == (0, plan.settings.margin_floor_mag)
    # TOPEX's own rungs fix one sub-sample instead (model = { n_sub = 1 }); the others measure.
    observed = read_file(TOPEX_PHV)[0]
    models = {rung.name: config.model for rung, config in plan.configs(observed)}
    assert (models["topex_louvered-inertial"].n_sub, models["topex_louvered-inertial"].sub_tolerance_mag) == (1, 0.0)
    assert (models["box_panels-inertial"].n_sub, models["box_panels-inertial"].sub_tolerance_mag) == (0, 0.02)
    assert models["topex_louvered-inertial"].shape == "topex_louvered"
    with pytest.raises(ValueError, match="shape"):
        Rung.from_dict({"shape": "box", "attitude": "inertial", "model": {"shape": "ellipsoid"}})
    whole = FitConfig.from_toml(PROJECT_ROOT / "configs" / "topex_whole_pass.toml")
    assert (whole.model.shape, whole.data.duration_s) == ("topex", 0.0)
    louvered = FitConfig.from_toml(PROJECT_ROOT / "configs" / "topex_whole_pass_louvered.toml")
    assert louvered.model.shape == "topex_louvered"
    assert {"nadir_albedo", "louver_reflectance", "louver_roughness"} <= set(louvered.parameters)


@pytest.fixture(scope="module")
def injected(tmp_path_factory):
    """A 60 s pass of the ellipsoid with an inertial spin (pole RA 40, Dec 60 deg), 0.02 mag noise."""
    observed = read_file(TOPEX_PHV)[0]
    template = window(observed, 100.0, 60.0, bin_size=4)
    truth = {"spin_period_s": 9.86, "spin_phase_deg": 30.0, "pole_ra_deg": 40.0, "pole_dec_deg": 60.0}
    config = FitConfig.from_dict(
        {"model": {"shape": "ellipsoid", "attitude": "inertial", "n_sub": 1}, "parameters": PLAN["fit"]["parameters"]}
    )
    model = FitProblem.build(template, config).posterior.model
    archive = Archive(tmp_path_factory.mktemp("ladder") / "archive")
    archive.add([inject(template, model, truth, noise_mag=0.02, rng=np.random.default_rng(3))])
    return archive


def test_score_only_on_an_unfitted_pass_lists_every_rung_as_not_fitted(injected, tmp_path, capsys):
    path = tmp_path / "ladder.toml"
    path.write_text('[ladder]\nname = "lad"\nrungs = [{shape = "box", attitude = "inertial"}]\n')
    assert main(["ladder", "--archive", str(injected.path), "--config", str(path), "--score-only", "--json"]) == 0
    (ladder,) = json.loads(capsys.readouterr().out)["ladders"]
    assert ladder["chosen"] == "" and ladder["scores"][0]["status"] == "not fitted"


@pytest.mark.slow
def test_the_ladder_chooses_the_true_shape_on_held_out_samples(injected, tmp_path):
    plan = LadderPlan.from_dict(PLAN)
    (pass_id,) = [row.pass_id for row in injected.summaries()]
    (ladder,) = run_ladder(injected, [pass_id], plan, in_process=True, progress=False)
    assert {s.rung for s in ladder.scores} == {"ellipsoid-inertial", "box-inertial", "ellipsoid-precessing"}
    assert all(s.status == "ok" for s in ladder.scores)
    truth = ladder.score("ellipsoid-inertial")
    # The model that made the data predicts the unseen 30% near its 0.02 mag noise (0.1 mag allows a
    # short chain's period error carried over 18 s); the box cannot follow it.
    assert truth.heldout_rms_mag < 0.1
    assert ladder.score("box-inertial").heldout_rms_mag > truth.heldout_rms_mag + 0.05
    # The precessing rung has more parameters: chosen only if it beat the truth by more than the margin.
    assert ladder.chosen == "ellipsoid-inertial"
    assert "lad.ellipsoid-inertial" in injected.result_names(pass_id, "fits")

    # Replayed at the posterior median (predict_fit), the true model predicts as well.
    replayed = score_ladder(injected, pass_id, plan, median=True).score("ellipsoid-inertial")
    assert replayed.median_heldout_rms_mag < 0.1

    # With the pass's period stored, the no-model yardstick scores the same held-out samples:
    # the last cycle carries its own noise and the interpolation between 0.8 s bins, so the
    # true model predicts better.
    assert ladder.naive is None
    assert main(["periods", "--archive", str(injected.path)]) == 0
    naive = score_ladder(injected, pass_id, plan).naive
    assert naive.n_heldout == truth.n_heldout and naive.heldout_rms_mag > truth.heldout_rms_mag

    page = build_ladder_report(injected, [ladder]).write(tmp_path / "ladder.html").read_text()
    # The scores, the chosen rung's curve, and its fold: an ellipsoid's light curve repeats every
    # half turn, which is what the period search finds in the model's curve (4.9 s: enough cycles).
    assert page.count("<img") == 3 and "held-out RMS (mag)" in page
    assert f"<td>{ladder.chosen}</td>" in page and "<td>chosen</td>" in page
