"""The virtual lab: a stand-in for the arm, the string and the high-speed camera.

It shares no code with the string model (``stringcast.model.string_model``): the string is a
MuJoCo capsule chain (:mod:`.mjcf`, :mod:`.physics`) in air (:mod:`.air`), held by an arm with
servo lag (:mod:`.servo`), filmed by a simulated pinhole camera with OpenCV lens
distortion, motion blur and sensor noise (:mod:`.camera`, :mod:`.scene`).
:func:`run_trial` writes a trial's raw files exactly as docs/data_contract.md's data
contract says (plus ground truth for tests and benchmarks);
:func:`write_calibration_clip` films the ChArUco board for intrinsics;
:func:`apply_preset` makes the footage harder (dim, blur, oblique, fast, lowres, flicker).
"""
from .camera import PRESETS, CameraModel, IdealCanvas, Sensor, apply_preset, camera_settings
from .mjcf import StringPhysics
from .physics import ChainSim, Recording, simulate
from .servo import servo_lag
from .trial import build_renderer, motion_end, run_trial, write_calibration_clip

__all__ = [
    "PRESETS", "apply_preset", "CameraModel", "IdealCanvas", "Sensor", "camera_settings", "ChainSim",
    "Recording", "StringPhysics", "servo_lag", "simulate", "build_renderer", "motion_end", "run_trial", "write_calibration_clip",
]
