"""The layer under every stage: the config and its settings objects, the planar arm
(forward kinematics, joint limits) and the data files (atomic writers, readers that name
the bad file).
"""
from .arm import (JointLimitError, assert_within_limits, check_limits, forward_kinematics, hand_pose, joints_at,
                  motion_start, motion_window)
from .config import (DEFAULT_CONFIG, METHOD_CONFIGS, PAPER_CONFIG, PARAM_NAMES, ConfigError, load_config, load_yaml,
                     merge_config, model_ranges, schema_problems, typed_overrides, validate)
from .specs import ArmSpec, BoardSpec, Campaign, SetupSpec, StringSpec, TargetSpec
from .campaign import (NO_TARGET, REACH_MARGIN, campaign_entries, load_campaign, resolve_campaign, target_reach_problem,
                       without_target)
from .files import (TRACK_COLUMNS, DataError, atomic_path, find_video, read_json, read_parquet, read_parquet_columns,
                    read_video_meta, tracks_arrays, trial_result, TrialFiles, TrialResults, write_by_content, write_job_config, write_json, write_parquet,
                    write_text, write_yaml)
from .joint_log import (check_joint_coverage, check_joint_header, check_motion_timing, end_speed_shares, joint_log_span,
                        read_joint_table, read_motion_sidecar, write_joint_table)
from .sections import markdown_table, sections_read, sections_read_from_source, settings_digest, stage_kwargs
from .settings import (DRAG_LAWS, MODES, POLARITIES, SECTION_CLASSES, BoardCheckSettings, CalibrationSettings,
                       EstimationSettings, EvaluationSettings, ExecutorSettings, ModelSettings, MotionSettings,
                       Settings, SweepSettings, SyncSettings, TrackingSettings, settings_from_config)
from .verdict import STATUSES, Verdict, worst
from .stages import REFERENCE_MARK, STAGES, TARGET_COMMANDS, reads_target, settings_reference, stage_entry, stage_sections
from .forked import chunked, forked_map
from .joblog import INTERNAL_ERROR_STATUS, TRACEBACK_DIR_ENV, JobLog, internal_error
from .lifeline import start_lifeline, workflow_stamp
from .runlock import RunConflict, claim_results, outputs_newer_than
from .lazy import lazy_exports
from .ports import (INPUT_HELP, INPUTS, PRODUCT_FILES, RAW_FILES, Port, add_input_options, input_argv, stage_inputs,
                    trial_inputs)

__all__ = [
    "JointLimitError", "assert_within_limits", "check_limits", "forward_kinematics", "hand_pose", "joints_at",
    "motion_start", "motion_window",
    "DEFAULT_CONFIG", "METHOD_CONFIGS", "PAPER_CONFIG", "PARAM_NAMES", "ConfigError", "load_config", "load_yaml",
    "merge_config", "model_ranges", "schema_problems", "typed_overrides", "validate",
    "NO_TARGET", "REACH_MARGIN", "ArmSpec", "BoardSpec", "Campaign", "SetupSpec", "StringSpec", "TargetSpec", "campaign_entries",
    "load_campaign", "resolve_campaign", "target_reach_problem", "without_target",
    "TRACK_COLUMNS", "DataError", "atomic_path", "check_joint_coverage", "check_joint_header", "check_motion_timing",
    "end_speed_shares",
    "find_video", "joint_log_span", "read_joint_table", "read_json", "read_motion_sidecar", "read_parquet",
    "read_parquet_columns",
    "read_video_meta",
    "tracks_arrays", "trial_result", "TrialFiles", "TrialResults", "write_by_content", "write_job_config", "write_joint_table", "write_json", "write_parquet", "write_text", "write_yaml",
    "DRAG_LAWS", "MODES", "POLARITIES", "SECTION_CLASSES", "BoardCheckSettings", "CalibrationSettings", "EstimationSettings",
    "EvaluationSettings", "ExecutorSettings", "ModelSettings", "MotionSettings", "Settings", "SweepSettings",
    "SyncSettings",
    "TrackingSettings",
    "STATUSES", "Verdict", "worst",
    "REFERENCE_MARK", "STAGES", "TARGET_COMMANDS", "reads_target", "settings_reference", "stage_entry", "stage_sections",
    "chunked", "forked_map", "lazy_exports", "INTERNAL_ERROR_STATUS", "TRACEBACK_DIR_ENV", "JobLog", "internal_error", "start_lifeline", "workflow_stamp", "RunConflict",
    "claim_results", "outputs_newer_than",
    "markdown_table", "sections_read", "sections_read_from_source", "settings_digest", "settings_from_config",
    "stage_kwargs",
    "INPUT_HELP", "INPUTS", "PRODUCT_FILES", "RAW_FILES", "Port", "add_input_options", "input_argv", "stage_inputs",
    "trial_inputs",
]
