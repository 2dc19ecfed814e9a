"""The controller's regions (stressbots.coverage): geometry against brute force, the tally on hand-built
samples, the moments of a run on a hand-built plant record, and `stressbots bounds --trials`."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots import coverage as C
from stressbots.montecarlo import wilson_interval
from stressbots.robots import body_corners

from .conftest import EXAMPLES, assert_user_error

L, W = 260.0, 60.0


def _slot_frame_pose(goal, e, psi, behind):
    """A pose ``behind`` um back along its own heading from the point where its centre line crosses the
    slot's cross line ``e`` um right of the slot centre, turned ``psi`` from the slot's heading."""
    th = goal[2]
    rt = np.array([math.cos(th), -math.sin(th)])
    cross = np.asarray(goal[:2]) + e * rt
    hd = np.array([math.sin(th + psi), math.cos(th + psi)])
    p = cross - behind * hd
    return np.array([p[0], p[1], th + psi])


@settings(max_examples=60, deadline=None)
@given(st.floats(-80, 80), st.floats(-1.2, 1.2), st.floats(50, 900), st.floats(0, 2 * math.pi), st.floats(0, 400))
def test_approach_coords_are_constant_along_a_straight_run(e, psi, behind, th, more):
    goal = np.array([1000.0, -300.0, th])
    p = _slot_frame_pose(goal, e, psi, behind)
    q = _slot_frame_pose(goal, e, psi, behind + more)  # further back on the same line
    for pose in (p, q):
        ee, pp = C.approach_coords(goal, pose[None, :])
        assert ee[0] == pytest.approx(e, abs=1e-6) and pp[0] == pytest.approx(psi, abs=1e-9)


def _brute_capture_offset(e, psi):
    """Drive the body straight in 0.01 um steps until a corner reaches the face (the slot's front-edge line),
    then turn it about that corner until its front edge is flush; the centre's lateral offset after."""
    goal = np.array([0.0, 0.0, 0.0])  # slot heading +y: the face is the line y = L/2
    pose = _slot_frame_pose(goal, e, psi, 150.0)
    h = np.array([math.sin(pose[2]), math.cos(pose[2])])
    corners = body_corners(pose, L, W)[0]
    gap = 0.5 * L - corners[:, 1].max()  # how far the leading corner is from the face
    steps = math.floor(gap / h[1] / 0.01)
    pose[:2] += steps * 0.01 * h
    while body_corners(pose, L, W)[0][:, 1].max() < 0.5 * L:
        pose[:2] += 1e-4 * h
    c = body_corners(pose, L, W)[0]
    pivot = c[int(np.argmax(c[:, 1]))]
    phi = -pose[2]  # turn the heading back to the slot's (theta is clockwise: rotate the plane by +psi)
    rot = np.array([[math.cos(phi), math.sin(phi)], [-math.sin(phi), math.cos(phi)]])
    centre = pivot + rot @ (pose[:2] - pivot)
    flush = body_corners(np.array([*centre, 0.0]), L, W)[0]
    assert flush[:2, 1] == pytest.approx([0.5 * L, 0.5 * L], abs=2e-3)  # front edge on the face
    return centre[0]


@pytest.mark.parametrize("e, psi_deg", [(0.0, 0.0), (10.0, 5.0), (-20.0, 12.0), (5.0, -8.0), (30.0, -30.0), (-3.0, 40.0)])
def test_capture_offset_matches_brute_force(e, psi_deg):
    got = float(C.capture_offset(e, math.radians(psi_deg), L, W))
    assert got == pytest.approx(_brute_capture_offset(e, math.radians(psi_deg)), abs=0.02)


def test_docking_capture_region_limits():
    cap = C.DockingCapture(30.0, math.radians(45.0), L, W)
    psi = np.radians(np.linspace(-44.0, 44.0, 23))
    lo, hi = cap.lateral_limits(psi)
    for p, a, b in zip(psi, lo, hi, strict=True):  # the limits bound contains() exactly (brute-force scan)
        es = np.linspace(a - 5, b + 5, 7001)
        inside = es[cap.contains(es, np.full_like(es, p))]
        step = es[1] - es[0]
        assert inside.min() == pytest.approx(a, abs=1.5 * step) and inside.max() == pytest.approx(b, abs=1.5 * step)
    assert cap.contains(29.9, 0.0) and not cap.contains(30.1, 0.0)
    assert not cap.contains(float(lo[0]) + 30.0, math.radians(46.0))  # outside the sticking cone
    aim = C.StraightInAim(12.0, math.radians(6.0))
    assert aim.contains(-12.0, math.radians(6.0)) and not aim.contains(12.5, 0.0) and not aim.contains(0.0, math.radians(7.0))


def _brute_meeting(pn, vn, pm, vm):
    hn = np.array([math.sin(pn[2]), math.cos(pn[2])])
    hm = np.array([math.sin(pm[2]), math.cos(pm[2])])
    u = (hm - hn) / np.hypot(*(hm - hn))
    fn0, fm0 = pn[:2] + 0.5 * L * hn, pm[:2] + 0.5 * L * hm
    ts = np.linspace(0.0, 40.0, 400_001)
    gaps = ((fn0 + ts[:, None] * vn * hn) - (fm0 + ts[:, None] * vm * hm)) @ u
    k = int(np.argmax(gaps <= 0.0))
    d = (fn0 + ts[k] * vn * hn) - (fm0 + ts[k] * vm * hm)
    return abs(float(d @ np.array([u[1], -u[0]])))


@pytest.mark.parametrize("dx, dth_deg, vm", [(0.0, 0.0, 100.0), (40.0, 10.0, 90.0), (-25.0, -20.0, 120.0), (70.0, 35.0, 100.0)])
def test_straight_meeting_matches_stepping(dx, dth_deg, vm):
    pn = np.array([1000.0, 1800.0, math.pi + math.radians(dth_deg)])
    pm = np.array([1000.0 + dx, 1000.0, 0.0])
    w, a = C.straight_meeting(pn, 100.0, L, pm, vm, L)
    assert w == pytest.approx(_brute_meeting(pn, 100.0, pm, vm), abs=0.05)
    assert a == pytest.approx(-math.radians(dth_deg), abs=1e-9)
    assert C.straight_meeting(pm, vm, L, pn, 100.0, L)[0] == pytest.approx(w, abs=1e-6)  # symmetric in the pair
    assert C.straight_meeting(np.array([1000.0, 1800.0, 0.0]), 100.0, L, pm, vm, L)[0] == math.inf  # not closing


def test_rendezvous_regions():
    cap = C.RendezvousRegion(80.0, math.radians(60.0))
    aim = C.RendezvousRegion(80.0, math.radians(60.0), 0.6)
    assert cap.contains(79.0, math.radians(59.0)) and not cap.contains(80.0, 0.0) and not cap.contains(0.0, math.radians(-61.0))
    assert aim.contains(47.9, 0.0) and not aim.contains(48.1, 0.0) and not aim.contains(0.0, math.radians(36.5))


def test_tally_on_hand_built_samples():
    def s(region, robot, scale, inside):
        return C.Sample(region, robot, scale, 0, (0.0, 0.0), (0.0, 0.0), inside)

    samples = [s("capture", "B", 1.0, True)] * 3 + [s("capture", "B", 1.0, False)] + [s("capture", "B", 2.0, False)] * 2 + [
        s("rendezvous-capture", "C+A", 1.0, True)] * 5
    rows = C.tally(samples, {("capture", "B"): "box"}, {"B": "no", "C": "no", "A": "yes"})
    assert [(r.region, r.robot, r.scale, r.inside, r.samples) for r in rows] == [
        ("capture", "B", 1.0, 3, 4), ("capture", "B", 2.0, 0, 2), ("rendezvous-capture", "C+A", 1.0, 5, 5)]
    assert (rows[0].low, rows[0].high) == wilson_interval(3, 4) and rows[0].fraction == 0.75
    assert rows[0].size == "box" and rows[2].size == "-"
    assert rows[0].seed_verdict == "no" and rows[2].seed_verdict == "no / yes"


def _hand_built_run():
    """A 3-robot run record: D_1 = 'B' docks against the pair; its last turning Drive ends at t = 20."""
    scn = SimpleNamespace(names=("A", "B", "C"), speeds_um_s=np.full(3, 100.0), lengths_um=np.full(3, L),
                          turn_radii_um=np.full(3, 200.0))
    goal_b = np.array([500.0, 500.0, 0.0])
    start_straight = _slot_frame_pose(goal_b, 8.0, math.radians(2.0), 300.0)
    poses = np.zeros((3, 3, 3))
    poses[:, 1] = [_slot_frame_pose(goal_b, 90.0, 0.3, 500.0), start_straight, goal_b]
    drive_log = (np.array([10.0, 20.0, 24.0]), np.array([[1, 1, 0], [1, 1, 0], [1, 0, 0]], dtype=bool), poses)
    events = (SimpleNamespace(time_s=5.0, robot="C", kind="self_align", other="A"),
              SimpleNamespace(time_s=23.0, robot="B", kind="dock", other="C"))
    plant = SimpleNamespace(events=events, drive_log=lambda: drive_log, speed_factors=np.ones(3))
    rec = C.RecordingPlant(plant)
    goals = np.array([[0.0, 0.0, 0.0], goal_b, [0.0, 0.0, math.pi]])
    return scn, rec, goals


def test_approach_moment_from_a_hand_built_record():
    from stressbots.control import ControllerOptions

    scn, rec, goals = _hand_built_run()
    regions = C.ControllerRegions.of(SimpleNamespace(robots=[SimpleNamespace(name=n, length_um=L, width_um=W) for n in scn.names]),
                                     ControllerOptions())
    result = SimpleNamespace(goals=goals)
    got = C._approach_sample(scn, result, rec, regions, 1, {"A", "C"}, 5.0, 1.0, 0)
    assert [s.region for s in got] == ["straight-in", "capture"]
    assert got[0].coords == pytest.approx((8.0, 2.0)) and got[0].inside and got[1].inside
    # a contact with a robot not yet in the structure is not the approach's end; one while turning has no straight approach
    assert C._approach_sample(scn, result, rec, regions, 1, {"A"}, 5.0, 1.0, 0) == []
    t, turning, poses = rec.plant.drive_log()
    turning = turning.copy()
    turning[2, 1] = True
    arc = C.RecordingPlant(SimpleNamespace(events=rec.plant.events, drive_log=lambda: (t, turning, poses)))
    assert C._approach_sample(scn, result, arc, regions, 1, {"A", "C"}, 5.0, 1.0, 0) == []


def _three_robots(tmp_path):
    """The example without its D_1 (B): a pair and one docking robot (a quicker closed loop)."""
    text = (EXAMPLES / "four-robots.toml").read_text()
    i = text.index('[[robots]]\nname = "B"')
    j = text.index("[[robots]]", i + 5)
    path = tmp_path / "three.toml"
    path.write_text(text[:i] + text[j:])
    return path


def test_bounds_trials_table_json_and_files(run_cli, tmp_path):
    out = tmp_path / "b"
    r = run_cli("bounds", _three_robots(tmp_path), "--trials", "1", "--scales", "1", "--out", out)
    assert r.code == 0, r.err
    assert "rendezvous-capture" in r.out and "straight-in" in r.out and "seed A*" in r.out
    doc = json.loads((out / "bounds.json").read_text())
    cov = doc["controller_coverage"]
    assert cov["format"] == "stressbots.coverage/1" and cov["trials"] == 1 and cov["noise_scales"] == [1.0]
    regions = {(x["region"], x["robot"]) for x in cov["regions"]}
    assert ("rendezvous-capture", "C+A") in regions and ("capture", "D") in regions  # D_3 = C, D_2 = A, D_1 = D
    for x in cov["regions"]:
        assert 0 <= x["inside"] <= x["samples"] == 1 and x["seed_verdict"] in ("no", "no / no")
        assert x["inside"] == sum(s["inside"] for s in cov["samples"] if s["region"] == x["region"] and s["robot"] == x["robot"])
    assert (out / "coverage.png").stat().st_size > 10_000
    assert "rendezvous-capture" in (out / "coverage.html").read_text()


def test_bounds_rejects_bad_scales(run_cli):
    assert_user_error(run_cli("bounds", EXAMPLES / "four-robots.toml", "--trials", "1", "--scales", "1,x"), "--scales")


def test_report_section_lists_the_regions():
    from stressbots.report import coverage_page

    doc = {"scenario": "s", "trials": 4, "seed": 0, "noise_scales": [1.0], "successes": [4], "moments": {"capture": "start"},
           "regions": [{"region": "capture", "robot": "B", "size": "|e_f|<=30 um", "scale": 1.0, "inside": 3, "samples": 4,
                        "fraction": 0.75, "low": 0.3, "high": 0.95, "seed_verdict": "no"}]}
    html = coverage_page(doc, b"\x89PNG", title="t")
    assert "3/4" in html and "75 %" in html and "30-95 %" in html and "data:image/png;base64," in html


@settings(max_examples=80, deadline=None)
@given(st.floats(-100, 100), st.floats(-1.4, 1.4), st.floats(100, 400), st.floats(20, 120))
def test_capture_offset_is_mirror_symmetric_and_the_region_its_limits(e, psi, length, width):
    assert float(C.capture_offset(-e, -psi, length, width)) == pytest.approx(-float(C.capture_offset(e, psi, length, width)), abs=1e-9)
    cap = C.DockingCapture(30.0, math.radians(45.0), length, width)
    lo, hi = cap.lateral_limits(psi)
    inside = bool(cap.contains(e, psi))
    assert inside == (abs(psi) <= cap.cone_rad and float(lo) - 1e-9 <= e <= float(hi) + 1e-9) or abs(e - float(lo)) < 1e-6 or abs(
        e - float(hi)) < 1e-6


def test_main_job_report_shows_the_controller_regions(tmp_path):
    from stressbots.pipeline import coverage_extra, run_job
    from stressbots.scenario import load

    scn = load(_three_robots(tmp_path))
    calls: list[tuple[int, int]] = []
    job = run_job(scn, tmp_path / "job", seed=0, extra=coverage_extra(1, scales=(1.0,), progress=lambda d, t: calls.append((d, t))))
    html = job.report_path.read_text()
    assert "Controller regions" in html and "rendezvous-capture" in html
    assert (tmp_path / "job" / "coverage.png").stat().st_size > 10_000 and "coverage.png" in job.files
    assert job.extra["controller_coverage"]["trials"] == 1 and calls == [(1, 1)]
