import copy

import numpy as np
import pytest
import yaml

from stringcast.core import (PARAM_NAMES, ConfigError, StringSpec, load_campaign, load_config,
                               model_ranges, resolve_campaign, validate)
from stringcast.core.settings import settings_from_config


def test_default_config_resolves_every_string_and_target(config):
    for s in config["strings"]:
        spec = StringSpec.from_config(s, config["strings"][s])
        assert 0.029 <= spec.l0 <= 0.035  # about 30-34 mm between mass points
    for t in config["targets"]:
        camp = resolve_campaign({"string": 1, "target": t}, config)
        assert camp.target.x > camp.arm.reach + 0.05


def test_special_points_match_paper_table4(config):
    expected = {"1": [10], "2": [4], "3": [5], "4": [13, 15], "5": [6, 12, 13], "6": [13, 14, 15], "7": [9]}
    for s, pts in expected.items():
        assert StringSpec.from_config(s, config["strings"][s]).special_points() == pts


def test_mass_groups_number_special_points():
    spec = StringSpec("x", 0.3, 10, weights=((0.12, 0.01), (0.3, 0.01)))
    g = spec.mass_groups()
    assert g.tolist() == [0, 0, 0, 1, 0, 0, 0, 0, 0, 2]


def test_wrong_key_is_named(tmp_path, config):
    bad = copy.deepcopy({k: v for k, v in config.items() if k != "_path"})
    bad["model"] = {"dt_ss": 1e-4}
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(bad))
    with pytest.raises(ConfigError, match=r"c.yaml.*model.*dt_ss"):
        load_config(p)


def test_wrong_value_is_named(tmp_path, config):
    bad = copy.deepcopy({k: v for k, v in config.items() if k != "_path"})
    bad["strings"]["1"]["n_points"] = 0
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(bad))
    with pytest.raises(ConfigError, match="strings/1/n_points"):
        load_config(p)


def test_config_files_merge_in_order_as_snakemake_does(tmp_path, config):
    """--configfile files over the project's: sections merge key by key, lists are replaced."""
    base = config["_path"]
    mid, over = tmp_path / "mid.yaml", tmp_path / "over.yaml"
    mid.write_text("estimation: {iterations: 500}\nmotion: {T_range_s: [0.1, 2.0], batch: 32}\n")
    over.write_text("estimation: {optimizer: cmaes, cmaes_runs: 3}\nmotion: {T_range_s: [0.3, 0.9]}\n")
    merged = load_config([base, mid, over])
    assert merged["estimation"]["optimizer"] == "cmaes" and merged["estimation"]["cmaes_runs"] == 3
    assert merged["estimation"]["iterations"] == 500 and merged["motion"]["batch"] == 32   # kept from the file before
    assert merged["motion"]["T_range_s"] == [0.3, 0.9] and merged["strings"] == config["strings"]
    assert str(mid) in merged["_path"] and merged["_path"].index(str(mid)) < merged["_path"].index(str(over))
    s = settings_from_config(merged)   # the settings no file sets keep their defaults
    assert (s.estimation.optimizer, s.estimation.iterations, s.estimation.cmaes_runs) == ("cmaes", 500, 3)
    assert s.motion.T_range_s == (0.3, 0.9) and s.estimation.batch == settings_from_config(config).estimation.batch
    assert str(over) in merged["_path"]
    with pytest.raises(ConfigError, match=r"over.yaml.*required property"):   # a partial file alone is not a config
        load_config(over)
    bad = tmp_path / "bad.yaml"
    bad.write_text("estimation: {optimiser: cmaes}\n")
    with pytest.raises(ConfigError, match=r"bad.yaml.*optimiser"):   # the merge is validated, naming the files
        load_config([base, bad])
    lst = tmp_path / "list.yaml"
    lst.write_text("- 1\n")
    with pytest.raises(ConfigError, match=r"list.yaml: a config file must be a mapping"):
        load_config([base, lst])


def test_reachable_target_is_refused(config):
    with pytest.raises(ConfigError, match="within the grasp's reach"):
        resolve_campaign({"string": 1, "target": {"x_mm": 900, "y_mm": 0}}, config)
    camp = resolve_campaign({"string": 1, "target": {"x_mm": 900, "y_mm": 0}, "allow_reachable": True}, config)
    assert camp.target.x == pytest.approx(0.9)


def test_campaign_file_errors_name_the_file(tmp_path, config):
    p = tmp_path / "campaign.yaml"
    p.write_text("string: 99\ntarget: 1\n")
    with pytest.raises(ConfigError, match=r"campaign.yaml.*unknown string"):
        load_campaign(p, config)
    p.write_text("string: 1\ntarget: 1\ncolour: red\n")
    with pytest.raises(ConfigError, match="colour"):
        load_campaign(p, config)
    with pytest.raises(ConfigError, match="file not found"):
        load_campaign(tmp_path / "nope.yaml", config)


def test_inline_string_and_ranges(config, settings):
    camp = resolve_campaign({"string": {"length_mm": 400, "n_points": 12, "weights": [{"at_mm": 200}]},
                             "target": 4}, config)
    assert camp.string.n_points == 12 and camp.string.special_points() == [6]
    lo, hi, mu = model_ranges(settings.model)
    assert lo.shape == (len(PARAM_NAMES),) and np.all(hi > lo) and mu == (0.1, 100.0)


def test_board_to_robot_maps_board_origin(config, campaign):
    T = campaign.setup.board_to_robot
    o = T @ np.array([0, 0, 1.0])
    ox, oy = np.asarray(config["setups"]["default"]["board_origin_mm"]) / 1000
    assert o[:2] == pytest.approx([ox, oy])
    down = T @ np.array([0, 0.1, 1.0])  # board y runs down the printed board
    assert down[1] < o[1]


def test_campaign_entries_are_what_resolve_campaign_reads(config):
    """One lookup serves the campaign's specs and the workflow's params: ids with their config
    entries, inline entries as written, the first arm and the 'default' set-up by default."""
    import pytest

    from stringcast.core import ConfigError, campaign_entries, resolve_campaign

    inline = {"length_mm": 300.0, "n_points": 10}
    e = campaign_entries({"string": inline, "target": 1}, config)
    assert e["string"] == (None, inline) and e["target"] == ("1", config["targets"]["1"])
    arm_id = next(iter(config["arms"]))
    assert e["arm"] == (arm_id, config["arms"][arm_id]) and e["setup"] == ("default", config["setups"]["default"])
    assert e["camera"] == config["cameras"][config["setups"]["default"]["camera"]]
    c = resolve_campaign({"string": inline, "target": 1}, config, "c")
    assert c.string.name == "c-inline" and c.target.name == "1" and c.arm.name == arm_id and c.setup.name == "default"
    with pytest.raises(ConfigError, match="unknown target 99"):
        campaign_entries({"string": 1, "target": 99}, config)


def test_a_section_on_the_command_line_is_typed_as_in_a_file(tmp_path, config):
    """``--config 'evaluation={w: 0.5}'`` reaches Snakemake as {'w': '0.5'} (YAML's BaseLoader); typed
    again and merged, it is the setting w = 0.5, lists and booleans too; top-level scalars are kept;
    the job config file is named by its content."""
    from stringcast.core import merge_config, typed_overrides, write_job_config

    cfg = copy.deepcopy({k: v for k, v in config.items() if k != "_path"})
    over = {"evaluation": {"w": "0.5"}, "motion": {"T_range_s": ["0.3", "0.9"], "residual_correction": "true"},
            "note": "0.5"}
    typed = typed_overrides(over)
    assert typed == {"evaluation": {"w": 0.5}, "motion": {"T_range_s": [0.3, 0.9], "residual_correction": True},
                     "note": "0.5"}
    merge_config(cfg, {k: v for k, v in typed.items() if k != "note"})
    validate(cfg, "config.schema.json", "test")
    s = settings_from_config(cfg)
    assert s.evaluation.w == 0.5 and s.motion.T_range_s == (0.3, 0.9) and s.motion.residual_correction is True
    a = write_job_config(cfg, tmp_path)
    assert a == write_job_config(copy.deepcopy(cfg), tmp_path) and load_config([a])["evaluation"]["w"] == 0.5
    cfg["evaluation"]["w"] = 0.7
    assert write_job_config(cfg, tmp_path) != a and len(list(tmp_path.glob("config-*.yaml"))) == 2
