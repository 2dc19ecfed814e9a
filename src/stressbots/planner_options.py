"""Settings of the nominal planner (:func:`stressbots.planning.plan_assembly`): :class:`PlannerOptions`,
its search budget default and the :data:`SHORTEST` overrides.
"""

from __future__ import annotations

from dataclasses import dataclass

from .overlap import OverlapSettings
from .prepositioning import PrepositionSettings

SEARCH_BUDGET_DEFAULT = 128
"""Default :attr:`PlannerOptions.search_budget` (G_1 schedules, ~25-70 ms each). Of
``benchmarks/bench_planner.py``'s layouts of 2-8 robots, the ones that plan use at most 97 (cross-8, by
the extended search); tee-8 needs 232 (14 s of CPU) and is refused after 128 (~8 s) instead. Before
variants with the same G_1 slots shared their failure, tee-8 searched 288 (12 G_1 searches of 24, ~22 s
of CPU) and failed."""


@dataclass(frozen=True)
class PlannerOptions:
    """Planner settings (um, s).

    Attributes
    ----------
    clearance_um:
        Distance kept from orbit discs, the structure and the arena edge (room for control error).
    approach_um:
        Length of the final approach into every slot (capped by the slot's clear corridor): a gentle
        interpolated clockwise arc that arrives at the slot's heading, then a short straight push. The
        closed-loop controller flies the same arc as its fine motion, correcting its radius.
    sample_um:
        Spacing of the collision-check samples along routes.
    departure_phases:
        How many departure phases on its orbit a docking robot tries.
    roadmap_nodes:
        Sizes of the successive waypoint roadmaps tried when no direct route is clear.
    max_pieces:
        Largest number of pieces D_{n-1}'s route may be cut into while forming G_1.
    seed:
        Seed of the roadmap's random waypoints (the plan is a deterministic function of it).
    time_budget_s:
        Wall time after which no further structure variant is tried.
    max_candidates:
        Most structure variants tried (None: all). A deterministic budget: unlike ``time_budget_s`` it
        gives the same result on a loaded machine, so tests use it.
    pair_candidates:
        How many schedulable direct departures of D_{n-1} are compared when forming G_1 (the shortest
        schedule is kept, and one-piece schedules around roadmap routes are tried too); 1 takes the
        first schedulable route, as the seed does. Default 1 for now: see :data:`SHORTEST`.
    variants_compared:
        How many plannable structure variants (a named shape's mirror images and assignments) are
        planned in full, cheapest lower bound first; the shortest plan is returned. A variant whose
        lower bound is already longer than the best plan is skipped. 1 returns the first plan found
        (default for now: see :data:`SHORTEST`).
    orbit_phases:
        When D_n's whole-period path between two runs of G_1 is blocked, how many phases of its own
        orbit it may first orbit to before leaving (0: never, as in the seed's scheme).
    extended_search:
        When no variant is plannable, search again with the wider G_1 search: routed whole-period paths
        stretched in one leg, ``orbit_phases``, and parking-track runs that stop short of the track's end
        or fit after D_{n-1}'s wait (False: the standard search only).
    pair_schedules:
        G_1 schedules tried per G_1 search (each plans D_n around one cut of one route of D_{n-1}, the
        expensive step); when they are spent, the search ends: a hopeless pair costs at most this many.
    extended_max_pieces, extended_pair_schedules:
        ``max_pieces`` and ``pair_schedules`` of the extended search: more, shorter pieces of D_{n-1}'s
        route with D_n re-aimed between them (``max_pieces`` = 1, the seed's scheme, stays 1), and more
        schedules per G_1 search.
    overlap_pair:
        Form G_1 with overlapped schedules first (:mod:`stressbots.overlap`): D_n turns toward its slot
        while D_{n-1} turns (on its orbit and on its route's arcs), so it runs straight only while D_{n-1}
        does. Much shorter G_1 than the seed's two stages; False keeps only the seed's scheme and its
        pieces.
    overlap:
        Settings of that search.
    preposition:
        While a robot docks, let the next one drive straight during its straight stretches (P_{k-2}
        instead of P_{k-1}: :mod:`stressbots.prepositioning`) when that shortens the next one's docking.
    preposition_settings:
        Settings of that search.
    fallback_clearance_um:
        When a step (G_1, or one robot's docking) finds no plan at ``clearance_um``, that step alone is
        planned again at this clearance (um; None: never), the other steps keeping ``clearance_um``. The
        controller's plans (:func:`stressbots.control.nominal_plan`) use it: a wide clearance wherever
        it fits, in one search instead of a whole second one at the smaller clearance.
    tight_approach_deg, tight_approach_radius:
        Turn angles (deg, tried in order) and radius (times the robot's turning radius) of the tight
        final approaches a docking robot falls back on when no route reaches the start of its gentle
        approach (which starts ~``approach_um`` behind the slot): arcs that start beside the slot, for a
        slot whose rear lies near the arena edge (a long stem's tip). A radius just above the turning
        radius leaves the fine motion little room to correct, so they are only a fallback; () never.
    timed_roadmaps:
        How many of ``roadmap_nodes``' roadmaps D_n's routed timed paths of G_1 search (the first ones):
        a leg whose route fails in the 80-node roadmap mostly fails in the larger one too, and a G_1 search
        has other cuts and routes to try (2 until issue 15's speed work: gap-16's nominal plan 30 -> 16 s of
        CPU, three other seeds 10-15 % faster). A layout no search plans is planned again with one more
        roadmap (up to all of them) before it is refused, unless ``search_budget`` was spent (each such pass
        has its own budget): gap-14 of ``bench_planner.py`` needs the second.
    search_budget:
        G_1 schedules tried over the whole search (every structure variant, standard and extended): a
        deterministic bound on the time spent on a layout that cannot be planned (unlike
        ``time_budget_s``, the same on a loaded machine). When it is spent no further variant is tried and
        the failure names the most common obstacle. None: no bound.
    """

    clearance_um: float = 10.0
    approach_um: float = 160.0
    sample_um: float = 5.0
    departure_phases: int = 12
    roadmap_nodes: tuple[int, ...] = (80, 250, 700)
    max_pieces: int = 6
    seed: int = 0
    time_budget_s: float = 120.0
    max_candidates: int | None = None
    pair_candidates: int = 1
    variants_compared: int = 1
    orbit_phases: int = 16
    extended_search: bool = True
    pair_schedules: int = 24
    extended_max_pieces: int = 10
    extended_pair_schedules: int = 64
    fallback_clearance_um: float | None = None
    tight_approach_deg: tuple[float, ...] = (90.0, 60.0, 45.0)
    tight_approach_radius: float = 1.1
    search_budget: int | None = SEARCH_BUDGET_DEFAULT
    timed_roadmaps: int = 1
    overlap_pair: bool = True
    overlap: OverlapSettings = OverlapSettings()
    preposition: bool = True
    preposition_settings: PrepositionSettings = PrepositionSettings()


SHORTEST = {"pair_candidates": 4, "variants_compared": 3}
"""PlannerOptions overrides for shorter plans (issue 15): compare G_1 schedules and structure variants.

Not the default yet. The controller now assembles these plans as often as the default ones (tests/test_edr.py
passes with them; 21/28 closed-loop trials either way on 14 tuning layouts of bench_generality.py), and
they are 12 % shorter in total on bench_planner.py's layouts of 2-8 robots, but planning takes 2-13x
longer and some plans are longer (gap-8), so the default stays the faster plan the controller was tuned on.
Those figures predate the overlapped G_1 and pre-positioning (now default), which it does not change: its
G_1 comparison only runs when no overlapped schedule is found. Not re-measured since.
"""
