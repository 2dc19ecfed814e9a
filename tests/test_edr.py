"""The closed-loop EDR controller (issue 6): assembly under control error through the Plant protocol.

Independent truth here is the plant's: the simulator's true poses and its own record of who docked (the
controller never sees either), and the shape error recomputed from the true poses.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from stressbots.assessment import shape_error
from stressbots.control import Plant, assemble, nominal_plan
from stressbots.scenario import Noise, load
from stressbots.sim import SimulatedPlant

from .conftest import EXAMPLES
from .plants import ProtocolOnly


@pytest.fixture(scope="module")
def example():
    scn = load(EXAMPLES / "four-robots.toml")
    return scn, nominal_plan(scn)


def _check_truth(scn, plan, sim, result):
    truth = sim.true_poses()
    independent = shape_error(truth, plan.plan.goal_array(), scn.lengths_um, scn.widths_um).rms_um
    assert sim.docked.all(), sim.events[-5:]
    assert independent <= 10.0
    return independent


def test_closed_loop_without_noise_assembles_through_the_protocol(example):
    scn, _ = example
    scn = scn.with_noise(Noise())
    plan = nominal_plan(scn)
    sim = SimulatedPlant(scn, seed=0)
    result = assemble(scn, ProtocolOnly(sim), seed=0, plan=plan)
    assert isinstance(ProtocolOnly(sim), Plant)
    assert result.success, (result.failure, result.events)
    assert result.final_true is None  # the controller saw only the protocol
    truth = sim.true_poses()
    assert np.allclose(result.final_observed, truth, atol=1e-6)  # noiseless camera: estimate = truth
    independent = _check_truth(scn, plan, sim, result)
    # D docks 2.4 um off its slot (the noiseless loop's own placement), and B's slot at the end of D's face follows the
    # face so that both of B's front corners land on it (control.landing): 1.4 um RMS, was 0.9 before B followed it
    assert independent < 2.0 and abs(independent - result.shape_error_rms_um) < 1e-9
    d = result.to_dict()
    assert {"success", "seed", "robots"} <= set(d) and all({"name", "final", "goal", "docked"} <= set(r) for r in d["robots"])


def test_closed_loop_at_literature_noise_assembles_the_example(example):
    """Speed sd 5 %, radius sd 3 %, drift 3.7 deg/mm, camera 2 um / 1 deg, 2 % dropouts, t_x = 1 s.

    Since the simulator's heading drift is a persistent per-robot process (a bias per run plus a random
    walk, issue 11) the example assembles in about 85-90 % of plant seeds (of seeds 0-19: 18 with the
    controller before issue 12's changes, 17 after), so a per-seed assertion would test luck: at least 5
    of seeds 0-5 must assemble, each checked against the plant's truth.
    """
    scn, plan = example
    ok = 0
    for seed in range(6):
        sim = SimulatedPlant(scn, seed=seed)
        result = assemble(scn, ProtocolOnly(sim), seed=seed, plan=plan)
        if not result.success:
            continue
        ok += 1
        independent = _check_truth(scn, plan, sim, result)
        # the controller's own figure comes from its estimates; it agrees with the truth to camera accuracy
        assert abs(independent - result.shape_error_rms_um) < 3.0
        kinds = {e["kind"] for e in result.events}
        assert {"transfer", "depart", "G_1", "docked"} <= kinds
    assert ok >= 5, ok


def test_same_seed_same_run(example):
    scn, plan = example
    a = assemble(scn, SimulatedPlant(scn, seed=7), seed=7, plan=plan)
    b = assemble(scn, SimulatedPlant(scn, seed=7), seed=7, plan=plan)
    assert a.final_true is not None and b.final_true is not None  # the simulator knows the truth
    assert a.events == b.events and np.array_equal(a.final_true, b.final_true)


class Jammed(ProtocolOnly):
    """A plant written here, protocol only, with a sticky patch: one robot is held in place (as if stuck
    in the failure region H) through the waveforms it is sent during ``jam_s`` s from ``after_s`` on, while it
    steers toward its slot (the controller cuts a t_x into several waveforms: a fault lasts a time, not a count)."""

    def __init__(self, inner, robot: int, after_s: float, jam_s: float):
        super().__init__(inner)
        self.robot, self.after_s, self.jam_s = robot, after_s, jam_s
        self.jammed_s = 0.0

    def apply(self, waveform):
        before = self._inner.true_poses()[self.robot].copy()
        t0 = self._inner.time_s
        self._inner.apply(waveform)
        if t0 >= self.after_s and self.jammed_s < self.jam_s:
            self._inner._bodies.pose[self.robot] = before  # fault injection: the robot did not move
            self.jammed_s += self._inner.time_s - t0


def test_recovers_from_a_stuck_robot(example):
    scn, plan = example
    scn = scn.with_noise(Noise())
    sim = SimulatedPlant(scn, seed=0)
    d = scn.names.index("D")  # D_2: steers to its slot after G_1 forms (about 45 s)
    plant = Jammed(sim, d, after_s=50.0, jam_s=4.0)
    result = assemble(scn, plant, seed=0, plan=plan)
    assert 4.0 <= plant.jammed_s < 6.0
    stuck = [e for e in result.events if e["kind"] == "stuck" and e["robot"] == "D"]
    assert stuck, result.events
    assert result.success, (result.failure, result.events[-6:])
    _check_truth(scn, plan, sim, result)


class Blindfolded(ProtocolOnly):
    """The camera loses one robot for ``frames`` frames from ``after_s`` on (NaN rows)."""

    def __init__(self, inner, robot: int, after_s: float, frames: int):
        super().__init__(inner)
        self.robot, self.after_s, self.frames = robot, after_s, frames
        self.hidden = 0

    def observe(self):
        obs = self._inner.observe()
        if self._inner.time_s >= self.after_s and self.hidden < self.frames:
            obs[self.robot] = np.nan
            self.hidden += 1
        return obs


def test_recovers_from_dropouts(example):
    """20 % dropouts and one robot hidden for 5 frames: the controller dead-reckons and goes on. Success
    is statistical on the drifting simulator (see the test above): at least 2 of 3 plant seeds."""
    scn, plan = example
    heavy = scn.with_noise(replace(scn.noise, camera_dropout=0.2))
    c = scn.names.index("C")
    ok = 0
    for seed in (3, 4, 5):
        sim = SimulatedPlant(heavy, seed=seed)
        plant = Blindfolded(sim, c, after_s=20.0, frames=5)
        result = assemble(heavy, plant, seed=seed, plan=plan)
        assert plant.hidden == 5
        assert any(e["kind"] == "lost" for e in result.events)
        if result.success:
            ok += 1
            _check_truth(heavy, plan, sim, result)
    assert ok >= 2, ok


class DriftingCamera(ProtocolOnly):
    """Reports one orbiting robot's pose sliding toward the arena's bottom edge for a while (as an orbit
    drifting with accumulated heading error would), then the truth again."""

    def __init__(self, inner, robot: int, start_s: float, stop_s: float, um_per_frame: float):
        super().__init__(inner)
        self.robot, self.start_s, self.stop_s, self.rate = robot, start_s, stop_s, um_per_frame
        self.frames = 0

    def observe(self):
        obs = self._inner.observe()
        t = self._inner.time_s
        if self.start_s <= t < self.stop_s:
            self.frames += 1
            obs[self.robot, 1] -= self.rate * self.frames
        return obs


def test_detects_an_orbit_drifting_toward_a_collision(example):
    scn, plan = example
    scn = scn.with_noise(Noise())
    b = scn.names.index("B")  # D_1: orbits about (800, 600) until it docks last; its disc is 336 um above the edge
    plant = DriftingCamera(SimulatedPlant(scn, seed=0), b, start_s=10.0, stop_s=60.0, um_per_frame=8.0)
    result = assemble(scn, plant, seed=0, plan=plan)
    # detected: logged by the orbit watch, or (during another robot's gross motion, runner.tend_orbits) acted
    # on at once, the orbit moved away from the edge before the watch's 10 um
    drift = [e for e in result.events if e["robot"] == "B" and (e["kind"] == "park" or (e["kind"] == "orbit-drift"
                                                                                     and "arena edge" in e["detail"]))]
    assert drift, [e for e in result.events if e["kind"] in ("orbit-drift", "park")]
    assert drift[0]["t_s"] >= 10.0
