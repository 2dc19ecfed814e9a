"""Target structures: named shapes are valid by independent geometry, explicit goals are validated with
one clear reason per defect, and the rules do not depend on where the structure sits."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Point, Polygon

from stressbots.errors import PlanningError, ScenarioError
from stressbots.robots import Pose, Robot, angle_difference, body_corners, front_midpoints, orbit_radii
from stressbots.scenario import StructureSpec
from stressbots.structures import (
    SHAPES,
    Structure,
    candidate_structures,
    named_structure,
    structure_from_goals,
    target_structures,
)

DEG = math.pi / 180.0
SHAPE_NS = [("pair", 2)] + [(s, n) for s in ("tee", "cross", "comb", "ladder") for n in range(2, 13)]


def robots_v(n: int, lengths=None, widths=None, names=None) -> list[Robot]:
    """Robots D_1..D_n in voltage order (snap-down voltage rising with the index)."""
    out = []
    for i in range(n):
        out.append(
            Robot(
                name=names[i] if names else f"D{i + 1}",
                snap_down_V=120.0 + 5.0 * i,
                release_V=20.0 + 2.0 * i,
                length_um=260.0 if lengths is None else float(lengths[i]),
                width_um=60.0 if widths is None else float(widths[i]),
            )
        )
    return out


# ----------------------------------------------------------------------------------------------------
# Independent checks: plain shapely on the robots' own sizes, nothing from the module's validator.


def overlap_area(a, b) -> float:
    # Snap rounding: plain GEOS overlay can return a whole body for two bodies sharing an edge up to 1e-14.
    return float(shapely.intersection(a, b, grid_size=1e-6).area)


def union(polys):
    return shapely.union_all(polys, grid_size=1e-6)


def independent_check(s: Structure, robots: list[Robot]) -> None:
    n = len(robots)
    assert s.n == n
    assert s.order == tuple(r.name for r in robots)
    by_name = {r.name: r for r in robots}
    poses = s.goal_poses(s.docking_order)
    L = np.array([by_name[nm].length_um for nm in s.docking_order])
    W = np.array([by_name[nm].width_um for nm in s.docking_order])
    corners = body_corners(poses, L, W)
    polys = [Polygon(c) for c in corners]
    heads = np.stack([np.sin(poses[:, 2]), np.cos(poses[:, 2])], axis=1)

    # G_1: head-on, front-edge midpoints coincide.
    assert [sl.role for sl in s.slots[:2]] == ["pair", "pair"]
    assert abs(angle_difference(poses[0, 2], poses[1, 2] + math.pi)) < 1e-9
    mids = front_midpoints(poses[:2], L[:2])
    assert np.linalg.norm(mids[0] - mids[1]) < 1e-6

    # No two bodies overlap.
    for i in range(n):
        for j in range(i):
            assert overlap_area(polys[i], polys[j]) < 1e-3, (s.docking_order[i], s.docking_order[j])

    for k in range(2, n):
        built = union(polys[:k])
        # Front edge flush: every point of it on the structure built so far (so on the line of a side and
        # within its extent, since the body does not overlap), and it faces the structure.
        fl, fr = corners[k, 0], corners[k, 1]
        for f in np.linspace(0.0, 1.0, 9):
            assert built.distance(Point(fl + f * (fr - fl))) < 1e-6, (s.docking_order[k], f)
        probe = 0.5 * (fl + fr) + 1.0 * heads[k]
        assert built.contains(Point(probe)), s.docking_order[k]
        # Approach corridor: the body swept straight back by L + margin crosses nothing docked before.
        a = s.slots[k].approach_um
        assert a >= L[k]
        back = a * heads[k]
        lane = Polygon([corners[k, 0], corners[k, 1], corners[k, 2] - back, corners[k, 3] - back])
        assert overlap_area(lane, built) < 1e-3, s.docking_order[k]
        assert s.slots[k].role == "dock"


def all_valid(structures: list[Structure], robots: list[Robot]) -> None:
    for s in structures:
        independent_check(s, robots)
        # Re-validate the module's own output as explicit goals.
        again = structure_from_goals(robots, s.goals())
        assert again.docking_order == s.docking_order
        assert [sl.supports for sl in again.slots] == [sl.supports for sl in s.slots]


# ----------------------------------------------------------------------------------------------------
# Named shapes


@pytest.mark.parametrize("shape,n", SHAPE_NS)
def test_named_shape_valid_for_every_n(shape, n):
    robots = robots_v(n)
    at = Pose(1234.5, -321.0, 0.7 + 0.1 * n)
    cands = candidate_structures(robots, StructureSpec(shape, at))
    assert cands and cands[0].shape == shape and cands[0].frame == at
    all_valid(cands, robots)
    # Canonical variant: D_n on the -a end of the bar, G_1 junction at the frame origin.
    c = cands[0]
    assert np.allclose(c.slot(f"D{n}").front_midpoint, [at.x, at.y])
    a = np.array([math.cos(at.theta), -math.sin(at.theta)])
    assert np.dot(c.slot(f"D{n}").heading, a) == pytest.approx(1.0)
    # Variants are distinct placements.
    keys = {tuple(np.round(s.goal_poses(), 6).ravel()) for s in cands}
    assert len(keys) == len(cands)


@settings(max_examples=20)
@given(
    shape=st.sampled_from(["tee", "cross", "comb", "ladder"]),
    n=st.integers(2, 12),
    x=st.floats(-5e3, 5e3),
    y=st.floats(-5e3, 5e3),
    theta=st.floats(0.0, 2 * math.pi),
    data=st.data(),
)
def test_named_shapes_random_placement_and_sizes(shape, n, x, y, theta, data):
    lengths = data.draw(st.lists(st.floats(200.0, 320.0), min_size=n, max_size=n))
    # Widths non-decreasing in voltage order: later dockers are never wider than what they dock on.
    widths = sorted(data.draw(st.lists(st.floats(40.0, 80.0), min_size=n, max_size=n)))
    robots = robots_v(n, lengths, widths)
    cands = candidate_structures(robots, StructureSpec(shape, Pose(x, y, theta)))
    all_valid(cands, robots)


@settings(max_examples=15)
@given(
    shape=st.sampled_from(["tee", "cross", "comb", "ladder"]),
    n=st.integers(3, 12),
    data=st.data(),
)
def test_heterogeneous_widths_valid_or_clear_reason(shape, n, data):
    lengths = data.draw(st.lists(st.floats(220.0, 300.0), min_size=n, max_size=n))
    widths = data.draw(st.lists(st.floats(45.0, 75.0), min_size=n, max_size=n))
    robots = robots_v(n, lengths, widths)
    try:
        cands = candidate_structures(robots, StructureSpec(shape, Pose(0.0, 0.0, 0.3)))
    except PlanningError as exc:
        assert "is wider than the rear edge" in str(exc) and str(exc).startswith(shape)
        return
    all_valid(cands, robots)


def test_tee_stem_moves_off_a_step_between_g1_robots_of_different_widths():
    # D3 (left, canonical) is 80 um wide, D2 60 um: the bar's face has a 10 um step at the junction.
    robots = robots_v(3, lengths=[260, 260, 300], widths=[60, 60, 80])
    s = named_structure("tee", robots, Pose(0, 0, 0))
    independent_check(s, robots)
    d1 = s.d(1)
    # Bar middle is at s = (260 - 300) / 2 = -20 (on D3's stretch); the stem's front edge must stay on it.
    assert d1.pose.x == pytest.approx(-30.0) and d1.pose.y == pytest.approx(-40.0 - 130.0)
    assert d1.supports == ("D3",)


def test_stem_wider_than_rear_edge_is_refused():
    robots = robots_v(4, widths=[70, 60, 60, 60])  # D1 (docks on D2's rear edge) is wider than D2
    with pytest.raises(PlanningError, match=r"tee: D1 \(70\.0 um wide\) is wider than the rear edge of D2 \(60\.0 um\)"):
        candidate_structures(robots, StructureSpec("tee", Pose(0, 0, 0)))
    # A comb puts D1 on the bar instead, so it is fine.
    all_valid(candidate_structures(robots, StructureSpec("comb", Pose(0, 0, 0))), robots)


def test_shape_errors():
    with pytest.raises(PlanningError, match="shape 'pair' holds exactly 2 robots"):
        candidate_structures(robots_v(3), StructureSpec("pair", Pose(0, 0, 0)))
    with pytest.raises(ScenarioError, match=r"structure.shape: unknown shape 'star'; known shapes: pair, tee"):
        candidate_structures(robots_v(3), StructureSpec("star", Pose(0, 0, 0)))
    with pytest.raises(PlanningError, match="at least 2 robots"):
        candidate_structures(robots_v(1), StructureSpec("tee", Pose(0, 0, 0)))
    with pytest.raises(PlanningError, match="comb: no room for a tooth"):
        candidate_structures(robots_v(3, lengths=[260, 50, 50]), StructureSpec("comb", Pose(0, 0, 0)))
    assert set(SHAPES) >= {"pair", "tee", "cross", "comb", "ladder"}


def test_canonical_tee_geometry_and_contacts():
    s = named_structure("tee", robots_v(4, names=["A", "B", "C", "D"]), Pose(0, 0, 0))
    assert s.docking_order == ("D", "C", "B", "A") and s.order == ("A", "B", "C", "D")
    np.testing.assert_allclose(
        s.goal_poses(),
        np.array([[0, -420, 0], [0, -160, 0], [130, 0, 1.5 * math.pi], [-130, 0, 0.5 * math.pi]]),
        atol=1e-9,
    )
    b = s.slot("B")
    assert b.role == "dock" and b.index == 2 and b.supports == ("D", "C") and b.neighbours == ("D", "C")
    np.testing.assert_allclose(sorted(b.contact), [(-260.0, -30.0), (260.0, -30.0)], atol=1e-9)
    a = s.slot("A")
    assert a.supports == ("B",) and a.neighbours == ("B",)
    assert s.slot("D").partner == "C"
    np.testing.assert_allclose(s.slot("D").contact, s.slot("C").front_edge, atol=1e-9)
    assert s.d(4).robot == "D" and s.step_of("A") == 3 and s.goal_poses(["D", "A"]).shape == (2, 3)


# ----------------------------------------------------------------------------------------------------
# Helpers the planner and the simulator use


def test_free_sides_outline_corridor_and_proximity_region():
    robots = robots_v(4)
    s = named_structure("tee", robots, Pose(500, 500, 0.0))
    # G_1 alone: the two long faces merge into one 520 um side each, plus the two ends.
    sides = s.free_sides(2)
    assert sorted(round(sd.length_um, 6) for sd in sides) == [60.0, 60.0, 520.0, 520.0]
    assert {sd.robots for sd in sides if sd.length_um > 500} == {("D4", "D3")}
    # After D2 docks, the lower face splits in two 230 um stretches.
    assert sorted(round(sd.length_um, 6) for sd in s.free_sides(3)) == [60, 60, 60, 230, 230, 260, 260, 520]
    assert len(s.free_sides(3, min_length_um=62.0)) == 5
    # Outline: one polygon with the area of the bodies.
    o = s.outline()
    assert o.geom_type == "Polygon" and o.area == pytest.approx(4 * 260 * 60, rel=1e-6)
    # Corridor of D1: its body swept back by L + 50 um.
    d1 = s.slot("D1")
    assert s.corridor("D1").area == pytest.approx(60 * (260 + d1.approach_um))
    assert d1.approach_um == pytest.approx(310.0)
    assert s.corridor("D1", 0.0).area == pytest.approx(60 * 260)
    # C_O of D1: the structure built before it, grown by 2 r*.
    r_star = float(orbit_radii(260, 60, 200))
    assert d1.orbit_radius_um == pytest.approx(r_star)
    c_o = s.proximity_region("D1")
    built = s.outline(3)
    assert s.docking_object("D1").symmetric_difference(built).area < 1e-6
    assert c_o.contains(built.buffer(2 * r_star - 1.0))
    assert not c_o.contains(built.buffer(2 * r_star + 1.0))
    assert c_o.contains(s.body("D1"))  # D1's slot lies inside its C_O: fine motion takes over there
    # C_O of a G_1 robot: around the partner only.
    assert s.docking_object("D4").equals(s.body("D3"))
    assert s.proximity_region("D4", 10.0).area == pytest.approx(s.body("D3").buffer(20.0).area)


def test_side_pose_at_gives_a_valid_slot():
    robots = robots_v(3)
    s = named_structure("pair", robots[1:], Pose(0, 0, 0.4))
    # Dock D1 anywhere on the long face of the bar, built with Side.pose_at.
    face = max(s.free_sides(), key=lambda sd: sd.length_um)
    goals = dict(s.goals())
    goals["D1"] = face.pose_at(260.0, 100.0)
    t = structure_from_goals(robots, goals)
    independent_check(t, robots)
    assert t.slot("D1").supports == ("D3",) or t.slot("D1").supports == ("D2",)
    assert face.fits(60.0) and not face.fits(600.0)


def test_moved_structure_is_congruent():
    s = named_structure("ladder", robots_v(7), Pose(0, 0, 0))
    m = s.moved(0.5, (100.0, -30.0))
    independent_check(m, robots_v(7))
    assert [sl.supports for sl in m.slots] == [sl.supports for sl in s.slots]
    assert m.frame is not None and m.frame.theta == pytest.approx(0.5)
    np.testing.assert_allclose(m.slot("D7").front_midpoint, [100.0, -30.0], atol=1e-9)


def test_target_structures_picks_goals_or_shape():
    robots = robots_v(4)
    s = named_structure("tee", robots, Pose(0, 0, 0))
    with_goals = [Robot(**{**r.__dict__, "goal": s.slot(r.name).pose}) for r in robots]
    (only,) = target_structures(with_goals)
    assert only.shape == "goals" and only.goal_poses() == pytest.approx(s.goal_poses())
    assert len(target_structures(robots, StructureSpec("tee", Pose(0, 0, 0)))) == 4
    with pytest.raises(PlanningError, match=r"^D4: no goal pose"):
        target_structures(robots)


# ----------------------------------------------------------------------------------------------------
# Explicit goals: accepted cases


def comb_goals():
    """Bar D5 | D4 along x, teeth D3 at x = -60 and D2 at x = +60 hanging down, D1 docks between them."""
    up, right, left = 0.0, 0.5 * math.pi, 1.5 * math.pi
    return {
        "D5": (-130.0, 0.0, right),
        "D4": (130.0, 0.0, left),
        "D3": (-60.0, -160.0, up),
        "D2": (60.0, -160.0, up),
        "D1": (0.0, -160.0, up),
    }


def test_docking_between_two_docked_neighbours_with_zero_clearance():
    robots = robots_v(5)
    s = structure_from_goals(robots, comb_goals())
    independent_check(s, robots)
    d1 = s.slot("D1")
    assert d1.supports == ("D5", "D4") and set(d1.neighbours) == {"D5", "D4", "D3", "D2"}
    assert math.dist(*d1.contact) == pytest.approx(60.0, abs=1e-6)  # the notch is exactly one robot wide


@settings(max_examples=30)
@given(
    seed=st.integers(0, 2**32 - 1),
    pos_sd=st.sampled_from([1e-9, 1e-6, 1e-3, 0.05]),
)
def test_floating_noise_in_goals_is_accepted(seed, pos_sd):
    rng = np.random.default_rng(seed)
    robots = robots_v(5)
    g = comb_goals()
    noisy = {k: (x + rng.normal(0, pos_sd), y + rng.normal(0, pos_sd), th + rng.normal(0, 1e-4 * DEG))
             for k, (x, y, th) in g.items()}
    structure_from_goals(robots, noisy)


def test_goals_as_array_and_degrees_round_trip():
    robots = robots_v(5)
    g = comb_goals()
    arr = np.array([g[r.name] for r in robots])
    assert structure_from_goals(robots, arr).goal_poses() == pytest.approx(arr)
    # Goals written to a file with 3 decimals in um and degrees.
    rounded = {k: Pose.from_degrees(*np.round(Pose(*v).to_degrees(), 3)) for k, v in g.items()}
    structure_from_goals(robots, rounded)


# ----------------------------------------------------------------------------------------------------
# Explicit goals: one clear reason per defect

UP, DOWN, RIGHT, LEFT = 0.0, math.pi, 0.5 * math.pi, 1.5 * math.pi
NAMED = ["A", "B", "C", "D"]  # A = D1 ... D = D4
TEE = {"D": (-130.0, 0.0, RIGHT), "C": (130.0, 0.0, LEFT), "B": (0.0, -160.0, UP), "A": (0.0, -420.0, UP)}

REJECTIONS = [
    ({"C": (142.0, 0.0, LEFT)}, "D3/D4 (robots 'C'/'D') do not form G_1: front edges 12.0 um apart"),
    ({"C": (130.0, 8.0, LEFT)}, "D3/D4 (robots 'C'/'D') do not form G_1: front edges offset by 8.0 um sideways"),
    ({"C": (125.0, 0.0, LEFT)}, "D3/D4 (robots 'C'/'D') do not form G_1: bodies overlap by 5.0 um along their axis"),
    ({"C": (130.0, 0.0, 260 * DEG)},
     "D3/D4 (robots 'C'/'D') do not form G_1: headings 170.0 deg apart, must be opposite (180 deg, head-on)"),
    ({"B": (0.0, -195.2, UP)}, "D2 (robot 'B'): goal is not flush with the structure: front edge 35.2 um from the nearest free side"),
    ({"B": (250.0, -160.0, UP)}, "D2 (robot 'B'): front edge overhangs the end of the free side it rests on by 20.0 um"),
    ({"B": (0.0, -30.0 - 130.0 * math.cos(DEG) - 30.0 * math.sin(DEG), 1.0 * DEG)},
     "D2 (robot 'B'): front edge is at 1.0 deg to the free side it touches (must be parallel to it within 0.1 deg)"),
    ({"B": (0.0, -163.0, 1.0 * DEG)},
     "D2 (robot 'B'): goal is not flush with the structure: front edge 2.5 um from the nearest free side and at 1.0 deg to it"),
    ({"B": (0.0, -200.0, 1.0 * DEG)},
     "D2 (robot 'B'): goal is not flush with the structure: front edge 39.5 um from the nearest free side and at 1.0 deg to it"),
    ({"B": (0.0, -160.0, DOWN)}, "D2 (robot 'B'): its rear edge, not its front edge, is on a free side"),
    ({"B": (0.0, -150.0, UP)}, "D2 (robot 'B'): body overlaps D4 (robot 'D') by 300 um^2"),
    ({"A": (0.0, -160.0, UP)}, "D1 (robot 'A'): body overlaps D2 (robot 'B') by 15600 um^2"),
    ({"A": (0.0, float("nan"), UP)}, "D1 (robot 'A'): goal pose is not finite"),
]


@pytest.mark.parametrize("change,message", REJECTIONS, ids=[m.split(": ", 1)[-1][:40] for _, m in REJECTIONS])
def test_invalid_goals_rejected_with_one_line_reason(change, message):
    robots = robots_v(4, names=NAMED)
    structure_from_goals(robots, TEE)  # the unchanged goals are valid
    with pytest.raises(PlanningError) as info:
        structure_from_goals(robots, {**TEE, **change})
    text = str(info.value)
    assert "\n" not in text
    assert text.startswith(message), text


def test_approach_corridor_blocked():
    # Bar, D3 tooth at x = -100, D2 at x = +225; D1 docks on D3's right flank heading -x: its slot is
    # free, but the lane behind it runs into D2.
    robots = robots_v(5)
    goals = {
        "D5": (-130.0, 0.0, RIGHT),
        "D4": (130.0, 0.0, LEFT),
        "D3": (-100.0, -160.0, UP),
        "D2": (225.0, -160.0, UP),
        "D1": (-70.0 + 130.0, -250.0, LEFT),
    }
    with pytest.raises(PlanningError, match=r"^D1: approach corridor \(310 um straight back along its heading\) crosses D2's body"):
        structure_from_goals(robots, goals)
    # A shorter approach does not reach D2.
    s = structure_from_goals(robots, goals, approach_margin_um=-260.0 + 4.0)
    assert s.slot("D1").supports == ("D3",)


def test_goal_list_errors():
    robots = robots_v(4)
    with pytest.raises(PlanningError, match=r"^D2: no goal pose given"):
        structure_from_goals(robots, {k: v for k, v in comb_goals().items() if k in ("D1", "D3", "D4")})
    with pytest.raises(PlanningError, match=r"goals must be an \(4, 3\) array"):
        structure_from_goals(robots, np.zeros((3, 3)))
    with pytest.raises(PlanningError, match="appears twice"):
        structure_from_goals(robots_v(2) + robots_v(1), np.zeros((3, 3)))
    with pytest.raises(PlanningError, match="goal given for unknown robot 'X'"):
        structure_from_goals(robots_v(2), {"D1": (130, 0, LEFT), "D2": (-130, 0, RIGHT), "X": (0, 0, 0)})


# ----------------------------------------------------------------------------------------------------
# Invariance under rigid motion of the whole goal set


def _move(goals: dict, phi: float, dx: float, dy: float) -> dict:
    c, s = math.cos(phi), math.sin(phi)
    return {k: (c * x + s * y + dx, -s * x + c * y + dy, th + phi) for k, (x, y, th) in goals.items()}


def _numbers(text: str) -> list[float]:
    return [float(v) for v in re.findall(r"-?\d+\.\d+|-?\d+(?= um)", text)]


@settings(max_examples=25)
@given(
    phi=st.floats(-2 * math.pi, 2 * math.pi),
    dx=st.floats(-1e4, 1e4),
    dy=st.floats(-1e4, 1e4),
    which=st.integers(0, len(REJECTIONS) - 2),  # the NaN case has no geometry to move
)
def test_rigid_motion_invariance(phi, dx, dy, which):
    robots = robots_v(4, names=NAMED)
    # A valid goal set stays valid, with the same contacts.
    ref = structure_from_goals(robots, TEE)
    moved = structure_from_goals(robots, _move(TEE, phi, dx, dy))
    assert [(sl.supports, sl.neighbours) for sl in moved.slots] == [(sl.supports, sl.neighbours) for sl in ref.slots]
    assert len(moved.free_sides()) == len(ref.free_sides())
    # An invalid one fails for the same reason with the same numbers.
    bad = {**TEE, **REJECTIONS[which][0]}
    with pytest.raises(PlanningError) as a:
        structure_from_goals(robots, bad)
    with pytest.raises(PlanningError) as b:
        structure_from_goals(robots, _move(bad, phi, dx, dy))
    ta, tb = str(a.value), str(b.value)
    assert re.sub(r"\d+(\.\d+)?", "#", ta) == re.sub(r"\d+(\.\d+)?", "#", tb)
    assert np.allclose(_numbers(ta), _numbers(tb), atol=0.11)


@settings(max_examples=8)
@given(phi=st.floats(0, 2 * math.pi), dx=st.floats(-1e4, 1e4), dy=st.floats(-1e4, 1e4))
def test_named_shape_moves_with_its_frame(phi, dx, dy):
    robots = robots_v(6)
    ref = candidate_structures(robots, StructureSpec("comb", Pose(0.0, 0.0, 0.0)))
    mov = candidate_structures(robots, StructureSpec("comb", Pose(dx, dy, phi)))
    assert len(ref) == len(mov)
    for r, m in zip(ref, mov, strict=False):
        want = _move({k: tuple(p) for k, p in r.goals().items()}, phi, dx, dy)
        got = m.goals()
        for k in want:
            assert np.allclose(want[k][:2], got[k][:2], atol=1e-6)
            assert abs(angle_difference(want[k][2], got[k].theta)) < 1e-9
