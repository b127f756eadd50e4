"""The lab's high-speed camera: pinhole + OpenCV lens distortion, optics blur, sensor.

Rendering happens on an *ideal* (undistorted pinhole) canvas with intrinsics
``K_ideal`` (same focal length, principal point shifted so the canvas covers
everything the real lens sees); one precomputed ``cv2.remap`` turns it into the
distorted image. The remap tables come from ``cv2.undistortPoints`` (50 iterations) of every
output pixel, so the distortion is exactly OpenCV's model (k1, k2, p1, p2, k3)
and a calibration with ``cv2.calibrateCamera`` can recover it.

World frame = robot base frame (x towards the target, y up, swing plane z = 0).
The camera looks at the swing plane from +z: its optical axis meets the plane at
``lab.camera.center_mm``, from ``distance_mm`` away, turned by ``tilt_deg`` about
the camera's x and y axes (pitch, yaw: an oblique view of the swing plane) and
rolled by ``roll_deg`` about its optical axis.

Sensor: image = 255 * gain * radiance (radiance in [0, 1] from the scene's
reflectance times illumination and vignetting), plus Gaussian read noise
(``noise_sigma`` DN) and shot noise (variance ``shot_gain`` * DN), rounded and
clipped to 8 bit. ``light_level`` scales the illumination (dim light: a lower
signal at the same read noise); ``light_drift_per_s`` and ``flicker`` (at
``flicker_hz``, averaged over the exposure) make it vary from frame to frame.

Harder footage: named presets (:data:`PRESETS`, overridable and extendable in
``lab.presets``) merged into the config by :func:`apply_preset`.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from collections.abc import Mapping

import cv2
import numpy as np

from stringcast.core import ConfigError
from .settings import LabSettings

CAMERA_DEFAULTS = {
    "distance_mm": 2500.0,
    "center_mm": [560.0, 60.0],
    "focal_px": 1390.0,
    "principal_offset_px": [4.0, -3.0],
    "dist_coeffs": [-0.08, 0.03, 0.0005, -0.0003, 0.0],
    "tilt_deg": [1.5, -1.0],
    "exposure_s": 0.0008,
    "noise_sigma": 1.5,
    "shot_gain": 0.003,
    "blur_sigma_px": 0.5,
    "vignetting": 0.25,
    "roll_deg": 0.0,
    "light_level": 1.0,
    "light_drift_per_s": 0.0,
    "flicker": 0.0,
    "flicker_hz": 100.0,
}

PRESETS = {
    # a quarter of the light at the same read noise (and a little more: gain turned up)
    "dim": {"camera": {"light_level": 0.25, "noise_sigma": 1.6}},
    # the shutter open for 95 % of a 500 fps frame period, and slightly out of focus
    "blur": {"camera": {"exposure_s": 0.0019, "blur_sigma_px": 1.0}},
    # the camera 30 deg to the side of the plane's normal and 15 deg above it, rolled 4 deg
    "oblique": {"camera": {"tilt_deg": [15.0, -30.0], "roll_deg": 4.0}},
    # 2000 fps with a matching short exposure and less light per frame
    "fast": {"cameras": {"fps": 2000.0}, "camera": {"exposure_s": 0.0004, "light_level": 0.6}},
    # a 640 x 640 sensor seeing the same field (about 2.9 mm per pixel at the default camera)
    "lowres": {"cameras": {"width_px": 640, "height_px": 640}, "camera": {"focal_px": 869.0}},
    # light drifting by -30 %/s with 100 Hz mains flicker of +-6 %
    "flicker": {"camera": {"light_drift_per_s": -0.3, "flicker": 0.06}},
}
"""Named lab settings for harder footage: ``camera`` entries go into ``lab.camera``,
``cameras`` entries into every camera of ``cameras:`` (fps, width_px, height_px)."""


def camera_settings(config: Mapping) -> dict:
    """``lab.camera`` merged over :data:`CAMERA_DEFAULTS` (unknown keys are an error)."""
    lab = LabSettings.from_config(config).camera
    unknown = set(lab) - set(CAMERA_DEFAULTS)
    if unknown:
        raise ConfigError(f"lab.camera: unknown keys {sorted(unknown)}")
    return {**CAMERA_DEFAULTS, **lab}


def presets(config: Mapping) -> dict:
    """:data:`PRESETS` updated with ``lab.presets`` (a preset there replaces the built-in one)."""
    extra = LabSettings.from_config(config).presets
    if not isinstance(extra, Mapping):
        raise ConfigError("lab.presets: expected a mapping of preset name -> settings")
    return {**PRESETS, **extra}


def apply_preset(config: Mapping, name: str) -> dict:
    """A deep copy of ``config`` with the lab preset(s) ``name`` applied.

    Args:
        config: the loaded config. name: a preset name, or several joined by ``+``
            (``"dim+blur"``; later ones win where they set the same key).

    Returns:
        The new config: each preset's ``camera`` mapping merged into ``lab.camera``,
        its ``cameras`` mapping merged into every entry of ``cameras:``.

    Raises:
        ConfigError: an unknown preset, a preset with keys other than ``camera`` and
            ``cameras``, or ``camera`` keys unknown to ``lab.camera``.
    """
    out = copy.deepcopy(dict(config))
    table = presets(config)
    for part in str(name).split("+"):
        part = part.strip()
        if part not in table:
            raise ConfigError(f"lab preset '{part}' unknown; known: {sorted(table)}")
        p = table[part] or {}
        bad = set(p) - {"camera", "cameras"}
        if bad:
            raise ConfigError(f"lab.presets.{part}: unknown keys {sorted(bad)} (expected camera, cameras)")
        lab = out.setdefault("lab", {}) or {}
        out["lab"] = lab
        lab["camera"] = {**(lab.get("camera", {}) or {}), **(p.get("camera", {}) or {})}
        camera_settings(out)                       # unknown lab.camera keys are an error
        for cam in (out.get("cameras", {}) or {}).values():
            cam.update(p.get("cameras", {}) or {})
    return out


@dataclass(frozen=True)
class CameraModel:
    """A calibrated pinhole camera with OpenCV distortion.

    Attributes:
        K: (3, 3) intrinsics, px. dist: (5,) (k1, k2, p1, p2, k3).
        R: (3, 3) world-to-camera rotation; t: (3,) world-to-camera translation, m
            (x_cam = R x_world + t, OpenCV convention: z forward, y down).
        width, height: image size, px.
    """

    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int

    def __post_init__(self):
        for name, shape in (("K", (3, 3)), ("dist", (5,)), ("R", (3, 3)), ("t", (3,))):
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"CameraModel.{name} must have shape {shape}")
        if not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-9):
            raise ValueError("CameraModel.R is not a rotation")
        if self.width < 8 or self.height < 8:
            raise ValueError("CameraModel: image too small")

    @classmethod
    def from_config(cls, setup_camera: Mapping, config: Mapping) -> CameraModel:
        """Image size from the set-up's camera (width_px, height_px); the rest from ``lab.camera``."""
        c = camera_settings(config)
        try:
            w, h = int(setup_camera["width_px"]), int(setup_camera["height_px"])
        except KeyError as exc:
            raise ConfigError(f"setup camera: missing {exc.args[0]}") from exc
        f = float(c["focal_px"])
        off = np.asarray(c["principal_offset_px"], float)
        K = np.array([[f, 0, (w - 1) / 2 + off[0]], [0, f, (h - 1) / 2 + off[1]], [0, 0, 1.0]])
        dist = np.asarray(c["dist_coeffs"], float)
        if dist.shape != (5,):
            raise ConfigError("lab.camera.dist_coeffs: expected 5 values (k1, k2, p1, p2, k3)")
        ax, ay = np.radians(np.asarray(c["tilt_deg"], float))
        az = math.radians(float(c["roll_deg"]))
        rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
        ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
        rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
        R = rz @ rx @ ry @ np.diag([1.0, -1.0, -1.0])  # camera looks along world -z
        corners = np.array([[0, 0, 1], [w, 0, 1], [w, h, 1], [0, h, 1]], float)
        rays = (R.T @ np.linalg.solve(K, corners.T)).T  # world directions of the image corners
        if np.any(rays[:, 2] > -0.05 * np.linalg.norm(rays, axis=1)):
            raise ConfigError(f"lab.camera: tilt_deg {list(c['tilt_deg'])} turns the {w}x{h} image past the "
                              "swing plane's horizon (an image corner's ray misses the plane)")
        forward = R.T @ np.array([0, 0, 1.0])
        P = np.array([*np.asarray(c["center_mm"], float) / 1000, 0.0])
        C = P - float(c["distance_mm"]) / 1000 * forward
        return cls(K, dist, R, -R @ C, w, h)

    @property
    def rvec(self) -> np.ndarray:
        """(3,) Rodrigues vector of R (``cv2.Rodrigues``)."""
        return cv2.Rodrigues(self.R)[0].ravel()

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in the world, m."""
        return -self.R.T @ self.t

    def project(self, pts: np.ndarray) -> np.ndarray:
        """World points (N, 3) or plane points (N, 2) (z = 0), m -> distorted pixels (N, 2).

        ``cv2.projectPoints`` with K, dist, R, t.
        """
        pts = np.asarray(pts, float).reshape(-1, np.shape(pts)[-1])
        if pts.shape[1] == 2:
            pts = np.column_stack([pts, np.zeros(len(pts))])
        img, _ = cv2.projectPoints(pts, self.rvec, self.t, self.K, self.dist)
        return img.reshape(-1, 2)

    def plane_homography(self, K: np.ndarray | None = None) -> np.ndarray:
        """(3, 3) homography from the swing plane (x, y, 1) in m to *undistorted* pixels of K."""
        K = self.K if K is None else K
        return K @ np.column_stack([self.R[:, 0], self.R[:, 1], self.t])

    def truth(self) -> dict:
        """Camera ground truth for ground_truth.json: K, dist, rvec, tvec, R, size."""
        return {"K": self.K, "dist": self.dist, "rvec": self.rvec, "tvec": self.t, "R": self.R,
                "width_px": self.width, "height_px": self.height}


def apply_homography(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(N, 2) points through a 3x3 homography -> (N, 2)."""
    pts = np.asarray(pts, float)
    p = pts @ H[:, :2].T + H[:, 2]
    return p[:, :2] / p[:, 2:3]


@dataclass(frozen=True)
class IdealCanvas:
    """The undistorted render canvas and the remap tables to the camera image.

    Attributes:
        K: (3, 3) intrinsics of the canvas (the camera's f, shifted principal point).
        width, height: canvas size, px.
        map_x, map_y: (H_img, W_img) float32: canvas coordinates of each image pixel.
        cam_K, dist: the camera's intrinsics and distortion.
    """

    K: np.ndarray
    width: int
    height: int
    map_x: np.ndarray
    map_y: np.ndarray
    cam_K: np.ndarray
    dist: np.ndarray

    def __post_init__(self):
        if np.shape(self.K) != (3, 3) or np.shape(self.cam_K) != (3, 3):
            raise ValueError("IdealCanvas: K and cam_K must be 3x3")
        if self.map_x.shape != self.map_y.shape or self.map_x.ndim != 2:
            raise ValueError("IdealCanvas: map_x and map_y must be equal (H, W) arrays")

    @classmethod
    def for_camera(cls, cam: CameraModel, margin_px: int = 4) -> IdealCanvas:
        """Canvas covering the undistorted positions of every image pixel (+ margin)."""
        u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), np.arange(cam.height, dtype=np.float64))
        pix = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
        ideal = cv2.undistortPoints(pix, cam.K, cam.dist, R=None, P=cam.K, criteria=crit).reshape(-1, 2)
        lo = np.floor(ideal.min(axis=0)) - margin_px
        hi = np.ceil(ideal.max(axis=0)) + margin_px
        K = cam.K.copy()
        K[0, 2] -= lo[0]
        K[1, 2] -= lo[1]
        w, h = (hi - lo).astype(int) + 1
        mx = (ideal[:, 0] - lo[0]).reshape(cam.height, cam.width).astype(np.float32)
        my = (ideal[:, 1] - lo[1]).reshape(cam.height, cam.width).astype(np.float32)
        return cls(K, int(w), int(h), mx, my, cam.K, cam.dist)

    def distort(self, img: np.ndarray, roi: tuple[int, int, int, int] | None = None,
                origin: tuple[int, int] = (0, 0)) -> np.ndarray:
        """Canvas image (or a canvas crop starting at ``origin`` = (x0, y0)) -> camera image.

        ``roi`` = (x0, y0, x1, y1) in camera pixels restricts the output to that box.
        Bilinear ``cv2.remap``.
        """
        if roi is None:
            mx, my = self.map_x, self.map_y
        else:
            x0, y0, x1, y1 = roi
            mx, my = self.map_x[y0:y1, x0:x1], self.map_y[y0:y1, x0:x1]
        if origin != (0, 0):
            mx = mx - np.float32(origin[0])
            my = my - np.float32(origin[1])
        return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    def to_image(self, pts: np.ndarray) -> np.ndarray:
        """Canvas pixels (N, 2) -> distorted camera pixels (N, 2) (``cv2.projectPoints``)."""
        pts = np.asarray(pts, float)
        f = self.K[0, 0]
        xn = np.column_stack([(pts[:, 0] - self.K[0, 2]) / f, (pts[:, 1] - self.K[1, 2]) / self.K[1, 1],
                              np.ones(len(pts))])
        img, _ = cv2.projectPoints(xn, np.zeros(3), np.zeros(3), self.cam_K, self.dist)
        return img.reshape(-1, 2)

    def image_roi(self, box: tuple[float, float, float, float], pad: int = 2
                  ) -> tuple[int, int, int, int] | None:
        """Camera-pixel box (x0, y0, x1, y1) holding the image of the canvas box (x0, y0, x1, y1).

        The box's boundary is mapped (the distortion is one-to-one over the
        canvas), so the result is the bounding box of the mapped region plus
        ``pad``, clipped to the image; None if that is empty.
        """
        x0, y0, x1, y1 = box
        t = np.linspace(0, 1, 17)
        edge = np.concatenate([np.column_stack([x0 + (x1 - x0) * t, np.full_like(t, y0)]),
                               np.column_stack([x0 + (x1 - x0) * t, np.full_like(t, y1)]),
                               np.column_stack([np.full_like(t, x0), y0 + (y1 - y0) * t]),
                               np.column_stack([np.full_like(t, x1), y0 + (y1 - y0) * t])])
        p = self.to_image(edge)
        h, w = self.map_x.shape
        lo = np.maximum(np.floor(p.min(axis=0)).astype(int) - pad, 0)
        hi = np.minimum(np.ceil(p.max(axis=0)).astype(int) + pad + 1, [w, h])
        if np.any(hi <= lo):
            return None
        return int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])


class Sensor:
    """Lens vignetting, optics blur, noise and 8-bit quantisation.

    Args:
        cam: the camera; settings: :func:`camera_settings`.
    """

    def __init__(self, cam: CameraModel, settings: Mapping):
        self.sigma = float(settings["noise_sigma"])
        self.shot_gain = float(settings["shot_gain"])
        self.blur_sigma = float(settings["blur_sigma_px"])
        self.light_level = float(settings["light_level"])
        self.light_drift = float(settings["light_drift_per_s"])
        self.flicker = float(settings["flicker"])
        self.flicker_hz = float(settings["flicker_hz"])
        if not 0 < self.light_level <= 4:
            raise ConfigError(f"lab.camera.light_level = {self.light_level}: expected (0, 4]")
        if abs(self.flicker) >= 1 or self.flicker_hz <= 0:
            raise ConfigError("lab.camera: flicker must be in (-1, 1) and flicker_hz > 0")
        u, v = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
        r2 = ((u - cam.K[0, 2]) ** 2 + (v - cam.K[1, 2]) ** 2) / cam.K[0, 0] ** 2
        # cos^4-like fall-off, scaled so the image corners lose about ``vignetting``.
        corner = ((cam.width / 2) ** 2 + (cam.height / 2) ** 2) / cam.K[0, 0] ** 2
        a = float(settings["vignetting"])
        k = (1 / max(1e-6, 1 - a)) ** 0.5 - 1
        self.vignette = (1.0 / (1 + k * r2 / max(corner, 1e-9)) ** 2).astype(np.float32)

    def light(self, t: float, exposure: float) -> float:
        """Relative illumination of a frame exposed over t +- exposure / 2 (s): drift x flicker.

        1 + light_drift_per_s t (at least 0.05), times 1 + flicker sin(2 pi f t) averaged over
        the exposure (the sinusoid's mean over the window: a sinc factor).
        """
        drift = max(0.05, 1.0 + self.light_drift * t)
        if self.flicker == 0:
            return drift
        w = math.pi * self.flicker_hz * exposure
        avg = math.sin(w) / w if w > 1e-9 else 1.0
        return drift * (1.0 + self.flicker * avg * math.sin(2 * math.pi * self.flicker_hz * t))

    def blur(self, img: np.ndarray) -> np.ndarray:
        """Optics point-spread: a Gaussian of ``blur_sigma_px`` (on the ideal canvas)."""
        if self.blur_sigma <= 0:
            return img
        return cv2.GaussianBlur(img, (0, 0), self.blur_sigma, borderType=cv2.BORDER_REPLICATE)

    @staticmethod
    def seed(seed: int) -> None:
        """Seed the noise generator (OpenCV's per-thread RNG, ``cv2.setRNGSeed``)."""
        cv2.setRNGSeed(int(seed) & 0x7FFFFFFF)

    def expose(self, dn: np.ndarray) -> np.ndarray:
        """Noise-free digital numbers (H, W) float32 -> uint8 image with read and shot noise.

        Gaussian noise of variance noise_sigma^2 + shot_gain * DN (``cv2.randn``: call
        :meth:`seed` first for reproducible frames), rounded and saturated to 0..255. Colour
        (H, W, 3) BGR: a Bayer sensor; each pixel keeps one channel (RGGB: R at even rows and
        columns), gets its noise, and OpenCV's edge-aware demosaicing
        (``COLOR_BayerBG2BGR_EA``) makes the (H, W, 3) uint8 BGR frame.
        """
        dn = np.asarray(dn, np.float32)
        if dn.ndim == 3:
            mosaic = np.empty(dn.shape[:2], np.float32)
            mosaic[0::2, 0::2] = dn[0::2, 0::2, 2]
            mosaic[0::2, 1::2] = dn[0::2, 1::2, 1]
            mosaic[1::2, 0::2] = dn[1::2, 0::2, 1]
            mosaic[1::2, 1::2] = dn[1::2, 1::2, 0]
            return cv2.cvtColor(self.expose(mosaic), cv2.COLOR_BayerBG2BGR_EA)
        noise = np.empty_like(dn)
        cv2.randn(noise, 0.0, 1.0)
        std = dn * np.float32(self.shot_gain) + np.float32(self.sigma ** 2)
        np.maximum(std, 0, out=std)
        cv2.sqrt(std, std)
        noise *= std
        noise += dn
        np.maximum(noise, 0, out=noise)
        return cv2.convertScaleAbs(noise)        # rounds and saturates at 255 (values are >= 0)
