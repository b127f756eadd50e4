"""The face for scripts (stringcast.api): every name resolves, loads its stage only when used, and the
in-memory calls do what the file stages do."""
from __future__ import annotations

import subprocess
import sys

import numpy as np

import stringcast.api as api
from stringcast.core import PARAM_NAMES, read_json, write_json


def test_every_name_of_the_face_resolves_and_says_what_it_is():
    for name in api.__all__:
        obj = getattr(api, name)
        assert (obj.__doc__ or "").strip(), name
    assert "fit_tracks" in dir(api)


def test_importing_the_face_loads_no_stage():
    code = ("import sys, stringcast.api as a; "
            "print(sorted(m for m in sys.modules if m.split('.')[1:2] and m.startswith('stringcast.') and "
            "m.split('.')[1] in ('track', 'estimate', 'plan', 'model', 'report', 'calibrate', 'sync', 'video')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out


def test_plan_next_in_memory_is_the_plan_stage_without_its_files(tmp_path, campaign, settings):
    """plan_next on the estimate and the played motion gives the motion run_plan writes (the paper's
    planner: no tracks needed)."""
    from dataclasses import replace

    from stringcast.plan import planning
    from stringcast.plan.motion import read_motion_json

    s = replace(settings, motion=replace(settings.motion, max_candidates=512, extra_after_hit=32, batch=64,
                                         posture_pool=8))
    coeffs, mu = planning.first_parameters(model=s.model, motion=s.motion, string=campaign.string)
    first = planning.search(campaign, s.model, s.motion, coeffs, mu, np.random.default_rng(3))
    planning.write_motion(first, campaign, s.motion, coeffs, mu, 0, tmp_path / "m1.csv", tmp_path / "m1.json", "first")
    params = {"coefficients": dict(zip(PARAM_NAMES, coeffs * 2)), "mu": mu}
    write_json(tmp_path / "params.json", params)
    filed = api.run_plan(tmp_path / "params.json", tmp_path / "m1.json", campaign, tmp_path / "m2.csv",
                         tmp_path / "m2.json", seed=4, model=s.model, motion=s.motion)
    played = read_motion_json(tmp_path / "m1.json", campaign.arm.n_joints, campaign.arm.controller_rate)
    memory = api.plan_next(read_json(tmp_path / "params.json"), played, campaign, 4, model=s.model, motion=s.motion)
    np.testing.assert_array_equal(memory.result.motion.control_points, filed.motion.control_points)
    assert memory.result.d_min == filed.d_min and memory.failed_fit is None
    np.testing.assert_allclose(memory.coeffs, coeffs * 2)


def test_the_face_is_documented_in_numpydoc_sections():
    """Each function of the face says its Parameters (with shapes and units where arrays) and what it
    returns; each record its Attributes, in numpydoc's underlined sections."""
    import inspect
    import re

    def section(doc: str, name: str) -> bool:
        return re.search(rf"^{name}\n-{{{len(name)}}}$", doc, re.M) is not None

    missing = []
    for name in api.__all__:
        obj = getattr(api, name)
        doc = inspect.getdoc(obj) or ""
        if inspect.isclass(obj):
            if not (section(doc, "Attributes") or section(doc, "Parameters")):
                missing.append(f"{name}: Attributes")
            continue
        sig = inspect.signature(obj)
        params = [p for p in sig.parameters.values() if p.kind is not p.VAR_KEYWORD]
        if params and not section(doc, "Parameters"):
            missing.append(f"{name}: Parameters")
        if sig.return_annotation not in (None, "None") and not section(doc, "Returns"):
            missing.append(f"{name}: Returns")
    assert missing == []
