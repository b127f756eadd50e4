"""The report's frame strip draws tracked and simulated points where the calibration puts them."""
import cv2
import numpy as np
import pandas as pd

from stringcast.calibrate.calibration import Calibration
from stringcast.report.strip import GRASP, SIMULATED, TRACKED, choose_frames, frame_strip


def _setup(tmp_path, n_frames=5):
    folder = tmp_path / "video"
    folder.mkdir()
    for k in range(n_frames):
        cv2.imwrite(str(folder / f"frame_{k:04d}.png"), np.full((200, 240), 128, np.uint8))
    cal = Calibration(np.diag([0.001, 0.001, 1.0]), (240, 200))      # 1 mm per px, robot = pixel / 1000
    rows, fit = [], []
    for k in range(n_frames):
        rows.append((k, k / 500, 0, 0.120, 0.050, True))              # grasp at pixel (120, 50)
        for i in (1, 2):
            rows.append((k, k / 500, i, 0.120, 0.050 + 0.040 * i, i == 1))   # tracked: straight down
            fit.append((k, k / 500, i, 0.120 + 0.030 * i, 0.050 + 0.030 * i))  # simulated: diagonal
    tracks = pd.DataFrame(rows, columns=["frame", "t_s", "point", "x_m", "y_m", "valid"])
    fit = pd.DataFrame(fit, columns=["frame", "t_s", "point", "x_sim_m", "y_sim_m"])
    return folder, cal, tracks, fit


def _near(img, colour, tol=60):
    return np.all(np.abs(img.astype(int) - colour) < tol, axis=2)


def test_strip_shows_tracked_and_simulated_points(tmp_path):
    folder, cal, tracks, fit = _setup(tmp_path)
    img = frame_strip(folder, cal, tracks, fit, length_m=0.1, n_frames=3, tile_px=220, margin_m=0.01)
    assert img.shape == (220, 3 * 220, 3)
    tile = img[:, :220]
    # the tile spans 2 R = 2 (L + margin) / (1 mm/px) = 220 px around the grasp: 1 px per px
    # pixel (u, v) -> tile (u - 120 + 110, v - 50 + 110), indexed [row, col] = [v, u]
    assert _near(tile[165:176, 165:176], SIMULATED).any()   # simulated point 2: pixel (180, 110)
    assert _near(tile[135:146, 135:146], SIMULATED).any()   # simulated point 1: pixel (150, 80)
    assert _near(tile[130:170, 90:130], TRACKED).any()      # tracked point 1: pixel (120, 90) -> tile (110, 150)
    assert not _near(tile[175:215, 90:130], TRACKED).any()  # point 2 is invalid: not drawn
    assert _near(tile[95:125, 95:125], GRASP).any()         # the grasp at the tile centre


def test_strip_without_frames_says_so(tmp_path):
    folder, cal, tracks, fit = _setup(tmp_path)
    img = frame_strip(folder, cal, tracks, fit.iloc[:0], length_m=0.1, tile_px=100)
    assert img.shape == (100, 100, 3) and img.max() == 255   # a note tile, white text on black


def test_choose_frames_spreads_over_the_fit():
    fit = pd.DataFrame({"frame": np.repeat(np.arange(10, 110), 3)})
    k = choose_frames(fit, 5)
    assert k.tolist() == [10, 35, 60, 84, 109]


def test_strip_survives_a_grasp_outside_the_image(tmp_path):
    """A grasp point far outside the image (the camera does not see the arm's hand) gives a note tile,
    not a crash (cv2.resize on an empty crop); one just beyond the edge gives the part of its square
    that is inside, black elsewhere."""
    folder, cal, tracks, fit = _setup(tmp_path)
    far = tracks.copy()
    far[["x_m", "y_m"]] += [5.0, -3.0]                                   # pixel (5120, -2950): nowhere near
    img = frame_strip(folder, cal, far, fit.assign(x_sim_m=fit['x_sim_m'] + 5.0), length_m=0.1, n_frames=3, tile_px=120, margin_m=0.01)
    assert img.shape == (120, 120, 3) and img.max() == 255               # one note tile
    edge = tracks.copy()
    edge["x_m"] -= 0.2                                                   # grasp at pixel (-80, 50): off the left
    fit_edge = fit.assign(x_sim_m=fit["x_sim_m"] - 0.2)
    img = frame_strip(folder, cal, edge, fit_edge, length_m=0.1, n_frames=3, tile_px=220, margin_m=0.01)
    assert img.shape == (220, 3 * 220, 3)
    tile = img[:, :220]
    # the square spans pixels u in [-190, 30), v in [-60, 160): only u >= 0, v >= 0 (tile columns 190-219,
    # rows 60-219) is in the image, grey; the rest is black (the drawn points lie left of the image)
    assert tile[25:, :185].max() == 0 and tile[25:55].max() == 0
    assert (tile[65:215, 192:218] == 128).all()
