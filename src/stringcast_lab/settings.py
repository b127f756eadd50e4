"""The virtual lab's settings: the config's ``lab:`` section, typed, every default declared once.

The pipeline never reads this section: it is the lab's hidden physics and its camera and room.
:class:`LabSettings` holds the lab's own scalars (its physics, the simulation's step and settling,
the arm's servo, the joint log's noise and the trigger's error) with their defaults here and
nowhere else, and carries the nested sections (``camera``, ``video``, ``look``, ``calibration``,
``air``, ``strings``, ``string_bands``, ``presets``, ``material``) as written, for the modules that
read them (:mod:`.camera`, :mod:`.encode`, :mod:`.look`, :mod:`.calib_clip`, :mod:`.mjcf`,
:mod:`.materials`). A key the class does not know is an error naming it.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from stringcast.core import ConfigError

PHYSICS = ("mujoco", "elastica")
"""``lab.physics``: the MuJoCo capsule chain or the PyElastica Cosserat rod."""
JOINT_LOGS = ("full", "at_motion_start")
"""``lab.joint_log``: the whole recording, or a log that begins when the motion does."""
SECTIONS = ("air", "camera", "video", "look", "calibration", "strings", "string_bands", "presets", "material")
"""The nested sections :class:`LabSettings` carries as written, for the modules that read them."""


def _section(value):
    """A nested section read-only as written (a value that is not a mapping is left for its reader to name)."""
    return MappingProxyType(dict(value)) if isinstance(value, Mapping) else value


@dataclass(frozen=True)
class LabSettings:
    """``lab:``: the virtual lab (module doc). Times in s, angles in rad.

    Raises:
        ConfigError: from :meth:`from_config`, an unknown key or a value of the wrong kind (named).
    """

    physics: str = field(default="mujoco", metadata={"help": "mujoco (capsule chain) or elastica (Cosserat rod)"})
    links_per_point: int = field(default=3, metadata={"help": "MuJoCo capsules (or rod elements) per model segment"})
    timestep_s: float = field(default=5.0e-5, metadata={"help": "MuJoCo's step; elastica records at it"})
    settle_s: float = field(default=0.3, metadata={"help": "free run after the static equilibrium, before t = 0"})
    servo_lag_s: float = field(default=0.008, metadata={"help": "the arm's joint servo trails a ramp by this"})
    joint_noise_rad: float = field(default=2.0e-4, metadata={"help": "noise on the measured joint log"})
    trigger_error_s: float = field(default=0.002, metadata={"help": "+- error of the trigger time in video.yaml"})
    trigger_offset_s: float = field(default=0.0, metadata={"help": "a fixed error added to it (a wrong trigger)"})
    trigger_written: bool = field(default=True, metadata={"help": "false: video.yaml has no trigger_time_s"})
    joint_log: str = field(default="full", metadata={"help": "full, or at_motion_start (the log begins with the motion)"})
    render: bool = field(default=True, metadata={"help": "false: film nothing, only the camera's clock and the truth"})
    scene_seed: int = field(default=11, metadata={"help": "clutter and light, the same for every trial"})
    air: Mapping = field(default_factory=lambda: _section({}))
    camera: Mapping = field(default_factory=lambda: _section({}))
    video: Mapping = field(default_factory=lambda: _section({}))
    look: Mapping = field(default_factory=lambda: _section({}))
    calibration: Mapping = field(default_factory=lambda: _section({}))
    strings: Mapping = field(default_factory=lambda: _section({}))
    string_bands: Mapping | None = None
    presets: Mapping = field(default_factory=lambda: _section({}))
    material: Mapping | None = None

    def __post_init__(self):
        if self.physics not in PHYSICS:
            raise ConfigError(f"lab.physics = {self.physics!r}: expected one of {list(PHYSICS)}")
        if self.joint_log not in JOINT_LOGS:
            raise ConfigError(f"lab.joint_log = {self.joint_log!r}: expected one of {list(JOINT_LOGS)}")
        for name in ("trigger_written", "render"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"lab.{name} = {getattr(self, name)!r}: expected true or false")
        if not (isinstance(self.links_per_point, int) and self.links_per_point >= 1):
            raise ConfigError(f"lab.links_per_point = {self.links_per_point!r}: expected a whole number >= 1")
        for name in ("timestep_s", "settle_s", "servo_lag_s", "joint_noise_rad", "trigger_error_s"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool) or value < 0:
                raise ConfigError(f"lab.{name} = {value!r}: expected a number >= 0")
        if self.timestep_s <= 0:
            raise ConfigError(f"lab.timestep_s = {self.timestep_s!r}: expected a number > 0")

    @classmethod
    def from_config(cls, config: Mapping) -> LabSettings:
        """The config's ``lab:`` section (absent or null: every default).

        Raises:
            ConfigError: a key this class does not have (named, with the known ones), or a bad value.
        """
        lab = dict((config or {}).get("lab") or {})
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(lab) - names)
        if unknown:
            raise ConfigError(f"lab: unknown setting(s) {', '.join(unknown)} (known: {', '.join(sorted(names))})")
        for key in SECTIONS:
            if key in lab:
                lab[key] = _section(lab[key]) if lab[key] is not None or key in ("string_bands", "material") \
                    else _section({})
        return cls(**lab)
