"""Replay verification of a plan, on a code path independent of the planner.

The planner builds plans from paths; this module only integrates SPEC section 3's closed-form motion
step by step, finely sampled, and checks what a lab would care about:

- every step names a primitive whose turning set is an accessible control state of the design;
- no two bodies ever interpenetrate (touching is allowed) and every body stays inside the arena;
- a robot moving straight that reaches its slot in contact with the structure (or, for G_1, meeting its
  partner at the same moment) docks and stops there; a docked robot only ever receives straight-motion
  primitives afterwards (it keeps pushing, SPEC 5);
- at the end every robot is docked at its slot.

It deliberately re-implements the motion formulas instead of calling :mod:`stressbots.kinematics`, so
that a bug there cannot hide a bad plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .collision import outside_arena, penetration_depth
from .plans import Plan

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class ReplayReport:
    """Outcome of a replay. ``problems`` is empty iff ``ok``; ``trace`` holds sampled poses for pictures."""

    ok: bool
    problems: tuple[str, ...]
    final: np.ndarray  # (n, 3) scenario order, rad
    docked: np.ndarray  # (n,) bool
    dock_times_s: np.ndarray  # (n,) NaN where never docked
    trace_t: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    trace_poses: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 0, 3)))


def _motion(p0: np.ndarray, turning: np.ndarray, speed: np.ndarray, radius: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Poses ``(K, n, 3)`` at times ``t`` (K,) from ``p0`` (n, 3): SPEC 3's straight line / clockwise arc."""
    x, y, th = p0[:, 0], p0[:, 1], p0[:, 2]
    s = t[:, None] * speed[None, :]  # arc length (K, n)
    dphi = np.where(turning[None, :], s / radius[None, :], 0.0)
    th1 = th[None, :] + dphi
    arc_x = x + radius * (np.cos(th)[None, :] - np.cos(th1))
    arc_y = y + radius * (np.sin(th1) - np.sin(th)[None, :])
    lin_x = x + s * np.sin(th)[None, :]
    lin_y = y + s * np.cos(th)[None, :]
    out = np.empty(t.shape + p0.shape)
    out[..., 0] = np.where(turning[None, :], arc_x, lin_x)
    out[..., 1] = np.where(turning[None, :], arc_y, lin_y)
    out[..., 2] = np.mod(th1, TWO_PI)
    return out


def replay(
    plan: Plan,
    scenario,
    goals: np.ndarray | None = None,
    *,
    accessible_turning: set[frozenset[str]] | None = None,
    max_step_um: float = 2.0,
    tol_um: float = 0.5,
    heading_tol_rad: float = 1e-4,
    trace_every_um: float | None = 10.0,
) -> ReplayReport:
    """Replay ``plan`` on ``scenario``'s robots from their start poses and check it (see module doc).

    Parameters
    ----------
    goals:
        Slots ``(n, 3)`` in scenario order (rad); default the plan's ``goals``.
    accessible_turning:
        The turning sets of the design's accessible control states; when given, every plan primitive
        must be one of them.
    max_step_um:
        Largest distance any robot travels between two checked samples.
    tol_um:
        Interpenetration (and docking position) tolerance; touching bodies are fine.
    """
    names = list(scenario.names)
    n = len(names)
    if sorted(plan.robots) != sorted(names):
        return ReplayReport(False, ("plan robots differ from the scenario's",), np.full((n, 3), np.nan), np.zeros(n, bool),
                            np.full(n, np.nan))
    order = [plan.robots.index(nm) for nm in names]  # plan column of each scenario robot
    turning_all = plan.turning_matrix()[:, order]
    problems: list[str] = _inaccessible_primitives(plan, accessible_turning)
    if goals is None:
        goals = np.array([plan.goals[nm] if nm in plan.goals else (np.nan,) * 3 for nm in names], dtype=np.float64)
    goals = np.asarray(goals, dtype=np.float64)

    speed = scenario.speeds_um_s
    pose = scenario.starts.copy()
    pose[:, 2] = np.mod(pose[:, 2], TWO_PI)
    docked = np.zeros(n, dtype=bool)
    dock_time = np.full(n, np.nan)
    t_now = 0.0
    trace_t: list[float] = [0.0]
    trace_p: list[np.ndarray] = [pose.copy()]
    vmax = float(speed.max())
    note = _ProblemLog(problems)
    for k, step in enumerate(plan.steps):
        turning = turning_all[k]
        for i in np.flatnonzero(docked & turning).tolist():
            note(("turn-docked", i), f"step {k} ({step.primitive}): docked robot {names[i]} receives a turning primitive")
        if step.duration_s <= 0:
            continue
        traj, t, t_dock, accepted = _step_motion(pose, goals, docked, turning, scenario, step.duration_s,
                                                 max(2, int(math.ceil(vmax * step.duration_s / max_step_um)) + 1),
                                                 tol_um, heading_tol_rad)
        _note_contacts(note, traj, t + t_now, scenario, tol_um, f"step {k}", step.primitive)
        pose = traj[-1].copy()
        docked[accepted] = True
        dock_time[accepted] = t_now + t_dock[accepted]
        if trace_every_um is not None:
            _extend_trace(trace_t, trace_p, traj, t, t_now, trace_every_um, vmax)
        t_now += step.duration_s

    problems.extend(_undocked(pose, goals, docked, names))
    return ReplayReport(
        ok=not problems,
        problems=tuple(problems),
        final=pose,
        docked=docked,
        dock_times_s=dock_time,
        trace_t=np.asarray(trace_t),
        trace_poses=np.asarray(trace_p),
    )


class _ProblemLog:
    """Appends a problem to ``problems`` once per key (a collision or exit is reported at its first sample only)."""

    def __init__(self, problems: list[str]):
        self.problems = problems
        self.reported: set[tuple] = set()

    def __call__(self, key: tuple, text: str) -> None:
        if key not in self.reported:
            self.reported.add(key)
            self.problems.append(text)


def _note_contacts(note: _ProblemLog, traj: np.ndarray, t_s: np.ndarray, scenario, tol_um: float, where: str,
                   primitive: str) -> None:
    """Note every pair of bodies that interpenetrates, and every body outside the arena, along one step's samples."""
    names = list(scenario.names)
    length, width = scenario.lengths_um, scenario.widths_um
    pairs_i, pairs_j = np.triu_indices(len(names), k=1)
    for key, text in _overlaps(traj, t_s, pairs_i, pairs_j, length, width, tol_um, names, f"{where}, {primitive}"):
        note(key, text)
    if scenario.arena_um is not None:
        for key, text in _arena_exits(traj, t_s, length, width, scenario.arena_um, tol_um, names, where):
            note(key, text)


def _step_motion(pose: np.ndarray, goals: np.ndarray, docked: np.ndarray, turning: np.ndarray, scenario, dur: float,
                 ksteps: int, tol_um: float, heading_tol_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One primitive of ``dur`` s from ``pose``: ``(traj (K, n, 3), t (K,) s, t_dock (n,) s, accepted (n,))``.

    ``ksteps`` evenly spaced samples plus every docking instant (straight-moving robots whose slot lies ahead
    on their line within the step); docked robots stay put; a robot whose docking is accepted stops there.
    """
    speed = scenario.speeds_um_s
    moving = ~docked
    t_dock = _docking_times(pose, goals, moving & ~turning, speed, dur, tol_um, heading_tol_rad)
    t = np.unique(np.concatenate([np.linspace(0.0, dur, ksteps), t_dock[np.isfinite(t_dock)]]))
    traj = _motion(pose, turning & moving, speed, scenario.turn_radii_um, t)
    traj[:, docked, :] = pose[docked]
    accepted = _accepted_docks(t_dock, goals, pose, docked, scenario.lengths_um, scenario.widths_um, speed, tol_um)
    _stop_at_docks(traj, t, pose, speed, t_dock, accepted)
    return traj, t, t_dock, accepted


def _inaccessible_primitives(plan: Plan, accessible_turning: set[frozenset[str]] | None) -> list[str]:
    """One problem per plan primitive whose turning set is not an accessible control state."""
    if accessible_turning is None:
        return []
    return [f"primitive {p.name} (turning {sorted(p.turning)}) is not an accessible control state"
            for p in plan.primitives if frozenset(p.turning) not in accessible_turning]


def _docking_times(pose: np.ndarray, goals: np.ndarray, straight: np.ndarray, speed: np.ndarray, dur: float, tol_um: float,
                   heading_tol_rad: float) -> np.ndarray:
    """``(n,)`` time (s into the step) at which each straight-moving robot reaches its slot, inf if it does not
    this step (its slot not ahead on its line, or not within ``dur``)."""
    n = len(pose)
    t_dock = np.full(n, np.inf)
    for i in np.flatnonzero(straight & np.isfinite(goals[:, 0])).tolist():
        g = goals[i]
        dth = (g[2] - pose[i, 2] + math.pi) % TWO_PI - math.pi
        if abs(dth) > heading_tol_rad:
            continue
        h = np.array([math.sin(pose[i, 2]), math.cos(pose[i, 2])])
        d = g[:2] - pose[i, :2]
        along = float(d @ h)
        lateral = abs(float(d[0] * h[1] - d[1] * h[0]))
        if lateral <= tol_um and -tol_um <= along <= speed[i] * dur + tol_um:
            # within tolerance of the step's end counts as arriving at its end: never sample past it
            t_dock[i] = min(max(along, 0.0) / speed[i], dur)
    return t_dock


def _accepted_docks(t_dock: np.ndarray, goals: np.ndarray, pose: np.ndarray, docked: np.ndarray, length: np.ndarray,
                    width: np.ndarray, speed: np.ndarray, tol_um: float) -> np.ndarray:
    """``(n,)`` bool: docking events accepted, i.e. only against the structure: touching a docked body, or
    meeting the partner that docks at the same moment (G_1)."""
    n = len(t_dock)
    accepted = np.zeros(n, dtype=bool)
    for i in np.flatnonzero(np.isfinite(t_dock)).tolist():
        gi = goals[i]
        for j in range(n):
            if j == i:
                continue
            if docked[j] or (np.isfinite(t_dock[j]) and abs(t_dock[j] - t_dock[i]) * speed[i] <= tol_um):
                pj = pose[j] if docked[j] else goals[j]
                if penetration_depth(gi, length[i], width[i], pj, length[j], width[j])[0] >= -tol_um:
                    accepted[i] = True
                    break
    return accepted


def _stop_at_docks(traj: np.ndarray, t: np.ndarray, pose: np.ndarray, speed: np.ndarray, t_dock: np.ndarray,
                   accepted: np.ndarray) -> None:
    """Hold each robot whose docking was accepted at its docking pose from its docking time on (in place)."""
    for i in np.flatnonzero(accepted).tolist():
        after = t >= t_dock[i]
        h = np.array([math.sin(pose[i, 2]), math.cos(pose[i, 2])])
        stop = pose[i, :2] + speed[i] * t_dock[i] * h
        traj[after, i, 0:2] = stop
        traj[after, i, 2] = pose[i, 2]


def _overlaps(traj: np.ndarray, t_abs: np.ndarray, pairs_i: np.ndarray, pairs_j: np.ndarray, length: np.ndarray,
              width: np.ndarray, tol_um: float, names: list[str], where: str) -> list[tuple[tuple, str]]:
    """``(key, problem)`` for every pair of bodies that interpenetrate at some sample ``t_abs`` (s)."""
    if not len(pairs_i):
        return []
    K = traj.shape[0]
    a = traj[:, pairs_i, :].reshape(-1, 3)
    b = traj[:, pairs_j, :].reshape(-1, 3)
    depth = penetration_depth(
        a, np.tile(length[pairs_i], K), np.tile(width[pairs_i], K), b, np.tile(length[pairs_j], K), np.tile(width[pairs_j], K)
    ).reshape(K, -1)
    bad = depth > tol_um
    found = []
    for pk in np.flatnonzero(bad.any(axis=0)).tolist():
        kk = int(np.argmax(bad[:, pk]))
        i, j = int(pairs_i[pk]), int(pairs_j[pk])
        found.append((("overlap", i, j),
                      f"bodies of {names[i]} and {names[j]} overlap by {depth[:, pk].max():.1f} um at t = {t_abs[kk]:.2f} s ({where})"))
    return found


def _arena_exits(traj: np.ndarray, t_abs: np.ndarray, length: np.ndarray, width: np.ndarray, arena, tol_um: float,
                 names: list[str], where: str) -> list[tuple[tuple, str]]:
    """``(key, problem)`` for every robot whose body leaves the arena at some sample ``t_abs`` (s)."""
    K, n = traj.shape[0], traj.shape[1]
    out = outside_arena(traj.reshape(-1, 3), np.tile(length, K), np.tile(width, K), arena, tol_um=tol_um).reshape(K, n)
    found = []
    for i in np.flatnonzero((out > 0).any(axis=0)).tolist():
        kk = int(np.argmax(out[:, i] > 0))
        found.append((("arena", int(i)), f"{names[i]} leaves the arena by {out[:, i].max():.1f} um at t = {t_abs[kk]:.2f} s ({where})"))
    return found


def _extend_trace(trace_t: list[float], trace_p: list[np.ndarray], traj: np.ndarray, t: np.ndarray, t_now: float,
                  trace_every_um: float, vmax: float) -> None:
    """Append the step's samples about every ``trace_every_um`` um of the fastest robot, and its end (in place)."""
    stride = max(1, int(round(trace_every_um / max(vmax * (t[1] - t[0]) if len(t) > 1 else 1.0, 1e-9))))
    trace_t.extend((t_now + t[stride::stride]).tolist())
    trace_p.extend(traj[stride::stride])
    if (len(t) - 1) % stride:
        trace_t.append(t_now + t[-1])
        trace_p.append(traj[-1])


def _undocked(pose: np.ndarray, goals: np.ndarray, docked: np.ndarray, names: list[str]) -> list[str]:
    """One problem per robot not docked at the end."""
    problems = []
    for i in np.flatnonzero(~docked).tolist():
        if np.isfinite(goals[i, 0]):
            dist = float(np.hypot(*(pose[i, :2] - goals[i, :2])))
            problems.append(f"{names[i]} is not docked at its slot at the end (ends {dist:.1f} um from it)")
        else:
            problems.append(f"{names[i]} has no slot")
    return problems
