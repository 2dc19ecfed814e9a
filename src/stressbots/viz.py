"""Pictures: plans, structures and runs drawn to scale in the arena frame (um, y up).

Pure drawing: functions take computed results and return matplotlib figures; saving goes through
:func:`stressbots.outputs.save_figure`. matplotlib is imported with the non-interactive Agg backend so
that pictures work on machines without a screen.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from .robots import body_corners, orbit_radii, turning_centres


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def robot_colours(n: int) -> list:
    """One distinct colour per robot (scenario order)."""
    plt = _plt()
    cmap = plt.get_cmap("tab10" if n <= 10 else "tab20")
    return [cmap(i % cmap.N) for i in range(n)]


def draw_bodies(ax, poses, lengths, widths, colours, *, fill_alpha=0.0, edge_alpha=1.0, lw=1.0, front=True, zorder=3):
    """Draw body rectangles (and a mark on each front edge) for ``poses`` (N, 3)."""
    from matplotlib.patches import Polygon as MplPolygon

    corners = body_corners(poses, lengths, widths)
    for k, c in enumerate(corners):
        col = colours[k]
        ax.add_patch(
            MplPolygon(c, closed=True, facecolor=(*col[:3], fill_alpha), edgecolor=(*col[:3], edge_alpha), lw=lw, zorder=zorder)
        )
        if front:
            ax.plot(c[:2, 0], c[:2, 1], color=col, lw=lw * 2.5, alpha=edge_alpha, zorder=zorder + 0.1, solid_capstyle="butt")


def _frame(ax, scenario, pts: np.ndarray, pad: float = 150.0):
    if scenario.arena_um is not None:
        w, h = scenario.arena_um
        ax.add_patch(_plt().Rectangle((0, 0), w, h, fill=False, lw=1.2, ec="0.3", zorder=1))
        ax.set_xlim(-pad, w + pad)
        ax.set_ylim(-pad, h + pad)
    else:
        lo, hi = pts.min(axis=0) - pad, pts.max(axis=0) + pad
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (um)")
    ax.set_ylabel("y (um)")
    ax.grid(True, lw=0.3, alpha=0.5)


def plot_plan(scenario, result, *, title: str | None = None):
    """The nominal plan: start poses, orbit discs, trajectories coloured by robot, and the slots.

    ``result`` is a :class:`stressbots.planning.PlanResult` (its replay trace gives the trajectories).
    """
    plt = _plt()
    n = scenario.n
    cols = robot_colours(n)
    fig, ax = plt.subplots(figsize=(8, 8))
    L, W, R = scenario.lengths_um, scenario.widths_um, scenario.turn_radii_um
    starts = scenario.starts
    goals = result.plan.goal_array()
    order = list(result.analysis.order)
    rank = {name: k + 1 for k, name in enumerate(order)}
    centres = turning_centres(starts, R)
    rstar = orbit_radii(L, W, R)
    for i, name in enumerate(scenario.names):
        if rank[name] < n:  # D_1..D_{n-1} orbit at their starts
            ax.add_patch(plt.Circle(centres[i], rstar[i], fill=True, fc=(*cols[i][:3], 0.06), ec=cols[i], ls="--", lw=0.8, zorder=1))
    trace = result.replay.trace_poses
    if trace.size:
        for i in range(n):
            ax.plot(trace[:, i, 0], trace[:, i, 1], color=cols[i], lw=1.2, alpha=0.9, zorder=2)
    draw_bodies(ax, starts, L, W, cols, fill_alpha=0.15)
    draw_bodies(ax, goals, L, W, cols, fill_alpha=0.55, lw=0.8)
    for i, name in enumerate(scenario.names):
        ax.annotate(f"{name} (D{rank[name]})", starts[i, :2], xytext=(6, 6), textcoords="offset points", fontsize=8, color=cols[i], zorder=5)
    pts = np.vstack([starts[:, :2], goals[:, :2], centres + rstar[:, None], centres - rstar[:, None]])
    _frame(ax, scenario, pts)
    s = result.summary
    ax.set_title(
        title
        or f"{scenario.name}: {s['structure']} by {n} robots - {s['duration_s']:.1f} s, {s['steps']} steps, efficiency {s['efficiency']:.2f}",
        fontsize=10,
    )
    return fig


def plot_structure(scenario, poses, goals, *, title: str = "", labels: Sequence[str] | None = None):
    """Final bodies (filled) over the target slots (outlined)."""
    plt = _plt()
    n = scenario.n
    cols = robot_colours(n)
    fig, ax = plt.subplots(figsize=(5, 5))
    draw_bodies(ax, goals, scenario.lengths_um, scenario.widths_um, ["0.4"] * n, fill_alpha=0.0, lw=1.0, front=False)
    draw_bodies(ax, poses, scenario.lengths_um, scenario.widths_um, cols, fill_alpha=0.5)
    pts = np.vstack([poses[:, :2], goals[:, :2]])
    lo, hi = np.nanmin(pts, axis=0) - 250, np.nanmax(pts, axis=0) + 250
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_title(title, fontsize=10)
    return fig


def heading_arrow(theta: float, length: float = 1.0) -> tuple[float, float]:
    """Heading vector (sin, cos) scaled: for quiver-style arrows."""
    return length * math.sin(theta), length * math.cos(theta)


_EVENT_MARKS = {
    "dock": ("o", "tab:green"),
    "self_align": ("D", "tab:green"),
    "stuck": ("X", "tab:red"),
    "slide": ("v", "tab:orange"),
    "blocked": ("s", "tab:red"),
    "arena": ("P", "tab:purple"),
    "contact": ("x", "0.3"),
}


def plot_run(scenario, times, poses, goals, events=(), *, title: str = ""):
    """A simulated run: trajectories coloured by robot, start bodies (faint), final bodies (filled),
    target slots (grey outlines) and contact events marked where the robot was when they happened.

    ``times`` (M,) and ``poses`` (M, n, 3) are a sampled trajectory (e.g.
    :meth:`stressbots.sim.SimulatedPlant.trace`); ``goals`` (n, 3) the slots; ``events`` the plant's
    :class:`stressbots.sim.SimEvent` log.
    """
    plt = _plt()
    n = scenario.n
    cols = robot_colours(n)
    L, W = scenario.lengths_um, scenario.widths_um
    poses = np.asarray(poses, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    goals = np.asarray(goals, dtype=np.float64)
    fig, ax = plt.subplots(figsize=(8, 8))
    for i in range(n):
        ax.plot(poses[:, i, 0], poses[:, i, 1], color=cols[i], lw=1.1, alpha=0.9, zorder=2)
    draw_bodies(ax, poses[0], L, W, cols, fill_alpha=0.1, edge_alpha=0.5)
    if not np.isnan(goals).any():
        draw_bodies(ax, goals, L, W, [(0.45, 0.45, 0.45)] * n, fill_alpha=0.0, lw=0.8, front=False, zorder=2.5)
    draw_bodies(ax, poses[-1], L, W, cols, fill_alpha=0.55)
    index = {name: k for k, name in enumerate(scenario.names)}
    seen = set()
    for ev in events:
        if ev.kind not in _EVENT_MARKS or ev.robot not in index:
            continue
        i = index[ev.robot]
        k = min(int(np.searchsorted(times, ev.time_s, side="right")) - 1, len(times) - 1)
        marker, colour = _EVENT_MARKS[ev.kind]
        ax.scatter(*poses[max(k, 0), i, :2], marker=marker, s=50, color=colour, zorder=6, label=ev.kind if ev.kind not in seen else None)
        seen.add(ev.kind)
    for i, name in enumerate(scenario.names):
        ax.annotate(name, poses[0, i, :2], xytext=(6, 6), textcoords="offset points", fontsize=8, color=cols[i], zorder=5)
    pts = np.vstack([poses[:, :, :2].reshape(-1, 2)] + ([goals[:, :2]] if not np.isnan(goals).any() else []))
    _frame(ax, scenario, pts)
    if seen:
        ax.legend(loc="upper right", fontsize=8, title="events", title_fontsize=8)
    ax.set_title(title or f"{scenario.name}: simulated run, {times[-1]:.1f} s", fontsize=10)
    return fig
