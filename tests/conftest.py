"""Shared fixtures: where the real data of ../shared/data lives.

When ../shared is missing, the tests that read it are skipped with a message saying where it
should be; every other test runs.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

PROJECT_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = (PROJECT_ROOT / ".." / "shared" / "data").resolve()
OBSERVATIONS = SHARED_DATA / "observations"
MODELS = SHARED_DATA / "models"
TLES = SHARED_DATA / "tle" / "tles.txt"

TOPEX_PHV = OBSERVATIONS / "result_22076_20240730_UT212240.phV"
COSMOS2540_PHV = OBSERVATIONS / "result_44517_20250130_UT173650.phV"
COSMOS2553_JD_PHV = OBSERVATIONS / "51511_20250311_UT173120_OES30.phV"
COSMOS2553_PHC = OBSERVATIONS / "51511_250130_1719.phc"
REAL_CCD_PHOT = [TOPEX_PHV, COSMOS2540_PHV, COSMOS2553_JD_PHV]
REAL_FILES = REAL_CCD_PHOT + [COSMOS2553_PHC]

MISSING_SHARED = (
    f"real data not found at {SHARED_DATA}: clone the project beside the 'shared' folder (../shared/data) "
    "to run this test"
)


@pytest.fixture(scope="session")
def shared_shapes(tmp_path_factory) -> Path:
    """A shape-cache directory (rsodb.fit.shape_store) that every test of the run shares, both
    pytest-xdist workers included: the paper mesh's cache takes ~50 s to build and two tests
    need the same one. The store locks a key while it builds, so a second worker waits for the
    first instead of building it again."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    path = root / "shared_shapes"
    path.mkdir(exist_ok=True)
    return path


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(MISSING_SHARED)
    return SHARED_DATA


def _reads_missing_shared_data(excinfo) -> bool:
    """True when a test failed only because a file under ../shared/data is not there."""
    if SHARED_DATA.is_dir() or excinfo is None:
        return False
    error = excinfo.value
    while error is not None:
        if str(SHARED_DATA) in str(error) or str(SHARED_DATA) in str(getattr(error, "filename", "")):
            return True
        error = error.__cause__ or error.__context__
    return False


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    # A test (or its fixture) that opens a file of ../shared/data is skipped, not failed, when the
    # folder is missing; any other failure stands.
    outcome = yield
    report = outcome.get_result()
    if report.failed and _reads_missing_shared_data(call.excinfo):
        report.outcome = "skipped"
        report.longrepr = (str(item.path), item.location[1] or 0, f"Skipped: {MISSING_SHARED}")


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    # A test module that reads ../shared/data when it is imported is skipped as a whole.
    outcome = yield
    report = outcome.get_result()
    if report.failed and not SHARED_DATA.is_dir() and str(SHARED_DATA) in str(report.longrepr):
        report.outcome = "skipped"
        report.longrepr = (str(collector.path), 0, f"Skipped: {MISSING_SHARED}")


def sun_and_observer_at_pass_phases(rng, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) unit sun and observer directions at random orientations, phase angles 20-100 deg
    as on a pass."""
    sun = rng.normal(size=(n, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    tilt = np.deg2rad(rng.uniform(20.0, 100.0, n))
    side = np.cross(sun, rng.normal(size=(n, 3)))
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    return sun, np.cos(tilt)[:, None] * sun + np.sin(tilt)[:, None] * side
