"""Injection-recovery coverage, reduced: truths drawn from the fit's prior, rendered and fitted
with the same model; the 16-84% intervals must hold the truth about 68% of the time.

The full study (20+ truths, the published five parameters plus jitter, the TOPEX model) is
bench/fit_coverage.py; this test keeps the cost under ~2 minutes: the analytic `lopsided`
body (no rotational symmetry, so no phase is ambiguous), four free parameters (spin period and
phase, precession phase and cone angle; precession period fixed), 10 truths.
"""

from __future__ import annotations

import numpy as np
import pytest

from ingest import read_file
from rsodb.fit.config import FitConfig
from rsodb.fit.coverage import coverage_bounds, coverage_study, window
from tests.conftest import TOPEX_PHV

N_TRUTHS = 10
CONFIG = {
    "name": "coverage",
    "model": {"shape": "lopsided", "n_sub": 1},
    "parameters": {
        "spin_period_s": {"kind": "uniform", "low": 9.76, "high": 9.96},
        "precession_period_s": 700.0,
        "jitter_mag": 0.0,
    },
    # Walkers start around the search's best point and move with the stretch move. Started from
    # the search's final population instead (init "population", DE moves), walkers sitting in
    # separate local modes accepted ~2% of proposals and stayed where they started.
    "sampler": {"n_walkers": 16, "n_steps": 800, "search_popsize": 10, "search_maxiter": 60, "init": "search"},
}


@pytest.mark.slow
def test_68_percent_intervals_hold_the_truth_about_68_percent_of_the_time(tmp_path):
    template = window(read_file(TOPEX_PHV)[0], 0.0, 30.0, bin_size=4)
    recoveries = coverage_study(
        template,
        FitConfig.from_dict(CONFIG),
        range(N_TRUTHS),
        noise_mag=0.02,
        chain_dir=tmp_path,
        processes=2,
        progress=False,
    )
    covered = np.array([list(r.covered.values()) for r in recoveries])
    assert covered.shape == (N_TRUTHS, 4)
    # For a calibrated posterior each of the 40 intervals holds its truth with probability 0.68:
    # the count is binomial (truths are independent; the four intervals of one truth are not,
    # which widens the spread a little). Its 3-sigma band is 0.68 +- 3 sqrt(0.68 * 0.32 / 40),
    # i.e. 0.46-0.90; a sampler stuck in its starting ball (intervals far too narrow) or in a
    # wrong mode lands well below it.
    low, high = coverage_bounds(covered.size)
    assert low <= covered.mean() <= high, f"pooled coverage {covered.mean():.2f} outside {low:.2f}-{high:.2f}"
    # No parameter may be covered in fewer than 3 of 10 truths (P = 0.003 for p = 0.68).
    assert covered.sum(axis=0).min() >= 3, covered.sum(axis=0)
