"""The lab's settings are typed: one class, every default declared once, a wrong key named."""
import dataclasses

import pytest

from stringcast.core import ConfigError
from stringcast_lab.settings import LabSettings
from stringcast_lab.trial import lab_physics


def test_the_projects_lab_section_is_read_and_the_rest_takes_the_defaults(config):
    lab = LabSettings.from_config(config)
    assert lab.timestep_s == config["lab"]["timestep_s"] and lab.scene_seed == config["lab"]["scene_seed"]
    assert lab.air["density_kg_m3"] == config["lab"]["air"]["density_kg_m3"]
    defaults = LabSettings.from_config({})
    assert defaults == LabSettings() and defaults.physics == "mujoco" and defaults.string_bands is None
    assert dataclasses.replace(defaults, physics="elastica").physics == "elastica"
    with pytest.raises(TypeError):
        lab.camera["focal_px"] = 1.0          # read-only, as every setting


@pytest.mark.parametrize("lab, match", [
    ({"timestep": 1e-4}, r"unknown setting\(s\) timestep .*timestep_s"),
    ({"physics": "MuJoCo"}, "lab.physics = 'MuJoCo'"),
    ({"joint_log": "before_motion"}, "lab.joint_log"),
    ({"render": "no"}, "lab.render = 'no'"),
    ({"links_per_point": 0}, "lab.links_per_point"),
    ({"servo_lag_s": -0.1}, "lab.servo_lag_s"),
])
def test_a_wrong_lab_setting_is_named(lab, match):
    with pytest.raises(ConfigError, match=match):
        LabSettings.from_config({"lab": lab})


def test_the_physics_is_chosen_from_the_settings_or_the_mapping():
    assert lab_physics(LabSettings(physics="elastica")).__name__ == "simulate_rod"
    assert lab_physics({"physics": "mujoco"}).__name__ == "simulate"
