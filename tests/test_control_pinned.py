"""A robot near its slot or the arena edge is not driven into a pin (session 15): pure queries and hand-built loops,
checked against kinematics and closed-form geometry.

- ``escapes.move_stops``: the t_x stops of a turn-then-straight move;
- ``Escapes.drive_move``: an open-loop move is checked again from each measured pose and stops before the rest
  of it meets the arena edge;
- ``Escapes.free_move``: a move on whose first t_x would already box the robot in is not taken;
- ``SlotApproach.can_arc_in`` / ``cut_in``: without an approach line, a robot short of a_i starts its S_2f arc from
  there only where a loop is blocked and the arc keeps off the structure;
- ``Rendezvous._drive_rest_open_loop``: D_n's open-loop final seconds only where they keep off the arena edge.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.collision import arena_gap, penetration_depth
from stressbots.control.escapes import escape_sweep, move_stops
from stressbots.control.gross import GrossMotion
from stressbots.control.queries import in_funnel, line_coords, line_pose
from stressbots.control.slot_approach import SlotApproach
from stressbots.control.tuning import ControllerOptions, Tuning
from stressbots.kinematics import move
from stressbots.robots import orbit_radii

L, W, R, V, TX = 250.0, 60.0, 200.0, 100.0, 1.0
RSTAR = float(orbit_radii(L, W, R))


# -- move_stops -------------------------------------------------------------------------------------

@settings(max_examples=60, deadline=None)
@given(st.floats(0.0, 5.0), st.floats(0.0, 5.0), st.floats(0.2, 2.0))
def test_move_stops_are_tx_apart_and_end_with_the_whole_move(turn_s, straight_s, tx):
    stops = move_stops((turn_s, straight_s), tx)
    totals = [a + b for a, b in stops]
    assert stops[-1] == (turn_s, straight_s) or np.allclose(stops[-1], (turn_s, straight_s))
    assert all(0.0 < b - a <= tx + 1e-9 for a, b in zip([0.0, *totals[:-1]], totals, strict=True)) or turn_s + straight_s == 0.0
    # the turn comes first: no straight before the whole turn is driven
    assert all(b == 0.0 or a == turn_s for a, b in stops)


# -- drive_move and free_move on a hand-built loop ----------------------------------------------------

class DriftLoop:
    """One robot alone in a ``size`` um arena, driven by exact kinematics; after the first drive its heading is turned
    by ``kick`` rad (what an unmodelled drift or a heading error does to an open-loop move)."""

    def __init__(self, pose, kick: float = 0.0, size: float = 2000.0):
        self.est = np.array([pose], float)
        self.v_hat, self.r_hat, self.L, self.W = np.array([V]), np.array([R]), np.array([L]), np.array([W])
        self.docked, self.rstar = np.zeros(1, bool), np.array([RSTAR])
        self.scn = SimpleNamespace(arena_um=(size, size), names=("R0",))
        self.opts, self.tune, self.tx = ControllerOptions(), Tuning(), TX
        self.kick = kick
        self.n = 1
        self.driven: list[list] = []
        self.logged: list[str] = []

    def drive(self, steps):
        for k, d in steps:
            self.est[0] = move(self.est[0], V * d, 1.0 / R if k == 1 else 0.0)
        if not self.driven:
            self.est[0, 2] += self.kick
        self.driven.append(list(steps))

    def log(self, kind, robot=None, detail=""):
        self.logged.append(kind)


def test_an_open_loop_move_stops_before_its_rest_meets_the_arena_edge():
    # heading east, 900 um from the east edge: a 6 s straight (600 um) is clear as planned
    start = np.array([1000.0, 1000.0, 0.5 * math.pi])
    calm = DriftLoop(start)
    GrossMotion(calm).escapes.drive_move(0, 1, 0, (0.0, 6.0), [])  # type: ignore[arg-type]
    assert sum(d for steps in calm.driven for _, d in steps) == 6.0 and "move-cut" not in calm.logged
    assert all(sum(d for _, d in steps) <= TX + 1e-12 for steps in calm.driven)
    # the same move near the edge, its heading kicked 60 deg toward the north edge after the first t_x: the rest
    # would run into that edge, so it stops there
    near = DriftLoop(np.array([1000.0, 1500.0, 0.5 * math.pi]), kick=-math.radians(60.0))
    GrossMotion(near).escapes.drive_move(0, 1, 0, (0.0, 6.0), [])  # type: ignore[arg-type]
    rest = escape_sweep(near.est[0], (0.0, 5.0), V, R)
    assert near.logged == ["move-cut"] and len(near.driven) == 1
    assert (rest[:, 1] + 0.5 * L > 2000.0).any()  # what it did not drive would have left the arena


def test_a_move_on_whose_first_stop_boxes_the_robot_in_is_not_taken():
    # a notch opening south (two docked bodies in a V, apex at (1000, 1300)); the robot below it, heading east
    a = math.radians(55.94)
    notch = [np.array([1000.0 - 0.5 * L * math.sin(a), 1300.0 - 0.5 * L * math.cos(a), a]),
             np.array([1000.0 + 0.5 * L * math.sin(a), 1300.0 - 0.5 * L * math.cos(a), 2.0 * math.pi - a])]
    pose = np.array([769.697, 1082.495, 1.461])
    lp = DriftLoop(pose)
    lp.est = np.array([pose, *notch])
    lp.v_hat, lp.r_hat, lp.L, lp.W = np.full(3, V), np.full(3, R), np.full(3, L), np.full(3, W)
    lp.docked, lp.rstar = np.array([False, True, True]), np.full(3, RSTAR)
    esc = GrossMotion(lp).escapes  # type: ignore[arg-type]

    def boxed_after(m):
        return esc.boxed_in(0, escape_sweep(pose, m, V, R)[-1], [])

    # the cheapest move on that ends free (straight ahead, one body length) leaves it boxed in at its first t_x stop
    cheapest = next(m for m in esc.free_moves(0, pose, []) if not boxed_after(m))
    assert cheapest == (0.0, L / V) and any(boxed_after(s) for s in move_stops(cheapest, TX)[:-1])
    m = esc.free_move(0, [])
    assert m is not None and m != cheapest and not boxed_after(m)
    assert not any(boxed_after(s) for s in move_stops(m, TX)[:-1])


# -- arcs in where a loop is blocked ---------------------------------------------------------------------

def docking_loop(pose, goal, blocked: bool, bodies=(), kappa: float = 0.0):
    """The least of a closed loop SlotApproach.cut_in / can_arc_in read; ``loop_blocked`` as told; every robot's identified
    straight-line drift ``kappa`` (rad/um)."""
    est = np.array([pose, *[b[0] for b in bodies]], float)
    n = len(est)
    lp = SimpleNamespace(
        est=est, goals=np.array([goal] * n, float), r_hat=np.full(n, R), L=np.full(n, L), W=np.full(n, W),
        docked=np.array([False] + [True] * (n - 1)), opts=ControllerOptions(), tune=Tuning(), rstar=np.full(n, RSTAR),
        scn=SimpleNamespace(arena_um=(2000.0, 2000.0)), orbiting_below=lambda _k: [],
        straight_drift=SimpleNamespace(kappa=np.full(n, kappa)),
    )
    lp.obstacles_hit = GrossMotion(lp).obstacles_hit
    sa = SlotApproach(lp)
    sa.loop_blocked = lambda *_: blocked  # type: ignore[method-assign]
    return sa


def test_a_robot_short_of_a_i_arcs_in_from_there_only_where_a_loop_is_blocked_and_the_arc_is_clear():
    goal = np.array([1000.0, 1000.0, 0.0])
    # on a clockwise arc of radius 2 r that ends in the slot: one interpolated arc takes it in
    pose = move(goal, -300.0, 1.0 / (2.0 * R))
    assert docking_loop(pose, goal, blocked=True).can_arc_in(0, 2)
    assert not docking_loop(pose, goal, blocked=False).can_arc_in(0, 2)
    sa = docking_loop(pose, goal, blocked=True)
    sa.loop.scn.names = ("R0", "R1")
    event, reason = sa.cut_in(0, 2, None) or ("", "")
    assert event == "cut-in" and "arcs into its slot" in reason
    assert sa.cut_in(0, 2, 450.0) is None  # a robot with an approach line merges from its funnel only
    # pointing away from the slot: no clockwise arc reaches it
    assert not docking_loop(np.array([pose[0], pose[1], pose[2] + math.pi]), goal, blocked=True).can_arc_in(0, 2)
    # a docked body across the arc's middle: not from here
    mid = move(goal, -150.0, 1.0 / (2.0 * R))
    assert not docking_loop(pose, goal, blocked=True, bodies=[(mid,)]).can_arc_in(0, 2)


# -- G_1: D_n's open-loop final seconds ---------------------------------------------------------------

def test_d_n_drives_the_rest_of_its_timed_plan_open_loop_only_where_it_keeps_off_the_arena_edge():
    from stressbots import paths as pathlib
    from stressbots.control.rendezvous import Rendezvous

    def attempt(gap_um: float):
        # D_n heading north, its front gap_um from the north edge; its last plan: 100 um driven, 150 um straight left
        pose = np.array([1000.0, 2000.0 - 0.5 * L - gap_um, 0.0])
        lp = DriftLoop(pose)
        lp.obstacles_hit = GrossMotion(lp).obstacles_hit  # type: ignore[attr-defined,arg-type]
        prev = pathlib.Path(pose - np.array([0.0, 100.0, 0.0]), R, (("S", 250.0),))
        done = Rendezvous(SimpleNamespace(loop=lp))._drive_rest_open_loop(0, prev, V, [], [])  # type: ignore[arg-type]
        return done, lp

    done, lp = attempt(200.0)  # 150 um on: 50 um short of the edge
    assert done and lp.driven == [[(0, 1.5)]] and np.isclose(lp.est[0, 1], 2000.0 - 0.5 * L - 50.0)
    done, lp = attempt(100.0)  # 150 um on would run 50 um into the edge: nothing driven, the caller plans again
    assert not done and lp.driven == [] and lp.logged == ["final"]


def test_an_arc_whose_compliant_aim_lies_far_along_the_face_is_not_an_arc_in():
    goal = np.array([1000.0, 1000.0, 0.0])
    # an arc of radius 2 r through the slot's centre, arriving 35 deg counter-clockwise of the slot's heading: compliance
    # would turn it flush, so the arc must aim ~(L/2) sin 35 deg = 72 um along the face
    off = np.array([goal[0], goal[1], -math.radians(35.0)])
    pose = move(off, -300.0, 1.0 / (2.0 * R))
    sa = docking_loop(pose, goal, blocked=True)
    assert not sa.can_arc_in(0, 2)
    sa.loop.tune = Tuning(arc_in_aim_um=1000.0)  # the same arc, the aim allowed anywhere: taken
    assert sa.can_arc_in(0, 2)


# -- where the gross motion aims in the approach funnel ---------------------------------------------------

def test_the_funnel_aim_moves_back_from_the_corridors_end_only_as_far_as_a_loop_through_it_needs():
    """A docked body across the approach line, at 36 places from 300 um behind the slot to 400 um ahead of it (a stand-in
    for the structure ahead of the aim): the aim is the nearest of (corridor's end,
    + half of ``aim_behind_extra_um``, + all of it) whose clockwise loop (the only way back to it for a one-way robot
    that arrived off it) keeps the clearance from the body and the arena edge, recomputed here from the swept bodies;
    the corridor's end when none does. Every aim is in the approach funnel."""
    back, tune, clearance = 450.0, Tuning(), ControllerOptions().clearance_um
    extra = tune.aim_behind_extra_um
    goal = np.array([1000.0, 1200.0, 0.0])  # slot heading +y: its approach line runs back toward -y
    seen = set()
    for ahead in np.linspace(-300.0, 400.0, 36):
        body = np.array([1000.0, goal[1] + ahead, 0.5 * math.pi])  # across the line
        sa = docking_loop(np.array([1000.0, 1900.0, 0.0]), goal, blocked=False, bodies=[(body,)])
        b, right, psi = line_coords(goal, sa._aim_behind(0, goal, back, []))
        assert abs(right - 20.0) < 1e-6 and abs(psi + math.radians(6.0)) < 1e-9
        assert in_funnel(b, right, psi, back, R, tune)

        def loop_clear(bb: float, body=body) -> bool:
            # the gross motion's rule: the docked clearance applies beyond a body length from the aim
            pose = line_pose(goal, bb, 20.0, -math.radians(6.0))
            swept = move(pose, np.linspace(0.0, 2.0 * math.pi * R, 400), 1.0 / R)
            need = np.where(np.hypot(*(swept[:, :2] - pose[:2]).T) > L, max(clearance, tune.gross_docked_clearance_um), clearance)
            return bool((penetration_depth(swept, L, W, body[None], L, W) <= -need).all()
                        and arena_gap(swept, L, W, (2000.0, 2000.0)).min() >= clearance)

        expected = next((bb for bb in (back, back + 0.5 * extra, back + extra) if loop_clear(bb)), back)
        assert abs(b - expected) < 1e-6
        seen.add(round(b - back))
    assert seen == {0, round(0.5 * extra), round(extra)}  # the sweep reaches all three
