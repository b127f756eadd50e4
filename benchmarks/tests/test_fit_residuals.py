"""benchmarks.fit_residuals: a fit's point errors and its tracked string's length, on a fit made here."""
import pandas as pd
import pytest

from benchmarks.fit_residuals import fit_residual, summarize


def test_a_fits_errors_by_point_and_its_strings_length(tmp_path):
    """Six points 10 mm apart on a line, the model's off by 0..5 mm along y; one frame stretched 10 %."""
    rows = []
    for frame, scale in enumerate([1.0, 1.0, 1.0, 1.1]):
        for p in range(6):
            x = 0.01 * p * scale
            rows.append({"frame": frame, "t_s": frame / 500, "point": p + 1, "x_tracked_m": x, "y_tracked_m": 0.0,
                         "valid": True, "x_sim_m": x, "y_sim_m": 0.001 * p})
    pd.DataFrame(rows).to_parquet(tmp_path / "fit.parquet")
    r = fit_residual(tmp_path / "fit.parquet")
    assert r["median_mm"] == pytest.approx(2.5) and r["tip_mm"] == pytest.approx(5.0)
    assert r["thirds_mm"] == pytest.approx([0.5, 2.5, 4.5])
    assert r["length_p95_over_median_pct"] == pytest.approx(8.5)   # lengths 50, 50, 50, 55 mm: p95 54.25
    s = summarize([{"physics": "mujoco", "string": 1, "seed": 0, "trial": 1, **r},
                   {"physics": "mujoco", "string": 1, "seed": 0, "trial": 2, **r}])
    assert s["mujoco"]["first_fits"] == 1 and s["mujoco"]["fits"] == 2
    assert s["mujoco"]["first_fit_median_mm"] == pytest.approx(2.5)
