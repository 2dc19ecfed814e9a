"""benchmarks/inspect_trial.py: the shape error split by robot against the shape metric itself (SPEC 6), and a
replayed benchmark trial's events against the benchmark's own run."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.assessment import shape_error

_BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(_BENCHMARKS))  # inspect_trial imports its neighbour bench_generality the same way

import bench_generality  # noqa: E402
import inspect_trial as it  # noqa: E402

# a tee of three: two robots front to front, a third docked on their joint (um, rad)
GOALS = np.array([[0.0, -130.0, 0.0], [0.0, 130.0, math.pi], [130.0, 0.0, 1.5 * math.pi]])
L = np.array([260.0, 260.0, 240.0])
W = np.array([60.0, 55.0, 50.0])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-30, 30), st.floats(-30, 30), st.floats(-0.1, 0.1)), min_size=3, max_size=3),
       st.floats(0, 2 * math.pi), st.floats(-500, 500), st.floats(-500, 500))
def test_per_robot_shares_make_up_the_shape_error(errors, turn, dx, dy):
    """The mean square of the robots' shares is the square of the shape error, wherever the structure lies
    (a rigid motion of the final poses changes neither)."""
    final = GOALS + np.array(errors)
    c, s = math.cos(turn), math.sin(turn)
    moved = final.copy()
    moved[:, 0] = c * final[:, 0] - s * final[:, 1] + dx
    moved[:, 1] = s * final[:, 0] + c * final[:, 1] + dy
    moved[:, 2] = final[:, 2] - turn  # headings clockwise from +y: a counter-clockwise turn lowers them
    per_robot, _ = it.shape_shares(moved, GOALS, L, W)
    assert math.isclose(float(np.sqrt(np.mean(per_robot**2))), shape_error(moved, GOALS, L, W).rms_um, rel_tol=1e-9, abs_tol=1e-9)


def test_the_robot_that_spoils_the_shape_is_the_one_whose_removal_leaves_none():
    """One robot docked 30 um along its face, the others exact: without it the shape error is 0; without either of
    the others it stays (the spoiler is still there)."""
    final = GOALS.copy()
    final[2, 1] += 30.0
    per_robot, without = it.shape_shares(final, GOALS, L, W)
    assert without[2] < 1e-6
    assert min(without[0], without[1]) > 5.0
    assert int(np.argmax(per_robot)) == 2


def test_events_replay_the_benchmark_trial(capsys):
    """The replayed trial (tuning layout 0, a pair, plant seed 0) ends as bench_generality's run of it does."""
    rec = bench_generality.run_layout("tuning", 0, [0], 1.0)
    it.main(["events", "tuning", "0:0"])
    out = capsys.readouterr().out
    last = out.strip().splitlines()[-1]
    assert last.startswith("assembled" if rec["trials"][0]["success"] else "not assembled")
    assert f"{rec['trials'][0]['shape_error_um']:.1f} um RMS" in last


def test_events_replay_the_independent_plant_trial(capsys):
    """``--plant independent`` replays bench_independent_plant's run of the trial (tuning layout 0, plant seed 0)."""
    import bench_independent_plant

    rec = bench_independent_plant.run_layout("tuning", 0, [0], 1.0, None, "")
    it.main(["events", "tuning", "0:0", "--plant", "independent"])
    last = capsys.readouterr().out.strip().splitlines()[-1]
    trial = rec["trials"][0]
    assert last.startswith("assembled" if trial["claimed"] else "not assembled")
    assert f"{trial['shape_error_um']:.1f} um RMS" in last


def test_docking_order_ends_with_the_g1_pair(capsys):
    """The printed docking order D_1 .. D_n ends with the pair that formed G_1 (D_{n-1}, D_n), whatever the scenario's
    own order of the robots (tuning layout 1, a tee of three)."""
    it.main(["events", "tuning", "1:0"])
    out = capsys.readouterr().out.splitlines()
    order = out[0].split(":", 1)[1].split()
    g1 = next(line for line in out if " G_1 " in line)
    d_n, d_n1 = g1.split()[2].rstrip(":"), g1.split("formed with ")[1].split()[0]
    assert order[-2:] == [d_n1, d_n]


def test_a_bad_tune_is_one_error_line_and_status_2(capsys):
    try:
        it.main(["events", "tuning", "0:0", "--tune", "no_such_field=1"])
    except SystemExit as exc:
        assert exc.code == 2
    else:
        raise AssertionError("a bad --tune must exit")
    assert capsys.readouterr().err.startswith("error: --tune: 'no_such_field'")


_POINT_TARGETS = it.Replay("sim", it.tuning_options("region_targets=False,left_bias_hold=False,loop_defer_deg=0,left_bias_shrink=False"))
"""The controller aiming gross motion at points, as before waypoint regions, and its left bias as before session 24 (no
hold, no deferred loop, no shrinking): held-out 43:0 at 2x then fails as traced."""


def test_pins_watch_only_observes_and_finds_the_pin_of_a_robot_that_gave_up():
    """``pins`` (held-out layout 43, a comb of three, plant seed 0 at 2x noise, replayed without the waypoint regions
    (``Tuning.region_targets``) and the left bias as before session 24, with either of which it assembles: R0 gives up
    with no path clear): the watched replay ends
    exactly as the plain one (observation only), the loop's ``drive`` is restored afterwards, and a robot that ended
    with no clear path was boxed in by some applied step after a pose where it could move on."""
    from stressbots.control.loop import PlantLoop

    scn, plan, ps = it._trial("heldout", "43:0", 2.0, "")
    plain, _ = it._run(scn, plan, ps, replay=_POINT_TARGETS)
    drive = PlantLoop.drive
    with it._PinWatch(scn.names.index("R0")) as watch:
        watched, _ = it._run(scn, plan, ps, replay=_POINT_TARGETS)
    assert PlantLoop.drive is drive
    assert (watched.success, watched.failure, watched.duration_s) == (plain.success, plain.failure, plain.duration_s)
    assert plain.failure and "R0" in plain.failure and "um of its path clear" in plain.failure, (
        f"held-out 43:0 at 2x no longer fails with R0 pinned ({plain.failure!r}): point this test at a trial that does")
    assert watch.pins and all(t <= plain.duration_s for t, *_ in watch.pins)


def test_routes_watch_only_observes_and_names_why_no_route_was_found():
    """``routes`` on the same trial (held-out 43:0 at 2x, without waypoint regions): the watched replay ends exactly as
    the plain one, the gross motion's roadmap search is restored afterwards, and R0's failed searches are explained by
    the planner's own reason, the arena edge (R0 ends boxed in beside it), re-asked with a random stream of its own."""
    from stressbots.control.gross import GrossMotion

    scn, plan, ps = it._trial("heldout", "43:0", 2.0, "")
    plain, _ = it._run(scn, plan, ps, replay=_POINT_TARGETS)
    search = GrossMotion.roadmap_route
    with it._RouteWatch() as watch:
        watched, _ = it._run(scn, plan, ps, replay=_POINT_TARGETS)
    assert GrossMotion.roadmap_route is search
    assert (watched.success, watched.failure, watched.duration_s) == (plain.success, plain.failure, plain.duration_s)
    r0 = scn.names.index("R0")
    assert watch.failed and all(t <= plain.duration_s for t, *_ in watch.failed)
    assert any(i == r0 and "arena edge" in why for _, i, _, _, _, why in watch.failed)
