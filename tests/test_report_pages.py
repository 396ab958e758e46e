"""The reports one sends: trust levels and their reasons, the spin state in words, sortable tables
with links, and the index's reason for every missing value."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from rsodb.archive import Archive
from rsodb.campaign.period_survey import survey_periods
from rsodb.report.html import Document, Link, Table
from rsodb.report.index_page import COLUMNS, build_index
from rsodb.report.spin_state import axis_text, interval, spin_state_rows
from rsodb.report.trust import assess
from tests.conftest import REAL_FILES


def fake_fit(converged=True, flags=(), curve=(9.8216, 9.8210, 9.8222), fixed=None, reduced_chi2=1.1):
    """A stored fit's fields that the reports read: converged, 80 autocorrelation times long; or
    not, 9.1 long at acceptance 0.07."""
    median, p16, p84 = curve
    kept, tau, acceptance = (240, 3.0, 0.3) if converged else (91, 10.0, 0.07)
    return SimpleNamespace(
        converged=converged,
        verdict="converged" if converged else "not converged",
        n_steps=kept + 100,
        discard=100,
        autocorr_time=np.array([tau, tau / 2]),
        acceptance_fraction=np.full(12, acceptance),
        flags=tuple(flags),
        reduced_chi2=reduced_chi2,
        names=("spin_period_s", "precession_angle_deg"),
        median=(9.87, 20.0),
        p16=(9.86, 15.0),
        p84=(9.88, 26.0),
        space=SimpleNamespace(fixed=dict(fixed or {"precession_period_s": 1620.0})),
        spin_periods={
            "conventions": {"light_curve": {"median": median, "p16": p16, "p84": p84}},
            "definitions": {"light_curve": "the light curve's repeat period"},
        },
    )


def fake_period(verdict="confident", period=9.8215, error=0.0004):
    return SimpleNamespace(verdict=verdict, best_period_s=period, uncertainty_s=error)


def test_a_converged_fit_that_agrees_with_a_confident_period_is_trusted():
    trust = assess(fake_fit(), fake_period())
    assert (trust.level, trust.reasons) == ("high", ())


@pytest.mark.parametrize(
    ("fit", "period", "level", "reason"),
    [
        (fake_fit(converged=False), fake_period(), "low", "chain not converged (9.1 autocorrelation times, 50 wanted)"),
        (fake_fit(flags=("model misfit: residuals ...",), reduced_chi2=7.3), fake_period(), "low", "reduced chi2 7.3"),
        (fake_fit(flags=("stuck walkers: 3 of 12",)), fake_period(), "medium", "stuck walkers"),
        (fake_fit(), fake_period("ambiguous harmonic"), "medium", "period search 'ambiguous harmonic'"),
        (fake_fit(), None, "medium", "no period search"),
        # 9.8216 +- 0.0006 against 9.80 +- 0.0004 is 30 sigma apart: a disagreement, no multiple.
        (fake_fit(), fake_period(period=9.80), "medium", "unlike the periodogram's"),
        # A fitted light curve at twice the periodogram's period (a body with two similar halves).
        (fake_fit(), fake_period(period=4.9108, error=0.0002), "medium", "2x the periodogram's"),
    ],
)
def test_each_doubt_lowers_the_trust_and_says_why(fit, period, level, reason):
    trust = assess(fit, period)
    assert trust.level == level
    assert any(reason in r for r in trust.reasons), trust.reasons


def test_a_fit_judged_by_an_older_rule_keeps_its_own_reason():
    # Stored as not converged, but healthy by today's numbers (the rule changed since): the
    # table quotes the stored verdict rather than an empty reason.
    fit = fake_fit()
    fit.converged, fit.verdict = False, "not converged: tau still drifting. Run more steps."
    assert assess(fit, fake_period()).reasons == ("chain not converged (tau still drifting)",)


def test_the_worst_doubt_sets_the_level():
    trust = assess(fake_fit(converged=False, flags=("stuck walkers: 3",)), fake_period("ambiguous harmonic"))
    assert trust.level == "low" and len(trust.reasons) == 3


def test_no_fit_has_no_trust_and_the_reason():
    assert assess(None, fake_period(), missing="fit failed: no orbital elements").text() == (
        "none: fit failed: no orbital elements"
    )


def test_spin_state_rows_put_the_axis_first_and_mark_fixed_values():
    rows = spin_state_rows(fake_fit())
    assert [r[0] for r in rows] == [
        "spin_period_s",
        "precession_period_s",
        "precession_angle_deg",
        "spin period (light_curve)",
    ]
    assert rows[0][1:3] == ("9.87 -0.01 +0.01", "s")
    assert rows[1][1] == "1620 (fixed)"
    assert rows[3][1] == "9.8216 -0.0006 +0.0006"
    assert axis_text(fake_fit()) == "P_pr 1620 (fixed) s, cone 20 +-5.5 deg"


def test_interval_of_a_missing_value():
    assert interval(float("nan"), 1.0, 2.0) == "-"


def test_sortable_table_with_links_and_row_classes():
    table = Table(
        ("pass", "period"),
        ((Link("a<b", "x.html#pass-a"), "9.8"), ("c", "-")),
        sortable=True,
        row_classes=("trust-high", "trust-none"),
    )
    page = Document("t").add(table).to_html()
    assert '<table class="sortable">' in page
    assert '<tr class="trust-high"><td><a href="x.html#pass-a">a&lt;b</a></td>' in page
    assert page.count("<script>") == 1
    assert "<script>" not in Document("t").add(Table(("a",), (("1",),))).to_html()
    with pytest.raises(ValueError, match="1 row classes for 2 rows"):
        Table(("a",), (("1",), ("2",)), row_classes=("x",))


@pytest.fixture(scope="module")
def surveyed_archive(tmp_path_factory):
    archive = Archive(tmp_path_factory.mktemp("archive"))
    archive.ingest([str(f) for f in REAL_FILES], progress=False)
    survey_periods(archive, processes=1, progress=False)
    return archive


def test_index_gives_a_reason_for_every_missing_value(surveyed_archive, tmp_path):
    rows = surveyed_archive.summaries()
    failed = rows[0].pass_id
    page = build_index(surveyed_archive, [], "quick", {failed: ("fits", "no orbital elements")}).to_html()
    cells = re.findall(r"<tr[^>]*>(.*?)</tr>", page, re.S)[1:]
    assert len(cells) == len(rows)
    for row in cells:
        values = re.findall(r"<td[^>]*>(.*?)</td>", row, re.S)
        assert len(values) == len(COLUMNS)
        why = values[COLUMNS.index("why")]
        assert values[COLUMNS.index("trust")] == "none"
        # No fit anywhere: every row says why, and a period-less row says why as well.
        assert "not fitted: no orbital elements" in why or "no fit named &#x27;quick&#x27;" in why
        if values[COLUMNS.index("period search (s, synodic)")] == "-":
            assert "no period" in why
    assert f"{failed}</td>" in page or f">{failed}</a>" in page
