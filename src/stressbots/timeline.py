"""The planner's forward model: the nominal poses of the whole group as primitives are applied
(:class:`Timeline`), and the :class:`Phase` records a closed-loop controller follows.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from . import paths as pathlib
from .errors import PlanningError
from .kinematics import advance
from .plans import PlanStep
from .robots import TWO_PI


@dataclass(frozen=True)
class Phase:
    """One phase of a plan, as a closed-loop controller follows it.

    ``mover`` (scenario index) drives toward ``target`` with primitives ``turn_k`` (its arm down) and
    ``straight_k`` (arm up); every robot with a lower voltage index orbits, higher ones push or (for
    ``pair-B``) drive straight. Kinds: ``pair-A`` (D_n moves, D_{n-1} orbits), ``pair-B`` (D_{n-1} moves,
    D_n runs straight: ``run`` is D_n's run start and length), ``wait`` (a docking robot orbits before
    leaving), ``route`` (it drives to the start of its approach through ``waypoints``) and ``approach``
    (its final approach into the slot: an interpolated clockwise arc, then a short straight push).
    ``path``/``path_start`` give the mover's planned path; ``approach_um`` the length of its final approach.
    """

    kind: str
    mover: int
    turn_k: int
    straight_k: int
    t0_s: float
    duration_s: float
    target: tuple[float, float, float]
    waypoints: tuple[tuple[float, float, float], ...] = ()
    partner: int = -1
    run: tuple[tuple[float, float, float], float] | None = None
    last: bool = False
    partner_end: tuple[float, float, float] | None = None
    path: tuple[tuple[str, float], ...] = ()
    path_start: tuple[float, float, float] | None = None
    approach_um: float = 0.0


class Timeline:
    """Nominal poses of the whole group as primitives are applied (the planner's own forward model)."""

    def __init__(self, scenario, rank: np.ndarray, names_by_rank: Sequence[str]):
        self.scenario = scenario
        self.rank = rank  # rank[i] = k means robot i (scenario order) is D_k (1-based)
        self.names_by_rank = names_by_rank
        self.poses = scenario.starts.copy()
        self.poses[:, 2] = np.mod(self.poses[:, 2], TWO_PI)
        self.docked = np.zeros(scenario.n, dtype=bool)
        self.speed = scenario.speeds_um_s
        self.radius = scenario.turn_radii_um
        self.t = 0.0
        self.steps: list[PlanStep] = []
        self.travel = np.zeros(scenario.n)  # distance driven off-orbit per robot (um)
        self.phases: list[Phase] = []

    def phase(self, kind: str, mover: int, turn_k: int, straight_k: int, t0: float, target, **extra) -> None:
        """Record the phase that just ran (from ``t0`` to now)."""
        self.phases.append(
            Phase(kind, int(mover), int(turn_k), int(straight_k), float(t0), float(self.t - t0),
                  (float(target[0]), float(target[1]), float(target[2])), **extra)
        )

    def apply(self, k: int, duration: float, *, counts_for: Sequence[int] = ()) -> None:
        """Apply P_k for ``duration`` s (docked robots stay, they push against the structure)."""
        if duration <= 0:
            return
        turning = self.rank <= k
        moving = ~self.docked
        new = advance(self.poses, turning, self.speed, self.radius, duration)
        self.poses[moving] = new[moving]
        for i in counts_for:
            self.travel[i] += self.speed[i] * duration
        self.steps.append(PlanStep(f"P{k}", float(duration)))
        self.t += duration

    def apply_path(self, i: int, path: pathlib.Path, turn_k: int, straight_k: int) -> None:
        """Drive robot ``i`` along ``path`` with the two primitives that move it (R -> turn_k, S -> straight_k)."""
        v = self.speed[i]
        for kind, ell in path.segments:
            self.apply(turn_k if kind == "R" else straight_k, ell / v, counts_for=(i,))

    def dock(self, i: int, goal: np.ndarray, who: str, tol_um: float = 1e-3) -> None:
        err = float(np.hypot(*(self.poses[i, :2] - goal[:2])))
        dth = abs((self.poses[i, 2] - goal[2] + math.pi) % TWO_PI - math.pi)
        if err > tol_um or dth > 1e-6:
            raise PlanningError(f"internal: {who} ends {err:.3g} um / {math.degrees(dth):.3g} deg from its slot")
        self.poses[i] = goal
        self.docked[i] = True
