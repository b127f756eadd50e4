"""Optimizers for the parameter search (paper Section VI, eqs. 2-3).

All work in chi space, x = chi in [0, 1]^D (eq. 2, :func:`stringcast.estimation.decode`),
and share one interface::

    optimizer(rec: Recorder, chi_best (D,), batch, M, rng, settings) -> None

They ask ``rec`` (the batch objective chi (B, D) -> E (B,) in m, +inf where the
simulation blew up) for candidates in batches of at most ``batch`` until its
budget (``config.estimation.iterations``) is spent; ``rec`` keeps every candidate,
its E and the search history. ``settings`` is ``config.estimation``.

* ``random_search`` (the paper's eq. 3): chi_m = chi_best + (chi0 / M) beta^m
  RAND(-1, 1), clipped to [0, 1], M = executions so far (the trial index), m the
  candidate index; chi_best starts at the previous trial's estimate and is moved
  to the best candidate after every batch. The first candidate is chi_best itself.
* ``cmaes``: CMA-ES (``cma``) from chi_best, sigma0 = 0.3 chi0 / M, bounds [0, 1].
* ``de``: SciPy differential evolution (vectorized), x0 = chi_best.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np


class Recorder:
    """Wraps the objective: counts the budget, records every candidate, the history, a progress bar.

    ``rec(chi)`` takes chi (B, D) (clipped to [0, 1]) and returns E (B,) in m.
    Attributes: chi, E (lists of the batches asked), history {"evaluations": [...],
    "best_E_m": [...]} after each batch, best (m), bar (tqdm; the caller closes it).
    """

    def __init__(self, objective, budget: int, desc: str):
        from tqdm.auto import tqdm

        self.objective, self.budget = objective, int(budget)
        self.chi: list[np.ndarray] = []
        self.E: list[np.ndarray] = []
        self.history = {"evaluations": [], "best_E_m": []}
        self.best = np.inf
        self.bar = tqdm(total=self.budget, desc=desc, unit="cand", disable=None)

    @property
    def remaining(self) -> int:
        """Candidates left in the budget."""
        return self.budget - sum(len(e) for e in self.E)

    def __call__(self, chi: np.ndarray) -> np.ndarray:
        chi = np.clip(np.atleast_2d(np.asarray(chi, float)), 0.0, 1.0)
        E = self.objective(chi)
        self.chi.append(chi)
        self.E.append(E)
        self.best = min(self.best, float(np.min(E)))
        self.history["evaluations"].append(self.budget - self.remaining)
        self.history["best_E_m"].append(self.best)
        self.bar.update(len(E))
        return E


def random_search(rec: Recorder, chi_best: np.ndarray, batch: int, M: int, rng: np.random.Generator,
                  settings: Mapping) -> None:
    """The paper's eq. (3) (see module doc); chi_best moves to the best candidate after each batch."""
    chi0, beta = float(settings.get("chi0", 1.0)), float(settings.get("beta", 0.998))
    chi_best = np.asarray(chi_best, float)
    best_E, m = np.inf, 0
    while rec.remaining > 0:
        b = min(batch, rec.remaining)
        ms = np.arange(m, m + b)
        step = (chi0 / M) * beta ** ms[:, None] * rng.uniform(-1.0, 1.0, (b, len(chi_best)))
        if m == 0:
            step[0] = 0.0  # candidate 0 is chi_best itself
        cand = np.clip(chi_best + step, 0.0, 1.0)
        E = rec(cand)
        i = int(np.argmin(E))
        if E[i] < best_E:
            best_E, chi_best = float(E[i]), cand[i]
        m += b


def cmaes_search(rec: Recorder, chi_best: np.ndarray, batch: int, M: int, rng: np.random.Generator,
                 settings: Mapping) -> None:
    """CMA-ES (``cma.CMAEvolutionStrategy``, ask/tell) in [0, 1]^D, population = batch."""
    import cma

    sigma0 = 0.3 * float(settings.get("chi0", 1.0)) / M
    es = cma.CMAEvolutionStrategy(np.asarray(chi_best, float), sigma0, {
        "bounds": [0.0, 1.0], "popsize": max(4, batch), "seed": int(rng.integers(1, 2**31 - 1)),
        "verbose": -9, "maxfevals": rec.budget, "tolfun": 0.0, "tolx": 1e-9})
    while rec.remaining > 0 and not es.stop():
        xs = es.ask()
        xs = xs[:rec.remaining] if len(xs) > rec.remaining else xs
        E = rec(np.asarray(xs))
        if len(xs) < es.popsize:
            break
        finite = E[np.isfinite(E)]
        worst = (2.0 * finite.max() + 1.0) if finite.size else 1e6
        es.tell(xs, np.where(np.isfinite(E), E, worst).tolist())


def de_search(rec: Recorder, chi_best: np.ndarray, batch: int, M: int, rng: np.random.Generator,
              settings: Mapping) -> None:
    """SciPy ``differential_evolution`` (vectorized, no polish), x0 = chi_best; candidates in chunks of ``batch``."""
    from scipy.optimize import differential_evolution

    d = len(chi_best)
    popsize = int(settings.get("de_popsize", 8))

    def f(x):  # x (D, S) -> (S,)
        x = np.asarray(x).T
        out = np.full(len(x), 1e6)
        for a in range(0, len(x), batch):
            k = min(batch, rec.remaining)
            if k <= 0:
                break
            E = rec(x[a:a + k])
            out[a:a + k] = np.where(np.isfinite(E), E, 1e6)
        return out

    maxiter = max(0, rec.budget // (popsize * d) - 1)
    differential_evolution(f, [(0.0, 1.0)] * d, maxiter=maxiter, popsize=popsize, polish=False, tol=0.0,
                           x0=np.asarray(chi_best, float), vectorized=True, updating="deferred",
                           rng=np.random.default_rng(rng.integers(2**31)))


OPTIMIZERS = {"random_search": random_search, "cmaes": cmaes_search, "de": de_search}
