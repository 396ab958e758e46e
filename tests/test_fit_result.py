"""A whole fit through the archive: the stored period sets the prior, the chain lives at
archive.chain_path, the FitResult round-trips through HDF5, plots are written, and a
misspecified model reports its misfit."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import h5py
import numpy as np
import pytest

from ingest import read_file
from rsodb.archive import Archive
from rsodb.fit.config import FitConfig
from rsodb.fit.coverage import inject, window
from rsodb.fit.parameters import ParameterSpace
from rsodb.fit.priors import Uniform
from rsodb.fit.result import FitResult, assess_convergence, prior_bound_flags
from rsodb.fit.runner import FitProblem, fit_pass
from rsodb.report.fit_report import _table
from rsodb.report.trust import assess
from tests.conftest import TOPEX_PHV

TRUTH = {
    "spin_period_s": 9.86,
    "spin_phase_deg": 100.0,
    "precession_period_s": 700.0,
    "precession_phase_deg": 180.0,
    "precession_angle_deg": 35.0,
}
QUICK = {"n_walkers": 14, "n_steps": 120, "search_maxiter": 60, "seed": 2}


def synthetic_archive(tmp_path, shape: str, noise_mag: float = 0.02):
    template = window(read_file(TOPEX_PHV)[0], 0.0, 30.0, bin_size=3)
    render = FitConfig.from_dict(
        {
            "model": {"shape": shape, "n_sub": 2},
            "parameters": {"spin_period_s": {"kind": "uniform", "low": 9.0, "high": 11.0}},
        }
    )
    posterior = FitProblem.build(template, render).posterior
    truth = dict(posterior.space.fixed, **TRUTH)  # the shape's articulations at their defaults
    observed = inject(
        template, posterior.model, truth, noise_mag=noise_mag, rng=np.random.default_rng(4), offset_mag=0.7
    )
    archive = Archive(tmp_path / "archive")
    archive.add([observed])
    return archive, archive.passes()[0].pass_id


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    from rsodb.periods.analysis import analyse_pass

    archive, pass_id = synthetic_archive(tmp_path_factory.mktemp("fit"), "ellipsoid")
    periods = analyse_pass(archive.get(pass_id))
    # epoch_utc is not used by the prior; without it the record also stores on versions of
    # PeriodResult.to_hdf5 that cannot write a numpy datetime string attribute.
    periods = replace(periods, epoch_utc=None)
    archive.store_result(pass_id, "periods", "default", periods)
    # A triaxial ellipsoid looks the same after half a turn: its light curve repeats at P/2,
    # which is what the periodogram measures; "multiple = 2" turns that into the spin prior.
    # The width is 3%, not the default 1%: with a precessing spin axis the light curve's period
    # is not the spin period (see test_spin_period_prior_comes_from_the_stored_period).
    config = FitConfig.from_dict(
        {
            "name": "quick",
            "model": {"shape": "ellipsoid", "n_sub": 2},
            "sampler": QUICK,
            "parameters": {"spin_period_s": {"from": "periods", "multiple": 2.0, "width": 0.03}},
        }
    )
    return archive, pass_id, periods, fit_pass(archive, pass_id, config, progress=False)


def test_fit_is_stored_with_the_chain_in_the_archive(fitted):
    archive, pass_id, periods, result = fitted
    assert archive.result_names(pass_id, "fits") == ["quick"]
    assert str(archive.chain_path(pass_id, "quick")) == result.chain_path
    stored = archive.load_result(pass_id, "fits", "quick", FitResult.from_hdf5)
    assert stored.names == result.names and stored.space == result.space
    for name in ("median", "p16", "p84", "best", "mag_model", "samples", "acceptance_fraction"):
        np.testing.assert_array_equal(getattr(stored, name), getattr(result, name))
    np.testing.assert_array_equal(stored.time_utc, result.time_utc)
    assert (stored.verdict, stored.flags, stored.n_steps) == (result.verdict, result.flags, 120)
    assert stored.config["model"]["shape"] == "ellipsoid"


def test_spin_period_prior_comes_from_the_stored_period(fitted):
    archive, pass_id, periods, result = fitted
    prior = result.space.free[result.names.index("spin_period_s")].prior
    expected = Uniform(*periods.prior_interval_s(0.03))
    assert (prior.low, prior.high) == pytest.approx((2 * expected.low, 2 * expected.high), rel=1e-12)
    # The light curve repeats near half the spin period, but not at it: the spin axis turns
    # too (precession: cos(theta) / P_pr = 1.2% of 1/P here; the orbit frame and the changing
    # viewing geometry add more), so the periodogram's P/2 is 1-2% short of P_spin / 2.
    assert periods.best_period_s == pytest.approx(TRUTH["spin_period_s"] / 2, rel=0.03)
    assert prior.low < TRUTH["spin_period_s"] < prior.high


def test_best_fit_reproduces_the_injected_light_curve(fitted):
    _, _, _, result = fitted
    # Same model as the injection: the best fit is within the noise. RMS of 30 N(0, 0.02)
    # residuals exceeds 0.03 mag with probability < 1e-3.
    assert result.residual_rms_mag < 0.03
    # (The offset itself trades off against the attitude: a different cone angle shows more or
    # less of the ellipsoid's long side, so it is not compared with the injected 0.7 mag.)
    assert 0.3 < result.reduced_chi2 < 2.0
    assert not any(flag.startswith("model misfit") for flag in result.flags)
    # The summary is ordered: p16 <= median <= p84 on the unrolled branch.
    assert np.all(result.p16 <= result.median + 1e-9) and np.all(result.median <= result.p84 + 1e-9)


def test_hdf5_layout_is_readable_with_plain_h5py(fitted, tmp_path):
    _, _, _, result = fitted
    with h5py.File(tmp_path / "r.h5", "w") as handle:
        result.to_hdf5(handle.create_group("fit"))
    with h5py.File(tmp_path / "r.h5", "r") as handle:
        group = handle["fit"]
        names = [n.decode() for n in group["summary"]["name"]]
        assert names == list(result.names)
        np.testing.assert_array_equal(group["summary"]["median"], result.median)
        assert group.attrs["kind"] == "fit" and group.attrs["schema_version"] == 2
        assert group["lightcurve"].shape == result.mag_obs.shape
        assert group["lightcurve"]["in_window"].all() and group["lightcurve"]["fitted"].all()
        # The model curve over the pass: a row per band level, one column per fine time step.
        assert group["curve"]["mag_band"].shape == (5, group["curve"]["time_utc"].shape[0])


def test_plots_are_written(fitted, tmp_path):
    from rsodb.fit.plots import corner_figure, save_all

    _, _, _, result = fitted
    paths = save_all(result, tmp_path, truths=TRUTH)
    assert sorted(paths) == ["corner", "lightcurve", "trace"]
    for path in paths.values():
        assert path.stat().st_size > 10_000  # a real PNG with content, not an empty canvas
    figure = corner_figure(result)
    assert len(figure.axes) == len(result.names) ** 2


def test_the_folded_figure_shows_each_stretch_and_its_misfit(fitted, tmp_path):
    from rsodb.fit.plots import fold_period_s, folded_figure

    _, _, _, result = fitted
    # Folded at the period the period search finds in the model's own curve (rsodb.fit.conventions).
    searched = result.spin_periods["conventions"]["periodogram"]["median"]
    assert fold_period_s(result) == searched
    figure = folded_figure(result, tmp_path / "folded.png", windows=2)
    assert (tmp_path / "folded.png").stat().st_size > 10_000
    shown = [axis for axis in figure.axes if axis.get_visible()]
    assert len(shown) == 2
    # The second stretch's title gives the RMS of its own residuals.
    t = result.t_s[result.in_window]
    late = result.in_window & (result.t_s >= 0.5 * (t[0] + t[-1]))
    rms = np.sqrt(np.mean((result.mag_obs[late] - result.mag_model[late]) ** 2))
    assert shown[1].get_title().endswith(f"RMS {rms:.2f} mag")
    # One model line per cycle in each stretch, drawn from the stored continuous curve.
    cycles = np.unique(np.floor(((result.curve.time_utc - result.time_utc[0]) / np.timedelta64(1, "s")) / searched))
    assert sum(len(axis.lines) - 2 for axis in shown) >= len(cycles)


@pytest.mark.slow
def test_misspecified_model_reports_its_misfit(tmp_path):
    # Data rendered from the detailed TOPEX model (cached renderer), fitted with the ellipsoid.
    archive, pass_id = synthetic_archive(tmp_path, "topex", noise_mag=0.01)
    config = FitConfig.from_dict(
        {
            "name": "simple",
            "model": {"shape": "ellipsoid", "n_sub": 2},
            "sampler": QUICK,
            "parameters": {"spin_period_s": {"kind": "uniform", "low": 9.5, "high": 10.2}},
        }
    )
    result = fit_pass(archive, pass_id, config, progress=False)
    # An ellipsoid cannot make TOPEX's light curve: residuals far above the 0.01 mag noise,
    # the jitter absorbing them, and the result saying so.
    assert result.reduced_chi2 > 10
    assert result.jitter_mag > 0.03
    assert any(flag.startswith("model misfit") and "jitter term" in flag for flag in result.flags)


def test_stored_draws_keep_every_walker():
    # 400 kept steps x 16 walkers = 6400 draws, thinned to at most 4000 (MAX_STORED_SAMPLES):
    # a stride of 2 over the flattened (step, walker) order would keep only the even walkers.
    # Even walkers sit at P = 9.80 s and odd ones at 9.90 s, so the stored draws must hold
    # exactly half of each (an exact count, no tolerance needed).
    from rsodb.fit.result import MAX_STORED_SAMPLES
    from rsodb.fit.sampler import ChainRun

    template = window(read_file(TOPEX_PHV)[0], 0.0, 20.0, bin_size=4)
    config = FitConfig.from_dict(
        {
            "model": {"shape": "lopsided", "n_sub": 1},
            "parameters": {"spin_period_s": {"kind": "uniform", "low": 9.7, "high": 10.0}},
        }
    )
    posterior = FitProblem.build(template, config).posterior
    rng = np.random.default_rng(3)
    n_steps, n_walkers = 800, 16
    start = posterior.space.sample_prior(rng, 1)[0]
    chain = np.broadcast_to(start, (n_steps, n_walkers, start.size)).copy()
    chain[:, :, 0] = np.where(np.arange(n_walkers) % 2 == 0, 9.80, 9.90)
    run = ChainRun(
        posterior.space.names,
        chain,
        np.zeros((n_steps, n_walkers)),
        np.full(n_walkers, 0.3),
        np.full(start.size, 10.0),
        0,
        n_steps,
        1.0,
        {},
        "",
    )
    result = FitResult.from_run(run, posterior, pass_id="p", name="n", time_utc=template.time_utc)
    periods = result.samples[:, 0]
    assert periods.size <= MAX_STORED_SAMPLES
    assert np.sum(periods < 9.85) == np.sum(periods > 9.85) == periods.size // 2


def test_the_folded_figure_of_a_whole_pass_marks_what_the_fit_did_not_see(fitted):
    from rsodb.fit.plots import folded_figure

    _, _, _, result = fitted
    # As a ladder rung: fitted on the first 70% of the pass, the rest held out.
    cut = result.t_s[0] + 0.7 * (result.t_s[-1] - result.t_s[0])
    rung = replace(result, in_window=result.in_window & (result.t_s <= cut), fitted=result.fitted & (result.t_s <= cut))
    figure = folded_figure(rung, windows=2, whole_pass=True)
    late = [axis for axis in figure.axes if axis.get_visible()][1]
    held = (result.t_s > cut) & np.isfinite(result.mag_obs)
    blue = [line for line in late.lines if line.get_color() == "C0"]
    assert len(blue) == 1 and len(blue[0].get_xdata()) == held.sum() > 0
    # Without whole_pass the figure ends where the fit's window ends.
    window_only = folded_figure(rung, windows=2)
    assert all(line.get_color() != "C0" for axis in window_only.axes for line in axis.lines)


@pytest.mark.parametrize(
    ("n_kept", "acceptance", "converged", "says"),
    [
        (3000, 0.30, True, "converged: the kept chain is 60 autocorrelation times long"),
        # Too short: more steps are the cure.
        (1500, 0.30, False, "only 30.0 autocorrelation times long (50 wanted; tau = 50 steps)"),
        (1500, 0.30, False, "Run more steps (a rerun resumes the chain)."),
        # Long enough, but the walkers hardly move: more steps are not the cure, and the verdict
        # must not send the user to run them.
        (3000, 0.13, False, "60 autocorrelation times long (tau = 50 steps), but mean acceptance 0.13 is outside"),
        (3000, 0.13, False, "more steps will not change it"),
    ],
)
def test_the_verdict_says_whether_more_steps_would_help(n_kept, acceptance, converged, says):
    tau = np.array([20.0, 50.0, 35.0])
    got, verdict = assess_convergence(n_kept, tau, np.full(20, acceptance))
    assert got is converged
    assert says in verdict, verdict
    if n_kept == 3000 and not converged:
        assert "Run more steps" not in verdict


def test_a_posterior_cut_off_by_a_chosen_prior_bound_is_flagged_and_a_physical_one_is_not():
    space = ParameterSpace.from_names(["spin_period_s", "spin_phase_deg", "precession_angle_deg", "jitter_mag"])
    space = space.with_prior("spin_period_s", Uniform(9.76, 9.96)).with_prior("jitter_mag", Uniform(0.0, 0.5))
    rng = np.random.default_rng(3)
    n = 4000
    piled_high = 9.96 - np.abs(rng.normal(0.0, 0.004, n))  # the +-1% prior cuts it at 9.96
    phase = np.mod(rng.normal(0.0, 2.0, n), 360.0)  # around 0 deg: a wrapped angle has no bound
    spread = rng.uniform(0.0, 90.0, n)  # a cone the data do not constrain: 1% per edge
    at_zero = np.abs(rng.normal(0.0, 0.01, n))  # a jitter of 0 is the data fitting, not a cut
    flags = prior_bound_flags(space, np.column_stack([piled_high, phase, spread, at_zero]))
    assert len(flags) == 1, flags
    assert flags[0].startswith("at a prior bound: spin_period_s piles at its prior's upper bound 9.96 (")
    # The jitter pressed against the 0.5 mag it was allowed (a misfit wanting more), and a cone
    # at 90 deg (half the 0-180 deg the angle can take) are choices of the prior.
    at_cap = 0.5 - np.abs(rng.normal(0.0, 0.002, n))
    cone_90 = 90.0 - np.abs(rng.normal(0.0, 0.3, n))
    flags = prior_bound_flags(space, np.column_stack([rng.uniform(9.8, 9.9, n), phase, cone_90, at_cap]))
    assert [f.split(" piles")[0] for f in flags] == [
        "at a prior bound: precession_angle_deg",
        "at a prior bound: jitter_mag",
    ]
    # A cone at its physical 0 deg is not flagged.
    assert prior_bound_flags(space, np.column_stack([rng.uniform(9.8, 9.9, n), phase, at_zero, spread / 180])) == []


def test_the_trust_table_names_what_keeps_a_long_chain_from_converging():
    # The trust table reads the stored chain's numbers, as the verdict did (not the verdict's words).
    tau, acceptance = np.array([50.0]), np.full(20, 0.13)
    _, verdict = assess_convergence(3000, tau, acceptance)
    fit = SimpleNamespace(
        converged=False,
        verdict=verdict,
        flags=(),
        spin_periods={},
        n_steps=3400,
        discard=400,
        autocorr_time=tau,
        acceptance_fraction=acceptance,
    )
    reasons = assess(fit, SimpleNamespace(verdict="confident", best_period_s=9.5, uncertainty_s=0.001)).reasons
    assert reasons[0] == "chain not converged (mean acceptance 0.13 is outside 0.15-0.7)"


def test_the_table_tells_the_samples_the_likelihood_saw_from_those_between_them(fitted):
    _, _, _, result = fitted
    # Every other 10 s seen, the model exact there and 0.3 mag off between.
    seen = (result.t_s // 10.0).astype(int) % 2 == 0
    rung = replace(result, fitted=seen, mag_model=result.mag_obs - np.where(seen, 0.0, 0.3))
    seen_rms, unseen_rms = rung.residual_rms_by_sight()
    assert seen_rms == pytest.approx(0.0, abs=1e-12)
    assert unseen_rms == pytest.approx(0.3, rel=1e-9)
    lines = [line for line in rung.table().splitlines() if "likelihood saw" in line]
    assert lines == [
        f"  of which 0.000 mag over the {int(seen.sum())} samples the likelihood saw, "
        f"0.300 over the {int((~seen).sum())} between them it did not"
    ]
    assert rung.to_dict()["residual_rms_unseen_mag"] == pytest.approx(0.3, rel=1e-9)
    # A fit that saw every sample of its window says nothing of the kind.
    assert "likelihood saw" not in result.table()
    assert result.to_dict()["residual_rms_unseen_mag"] is None
    # The campaign report's table has the column: the RMS between the fit's samples, or "-".
    table = _table([rung, result], {})
    column = table.columns.index("RMS between the fit's samples [mag]")
    assert [row[column] for row in table.rows] == ["0.300", "-"]
    assert column in table.numeric
