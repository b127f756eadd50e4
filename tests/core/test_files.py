import numpy as np
import pytest

from stringcast.core.files import DataError, atomic_path, read_video_meta, write_json, read_json
from stringcast.core.joint_log import read_joint_table, write_joint_table


def test_joint_table_round_trip(tmp_path):
    t = np.arange(5) * 0.002
    q = np.random.default_rng(0).normal(size=(5, 3))
    write_joint_table(tmp_path / "joints.csv", t, q, {"q1_cmd_rad": q[:, 0]})
    t2, q2 = read_joint_table(tmp_path / "joints.csv")
    assert t2 == pytest.approx(t) and q2 == pytest.approx(q) and q2.shape == (5, 3)   # q1_cmd_rad left out


@pytest.mark.parametrize("fmt", ["%.9g", "%.17g", "%.6f"])
def test_joint_table_parses_as_pandas_did(tmp_path, fmt):
    """The csv-module reader gives the very floats ``pandas.read_csv`` gave (the stages read the
    log without pandas now), for the lab's format and longer and fixed-point ones; blank lines
    and a byte-order mark are skipped as there."""
    pd = pytest.importorskip("pandas")
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(1e-4, 3e-3, 4000))
    q = np.concatenate([rng.normal(0, 2, (2000, 3)), rng.normal(0, 1e-5, (2000, 3))])
    rows = "\n".join(",".join(fmt % v for v in (t[i], *q[i], -q[i, 0])) for i in range(len(t)))
    p = tmp_path / "joints.csv"
    p.write_text("\ufefft_s,q1_rad,q2_rad,q3_rad,q1_cmd_rad\n" + rows + "\n\n", encoding="utf-8")
    t2, q2 = read_joint_table(p, n_joints=3)
    ref = pd.read_csv(p, encoding="utf-8-sig")
    assert np.array_equal(t2, ref["t_s"].to_numpy(float))
    assert np.array_equal(q2, ref[["q1_rad", "q2_rad", "q3_rad"]].to_numpy(float))


@pytest.mark.parametrize("body,msg", [
    ("t_s,q1_rad\n0,0\n0.002,nan\n", "NaN"),
    ("t_s,q1_rad\n0,0\n0.002,0\n0.002,0\n", "not strictly increasing at row 4"),
    ("time,q1_rad\n0,0\n1,0\n", "no 't_s' column"),
    ("t_s,a\n0,0\n1,0\n", "no joint columns"),
    ("t_s,q1_rad\n0,0\n0.002,0.1rad\n", r"row 3, column q1_rad: '0.1rad' is not a number"),
    ("t_s,q1_rad\n0,0\n0.002,0,7\n", "not a readable CSV file: row 3 has 3 fields, the header 2"),
    ("", "not a readable CSV file: it is empty"),
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


def test_joint_table_written_as_pandas_wrote_it(tmp_path):
    """write_joint_table's bytes are those of the pandas writer it replaced (``to_csv``, ``%.9g``,
    NaN as an empty cell), extra columns included."""
    pd = pytest.importorskip("pandas")
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(1e-4, 3e-3, 300))
    q = np.concatenate([rng.normal(0, 2, (150, 2)), rng.normal(0, 1e-7, (150, 2))])
    extra = {"q1_cmd_rad": np.where(np.arange(300) % 7 == 0, np.nan, rng.normal(size=300) * 1e3)}
    write_joint_table(tmp_path / "new.csv", t, q, extra)
    ref = pd.DataFrame({"t_s": t, "q1_rad": q[:, 0], "q2_rad": q[:, 1], **extra})
    ref.to_csv(tmp_path / "ref.csv", index=False, float_format="%.9g")
    assert (tmp_path / "new.csv").read_bytes() == (tmp_path / "ref.csv").read_bytes()
    with pytest.raises(ValueError, match=r"columns \['q1_cmd_rad'\] are not \(300,\)"):
        write_joint_table(tmp_path / "bad.csv", t, q, {"q1_cmd_rad": t[:10]})
    assert not (tmp_path / "bad.csv").exists()


def test_parquet_columns_equal_the_pandas_table(tmp_path):
    """read_parquet_columns (pyarrow alone) gives read_parquet's values, and names missing columns."""
    pd = pytest.importorskip("pandas")
    from stringcast.core.files import TRACK_COLUMNS, read_parquet, read_parquet_columns, tracks_arrays, write_parquet

    rng = np.random.default_rng(2)
    F, n = 40, 5
    df = pd.DataFrame({"frame": np.repeat(np.arange(F), n + 1), "t_s": np.repeat(np.arange(F) / 500, n + 1),
                       "point": np.tile(np.arange(n + 1), F), "x_m": rng.normal(size=F * (n + 1)),
                       "y_m": rng.normal(size=F * (n + 1)), "valid": rng.random(F * (n + 1)) > 0.2})
    write_parquet(tmp_path / "tracks.parquet", df)
    cols = read_parquet_columns(tmp_path / "tracks.parquet", TRACK_COLUMNS)
    for a, b in zip(tracks_arrays(cols, n), tracks_arrays(read_parquet(tmp_path / "tracks.parquet"), n)):
        assert np.array_equal(a, b, equal_nan=True)
    with pytest.raises(DataError, match=r"tracks.parquet: missing columns \['z_m'\]"):
        read_parquet_columns(tmp_path / "tracks.parquet", ["x_m", "z_m"])
    (tmp_path / "bad.parquet").write_text("not parquet")
    with pytest.raises(DataError, match="bad.parquet: not a readable Parquet file"):
        read_parquet_columns(tmp_path / "bad.parquet", ["x_m"])
