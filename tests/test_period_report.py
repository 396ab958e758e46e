"""The period survey command, stored results, the spin trend and the HTML report."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg
import numpy as np
import pytest

from rsodb.archive import Archive
from rsodb.campaign.period_survey import input_sha256, load_period_results, survey_periods
from rsodb.cli import main
from rsodb.cli.report import REPORT_KINDS
from rsodb.fit.priors import Uniform
from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.search import PeriodResult, PeriodSettings
from rsodb.periods.trend import fit_period_trend, group_epochs, trend_from_results
from rsodb.report.html import Document, Figure, Heading, Paragraph, Table
from rsodb.report.period_report import build_period_report, pass_figure, trend_figure
from tests.conftest import REAL_FILES


@pytest.fixture(scope="module")
def surveyed(tmp_path_factory):
    """An archive of the four real files with a stored period survey.

    The survey is run here, not left to the CLI test: pytest-xdist may run any test of this module
    first, on any worker.  The CLI test surveys again, which replaces the stored results.
    """
    path = tmp_path_factory.mktemp("archive")
    archive = Archive(path)
    archive.ingest([str(f) for f in REAL_FILES], progress=False)
    survey_periods(archive, processes=1, progress=False)
    return path


def test_cli_survey_stores_a_result_for_every_pass(surveyed, capsys):
    status = main(["periods", "--archive", str(surveyed), "--json", "--processes", "2"])
    printed = json.loads(capsys.readouterr().out)
    assert status == 0 and printed["failures"] == [] and printed["stored_as"] == "default"
    by_id = {r["pass_id"]: r for r in printed["results"]}
    assert len(by_id) == 5  # 3 ccd_phot passes + B and V of the phc
    topex = next(r for r in printed["results"] if r["norad"] == 22076)
    assert topex["verdict"] == "confident" and abs(topex["best_period_s"] - 9.48) < 0.02
    assert topex["synodic"]["sidereal_prograde_s"] < topex["best_period_s"] < topex["synodic"]["sidereal_retrograde_s"]
    archive = Archive(surveyed, create=False)
    stored = load_period_results(archive)
    assert {r.pass_id for r in stored} == set(by_id)
    for result in stored:
        # What the archive gives back is what the survey printed.
        assert result.to_dict() == by_id[result.pass_id]
        assert archive.result_names(result.pass_id, "periods") == ["default"]


def test_stored_pass_chain_and_prior_from_the_archive(surveyed):
    archive = Archive(surveyed, create=False)
    stored = archive.passes(norad=22076)[0]
    assert stored.detrend().periodogram().best_period.value == pytest.approx(9.48, abs=0.02)
    result = archive.load_result(stored.pass_id, "periods", "default", PeriodResult.from_hdf5)
    prior = Uniform(*result.prior_interval_s())
    assert prior.low < 9.48 < prior.high and prior.high - prior.low < 0.04 * 9.48


def test_cli_table_output_and_errors(surveyed, capsys):
    assert (
        main(
            ["periods", "--archive", str(surveyed), "--object", "44517", "--processes", "1", "--no-store", "--quiet"]
            + ["--force"]
        )
        == 0
    )
    out = capsys.readouterr().out
    # A header row, then one row per pass (COSMOS 2540: its slow humps, ~66.6 s).
    header, rule, row = out.splitlines()[:3]
    assert header.split()[:4] == ["pass", "period", "s", "+-"] and "verdict" in header and set(rule) == {"-"}
    assert row.startswith("44517-") and float(row.split()[1]) == pytest.approx(66.6, abs=1.0)
    assert "stored" not in out
    assert main(["periods", "--archive", str(surveyed), "--processes", "0"]) == 2
    assert "--processes 0 must be at least 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["periods", "--help"])
    assert "rsodb periods --archive archive --object 22076" in capsys.readouterr().out


def test_a_survey_searches_only_passes_whose_inputs_changed(surveyed, tmp_path, capsys):
    path = tmp_path / "archive"
    shutil.copytree(surveyed, path)
    archive = Archive(path, create=False)
    ids = [row.pass_id for row in archive.summaries(norad=51511)]
    stored = {r.pass_id: r.to_dict() for r in load_period_results(archive, norad=51511)}
    # The fixture's survey used the same settings: nothing is searched, the stored results come back.
    again = survey_periods(archive, 51511, processes=1, progress=False)
    assert sorted(again.reused) == sorted(ids) and {r.pass_id: r.to_dict() for r in again.results} == stored
    # Other settings, no geometry, or force: searched again (and stored, replacing the old ones).
    for changes in ({"settings": PeriodSettings(min_cycles=2.0)}, {"geometry": False}, {"force": True}):
        survey = survey_periods(archive, 51511, processes=1, progress=False, **changes)
        assert survey.reused == () and len(survey.results) == len(ids), changes
    # What was stored last (found without --force from the default settings and geometry) is reused.
    assert sorted(survey_periods(archive, 51511, processes=1, progress=False).reused) == sorted(ids)
    assert main(["periods", "--archive", str(path), "--object", "51511", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"{len(ids)} pass(es) not searched again" in out and "stored 2 result(s)" not in out
    # The inputs' hash follows the pass's content: other data, other hash.
    assert input_sha256("a" * 64, PeriodSettings(), True) != input_sha256("b" * 64, PeriodSettings(), True)


def test_report_command_writes_a_self_contained_page(surveyed, tmp_path, capsys):
    out = tmp_path / "c2553.html"
    assert main(["report", "periods", "--archive", str(surveyed), "--object", "51511", "--out", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    page = out.read_text()
    # No external references: every image is inline base64 PNG.
    assert "http://" not in page and "https://" not in page and 'src="data:image/png;base64,' in page
    images = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(images) == 1 + 3  # trend + one figure per pass (B, V, March)
    for encoded in images:
        picture = mpimg.imread(io.BytesIO(base64.b64decode(encoded)), format="png")
        assert picture.shape[0] > 300 and picture.shape[1] > 600
    for pass_id in ("51511-20250130T171941-B-uzhhorod", "51511-20250311T173120-V-derenivka"):
        assert pass_id in page
    # One confident pass (March V; January's two bands are "ambiguous harmonic"): the report says
    # in words why there is no trend.
    assert "Spin trend from the passes with verdict confident: no trend:" in page
    assert "one night (2025-03-11, one epoch)" in page


def test_report_without_results_says_what_to_run(tmp_path, capsys):
    archive = Archive(tmp_path / "a")
    archive.ingest([str(REAL_FILES[0])], progress=False)
    status = main(
        ["report", "periods", "--archive", str(tmp_path / "a"), "--object", "22076", "--out", str(tmp_path / "r.html")]
    )
    assert status == 2
    assert "run 'rsodb periods --archive" in capsys.readouterr().err
    with pytest.raises(ValueError, match="object 22076 has no period results named 'default'"):
        build_period_report(archive, 22076)


def test_report_kinds_table(capsys):
    assert set(REPORT_KINDS) == {"periods", "campaign"}
    assert all(description and callable(build) for description, _, _, build in REPORT_KINDS.values())
    with pytest.raises(SystemExit):
        main(["report", "survey", "--archive", "a", "--object", "1", "--out", "r.html"])
    assert "invalid choice: 'survey'" in capsys.readouterr().err


# -- spin trend --------------------------------------------------------------------------------
def test_trend_of_an_exact_line():
    times = np.array(["2016-10-19", "2018-06-01", "2020-08-02", "2024-07-30"], dtype="datetime64[ns]")
    years = (times - times[0]) / np.timedelta64(1, "s") / (365.25 * 86400)
    periods = 10.73 - 0.16 * years
    trend = fit_period_trend(times, periods, np.full(4, 0.01))
    # An exact line: slope to rounding, chi-square zero, errors from the weights alone.
    assert trend.slope_s_per_yr == pytest.approx(-0.16, abs=1e-9)
    assert trend.chi2_reduced == pytest.approx(0.0, abs=1e-12) and trend.birge_ratio == 1.0
    sxx = np.sum((years - years.mean()) ** 2) / 0.01**2
    assert trend.slope_err_s_per_yr == pytest.approx(1 / np.sqrt(sxx), rel=1e-9)
    np.testing.assert_allclose(trend.period_s(times), periods, atol=1e-9)
    assert trend.sense == "spinning up" and "spinning up: dP/dt = -0.16" in trend.summary()
    assert trend.span_days == pytest.approx(2841.0)


def test_trend_errors_grow_with_scatter_beyond_the_error_bars():
    times = np.array(["2020-01-01", "2021-01-01", "2022-01-01", "2023-01-01"], dtype="datetime64[ns]")
    scatter = np.array([0.0, 0.1, -0.1, 0.0])
    trend = fit_period_trend(times, 10 + scatter, np.full(4, 0.01))
    # Residual scatter of ~0.1 s against 0.01 s errors: chi2/dof ~ 10^2, errors scaled by its root.
    assert trend.birge_ratio == pytest.approx(np.sqrt(trend.chi2_reduced))
    assert trend.birge_ratio > 5
    with pytest.raises(ValueError, match="needs passes at two or more epochs .nights., got 1"):
        fit_period_trend(times[:1], [10.0], [0.01])
    with pytest.raises(ValueError, match="period_err_s must be positive and finite"):
        fit_period_trend(times, np.full(4, 10.0), [0.01, 0.0, 0.01, 0.01])


def test_passes_of_one_night_are_one_epoch_and_give_no_trend():
    # Three passes within two hours (the case gave dP/dt = -4.8e5 +- 5.8e7 s/yr).
    night = np.datetime64("2025-01-30T17:00", "ns") + np.array([0, 40, 110], dtype="timedelta64[m]")
    with pytest.raises(ValueError, match="two or more epochs .nights., got 1"):
        fit_period_trend(night, [4.93, 4.92, 4.95], [0.002, 0.003, 0.01])
    epochs = group_epochs(night, [4.93, 4.92, 4.95], [0.002, 0.003, 0.01], pass_ids=["a", "b", "c"])
    assert len(epochs) == 1 and epochs[0].n_passes == 3 and epochs[0].pass_ids == ("a", "b", "c")
    # The epoch's period is the weighted mean; the passes disagree beyond their errors, so its
    # error is scaled by the Birge ratio (chi2 = 4.1 on 2 degrees of freedom here).
    w = 1 / np.array([0.002, 0.003, 0.01]) ** 2
    mean = np.sum(w * [4.93, 4.92, 4.95]) / w.sum()
    chi2 = np.sum(w * (np.array([4.93, 4.92, 4.95]) - mean) ** 2)
    assert epochs[0].period_s == pytest.approx(mean, rel=1e-12)
    assert epochs[0].period_err_s == pytest.approx(np.sqrt(chi2 / 2) / np.sqrt(w.sum()), rel=1e-9)
    # Two nights a day apart: epochs, but less than the 7 days a trend needs.
    with pytest.raises(ValueError, match="span 1 days, less than the 7 days"):
        fit_period_trend(np.concatenate([night, night + np.timedelta64(1, "D")]), np.full(6, 4.93), np.full(6, 0.01))


def test_a_trend_is_claimed_only_at_two_sigma_otherwise_its_bound_is_given():
    times = np.array(["2025-01-30", "2025-03-11"], dtype="datetime64[ns]")
    # The second case: -0.165 +- 0.38 s/yr was called "spinning up" at under 1 sigma.
    years = 40 / 365.25
    weak = fit_period_trend(times, [4.93, 4.93 - 0.165 * years], np.full(2, 0.38 * years / np.sqrt(2)))
    assert weak.slope_err_s_per_yr == pytest.approx(0.38, rel=1e-9)
    assert weak.sense == "no significant trend"
    assert weak.bound_s_per_yr == pytest.approx(0.165 + 2 * 0.38, rel=1e-9)
    assert "no significant trend: dP/dt = -0.165 +- 0.38 s/yr (0.4 sigma), |dP/dt| < 0.93 s/yr" in weak.summary()
    strong = fit_period_trend(times, [4.930, 4.849], [0.001, 0.001])
    assert strong.sense == "spinning up" and strong.significance > 2


@pytest.mark.parametrize("n_epochs", [2, 5])
def test_false_trend_claims_stay_at_the_two_sigma_rate_and_real_trends_are_found(n_epochs):
    # Periods with no trend, scattered by exactly their stated errors: "spinning up/down" must be
    # claimed no more often than a 2-sigma two-sided test allows, 4.55% (two epochs: the error is
    # exact; more: the Birge ratio only ever widens it). 500 trials: binomial sigma 0.93%, so
    # the bound below is 3 sigma above 4.55%.
    rng = np.random.default_rng(n_epochs)
    days = np.sort(rng.uniform(0, 300, n_epochs))
    days[0], days[-1] = 0.0, 300.0
    times = np.datetime64("2025-01-30T18:00", "ns") + (days * 86400e9).astype("timedelta64[ns]")
    sigma = rng.uniform(0.001, 0.01, n_epochs)
    trials = 500
    claims = sum(
        fit_period_trend(times, 9.5 + rng.normal(0, sigma), sigma).sense != "no significant trend"
        for _ in range(trials)
    )
    assert claims / trials <= 0.0455 + 3 * 0.0093
    # A spin-up of 4 standard errors is claimed, in the right sense, in nearly every trial
    # (expected 97.7% with known errors; fewer when a Birge ratio above 1 widens the error).
    error = fit_period_trend(times, np.full(n_epochs, 9.5), sigma).slope_err_s_per_yr
    years = (days - days.mean()) / 365.25
    found = [fit_period_trend(times, 9.5 - 4 * error * years + rng.normal(0, sigma), sigma).sense for _ in range(100)]
    assert found.count("spinning up") >= 85


def test_trend_from_results_counts_the_synodic_correction_as_error(surveyed):
    results = load_period_results(Archive(surveyed, create=False), 51511)
    # January (phc, both bands) says "ambiguous harmonic", March "confident".
    confident = trend_from_results(results)
    assert confident.trend is None and "one night (2025-03-11, one epoch)" in confident.note
    both = trend_from_results(results, ("confident", "ambiguous harmonic"))
    trend = both.trend
    assert [e.n_passes for e in both.epochs] == [2, 1] and trend.n_points == 2
    # January 4.93 s -> March 4.85 s: a spin-up at many sigma (each error includes the March
    # pass's synodic correction, the phc pass has no elements).
    march = next(r for r in results if r.band == "V" and str(r.epoch_utc).startswith("2025-03"))
    assert march.synodic is not None
    assert trend.epochs[1].period_err_s == pytest.approx(np.hypot(march.uncertainty_s, march.synodic.max_correction_s))
    assert trend.sense == "spinning up" and trend.slope_s_per_yr < 0
    assert "2 epochs (2025-01-30, 2025-03-11) spanning 40 days" in both.summary()
    assert trend_from_results(results[:0]).note == "no trend: no pass has verdict 'confident'"


def test_trend_figure_has_a_dated_axis_and_the_line_through_the_epochs(surveyed):
    results = load_period_results(Archive(surveyed, create=False), 51511)
    spin_trend = trend_from_results(results, ("confident", "ambiguous harmonic"))
    fig = trend_figure(results, spin_trend)
    ax = fig.axes[0]
    fig.canvas.draw()
    labels = " ".join(t.get_text() for t in ax.get_xticklabels()) + ax.xaxis.get_offset_text().get_text()
    # Month names or dates on the axis, not day numbers like "43.0".
    assert re.search(r"Feb|Mar|2025", labels), labels
    assert not re.search(r"\b\d+\.\d\b", labels), labels
    # The line is drawn from the first to the last epoch only, through the data's range.
    line = next(line for line in ax.get_lines() if line.get_label().startswith("trend"))
    y = line.get_ydata()
    periods = [e.period_s for e in spin_trend.epochs]
    assert min(periods) - 0.01 <= y.min() and y.max() <= max(periods) + 0.01
    low, high = ax.get_ylim()
    assert low < min(periods) and max(periods) < high and high - low < 0.5


def test_pass_figure_axes_come_from_the_data(surveyed):
    archive = Archive(surveyed, create=False)
    stored = archive.passes(norad=44517)[0]
    result = archive.load_result(stored.pass_id, "periods", "default", PeriodResult.from_hdf5)
    lc = LightCurve.from_pass(stored)
    fig = pass_figure(result, lc)
    curve, power, fold, colour_bar = fig.axes
    assert colour_bar.get_ylabel().startswith("cycle")  # the fold's colours have a key
    assert fold.get_ylabel() == f"{lc.band} magnitude (reduced to 1000 km) - trend"
    bottom, top = curve.get_ylim()
    # Brighter up, and the range is the data's (within 15% margins), whatever the model does.
    assert bottom > top
    assert top <= lc.mag.min() + 0.05 and bottom >= lc.mag.max() - 0.05
    assert bottom - top < 1.5 * np.ptp(lc.mag)
    # The reported candidate is marked with its error on the periodogram.
    assert any("reported 66" in text.get_text() for text in power.get_legend().get_texts())


# -- HTML builder ------------------------------------------------------------------------------
def test_document_is_immutable_escaped_and_written_atomically(tmp_path):
    doc = Document("A <b> report")
    bigger = doc.add(
        Heading("Section & more"),
        Paragraph("1 < 2"),
        Table(("a", "b"), (("x", "1.5"),), numeric=frozenset({1})),
        Figure(b"\x89PNG fake", "caption"),
    )
    assert doc.blocks == () and len(bigger.blocks) == 4
    html = bigger.to_html()
    assert "<title>A &lt;b&gt; report</title>" in html and "<p>1 &lt; 2</p>" in html
    assert '<h2 id="section---more">Section &amp; more</h2>' in html
    assert '<td class="num">1.5</td>' in html
    assert base64.b64encode(b"\x89PNG fake").decode() in html
    path = bigger.write(tmp_path / "sub" / "r.html")
    assert path.read_text() == html and not list(path.parent.glob(".*tmp"))
    with pytest.raises(ValueError, match="table row 0 has 1 cells but there are 2 columns"):
        Table(("a", "b"), (("x",),))
    with pytest.raises(TypeError, match="str is not a report block"):
        doc.add("text")


def test_survey_of_an_empty_selection(surveyed):
    survey = survey_periods(Archive(surveyed, create=False), norad=99999, processes=1, progress=False)
    assert survey.results == () and survey.failures == () and survey.ok
