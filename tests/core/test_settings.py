"""Settings: one frozen object per config section, every default in one place, and the map of
which stage reads which sections (the workflow's params) derived from the stages' signatures."""
import dataclasses

import pytest

from stringcast.core import STAGES, stage_entry, stage_sections
from stringcast.core import (SECTION_CLASSES, ConfigError, EstimationSettings, EvaluationSettings, ModelSettings, MotionSettings,
                             Settings, TrackingSettings, load_config, sections_read, settings_digest,
                             settings_from_config, stage_kwargs)


def test_defaults_are_the_project_config_and_frozen(config):
    s = settings_from_config(config)
    assert s == Settings()   # config/config.yaml describes the lab and sets no stage setting
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.motion.flight_window_s = 1.0
    with pytest.raises(TypeError):
        s.model.ranges["k_s"] = (1.0, 2.0)   # a mapping setting is read-only too
    assert isinstance(s.motion.T_range_s, tuple)


def test_a_file_sets_some_keys_and_a_mapping_merges_over_its_default():
    s = settings_from_config({"motion": {"planner": "robust"}, "model": {"ranges": {"k_ph": [1e-3, 1.0]}}})
    assert s.motion.planner == "robust" and s.motion.flight_window_s == MotionSettings().flight_window_s
    assert s.model.ranges["k_ph"] == (1e-3, 1.0) and s.model.ranges["k_s"] == ModelSettings().ranges["k_s"]
    assert s.model.as_dict()["ranges"]["k_ph"] == [1e-3, 1.0]   # plain data again, for JSON and params


@pytest.mark.parametrize("doc, match", [({"tracking": {"rest_frame": 3}}, "tracking: unknown setting.*rest_frame"),
                                        ({"estimation": {"optimizer": "bfgs"}}, "estimation.optimizer"),
                                        ({"motion": {"planner": "magic"}}, "motion.planner"),
                                        ({"tracking": {"mode": "laser"}}, "tracking.mode"),
                                        ({"model": {"dt_s": 0.0}}, "model.dt_s"),
                                        ({"sweep": {"k1_prior": 0.0}}, "sweep: .*k1_prior must be > 0")])
def test_a_wrong_setting_is_an_error_naming_it(doc, match):
    with pytest.raises(ConfigError, match=match):
        settings_from_config(doc)


def test_sections_read_and_stage_kwargs_follow_the_annotations():
    def stage(path, tracking: TrackingSettings, model: ModelSettings, seed: int = 0):
        return tracking, model

    def everything(path, *, settings: Settings):
        return settings

    s = Settings(tracking=TrackingSettings(rest_frames=7))
    assert sections_read(stage) == ("model", "tracking")   # SECTION_CLASSES order
    assert stage(1, **stage_kwargs(stage, s)) == (s.tracking, s.model)
    assert sections_read(everything) == tuple(c.SECTION for c in SECTION_CLASSES)
    assert everything(1, **stage_kwargs(everything, s)) is s


def test_every_workflow_stage_names_what_it_reads():
    """The map the rules' params come from: each stage's sections, as its entry point takes them."""
    read = {cmd: stage_sections(cmd) for cmd in STAGES}
    assert read["calibrate"] == ("board_check", "calibration")
    assert read["sync"] == ("sync", "board_check")
    assert read["track"] == ("tracking",)
    assert set(read["estimate"]) == {"model", "evaluation", "estimation", "motion", "tracking"}
    assert set(read["plan"]) == set(read["plan-first"]) == {"model", "motion"}
    assert read["report-trial"] == read["report-campaign"] == tuple(c.SECTION for c in SECTION_CLASSES)
    for cmd in STAGES:   # nothing else in the signature looks like a config
        assert "config" not in stage_entry(cmd).__code__.co_varnames[:stage_entry(cmd).__code__.co_argcount]
    # read from the source (the Snakefile does not import the stages): the same as the imported signature's
    assert read == {cmd: sections_read(stage_entry(cmd)) for cmd in STAGES}
    assert read["decode"] == ()


def test_sections_from_source_follow_a_re_export_and_refuse_a_missing_function():
    from stringcast.core import sections_read_from_source

    assert sections_read_from_source("stringcast.sync:run_sweep") == ("board_check", "sweep")   # via sync/__init__
    assert sections_read_from_source("stringcast.sync.sweep:run_sweep") == ("board_check", "sweep")
    with pytest.raises(ValueError, match="no function nothing_here"):
        sections_read_from_source("stringcast.sync:nothing_here")


def test_digest_is_of_the_settings_not_the_files(config):
    same = dict(config, estimation={"iterations": EstimationSettings().iterations}, lab={"scene_seed": 99})
    assert settings_digest(settings_from_config(same)) == settings_digest(Settings())
    other = settings_from_config({"estimation": {"iterations": 10}})
    assert settings_digest(other) != settings_digest(Settings())


def test_paper_yaml_is_read_by_the_same_classes():
    from stringcast.core import DEFAULT_CONFIG, PAPER_CONFIG

    s = settings_from_config(load_config([DEFAULT_CONFIG, PAPER_CONFIG]))
    assert s.estimation.optimizer == "random_search" and s.evaluation.w == 0.1 and s.motion.first_k_s == "carrying"
    assert Settings().estimation.optimizer == "cmaes" and Settings().motion.planner == "robust"   # ours


def test_each_setting_is_declared_once_and_the_schema_is_made_from_it():
    """The packaged config.schema.json declares no stage section; the schema the config is checked
    against takes them from the settings classes (type, constraints, help), so a setting a class
    has is one a config file can set, and a constraint written beside it is enforced."""
    import json
    from importlib.resources import files

    from stringcast.core.config import _schema, validate

    packaged = json.loads(files("stringcast.core").joinpath("schemas", "config.schema.json").read_text())
    assert not set(packaged["properties"]) & {c.SECTION for c in SECTION_CLASSES}
    schema = _schema("config.schema.json")
    for cls in SECTION_CLASSES:
        section = schema["properties"][cls.SECTION]
        assert section.get("additionalProperties") is False
        assert set(section["properties"]) == {f.name for f in dataclasses.fields(cls)}, cls.SECTION
        assert all(p["description"] and p["type"] for p in section["properties"].values()), cls.SECTION
    assert schema["properties"]["estimation"]["properties"]["optimizer"]["enum"] == ["random_search", "cmaes", "de"]
    assert schema["properties"]["evaluation"]["properties"]["w"] == {
        "minimum": 0, "type": "number", "description": EvaluationSettings.__dataclass_fields__["w"].metadata["help"]}
    lab = {k: v for k, v in load_config().items() if k != "_path"}
    with pytest.raises(ConfigError, match="evaluation.*w"):
        validate({**lab, "evaluation": {"w": -1.0}}, "config.schema.json", "test")
    with pytest.raises(ConfigError, match="compare_after_motion_s"):
        validate({**lab, "estimation": {"compare_after_motion_s": "soon"}}, "config.schema.json", "test")
    validate({**lab, "estimation": {"compare_after_motion_s": None}}, "config.schema.json", "test")
