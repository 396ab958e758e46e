"""bench/render.py's measurement of the fast path's build: its traced peak is the build's own,
not numba's compiler's."""

from __future__ import annotations

from pathlib import Path
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


@pytest.mark.slow  # two builds of the bus
def test_traced_build_measures_a_build_that_compiled_nothing():
    from bench.render import compiled_loops, traced_build
    from raycast.cycles.comparison import comparison_scenes

    bus = comparison_scenes(ROOT.parent / "shared" / "data" / "models", ("bus_wings",))["bus_wings"].scene
    cache, wall, cpu, peak_mb = traced_build(bus, 8)
    loops = compiled_loops()
    assert loops > 0  # the build ran the renderer's compiled loops, and they are counted
    # Built once more: nothing left to compile, and the same peak to 5% (the build is deterministic).
    again = traced_build(bus, 8)
    assert compiled_loops() == loops
    assert again[3] == pytest.approx(peak_mb, rel=0.05)
    # The peak holds the tables, which the cache keeps, and the build's temporaries above them.
    assert peak_mb > cache.nbytes / 1e6
    assert wall > 0 and cpu > 0


def test_the_normal_options_reach_the_build_and_name_the_rows():
    from bench.render import cache_label, cache_suffix, traced_build
    from raycast.cycles.comparison import comparison_scenes

    plate = comparison_scenes(ROOT.parent / "shared" / "data" / "models", ("plate",))["plate"].scene
    assert traced_build(plate, 4, normal_step_deg=6.0)[0].normal_step_deg == pytest.approx(6.0, abs=1e-9)
    assert traced_build(plate, 4)[0].normal_step_deg != pytest.approx(6.0, abs=0.1)  # the material's own rule
    assert traced_build(plate, 4, normal_bins_per_step=1.5)[0].normal_bins_per_step == 1.5
    assert traced_build(plate, 4, normal_bins_per_step=None)[0].normal_bins_per_step == 3.0
    options = {"normal_step_deg": None, "normal_bins_per_step": 1.0}
    assert cache_label(options) == ["1 normal bins per step"]
    assert cache_label(options, title=True) == ["shading classes 1 per normal step"]
    assert traced_build(plate, 4, element_size_m=0.2)[0].element_size_m == 0.2
    assert cache_label({"element_size_m": 0.2}) == ["elements 0.2 m"]
    tail = {"edge_rays_per_side": 2, "coarse_bin_ratio": 1 / 3, "far_lobe_widths": 2.0}
    cache = traced_build(plate, 4, **tail)[0]
    assert (cache.edge_rays_per_side, cache.coarse_bin_ratio, cache.far_lobe_widths) == (2, 1 / 3, 2.0)
    assert cache_label(tail) == ["2 x 2 edge rays", "coarse bins at 0.333", "far pairs beyond 2 lobes"]
    assert cache_suffix({"normal_bins_per_step": 1.0, "element_size_m": None, **tail}) == (
        "_normal_bins_1_edge_rays_2_tail_0.333_far_2"
    )
    assert cache_suffix({"normal_step_deg": None}) == ""


def test_the_verdict_judges_the_cycles_ratio_by_the_target_and_names_the_aim():
    from bench.render import verdict

    def rows(cycles_cpu_s):
        # The direct renderer at 0.004 mag in 0.1 s; Cycles from 0.02 to 0.002 mag, its time
        # at 0.004 mag interpolated log-log between its two settings.
        direct = {"method": "direct", "setting": "r/150", "error_mag": 0.004, "cpu_s": 0.1, "wall_s": 0.06}
        cycles = [
            {"method": "cycles", "setting": "4 spp", "error_mag": 0.02, "cpu_s": cycles_cpu_s / 10, "wall_s": 1.0},
            {"method": "cycles", "setting": "64 spp", "error_mag": 0.002, "cpu_s": cycles_cpu_s * 2, "wall_s": 1.0},
        ]
        return [direct, *cycles]

    # Cycles' time at 0.004 mag, log-log between (0.002 mag, 2c) and (0.02 mag, c / 10):
    # 2c * 0.05**(log 2 / log 10) = 0.81c, so the ratio is 8.1c.
    assert "meets 20x, under the 100x aim" in verdict(rows(5.0), "direct", 0.005, 1.0)  # 40x
    assert verdict(rows(50.0), "direct", 0.005, 1.0).endswith(": 406x (meets 20x)")
    assert "MISSES 20x" in verdict(rows(1.0), "direct", 0.005, 1.0)  # 8x
