import numpy as np
import pytest

from stringcast.core.files import (DataError, atomic_path, read_joint_table, read_video_meta, write_joint_table,
                              write_json, read_json)


def test_joint_table_round_trip(tmp_path):
    t = np.arange(5) * 0.002
    q = np.random.default_rng(0).normal(size=(5, 3))
    write_joint_table(tmp_path / "joints.csv", t, q, {"q1_cmd_rad": q[:, 0]})
    t2, q2, df = read_joint_table(tmp_path / "joints.csv")
    assert t2 == pytest.approx(t) and q2 == pytest.approx(q) and "q1_cmd_rad" in df


@pytest.mark.parametrize("body,msg", [
    ("t_s,q1_rad\n0,0\n0.002,nan\n", "NaN"),
    ("t_s,q1_rad\n0,0\n0.002,0\n0.002,0\n", "not strictly increasing at row 4"),
    ("time,q1_rad\n0,0\n1,0\n", "no 't_s' column"),
    ("t_s,a\n0,0\n1,0\n", "no joint columns"),
])
def test_bad_joint_logs_are_named(tmp_path, body, msg):
    p = tmp_path / "joints.csv"
    p.write_text(body)
    with pytest.raises(DataError, match=msg) as e:
        read_joint_table(p)
    assert "joints.csv" in str(e.value)


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.json"
    write_json(target, {"a": 1})
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert read_json(target) == {"a": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]


def test_video_meta_checked(tmp_path):
    p = tmp_path / "video.yaml"
    p.write_text("fps: 500\nframes: 10\ntrigger_time_s: 0.01\n")
    assert read_video_meta(p)["frames"] == 10
    p.write_text("fps: -1\nframes: 10\n")
    with pytest.raises(DataError, match="video.yaml.*fps"):
        read_video_meta(p)


def test_json_non_finite_becomes_null(tmp_path):
    write_json(tmp_path / "x.json", {"E": float("inf"), "a": np.arange(2)})
    assert read_json(tmp_path / "x.json") == {"E": None, "a": [0, 1]}
