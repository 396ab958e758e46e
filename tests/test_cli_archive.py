"""The archive commands: rsodb ingest, ls, show, export, check, elements (through main([...]))."""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import ingest
from rsodb.cli import main
from tests.conftest import COSMOS2540_PHV, COSMOS2553_PHC, PROJECT_ROOT, REAL_FILES, TOPEX_PHV

TOPEX_ID = "22076-20240730T212240-V-derenivka"


@pytest.fixture
def archive_dir(tmp_path, shared_data, capsys):
    observations = tmp_path / "observations"
    observations.mkdir()
    for path in REAL_FILES:
        shutil.copy(path, observations / path.name)
    archive = tmp_path / "archive"
    assert main(["ingest", str(observations), "--archive", str(archive), "--no-progress"]) == 0
    capsys.readouterr()
    return archive


@pytest.mark.parametrize("command", ["ingest", "ls", "show", "export", "check", "elements"])
def test_every_command_has_help_with_an_example(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert "example:" in text and f"rsodb {command} " in text and "--archive" in text


def test_ingest_summary_and_exit_status(tmp_path, shared_data, capsys):
    archive = tmp_path / "archive"
    bad = tmp_path / "bad.phV"
    bad.write_text("# TLE:\n")
    status = main(["ingest", str(TOPEX_PHV), str(COSMOS2553_PHC), str(bad), "--archive", str(archive), "--no-progress"])
    captured = capsys.readouterr()
    assert status == 1  # one file failed
    assert "ingested 2 file(s) (3 pass(es))" in captured.out
    assert "0 already present, 1 failed" in captured.out
    assert f"  {bad}:" in captured.out  # file:line: reason, indented under "failed:"

    status = main(["ingest", str(TOPEX_PHV), "--archive", str(archive), "--no-progress", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert status == 0
    assert report["already_present"] == [str(TOPEX_PHV)] and report["ingested"] == [] and report["failed"] == []


def test_ingest_progress_bar_goes_to_stderr(tmp_path, shared_data, capsys):
    assert main(["ingest", str(COSMOS2540_PHV), "--archive", str(tmp_path / "a")]) == 0
    captured = capsys.readouterr()
    assert "ingest: 100%" in captured.err and "1/1" in captured.err
    assert "ingested 1 file(s)" in captured.out


def test_ls_table_and_json(archive_dir, capsys):
    assert main(["ls", "--archive", str(archive_dir)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == [
        "PASS",
        "ID",
        "NORAD",
        "NAME",
        "SITE",
        "BAND",
        "START",
        "UTC",
        "DURATION",
        "S",
        "POINTS",
    ]
    assert len(lines) == 6
    topex = next(line for line in lines if line.startswith(TOPEX_ID))
    # duration = last - first mid-exposure time of the real file: 2319 samples at ~0.2 s
    assert topex.split()[-3:] == ["21:22:40", "464.2", "2320"]
    assert "TOPEX/POSEIDON" in topex and "Derenivka" in topex

    assert main(["ls", "--archive", str(archive_dir), "--json", "--norad", "51511", "--band", "B"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["pass_id"] == "51511-20250130T171941-B-uzhhorod"
    assert (row["norad"], row["site"], row["band"], row["n_points"]) == (51511, "Uzhhorod", "B", 692)
    assert row["start_utc"] == "2025-01-30T17:19:41.500Z"
    assert row["duration_s"] == 699.0  # 17:19:41.5 .. 17:31:20.5 (rows roll on without gaps at 1 s)


def test_ls_missing_archive_is_a_clear_error(tmp_path, capsys):
    assert main(["ls", "--archive", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rsodb ls: error: no archive at ") and "create one with 'rsodb ingest" in err
    assert not (tmp_path / "nowhere").exists()


def test_show_text_json_and_plot(archive_dir, tmp_path, capsys):
    assert main(["show", "22076", "--archive", str(archive_dir)]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"pass       {TOPEX_ID}  (version 1, current)")
    assert "A = 19.400 mag, airmass term +0.100" in text and "sign error" in text  # PROVENANCE.md
    assert "1 22076U 92052A" in text

    plot = tmp_path / "lc.png"
    assert main(["show", "51511-20250130T171941-V", "--archive", str(archive_dir), "--json", "--plot", str(plot)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["n_points"], info["n_valid"], info["exposure_s"], info["band"]) == (692, 692, 1.0, "V")
    assert info["site"]["name"] == "Uzhhorod" and info["results"] == {"periods": {}, "fits": {}}
    assert info["elements_source"] is None and info["rows_set_aside"] == []
    # The .phc file carries no elements and none were given: said with the pass, with the fix.
    (warning,) = info["warnings"]
    assert warning["reason"].startswith("no orbit: the file carries no orbital elements")
    assert "rsodb elements add FILE" in warning["reason"]
    assert plot.stat().st_size > 10_000 and plot.read_bytes()[:4] == b"\x89PNG"

    assert main(["show", "51511", "--archive", str(archive_dir)]) == 2
    assert "matches 3 passes" in capsys.readouterr().err


def test_export_csv_round_trip(archive_dir, tmp_path, capsys):
    out = tmp_path / "topex.csv"
    assert main(["export", "22076", "--archive", str(archive_dir), "--format", "csv", "--out", str(out)]) == 0
    frame = pd.read_csv(out, comment="#", index_col="time_utc", float_precision="round_trip")
    (topex,) = ingest.read_file(TOPEX_PHV)
    assert len(frame) == len(topex)
    assert list(frame.columns) == [
        "mag_file",
        "mag_corrected",
        "mag_err",
        "flux",
        "flux_err",
        "az_deg",
        "el_deg",
        "range_km",
        "saturated",
        "valid",
    ]
    times = pd.to_datetime(frame.index, format="ISO8601").tz_localize(None).values
    np.testing.assert_array_equal(times, topex.time_utc)  # to the nanosecond
    # The file prints 3 decimals (magnitudes, angles, range) and 4 (flux): the CSV keeps them all.
    for column, attribute in (("mag_file", "mag"), ("mag_err", "mag_err"), ("flux", "flux"), ("el_deg", "el_deg")):
        np.testing.assert_array_equal(frame[column].to_numpy(), getattr(topex, attribute))
    np.testing.assert_array_equal(frame["range_km"].to_numpy(), topex.range_km)
    # The corrected magnitude is computed: 4 decimals, half a unit of the last one at most.
    assert np.max(np.abs(frame["mag_corrected"].to_numpy() - topex.mag_corrected)) <= 5e-5
    data = [line.split(",") for line in out.read_text().splitlines() if not line.startswith(("#", "time_utc"))]
    assert all(re.fullmatch(r"-?\d+\.\d{4}", row[2]) for row in data)  # no 16-digit floats
    np.testing.assert_array_equal(frame["saturated"].to_numpy(), topex.saturated)

    # rsodb ingests its own CSV: into the archive it came from, a duplicate source of the pass;
    # into a new one, the same pass id and values.
    assert main(["ingest", str(out), "--archive", str(archive_dir), "--no-progress", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["duplicates"][0]["pass_ids"] == [TOPEX_ID] and report["ingested"] == []
    assert main(["ingest", str(out), "--archive", str(tmp_path / "new"), "--no-progress", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ingested"][0]["pass_ids"] == [TOPEX_ID]

    assert main(["export", "22076", "--archive", str(archive_dir), "--format", "csv", "--out", str(out)]) == 2
    assert "exists; choose another --out or add --force" in capsys.readouterr().err

    assert main(["export", "44517", "--archive", str(archive_dir)]) == 0  # CSV by default
    stdout = capsys.readouterr().out
    assert len(pd.read_csv(io.StringIO(stdout), comment="#")) == 2535


def test_ingest_of_a_generic_csv(tmp_path, shared_data, capsys):
    """A table from another tool: time, mag, mag_err under a small header."""
    (cosmos,) = ingest.read_file(COSMOS2540_PHV)
    rows = [
        f"{t}Z,{m:.3f},{e:.3f}"
        for t, m, e in zip(np.datetime_as_string(cosmos.time_utc, unit="ms"), cosmos.mag, cosmos.mag_err)
    ]
    path = tmp_path / "other_tool.csv"
    path.write_text(
        "# object = 44517\n# band = V\n# exposure_s = 0.1\n# site = Derenivka\ntime_utc,mag,mag_err\n"
        + "\n".join(rows)
        + "\n"
    )
    archive = tmp_path / "archive"
    assert main(["ingest", str(path), "--archive", str(archive), "--no-progress", "--json"]) == 0
    (item,) = json.loads(capsys.readouterr().out)["ingested"]
    assert item["pass_ids"] == ["44517-20250130T173650-V-derenivka"]
    assert main(["show", "44517", "--archive", str(archive), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["n_points"], info["source_format"], info["mag_median"]) == (2535, "csv", float(np.median(cosmos.mag)))
    assert info["range_km_min"] is None and "orbit" not in info  # no geometry columns: none invented
    # A column rsodb does not know is refused, not ignored.
    path.write_text(path.read_text().replace("time_utc,mag,mag_err", "time_utc,mag,mag_err_v"))
    assert main(["ingest", str(path), "--archive", str(archive), "--no-progress"]) == 1
    assert "column 'mag_err_v' is not one rsodb reads" in capsys.readouterr().out


def test_a_generic_csv_with_other_tools_names(tmp_path, capsys):
    # issue 19: "a generic CSV of time, mag, mag_err with a small header of object, site, band,
    # exposure": the column 'time' and the header key 'exposure' (seconds) are read as rsodb's.
    path = tmp_path / "generic.csv"
    header = "# object = 44517\n# site = Derenivka\n# band = V\n# exposure = 0.1\n"
    rows = "".join(f"2025-02-01 17:00:0{k}.5,{6.5 + 0.01 * k:.2f},0.01\n" for k in range(5))
    path.write_text(header + "time,mag,mag_err\n" + rows)
    archive = str(tmp_path / "archive")
    assert main(["ingest", str(path), "--archive", archive, "--no-progress", "--json"]) == 0
    (item,) = json.loads(capsys.readouterr().out)["ingested"]
    assert item["pass_ids"] == ["44517-20250201T170000-V-derenivka"]
    assert main(["show", "44517", "--archive", archive, "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["exposure_s"], info["n_points"], info["mag_max"]) == (0.1, 5, 6.54)
    # What is missing is named with an example of its own kind.
    path.write_text(header.replace("# exposure = 0.1\n", "") + "time,mag\n" + rows)
    assert main(["ingest", str(path), "--archive", archive, "--no-progress"]) == 1
    assert f"{path}:4: the CSV has no mag_err column" in capsys.readouterr().out
    path.write_text(header.replace("# exposure = 0.1\n", "") + "time,mag,mag_err\n" + rows)
    assert main(["ingest", str(path), "--archive", archive, "--no-progress"]) == 1
    assert "no '# exposure_s = ' line; add it (e.g. '# exposure_s = 0.1')" in capsys.readouterr().out


def test_default_archive_from_the_environment_or_the_directory(archive_dir, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("RSODB_ARCHIVE", str(archive_dir))
    assert main(["ls", "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 5
    monkeypatch.delenv("RSODB_ARCHIVE")
    monkeypatch.chdir(tmp_path)  # archive_dir is ./archive here
    assert main(["show", "44517"]) == 0
    assert capsys.readouterr().out.startswith("pass       44517-20250130T173650-V-derenivka")
    monkeypatch.chdir(tmp_path / "observations")
    assert main(["ls"]) == 2
    err = capsys.readouterr().err
    assert "no archive at 'archive'" in err and "comes from the default; give --archive DIR or set RSODB_ARCHIVE" in err
    # The report commands take the same default (no period results stored yet: a clear error).
    monkeypatch.chdir(tmp_path)
    assert main(["report", "periods", "--object", "44517", "--out", "r.html"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rsodb report periods: error:") and "rsodb periods" in err


def test_export_eossa_reads_back(archive_dir, tmp_path, monkeypatch, capsys):
    from astropy.io import fits

    monkeypatch.chdir(tmp_path)
    assert main(["export", "22076", "--archive", str(archive_dir), "--format", "eossa"]) == 0
    path = tmp_path / f"{TOPEX_ID}.eossa.fits"
    (topex,) = ingest.read_file(TOPEX_PHV)
    with fits.open(path) as hdus:
        header, table = hdus[1].header, hdus[1].data
        assert header["VERS"] == "3.1.1" and header["OBJNUM"] == 22076 and header["SPFNAM1"] == "V"
        assert header["TELLAT"] == topex.site.lat_deg and header["TELESCOP"] == "Derenivka"
        assert header["TLELN1"] == topex.tle[-2][2:] and len(header["TLELN2"]) == 67
        assert len(table) == 2320
        # JD of mid-exposure: float64 resolves ~40 us at JD 2.46e6; compare to 0.1 ms.
        jd_ns = np.round((table["JD_Mid_Exp"] - 2440587.5) * 86400e9).astype("int64")
        assert np.max(np.abs(jd_ns - topex.time_utc.view("int64"))) < 100_000
        assert table["UTC_Begin_exp"][0] == "2024-07-30T21:22:39.908"  # mid 40.0088 - 0.1 s, ms floor
        np.testing.assert_array_equal(table["Mag_Range_Norm"], topex.mag_corrected)  # sign error fixed
        np.testing.assert_allclose(
            table["Mag_Exo_Atm"] - table["Mag_Range_Norm"], 5 * np.log10(topex.range_km / 1000.0), atol=1e-12
        )
        np.testing.assert_array_equal(table["Tel_Obj_Range"], topex.range_km * 1000.0)
        np.testing.assert_array_equal(table["Eph_AZ_EL"][:, 1], topex.el_deg)
        assert np.all(table["Met_RA_DE"] == -9999.0)


def test_names_with_spaces_dots_and_shell_characters(tmp_path, shared_data, capsys):
    observations = tmp_path / "odd names"
    observations.mkdir()
    names = ["a b.phV", "..hidden-looking..phV".lstrip("."), "x..y.phV", "$(touch pwned);`id`|&.phV", "-n.phV"]
    for name, source in zip(names, [TOPEX_PHV, COSMOS2540_PHV, REAL_FILES[2], TOPEX_PHV, COSMOS2540_PHV]):
        shutil.copy(source, observations / name)
    (observations / "sub").mkdir()
    os.symlink("..", observations / "sub" / "loop")  # a symlink loop back to the parent
    os.symlink(observations, observations / "self")
    archive = tmp_path / "archive"
    status = main(["ingest", str(observations), "--archive", str(archive), "--no-progress", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert status == 0 and report["failed"] == []
    # three distinct contents; the copies of TOPEX and COSMOS 2540 under other names are found
    # already present (same SHA-256), not stored twice
    assert len(report["ingested"]) == 3 and len(report["already_present"]) == 2
    assert not (tmp_path / "pwned").exists() and not Path("pwned").exists()
    assert main(["ls", "--archive", str(archive), "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 3


@pytest.mark.parametrize("path", [TOPEX_PHV, COSMOS2540_PHV], ids=["topex", "cosmos2540"])
def test_eossa_geometry_against_authorities(path, shared_data):
    """RA/Dec and phase angle against SGP4 + skyfield from the file's TLE; the Sun against astropy.

    The file's Az/El were computed by PyEphem from the same TLE; they agree with SGP4 + skyfield
    to 0.0025 deg (measured on both files), so 0.01 deg is four times the input's own accuracy.
    """
    import datetime

    from astropy.coordinates import AltAz, EarthLocation, get_body
    from astropy.time import Time
    import astropy.units as u
    from skyfield.api import EarthSatellite, wgs84

    from raycast.geometry import ephemeris
    from raycast.geometry.orbit import Satellite
    from raycast.geometry.pass_geometry import PassGeometry
    from rsodb.archive.eossa import eossa_hdus

    (observed,) = ingest.read_file(path)
    table = eossa_hdus(observed)[1].data
    ts = ephemeris.timescale()
    times = ts.from_datetimes(
        [t.replace(tzinfo=datetime.UTC) for t in observed.time_utc.astype("datetime64[us]").astype(object)]
    )
    site = wgs84.latlon(observed.site.lat_deg, observed.site.lon_deg, elevation_m=observed.site.elevation_m)
    ra, dec, _ = (EarthSatellite(*observed.tle[-2:], ts=ts) - site).at(times).radec()
    ra1, dec1, ra2, dec2 = map(
        np.radians, (table["Eph_RA_DE"][:, 0], table["Eph_RA_DE"][:, 1], ra._degrees, dec.degrees)
    )
    separation_deg = np.degrees(
        np.arccos(np.clip(np.sin(dec1) * np.sin(dec2) + np.cos(dec1) * np.cos(dec2) * np.cos(ra1 - ra2), -1.0, 1.0))
    )
    assert separation_deg.max() < 0.01

    geometry = PassGeometry.compute(Satellite.from_tle(observed.tle), observed.site, observed.time_utc)
    assert np.max(np.abs(table["Solar_Phase_Ang"] - geometry.phase_angle_deg)) < 0.01

    # The Sun from astropy's own ephemeris and Earth rotation, an implementation independent of
    # skyfield: they agree to 1e-4 deg; 1e-3 deg allows for astropy's bundled IERS tables.
    every_100th = slice(None, None, 100)
    location = EarthLocation.from_geodetic(
        observed.site.lon_deg * u.deg, observed.site.lat_deg * u.deg, observed.site.elevation_m * u.m
    )
    when = Time(observed.time_utc[every_100th])
    sun = get_body("sun", when, location).transform_to(AltAz(obstime=when, location=location))
    sun_az_el = table["Sun_AZ_EL"][every_100th]
    assert np.max(np.abs((sun_az_el[:, 0] - sun.az.deg + 180.0) % 360.0 - 180.0)) < 1e-3
    assert np.max(np.abs(sun_az_el[:, 1] - sun.alt.deg)) < 1e-3


def test_ingest_of_a_directory_without_observations_says_so(tmp_path, capsys):
    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / "image_0001.fits").write_bytes(b"SIMPLE  =                    T")
    assert main(["ingest", str(tmp_path / "frames"), "--archive", str(tmp_path / "a"), "--no-progress"]) == 0
    assert capsys.readouterr().out.strip() == (
        "no observation files found (directories are searched for *.ph<letter> files; name other files explicitly)"
    )


def test_the_command_line_parser_loads_no_archive_code():
    # 'rsodb --help' and argument errors stay fast: the commands reach the archive (and h5py)
    # through the lazy front door, only when they run.
    code = (
        "import sys; from rsodb.cli import build_parser; build_parser(); "
        "print(sorted(m for m in sys.modules if m.startswith(('rsodb.archive', 'h5py', 'tqdm'))))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=PROJECT_ROOT)
    assert done.stdout.strip() == "[]"
