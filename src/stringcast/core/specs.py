"""The lab as the config describes it: arm, camera set-up and ChArUco board, string, target,
and a campaign that names one of each (resolved from ``data/<campaign>/campaign.yaml`` by
:mod:`stringcast.core.campaign`).

Everything is converted to SI on load (mm -> m, deg -> rad, g -> kg) and held in frozen
dataclasses that check their own shapes, in the manner of MuJoCo's sysid.

Errors: :class:`~stringcast.core.config.ConfigError` naming the file and the key.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from collections.abc import Mapping

import numpy as np

from .config import ConfigError


def _arr(x, shape=None, name="array") -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if shape is not None and a.shape != shape:
        raise ConfigError(f"{name}: expected shape {shape}, got {a.shape}")
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class ArmSpec:
    """A planar serial arm (SI units).

    Attributes:
        link_lengths: (J,) link lengths in m.
        gripper: gripper length in m, along the last link, to the grasp point.
        q_min, q_max: (J,) joint position limits, rad.
        qd_max: (J,) joint speed limits, rad/s.
        qdd_max: (J,) joint acceleration limits, rad/s^2.
        controller_rate: servo rate in Hz (motion files are sampled at it).
        floor_y: height of the floor/table in the robot frame, m.
        link_widths: (>= 1,) the links' widths as the camera sees them, m (the last repeats).
        joint_radii: (>= 1,) the joint discs' radii from the base on, m (the last repeats).
        gripper_widths: (2,) the gripper's width at the wrist and at the fingertips, m.
        gripper_mask_extend: the gripper's outline reaches this past the grasp point, m.
    The outline is what tracking masks out and what the board and sync checks look for.
    """

    name: str
    link_lengths: np.ndarray
    gripper: float
    q_min: np.ndarray
    q_max: np.ndarray
    qd_max: np.ndarray
    qdd_max: np.ndarray
    controller_rate: float
    floor_y: float
    link_widths: np.ndarray
    joint_radii: np.ndarray
    gripper_widths: np.ndarray
    gripper_mask_extend: float

    def __post_init__(self):
        j = len(self.link_lengths)
        for name in ("q_min", "q_max", "qd_max", "qdd_max"):
            if np.shape(getattr(self, name)) != (j,):
                raise ConfigError(f"arm {self.name}: {name} must have {j} entries")
        if np.any(self.q_min >= self.q_max):
            raise ConfigError(f"arm {self.name}: q_min must be below q_max")

    @property
    def n_joints(self) -> int:
        return len(self.link_lengths)

    @property
    def reach(self) -> float:
        """Maximum distance from the base to the grasp point, m."""
        return float(np.sum(self.link_lengths) + self.gripper)

    @classmethod
    def from_config(cls, name: str, d: Mapping) -> ArmSpec:
        rad = math.pi / 180
        return cls(
            name=name,
            link_lengths=_arr(np.asarray(d["link_lengths_mm"]) / 1000),
            gripper=float(d["gripper_mm"]) / 1000,
            q_min=_arr(np.asarray(d["q_min_deg"]) * rad),
            q_max=_arr(np.asarray(d["q_max_deg"]) * rad),
            qd_max=_arr(np.asarray(d["qd_max_deg_s"]) * rad),
            qdd_max=_arr(np.asarray(d["qdd_max_deg_s2"]) * rad),
            controller_rate=float(d["controller_rate_hz"]),
            floor_y=float(d["floor_y_mm"]) / 1000,
            link_widths=_arr(np.asarray(d["link_widths_mm"], float) / 1000),
            joint_radii=_arr(np.asarray(d["joint_radii_mm"], float) / 1000),
            gripper_widths=_arr(np.asarray(d["gripper_widths_mm"], float) / 1000, (2,), f"arm {name}: gripper_widths_mm"),
            gripper_mask_extend=float(d["gripper_mask_extend_mm"]) / 1000,
        )


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board: squares, sizes in m, OpenCV dictionary name."""

    squares_x: int
    squares_y: int
    square: float
    marker: float
    dictionary: str
    legacy_pattern: bool = False

    def __post_init__(self):
        if self.squares_x < 2 or self.squares_y < 2:
            raise ConfigError(f"board: squares_x and squares_y must be >= 2 (a ChArUco board has corners between "
                              f"squares), got {self.squares_x} x {self.squares_y}")
        if not 0 < self.marker < self.square:
            raise ConfigError("board: marker_mm must be positive and smaller than square_mm")

    @property
    def n_markers(self) -> int:
        """The markers on the board: one in every other square."""
        return self.squares_x * self.squares_y // 2

    def make(self):
        """The OpenCV ``cv2.aruco.CharucoBoard`` (sizes in m).

        Raises:
            ConfigError: a dictionary OpenCV does not know, or one with fewer markers than the
                board needs (OpenCV would repeat ids; the board could not be identified).
        """
        import cv2

        dic_id = getattr(cv2.aruco, self.dictionary, None)
        if not isinstance(dic_id, int):
            known = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
            close = difflib.get_close_matches(str(self.dictionary), known, n=3, cutoff=0.6)
            raise ConfigError(f"board: unknown ArUco dictionary {self.dictionary!r} ("
                              + (f"did you mean {' or '.join(close)}?" if close else f"OpenCV knows {', '.join(known)}")
                              + ")")
        dictionary = cv2.aruco.getPredefinedDictionary(dic_id)
        size = int(dictionary.bytesList.shape[0])
        if size < self.n_markers:
            raise ConfigError(f"board: a {self.squares_x} x {self.squares_y} board has {self.n_markers} markers, but "
                              f"{self.dictionary} holds only {size}: the printed board's dictionary is another "
                              "(a larger one, e.g. _100 or _250)?")
        board = cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), self.square, self.marker, dictionary,
        )
        board.setLegacyPattern(self.legacy_pattern)
        return board


@dataclass(frozen=True)
class SetupSpec:
    """Camera and board of one lab set-up.

    ``board_to_robot`` is the 3x3 homogeneous transform taking board-frame points
    (m, in the board plane, OpenCV's board frame) to robot-frame (x, y) in m.
    """

    name: str
    camera: dict
    board: BoardSpec
    board_to_robot: np.ndarray
    reprojection_warn_px: float

    def __post_init__(self):
        if np.shape(self.board_to_robot) != (3, 3):
            raise ConfigError(f"setup {self.name}: board_to_robot must be 3x3")

    @classmethod
    def from_config(cls, name: str, d: Mapping, cameras: Mapping) -> SetupSpec:
        cam_name = d["camera"]
        if cam_name not in cameras:
            raise ConfigError(f"setup {name}: unknown camera {cam_name!r}")
        b = d["board"]
        board = BoardSpec(int(b["squares_x"]), int(b["squares_y"]), b["square_mm"] / 1000,
                          b["marker_mm"] / 1000, b["dictionary"], bool(b.get("legacy_pattern", False)))
        a = math.radians(d.get("board_angle_deg", 0.0))
        flip = -1.0 if d.get("board_flip_y", True) else 1.0
        ox, oy = np.asarray(d["board_origin_mm"], float) / 1000
        T = np.array([[math.cos(a), -math.sin(a) * flip, ox],
                      [math.sin(a), math.cos(a) * flip, oy],
                      [0.0, 0.0, 1.0]])
        return cls(name, dict(cameras[cam_name], name=cam_name), board, _arr(T, (3, 3)),
                   float(d.get("reprojection_warn_px", 1.0)))


@dataclass(frozen=True)
class StringSpec:
    """What is known of a string: length, model points, weights, stiff sections.

    Attributes:
        length: m. n_points: model mass points n (p_1..p_n; p_n is the tip).
        weights: ((at_m, mass_kg), ...). stiff_sections: ((from_m, to_m), ...).
    """

    name: str
    length: float
    n_points: int
    weights: tuple = ()
    stiff_sections: tuple = ()

    def __post_init__(self):
        if not (0.05 <= self.length <= 5.0):
            raise ConfigError(f"string {self.name}: length {self.length} m out of range")
        if self.n_points < 2:
            raise ConfigError(f"string {self.name}: n_points must be >= 2")
        for at, _ in self.weights:
            if not 0 <= at <= self.length + 1e-9:
                raise ConfigError(f"string {self.name}: weight at {at} m is off the string")

    @property
    def l0(self) -> float:
        """Rest segment length L / n, m."""
        return self.length / self.n_points

    def weight_points(self) -> list[int]:
        """Model points (1..n) carrying a weight: each weight's nearest point."""
        return sorted({int(min(self.n_points, max(1, round(at / self.l0)))) for at, _ in self.weights})

    def special_points(self) -> list[int]:
        """Model points (1..n) where a weight or stiff section sits (paper Table 4).

        A weight falls on the nearest point; a stiff section covers every point
        whose arc position lies inside it (at least the nearest one).
        """
        pts = set(self.weight_points())
        for a, b in self.stiff_sections:
            inside = [i for i in range(1, self.n_points + 1) if a - 1e-9 <= i * self.l0 <= b + 1e-9]
            if not inside:
                inside = [int(min(self.n_points, max(1, round(0.5 * (a + b) / self.l0))))]
            pts.update(inside)
        return sorted(pts)

    def mass_groups(self) -> np.ndarray:
        """(n,) int: 0 for plain points (shared mu_others), g >= 1 for the g-th special point."""
        groups = np.zeros(self.n_points, dtype=np.int64)
        for g, i in enumerate(self.special_points(), start=1):
            groups[i - 1] = g
        return groups

    @classmethod
    def from_config(cls, name: str, d: Mapping) -> StringSpec:
        return cls(
            name=str(name),
            length=float(d["length_mm"]) / 1000,
            n_points=int(d["n_points"]),
            weights=tuple((w["at_mm"] / 1000, w.get("mass_g", 10.0) / 1000) for w in d.get("weights", [])),
            stiff_sections=tuple((s["from_mm"] / 1000, s["to_mm"] / 1000) for s in d.get("stiff_sections", [])),
        )


@dataclass(frozen=True)
class TargetSpec:
    """A target disc in the swing plane: centre (x, y) and radius, m."""

    name: str
    x: float
    y: float
    radius: float

    @property
    def xy(self) -> np.ndarray:
        return np.array([self.x, self.y])


@dataclass(frozen=True)
class Campaign:
    """One string, one target, one arm and set-up, resolved from ``campaign.yaml``.

    ``target`` is None for a campaign read without one (:data:`WITHOUT_TARGET`: the file the workflow
    gives the stages that never read the target)."""

    name: str
    string: StringSpec
    target: TargetSpec | None
    arm: ArmSpec
    setup: SetupSpec
    string_id: str | None = None
    config: dict = field(default_factory=dict, repr=False, compare=False)

    def string_setting(self, key: str) -> str:
        """Where the string's ``key`` (``length_mm``, ``n_points``) is set, for a message:
        ``strings.<id>.<key>`` in the config, or ``string.<key>`` of the campaign.yaml (inline)."""
        return f"strings.{self.string_id}.{key}" if self.string_id else f"string.{key} in campaign.yaml"

    def setup_setting(self, key: str) -> str:
        """Where the set-up's ``key`` (``board.square_mm``, ``board.dictionary``, ...) is set, for a
        message: ``setups.<name>.<key>`` in the config, or ``setup.<key>`` of the campaign.yaml (inline)."""
        return f"setups.{self.setup.name}.{key}" if self.setup.name != "inline" else f"setup.{key} in campaign.yaml"
