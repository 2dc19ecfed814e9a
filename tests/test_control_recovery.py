"""Closed-loop behaviour beyond the nominal plan: determinism, runs without a nominal plan, G_1 re-planning,
and a robot whose orbit drifts into another's way (protocol-only plants written here).

Independent truth is the simulator's: its true poses, its own docking record and its contact events.
"""

from __future__ import annotations

import numpy as np
import pytest

from stressbots.control import Targets, assemble, check_determinism, structure_targets
from stressbots.control import pair as pair_mod
from stressbots.control import runner as runner_mod
from stressbots.errors import PlanningError
from stressbots.generate import LITERATURE_NOISE, random_scenario
from stressbots.scenario import Noise
from stressbots.sim import SimulatedPlant

from .plants import ProtocolOnly


@pytest.fixture(scope="module")
def pair():
    return random_scenario(2, 5, shape="pair", noise=LITERATURE_NOISE)


def test_check_determinism_passes_for_a_seeded_run(pair):
    res = check_determinism(pair, 3, plan=structure_targets(pair))
    assert res.success, res.failure


class Unseeded(SimulatedPlant):
    """A plant whose camera draws from an unseeded generator: two runs cannot agree."""

    def observe(self):
        return super().observe() + np.random.default_rng().normal(0.0, 1e-3, (self.scenario.n, 3))


def test_check_determinism_catches_an_unseeded_plant(pair):
    with pytest.raises(AssertionError, match="differ"):
        check_determinism(pair, 3, plan=structure_targets(pair), plant_factory=Unseeded)


def test_assembles_without_a_nominal_plan(monkeypatch):
    """When the planner finds no plan, the controller runs on the structure's slots alone (issue 15)."""
    scn = random_scenario(3, 11, shape="tee", noise=Noise())

    def no_plan(*_a, **_k):
        raise PlanningError("no plan (test)")

    monkeypatch.setattr(runner_mod, "nominal_plan", no_plan)
    sim = SimulatedPlant(scn, seed=0)
    result = assemble(scn, ProtocolOnly(sim), seed=0)
    assert any(e["kind"] == "no-plan" for e in result.events)
    assert result.success, (result.failure, result.events[-5:])
    assert sim.docked.all()
    goals = structure_targets(scn).goals
    assert np.allclose(result.nominal_goals, goals)


def test_g1_is_replanned_in_another_frame_when_the_nominal_one_fails(pair, monkeypatch):
    """A rendezvous that finds no timed path does not end the run: sigma_1 is re-planned toward another
    pair frame (the structure turned or shifted), and the pair still forms."""
    calls = {"n": 0}
    original = pair_mod.Rendezvous.rendezvous

    def first_fails(self, N, M, D, lower):
        calls["n"] += 1
        if calls["n"] == 1:
            raise pair_mod.Replan(f"{self.loop.scn.names[N]} found no timed path to its approach line (injected)")
        return original(self, N, M, D, lower)

    monkeypatch.setattr(pair_mod.Rendezvous, "rendezvous", first_fails)
    scn = pair.with_noise(Noise())
    sim = SimulatedPlant(scn, seed=1)
    result = assemble(scn, ProtocolOnly(sim), seed=1, plan=structure_targets(scn))
    replans = [e for e in result.events if e["kind"] == "replan"]
    assert replans and "injected" in replans[0]["detail"]
    assert result.success, (result.failure, result.events[-5:])
    assert sim.docked.all()
    # success is judged on the shape: the pair may legitimately have formed in the new frame
    assert result.shape_error_rms_um <= 10.0


class Jam(ProtocolOnly):
    """Fault injection: the first time the G_1 pair's front edges come within ``near_um`` of each other,
    the plant swallows the commands of the next ``jam_s`` s (the pair stays where it is, as if jammed corner to
    corner outside the self-alignment limits: failure region H). Then it obeys again."""

    def __init__(self, inner, near_um: float, jam_s: float = 1.0):
        super().__init__(inner)
        self.near_um, self.left, self.jammed = near_um, jam_s, False

    def apply(self, waveform):
        from stressbots.robots import front_midpoints
        from stressbots.waveform import duration

        sim = self._inner
        if not self.jammed:
            ends = front_midpoints(sim.true_poses(), sim.scenario.lengths_um)
            self.jammed = bool(np.hypot(*(ends[0] - ends[1])) < self.near_um)
        if self.jammed and self.left > 0:  # a fault lasts a time: the controller cuts a t_x into several waveforms
            self.left -= duration(waveform)
            return
        super().apply(waveform)


def test_a_g1_pair_stopped_apart_turns_away_and_meets_again(pair):
    """A pair that stops short of each other (region H) is not the end of the run: both turn away (P_n),
    D_n approaches again, and the simulator itself records G_1 formed."""
    scn = pair.with_noise(Noise())
    sim = SimulatedPlant(scn, seed=1)
    plant = Jam(sim, near_um=300.0)
    result = assemble(scn, plant, seed=1, plan=structure_targets(scn))
    assert plant.jammed and plant.left <= 0
    apart = [e for e in result.events if e["kind"] == "stuck" and "approaches again" in e["detail"]]
    assert apart, result.events[-6:]
    assert result.success, (result.failure, result.events[-5:])
    assert any(e.kind == "self_align" for e in sim.events)
    assert sim.docked.all()


class Shove(ProtocolOnly):
    """Fault injection: once ``mover`` starts its own gross motion, the orbiting ``victim`` is displaced
    (as by an orbit drifting with accumulated error) so that its orbit disc covers the straight line from
    the mover to its slot. The controller must see the new orbit and keep clear of it."""

    def __init__(self, inner, mover: int, victim: int, goal, after_s: float):
        super().__init__(inner)
        self.mover, self.victim, self.goal, self.after_s = mover, victim, np.asarray(goal, float), after_s
        self.done = False

    def apply(self, waveform):
        sim = self._inner
        if not self.done and sim.time_s >= self.after_s:
            from stressbots.robots import orbit_radii, turning_centres

            p = sim.true_poses()
            L, W, R = sim.scenario.lengths_um, sim.scenario.widths_um, sim.scenario.turn_radii_um
            v = self.victim
            rs = float(orbit_radii(L[v], W[v], R[v]))
            a, b = p[self.mover, :2], self.goal[:2]
            centre = a + 0.5 * (b - a)  # the victim's new orbit centre: mid-way along the mover's line
            old = turning_centres(p[v], R[v])[0]
            sim._bodies.pose[v, :2] = p[v, :2] + (centre - old)
            if np.hypot(*(b - a)) > 2.0 * rs + L[self.mover]:
                self.done = True
            else:  # too close: undo and try again later
                sim._bodies.pose[v, :2] = p[v, :2]
        super().apply(waveform)


def test_keeps_clear_of_an_orbit_that_drifted_into_its_way():
    scn = random_scenario(4, 6, shape="tee", noise=Noise())
    plan = structure_targets(scn)
    # dry run: when does D_1 (the last robot) start to move, and where is its slot?
    from stressbots.electrostatics import analyse_scenario

    order = analyse_scenario(scn).order_index
    assert order is not None  # a STRING scenario has a docking order
    d1, d2 = int(order[0]), int(order[1])
    dry = assemble(scn, SimulatedPlant(scn, seed=0), seed=0, plan=plan)
    assert dry.success and not any(e["kind"] == "detour" for e in dry.events)
    t_g1 = next(e["t_s"] for e in dry.events if e["kind"] == "G_1")
    sim = SimulatedPlant(scn, seed=0)
    # D_2 docks after G_1 while D_1 orbits: shove D_1's orbit into D_2's way
    plant = Shove(sim, d2, d1, dry.goals[d2], after_s=t_g1 + 1.0)
    result = assemble(scn, plant, seed=0, plan=Targets(plan.goals))
    assert plant.done
    # contacts between the two other than the final docking of D_1 onto the structure
    hits = [e for e in sim.events if {e.robot, e.other} == {scn.names[d1], scn.names[d2]} and e.kind != "dock"]
    assert not hits, hits
    assert any(e["kind"] == "detour" and e["robot"] == scn.names[d2] for e in result.events)  # it went around
    assert result.success, (result.failure, result.events[-6:])


class SideShove(ProtocolOnly):
    """Fault injection: when ``robot`` is within ``near_um`` of its slot, its true pose is pushed ``shift_um``
    to its right (as by a drift burst the camera saw too late): it meets the face off its slot."""

    def __init__(self, inner, robot: int, goal, near_um: float, shift_um: float):
        super().__init__(inner)
        self.robot, self.goal, self.near_um, self.shift_um = robot, np.asarray(goal, float), near_um, shift_um
        self.done = False

    def apply(self, waveform):
        sim = self._inner
        p = sim.true_poses()[self.robot]
        if not self.done and np.hypot(*(p[:2] - self.goal[:2])) < self.near_um:
            sim._bodies.pose[self.robot, :2] += self.shift_um * np.array([np.cos(p[2]), -np.sin(p[2])])
            self.done = True
        super().apply(waveform)


def test_a_robot_stopped_flush_off_its_slot_is_docked_not_backed_off():
    """A robot that meets its slot's face 35 um to the side cannot leave it (front contact: it can neither
    turn off nor reverse). The controller records it as docked off its slot and goes on; before, it
    'backed off' against the face six times and the run failed."""
    scn = random_scenario(3, 11, shape="tee", noise=Noise())
    plan = structure_targets(scn)
    from stressbots.electrostatics import analyse_scenario

    order = analyse_scenario(scn).order_index
    assert order is not None
    d1 = int(order[0])
    dry = assemble(scn, SimulatedPlant(scn, seed=0), seed=0, plan=plan)
    assert dry.success
    sim = SimulatedPlant(scn, seed=0)
    # shoved 12 um short of the face: the next frame finds it touching (the controller reads frames 0.05 s apart)
    plant = SideShove(sim, d1, dry.goals[d1], near_um=12.0, shift_um=35.0)
    result = assemble(scn, plant, seed=0, plan=plan)
    assert plant.done
    assert sim.docked[d1]  # the simulator's own record: flush against the structure
    mine = [e for e in result.events if e["robot"] == scn.names[d1]]
    assert any(e["kind"] == "docked" and "off its slot" in e["detail"] for e in mine), mine[-4:]
    assert not any(e["kind"] == "stuck" for e in mine)
    assert result.docked.all() and (result.failure is None or result.failure.startswith("shape error"))


class ShoveOntoAim(ProtocolOnly):
    """Fault injection: once ``after_s`` has passed, the orbiting ``victim`` is displaced (as by an orbit drifting
    with accumulated error) so that its orbit disc sits on ``mover``'s approach line, ``behind_um`` behind its slot
    ``goal``: no route reaches the funnel while it waits there."""

    def __init__(self, inner, victim: int, goal, behind_um: float, after_s: float):
        super().__init__(inner)
        self.victim, self.goal, self.behind_um, self.after_s = victim, np.asarray(goal, float), behind_um, after_s
        self.done = False

    def apply(self, waveform):
        sim = self._inner
        if not self.done and sim.time_s >= self.after_s:
            from stressbots.robots import turning_centres

            p = sim.true_poses()
            R = sim.scenario.turn_radii_um
            v = self.victim
            h = np.array([np.sin(self.goal[2]), np.cos(self.goal[2])])
            centre = self.goal[:2] - self.behind_um * h
            sim._bodies.pose[v, :2] = p[v, :2] + (centre - turning_centres(p[v], R[v])[0])
            self.done = True
        super().apply(waveform)


def test_a_waiting_orbit_on_the_approach_line_is_moved_off_it():
    """D_1's orbit sits on D_2's approach line: there is no route to D_2's funnel around it, and before, every
    retry met the same orbit. The controller moves D_1's orbit off the way (it is not needed yet) and both dock."""
    from stressbots.electrostatics import analyse_scenario
    from stressbots.robots import orbit_radii

    scn = random_scenario(4, 6, shape="tee", noise=Noise())
    plan = structure_targets(scn)
    order = analyse_scenario(scn).order_index
    assert order is not None
    d1, d2 = int(order[0]), int(order[1])
    dry = assemble(scn, SimulatedPlant(scn, seed=0), seed=0, plan=plan)
    assert dry.success
    t_g1 = next(e["t_s"] for e in dry.events if e["kind"] == "G_1")
    rs = float(orbit_radii(scn.lengths_um[d1], scn.widths_um[d1], scn.turn_radii_um[d1]))
    sim = SimulatedPlant(scn, seed=0)
    plant = ShoveOntoAim(sim, d1, dry.goals[d2], rs + 0.5 * scn.lengths_um[d2] + 60.0, after_s=t_g1 - 5.0)
    result = assemble(scn, plant, seed=0, plan=Targets(plan.goals))
    assert plant.done
    moved = [e for e in result.events if e["kind"] == "unblock" and e["robot"] == scn.names[d1] and "moves" in e["detail"]]
    assert moved, [e for e in result.events if e["kind"] in ("unblock", "blocked", "retry")]
    hits = [e for e in sim.events if {e.robot, e.other} == {scn.names[d1], scn.names[d2]} and e.kind != "dock"]
    assert not hits, hits
    assert result.success, (result.failure, result.events[-6:])
    assert sim.docked.all()


class Stuck(ProtocolOnly):
    """Fault injection: while ``armed`` (set by the test when D_(n-1)'s straight transfer leg starts), robot
    ``robot`` does not move through the commands of ``hold_s`` s (as if pushed against a body: its pose is restored
    after each command). Then it obeys again."""

    def __init__(self, inner, robot: int, hold_s: float):
        super().__init__(inner)
        self.robot, self.left, self.armed, self.held = robot, hold_s, False, 0.0

    def apply(self, waveform):
        sim = self._inner
        if self.armed and self.left > 0:
            before, t0 = sim._bodies.pose[self.robot].copy(), sim.time_s
            super().apply(waveform)
            sim._bodies.pose[self.robot] = before
            self.left -= sim.time_s - t0
            self.held += sim.time_s - t0
            return
        super().apply(waveform)


def test_a_stalled_transfer_leg_stops_and_g1_goes_on(pair, monkeypatch):
    """D_(n-1) held still during its straight transfer leg (pushed against something) ends the leg within
    ``Tuning.leg_stall_frames`` frames (one leg ran 242 s before) and the transfer moves on from there; the pair
    still forms, as the simulator itself records."""
    from stressbots.control import transfer as transfer_mod

    scn = pair.with_noise(Noise())
    sim = SimulatedPlant(scn, seed=1)
    plant = Stuck(sim, robot=-1, hold_s=12.0)
    original = transfer_mod.StationTransfer.straight_leg

    def armed(self, N, M, c_next, lower):
        if plant.robot < 0:
            plant.robot, plant.armed = M, True
        return original(self, N, M, c_next, lower)

    monkeypatch.setattr(transfer_mod.StationTransfer, "straight_leg", armed)
    result = assemble(scn, plant, seed=1, plan=structure_targets(scn))
    assert plant.armed, "no straight transfer leg in this scenario"
    stalled = [e for e in result.events if e["kind"] == "transfer" and "stalled" in e["detail"]]
    assert stalled, result.events[:8]
    assert plant.held <= 13.0
    assert result.success, (result.failure, result.events[-5:])
    assert any(e.kind == "self_align" for e in sim.events)
