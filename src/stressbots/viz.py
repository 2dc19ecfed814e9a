"""Pictures: plans, structures and runs drawn to scale in the arena frame (um, y up).

Pure drawing: functions take computed results and return matplotlib figures; saving goes through
:func:`stressbots.outputs.save_figure`. matplotlib is imported with the non-interactive Agg backend so
that pictures work on machines without a screen.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

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


def draw_bodies(ax, poses, lengths, widths, colours, *, fill_alpha=0.0, edge_alpha=1.0, lw=1.0, front=True, zorder=3, ls="-"):
    """Draw body rectangles (and a mark on each front edge) for ``poses`` (N, 3); ``ls`` the outline's line style."""
    from matplotlib.patches import Polygon as MplPolygon

    corners = body_corners(poses, lengths, widths)
    for k, c in enumerate(corners):
        col = colours[k]
        ax.add_patch(
            MplPolygon(c, closed=True, facecolor=(*col[:3], fill_alpha), edgecolor=(*col[:3], edge_alpha), lw=lw, ls=ls,
                       zorder=zorder)
        )
        if front:
            ax.plot(c[:2, 0], c[:2, 1], color=col, lw=lw * 2.5, alpha=edge_alpha, zorder=zorder + 0.1, solid_capstyle="butt")


def _frame(ax, scenario, pts: np.ndarray, pad: float = 150.0):
    if scenario.arena_um is not None:
        w, h = scenario.arena_um
        ax.add_patch(_plt().Rectangle((0, 0), w, h, fill=False, lw=1.2, ec="0.3", zorder=1))
        ax.set_xlim(-pad, w + pad)
        ax.set_ylim(-pad, h + pad)
        _plane_axes(ax)
    else:
        _zoom(ax, pts, pad)


def _zoom(ax, pts: np.ndarray, pad: float) -> None:
    """Axes around the points ``pts`` (um) with ``pad`` (um) on every side, in the arena plane."""
    lo, hi = pts.min(axis=0) - pad, pts.max(axis=0) + pad
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    _plane_axes(ax)


def _plane_axes(ax) -> None:
    """Equal scales, um labels and a light grid: every picture of the arena plane."""
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
        ax.annotate(f"{name} (D{rank[name]})", starts[i, :2], xytext=(6, 6), textcoords="offset points", fontsize=8,
                    color=cols[i], zorder=5)
    pts = np.vstack([starts[:, :2], goals[:, :2], centres + rstar[:, None], centres - rstar[:, None]])
    _frame(ax, scenario, pts)
    s = result.summary
    ax.set_title(
        title
        or (f"{scenario.name}: {s['structure']} by {n} robots - {s['duration_s']:.1f} s, {s['steps']} steps, "
            f"efficiency {s['efficiency']:.2f}"),
        fontsize=10,
    )
    return fig


def heading_arrow(theta: float, length: float = 1.0) -> tuple[float, float]:
    """Heading vector (sin, cos) scaled: for quiver-style arrows."""
    return length * math.sin(theta), length * math.cos(theta)


_EVENT_MARKS = {
    "dock": ("o", "tab:green"),
    "self_align": ("D", "tab:green"),
    "stuck": ("X", "tab:red"),
    "graze": ("v", "tab:orange"),
    "blocked": ("s", "tab:red"),
    "arena": ("P", "tab:purple"),
    "contact": ("x", "0.3"),
}


def plot_run(scenario, times, poses, goals, events=(), *, title: str = "", retargeted=None):
    """A simulated run: trajectories coloured by robot, start bodies (faint), final bodies (filled),
    planned slots (grey outlines), re-targeted slots (dotted, in the robot's colour) and contact events
    marked where the robot was when they happened.

    ``times`` (M,) and ``poses`` (M, n, 3) are a sampled trajectory (e.g.
    :meth:`stressbots.sim.SimulatedPlant.trace`); ``goals`` (n, 3) the planned slots; ``retargeted``
    (n, 3) the slots the controller aimed at once G_1 had formed (drawn where they differ from the
    planned ones); ``events`` the plant's :class:`stressbots.sim.SimEvent` log.
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
    slots = []
    if not np.isnan(goals).any():
        draw_bodies(ax, goals, L, W, [(0.45, 0.45, 0.45)] * n, fill_alpha=0.0, lw=0.8, front=False, zorder=2.5)
        slots.append(("planned slot", {"ls": "-", "color": "0.45"}))
    if retargeted is not None:
        rt = np.asarray(retargeted, dtype=np.float64)
        if np.isfinite(rt).all() and (np.isnan(goals).any() or not np.allclose(rt, goals, atol=0.05)):
            draw_bodies(ax, rt, L, W, cols, fill_alpha=0.0, lw=0.9, front=False, zorder=2.6, ls=":")
            slots.append(("re-targeted slot (after G_1)", {"ls": ":", "color": "0.2"}))
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
    for label, style in slots:
        ax.plot([], [], lw=0.9, label=label, **style)
    if seen or slots:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or f"{scenario.name}: simulated run, {times[-1]:.1f} s", fontsize=10)
    return fig


# ----------------------------------------------------------------------------------------------------
# Error bounds (stressbots bounds) and Monte Carlo studies (stressbots montecarlo)


def _draw_cone(ax, cone, speed_um_s: float, radius_um: float, model, colour, *, fixed: str = "") -> None:
    """One reachable cone in the robot's frame: the cone, arcs of intermediate duty cycles, and the
    forward projections of its two extreme sequences (paths under the corner error cases)."""
    from matplotlib.patches import Polygon as MplPolygon

    from .bounds import arc_points, s2f_sequence, sequence_poses

    ax.add_patch(MplPolygon(cone.polygon, closed=True, fc=(*colour[:3], 0.18), ec=colour, lw=1.0, zorder=2))
    k_in = 1.0 / cone.radius_min_um
    k_out = 0.0 if math.isinf(cone.radius_max_um) else 1.0 / cone.radius_max_um
    for kappa in np.linspace(k_in, k_out, 5)[1:-1]:
        pts = arc_points(1.0 / kappa if kappa > 0 else math.inf, cone.length_um)
        ax.plot(pts[:, 0], pts[:, 1], color=colour, lw=0.6, ls=":", zorder=3)
    errs = model.samples(3)
    for r_ext in (cone.radius_min_um, cone.radius_max_um):
        rho = 0.0 if math.isinf(r_ext) else min(radius_um / r_ext, 1.0)
        dur = cone.length_um / speed_um_s
        seq = s2f_sequence(rho, dur, dur / 40.0)
        t = np.linspace(0.0, dur, 60)
        p = sequence_poses((0.0, 0.0, 0.0), seq.turning, seq.durations_s, speed_um_s, radius_um, errs, t)
        for g in range(p.shape[0]):
            ax.plot(p[g, :, 0], p[g, :, 1], color="0.35", lw=0.4, alpha=0.5, zorder=1)
    ax.annotate("", xy=(0, 0.25 * cone.length_um), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="k", lw=1.2))
    ax.set_aspect("equal")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_xlabel("across (um)")
    ax.set_ylabel("along (um)")
    rmax = "inf" if math.isinf(cone.radius_max_um) else f"{cone.radius_max_um:.0f}"
    ax.set_title(
        f"{cone.label} ({cone.robot}): r' in [{cone.radius_min_um:.0f}, {rmax}] um\n{cone.duties[0]} .. {cone.duties[1]}"
        + (f"; {fixed}" if fixed else ""),
        fontsize=8,
    )


def _delta_panels(ax_xy, ax_th, report, colour: dict) -> None:
    """``delta_xy(t)`` (um) and ``delta_theta(t)`` (deg) of pure turning (solid) and pure straight motion
    (dashed) per robot, ``t_2pi`` dotted (where ``C_alpha,i`` is read)."""
    for rb in report.robots:
        c = colour[rb.name]
        for curve, ls in ((rb.delta_turning, "-"), (rb.delta_straight, "--")):
            ax_xy.plot(curve.times_s, curve.xy_um, color=c, ls=ls, lw=1.2, label=f"{rb.label} {curve.sequence}")
            ax_th.plot(curve.times_s, np.degrees(curve.theta_rad), color=c, ls=ls, lw=1.2)
        for ax in (ax_xy, ax_th):
            if math.isfinite(rb.t_2pi_s):
                ax.axvline(rb.t_2pi_s, color=c, lw=0.6, ls=":")
    ax_xy.set_xlabel("t (s)")
    ax_xy.set_ylabel("delta_xy (um)")
    ax_xy.set_title(f"delta_xy(t), {report.model.k:g}-sigma box (dotted: t_2pi)", fontsize=9)
    ax_xy.legend(fontsize=6, ncol=2)
    ax_th.set_xlabel("t (s)")
    ax_th.set_ylabel("delta_theta (deg)")
    ax_th.set_title("delta_theta(t): turning (solid), straight (dashed)", fontsize=9)
    for ax in (ax_xy, ax_th):
        ax.grid(True, lw=0.3, alpha=0.5)


def _draw_region(ax, reg, c) -> None:
    """One robot's sampled A_i* in colour ``c``: the preimage of G_i* outside C_O faint with its outline,
    A_i* filled, an example intermediate pose a_i as a 120 um arrow along its heading."""
    X, Y = np.meshgrid(reg.xs_um, reg.ys_um, indexing="ij")
    pre = reg.preimage.any(axis=2)
    if pre.any():
        ax.contourf(X, Y, pre.astype(float), levels=[0.5, 1.5], colors=[(*c[:3], 0.08)], zorder=1)
        ax.contour(X, Y, pre.astype(float), levels=[0.5], colors=[(*c[:3], 0.5)], linewidths=0.5, zorder=1)
    a = reg.mask.any(axis=2)
    if a.any():
        ax.contourf(X, Y, a.astype(float), levels=[0.5, 1.5], colors=[(*c[:3], 0.35)], zorder=2)
        ex = reg.example()
        ax.annotate("", xy=(ex[0] + 120 * math.sin(ex[2]), ex[1] + 120 * math.cos(ex[2])), xytext=(ex[0], ex[1]),
                    arrowprops=dict(arrowstyle="->", color=c, lw=1.4), zorder=4)


def _regions_panel(ax_map, scenario, report, colour: dict) -> None:
    """The regions A_i* in the arena over the slots (filled bodies) with C_O dashed, zoomed to the sampled
    grids, and every robot's verdict in the title."""
    st = report.structure
    pts = []
    for rb in report.robots:
        c = colour[rb.name]
        co = st.proximity_region(rb.name)
        for ring in getattr(co, "geoms", [co]):
            x, y = ring.exterior.xy
            ax_map.plot(x, y, color=c, lw=0.7, ls="--", zorder=2)
        reg = rb.region
        if reg is not None:
            _draw_region(ax_map, reg, c)
            pts.append([[reg.xs_um[0], reg.ys_um[0]], [reg.xs_um[-1], reg.ys_um[-1]]])
    goals = st.goal_poses(scenario.names)
    draw_bodies(ax_map, goals, scenario.lengths_um, scenario.widths_um, [colour[n] for n in scenario.names], fill_alpha=0.6, lw=0.8)
    verdicts = ", ".join(f"{rb.label}: {'yes' if rb.guaranteed else 'no'}" for rb in report.robots)
    if pts:
        p = np.array(pts).reshape(-1, 2)
        ax_map.set_xlim(p[:, 0].min(), p[:, 0].max())
        ax_map.set_ylim(p[:, 1].min(), p[:, 1].max())
    ax_map.set_aspect("equal")
    ax_map.grid(True, lw=0.3, alpha=0.5)
    ax_map.set_xlabel("x (um)")
    ax_map.set_ylabel("y (um)")
    ax_map.set_title(f"A_i* (solid), preimage of G_i* outside C_O (faint), C_O (dashed)\nguaranteed: {verdicts}", fontsize=8)


def _cone_panels(fig, gs, scenario, report, colour: dict) -> None:
    """The bottom row: the reachable cones S_2f, S_3f of D_n-1 and S_3f of D_n (first cone of each label;
    an empty panel when the report has none), the partner's fixed radius named in the title."""
    by_label: dict[str, Any] = {}
    for cone in report.cones:
        by_label.setdefault(cone.label, cone)
    panels = [by_label.get("S_2f"), by_label.get("S_3f D_n-1"), by_label.get("S_3f D_n")]
    fixed = {"S_3f D_n-1": "D_n keeps r'_n = 3 r", "S_3f D_n": "D_n-1 keeps r'_n-1 = 1.5 r"}
    for col, cone in enumerate(panels):
        ax = fig.add_subplot(gs[1, col])
        if cone is None:
            ax.axis("off")
            continue
        rob = scenario.robot(cone.robot)
        _draw_cone(ax, cone, rob.speed_um_s, rob.turn_radius_um, report.model, colour[cone.robot], fixed=fixed.get(cone.label, ""))


def plot_bounds(scenario, report):
    """The error bounds of a scenario (``stressbots bounds``), six panels.

    Top: ``delta_xy(t)`` and ``delta_theta(t)`` of pure turning (solid) and pure straight motion
    (dashed) per robot, with ``t_2pi`` marked (where ``C_alpha,i`` is read); the regions A_i* in the
    arena (filled; the nominal preimage of G_i* outside C_O faint, C_O dashed, an example a_i as an
    arrow). Bottom: the reachable cones of fine motion (seed Fig. 4) with the forward projections of
    their extreme sequences (grey paths, corner error cases): S_2f of a docking robot, S_3f of D_{n-1}
    and of D_n.

    ``report`` is a :class:`stressbots.bounds.BoundsReport`.
    """
    plt = _plt()
    cols = robot_colours(scenario.n)
    colour = {name: cols[i] for i, name in enumerate(scenario.names)}
    fig = plt.figure(figsize=(16, 10))
    gs = fig.add_gridspec(2, 3, hspace=0.32, wspace=0.28)
    ax_xy, ax_th, ax_map = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[0, 2])
    _delta_panels(ax_xy, ax_th, report, colour)
    _regions_panel(ax_map, scenario, report, colour)
    _cone_panels(fig, gs, scenario, report, colour)
    fig.suptitle(
        f"{report.scenario}: error bounds ({report.model.k:g} sigma: speed +-{100 * report.model.speed_rel:.1f} %, radius "
        f"+-{100 * report.model.radius_rel:.1f} %, drift +-{math.degrees(report.model.drift_rad_per_um) * 1000:.2g} deg/mm)",
        fontsize=11,
    )
    return fig


def plot_montecarlo(summary: dict, outcomes, *, title: str = ""):
    """Histograms of a Monte Carlo study: RMS shape error (successes and failures stacked, tolerance
    line if known; log-scaled when failures lie orders of magnitude off) and simulated duration.
    ``outcomes`` are :class:`stressbots.montecarlo.TrialOutcome`; trials that raised have no values."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    ok = np.array([o.success for o in outcomes], dtype=bool)
    shape = np.array([o.shape_error_rms_um for o in outcomes], dtype=float)
    dur = np.array([o.duration_s for o in outcomes], dtype=float)
    for ax, data, label in ((a1, shape, "RMS shape error (um)"), (a2, dur, "duration (s, simulated)")):
        good = np.isfinite(data)
        if good.any():
            lo, hi = float(np.min(data[good])), float(np.max(data[good]))
            if lo > 0 and hi / lo > 100:  # failures far off (mm) would squash the successes: log bins
                bins = np.geomspace(lo, hi, 31)
                ax.set_xscale("log")
            else:
                bins = np.linspace(lo, hi if hi > lo else lo + 1.0, 31)
            ax.hist([data[good & ok], data[good & ~ok]], bins=bins, stacked=True, color=["tab:green", "tab:red"],
                    label=[f"success ({int((good & ok).sum())})", f"failure ({int((good & ~ok).sum())})"])
        ax.set_xlabel(label)
        ax.set_ylabel("trials")
        ax.grid(True, lw=0.3, alpha=0.5)
        ax.legend(fontsize=8)
    tol = summary.get("shape_tolerance_um")
    if tol is not None:
        a1.axvline(tol, color="k", ls="--", lw=0.8)
    ci = summary.get("success_rate_ci95", [math.nan, math.nan])
    fig.suptitle(
        title
        or f"{summary.get('scenario', '')}: {summary['successes']}/{summary['trials']} successes, rate {summary['success_rate']:.3f} "
        f"(95 % CI {ci[0]:.3f}-{ci[1]:.3f})",
        fontsize=10,
    )
    return fig


def plot_sweep(sweep: Sequence[dict], *, title: str = ""):
    """Success rate against noise scale with 95 % Wilson intervals (``stressbots montecarlo --sweep``).

    ``sweep`` rows hold ``noise_scale``, ``success_rate`` and ``success_rate_ci95``.
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    x = np.array([row["noise_scale"] for row in sweep], dtype=float)
    y = np.array([row["success_rate"] for row in sweep], dtype=float)
    lo = np.array([row["success_rate_ci95"][0] for row in sweep], dtype=float)
    hi = np.array([row["success_rate_ci95"][1] for row in sweep], dtype=float)
    order = np.argsort(x)
    x, y, lo, hi = x[order], y[order], lo[order], hi[order]
    ax.fill_between(x, lo, hi, color="tab:blue", alpha=0.2, label="95 % CI (Wilson)")
    ax.errorbar(x, y, yerr=[y - lo, hi - y], fmt="o-", color="tab:blue", capsize=3, label="success rate")
    ax.axhline(0.9, color="0.4", ls=":", lw=0.8)
    ax.axvline(1.0, color="0.4", ls="--", lw=0.8)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("noise scale (x the scenario's [noise])")
    ax.set_ylabel("success rate")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8, loc="lower left")
    trials = sweep[0]["trials"] if sweep else 0
    ax.set_title(title or f"success rate vs noise ({trials} trials per point)", fontsize=10)
    return fig


# ----------------------------------------------------------------------------------------------------
# The main job's report (stressbots run / demo): a plan's waveform and the final structure


def _draw_segments(ax, segs: Sequence, e) -> float:
    """Each Hold as a spike from the middle of the drive band to its level (the level that sets the arms),
    each Drive as a band between its two levels (V); returns the waveform's duration (s)."""
    from .waveform import Hold

    t = 0.0
    for seg in segs:
        t1 = t + seg.duration_s
        if isinstance(seg, Hold):
            ax.plot([t, t], [0.5 * (e.drive_low_V + e.drive_high_V), seg.volts], color="tab:blue", lw=0.9)
            ax.plot([t], [seg.volts], "o", color="tab:blue", ms=2.5)
        else:
            ax.fill_between([t, t1], seg.low_V, seg.high_V, color="tab:orange", alpha=0.35, lw=0)
        t = t1
    return t


def _label_drives(ax, segs: Sequence, analysis, total_s: float, label_limit: int) -> None:
    """The primitive of each Drive (decoded from the waveform, the single source of truth for arm states)
    above the drive band, when there are at most ``label_limit`` Drives; Drives shorter than 1.2 % of
    the waveform stay unlabelled, since their labels would overlap."""
    from .waveform import decode

    drives = decode(segs, analysis.snap_down_V, analysis.release_V)
    if len(drives) <= label_limit:
        for d in drives:
            prim = analysis.primitive_for_state(d.states)
            if prim is not None and d.duration_s > 0.012 * total_s:
                ax.text(d.t_start_s + 0.5 * d.duration_s, analysis.electrodes.drive_high_V + 2, prim.name, ha="center",
                        va="bottom", fontsize=6.5)


def _threshold_lines(ax, analysis, total_s: float) -> None:
    """Every robot's snap-down (red) and release (green) threshold (V), dotted and named at the right edge."""
    for i, nm in enumerate(analysis.names):
        for v, col, lab in ((analysis.snap_down_V[i], "tab:red", "V_d"), (analysis.release_V[i], "tab:green", "V_u")):
            ax.axhline(v, color=col, ls=":", lw=0.7)
            ax.text(total_s * 1.005, v, f"{lab} {nm}", va="center", fontsize=6.5, color=col)


def _signal_start(az, segs: Sequence, e, zoom_periods: int, total_s: float) -> None:
    """The real signal from 0 to ``zoom_periods`` periods into the first Drive (the whole waveform when it
    has none), sampled at 40 samples per drive period or more (at least 200 samples), time in ms."""
    from .waveform import Drive, excerpt, sample

    t0 = 0.0
    end = None
    for seg in segs:
        if isinstance(seg, Drive):
            end = t0 + zoom_periods / e.drive_frequency_hz
            break
        t0 += seg.duration_s
    if end is None:
        end = total_s
    rate = max(40.0 * e.drive_frequency_hz, 200.0 / max(end, 1e-9))
    ts, vs = sample(excerpt(segs, end), rate_hz=rate, drive_frequency_hz=e.drive_frequency_hz, max_samples=200_000)
    az.step(ts * 1e3, vs, where="post", color="tab:blue", lw=1.0)
    az.axhspan(e.drive_low_V, e.drive_high_V, color="tab:orange", alpha=0.15, lw=0)
    az.set_xlim(0, end * 1e3)
    az.set_ylim(0, e.max_V * 1.03)
    az.set_xlabel("time (ms)")
    az.set_ylabel("level (V)")
    az.set_title(
        f"the first {end * 1e3:.2f} ms, sampled: Hold(s) of {e.hold_s * 1e3:g} ms set the arms, then the drive "
        f"square wave at {e.drive_frequency_hz:g} Hz between {e.drive_low_V:g} and {e.drive_high_V:g} V",
        fontsize=8.5,
    )


def plot_plan_waveform(waveform, analysis, *, title: str = "", zoom_periods: int = 6, label_limit: int = 40):
    """A plan's voltage waveform, two panels.

    Top: the whole waveform, each Hold as a spike to its level (the level that sets the arms), each
    Drive as a band between its two levels, with the robots' snap-down (red) and release (green)
    thresholds dotted and, when there are at most ``label_limit`` drives, the primitive of each drive.
    Bottom: the real signal at the start, sampled: the first Holds and ``zoom_periods`` periods of the
    first Drive's square wave.
    """
    plt = _plt()
    e = analysis.electrodes
    fig, (ax, az) = plt.subplots(2, 1, figsize=(10, 6.2), gridspec_kw={"height_ratios": [3, 2], "hspace": 0.42})
    segs = list(waveform)
    total = max(_draw_segments(ax, segs, e), 1e-9)
    _label_drives(ax, segs, analysis, total, label_limit)
    _threshold_lines(ax, analysis, total)
    ax.set_xlim(0, total * 1.07)
    ax.set_ylim(0, e.max_V * 1.03)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("level (V)")
    ax.set_title(title or f"Plan waveform: {len(segs)} segments, {total:.1f} s (Holds blue, Drives orange)", fontsize=10)
    _signal_start(az, segs, e, zoom_periods, total)
    for a in (ax, az):
        a.grid(True, lw=0.3, alpha=0.5)
    return fig


def aligned_target(final, goals, lengths_um, widths_um) -> np.ndarray:
    """The target poses moved by the proper rigid motion that best maps their bodies onto the final
    bodies (the alignment behind :func:`stressbots.assessment.shape_error`, inverted)."""
    from .assessment import kabsch_2d

    final = np.asarray(final, dtype=np.float64).reshape(-1, 3)
    goals = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
    g = body_corners(goals, lengths_um, widths_um).reshape(-1, 2)
    f = body_corners(final, lengths_um, widths_um).reshape(-1, 2)
    rot, t = kabsch_2d(g, f)
    phi = math.atan2(rot[1, 0], rot[0, 0])  # counter-clockwise
    out = goals.copy()
    out[:, :2] = goals[:, :2] @ rot.T + t
    out[:, 2] = np.mod(goals[:, 2] - phi, 2 * math.pi)  # headings are clockwise
    return out


def plot_final_structure(scenario, final, goals, docked=None, *, title: str = "", pad: float = 250.0):
    """The final bodies (filled, coloured by robot) against the target structure best aligned onto them
    (grey outlines, the shape that success is judged on) and the target where it was placed (dotted)."""
    from matplotlib.patches import Polygon as MplPolygon

    plt = _plt()
    n = scenario.n
    cols = robot_colours(n)
    L, W = scenario.lengths_um, scenario.widths_um
    final = np.asarray(final, dtype=np.float64)
    goals = np.asarray(goals, dtype=np.float64)
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    for c in body_corners(goals, L, W):
        ax.add_patch(MplPolygon(c, closed=True, fill=False, ec="0.55", lw=0.8, ls=":", zorder=2))
    aligned = aligned_target(final, goals, L, W)
    draw_bodies(ax, aligned, L, W, [(0.25, 0.25, 0.25)] * n, fill_alpha=0.0, lw=1.2, front=False, zorder=4)
    draw_bodies(ax, final, L, W, cols, fill_alpha=0.5)
    for i, name in enumerate(scenario.names):
        label = name if docked is None else f"{name} ({'docked' if docked[i] else 'not docked'})"
        ax.annotate(label, final[i, :2], xytext=(5, 5), textcoords="offset points", fontsize=8, color=cols[i], zorder=6)
    ax.plot([], [], color="0.25", lw=1.2, label="target, best rigid alignment")
    ax.plot([], [], color="0.55", lw=0.8, ls=":", label="target as placed")
    pts = np.vstack([final[:, :2], goals[:, :2], aligned[:, :2]])
    lo, hi = np.nanmin(pts, axis=0) - pad, np.nanmax(pts, axis=0) + pad
    side = max(hi - lo)
    mid = 0.5 * (lo + hi)
    ax.set_xlim(mid[0] - side / 2, mid[0] + side / 2)
    ax.set_ylim(mid[1] - side / 2, mid[1] + side / 2)
    ax.set_aspect("equal")
    ax.set_xlabel("x (um)")
    ax.set_ylabel("y (um)")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(loc="upper right", fontsize=7.5)
    ax.set_title(title, fontsize=9.5)
    return fig


# ----------------------------------------------------------------------------------------------------
# the controller's regions and their Monte Carlo coverage (stressbots.coverage)


def _coverage_structure(ax, scenario, cov, capture) -> None:
    """Left panel: the slots, each docking robot's capture corridor (heading = the slot's) and the true
    positions at the moments (filled: inside the capture region, crosses: outside)."""
    from matplotlib.patches import Polygon as MplPolygon

    names = list(scenario.names)
    cols = robot_colours(scenario.n)
    goals = np.asarray(cov.goals)
    draw_bodies(ax, goals, scenario.lengths_um, scenario.widths_um, [(0.45, 0.45, 0.45, 1.0)] * scenario.n, lw=0.8, ls="--", zorder=2)
    for nm in cov.order[:-2]:
        i = names.index(nm)
        g = goals[i]
        h, rt = np.array([math.sin(g[2]), math.cos(g[2])]), np.array([math.cos(g[2]), -math.sin(g[2])])
        tol, back = capture[nm].tol_um, 2.0 * float(scenario.lengths_um[i])
        band = [g[:2] + a * h + b * rt for a, b in ((0, -tol), (0, tol), (-back, tol), (-back, -tol))]
        ax.add_patch(MplPolygon(np.array(band), closed=True, fc=(*cols[i][:3], 0.18), ec=cols[i], lw=0.6, zorder=2))
    for s in cov.samples:
        if s.region not in ("capture", "rendezvous-capture"):
            continue
        i = names.index(s.robot.split("+")[0])
        ax.plot(*s.xy, "o" if s.inside else "x", ms=3.5 if s.inside else 5, color=cols[i], alpha=0.8, zorder=4,
                mfc=cols[i] if s.scale <= 1.0 else "none")
    pts = np.concatenate([goals[:, :2], np.array([s.xy for s in cov.samples]).reshape(-1, 2)])
    _zoom(ax, pts, 200.0)
    ax.set_title("true positions at the moments over the slots\n(bands: capture corridors; D_n at departure)", fontsize=8)


def _coverage_plane(ax, cov, regions: tuple[str, str], boxes, xlabel: str, ylabel: str, title: str) -> None:
    """A region's own coordinates: its outline(s) and the samples (filled: 1x noise, hollow: other scales)."""
    for xy, style in boxes:
        ax.plot(*np.asarray(xy).T, style, lw=1.0)
    for s in cov.samples:
        if s.region != regions[1]:
            continue
        c = "tab:green" if s.inside else "tab:red"
        ax.plot(*s.coords, "o", ms=3.5, color=c, mfc=c if s.scale <= 1.0 else "none", alpha=0.8)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_title(title, fontsize=8)


def plot_controller_coverage(scenario, cov, *, title: str = ""):
    """The controller's regions with the Monte Carlo moments (:func:`stressbots.coverage.controller_coverage`).

    Left: the slots, each docking robot's capture corridor and the true positions at the moments. Middle:
    the final straight approach in ``(e, psi)``: the capture region G_i* (solid) and the controller's aim
    (dashed). Right: the predicted G_1 meeting in ``(w_y, alpha)``: self-alignment's limits (solid) and the
    controller's departure test (dashed). Green inside the capture region, red outside; filled at the
    scenario's noise, hollow at other scales.
    """
    from .control import ControllerOptions
    from .coverage import ControllerRegions

    plt = _plt()
    reg = ControllerRegions.of(scenario, ControllerOptions())
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.2))
    _coverage_structure(axes[0], scenario, cov, reg.capture)
    psi = np.radians(np.linspace(-45.0, 45.0, 91))
    cap = reg.capture[cov.order[0]]
    lo, hi = (np.asarray(x) for x in cap.lateral_limits(psi))
    outline = np.concatenate([np.stack([lo, np.degrees(psi)], 1), np.stack([hi[::-1], np.degrees(psi[::-1])], 1), [[lo[0], -45.0]]])
    a, h = reg.aim.lateral_um, math.degrees(reg.aim.heading_rad)
    aim = [[-a, -h], [a, -h], [a, h], [-a, h], [-a, -h]]
    _coverage_plane(axes[1], cov, ("straight-in", "capture"), [(outline, "k-"), (aim, "k--")], "e: lateral offset at the slot (um)",
                    "psi: heading to the slot (deg)", "final straight approach: capture G_i* (solid), aim (dashed)")
    axes[1].set_xlim(-80, 80)
    axes[1].set_ylim(-20, 20)

    def box(w: float, al: float):
        return [[0, -al], [w, -al], [w, al], [0, al], [0, -al]]

    mc, ma = reg.meet_capture, reg.meet_aim
    _coverage_plane(axes[2], cov, ("rendezvous-aim", "rendezvous-capture"),
                    [(box(mc.max_offset_um, math.degrees(mc.max_incidence_rad)), "k-"),
                     (box(ma.fraction * ma.max_offset_um, math.degrees(ma.fraction * ma.max_incidence_rad)), "k--")],
                    "|w_y| at the predicted meeting (um)", "alpha (deg)", "G_1 rendezvous: self-alignment (solid), departure test (dashed)")
    axes[2].set_xlim(0, 120)
    axes[2].set_ylim(-75, 75)
    fig.suptitle(title or f"{scenario.name}: the controller's regions, {cov.trials} trials per noise scale "
                          f"({', '.join(f'{s:g}x' for s in cov.scales)})", fontsize=10)
    fig.tight_layout()
    return fig
