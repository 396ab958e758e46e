"""Shared fixtures: where the real data of ../shared/data lives."""
from __future__ import annotations

from pathlib import Path

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


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(f"real data not found at {SHARED_DATA}; the project expects ../shared beside it")
    return SHARED_DATA
