"""The layer under every stage: the config and its settings objects, the planar arm
(forward kinematics, joint limits) and the data files (atomic writers, readers that name
the bad file).
"""
from .arm import JointLimitError, assert_within_limits, check_limits, forward_kinematics, hand_pose, motion_start, motion_window
from .config import ArmSpec, BoardSpec, Campaign, ConfigError, DEFAULT_CONFIG, METHOD_CONFIGS, OURS_CONFIG, PARAM_NAMES, load_campaign, load_config, load_yaml, model_ranges, resolve_campaign
from .files import DataError, TRACK_COLUMNS, atomic_path, check_joint_coverage, check_joint_header, find_video, read_joint_table, read_json, read_parquet, read_video_meta, tracks_arrays, write_joint_table, write_json, write_parquet, write_text, write_yaml
from .settings import POLARITIES, tracking_settings

__all__ = ["ArmSpec", "BoardSpec", "Campaign", "ConfigError", "DEFAULT_CONFIG", "DataError", "JointLimitError", "METHOD_CONFIGS", "OURS_CONFIG", "PARAM_NAMES", "POLARITIES", "TRACK_COLUMNS", "assert_within_limits", "atomic_path", "check_joint_coverage", "check_joint_header", "check_limits", "find_video", "forward_kinematics", "hand_pose", "load_campaign", "load_config", "load_yaml", "model_ranges", "motion_start", "motion_window", "read_joint_table", "read_json", "read_parquet", "read_video_meta", "resolve_campaign", "tracking_settings", "tracks_arrays", "write_joint_table", "write_json", "write_parquet", "write_text", "write_yaml"]
