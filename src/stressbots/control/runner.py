"""Closed-loop assembly under control error: the two-step EDR strategy of seed Appendix 3.

The controller talks to the robots only through a :class:`stressbots.control.Plant` (``observe`` and
``apply``). Every ``replan_interval_s`` (t_x) it takes a camera frame, updates its estimates
(:mod:`stressbots.estimation`: filtered poses, identified speeds and turn rates) and re-plans the moving
robot's motion from where it really is. The nominal plan (:func:`stressbots.planning.plan_assembly`)
supplies the structure, the slots and the single robots' roadmap routes; the controller never replays
its timing.

**One-way robots and regions.** A robot that only turns clockwise cannot undo a small error to its
left without a full loop, so no step aims at an exact pose: every target is a region (the seed's A_i),
gross motion keeps a left bias (turns into long straights are cut short by up to 3 deg; the next
replan adds the missing clockwise turn), and the last seconds of a timed path run open loop rather
than being re-planned into a loop.

**G_1 (App. 3.3), as an orbit rendezvous** (:mod:`stressbots.control.pair`, handed this loop). Under P_n
and P_{n-1} D_{n-1} orbits in place while D_n is a free one-way robot (P_n turns it, P_{n-1} drives it
straight); under P_{n-2} both drive straight.

1. *Transfer*: D_{n-1} moves its orbit to a station orbit, in straight legs: it orbits until it heads
   along the leg, then P_{n-2} drives it (and D_n) straight; clockwise bearing corrections (P_{n-1}
   bursts) keep it on course. D_n either turns with D_{n-1} for a chosen fraction of the wait and then
   runs straight on a track checked to be clear, or first drives to a chosen clear track, timed to
   D_{n-1}'s departure.
2. *Rendezvous*: D_n drives to a region on the tangent of D_{n-1}'s orbit that leads to D_{n-1}'s slot,
   timed to arrive 1.2 s before D_{n-1} passes the tangent point. Timing comes from waiting on its own
   orbit (and straights before it): any arrival time is reachable without long detours. D_n then runs
   straight; D_{n-1} leaves its orbit at the heading that best lines it up with D_n as measured.
3. *Meeting*: both drive straight into each other; self-aligning compliance (|alpha| < 60 deg,
   |w_y| < 80 um) forms G_1 wherever they meet. The remaining slots follow the pair (``retarget``).

**Docking of single robots (sigma_1, sigma_2)** (:mod:`stressbots.control.single`, handed this loop).
Gross motion steers D_i (P_i turns, P_{i-1} straight, lower robots orbiting) into the approach funnel
behind its slot, outside the proximity region C_O: the region from which it can merge onto the slot's
approach line without a loop (to the line's right, pointing left of it). Fine motion merges with an
interpolated clockwise arc of radius r' >= r (P_i for a fraction rho_a, P_{i-1} for rho_b, SPEC 8's
``r' = r (1 + rho_b / rho_a)``), drives straight in and pushes; docking compliance absorbs the last
angle error. Tight gaps use the seed's S_2f arc through the docking point instead.

**Failure detection and recovery.** A robot that stops while it should move is in H (stuck): it backs
off by turning and tries again; a robot that misses its approach line loops back through the funnel; a
robot the camera loses is dead-reckoned until it is seen again; a path that would meet an orbit, the
structure or the arena edge is routed around them on a roadmap (one route, followed waypoint by
waypoint). Everything runs within a simulated time budget, and a run that fails says why.

Success is judged on the shape after a best rigid alignment (:mod:`stressbots.assessment`); the absolute
placement error is reported beside it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..collision import point_rectangle_distance
from ..errors import PlanningError
from ..kinematics import move
from ..robots import angle_difference, turning_centres
from .gross import GrossMotion, SteerOutcome
from .loop import PlantLoop
from .pair import PairPhase, Replan
from .park_tries import ParkTries
from .parking import blocking_orbits, orbit_gaps, straights_clear, unblock_move
from .queries import interpolated_steps
from .result import AssemblyResult, judge_run
from .single import SingleDocking
from .targets import Targets, nominal_plan, structure_targets
from .tuning import ControllerOptions

__all__ = ["assemble", "stream", "STREAMS"]


STREAMS = ("routes",)
"""Names of the controller's random streams, each spawned from the run's seed (:func:`stream`)."""


def stream(seed: int | None, name: str) -> np.random.Generator:
    """The random generator of the named stream ``name`` for a run with ``seed`` (None counts as 0).

    Streams are independent (``SeedSequence(seed, spawn_key=(index of name,))``), so adding draws to
    one never shifts another.
    """
    return np.random.default_rng(np.random.SeedSequence(0 if seed is None else int(seed), spawn_key=(STREAMS.index(name),)))


class _Abort(Exception):
    """The run cannot go on; ``reason`` says why (reported as the result's ``failure``)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason




class _Budget(_Abort):
    def __init__(self, budget_s: float):
        super().__init__(f"not assembled within the time budget of {budget_s:g} s (simulated)")


class _Runner(PlantLoop):
    def __init__(self, scenario, plant, plan_result, opts: ControllerOptions, seed):
        super().__init__(scenario, plant, budget_s=opts.time_budget_s, who="closed-loop assembly",
                         frame_interval_s=opts.frame_interval_s, frames_per_step=opts.frames_per_step,
                         drift_turn_max_deg=opts.tuning.drift_turn_max_deg)
        self.opts = opts
        self.tune = opts.tuning
        self.seed = seed
        self.tx = float(opts.replan_interval_s or scenario.control.replan_interval_s)
        # named random streams of this run (the roadmap's samples); never derived from the event count
        self.routes_rng = stream(seed, "routes")
        if not isinstance(plan_result, Targets):
            plan_result = Targets(plan_result.plan.goal_array(), tuple(plan_result.phases))
        self.pr = plan_result
        self.v, self.r = scenario.speeds_um_s, scenario.turn_radii_um
        self.nominal_goals = np.asarray(plan_result.goals, dtype=np.float64).copy()
        self.goals = self.nominal_goals.copy()
        self._warned: set = set()
        # (robot, phase k) -> park moves so far (parking); a move that did not widen the gap is the last of its phase
        self._parked: dict[tuple[int, int], int] = {}
        self._park_refused: dict[tuple[int, int], float] = {}  # (robot, phase k) -> gap (um) at its last refused park
        self._unblocks: dict[tuple[int, int], int] = {}  # (robot, phase k) -> orbit moves off a docking robot's way
        # rigid motion (phi, c_nom, c_meas) of the structure once G_1 formed
        self.motion: tuple[float, np.ndarray, np.ndarray] | None = None
        # gross motion sigma_1 (:mod:`stressbots.control.gross`), G_1 (:mod:`stressbots.control.pair`) and the single
        # robots' docking (:mod:`stressbots.control.single`), driven through this loop
        self.gross = GrossMotion(self)
        self.pair = PairPhase(self)
        self.single = SingleDocking(self)
        self.park_tries = ParkTries(self, self._group_move)

    # -- plant I/O ------------------------------------------------------------------------------------

    def over_budget(self) -> Exception:
        return _Budget(self.budget_s)

    def abort(self, reason: str) -> Exception:
        """The error a phase raises when the run cannot go on (the result's ``failure`` is ``reason``)."""
        return _Abort(reason)

    def after_drive(self, steps: Sequence[tuple[int, float]]) -> None:
        """Failure detection after every frame: robots lost to the camera, orbits drifting into trouble."""
        for i in np.flatnonzero(self.estimator.unseen == 3):
            self.log("lost", int(i), "not seen for 3 frames; dead-reckoning")
        self.watch_orbits([i for i in range(self.n) if not self.docked[i] and self.rank[i] < min(k for k, _ in steps)])

    def watch_orbits(self, orbiting: Sequence[int]) -> None:
        """Failure detection: an orbit (drifting with the heading noise) within 10 um of another orbit,
        a docked body or the arena edge is logged once. Paths are always planned around the orbits as
        measured, so the robot moving meanwhile keeps clear of them; a collision would show as a stall."""
        if not orbiting:
            return
        c = turning_centres(self.est[orbiting], self.r_hat[orbiting])
        rs = self.rstar[orbiting]
        for a, i in enumerate(orbiting):
            near = []
            for b, j in enumerate(orbiting[a + 1:], start=a + 1):
                gap = float(np.hypot(*(c[a] - c[b]))) - rs[a] - rs[b]
                if gap < self.tune.orbit_watch_um:
                    near.append((f"the orbit of {self.scn.names[j]}", gap))
            for j in np.flatnonzero(self.docked).tolist():
                gap = float(point_rectangle_distance(c[a][None, :], self.est[j][None, :], self.L[j], self.W[j])[0, 0]) - rs[a]
                if gap < self.tune.orbit_watch_um:
                    near.append((f"docked {self.scn.names[j]}", gap))
            if self.scn.arena_um is not None:
                w, h = self.scn.arena_um
                gap = float(min(c[a][0], w - c[a][0], c[a][1], h - c[a][1])) - rs[a]
                if gap < self.tune.orbit_watch_um:
                    near.append(("the arena edge", gap))
            for what, gap in near:
                key = (i, what)
                if key not in self._warned:
                    self._warned.add(key)
                    self.log("orbit-drift", i, f"the orbit of {self.scn.names[i]} is {gap:.0f} um from {what}")

    # -- geometry -------------------------------------------------------------------------------------

    def obstacles_hit(self, samples: np.ndarray, i: int, orbiting: Sequence[int], *, extra_discs=(), clearance: float | None = None,
                      target=None) -> bool:
        """Whether robot ``i``'s body along ``samples`` hits an orbit, a docked body or the arena edge
        (:meth:`stressbots.control.gross.GrossMotion.obstacles_hit`)."""
        return self.gross.obstacles_hit(samples, i, orbiting, extra_discs=extra_discs, clearance=clearance, target=target)

    def park_orbits(self, k: int, top: int | None = None, margin_um: float | None = None, among: Sequence[int] = ()) -> None:
        """Before D_k's phase: move waiting orbits that drifted within ``margin_um`` (default
        ``Tuning.park_margin_um``) of the arena edge, the structure or another orbit
        (:mod:`stressbots.control.parking`). Only the orbits of D_1 .. D_top count (``top`` = k; k - 1 while D_k
        moves: it has no orbit then). An orbit may be moved again in the same phase when it drifts back (up to
        ``Tuning.park_moves_per_phase`` moves), unless its last move did not widen its gap by
        ``Tuning.park_progress_um`` (a trapped robot: repeating the move would not free it). A move refused after its
        wait (its straight no longer clear) is tried again once the orbit drifted ``Tuning.park_retry_drift_um`` closer to
        trouble. The orbit discs of the robots ``among`` (D_(n-1) orbiting at the end of a station-transfer leg, or
        during G_1's timed approach) count as trouble too."""
        margin = self.tune.park_margin_um if margin_um is None else margin_um
        waiting = [self.by_rank[j] for j in range(1, (k if top is None else top) + 1)]
        gaps = self._waiting_gaps(waiting, among)
        for idx in np.argsort(gaps):
            i = waiting[int(idx)]
            j = int(self.rank[i])
            if gaps[idx] >= margin or j == k or self._parked.get((i, k), 0) >= self.tune.park_moves_per_phase:
                continue
            refused = self._park_refused.get((i, k))
            if refused is not None and gaps[idx] > refused - self.tune.park_retry_drift_um:
                continue  # refused at about this gap: the same poses would be refused again
            move_, park = self.park_tries.find(i, k, float(gaps[idx]), margin)
            if move_ is None:
                if (i, "park") not in self._warned:  # once: tend_orbits asks every t_x
                    self._warned.add((i, "park"))
                    self.log("park", i, f"the orbit of {self.scn.names[i]} is {gaps[idx]:.0f} um from trouble and no clear move "
                                        "takes it away")
                continue
            self._warned.discard((i, "park"))
            self.replans += 1
            self._parked[(i, k)] = self._parked.get((i, k), 0) + 1
            move_ = self.park_tries.drive_wait(i, k, move_, park)
            if move_ is None:
                self.log("park", i, f"the orbit of {self.scn.names[i]} is {gaps[idx]:.0f} um from trouble, but after the wait "
                                    "its straight is not clear: it stays")
                # another wait from here would end the same way; once the orbit drifted on, the poses differ
                self._park_refused[(i, k)] = float(gaps[idx])
                continue
            self.log("park", i, f"the orbit of {self.scn.names[i]} is {gaps[idx]:.0f} um from trouble: it moves "
                                f"{park['shift_um']:.0f} um away")
            self._drive_group_straight(i, k, move_.straight_s)
            if self._waiting_gaps(waiting, among)[idx] < gaps[idx] + self.tune.park_progress_um:
                self._parked[(i, k)] = self.tune.park_moves_per_phase  # it did not help: not repeated this phase

    def _waiting_gaps(self, waiting: Sequence[int], among: Sequence[int] = ()) -> np.ndarray:
        """Measured gaps (um) of the ``waiting`` robots' orbit discs to the arena edge, the docked bodies, each other
        and the orbit discs of ``among``."""
        docked = np.flatnonzero(self.docked)
        discs = [*waiting, *among]
        return orbit_gaps(turning_centres(self.est[discs], self.r_hat[discs]), self.rstar[discs], self.scn.arena_um,
                          self.est[docked], self.L[docked], self.W[docked])[:len(waiting)]

    def _drive_group_straight(self, i: int, k: int, straight_s: float) -> None:
        """The straight of a group move of waiting robot ``i`` in D_k's phase (P_(j-1), j = rank of ``i``: D_j .. D_k
        straight), ``straight_s`` s, one t_x at a time: each part is driven only while it keeps every mover's orbit
        disc ``Tuning.park_clearance_um`` clear (or no closer) as measured (:func:`~stressbots.control.parking.straights_clear`)."""
        j = int(self.rank[i])
        movers, still = [self.by_rank[m] for m in range(j, k + 1)], [self.by_rank[m] for m in range(1, j)]
        left = straight_s
        while left > 1e-6:
            dt = min(left, self.tx)
            docked = np.flatnonzero(self.docked)
            if not straights_clear(movers, still, self.est, self.r_hat, self.v_hat, self.rstar, self.scn.arena_um, self.est[docked],
                                   self.L[docked], self.W[docked], dt, self.tune.park_clearance_um):
                self.log("park", i, f"the straight of {self.scn.names[i]}'s orbit move stops {left * self.v_hat[i]:.0f} um short: "
                                    "as measured it would run an orbit into trouble")
                return
            self.drive([(j - 1, dt)])
            left -= dt

    def tend_orbits(self, k: int) -> None:
        """During D_k's gross motion (every t_x): :meth:`park_orbits` for the orbits waiting below it.

        Orbits drift in a random walk while others move (an orbit went from 10 um to -6 um from the arena
        edge within one phase, trapping its robot); checked only before each phase, that was too late.
        Nothing during G_1 (k of the pair: its timing is the pair phase's own)."""
        if 1 <= k <= self.n - 2:
            self.park_orbits(k, top=k - 1)

    def _group_move(self, move_fn, i: int, k: int, *extra, **settings):
        """``move_fn`` (:func:`~stressbots.control.parking.park_move` or ``unblock_move``) for waiting robot ``i``
        during D_k's phase, from the present estimates: D_j .. D_k (j = rank of ``i``) drive straight under
        P_{j-1}, D_1 .. D_(j-1) keep orbiting, the docked bodies are obstacles."""
        j = int(self.rank[i])
        docked = np.flatnonzero(self.docked)
        return move_fn(i, [self.by_rank[m] for m in range(j, k + 1)], [self.by_rank[m] for m in range(1, j)], self.est, self.r_hat,
                       self.omega_hat, self.v_hat, self.rstar, self.scn.arena_um, self.est[docked], self.L[docked], self.W[docked],
                       *extra, **settings)

    def unblock_orbits(self, k: int, i: int, points: np.ndarray) -> bool:
        """During D_k's (robot ``i``'s) phase: move the waiting orbits (D_1 .. D_(k-1)) that block the ``points``
        (P, 2) robot ``i`` needs (:func:`~stressbots.control.parking.blocking_orbits`) off them
        (:func:`~stressbots.control.parking.unblock_move`), at most ``Tuning.unblock_moves_per_phase`` times
        each; True if one moved."""
        waiting = self.orbiting_below(k)
        if not waiting:
            return False
        reach = 0.5 * float(np.hypot(self.L[i], self.W[i])) + self.opts.clearance_um
        blocked = blocking_orbits(turning_centres(self.est[waiting], self.r_hat[waiting]), self.rstar[waiting], points, reach)
        moved = False
        for idx in np.flatnonzero(blocked):
            b = waiting[int(idx)]
            if self._unblocks.get((b, k), 0) >= self.tune.unblock_moves_per_phase:
                continue
            unblock = {"reach_um": reach, "margin_um": self.tune.unblock_margin_um, "max_shift_um": self.tune.unblock_max_shift_um,
                       "clearance_um": self.tune.park_clearance_um}
            move_ = self._group_move(unblock_move, b, k, points, loops=self.tune.unblock_extra_loops, **unblock)
            self._unblocks[(b, k)] = self._unblocks.get((b, k), 0) + 1
            if move_ is None:
                self.log("unblock", b, f"the orbit of {self.scn.names[b]} blocks {self.scn.names[i]}'s way and no clear move takes "
                                       "it off")
                continue
            if self.sweeps_into_contact(i, move_.wait_s):
                self.log("unblock", b, f"the orbit of {self.scn.names[b]} blocks {self.scn.names[i]}'s way, but {self.scn.names[i]} "
                                       "would turn into something while it waits: it stays")
                continue
            self.replans += 1
            heading = float(np.mod(self.est[b, 2] + self.omega_hat[b] * move_.wait_s, 2.0 * np.pi))
            self.drive([(k, move_.wait_s)])
            # the straight is checked again from the measured poses, along the heading the waiting robot has: one
            # touched by the docking robot cannot turn (its planned straight would run off in a direction nobody
            # checked), and the other movers' headings were predicted with rates identified from little motion
            turned = abs(angle_difference(self.est[b, 2], heading)) <= np.radians(self.tune.unblock_heading_tol_deg)
            move_ = self._group_move(unblock_move, b, k, points, headings=[float(self.est[b, 2])], **unblock)
            if move_ is None:
                why = "after the wait its straight is not clear" if turned else "it did not turn to its departure heading"
                self.log("unblock", b, f"the orbit of {self.scn.names[b]} blocks {self.scn.names[i]}'s way, but {why}: it stays")
                continue
            self.log("unblock", b, f"the orbit of {self.scn.names[b]} blocks {self.scn.names[i]}'s way: it moves "
                                   f"{move_.straight_s * self.v_hat[b]:.0f} um off it")
            self._drive_group_straight(b, k, move_.straight_s)
            moved = True
        return moved

    def sweeps_into_contact(self, i: int, turn_s: float) -> bool:
        """Whether robot ``i``, clear of everything now, would touch a waiting orbit, a docked body or the arena edge
        turning clockwise for ``turn_s`` s (the wait of a group move turns the docking robot as well: one such wait
        turned it into the very orbit being moved, and both were pinned). False when it touches something already
        (nothing to lose)."""
        k = int(self.rank[i])
        waiting = self.orbiting_below(k)
        if self.obstacles_hit(self.est[i][None, :], i, waiting, clearance=0.0):
            return False
        r = float(self.r_hat[i])
        arc = move(self.est[i], np.linspace(0.0, min(float(self.v_hat[i]) * turn_s, 2.0 * np.pi * r), 48), 1.0 / r)
        return self.obstacles_hit(arc, i, waiting, clearance=0.0)

    def escape(self, i: int, turn_k: int, straight_k: int, orbiting: Sequence[int]) -> bool:
        """A checked escape of robot ``i`` (:meth:`stressbots.control.escapes.Escapes.escape`); True if it moved."""
        return self.gross.escapes.escape(i, turn_k, straight_k, orbiting)

    def free_move(self, i: int, orbiting: Sequence[int]) -> tuple[float, float] | None:
        """A checked move on for robot ``i`` from where it is (:meth:`~stressbots.control.escapes.Escapes.free_move`)."""
        return self.gross.escapes.free_move(i, orbiting)

    def drive_move(self, i: int, turn_k: int, straight_k: int, move_: tuple[float, float], orbiting: Sequence[int]) -> None:
        """Drive robot ``i``'s move ``move_`` checked again every t_x (:meth:`~stressbots.control.escapes.Escapes.drive_move`)."""
        self.gross.escapes.drive_move(i, turn_k, straight_k, move_, orbiting)

    def boxed_in(self, i: int, orbiting: Sequence[int]) -> bool:
        """Whether robot ``i`` cannot move on from where it is (:meth:`~stressbots.control.escapes.Escapes.boxed_in`)."""
        return self.gross.escapes.boxed_in(i, self.est[i], orbiting)

    def orbiting_below(self, k: int) -> list[int]:
        return [self.by_rank[j] for j in range(1, k)]

    # -- motion primitives ------------------------------------------------------------------------------

    def steer(self, i: int, target: np.ndarray, turn_k: int, straight_k: int, orbiting: Sequence[int], *, extra_discs=(),
              max_cycles: int = 400, ready: Callable[[], bool] | None = None, via: bool = True,
              clearance: float | None = None, ready_if_blocked: Callable[[], tuple[str, str] | None] | None = None,
              waypoint: bool = False, region: np.ndarray | None = None) -> SteerOutcome:
        """Gross motion of robot ``i`` to ``target``; ARRIVED when there (:meth:`stressbots.control.gross.GrossMotion.steer`)."""
        return self.gross.steer(i, target, turn_k, straight_k, orbiting, extra_discs=extra_discs, max_cycles=max_cycles, ready=ready,
                                via=via, clearance=clearance, ready_if_blocked=ready_if_blocked, waypoint=waypoint,
                                region=region)

    def interpolated_steps(self, rho_turn: float, duration: float, turn_k: int, straight_k: int):
        """S_2f for ``duration`` s (:func:`~stressbots.control.queries.interpolated_steps`)."""
        return interpolated_steps(rho_turn, duration, turn_k, straight_k, self.opts.switch_period_s)

    # -- the whole assembly ---------------------------------------------------------------------------

    def run(self) -> str | None:
        phases = self.pr.phases
        try:
            # nothing tends the waiting orbits during G_1: those already near trouble move first
            self.park_orbits(self.n, top=self.n - 2, margin_um=self.tune.start_park_margin_um)
            self.pair.form()
            for k in range(self.n - 2, 0, -1):
                i = self.by_rank[k]
                route = next((p for p in phases if p.kind == "route" and p.mover == i), None)
                self.single.dock(k, route)
        except (_Abort, Replan) as exc:
            return exc.reason
        return None


def assemble(scenario, plant, *, seed: int | None = None, plan=None, time_budget_s: float | None = None,
             options: ControllerOptions | None = None) -> AssemblyResult:
    """Assemble ``scenario``'s structure through ``plant`` in closed loop (seed Appendix 3).

    Parameters
    ----------
    scenario:
        The scenario (robots, design, target structure, ``[control]`` settings).
    plant:
        Anything with ``observe()`` and ``apply(waveform)`` (:class:`stressbots.control.Plant`).
    seed:
        Recorded in the result (the controller itself is deterministic; the plant has its own seed).
    plan:
        A nominal :class:`stressbots.planning.PlanResult` to follow (computed when None; Monte Carlo
        runs share one).
    time_budget_s:
        Simulated time budget (overrides ``options``).
    """
    from dataclasses import replace

    from ..planning import PlanResult

    opts = options or ControllerOptions()
    if time_budget_s is not None:
        opts = replace(opts, time_budget_s=float(time_budget_s))
    no_plan = None
    if plan is None:
        try:
            plan = nominal_plan(scenario)
        except PlanningError as exc:
            # the controller needs the slots, not the nominal schedule: it re-plans everything from the
            # measured poses (G_1 as a rendezvous, single robots by routing); only the routes' hints are lost
            no_plan = str(exc)
            plan = structure_targets(scenario)
    if not isinstance(plan, (PlanResult, Targets)):
        raise TypeError("plan must be a PlanResult from stressbots.planning.plan_assembly")
    run = _Runner(scenario, plant, plan, opts, seed)
    if no_plan is not None:
        run.log("no-plan", None, f"the planner found no nominal plan ({no_plan}); the controller plans from the measured poses alone")
    failure = run.run()
    return judge_run(scenario, plant, seed=seed, failure=failure, estimates=run.est, goals=run.goals,
                     nominal_goals=run.nominal_goals, docked=run.docked, shape_tol_um=opts.shape_tol_um, duration_s=run.t,
                     replans=run.replans, events=run.events, trace_t=run.trace_t, trace_poses=run.trace_p)
