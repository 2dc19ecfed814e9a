"""Contact and compliance rules of the simulated plant on constructed contacts (no noise).

Each expected outcome is computed here independently: first contact by scanning the closed-form motion
(SPEC 3 formulas written out) against :func:`stressbots.collision.penetration_depth` and bisecting,
then the rule's geometry (rotation about the contact point, stuck where it met, G_1 junction) by hand.

The static "structure" is a G_1 pair pushing head-on: R1 heading +x and R2 heading -x, front edges
flush at x = 1000, so the bar spans x in [740, 1260], y in [970, 1030] (top face y = 1030).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from stressbots.collision import pairwise_overlaps, penetration_depth, point_rectangle_distance
from stressbots.electrostatics import Electrodes
from stressbots.robots import Pose, Robot, body_corners
from stressbots.scenario import Noise, Scenario
from stressbots.sim import SimulatedPlant
from stressbots.waveform import Drive, Hold

# A STRING design (D_1..D_4 = R0..R3); Hold(130) lowers R0's arm only.
THRESHOLDS = [(120.0, 15.0), (140.0, 30.0), (160.0, 45.0), (185.0, 60.0)]
V = 100.0  # um/s
R = 200.0  # um
BAR = [(870.0, 1000.0, 90.0), (1130.0, 1000.0, 270.0)]
TOP = 1030.0


def scenario(poses_deg, *, width=60.0, length=260.0, arena=(3000.0, 3000.0)) -> Scenario:
    robots = tuple(
        Robot(f"R{k}", *THRESHOLDS[k], length_um=length, width_um=width, speed_um_s=V, turn_radius_um=R, start=Pose.from_degrees(*p))
        for k, p in enumerate(poses_deg)
    )
    return Scenario(name="contact", robots=robots, electrodes=Electrodes(), arena_um=arena, noise=Noise())


def straight(t):
    return [Drive(75.0, 105.0, t)]


def turn_r0(t):
    return [Hold(130.0, 0.001), Drive(75.0, 105.0, t)]


def spec_motion(pose, t, turning):
    """SPEC 3 written out: pose after t seconds at speed V, straight or on the clockwise circle of radius R."""
    x, y, th = pose
    s = V * t
    if not turning:
        return np.array([x + s * math.sin(th), y + s * math.cos(th), th])
    d = s / R
    return np.array([x + R * (math.cos(th) - math.cos(th + d)), y + R * (math.sin(th + d) - math.sin(th)), th + d])


def first_contact(pose, obstacles, turning=False, t_max=20.0, L=260.0, W=60.0):
    """Time and pose of the first contact of a robot moving alone among static bodies (independent)."""

    def depth(t):
        p = spec_motion(pose, t, turning)
        return max(float(penetration_depth(p, L, W, q, L, W)[0]) for q in obstacles)

    ts = np.arange(0.0, t_max, 0.01)
    k = next(k for k, t in enumerate(ts) if depth(t) > 0.0)
    lo, hi = ts[k - 1], ts[k]
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if depth(mid) > 0.0 else (mid, hi)
    return lo, spec_motion(pose, lo, turning)


def rotate_about(pose, c, phi):
    """Clockwise (heading convention) rotation of a pose about point c by phi (rad)."""
    dx, dy = pose[0] - c[0], pose[1] - c[1]
    return np.array([c[0] + math.cos(phi) * dx + math.sin(phi) * dy, c[1] - math.sin(phi) * dx + math.cos(phi) * dy, pose[2] + phi])


def bar_poses():
    return np.array([Pose.from_degrees(*p) for p in BAR])


def assert_pose(actual, expected, atol=1e-6):
    np.testing.assert_allclose(actual[:2], expected[:2], atol=atol, rtol=0)
    d = (actual[2] - expected[2] + math.pi) % (2 * math.pi) - math.pi
    assert abs(d) < 1e-8, (actual, expected)


def kinds(plant, robot):
    return [e.kind for e in plant.events if e.robot == robot]


def no_overlap(plant, tol=1e-6):
    sc = plant.scenario
    assert not pairwise_overlaps(plant.true_poses(), sc.lengths_um, sc.widths_um, tol_um=tol)


def pose_above(corner_target, theta_deg, along_um):
    """A pose heading ``theta_deg`` whose front-edge midpoint is ``along_um`` behind ``corner_target``."""
    th = math.radians(theta_deg)
    h = np.array([math.sin(th), math.cos(th)])
    c = np.asarray(corner_target) - (130.0 + along_um) * h
    return (float(c[0]), float(c[1]), theta_deg)


def start_for_corner(theta_deg, contact_xy, back_um=100.0, corner=0):
    """A start pose heading ``theta_deg`` whose front corner (0 = left, 1 = right) drives straight onto
    ``contact_xy`` after ``back_um``."""
    th = math.radians(theta_deg)
    h = np.array([math.sin(th), math.cos(th)])
    r = np.array([math.cos(th), -math.sin(th)])
    offset = 130.0 * h + (-30.0 if corner == 0 else 30.0) * r
    c = np.asarray(contact_xy) - offset - back_um * h
    return np.array([c[0], c[1], th])


# ----------------------------------------------------------------------------------------------------


def test_bar_is_a_static_g1_pair():
    plant = SimulatedPlant(scenario(BAR), seed=0)
    plant.apply(straight(2.0))
    np.testing.assert_allclose(plant.true_poses(), bar_poses(), atol=1e-9)
    assert plant.docked.all()
    assert kinds(plant, "R0") == ["self_align"]


def test_straight_push_into_a_face_stops_exactly_and_docks():
    start = (1000.0, 1400.0, 180.0)
    plant = SimulatedPlant(scenario([start] + BAR), seed=0)
    plant.apply(straight(5.0))
    final = plant.true_poses()[0]
    assert_pose(final, np.array([1000.0, TOP + 130.0, math.pi]), atol=1e-6)
    assert plant.docked[0] and not plant.stuck[0]
    assert "dock" in kinds(plant, "R0")
    plant.apply(straight(2.0))  # keeps pushing, does not move
    assert_pose(plant.true_poses()[0], final, atol=1e-9)
    no_overlap(plant)


@pytest.mark.parametrize("alpha_deg", [30.0, -30.0, 10.0])
def test_docking_compliance_inside_the_sticking_cone(alpha_deg):
    start = np.array(Pose.from_degrees(1000.0, 1350.0, 180.0 + alpha_deg))
    t_c, at_contact = first_contact(start, bar_poses())
    corners = body_corners(at_contact, 260.0, 60.0)[0]
    c = corners[np.argmin(corners[:, 1])]  # the front corner on the face
    assert abs(c[1] - TOP) < 1e-6
    expected = rotate_about(at_contact, c, -math.radians(alpha_deg))
    plant = SimulatedPlant(scenario([tuple(Pose(*start).to_degrees())] + BAR), seed=0)
    plant.apply(straight(t_c + 1.0))
    final = plant.true_poses()[0]
    assert_pose(final, expected, atol=1e-6)
    assert abs(final[2] - math.pi) < 1e-9  # flush: heading along the face's inward normal
    fr = body_corners(final, 260.0, 60.0)[0][:2]
    np.testing.assert_allclose(fr[:, 1], TOP, atol=1e-6)
    assert plant.docked[0] and not plant.stuck[0]
    assert "dock" in kinds(plant, "R0")
    np.testing.assert_allclose(plant.true_poses()[1:], bar_poses(), atol=1e-9)  # the structure did not move
    no_overlap(plant)


def test_outside_the_sticking_cone_the_robot_is_stuck_where_it_met():
    # SPEC 6: outside the +-45 deg cone the robot is stuck (H): no turn, no slide along the face.
    start = start_for_corner(240.0, (1150.0, TOP))
    t_c, at_contact = first_contact(start, bar_poses())
    plant = SimulatedPlant(scenario([tuple(Pose(*start).to_degrees())] + BAR), seed=0)
    plant.apply(straight(t_c + 0.8))
    assert_pose(plant.true_poses()[0], at_contact, atol=1e-6)
    assert plant.stuck[0] and not plant.docked[0]
    assert "stuck" in kinds(plant, "R0") and "slide" not in kinds(plant, "R0")
    no_overlap(plant)


def test_a_robot_does_not_dock_against_a_robot_outside_the_structure():
    # R1 stands pushing at the arena's top edge (static, not docked); R0 meets R1's rear edge 10 deg off
    # flush, inside the sticking cone: docking compliance is for the structure only (SPEC 6), so R0 stays.
    top = 3000.0
    r1 = (1500.0, top - 130.0, 0.0)
    start = start_for_corner(10.0, (1490.0, top - 260.0), back_um=50.0)
    t_c, at_contact = first_contact(start, [np.array(Pose.from_degrees(*r1))])
    plant = SimulatedPlant(scenario([tuple(Pose(*start).to_degrees()), r1]), seed=0)
    plant.apply(straight(t_c + 1.0))
    assert plant.arena_hits[1] and not plant.docked[1]
    assert_pose(plant.true_poses()[0], at_contact, atol=1e-6)
    assert plant.stuck[0] and not plant.docked[0]
    assert kinds(plant, "R0") == ["stuck"]
    no_overlap(plant)


def test_structure_corner_on_the_front_edge_is_stuck_without_turning():
    # The structure's corner on the robot's front edge is no front corner on a face: no docking
    # compliance (SPEC 6), the robot stays where it met the corner.
    corner = (1260.0, TOP)  # the bar's right end, top
    start = pose_above(corner, 200.0, 40.0)  # the corner meets the middle of the front edge
    t_c, at_contact = first_contact(np.array(Pose.from_degrees(*start)), bar_poses())
    plant = SimulatedPlant(scenario([start] + BAR), seed=0)
    plant.apply(straight(3.0))
    assert_pose(plant.true_poses()[0], at_contact, atol=1e-6)
    assert plant.stuck[0] and not plant.docked[0]
    assert kinds(plant, "R0") == ["stuck"]
    no_overlap(plant)


@pytest.mark.parametrize(("off_deg", "docks"), [(0.3, True), (1.0, False)])
def test_a_front_edge_within_half_a_degree_of_flush_on_the_structures_corner_docks(off_deg, docks):
    # Arriving flush is docking (SPEC 6), to the simulator's tolerance of 0.5 deg: turned flush about the corner.
    corner = (1260.0, TOP)
    start = pose_above(corner, 180.0 + off_deg, 20.0)
    plant = SimulatedPlant(scenario([start] + BAR), seed=0)
    plant.apply(straight(3.0))
    final = plant.true_poses()[0]
    assert bool(plant.docked[0]) is docks and bool(plant.stuck[0]) is not docks
    assert bool(abs(final[2] - math.pi) < 1e-9) is docks
    no_overlap(plant)


def test_docking_compliance_obstructed_leaves_the_robot_stuck():
    blocker = (970.0, TOP + 130.0, 180.0)  # R3 docked upright on the face, x in [940, 1000]
    # R0's front-left corner lands at x = 1056; flush it would reach x = 996, inside R3.
    start = start_for_corner(210.0, (1056.0, TOP))
    plant = SimulatedPlant(scenario([tuple(Pose(*start).to_degrees())] + BAR + [blocker]), seed=0)
    plant.apply(straight(4.0))
    final = plant.true_poses()[0]
    assert plant.stuck[0] and not plant.docked[0]
    assert "stuck" in kinds(plant, "R0")
    assert math.pi < final[2] < math.radians(210.0) - 1e-3  # rotated part of the way
    assert penetration_depth(final, 260.0, 60.0, plant.true_poses()[3], 260.0, 60.0)[0] > -1e-6  # touching R3
    no_overlap(plant, tol=1e-3)


def test_turning_robot_is_blocked_at_first_contact():
    start = np.array(Pose.from_degrees(1000.0, 1200.0, 90.0))  # heading +x; turning clockwise swings it down
    t_c, at_contact = first_contact(start, bar_poses(), turning=True)
    plant = SimulatedPlant(scenario([tuple(Pose(*start).to_degrees())] + BAR), seed=0)
    plant.apply(turn_r0(t_c + 1.0))
    assert_pose(plant.true_poses()[0], at_contact, atol=1e-6)
    assert "blocked" in kinds(plant, "R0")
    assert not plant.docked[0]
    plant.apply(turn_r0(2.0))  # still pushing into the bar: stays
    assert_pose(plant.true_poses()[0], at_contact, atol=1e-6)
    no_overlap(plant)


def test_robot_stops_at_the_arena_edge():
    plant = SimulatedPlant(scenario([(2700.0, 1500.0, 90.0), (500.0, 500.0, 0.0)]), seed=0)
    plant.apply(straight(3.0))
    assert_pose(plant.true_poses()[0], np.array([3000.0 - 130.0, 1500.0, math.pi / 2]), atol=1e-6)
    assert plant.arena_hits[0] and not plant.arena_hits[1]
    assert kinds(plant, "R0") == ["arena"]
    plant.apply(straight(1.0))
    assert abs(plant.true_poses()[0, 0] - 2870.0) < 1e-6


def g1_case(alpha_deg, w_y, width=60.0):
    """R0 heading +x and R1 heading -x, each tilted by alpha/2 the opposite way (incidence alpha), R1 w_y higher."""
    half = 0.5 * alpha_deg
    a = np.array(Pose.from_degrees(700.0, 1000.0, 90.0 + half))
    b = np.array(Pose.from_degrees(1300.0, 1000.0 + w_y, 270.0 - half))
    return a, b


def contact_of_pair(a, b, width, t_max=10.0):
    def depth(t):
        return float(penetration_depth(spec_motion(a, t, False), 260.0, width, spec_motion(b, t, False), 260.0, width)[0])

    ts = np.arange(0.0, t_max, 0.005)
    k = next(k for k, t in enumerate(ts) if depth(t) > 0.0)
    lo, hi = ts[k - 1], ts[k]
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if depth(mid) > 0.0 else (mid, hi)
    return lo, spec_motion(a, lo, False), spec_motion(b, lo, False)


def front_mid(p, L=260.0):
    return p[:2] + 0.5 * L * np.array([math.sin(p[2]), math.cos(p[2])])


def lateral_offset(pa, pb):
    """|w_y|: offset of the two front-edge centres across the meeting axis (the bisector of the headings)."""
    ha = np.array([math.sin(pa[2]), math.cos(pa[2])])
    hb = np.array([math.sin(pb[2]), math.cos(pb[2])])
    axis = (ha - hb) / np.linalg.norm(ha - hb)
    return abs(float((front_mid(pb) - front_mid(pa)) @ np.array([axis[1], -axis[0]])))


# w_y = 0, 40, 70, 79 um (issue 11): 60-um-wide robots offset by more than their width meet only with an
# incidence (a front corner on the other's side near its front); wide ones meet front edge to front edge.
# 56.38 um at 40 deg is the corner-to-corner contact (60 cos 20 deg = 56.382 um).
INSIDE = [(40.0, 0.0, 60.0), (-40.0, 20.0, 60.0), (0.0, 50.0, 150.0), (30.0, 40.0, 60.0), (40.0, 56.38, 60.0),
          (40.0, 70.0, 60.0), (-40.0, 70.0, 60.0), (25.0, 79.0, 60.0), (-55.0, 79.0, 60.0), (0.0, 79.0, 180.0)]
OUTSIDE = [(70.0, 0.0, 60.0), (-70.0, 10.0, 60.0), (0.0, 100.0, 150.0), (40.0, 85.0, 60.0), (-55.0, 85.0, 60.0),
           (0.0, 85.0, 180.0), (0.0, 80.0, 180.0)]


@pytest.mark.parametrize("alpha_deg, w_y, width", INSIDE)
def test_self_aligning_compliance_forms_g1_inside_the_limits(alpha_deg, w_y, width):
    a, b = g1_case(alpha_deg, w_y, width)
    t_c, pa, pb = contact_of_pair(a, b, width)
    assert lateral_offset(pa, pb) == pytest.approx(w_y, abs=1e-6)  # the meeting is the one named
    axis_th = a[2] - 0.5 * math.radians(alpha_deg)  # the mean axis: each turns by half of alpha
    h = np.array([math.sin(axis_th), math.cos(axis_th)])
    junction = 0.5 * (front_mid(pa) + front_mid(pb))
    exp_a = np.array([*(junction - 130.0 * h), axis_th])
    exp_b = np.array([*(junction + 130.0 * h), axis_th + math.pi])
    sc = scenario([tuple(Pose(*a).to_degrees()), tuple(Pose(*b).to_degrees())], width=width)
    plant = SimulatedPlant(sc, seed=0)
    plant.apply(straight(t_c + 1.0))
    final = plant.true_poses()
    assert_pose(final[0], exp_a, atol=1e-6)
    assert_pose(final[1], exp_b, atol=1e-6)
    np.testing.assert_allclose(front_mid(final[0]), front_mid(final[1]), atol=1e-6)  # flush, collinear
    assert plant.docked.all() and not plant.stuck.any()
    assert kinds(plant, "R0") == ["self_align"]
    no_overlap(plant)


@pytest.mark.parametrize("alpha_deg, w_y, width", OUTSIDE)
def test_self_alignment_outside_the_limits_leaves_both_stuck(alpha_deg, w_y, width):
    a, b = g1_case(alpha_deg, w_y, width)
    t_c, pa, pb = contact_of_pair(a, b, width)
    assert lateral_offset(pa, pb) == pytest.approx(w_y, abs=1e-6)
    sc = scenario([tuple(Pose(*a).to_degrees()), tuple(Pose(*b).to_degrees())], width=width)
    plant = SimulatedPlant(sc, seed=0)
    plant.apply(straight(t_c + 1.0))
    final = plant.true_poses()
    assert_pose(final[0], pa, atol=1e-6)  # stopped where they met, unturned
    assert_pose(final[1], pb, atol=1e-6)
    assert plant.stuck.all() and not plant.docked.any()
    assert kinds(plant, "R0") == ["stuck"] and kinds(plant, "R1") == ["stuck"]
    no_overlap(plant)


def test_straight_robot_stops_behind_a_moving_robot_and_follows():
    # R1 drives straight ahead of R0 at the same speed, 0.5 um gap: R0 never catches it, no contact.
    sc = scenario([(1000.0, 1000.0, 0.0), (1000.0, 1260.5, 0.0)])
    plant = SimulatedPlant(sc, seed=0)
    plant.apply(straight(3.0))
    np.testing.assert_allclose(plant.true_poses()[:, 1], [1300.0, 1560.5], atol=1e-9)
    assert plant.events == ()


def test_a_sideswipe_is_not_a_head_on_meeting():
    """At 10 deg incidence and 79 um offset, 60-um-wide robots touch only when a front corner reaches the
    rear half of the other's side: they have passed each other (scratch drives cannot back up to flush),
    so they slide past; no G_1 and no permanent stall."""
    a, b = g1_case(10.0, 79.0)
    t_c, pa, pb = contact_of_pair(a, b, 60.0)
    sc = scenario([tuple(Pose(*a).to_degrees()), tuple(Pose(*b).to_degrees())])
    plant = SimulatedPlant(sc, seed=0)
    plant.apply(straight(t_c + 6.0))
    assert not plant.docked.any() and not plant.stuck.any()
    assert "self_align" not in kinds(plant, "R0") + kinds(plant, "R1")
    final = plant.true_poses()
    assert final[0, 0] > 1300.0 and final[1, 0] < 700.0  # they drove past each other
    no_overlap(plant)


@settings(max_examples=12, deadline=None, derandomize=True)
@given(alpha_deg=st.floats(-58.0, 58.0), w_y=st.floats(0.0, 95.0), width=st.floats(50.0, 200.0))
def test_head_on_meetings_form_g1_exactly_inside_the_seeds_limits(alpha_deg, w_y, width):
    """Any meeting whose contact lies in the front half of both bodies: G_1 iff |w_y| < 80 um (|alpha| < 60 deg)."""
    a, b = g1_case(alpha_deg, w_y, width)
    try:
        t_c, pa, pb = contact_of_pair(a, b, width)
    except StopIteration:  # they pass each other without touching
        assume(False)
    la = np.array([math.sin(pa[2]), math.cos(pa[2])])
    lb = np.array([math.sin(pb[2]), math.cos(pb[2])])
    ca, cb = body_corners(pa, 260.0, width)[0], body_corners(pb, 260.0, width)[0]
    touching = np.vstack([ca[point_rectangle_distance(ca, pb, 260.0, width)[0] < 1e-3],
                          cb[point_rectangle_distance(cb, pa, 260.0, width)[0] < 1e-3]])
    assume(touching.size and ((touching - pa[:2]) @ la >= 1.0).all() and ((touching - pb[:2]) @ lb >= 1.0).all())  # front halves
    assume(abs(lateral_offset(pa, pb) - 80.0) > 1e-3)
    sc = scenario([tuple(Pose(*a).to_degrees()), tuple(Pose(*b).to_degrees())], width=width)
    plant = SimulatedPlant(sc, seed=0)
    plant.apply(straight(t_c + 0.5))
    final = plant.true_poses()
    if lateral_offset(pa, pb) < 80.0:
        assert plant.docked.all() and kinds(plant, "R0") == ["self_align"]
        np.testing.assert_allclose(front_mid(final[0]), front_mid(final[1]), atol=1e-6)
    else:
        assert plant.stuck.all() and not plant.docked.any()
    no_overlap(plant)


# ----------------------------------------------------------------------------------------------------
# Docking on arrival (issue 11.3): arriving flush in the slot is docking, whatever the arm does.


@pytest.mark.parametrize("arc_um", [30.0, 120.0])
def test_a_robot_turning_into_its_slot_is_docked_on_arrival_and_stays_docked(arc_um):
    slot = np.array([1000.0, TOP + 130.0, math.pi])  # front edge flush on the bar's top face
    d = arc_um / R
    # the arc of SPEC 3 run backwards from the slot (independent of the simulator's kinematics)
    th0 = slot[2] - d
    start = np.array([slot[0] - R * (math.cos(th0) - math.cos(slot[2])), slot[1] - R * (math.sin(slot[2]) - math.sin(th0)), th0])
    np.testing.assert_allclose(spec_motion(start, arc_um / V, True), slot, atol=1e-9)
    for u in np.linspace(0.0, arc_um / V, 200)[:-1]:  # it touches nothing before the end
        assert max(float(penetration_depth(spec_motion(start, u, True), 260.0, 60.0, q, 260.0, 60.0)[0]) for q in bar_poses()) < 0.0
    plant = SimulatedPlant(scenario([tuple(Pose(*start).to_degrees())] + BAR), seed=0)
    plant.apply(turn_r0(arc_um / V))  # the Drive ends exactly on arrival
    assert_pose(plant.true_poses()[0], slot, atol=1e-9)
    assert plant.docked.all() and not plant.stuck.any()
    assert set(kinds(plant, "R0")) == {"dock"}  # on both bar robots' faces (the slot spans the junction)
    plant.apply([Drive(75.0, 105.0, 2.0)])  # arm still down: it pushes while turning, does not move
    assert plant.docked[0]
    assert_pose(plant.true_poses()[0], slot, atol=1e-9)
    plant.apply([Hold(0.0, 0.01)] + straight(2.0))  # arm up: it pushes straight in, still docked
    assert plant.docked[0] and set(kinds(plant, "R0")) == {"dock"}
    assert_pose(plant.true_poses()[0], slot, atol=1e-9)
    no_overlap(plant)


def test_turning_against_a_body_without_being_flush_is_blocked_not_docked():
    # R0 turning onto the bar's top face at an angle: its corner meets the face first.
    start = (1000.0, 1300.0, 150.0)
    plant = SimulatedPlant(scenario([start] + BAR), seed=0)
    plant.apply(turn_r0(4.0))
    assert kinds(plant, "R0")[0] == "blocked" and not plant.docked[0]
    no_overlap(plant)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 25), st.integers(0, 5), st.floats(50.0, 300.0), st.floats(20.0, 80.0), st.floats(-5.0, 5.0),
       st.integers(0, 2**32 - 1))
def test_bodies_hit_discs_equals_the_brute_force_distance_matrix(m, k, length, width, tol, seed):
    """The pruned test (only centre pairs within reach are measured) against the full (M, K) signed-distance
    matrix: identical for bodies and discs anywhere, negative reaches included."""
    from stressbots.collision import bodies_hit_discs

    rng = np.random.default_rng(seed)
    poses = np.column_stack([rng.uniform(0, 2000, m), rng.uniform(0, 2000, m), rng.uniform(0, 2 * math.pi, m)])
    centres, radii = rng.uniform(0, 2000, (k, 2)), rng.uniform(-50, 600, k)
    brute = point_rectangle_distance(centres, poses, length, width) < radii[None, :] - tol
    assert np.array_equal(bodies_hit_discs(poses, length, width, centres, radii, tol_um=tol), brute.reshape(m, k))


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 12))
def test_penetration_depth_is_positive_exactly_when_shapely_finds_the_bodies_overlapping(seed, m):
    """Independent truth: shapely's polygons of the body corners. Pairs within 0.5 um of touching are skipped
    (where either answer is rounding). One pose against many gives the same as that pose repeated."""
    from shapely.geometry import Polygon

    from stressbots.robots import body_corners

    rng = np.random.default_rng(seed)
    pa = np.column_stack([rng.uniform(0, 600, m), rng.uniform(0, 600, m), rng.uniform(-7, 7, m)])
    pb = np.column_stack([rng.uniform(0, 600, m), rng.uniform(0, 600, m), rng.uniform(-7, 7, m)])
    la, wa, lb, wb = rng.uniform(60, 300), rng.uniform(20, 80), rng.uniform(60, 300), rng.uniform(20, 80)
    depth = penetration_depth(pa, la, wa, pb, lb, wb)
    ca, cb = body_corners(pa, la, wa), body_corners(pb, lb, wb)
    for k in range(m):
        a, b = Polygon(ca[k]), Polygon(cb[k])
        gap, area = a.distance(b), a.intersection(b).area
        if 0.0 < gap < 0.5 or 0.0 <= area < 1.0 and gap == 0.0:
            continue  # nearly touching, apart or in
        assert (depth[k] > 0.0) == (area > 0.0)
    one = penetration_depth(pa[0], la, wa, pb, lb, wb)
    assert np.array_equal(one, penetration_depth(np.repeat(pa[:1], m, axis=0), la, wa, pb, lb, wb))
