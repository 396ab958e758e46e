"""``rsodb render``: a stored pass rendered, compared, plotted and shown as frames."""

import json

import pytest

from rsodb.archive import Archive
from rsodb.cli import main
from tests.conftest import TLES, TOPEX_PHV


@pytest.mark.slow
def test_render_command_json_plot_and_frames(tmp_path, capsys):
    archive = tmp_path / "archive"
    Archive(archive, create=True).ingest([TOPEX_PHV], progress=False)
    pass_id = Archive(archive).passes(norad=22076)[0].pass_id
    plot, frames = tmp_path / "lc.png", tmp_path / "frames"
    status = main(
        [
            "render",
            "--model",
            "topex",
            "--pass",
            pass_id[:12],
            "--archive",
            str(archive),
            "--period-s",
            "9.86",
            "--precession-period-s",
            "689",
            "--precession-angle-deg",
            "35",
            "--method",
            "cached",
            "--json",
            "--plot",
            str(plot),
            "--frames-png",
            str(frames),
            "--frames",
            "2",
        ]
    )
    assert status == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["n_frames"] == 2320 and summary["method"] == "cached"
    # The model is shape only (albedos are guesses): its offset to the observations is finite and
    # its residual RMS below the light curve's own 0.1-3 mag swing.
    assert summary["residual_rms_mag"] < 3.0
    assert plot.stat().st_size > 10_000 and len(list(frames.glob("*.png"))) == 2


def test_render_command_unknown_model(tmp_path, capsys):
    archive = tmp_path / "archive"
    Archive(archive, create=True).ingest([TOPEX_PHV], progress=False)
    pass_id = Archive(archive).passes()[0].pass_id
    assert main(["render", "--model", "hubble", "--pass", pass_id, "--archive", str(archive)]) == 2
    assert "model 'hubble' is neither a known model" in capsys.readouterr().err


@pytest.mark.slow
def test_render_command_for_a_tle_site_and_span(tmp_path, capsys):
    # No archive: TOPEX from the shared TLE list, seen from Derenivka over 60 s of the observed
    # pass of 2024-07-30 (the list also holds older TOPEX sets and another object).
    plot, frames = tmp_path / "span.png", tmp_path / "frames"
    status = main(
        [
            "render",
            "--model",
            "topex",
            "--tle",
            str(TLES),
            "--norad",
            "22076",
            "--site",
            "derenivka",
            "--start",
            "2024-07-30T21:24:00",
            "--duration",
            "60",
            "--cadence",
            "0.5",
            "--period-s",
            "9.86",
            "--method",
            "cached",
            "--json",
            "--plot",
            str(plot),
            "--frames-png",
            str(frames),
            "--frames",
            "2",
        ]
    )
    assert status == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["n_frames"] == 121 and summary["norad"] == 22076
    # The set nearest the span: epoch 2024 day 212.512 (2024-07-30 12:17 UTC).
    assert summary["tle_epoch_utc"].startswith("2024-07-30T12:17")
    # The observed pass is above the horizon and sunlit throughout these 60 s.
    assert summary["frames_above_horizon"] == 121 and summary["frames_sunlit"] == 121
    # TOPEX at ~1300-2000 km was observed between magnitude ~4 and ~9 (PROVENANCE: the .phV
    # file); the model's range of magnitudes along the span lies in that band, and reducing to
    # 1000 km brightens it (the range exceeds 1000 km).
    assert 2.0 < summary["mag_min"] < summary["mag_max"] < 11.0
    assert summary["mag_1000km_min"] < summary["mag_min"]
    assert plot.stat().st_size > 10_000 and len(list(frames.glob("*.png"))) == 2


def test_render_command_tle_errors_name_the_fix(tmp_path, capsys):
    base = ["render", "--model", "topex", "--tle", str(TLES), "--start", "2024-07-30T21:24:00", "--duration", "10"]
    assert main(base) == 2
    assert "holds element sets of 2 objects (22076, 40358); pick one with --norad" in capsys.readouterr().err
    assert main(base + ["--norad", "22076", "--site", "mars"]) == 2
    assert "unknown site 'mars'" in capsys.readouterr().err
    assert main(base + ["--norad", "22076", "--site", "48.5,22.4"]) == 2
    assert "nor LAT,LON,H" in capsys.readouterr().err
    assert main(base + ["--norad", "99999"]) == 2
    assert "no element set of NORAD 99999" in capsys.readouterr().err
    assert main(["render", "--model", "topex", "--pass", "x"]) == 2
    assert "--pass needs --archive DIR" in capsys.readouterr().err
