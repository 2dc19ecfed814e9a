"""One-way robots are never driven into a dead end (branch route7): pure queries on hand-built snapshots,
checked against independent truth (brute force, straight-line kinematics, replayed group moves).

- ``escapes.viable_prefix``: the longest clear beginning of a path whose end is not boxed in;
- ``queries.in_corridor``: a robot already on its approach line, heading along it, with a small lateral miss;
- ``parking.unblock_move``: the other waiting robots driven straight with the moved one do not end on the way;
- ``Escapes.boxed_in`` on a hand-built loop: a robot heading into a wall a few um ahead is boxed in, one
  driving along it is not.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots import paths as pathlib
from stressbots.control.escapes import viable_prefix
from stressbots.control.gross import GrossMotion, SteerOutcome
from stressbots.control.parking import unblock_move
from stressbots.control.queries import in_corridor, line_coords, line_pose
from stressbots.control.tuning import ControllerOptions, Tuning
from stressbots.kinematics import move
from stressbots.robots import Pose, orbit_radii, turning_centres

from .plants import replay_orbit_move

L, W, R, V = 250.0, 60.0, 200.0, 100.0
RSTAR = float(orbit_radii(L, W, R))


# -- viable_prefix ----------------------------------------------------------------------------------

@settings(max_examples=40, deadline=None)
@given(st.floats(50.0, 2000.0), st.floats(0.0, 2000.0), st.floats(5.0, 60.0))
def test_viable_prefix_is_the_last_free_end_found_stepping_back(length, wall_y, step):
    """A straight path north; ends beyond ``wall_y`` count as boxed in. The answer is the largest multiple-step
    end (stepping back from the clear length) below the wall, checked against a brute-force scan."""
    path = pathlib.Path(Pose(0.0, 0.0, 0.0), R, (("S", length),))
    calls = []

    def boxed(pose: np.ndarray) -> bool:
        calls.append(float(pose[1]))
        return bool(pose[1] > wall_y)

    got = viable_prefix(path, length, boxed, step_um=step, checks=10_000)
    ends = np.arange(length, 0.0, -step)
    free = [float(s) for s in ends if s <= wall_y]
    assert got == (free[0] if free else 0.0)
    assert all(c > wall_y for c in calls[:-1])  # it stops at the first free end


def test_viable_prefix_gives_up_after_its_check_budget():
    path = pathlib.Path(Pose(0.0, 0.0, 0.0), R, (("S", 1000.0),))
    assert viable_prefix(path, 1000.0, lambda pose: pose[1] > 100.0, step_um=25.0, checks=5) == 0.0
    assert viable_prefix(path, 1000.0, lambda pose: pose[1] > 100.0, step_um=25.0, checks=40) == 100.0


# -- in_corridor ------------------------------------------------------------------------------------

def lateral_miss(goal: np.ndarray, pose: np.ndarray) -> float:
    """Independent truth: drive ``pose`` straight (kinematics) until it reaches the slot's line across the
    approach (behind = 0); its right offset there (um)."""
    s = np.linspace(0.0, 3000.0, 30001)
    track = move(pose, s, 0.0)
    behind = np.array([line_coords(goal, p)[0] for p in track[::10]])
    k = int(np.argmax(behind <= 0.0)) * 10
    return line_coords(goal, track[k])[1]


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 2 * math.pi), st.floats(130.0, 650.0), st.floats(-60.0, 55.0), st.floats(-11.0, 11.0))
def test_in_corridor_matches_the_straight_line_miss(theta, behind, right, psi_deg):
    tune = Tuning()
    goal = np.array([1500.0, 1500.0, theta])
    pose = line_pose(goal, behind, right, math.radians(psi_deg))
    miss = lateral_miss(goal, pose)
    got = in_corridor(*line_coords(goal, pose), 450.0, tune)
    if abs(abs(miss) - tune.corridor_miss_um) > 0.5:  # away from the boundary (0.1 um steps of the replay)
        assert got == (abs(miss) <= tune.corridor_miss_um)


def test_in_corridor_rejects_robots_off_the_funnels_range_or_heading():
    tune = Tuning()
    goal = np.array([0.0, 0.0, 0.0])
    assert in_corridor(*line_coords(goal, line_pose(goal, 300.0, 10.0, -0.05)), 450.0, tune)
    assert not in_corridor(*line_coords(goal, line_pose(goal, 60.0, 0.0, 0.0)), 450.0, tune)  # too close to the slot
    assert not in_corridor(*line_coords(goal, line_pose(goal, 800.0, 0.0, 0.0)), 450.0, tune)  # beyond the funnel
    assert not in_corridor(*line_coords(goal, line_pose(goal, 300.0, 0.0, math.radians(20.0))), 450.0, tune)  # heading off
    assert not in_corridor(*line_coords(goal, line_pose(goal, 300.0, 80.0, math.radians(-12.0))), 450.0, tune)  # too far right


# -- unblock_move: the other movers stay off the way -----------------------------------------------

def test_unblock_move_keeps_the_other_waiting_movers_off_the_way():
    """D_j's orbit covers the aim; D_(j+1) waits beside the way and drives straight with it. Every move the
    query returns, replayed independently, leaves D_(j+1)'s disc off the way points (it started off them), and
    D_j's the margin clear."""
    rng = np.random.default_rng(7)
    pts = np.stack([np.linspace(1000.0, 1900.0, 37), np.full(37, 1500.0)], axis=1)
    reach = 0.5 * math.hypot(L, W) + 15.0
    found = 0
    for _ in range(25):
        th = rng.uniform(0.0, 2 * math.pi, 3)
        cj = np.array([1450.0, 1500.0 + rng.uniform(-100.0, 100.0)])
        cm = np.array([1450.0 + rng.uniform(-400.0, 400.0), 1500.0 - RSTAR - reach - rng.uniform(5.0, 80.0)])
        ck = np.array([600.0, 700.0])
        centres = np.array([cj, cm, ck])
        poses = np.column_stack([centres[:, 0] - R * np.cos(th), centres[:, 1] + R * np.sin(th), th])
        assert np.allclose(turning_centres(poses, np.full(3, R)), centres)
        mv = unblock_move(0, [0, 1, 2], [], poses, np.full(3, R), np.full(3, V / R), np.full(3, V), np.full(3, RSTAR), (3000.0, 3000.0),
                          np.zeros((0, 3)), [], [], pts, reach_um=reach, margin_um=30.0, max_shift_um=900.0, clearance_um=25.0)
        if mv is None:
            continue
        found += 1
        end = turning_centres(replay_orbit_move(poses, mv, [], V, R)[-1], np.full(3, R))
        d = np.hypot(*(pts[:, None, :] - end[None, :, :]).transpose(2, 0, 1)).min(axis=0)
        assert d[0] >= RSTAR + reach + 30.0 - 2.0  # D_j clear of the way (replay to ~1 um)
        assert d[1] >= RSTAR + reach - 2.0  # D_(j+1) not carried onto it
    assert found >= 5


# -- boxed_in on a hand-built loop ---------------------------------------------------------------------

def hand_loop(pose: np.ndarray, arena=(2000.0, 2000.0)):
    """The least of a closed loop Escapes.boxed_in reads: one robot, nothing docked, nobody orbiting."""
    return SimpleNamespace(
        est=np.array([pose], float), v_hat=np.array([V]), r_hat=np.array([R]), L=np.array([L]), W=np.array([W]),
        docked=np.zeros(1, bool), rstar=np.array([RSTAR]), scn=SimpleNamespace(arena_um=arena),
        opts=ControllerOptions(), tune=Tuning(),
    )


def test_a_robot_heading_into_the_arena_edge_a_few_um_ahead_is_boxed_in_one_along_it_is_not():
    # heading +y (north), its front 20 um from the top edge: it can neither turn (the front swings forward) nor go on
    into = np.array([1000.0, 2000.0 - 0.5 * L - 20.0, 0.0])
    esc = GrossMotion(hand_loop(into)).escapes
    assert esc.boxed_in(0, into, [])
    # the same distance from the edge, driving along it (heading west: the edge on its right) - straight on is free
    along = np.array([1000.0, 2000.0 - 0.5 * W - 20.0, 1.5 * math.pi])
    assert not esc.boxed_in(0, along, [])
    # in the open: free
    assert not esc.boxed_in(0, np.array([1000.0, 1000.0, 0.3]), [])


def test_a_g1_failure_names_a_d_n_boxed_in_against_the_arena_edge():
    """g1_failure.boxed_note: the failure message says D_n is pinned against the edge (tuning 116:0 gave up with only
    "found no timed path to its approach line"), and says nothing for a D_n that can still move on."""
    from stressbots.control.g1_failure import boxed_note

    into = np.array([1000.0, 2000.0 - 0.5 * L - 20.0, 0.0])
    for pose, boxed in ((into, True), (np.array([1000.0, 1000.0, 0.3]), False)):
        lp = hand_loop(pose)
        lp.gross = GrossMotion(lp)
        lp.scn.names = ("R5",)
        note = boxed_note(lp, 0)
        assert (note == "R5 is boxed in against the arena edge (no clockwise turn and straight of it keeps 5 um from it); ") == boxed
        assert boxed or note == ""


def test_g1_stops_re_planning_pair_frames_once_d_n_is_boxed_in():
    """PairPhase.form_round with D_n boxed in against the arena edge (``boxed_note`` non-empty) and a re-plan due: it
    tries no frame and returns the last reason (held-out 14:0 at 2x re-planned for 200 s of simulated time); with
    ``Tuning.give_up_boxed_in`` off, or D_n free, it goes on to re-plan (here: reaches the waiting orbits' park)."""
    from stressbots.control.pair import PairPhase

    class Parked(Exception):
        pass

    def park_orbits(*_a, **_k):
        raise Parked

    for give_up, note, stops in ((True, "R1 is boxed in ...; ", True), (False, "R1 is boxed in ...; ", False), (True, "", False)):
        lp = SimpleNamespace(tune=Tuning(give_up_boxed_in=give_up), park_orbits=park_orbits, n=3)
        phase = SimpleNamespace(loop=lp, boxed_note=lambda _n, note=note: note)
        if stops:
            assert PairPhase.form_round(phase, 1, 0, 300.0, [], "no track", 3) == (False, 0, "no track")  # type: ignore[arg-type]
        else:
            with pytest.raises(Parked):
                PairPhase.form_round(phase, 1, 0, 300.0, [], "no track", 3)  # type: ignore[arg-type]


class _Gave(Exception):
    pass


def _scripted_pair_phase(rounds_tried, moved: bool, boxed: str = ""):
    """A PairPhase stand-in whose rounds fail as scripted: ``rounds_tried`` frames per round, each failing with "R1 found
    no timed path to its approach line"; D_n moves between rounds when ``moved``; ``boxed`` is its boxed note."""
    tries = iter(rounds_tried)
    tune = Tuning()  # two rounds of pair frames (6, then 3)
    lp = SimpleNamespace(n=2, by_rank={1: 0, 2: 1}, tune=tune, scn=SimpleNamespace(names=("R0", "R1")),
                         orbiting_below=lambda _k: [], abort=_Gave, log=lambda *_a: None,
                         est=np.array([[0.0, 0.0, 0.0], [2000.0, 0.0, 0.0]]), docked=np.zeros(2, bool),
                         r_hat=np.array([R, R]), rstar=np.array([RSTAR, RSTAR]))
    return SimpleNamespace(
        loop=lp, meet_distance=lambda *_a: 300.0, room_frame=lambda *_a: (0.0, 0.0, 0.0),
        form_round=lambda *_a: (False, next(tries), "R1 found no timed path to its approach line"),
        between_rounds=lambda *_a: moved, meeting=SimpleNamespace(departure=SimpleNamespace(meet_as_they_are=lambda *_a: False)),
        boxed_note=lambda _n: boxed, body=lambda _i: (250.0, 60.0, 100.0, 200.0))


@pytest.mark.parametrize(("rounds_tried", "moved", "boxed", "starts"), [
    ((6, 3), True, "", "G_1 not formed: 2 rounds of pair frames (9 frames) failed, R1 waiting on a free orbit"),
    ((6,), False, "", "G_1 not formed: R1 could not move off where 6 pair frame(s) failed"),
    ((1,), False, "R1 is boxed in ...; ", "G_1 not formed: no re-plan frees R1 after 1 pair frame(s); R1 is boxed in"),
    ((4,), True, "", "G_1 not formed: no pair frame is left clear of the orbits as measured after 4 pair frame(s)"),
])
def test_a_g1_failure_gives_why_re_planning_stopped_not_a_stage_symptom(rounds_tried, moved, boxed, starts):
    """PairPhase.form's failure says first why re-planning G_1 stopped (every round failed, D_n could not move, D_n
    boxed in, no frame left), and the last frame's symptom only after it (issue 12, goal 1: never a failure of the
    kind "no timed path"; tuning 93:0 ended with "last: R3 found no timed path to its approach line")."""
    from stressbots.control.pair import PairPhase

    with pytest.raises(_Gave) as gave:
        PairPhase.form(_scripted_pair_phase(rounds_tried, moved, boxed))
    message = str(gave.value)
    assert message.startswith(starts), message
    assert message.endswith("; the last frame failed because R1 found no timed path to its approach line")
    assert message.index("no timed path") > message.index(";")


def test_a_g1_failure_names_the_orbit_d_n_is_hemmed_in_by():
    """g1_failure.overlap_note names the undocked robot whose orbit disc reaches deepest into D_n's and by how much
    (independent truth: both heading north, so both turning centres lie R east of the robots and are as far apart as
    the robots); nothing when no disc overlaps, and a docked robot's orbit does not count."""
    from stressbots.control.g1_failure import overlap_note

    d_n = np.array([1000.0, 1000.0, 0.0])
    near = d_n + np.array([1.5 * RSTAR, 0.0, 0.0])  # discs 0.5 r* into each other
    far = d_n + np.array([0.0, 2.5 * RSTAR, 0.0])  # 0.5 r* apart
    lp = SimpleNamespace(est=np.array([d_n, near, far]), r_hat=np.array([R, R, R]), rstar=np.array([RSTAR] * 3),
                         docked=np.zeros(3, bool), n=3, scn=SimpleNamespace(names=("R4", "R3", "R0")))
    note = overlap_note(lp, 0)
    assert note == f"R4's orbit lies {0.5 * RSTAR:.0f} um into R3's as measured; "
    lp.docked[1] = True
    assert overlap_note(lp, 0) == ""


# -- back_off: a free robot is never driven blindly --------------------------------------------------

class BackOffLoop:
    """A closed loop for SingleDocking.back_off that records what it drives; ``escape``/``free_move`` as told."""

    def __init__(self, escapes: bool, free: tuple[float, float] | None):
        self.escapes, self.free = escapes, free
        self.driven: list = []
        self.logged: list = []
        self.r, self.v = np.array([R, R]), np.array([V, V])
        self.scn = SimpleNamespace(names=("A", "B"))

    def orbiting_below(self, k):
        return [0] if k > 1 else []

    def escape(self, i, turn_k, straight_k, orbiting):
        return self.escapes

    def free_move(self, i, orbiting):
        return self.free

    def drive(self, steps):
        self.driven.append(list(steps))

    def drive_move(self, i, turn_k, straight_k, move_, orbiting):
        self.drive([(k, d) for k, d in ((turn_k, move_[0]), (straight_k, move_[1])) if d > 0.0])

    def log(self, kind, robot=None, detail=""):
        self.logged.append(kind)


def test_back_off_never_drives_a_robot_that_can_still_move_on_blindly():
    from stressbots.control.single import SingleDocking

    free = BackOffLoop(escapes=False, free=(0.7, 2.5))  # no escape ends clear: the checked move on, P_2 then P_1
    SingleDocking(free).back_off(1, 2)  # type: ignore[arg-type]
    assert free.driven == [[(2, 0.7), (1, 2.5)]] and free.logged == ["move-on"]
    straight = BackOffLoop(escapes=False, free=(0.0, 2.5))  # a move on straight ahead: no zero-length turn step
    SingleDocking(straight).back_off(1, 2)  # type: ignore[arg-type]
    assert straight.driven == [[(1, 2.5)]]
    boxed = BackOffLoop(escapes=False, free=None)  # boxed in already: the quarter turn and 150 um, as before
    SingleDocking(boxed).back_off(1, 2)  # type: ignore[arg-type]
    assert boxed.driven == [[(2, 0.5 * math.pi * R / V), (1, 150.0 / V)]]
    escaped = BackOffLoop(escapes=True, free=None)  # the checked escape drove it (through the loop): nothing more
    SingleDocking(escaped).back_off(1, 2)  # type: ignore[arg-type]
    assert escaped.driven == []


# -- a blocked gross motion that ends at the robot's own slot -----------------------------------------------


def test_a_robot_whose_blocked_gross_motion_stopped_it_at_its_slot_docks_there():
    """The gross motion is made to end each attempt driven straight in along the approach line and report itself
    stuck (as a blocked gross motion whose clear part ran into the slot does): the robot is pushed and judged
    where it stopped, and the simulator records it docked, instead of being backed off attempt after attempt."""
    from stressbots.control import structure_targets
    from stressbots.control.runner import _Runner
    from stressbots.control.tuning import ControllerOptions
    from stressbots.generate import random_scenario
    from stressbots.scenario import Noise
    from stressbots.sim import SimulatedPlant

    scn = random_scenario(3, 0, shape="tee", noise=Noise())
    sim = SimulatedPlant(scn, seed=0)
    run = _Runner(scn, sim, structure_targets(scn), ControllerOptions(), 0)
    run.pair.form()
    i = run.by_rank[1]
    real = run.gross.steer

    def steer_then_stop_in_the_slot(j, target, *args, **kwargs):
        real(j, target, *args, **kwargs)
        g = run.goals[j]
        behind = float((g[:2] - run.est[j, :2]) @ np.array([math.sin(g[2]), math.cos(g[2])]))
        run.drive([(0, max(behind - 3.0, 0.0) / float(run.v_hat[j]))])
        return SteerOutcome.STUCK

    run.steer = steer_then_stop_in_the_slot  # type: ignore[method-assign, assignment]
    run.single.dock(1, None)
    assert sim.docked[i] and run.docked[i]
    assert sum(e["kind"] == "docked" for e in run.events) == 1


def test_a_robot_whose_line_approach_missed_and_cannot_loop_back_is_backed_off_not_sent_down_the_line_again():
    """Policy of SingleDocking.dock with its moves scripted: the gross motion can never leave (stuck at once), the robot
    sits in its approach corridor and every line approach from there misses. The corridor shortcut is not taken again
    from where a line approach just missed (it ran six attempts out at the same instant): the robot is backed off."""
    import pytest

    from stressbots.control import structure_targets
    from stressbots.control.docking import DockOutcome
    from stressbots.control.gross import SteerOutcome
    from stressbots.control.runner import _Runner
    from stressbots.control.tuning import ControllerOptions
    from stressbots.generate import random_scenario
    from stressbots.scenario import Noise
    from stressbots.sim import SimulatedPlant

    scn = random_scenario(3, 0, shape="tee", noise=Noise())
    run = _Runner(scn, SimulatedPlant(scn, seed=0), structure_targets(scn), ControllerOptions(), 0)
    single = run.single
    calls = {"line": 0, "back_off": 0}

    def line_approach(i, k, attempt=0):
        calls["line"] += 1
        return DockOutcome.MISSED

    def back_off(i, k):
        calls["back_off"] += 1
        run.drive([(k, 1.0)])  # time passes: the robot is somewhere new

    def stuck_at_once(*_args, **_kwargs):
        return SteerOutcome.STUCK

    def always(value):
        return lambda *_args: value

    def clear_the_way(i, k, *_args):
        back_off(i, k)

    for obj, name, fake in ((run, "steer", stuck_at_once), (single.approach, "in_corridor", always(True)),
                            (single.approach, "in_funnel", always(False)), (single.approach, "approach_length", always(300.0)),
                            (single, "line_approach", line_approach),
                            (single, "back_off", back_off), (single, "_clear_the_way", clear_the_way)):
        setattr(obj, name, fake)
    with pytest.raises(Exception, match="did not dock"):
        single.dock(1, None)
    assert calls["back_off"] >= 2 and calls["line"] <= run.tune.dock_attempts - 2


def _scripted_single(in_funnel: bool, outcome):
    """A 3-robot run whose D_1 docking is scripted: the gross motion (``_steer_through``) records the funnel test it is
    handed and returns at once, not stuck, with no time passing; the robot is (or is not) in its funnel, never in its
    corridor; line approaches end in ``outcome`` with no time passing; backing off lets 1 s pass."""
    from stressbots.control import structure_targets
    from stressbots.control.runner import _Runner
    from stressbots.control.tuning import ControllerOptions
    from stressbots.generate import random_scenario
    from stressbots.scenario import Noise
    from stressbots.sim import SimulatedPlant

    scn = random_scenario(3, 0, shape="tee", noise=Noise())
    run = _Runner(scn, SimulatedPlant(scn, seed=0), structure_targets(scn), ControllerOptions(), 0)
    single = run.single
    seen: dict = {"ready": [], "back_off": 0, "line": 0}

    def steer_through(i, k, orbiting, targets, ready, cut_in, aim_region=None):
        seen["ready"].append(ready)
        return False

    def line_approach(i, k, attempt=0):
        seen["line"] += 1
        return outcome

    def back_off(i, k):
        seen["back_off"] += 1
        run.t += 1.0

    for obj, name, fake in ((single, "_steer_through", steer_through), (single.approach, "in_funnel", lambda *_a: in_funnel),
                            (single.approach, "in_corridor", lambda *_a: False), (single.approach, "approach_length", lambda *_a: 300.0),
                            (single, "line_approach", line_approach), (single, "back_off", back_off)):
        setattr(obj, name, fake)
    return run, single, seen


def test_after_a_line_approach_that_missed_in_place_the_gross_motion_drives_until_the_approach_takes_it():
    """The line approach predicted its miss and drove nothing: the next attempt's gross motion is not handed the funnel
    test (which would end it at once, in the same pose, for the same miss: six attempts at one instant), nor may it end
    by arriving in its aim's region (as coarse); it ends where the line approach's own first frame would take the robot
    (:meth:`SingleDocking.accepts`)."""
    import pytest

    from stressbots.control.docking import DockOutcome

    run, single, seen = _scripted_single(True, DockOutcome.MISSED)
    with pytest.raises(Exception, match="did not dock"):
        single.dock(1, None)
    assert seen["ready"][0] is not None and getattr(seen["ready"][0], "func", None) is None  # the first: the funnel test
    # after each in-place miss: the approach's acceptance, with the miss count so far
    i = run.by_rank[1]
    assert [(r.func, r.args) for r in seen["ready"][1:]] == [(single.accepts, (i, 1, m)) for m in range(1, run.tune.dock_attempts)]
    assert len(seen["ready"]) == run.tune.dock_attempts


def test_an_attempt_that_moved_nothing_and_ended_outside_the_funnel_backs_off_before_the_next():
    """The gross motion returned at once (at its aim already) outside the funnel: the same attempt from the same pose
    would again; the robot backs off (time passes, it is somewhere new) before the next one."""
    import pytest

    from stressbots.control.docking import DockOutcome

    run, single, seen = _scripted_single(False, DockOutcome.MISSED)
    with pytest.raises(Exception, match="did not dock"):
        single.dock(1, None)
    assert seen["line"] == 0 and seen["back_off"] == run.tune.dock_attempts
