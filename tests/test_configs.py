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


def test_the_two_readings_of_cosmos_2553_differ_only_in_the_model():
    # The joint fits of configs/joint_cosmos2553*.toml: an ellipsoid that turns once per two light-
    # curve periods, and a box with panels that turns once per period with its surfaces free.
    ellipsoid = FitConfig.from_toml(CONFIGS / "joint_cosmos2553.toml")
    panels = FitConfig.from_toml(CONFIGS / "joint_cosmos2553_panels.toml")
    assert (ellipsoid.model.shape, panels.model.shape) == ("ellipsoid", "box_panels")
    assert ellipsoid.parameters["spin_period_s"]["multiple"] == 2
    assert "multiple" not in panels.parameters["spin_period_s"]
    surfaces = {"cells_specular", "cells_roughness", "bus_albedo", "back_albedo"}
    assert set(panels.parameters) - set(ellipsoid.parameters) == surfaces
    assert panels.model.attitude == ellipsoid.model.attitude == "inertial"
