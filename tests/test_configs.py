"""The fit configurations shipped in configs/ load, and say what the code does."""

import pytest

from rsodb.fit.config import FitConfig
from rsodb.pipeline import QUICK_FIT
from tests.conftest import PROJECT_ROOT

CONFIGS = PROJECT_ROOT / "configs"


def test_standard_config_is_the_default_written_out():
    assert FitConfig.from_toml(CONFIGS / "standard.toml").to_dict() == FitConfig().to_dict()


def test_quick_config_is_the_main_jobs_first_look():
    assert FitConfig.from_toml(CONFIGS / "quick.toml").to_dict() == FitConfig.from_dict(QUICK_FIT).to_dict()


@pytest.mark.parametrize("name", ["short", "quick", "standard"])
def test_every_shipped_config_loads(name):
    config = FitConfig.from_toml(CONFIGS / f"{name}.toml")
    assert config.name == {"standard": "default"}.get(name, name)
