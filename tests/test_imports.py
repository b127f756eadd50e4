"""The package's import graph: no circles, function-level imports only for heavy or
optional dependencies, and stages that use each other's public faces only.

Every ``import`` and ``from ... import`` in ``src/stringcast`` is read with :mod:`ast`,
top-level and inside functions alike, so an import moved into a function to hide a
circle is still an edge of the graph.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "src" / "stringcast"
LAB = PKG.parent / "stringcast_lab"
# The stage subpackages (the paper's Fig. 2), lowest first.
SUBPACKAGES = ("core", "video", "check", "model", "calibrate", "sync", "track", "estimate", "plan",
               "execute", "report")
SIMULATORS = ("mujoco", "elastica", "av", "stringcast_lab")
"""What the ``lab`` extra brings: a lab with a real arm installs the pipeline without them."""


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in PKG.rglob("*.py")}


def _imports(path: Path, modules: dict[str, Path]):
    """(target module, imported names, line, inside a function) for each stringcast import."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text())
    funcs = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    in_func = {id(n) for f in funcs for n in ast.walk(f) if n is not f}
    for node in ast.walk(tree):
        nested = id(node) in in_func
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "stringcast":
                    yield a.name, (), node.lineno, nested
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "stringcast":
                continue
            names = tuple(a.name for a in node.names)
            subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in modules]
            for s in subs:
                yield s, (), node.lineno, nested
            rest = tuple(n for n in names if f"{target}.{n}" not in modules)
            if rest or not subs:
                yield target, rest, node.lineno, nested


def import_graph() -> dict[str, set[str]]:
    """Module -> the stringcast modules it imports (every import, wherever it stands)."""
    modules = _modules()
    return {m: {t for t, _, _, _ in _imports(p, modules) if t in modules and t != m}
            for m, p in modules.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle as a list of modules (first == last), or None (depth-first search)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                return stack[stack.index(t):] + [t]
            if t not in state and (c := visit(t)):
                return c
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (c := visit(m)):
            return c
    return None


def test_find_cycle_finds_a_planted_circle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_the_package_has_no_import_circle():
    graph = import_graph()
    assert len(graph) > 40
    assert find_cycle(graph) is None, " -> ".join(find_cycle(graph))


def test_the_top_level_reads_like_the_loop():
    names = sorted(p.name for p in PKG.iterdir() if not p.name.startswith(("_", ".")) and p.name != "py.typed")
    assert names == sorted([*SUBPACKAGES, "api.py", "chain.py", "cli.py", "cli_parser.py"])


def test_function_level_imports_only_in_the_cli():
    """Inside functions the package imports itself only in ``cli`` (each subcommand loads
    its own stage, so ``stringcast --help`` stays fast); elsewhere such an import hid a circle."""
    modules = _modules()
    late = [f"{_module_name(p)}:{line} imports {t}" for p in modules.values()
            for t, _, line, nested in _imports(p, modules)
            if nested and _module_name(p) != "stringcast.cli"]
    assert late == []


def test_stages_use_each_others_public_faces():
    """A module imports another subpackage through its face (``stringcast.track``), never
    one of its modules or a private name."""
    modules = _modules()
    bad = []
    for m, p in modules.items():
        own = m.split(".")[1] if m.count(".") else None
        for t, names, line, _ in _imports(p, modules):
            parts = t.split(".")
            if len(parts) < 2 or parts[1] == own or parts[1] not in SUBPACKAGES:
                continue
            if len(parts) > 2 or any(n.startswith("_") for n in names):
                bad.append(f"{m}:{line} imports {t} {names}")
    assert bad == []


@pytest.mark.parametrize("sub", SUBPACKAGES)
def test_a_stage_imports_only_lower_layers(sub):
    """Each subpackage imports only subpackages listed before it in SUBPACKAGES (execute stands
    beside the pipeline: it reads core and plan only)."""
    allowed = {"execute": {"core", "plan"}}.get(
        sub, set(SUBPACKAGES[: SUBPACKAGES.index(sub)]))
    graph = import_graph()
    bad = sorted({f"{m} -> {t}" for m, ts in graph.items() if m.startswith(f"stringcast.{sub}")
                  for t in ts if t.count(".") and t.split(".")[1] != sub
                  and t.split(".")[1] in SUBPACKAGES and t.split(".")[1] not in allowed})
    assert bad == []


def test_a_stage_loads_only_what_it_runs(tmp_path):
    """Lazy package faces: a fresh interpreter running the decode stage's entry has not loaded pandas,
    sync's has not loaded SciPy's optimizers (the sweep's), the sweep reading a joint log still has
    no pandas, and an unknown name is an AttributeError."""
    import subprocess
    import sys

    log = tmp_path / "joints.csv"
    log.write_text("t_s,q1_rad\n0,0\n0.002,0.1\n")
    code = ("import sys\nfrom stringcast.core import stage_entry\nstage_entry('decode')\n"
            "print('pandas' in sys.modules)\nstage_entry('sync')\nprint('scipy.optimize' in sys.modules)\n"
            "stage_entry('sweep')\nprint('scipy.optimize' in sys.modules)\n"
            f"from stringcast.core import read_joint_table\nread_joint_table({str(log)!r})\n"
            "print('pandas' in sys.modules)\n"
            "import stringcast.sync as s\ntry:\n    s.no_such_name\nexcept AttributeError as e:\n    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[:4] == ["False", "False", "True", "False"]
    assert "no attribute 'no_such_name'" in out[4]


def _top_level_imports(path: Path) -> set[str]:
    """The top-level package of every import in ``path``, wherever it stands."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            out.add(node.module.split(".")[0])
    return out


def test_the_pipeline_imports_no_simulator():
    """The pipeline's modules never import the virtual lab or its simulators: what runs the lab (the
    executor's ``virtual`` backend, the CLI's ``campaign`` and ``calib-clip``) loads it on demand by
    module name (:func:`stringcast.execute.lab_module`)."""
    bad = sorted(f"{_module_name(p)} imports {m}" for p in PKG.rglob("*.py")
                 for m in _top_level_imports(p) & set(SIMULATORS))
    assert bad == []


def test_the_lab_uses_the_pipelines_core_only():
    """The virtual lab shares no code with the string model, the estimator or the planner: it imports
    ``stringcast.core`` only (its campaign driver plays motions and runs the workflow by their commands,
    as a person does), so no import runs back up from the lab to the pipeline's higher floors."""
    bad = []
    for p in LAB.rglob("*.py"):
        tree = ast.parse(p.read_text())
        for node in ast.walk(tree):
            mods = ([a.name for a in node.names] if isinstance(node, ast.Import)
                    else [node.module] if isinstance(node, ast.ImportFrom) and not node.level and node.module else [])
            for mod in mods:
                parts = mod.split(".")
                if parts[0] == "stringcast" and (len(parts) < 2 or parts[1] != "core"):
                    bad.append(f"{p.relative_to(LAB)} imports {mod}")
    assert len(list(LAB.rglob("*.py"))) > 10
    assert bad == []


BLOCK_SIMULATORS = """
import importlib.abc, sys
class _NoLab(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in {blocked!r}:
            raise ImportError(f"No module named {{name!r}} (blocked: a core install)")
sys.meta_path.insert(0, _NoLab())
"""


def test_the_pipeline_runs_without_the_lab(tmp_path):
    """A fresh interpreter in which MuJoCo, PyElastica, PyAV and the virtual lab cannot be imported
    (a core install) imports every pipeline module, and the lab's commands say what to install."""
    import subprocess
    import sys

    code = BLOCK_SIMULATORS.format(blocked=set(SIMULATORS)) + f"""
import importlib, pkgutil, stringcast
names = [m.name for m in pkgutil.walk_packages(stringcast.__path__, 'stringcast.')]
for name in names:
    importlib.import_module(name)
print(len(names))
from stringcast.cli import main
print(main(['campaign', 'x', '--root', {str(tmp_path)!r}]))
from stringcast.execute.executor import virtual_lab_trial
try:
    virtual_lab_trial()
except Exception as e:
    print(type(e).__name__, e)
"""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]
    out = run.stdout.strip().split("\n")
    assert int(out[0]) > 40
    assert out[-2] == "2"                        # the CLI's status for bad input, not a traceback
    assert "pip install 'stringcast[lab]'" in run.stdout + run.stderr
    assert out[-1].startswith("ConfigError") and "stringcast[lab]" in out[-1]
