"""Figures for the reports (matplotlib, Agg), returned as inline PNG data URIs.

Each function takes plain arrays in SI units and draws in mm for people. The
figure numbers refer to the paper (Tabata et al.): Fig. 8a tip paths, Fig. 8b
arm tip paths, Fig. 11 parameters on log axes, Table 4 masses.
"""
from __future__ import annotations

import base64
import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def to_data_uri(fig) -> str:
    """Render a matplotlib figure to a ``data:image/png;base64,...`` URI and close it."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def png_file_uri(path) -> str:
    with open(path, "rb") as f:
        return "data:image/png;base64," + base64.b64encode(f.read()).decode("ascii")


def _plane(ax, target_xy, radius, title, **legend):
    """The swing-plane view shared by the path figures: the target (m) drawn, equal mm axes, legend."""
    ax.add_patch(plt.Circle(np.asarray(target_xy) * 1000, radius * 1000, color="tab:red", alpha=0.35))
    ax.plot(*(np.asarray(target_xy) * 1000), "x", color="tab:red", label="target")
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(title)
    ax.legend(fontsize=8, **legend)


def tip_paths(t_tr, tip_tr, t_sim, tip_sim, target_xy, radius, title="Tip paths (Fig. 8a)"):
    """Tracked vs simulated tip: (F,), (F,2) m each; plane view and distance over time."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    a.plot(tip_tr[:, 0] * 1000, tip_tr[:, 1] * 1000, ".", ms=2, label="tracked tip")
    a.plot(tip_sim[:, 0] * 1000, tip_sim[:, 1] * 1000, "-", lw=1, label="simulated tip (estimate)")
    _plane(a, target_xy, radius, title)
    for arr, lab, st in ((tip_tr, "tracked", "."), (tip_sim, "simulated", "-")):
        t = t_tr if lab == "tracked" else t_sim
        d = np.hypot(arr[:, 0] - target_xy[0], arr[:, 1] - target_xy[1]) * 1000
        b.plot(t, d, st, ms=2, lw=1, label=lab)
    b.axhline(radius * 1000, color="tab:red", lw=0.8, ls="--", label="target radius")
    b.set_xlabel("t [s] (controller clock)")
    b.set_ylabel("tip to target [mm]")
    b.set_yscale("log")
    b.legend(fontsize=8)
    return to_data_uri(fig)


def arm_paths(paths: dict, target_xy, radius, title="Arm tip (grasp) paths (Fig. 8b)"):
    """paths: label -> (K,2) m grasp-point paths."""
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    for label, p in paths.items():
        ax.plot(p[:, 0] * 1000, p[:, 1] * 1000, lw=1.2, label=label)
        ax.plot(p[0, 0] * 1000, p[0, 1] * 1000, "o", ms=4, color=ax.lines[-1].get_color())
    ax.plot(0, 0, "ks", label="arm base")
    _plane(ax, target_xy, radius, title)
    return to_data_uri(fig)


def parameters(names, values, lo, hi, spread=None, title="Estimated parameters against Table 2 (Fig. 11)",
               at_bound=None):
    """names (P,), values/lo/hi (P,): log-axis bars of each range with the estimate.

    spread: optional name -> (min, max, status) of the near-best parameter sets
    (``params.json`` diagnostics), drawn as a bar, green when pinned, orange when loose.
    at_bound: optional (P,) ``"lower"``/``"upper"``/``""`` (:func:`stringcast.report.verdicts.at_bounds`):
    an estimate at a bound of its range is ringed in red and its name marked.
    """
    fig, ax = plt.subplots(figsize=(7, 0.35 * len(names) + 1.2))
    y = np.arange(len(names))[::-1]
    shown = set()
    for name, yi, v, a, b in zip(names, y, values, lo, hi):
        ax.plot([a, b], [yi, yi], color="0.85", lw=8, solid_capstyle="butt",
                label=None if "range" in shown else "Table 2 range")
        shown.add("range")
        if spread and name in spread:
            s0, s1, status = spread[name]
            label = f"near-best sets ({status})"
            ax.plot([s0, s1], [yi, yi], color="tab:green" if status == "pinned" else "tab:orange", lw=3,
                    solid_capstyle="butt", label=None if label in shown else label)
            shown.add(label)
        ax.plot(v, yi, "o", color="tab:blue", label=None if "est" in shown else "estimate")
        shown.add("est")
    flags = list(at_bound) if at_bound is not None else [""] * len(names)
    for yi, v, flag in zip(y, values, flags):
        if flag:
            ax.plot(v, yi, "o", ms=13, mfc="none", mec="tab:red", mew=2,
                    label=None if "bound" in shown else "at a bound of its range")
            shown.add("bound")
    ax.set_yticks(y)
    ax.set_yticklabels([f"{n} (at {f} bound)" if f else n for n, f in zip(names, flags)])
    ax.set_xscale("log")
    ax.set_title(title)
    ax.grid(axis="x", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return to_data_uri(fig)


def masses(mu, special_points, title="Estimated relative masses per point (Table 4)"):
    """mu (n,): bar per mass point 1..n; special points (weights, pipes) highlighted."""
    n = len(mu)
    fig, ax = plt.subplots(figsize=(7, 2.8))
    colors = ["tab:orange" if i + 1 in set(special_points) else "tab:blue" for i in range(n)]
    ax.bar(np.arange(1, n + 1), mu, color=colors)
    ax.set_yscale("log")
    ax.set_xlabel("mass point i (orange: weight or stiff section)")
    ax.set_ylabel("m_i (relative)")
    ax.set_xticks(np.arange(1, n + 1))
    ax.set_title(title)
    return to_data_uri(fig)


def search_history(evals, best_E_m, title="E over the search"):
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.plot(evals, np.asarray(best_E_m) * 1000, "-")
    ax.set_xlabel("evaluations")
    ax.set_ylabel("best E [mm]")
    ax.set_yscale("log")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    return to_data_uri(fig)


def joint_curves(t, q, qd=None, title="Next motion: joint angles and velocities"):
    """t (K,), q (K,J) rad; velocities by finite differences when not given."""
    if qd is None:
        qd = np.gradient(q, t, axis=0)
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 3.2))
    for j in range(q.shape[1]):
        a.plot(t, np.degrees(q[:, j]), label=f"q{j + 1}")
        b.plot(t, np.degrees(qd[:, j]), label=f"q{j + 1}")
    a.set_ylabel("angle [deg]")
    b.set_ylabel("velocity [deg/s]")
    for ax in (a, b):
        ax.set_xlabel("t [s]")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    a.set_title(title)
    return to_data_uri(fig)


def valid_per_point(points, share_all, share_motion=None, title="Tracked points: share of frames valid"):
    """Bars: share (0-1) of frames in which each point 1..n was tracked, over the clip and (optional) the motion."""
    fig, ax = plt.subplots(figsize=(6, 3))
    points = np.asarray(points)
    w = 0.4 if share_motion is not None else 0.8
    ax.bar(points - (w / 2 if share_motion is not None else 0), np.asarray(share_all) * 100, w, label="whole clip")
    if share_motion is not None:
        ax.bar(points + w / 2, np.asarray(share_motion) * 100, w, label="motion and flight window")
    ax.set_xlabel("point (1 = next to the grasp, n = tip)")
    ax.set_ylabel("frames valid [%]")
    ax.set_ylim(0, 130)                                   # room for the legend above the bars
    ax.set_yticks(range(0, 101, 20))
    ax.set_title(title)
    ax.legend(fontsize=8, loc="upper left", ncol=2)
    ax.grid(alpha=0.3, axis="y")
    return to_data_uri(fig)


def campaign_tips(paths: dict, target_xy, radius, title="Tracked tip path per execution (Fig. 7)"):
    """paths: label -> (F,2) m tracked tip positions (NaN where not valid)."""
    fig, ax = plt.subplots(figsize=(6, 5))
    for label, p in paths.items():
        line, = ax.plot(p[:, 0] * 1000, p[:, 1] * 1000, ".", ms=2)
        ax.plot([], [], "o", ms=5, color=line.get_color(), label=label)  # legend entry readable at any ms
    ax.plot(0, 0, "ks", label="arm base")
    _plane(ax, target_xy, radius, title)
    return to_data_uri(fig)
