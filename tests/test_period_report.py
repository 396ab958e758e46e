"""The period survey command, stored results, the spin trend and the HTML report."""

from __future__ import annotations

import base64
import io
import json
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg
import numpy as np
import pytest

from rsodb.archive import Archive
from rsodb.campaign.period_survey import load_period_results, survey_periods
from rsodb.cli import main
from rsodb.cli.report import REPORT_KINDS
from rsodb.fit.priors import Uniform
from rsodb.periods.search import PeriodResult
from rsodb.periods.trend import fit_period_trend, trend_from_results
from rsodb.report.html import Document, Figure, Heading, Paragraph, Table
from rsodb.report.period_report import build_period_report
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
        main(["periods", "--archive", str(surveyed), "--object", "44517", "--processes", "1", "--no-store", "--quiet"])
        == 0
    )
    out = capsys.readouterr().out
    assert "too short" in out and "stored" not in out
    header, row = out.splitlines()[:2]  # issue 19: the table has a header row
    assert header.split() == ["PASS", "ID", "SYNODIC", "S", "+-", "ERR", "VERDICT", "SIDEREAL", "RANGE", "S"]
    assert row.startswith("44517-20250130T173650-V-derenivka")
    assert main(["periods", "--archive", str(surveyed), "--processes", "0"]) == 2
    assert "--processes 0 must be at least 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["periods", "--help"])
    assert "rsodb periods --archive archive --object 22076" in capsys.readouterr().out


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
    # Two confident passes (January V, March V) give a trend with its slope in s/yr.
    assert "dP/dt =" in page and "s/yr" in page


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
    assert "spinning up" in trend.summary()


def test_trend_errors_grow_with_scatter_beyond_the_error_bars():
    times = np.array(["2020-01-01", "2021-01-01", "2022-01-01", "2023-01-01"], dtype="datetime64[ns]")
    scatter = np.array([0.0, 0.1, -0.1, 0.0])
    trend = fit_period_trend(times, 10 + scatter, np.full(4, 0.01))
    # Residual scatter of ~0.1 s against 0.01 s errors: chi2/dof ~ 10^2, errors scaled by its root.
    assert trend.birge_ratio == pytest.approx(np.sqrt(trend.chi2_reduced))
    assert trend.birge_ratio > 5
    with pytest.raises(ValueError, match="needs passes at two or more times, got 1"):
        fit_period_trend(times[:1], [10.0], [0.01])
    with pytest.raises(ValueError, match="period_err_s must be positive and finite"):
        fit_period_trend(times, np.full(4, 10.0), [0.01, 0.0, 0.01, 0.01])


def test_trend_from_results_counts_the_synodic_correction_as_error(surveyed):
    results = load_period_results(Archive(surveyed, create=False), 51511)
    trend = trend_from_results(results)
    confident = [r for r in results if r.verdict == "confident"]
    assert trend.n_points == len(confident) == 2
    # Two passes: the line goes through both; January 4.930 s -> March 4.849 s is a spin-up.
    assert trend.slope_s_per_yr < 0
    assert trend_from_results(results[:1]) is None


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
