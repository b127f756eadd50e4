"""constraints.txt pins what `make venv` installs, and the benchmark JSONs record the versions."""
import re
import tomllib
from importlib.metadata import version
from pathlib import Path

from benchmarks.common import LIBRARIES, header

ROOT = Path(__file__).resolve().parents[2]


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _pins() -> dict[str, str]:
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            name, sep, ver = line.partition("==")
            assert sep, f"constraints.txt: {line!r} is not an exact pin (name==version)"
            pins[_norm(name)] = ver
    return pins


def test_constraints_pin_every_dependency_and_benchmark_library():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    deps = meta["dependencies"] + meta["optional-dependencies"]["lab"] + meta["optional-dependencies"]["test"]
    names = {_norm(re.split(r"[<>=!~\[; ]", d, maxsplit=1)[0]) for d in deps} | {_norm(n) for n in LIBRARIES}
    missing = sorted(names - set(_pins()))
    assert not missing, f"constraints.txt pins no version of {missing}: run `make lock`"


def test_benchmark_header_records_the_installed_library_versions():
    libs = header("x", quick=True)["libraries"]
    assert set(libs) == set(LIBRARIES)
    assert libs["numpy"] == version("numpy") and libs["mujoco"] == version("mujoco")
