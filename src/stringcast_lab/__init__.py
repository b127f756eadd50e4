"""The virtual lab: a stand-in for the arm, the string and the high-speed camera.

It lies beside the pipeline, not inside it (the ``lab`` extra: ``pip install 'stringcast[lab]'``):
it imports the pipeline's core (config, arm kinematics, file writers), the pipeline never imports it
(the executor's ``virtual`` backend loads it on demand).

It shares no code with the string model (``stringcast.model.string_model``): the string is a
MuJoCo capsule chain (:mod:`.mjcf`, :mod:`.physics`) in air (:mod:`.air`), held by an arm with
servo lag (:mod:`.servo`), filmed by a simulated pinhole camera with OpenCV lens
distortion, motion blur and sensor noise (:mod:`.camera`, :mod:`.scene`, :mod:`.background`),
mono or colour (:mod:`.look`), recorded as FFV1, MJPEG or H.264 (:mod:`.encode`).
:func:`run_trial` writes a trial's raw files exactly as docs/data_contract.md's data
contract says (plus ground truth for tests and benchmarks);
:func:`write_calibration_clip` films the ChArUco board for intrinsics;
:func:`apply_preset` makes the footage harder (dim, blur, oblique, fast, lowres, flicker);
:func:`draw_setup` and :func:`apply_setup` (:mod:`.randomize`) make it another lab altogether:
camera, lens, codec, light, background, board, arm, calibration set and clocks drawn from a family;
:func:`draw_material` and :func:`apply_material` (:mod:`.materials`) the string's material.
"""
try:
    import mujoco  # noqa: F401  (the default physics: without it, the lab extra is not installed)
except ImportError as exc:
    raise ImportError(f"{exc}, the virtual lab's physics engine (the lab extra)") from exc

from .calib_clip import write_calibration_clip
from .camera import PRESETS, CameraModel, IdealCanvas, Sensor, apply_preset, camera_settings
from .encode import h264_backend
from .materials import Material, apply_material, draw_material
from .mjcf import StringPhysics
from .physics import ChainSim, simulate
from .randomize import Setup, apply_setup, draw_setup
from .recording import Recording
from .servo import servo_lag
from .trial import build_renderer, motion_end, run_trial

__all__ = [
    "PRESETS", "apply_preset", "CameraModel", "IdealCanvas", "Sensor", "camera_settings", "ChainSim",
    "Recording", "StringPhysics", "servo_lag", "simulate", "build_renderer", "motion_end", "run_trial",
    "write_calibration_clip", "Setup", "apply_setup", "draw_setup", "h264_backend", "Material",
    "apply_material", "draw_material",
]
