"""Optimizers for the parameter search (paper Section VI, eqs. 2-3).

All work in chi space, x = chi in [0, 1]^D (eq. 2, :func:`stringcast.model.parameters.decode`),
and share one interface::

    optimizer(rec: Recorder, chi_best (D,), batch, M, rng, estimation) -> None

They ask ``rec`` (the batch objective chi (B, D) -> E (B,) in m, +inf where the
simulation blew up) for candidates in batches of at most ``batch`` until its
budget (``estimation.iterations``) is spent; ``rec`` keeps every candidate,
its E and the search history. ``estimation`` is the estimation settings
(:class:`~stringcast.core.EstimationSettings`).

* ``random_search`` (the paper's eq. 3): chi_m = chi_best + (chi0 / M) beta^m
  RAND(-1, 1), clipped to [0, 1], M = executions so far (the trial index), m the
  candidate index; chi_best starts at the previous trial's estimate and is moved
  to the best candidate after every batch. The first candidate is chi_best itself.
* ``cmaes``: CMA-ES (``cma``) in chi space, i.e. in log-parameter space (chi is
  log(P / P_min) / log(P_max / P_min), eq. 2), initial step ``cmaes_sigma0`` / M
  (default 0.3 / M, in chi units: 0.3 of every log range), population
  ``cmaes_popsize`` (default cma's own 4 + 3 ln D: 11 for D = 12; a small population
  takes many short generations, which suits a budget of a few thousand evaluations).
  Our choices, measured on lab trials (benchmarks/estimation.py): (a) the search is
  unbounded and each point is *evaluated clipped* to [0, 1] and told E (1 + |x -
  clip(x)|^2): Table 2's bounds often hold the optimum (k_s, c_sh at the maximum,
  mu_others at the minimum on the lab strings), and clipping lands on them exactly,
  as the paper's clipped eq. 3 does, where cma's bound transform only approaches them;
  (b) at M = 1 chi_best is the first plan's set (Table 2's minima, a corner, not an
  estimate): it is evaluated first and CMA-ES starts at the centre of the box
  (``cmaes_first_start: best`` starts at chi_best instead); later trials start at
  chi_best; (c) when CMA-ES converges with budget left it restarts from the best
  point; (d) ``cmaes_runs`` runs (default 2) share the budget and step side by side: the first from chi_best (at
  M = 1 the centre), the others from the centre with the full step. Candidates that blow up
  are told a finite worst value; (e) ``cmaes_first_look`` = L > 0: the first L candidates are
  eq. (3) at m = 0 around chi_best (chi_best itself, then chi_best + chi0 / M RAND(-1, 1)
  clipped, so many lie on the box's faces, where the lab strings' best sets sit) and the first
  run starts at their best instead of the centre. On the estimation benchmark's seven lab
  trials (3000 evaluations, 3 seeds) L = 300 ended lower than the centre start on 6 of 7 types
  (median final E, type 3: 84 -> 59 mm, type 2: 64 -> 53 mm): from the centre, CMA-ES settled
  in basins with a light clay point (its mu's chi 0.0-0.4 against 0.8-0.9 in the paper
  search's best sets). ``cmaes_options`` (a mapping) is passed on to
  ``cma.CMAOptions`` (e.g. ``CSA_dampfac``); an unknown name is a ConfigError; (f)
  ``cmaes_grasp_flip`` = s > 0: after the runs have spent the budget, s times the budget left after
  the first look is *added* for a last run from the best set with the hand spring k_ph moved to the
  other end of its range, step sigma0 / 2. E has a weak- and a stiff-hand-spring basin (docs/method.md,
  "Two basins of the hand spring"), and a run seldom crosses from one to the other: the last run tries
  the other basin with everything else as found. The runs before it are exactly those without the
  option, so the estimate changes only where the other basin's E is lower.
* ``de``: SciPy differential evolution (vectorized), x0 = chi_best.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from stringcast.core import PARAM_NAMES, ConfigError, EstimationSettings

from .diagnostics import upper_basin

K_PH = PARAM_NAMES.index("k_ph")
"""chi's index of the hand spring k_ph (``cmaes_grasp_flip``)."""


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

    def extend(self, n: int) -> None:
        """Raise the budget by ``n`` candidates (``cmaes_grasp_flip``'s added evaluations)."""
        self.budget += int(n)
        self.bar.total = self.budget
        self.bar.refresh()

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


def eq3_candidates(chi_best: np.ndarray, chi0: float, M: int, decay: np.ndarray, first: bool,
                   rng: np.random.Generator) -> np.ndarray:
    """Candidates of the paper's eq. (3): chi_best + (chi0 / M) decay_m RAND(-1, 1), clipped to [0, 1].

    Args:
        chi_best: (D,). decay: (B,) beta^m of each candidate. first: the batch starts at m = 0,
            whose candidate is chi_best itself.
    Returns:
        (B, D) candidates."""
    step = (chi0 / M) * decay[:, None] * rng.uniform(-1.0, 1.0, (len(decay), len(chi_best)))
    if first:
        step[0] = 0.0
    return np.clip(chi_best + step, 0.0, 1.0)


def random_search(rec: Recorder, chi_best: np.ndarray, batch: int, M: int, rng: np.random.Generator,
                  estimation: EstimationSettings) -> None:
    """The paper's eq. (3) (see module doc); chi_best moves to the best candidate after each batch."""
    chi0, beta = float(estimation.chi0), float(estimation.beta)
    chi_best = np.asarray(chi_best, float)
    best_E, m = np.inf, 0
    while rec.remaining > 0:
        b = min(batch, rec.remaining)
        cand = eq3_candidates(chi_best, chi0, M, beta ** np.arange(m, m + b), m == 0, rng)
        E = rec(cand)
        i = int(np.argmin(E))
        if E[i] < best_E:
            best_E, chi_best = float(E[i]), cand[i]
        m += b


def cmaes_search(rec: Recorder, chi_best: np.ndarray, batch: int, M: int, rng: np.random.Generator,
                 estimation: EstimationSettings) -> None:
    """CMA-ES (``cma.CMAEvolutionStrategy``, ask/tell) in [0, 1]^D (module doc). Restarts from the best
    point with the initial step when CMA-ES stops early (converged) and budget is left.

    ``cmaes_runs`` (default 2) runs share the budget equally: the first from chi_best with the
    step sigma0 / M (at M = 1 from the centre), the others from the centre with sigma0, so that
    a later trial can leave the basin an earlier one settled in (E is multi-modal: on the lab
    strings a run ends in a weak-hand-spring basin about one time in three).

    The runs are independent, so they step side by side: each generation, every run's population
    is simulated in one batch (chunks of ``batch``), which fills the batch kernel's blocks and
    cores (:func:`stringcast.model.batch_kernels.simulate_batch_kernel`) where one population of
    11 leaves a block of 16 lanes part empty and one core idle. Each run draws its seeds from its
    own generator (``rng.spawn``), so its path is the same however the runs are stepped."""
    d = len(chi_best)
    options = cma_options(estimation)
    sigma0 = float(estimation.cmaes_sigma0)
    popsize = int(estimation.cmaes_popsize) or 4 + int(3 * np.log(d))
    runs = max(1, int(estimation.cmaes_runs))
    first = np.asarray(chi_best, float)
    look = min(int(estimation.cmaes_first_look), rec.remaining)
    if look > 0:  # eq. (3) at m = 0 around chi_best: clipped steps put many samples on the box's faces
        cand = eq3_candidates(first, float(estimation.chi0), M, np.ones(look), True, rng)
        E = np.concatenate([rec(cand[a:a + batch]) for a in range(0, look, batch)])
        first = cand[int(np.argmin(E))]
    elif M == 1 and estimation.cmaes_first_start == "centre":
        rec(first[None])  # chi_best is evaluated, but not an estimate yet: start at the centre
        first = np.full(d, 0.5)
    starts = [(first, sigma0 / M)] + [(np.full(d, 0.5), sigma0)] * (runs - 1)
    added = int(float(estimation.cmaes_grasp_flip) * rec.remaining)
    share = rec.remaining // runs
    quotas = [share] * (runs - 1) + [rec.remaining - share * (runs - 1)]
    gens = [_cma_run(x0, s0, popsize, quota, child, options)
            for (x0, s0), quota, child in zip(starts, quotas, rng.spawn(runs))]
    results = _side_by_side(rec, gens, starts, batch)
    _, best, s0 = min(results, key=lambda x: x[0])
    _spend_around(rec, best, s0 / 4, batch, rng)
    if added >= popsize:  # cmaes_grasp_flip: added evaluations in the hand spring's other basin
        rec.extend(added)
        flip = (flipped_grasp(best), sigma0 / 2)
        (_, best, s0), = _side_by_side(rec, [_cma_run(*flip, popsize, added, rng.spawn(1)[0], options)], [flip],
                                       batch)
        _spend_around(rec, best, s0 / 4, batch, rng)


def _spend_around(rec: Recorder, centre: np.ndarray, step: float, batch: int, rng: np.random.Generator) -> None:
    """Spend what is left of the budget (< popsize, or after a stop) on Gaussian steps around ``centre``."""
    while rec.remaining > 0:
        rec(np.clip(centre + step * rng.standard_normal((min(batch, rec.remaining), len(centre))), 0.0, 1.0))


def flipped_grasp(chi: np.ndarray) -> np.ndarray:
    """chi (D,) with the hand spring k_ph moved to the other end of its range (chi 0 <-> 1, split at
    ``diagnostics.BASIN_SPLIT``)."""
    out = np.array(chi, float, copy=True)
    out[K_PH] = 0.0 if upper_basin(out[K_PH]) else 1.0
    return out


def _side_by_side(rec: Recorder, gens: list, starts: list, batch: int) -> list[tuple[float, np.ndarray, float]]:
    """Step CMA-ES runs (:func:`_cma_run` generators, started at ``starts``, (x0, sigma0) each) side by
    side until all are done: each generation every run's population in one batch, evaluated by ``rec``
    in chunks of ``batch``. Returns each run's best (E, point, sigma0)."""
    results = [(np.inf, x0, s0) for x0, s0 in starts]
    asked = {}
    for r, gen in enumerate(gens):
        _advance(gen, None, r, asked, results, starts)
    while asked:
        order = sorted(asked)
        xs = np.concatenate([asked[r] for r in order])
        E = np.concatenate([rec(xs[a:a + batch]) for a in range(0, len(xs), batch)])
        for r, part in zip(order, np.split(E, np.cumsum([len(asked[r]) for r in order])[:-1])):
            _advance(gens[r], part, r, asked, results, starts)
    return results


def _advance(gen, E, r: int, asked: dict, results: list, starts: list) -> None:
    """Tell run ``r`` its population's E (None: start it); keep what it asks next in ``asked``, or its
    best (E, point, sigma0) in ``results`` once it is done."""
    try:
        asked[r] = gen.send(E)
    except StopIteration as done:
        asked.pop(r, None)
        results[r] = (*done.value, starts[r][1])


def cma_options(estimation: EstimationSettings) -> dict:
    """``estimation.cmaes_options`` checked against ``cma.CMAOptions``.

    Raises:
        ConfigError: not a mapping, or a name cma does not know."""
    import cma

    options = estimation.cmaes_options or {}
    if not isinstance(options, Mapping):
        raise ConfigError("estimation.cmaes_options: expected a mapping of cma.CMAOptions names to values")
    unknown = sorted(set(options) - set(cma.CMAOptions()))
    if unknown:
        raise ConfigError(f"estimation.cmaes_options: unknown cma option(s) {unknown} (see cma.CMAOptions())")
    return dict(options)


def _cma_run(x0: np.ndarray, sigma0: float, popsize: int, quota: int, rng: np.random.Generator,
             options: Mapping | None = None):
    """One CMA-ES run from x0 over ``quota`` evaluations, as a generator: it yields each population
    clipped to [0, 1] ((popsize, D)), is sent its E ((popsize,), m), and returns its best (E, point).
    ``options`` (checked by :func:`cma_options`) override the defaults below. CMA-ES restarts from the
    best point, with sigma0, when it stops."""
    import cma

    best = (np.inf, x0)
    while quota >= popsize:
        es = cma.CMAEvolutionStrategy(x0, sigma0, {
            "popsize": popsize, "seed": int(rng.integers(1, 2**31 - 1)),
            "verbose": -9, "tolfun": 1e-12, "tolx": 1e-6, **(options or {})})
        if es.stop():
            break
        while quota >= popsize and not es.stop():
            xs = np.asarray(es.ask())
            inside = np.clip(xs, 0.0, 1.0)
            E = np.asarray((yield inside), float)
            quota -= len(E)
            finite = E[np.isfinite(E)]
            worst = (2.0 * finite.max() + 1.0) if finite.size else 1e6
            fit = np.where(np.isfinite(E), E, worst) * (1.0 + np.sum((xs - inside) ** 2, axis=1))
            es.tell(list(xs), fit.tolist())
            i = int(np.argmin(E))
            if E[i] < best[0]:
                best = (float(E[i]), inside[i])
        x0 = best[1]
    return best


def de_search(rec: Recorder, chi_best: np.ndarray, batch: int, M: int, rng: np.random.Generator,
              estimation: EstimationSettings) -> None:
    """SciPy ``differential_evolution`` (vectorized, no polish), x0 = chi_best; candidates in chunks of ``batch``."""
    from scipy.optimize import differential_evolution

    d = len(chi_best)
    popsize = int(estimation.de_popsize)

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
