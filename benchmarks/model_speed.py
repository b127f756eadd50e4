"""Benchmark ``model_speed``: string-model throughput (docs/results.md, "Benchmark records").

Figures, measured in this run:
* point_steps_per_s_per_core: mass-point steps per second of ``model.simulate_batch``
  on one thread (``numba.set_num_threads(1)``), n = 15 points, dt = 1e-4 s, a batch of
  ``batch_single_thread`` (64) candidates: the size estimation and planning call it with
  (``estimation.batch``, ``motion.batch``); the kernel steps ``lanes`` (16) candidates at
  once. ``..._batch_8`` is the same for a batch of 8, the size this figure used before the
  lock-step kernel (half of a 16-lane block idles there).
* candidates_per_s: candidates per second of a batch on all cores (1 s of motion,
  frames sampled at 500 fps), and the same for ``closest_approach_batch``.
* reference: MuJoCo stepping a planar chain of hinge-jointed capsules with the same
  number of links (Euler integrator, same dt), one thread, stepped in C by
  ``mujoco.rollout``.
* ratio_to_reference: the model's single-thread rate over MuJoCo's, the median over 15 pairs
  timed in turn (:func:`paired_ratio`, each pair's in ``ratio_to_reference_paired``);
  ``ratio_of_best_rates`` is the two best-of-7 rates' ratio, as this figure was before.

Run: ``python -m benchmarks.model_speed [--quick]`` -> results/bench/model_speed.json.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.common import header, write

N_POINTS, L0, DT = 15, 0.034, 1e-4


def _case(duration: float):
    """Mid-range Table 2 coefficients, a 2 Hz swinging hand, the hanging start."""
    from stringcast.core import model_ranges, settings_from_config
    from stringcast.core import load_config
    from stringcast.api import hanging_equilibrium

    lo, hi, _ = model_ranges(settings_from_config(load_config()).model)
    coeffs = np.sqrt(lo * hi)
    hand_t = np.arange(0.0, duration + 1e-9, 0.002)
    w = 2 * np.pi * 2.0
    hand = np.stack([0.8 + 0.1 * np.sin(w * hand_t), 0.3 + 0.05 * np.cos(1.5 * w * hand_t),
                     -1.2 + 0.6 * np.sin(w * hand_t)], axis=1)
    mu = np.ones(N_POINTS)
    p0 = hanging_equilibrium(coeffs, mu, hand[0], L0, 0.0, N_POINTS)
    return coeffs, mu, hand_t, hand, p0


def _best_of(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def model_rates(duration: float, batch: int, repeats: int) -> dict:
    import numba

    from stringcast.model.lockstep import LANES
    from stringcast.api import closest_approach_batch, simulate_batch

    coeffs, mu, hand_t, hand, p0 = _case(duration)
    sample_t = np.arange(0.0, duration, 0.002)
    steps = int(np.ceil(duration / DT))

    def sim(b):
        C = np.tile(coeffs, (b, 1))
        M = np.tile(mu, (b, 1))
        idx = np.zeros(b, np.int64)
        return lambda: simulate_batch(C, M, hand_t, hand[None], idx, p0[None], L0, 0.0, DT, sample_t)

    def closest(b):
        idx = np.zeros(b, np.int64)
        return lambda: closest_approach_batch(coeffs, mu, hand_t, hand[None], idx, p0[None], L0, 0.0, DT,
                                              0.0, duration, np.array([1.3, 0.45]))

    all_threads = numba.get_num_threads()
    sim(1)()
    closest(1)()                                         # compile (or load the cache)
    numba.set_num_threads(1)
    try:
        t_single = _best_of(sim(batch), repeats)
        t_single_closest = _best_of(closest(batch), repeats)
        t_single_8 = _best_of(sim(8), repeats)
    finally:
        numba.set_num_threads(all_threads)
    t_batch = _best_of(sim(batch), repeats)
    t_batch_closest = _best_of(closest(batch), repeats)
    return {
        "point_steps_per_s_per_core": batch * N_POINTS * steps / t_single,
        "point_steps_per_s_per_core_closest_approach": batch * N_POINTS * steps / t_single_closest,
        "point_steps_per_s_per_core_batch_8": 8 * N_POINTS * steps / t_single_8,
        "batch_single_thread": batch, "lanes": LANES,
        "candidates_per_s": batch / t_batch,
        "candidates_per_s_closest_approach": batch / t_batch_closest,
        "threads": all_threads, "batch": batch, "simulated_s": duration,
    }


def _mujoco_chain(duration: float):
    """MuJoCo: a planar chain of N_POINTS hinged capsules hanging from a fixed base; (one run, its
    point-steps). One run is ``duration`` s stepped in C by mujoco.rollout, one MjData: one thread."""
    import mujoco
    from mujoco import rollout

    def body(i: int) -> str:
        inner = body(i + 1) if i + 1 < N_POINTS else ""
        pos = "0 0 0" if i == 0 else f"0 {-L0} 0"
        return (f'<body pos="{pos}"><joint type="hinge" axis="0 0 1" stiffness="1e-3" damping="1e-3"/>'
                f'<geom type="capsule" fromto="0 0 0 0 {-L0} 0" size="0.0015" mass="0.001"/>{inner}</body>')

    xml = (f'<mujoco><option timestep="{DT}" integrator="Euler" gravity="0 -9.81 0"/>'
           f'<worldbody>{body(0)}</worldbody></mujoco>')
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qpos[:] = 0.3
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state0, spec)
    steps = int(np.ceil(duration / DT))
    return (lambda: rollout.rollout(model, data, state0[None], nstep=steps)), N_POINTS * steps


def mujoco_chain_rate(duration: float, repeats: int) -> dict:
    """MuJoCo's chain (:func:`_mujoco_chain`): point-steps per second, best of ``repeats``."""
    import mujoco

    run, point_steps = _mujoco_chain(duration)
    return {"name": "mujoco_chain", "links": N_POINTS, "integrator": "Euler", "stepping": "mujoco.rollout",
            "point_steps_per_s_per_core": point_steps / _best_of(run, repeats), "mujoco_version": mujoco.__version__}


def paired_ratio(duration: float, batch: int, ref_duration: float, pairs: int) -> dict:
    """The model's single-thread rate over MuJoCo's, timed in turn (ours, MuJoCo, ours, ...) and
    taken pair by pair: a shared machine's speed drifts within a run (MuJoCo's best-of-7 moved
    from 1.4 to 2.2 M point-steps/s between runs here), and a pair sees the same machine."""
    import numba

    from stringcast.api import simulate_batch

    coeffs, mu, hand_t, hand, p0 = _case(duration)
    sample_t = np.arange(0.0, duration, 0.002)
    C, M, idx = np.tile(coeffs, (batch, 1)), np.tile(mu, (batch, 1)), np.zeros(batch, np.int64)
    ours_steps = batch * N_POINTS * int(np.ceil(duration / DT))
    ref, ref_steps = _mujoco_chain(ref_duration)
    all_threads = numba.get_num_threads()
    numba.set_num_threads(1)
    ratios = []
    try:
        for _ in range(pairs):
            t0 = time.perf_counter()
            simulate_batch(C, M, hand_t, hand[None], idx, p0[None], L0, 0.0, DT, sample_t)
            t1 = time.perf_counter()
            ref()
            t2 = time.perf_counter()
            ratios.append((ours_steps / (t1 - t0)) / (ref_steps / (t2 - t1)))
    finally:
        numba.set_num_threads(all_threads)
    return {"median": float(np.median(ratios)), "pairs": [float(r) for r in ratios]}


def run(quick: bool = False) -> dict:
    """Measure, write results/bench/model_speed.json and return its content."""
    duration = 0.25 if quick else 1.0
    repeats = 3 if quick else 7                   # best of: the machine may be shared
    rates = model_rates(duration, batch=64, repeats=repeats)
    ref = mujoco_chain_rate(0.1 if quick else 0.5, repeats)
    paired = paired_ratio(duration, 64, 0.1 if quick else 0.5, 5 if quick else 15)
    doc = {
        **header("model_speed", quick), "n_points": N_POINTS, "dt_s": DT, **rates,
        "reference": ref,
        "ratio_to_reference": paired["median"],
        "ratio_to_reference_paired": paired["pairs"],
        "ratio_of_best_rates": rates["point_steps_per_s_per_core"] / ref["point_steps_per_s_per_core"],
    }
    write("model_speed", doc)
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="short runs")
    doc = run(ap.parse_args().quick)
    print(f"model: {doc['point_steps_per_s_per_core'] / 1e6:.1f} M point-steps/s/core, "
          f"{doc['candidates_per_s']:.1f} candidates/s ({doc['threads']} threads, {doc['simulated_s']} s each); "
          f"MuJoCo chain {doc['reference']['point_steps_per_s_per_core'] / 1e6:.2f} M "
          f"(ratio {doc['ratio_to_reference']:.1f})")


if __name__ == "__main__":
    main()
