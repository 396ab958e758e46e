"""bench/cache_frontier.py: its settings' grammar and a run on the plate scene."""

from __future__ import annotations

import pytest

from bench.cache_frontier import main, parse_setting


def test_settings_read_as_build_options():
    assert parse_setting("default", 8.0) == {}
    assert parse_setting("elements=r/40,bins=1", 8.0) == {"element_size_m": 0.2, "normal_bins_per_step": 1.0}
    assert parse_setting("elements=0.3,step=6", 8.0) == {"element_size_m": 0.3, "normal_step_deg": 6.0}
    assert parse_setting("grid=64,edge=2,bins=1", 8.0) == {
        "grid_size": 64,
        "edge_rays_per_side": 2,
        "normal_bins_per_step": 1.0,
    }
    assert parse_setting("tail=1/4,far=2", 8.0) == {"coarse_bin_ratio": 0.25, "far_lobe_widths": 2.0}
    with pytest.raises(SystemExit, match="'size=48' is not one of bins=, elements=, step=, grid=, edge=, tail="):
        parse_setting("size=48", 8.0)
    with pytest.raises(SystemExit, match="'grid=4.5': grid takes a whole number"):
        parse_setting("grid=4.5", 8.0)


def test_a_run_on_the_plate_prints_every_setting_and_its_error(capsys):
    assert main(["--scene", "plate", "--settings", "default;elements=r/10", "--repeats", "1", "--no-record"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = [line for line in out if " mag RMS " in line]
    assert [line.split(":")[0] for line in rows] == ["default", "elements=r/10"]
    # A plate has no shadows: the fast path is the direct renderer's equal to the pixel error.
    assert all(float(line.split(" mag RMS")[0].split()[-1]) < 0.01 for line in rows)
    assert out[-1].startswith("settings meeting both targets: ")
