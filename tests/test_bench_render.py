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
    from bench.render import cache_label, traced_build
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
