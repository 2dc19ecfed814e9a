"""State of the nominal planner: what one structure variant's planner holds (:class:`PlannerState`: the
scenario, the slots, the group's :class:`~stressbots.timeline.Timeline`, its random stream and notes) and
what the variants of one :func:`~stressbots.planning.plan_assembly` call share (:class:`SharedSearch`:
the search budget and the failures remembered across variants).

The planner's steps are classes built on :class:`PlannerState`, one concept per module:
:mod:`stressbots.dock_planning` (single-robot docking, pre-positioning, final approaches),
:mod:`stressbots.timed_paths` (paths of a prescribed duration), :mod:`stressbots.overlapped_pair`
(the overlapped G_1), :mod:`stressbots.pair_schedules` (the piece scheme of G_1) and
:mod:`stressbots.pair_planning` (the G_1 search that tries them).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from .electrostatics import ControlAnalysis
from .overlap import PairSchedule
from .planner_options import PlannerOptions
from .robots import orbit_radii, turning_centres
from .routing import NoRoute, Obstacles
from .structures import Structure
from .timeline import Timeline


class SharedSearch:
    """Work shared by the structure variants of one ``plan_assembly`` call.

    ``used`` counts the G_1 schedules tried against :attr:`PlannerOptions.search_budget`.
    ``pair_failures`` maps what a G_1 search depends on (see :meth:`~stressbots.pair_planning.PairPlanning.form_pair`) to why it
    failed: variants that differ only in later slots (which side stems grow on, which tooth is first)
    would repeat the same failing search exactly, so they fail at once with the same reason.
    ``bottlenecks`` are the ranks of robots whose docking failed in a variant: later variants check first
    that those robots can reach their slots at all (:meth:`~stressbots.dock_planning.DockPlanning.dock_check`), before forming G_1.
    ``docking_failed`` holds the variants (by id) that failed after G_1 was formed: the extended search,
    which only widens the G_1 search, skips them.
    """

    def __init__(self, budget: int | None):
        self.budget = budget
        self.used = 0
        self.pair_failures: dict = {}
        self.bottlenecks: list[int] = []
        self.docking_failed: set[int] = set()

    @property
    def spent(self) -> bool:
        return self.budget is not None and self.used >= self.budget

    def take(self) -> None:
        self.used += 1


def robot_label(scn, i: int, rank: int) -> str:
    """How messages name robot ``i`` of rank ``rank``: ``D3 ('R2')``."""
    return f"D{rank} ({scn.names[i]!r})"


def approach_length(struct: Structure, name: str, opts: PlannerOptions) -> float:
    """Length (um) of robot ``name``'s final approach: the planner's, capped by its slot's clear corridor."""
    return float(min(opts.approach_um, struct.slot(name).approach_um))


def pre_approach_pose(goal: np.ndarray, a: float) -> np.ndarray:
    """The pose ``a`` um straight back from ``goal`` along its heading (negative ``a``: ahead of it)."""
    return np.array([goal[0] - a * math.sin(goal[2]), goal[1] - a * math.cos(goal[2]), goal[2]])


class PlannerState:
    """What the planner of one structure variant holds: the scenario, the slots, the robots' sizes and
    motion, the group's :class:`~stressbots.timeline.Timeline`, the random stream of its route searches
    and its notes. ``extended`` selects the wider G_1 search (after every variant failed).
    """

    def __init__(self, scn, analysis: ControlAnalysis, struct: Structure, opts: PlannerOptions, *, extended: bool = False,
                 search: SharedSearch | None = None):
        self.search = search or SharedSearch(opts.search_budget)  # shared by every variant of one plan_assembly call
        self.extended = extended  # the wider G_1 search (leg stretch, orbit first, ...): after all variants failed
        self._wide_schedules = opts.pair_schedules  # G_1 schedules of an attempt at the wider of two clearances
        if extended:  # the wider G_1 search: more pieces (the seed's one-piece scheme stays one), more schedules
            pieces = max(opts.max_pieces, opts.extended_max_pieces) if opts.max_pieces > 1 else opts.max_pieces
            opts = replace(opts, max_pieces=pieces, pair_schedules=max(opts.pair_schedules, opts.extended_pair_schedules))
        self.scn = scn
        self.analysis = analysis
        self.struct = struct
        self.opts = opts
        self.n = scn.n
        order = analysis.order_index  # scenario indices of D_1..D_n
        assert order is not None and analysis.order is not None  # a STRING design (checked by plan_assembly)
        self.by_rank = {k + 1: int(i) for k, i in enumerate(order)}
        self.rank = np.empty(self.n, dtype=int)
        for k, i in self.by_rank.items():
            self.rank[i] = k
        self.goals = struct.goal_poses(scn.names)
        self.L, self.W = scn.lengths_um, scn.widths_um
        self.v, self.r = scn.speeds_um_s, scn.turn_radii_um
        self.rstar = orbit_radii(self.L, self.W, self.r)
        self.rng = np.random.default_rng(np.random.SeedSequence(opts.seed))
        self.tl = Timeline(scn, self.rank, [analysis.order[k] for k in range(self.n)])
        self.notes: list[str] = []
        self.route_lengths = np.zeros(self.n)
        self._timed_cache: dict = {}
        self._route_cache: dict = {}
        # Set by the G_1 search (:mod:`stressbots.pair_planning`) and read by the schedules it tries:
        self._orbit_first_on = False  # timed paths may first orbit at their start (the second G_1 pass)
        self._overlap_sched: PairSchedule | None = None  # an overlapped schedule accepted around a roadmap route
        self._overlap_routes_tried = 0  # roadmap routes tried overlapped in this G_1 search
        self._pair_schedule: tuple | None = None  # the piece scheme's accepted schedule
        self._pair_stage = "all"  # which part of the G_1 search runs: "all", "overlap" or "pieces" (form_pair_staged)

    def lab(self, i: int) -> str:
        return robot_label(self.scn, i, self.rank[i])

    def step_with_fallback(self, step: Callable[[], None], what: str) -> None:
        """Run one planning step (G_1, or one robot's docking); when it fails at the planner's clearance,
        plan that step again at :attr:`PlannerOptions.fallback_clearance_um`.

        The steps before and after keep the wider clearance: a failed step leaves the timeline as it
        was (steps are committed only once found), and a step starts from much the same configuration
        whatever the clearance of the steps before (docked robots in their slots, the others on their
        orbits), so the plan is about as complete as one planned at the fallback clearance throughout,
        at the cost of one search instead of two. The G_1 schedules the failed wide attempt tried are
        added to the search budget, so the fallback searches as far as a search at its clearance alone
        would. Raises the fallback attempt's :class:`NoRoute`.

        The wide clearance is a preference: in the extended search its attempt gets the standard search's
        G_1 schedules per G_1 search (:attr:`PlannerOptions.pair_schedules`), the extended search's
        (``extended_pair_schedules``) being for the fallback, where completeness is at stake (gap-16:
        63 schedules, 12 s, failed at 40 um before 5 planned it at 10 um).
        """
        wide, fallback = self.opts, self.opts.fallback_clearance_um
        two = fallback is not None and fallback < wide.clearance_um
        used = self.search.used
        if two and wide.pair_schedules > self._wide_schedules:
            self.opts = replace(wide, pair_schedules=self._wide_schedules)
        try:
            step()
            return
        except NoRoute:
            if not two:
                raise
        finally:
            self.opts = wide
        if self.search.budget is not None:  # the failed wide attempt's G_1 schedules are not the fallback's to miss
            self.search.budget += self.search.used - used
        assert fallback is not None  # ``two``
        self.opts = replace(wide, clearance_um=fallback, fallback_clearance_um=None)
        self._timed_cache.clear()  # both caches hold paths checked at the wider clearance
        self._route_cache.clear()
        try:
            step()
        finally:
            self.opts = wide
            self._timed_cache.clear()
            self._route_cache.clear()
        if what:
            self.notes.append(f"{what} planned with {fallback:g} um clearance (none found with {wide.clearance_um:g} um)")

    def obstacles(self, orbiting: Sequence[int], docked: Sequence[int]) -> Obstacles:
        orbiting = list(orbiting)
        docked = list(docked)
        centres = turning_centres(self.tl.poses[orbiting], self.r[orbiting]) if orbiting else np.zeros((0, 2))
        return Obstacles(
            centres,
            self.rstar[orbiting] if orbiting else np.zeros(0),
            tuple(f"the orbit of {self.lab(i)}" for i in orbiting),
            self.goals[docked] if docked else np.zeros((0, 3)),
            self.L[docked] if docked else np.zeros(0),
            self.W[docked] if docked else np.zeros(0),
            tuple(f"the docked body of {self.lab(i)}" for i in docked),
            self.scn.arena_um,
        )
