"""Campaigns on a Dask LocalCluster: every pass fitted and stored, finished fits skipped on
rerun, failures reported per pass, and the HTML campaign report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ingest import read_file
from rsodb.archive import Archive
from rsodb.campaign.fit_campaign import NO_ORBIT, run_campaign, run_campaigns
from rsodb.cli import main
from rsodb.fit.config import FitConfig
from rsodb.fit.coverage import inject, window
from rsodb.fit.runner import FitProblem
from rsodb.report.index_page import build_index
from tests.conftest import TOPEX_PHV

TRUTH = {
    "spin_period_s": 9.86,
    "spin_phase_deg": 100.0,
    "precession_period_s": 700.0,
    "precession_phase_deg": 180.0,
    "precession_angle_deg": 35.0,
}
FIT = {
    "name": "camp",
    "model": {"shape": "ellipsoid", "n_sub": 1},
    "parameters": {"spin_period_s": {"kind": "uniform", "low": 9.5, "high": 10.2}},
    "sampler": {"n_walkers": 12, "n_steps": 40, "search_maxiter": 8, "search_popsize": 5, "seed": 1},
}


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    observed = read_file(TOPEX_PHV)[0]
    archive = Archive(tmp_path_factory.mktemp("campaign") / "archive")
    passes = []
    for k, start_s in enumerate((0.0, 200.0)):
        template = window(observed, start_s, 20.0, bin_size=4)
        model = FitProblem.build(template, FitConfig.from_dict(FIT)).posterior.model
        passes.append(inject(template, model, TRUTH, noise_mag=0.02, rng=np.random.default_rng(k)))
    archive.add(passes)
    return archive


@pytest.mark.slow
def test_campaign_fits_every_pass_then_skips_them_and_reports(archive, tmp_path, capsys):
    config = FitConfig.from_dict(FIT)
    first = run_campaign(archive, 22076, config=config, n_workers=2, progress=False)
    ids = [row.pass_id for row in archive.summaries(22076)]
    assert len(ids) == 2 and first.ok
    assert sorted(r["pass_id"] for r in first.fitted) == sorted(ids)
    assert all(archive.result_names(p, "fits") == ["camp"] for p in ids)
    assert first.scheduler.startswith("tcp://") or first.scheduler.startswith("inproc://")

    again = run_campaign(archive, 22076, config=config, n_workers=2, progress=False)
    assert again.fitted == () and sorted(again.skipped) == sorted(ids)

    # The command line: a rerun skips both and writes the report.
    report = tmp_path / "fits.html"
    status = main(
        [
            "campaign",
            "--archive",
            str(archive.path),
            "--object",
            "22076",
            "--name",
            "camp",
            "--steps",
            "40",
            "--report",
            str(report),
            "--json",
        ]
    )
    outcome = json.loads(capsys.readouterr().out)
    assert status == 0 and outcome["fitted"] == [] and len(outcome["skipped"]) == 2
    page = report.read_text()
    assert all(p in page for p in ids) and page.count("<img") >= 4  # period, parameters, 2 passes


def test_campaign_reports_a_failed_pass_and_carries_on(archive):
    # No stored period: the default spin-period prior cannot be built, for every pass.
    config = FitConfig.from_dict(dict(FIT, name="noperiod", parameters={}))
    outcome = run_campaign(archive, 22076, config=config, n_workers=1, progress=False)
    assert not outcome.ok and len(outcome.failed) == 2
    assert all("run 'rsodb periods' on it first" in error for _, error in outcome.failed)


def test_campaigns_share_one_client_and_report_per_group(archive):
    # Two configurations side by side (as the pipeline runs one per model): one fits its pass,
    # the other fails on its pass; each outcome holds only its own group's passes.
    first, second = [row.pass_id for row in archive.summaries(22076)]
    good = FitConfig.from_dict(dict(FIT, name="groupgood"))
    bad = FitConfig.from_dict(dict(FIT, name="groupbad", parameters={}))
    outcomes = run_campaigns(archive, [(good, [first]), (bad, [second])], n_workers=2, progress=False)
    assert [o.name for o in outcomes] == ["groupgood", "groupbad"]
    assert [r["pass_id"] for r in outcomes[0].fitted] == [first] and outcomes[0].ok
    assert outcomes[1].fitted == () and [p for p, _ in outcomes[1].failed] == [second]
    assert archive.result_names(first, "fits").count("groupgood") == 1
    assert "groupbad" not in archive.result_names(second, "fits")
    assert outcomes[0].scheduler == outcomes[1].scheduler and 0 < outcomes[0].elapsed_s


def test_campaign_needs_a_selection(archive, capsys):
    with pytest.raises(ValueError, match="a campaign needs an object"):
        run_campaign(archive, config=FitConfig.from_dict(FIT), progress=False)
    assert main(["campaign", "--archive", str(archive.path), "--passes", "99999-nope"]) == 2
    assert "rsodb campaign: error:" in capsys.readouterr().err


def _csv_without_orbit(path, start_utc: str) -> None:
    """A CSV light curve with neither elements nor Az/El/range columns: no geometry at all."""
    times = np.datetime64(start_utc) + np.arange(40) * np.timedelta64(1, "s")
    rows = "".join(f"{t}Z,{5 + 0.1 * np.sin(k):.3f},0.02\n" for k, t in enumerate(times))
    path.write_text("# object = 51511\n# band = V\n# exposure_s = 1\n# site = Uzhhorod\ntime_utc,mag,mag_err\n" + rows)


def test_passes_without_an_orbit_are_named_not_sent_to_dask(tmp_path):
    # issue 19: the main job printed Dask's "Compute Failed" tracebacks for passes without
    # elements, and its index showed "-" for them with no reason. A .phc pass now has the track
    # of its Az/El/range columns (tests/test_track.py); a table with neither has no orbit.
    files = [tmp_path / "a.csv", tmp_path / "b.csv"]
    _csv_without_orbit(files[0], "2025-01-30T17:19:41")
    _csv_without_orbit(files[1], "2025-01-31T17:19:41")
    archive = Archive(tmp_path / "archive")
    archive.ingest(files, progress=False)
    ids = [row.pass_id for row in archive.summaries(51511)]
    assert len(ids) == 2
    (outcome,) = run_campaigns(archive, [(FitConfig.from_dict(FIT), ids)], progress=False)
    assert outcome.scheduler == "nothing to run"  # no cluster was started
    assert outcome.failed == tuple((pass_id, NO_ORBIT) for pass_id in ids) and outcome.fitted == ()
    missing = {pass_id: ("fits", error) for pass_id, error in outcome.failed}
    page = build_index(archive, [], "camp", missing).to_html()
    assert page.count("not fitted: no orbital elements and no Az/El/range columns") == 2
    assert "rsodb elements add" in page
