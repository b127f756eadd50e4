"""The string model's predictions for the planner (:mod:`stringcast.plan.planning`).

:class:`Predictor` turns candidate motions into what the model says they do: the
hanging equilibrium at a posture (the initial state), the tip's closest approach to
the target over [0, T + flight window] under the planned set or an ensemble
(:func:`stringcast.model.string_model.closest_approach_batch`, all candidates of a batch in one
numba call), and the tip path written to motion.json. With a residual correction
(:meth:`Predictor.set_residual`, :mod:`stringcast.plan.residual`) every prediction is scored
against the target minus the model's error on the played motion, per parameter set.
"""
from __future__ import annotations


import numpy as np

from stringcast.core import Campaign, ModelSettings, MotionSettings, hand_pose
from .motion import Motion
from stringcast.model import closest_approach_batch, hanging_equilibrium, simulate, simulate_batch, straight_hanging
from .residual import tip_residual


class Predictor:
    """What the string model predicts for candidate motions of one plan.

    Holds the planned parameter set (coeffs (10,), mu (n,)), the campaign's target and
    arm, and the model settings (dt, psi0, the flight window after T), and, once
    :meth:`set_residual` has run, the residual correction (:mod:`stringcast.plan.residual`)
    that moves the target the candidates are scored against.
    """

    def __init__(self, campaign: Campaign, model: ModelSettings, motion: MotionSettings, coeffs: np.ndarray,
                 mu: np.ndarray):
        self.campaign, self.arm = campaign, campaign.arm
        self.coeffs, self.mu = np.asarray(coeffs, float), np.asarray(mu, float)
        self.rate = float(self.arm.controller_rate)
        self.flight = float(motion.flight_window_s)
        self.dt = float(model.dt_s)
        self.psi0 = np.radians(float(model.psi0_deg))
        self.drag = str(model.drag)
        self.halvings = int(model.blowup_halvings)
        self.n, self.l0 = campaign.string.n_points, campaign.string.l0
        self.warnings: list[str] = []
        self.residual = None    # residual.TipResidual: row 0 the planned set, rows 1.. the ensemble

    def _targets(self, rows: np.ndarray) -> dict:
        """closest_approach_batch's target arguments: the fixed target, or per row the
        residual-corrected moving target (:mod:`stringcast.plan.residual`)."""
        if self.residual is None:
            return {"target_xy": self.campaign.target.xy}
        return {"target_xy": self.residual.targets(self.campaign.target.xy), "target_dt": self.residual.dt,
                "target_idx": np.asarray(rows, np.int64)}

    def equilibrium(self, q0: np.ndarray, coeffs: np.ndarray | None = None, mu: np.ndarray | None = None) -> np.ndarray:
        """Hanging equilibrium (n, 2) m at posture q0 with the planned parameters (or ``coeffs``, ``mu``).

        If the model cannot settle (RuntimeError), the string hangs straight down
        instead and a warning is kept for the plan's message.
        """

        c = self.coeffs if coeffs is None else coeffs
        m = self.mu if mu is None else mu
        hp = hand_pose(self.arm, q0)
        try:
            return np.asarray(hanging_equilibrium(c, m, hp, self.l0, self.psi0, self.n, self.dt), float)
        except RuntimeError as exc:
            self.warnings.append(f"initial state straight down: {exc}")
            return np.asarray(straight_hanging(c, m, hp, self.l0, self.n), float)

    def evaluate_ensemble(self, q: np.ndarray, T: float, p_init: np.ndarray, coeffs: np.ndarray, mu: np.ndarray):
        """S candidates q (S, K_t, J) under K parameter sets coeffs (K, 10), mu (K, n), from
        p_init (S, K, n, 2), in one batch: d_min, min_y, ok, each (S, K)."""

        s, k = len(q), len(coeffs)
        hand_t, hand = self.hand_trajectory(q)
        hand = np.ascontiguousarray(np.repeat(hand, k, axis=0))          # (S K, K_t, 3)
        p = np.ascontiguousarray(p_init.reshape(s * k, self.n, 2))
        tg = self._targets(np.tile(np.arange(1, k + 1), s))
        d, _, my, ok = closest_approach_batch(np.tile(coeffs, (s, 1)), np.tile(mu, (s, 1)), hand_t, hand,
                                              np.arange(s * k, dtype=np.int64), p, self.l0, self.psi0, self.dt,
                                              0.0, T + self.flight, floor_y=self.arm.floor_y, drag=self.drag,
                                              halvings=self.halvings, **tg)
        return (np.asarray(d, float).reshape(s, k), np.asarray(my, float).reshape(s, k),
                np.asarray(ok, bool).reshape(s, k))

    def hand_trajectory(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """q (..., K, J) over [0, T] -> hand_t (K + hold,) and hand (..., K + hold, 3), end held for the flight window."""
        hold = int(round(self.flight * self.rate))
        q_ext = np.concatenate([q, np.repeat(q[..., -1:, :], hold, axis=-2)], axis=-2)
        return np.arange(q_ext.shape[-2]) / self.rate, hand_pose(self.arm, q_ext)

    def evaluate(self, q: np.ndarray, T: float, p_init: np.ndarray):
        """Closest approach of B candidates q (B, K, J) from p_init (B, n, 2): d_min, t_min, min_y, ok (B,)."""

        hand_t, hand = self.hand_trajectory(q)
        b = len(q)
        d, tm, my, ok = closest_approach_batch(self.coeffs, self.mu, hand_t, np.ascontiguousarray(hand),
                                               np.arange(b, dtype=np.int64), np.ascontiguousarray(p_init),
                                               self.l0, self.psi0, self.dt, 0.0, T + self.flight,
                                               floor_y=self.arm.floor_y, drag=self.drag, halvings=self.halvings,
                                               **self._targets(np.zeros(b)))
        return (np.asarray(d, float), np.asarray(tm, float), np.asarray(my, float), np.asarray(ok, bool))

    def chord_share(self, q: np.ndarray, p_init: np.ndarray, t: np.ndarray) -> np.ndarray:
        """How taut the model string is: the tip's distance from the grasp over the string's length
        (n l0), for candidates q (B, K, J) from p_init (B, n, 2), each at its own time t (B,) s
        (:func:`~stringcast.model.string_model.simulate_batch` sampled there; the grasp is the hand's
        position at the controller sample nearest t). (B,); NaN where t is not finite or the run blew up."""
        hand_t, hand = self.hand_trajectory(q)
        t = np.asarray(t, float)
        out = np.full(len(q), np.nan)
        good = np.flatnonzero(np.isfinite(t))
        if not len(good):
            return out
        times, at = np.unique(np.clip(t[good], 0.0, hand_t[-1]), return_inverse=True)
        g = len(good)
        pos, _ = simulate_batch(np.tile(self.coeffs, (g, 1)), np.tile(self.mu, (g, 1)), hand_t, np.ascontiguousarray(hand[good]),
                                np.arange(g, dtype=np.int64), np.ascontiguousarray(p_init[good]), self.l0,
                                self.psi0, self.dt, np.concatenate([[0.0], times]), drag=self.drag,
                                halvings=self.halvings)                        # from rest at t = 0
        tip = np.asarray(pos)[np.arange(g), 1 + at, -1, :]                          # (G, 2)
        k = np.clip(np.rint(times[at] * self.rate).astype(np.int64), 0, len(hand_t) - 1)
        grasp = hand[good, k, :2]
        out[good] = np.linalg.norm(tip - grasp, axis=1) / (self.n * self.l0)
        return out

    def set_residual(self, previous: Motion, observed: tuple, p_init: np.ndarray, coeffs: np.ndarray,
                     mu: np.ndarray) -> str:
        """Build ``self.residual`` from the played motion's tracked tip ``observed`` (frame_t, tip,
        valid, delay: :func:`stringcast.plan.residual.observed_tip`) and the model's tip of it under
        each set coeffs (P, 10), mu (P, n) from p_init (P, n, 2). Returns "" or why there is none."""

        ft, tip, valid, delay = observed
        horizon = previous.T + self.flight
        sel = (ft >= 0) & (ft <= horizon)
        if sel.sum() < 2:
            return "no residual correction: no tracked frame within the played motion"
        hand_t, hand = self.hand_trajectory(previous.q)
        p = len(coeffs)
        pos, _ = simulate_batch(coeffs, mu, hand_t, np.repeat(hand[None], p, axis=0), np.arange(p, dtype=np.int64),
                                np.ascontiguousarray(p_init), self.l0, self.psi0, self.dt,
                                np.concatenate([[0.0], ft[sel]]), drag=self.drag, halvings=self.halvings)
        self.residual, why = tip_residual(ft[sel], tip[sel], valid[sel], np.asarray(pos)[:, 1:, -1, :], horizon,
                                          delay)
        return why

    def tip_path(self, motion: Motion, p_init: np.ndarray, rate_hz: float = 200.0) -> np.ndarray:
        """Predicted tip path (S, 3) = (t, x, y) over [0, T + flight window]."""

        hand_t, hand = self.hand_trajectory(motion.q)
        sample_t = np.arange(0.0, hand_t[-1] + 1e-12, 1.0 / rate_hz)
        pos, _ = simulate(self.coeffs, self.mu, hand_t, hand, p_init, self.l0, self.psi0, self.dt, sample_t,
                          drag=self.drag, halvings=self.halvings)
        return np.column_stack([sample_t, np.asarray(pos)[:, -1, :]])
