"""The simulator's plain-float fast paths and caches give the array forms' results to the last bit."""

from __future__ import annotations

import numpy as np
import pytest

from stressbots.collision import point_rectangle_distance
from stressbots.generate import LITERATURE_NOISE, random_scenario
from stressbots.kinematics import follow, move
from stressbots.robots import body_corners
from stressbots.sim import SimulatedPlant
from stressbots.sim.bodies import TOUCH_UM, depth, depth_one, wall_gap, wall_gap_one, with_trig
from stressbots.sim.compliance import contact_points
from stressbots.sim.search import drift_poses, drift_poses_one


def _drift_poses_on_arrays(b, drift, p0, idx, speed, kappa, taus):
    """The array form ``drift_poses`` replaced: drift.segments, follow and move on padded arrays."""
    tmax = float(taus.max())
    pieces = [drift.segments(int(i), b.odo[i], sp * tmax) for i, sp in zip(idx, speed, strict=False)]
    k = max(len(p[0]) for p in pieces)
    lengths = np.zeros((len(pieces), k))
    kd = np.zeros((len(pieces), k))
    for r, (ln, kv) in enumerate(pieces):
        lengths[r, : ln.size] = ln
        kd[r, : ln.size] = kv
    curv = kappa[:, None] + kd
    nodes = follow(p0, lengths, curv)
    cum = np.concatenate([np.zeros((len(pieces), 1)), np.cumsum(lengths, axis=1)], axis=1)
    s = np.minimum(speed[None, :] * taus[:, None], cum[None, :, -1])
    last = np.array([p[0].size - 1 for p in pieces])
    j = np.minimum((s[..., None] >= cum[None, :, 1:]).sum(axis=-1), last[None, :])
    rows = np.arange(len(pieces))[None, :]
    return move(nodes[rows, j], s - cum[rows, j], curv[rows, j])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_drift_poses_in_plain_floats_are_the_array_forms_bit_for_bit(seed):
    """``drift_poses`` (joints in plain floats) and ``drift_poses_one`` (all in plain floats) against the
    array form, at one time and at many."""
    scn = random_scenario(4, 900 + seed, shape="tee", noise=LITERATURE_NOISE.scaled(3.0))
    plant = SimulatedPlant(scn, seed=seed)
    b, drift = plant._bodies, plant._drift
    rng = np.random.default_rng(seed)
    idx = np.arange(4)
    for _ in range(50):
        b.odo = rng.uniform(0.0, 3000.0, 4) * (rng.random(4) < 0.8)
        speed = rng.uniform(20.0, 150.0, 4)
        kappa = np.where(rng.random(4) < 0.5, 1.0 / rng.uniform(100.0, 400.0, 4), 0.0)
        tau = float(rng.choice([0.0, 1e-9, rng.uniform(0.0, 2.0)]))
        fast = drift_poses_one(b, drift, b.pose, idx, speed, kappa, tau)
        assert np.array_equal(fast, _drift_poses_on_arrays(b, drift, b.pose, idx, speed, kappa, np.array([tau]))[0])
        taus = np.linspace(0.0, tau, 7)
        want = _drift_poses_on_arrays(b, drift, b.pose, idx, speed, kappa, taus)
        assert np.array_equal(drift_poses(b, drift, b.pose, idx, speed, kappa, taus), want)


def test_one_pair_depth_and_wall_gap_in_plain_floats_are_the_array_kernels_bit_for_bit():
    """``depth_one`` and ``wall_gap_one`` against ``depth`` and ``wall_gap`` on touching, crossing and far
    pairs of random sizes (the contact rules' probes use the float forms)."""
    rng = np.random.default_rng(4)
    m = 2000
    pa = np.column_stack([rng.uniform(0, 400, m), rng.uniform(0, 400, m), rng.uniform(-7, 7, m)])
    pb = pa + np.column_stack([rng.normal(0, 150, m), rng.normal(0, 150, m), rng.choice([0.0, np.pi / 2, 1.0], m)])
    hla, hwa, hlb, hwb = (rng.uniform(10, 130, m) for _ in range(4))
    want = depth(pa, pb, hla, hwa, hlb, hwb)
    ta, tb = with_trig([tuple(p) for p in pa.tolist()]), with_trig([tuple(p) for p in pb.tolist()])
    got = [depth_one(a, b, *h) for a, b, *h in zip(ta, tb, hla.tolist(), hwa.tolist(), hlb.tolist(), hwb.tolist(), strict=True)]
    assert np.array_equal(np.array(got), want)
    arena = (500.0, 450.0)
    gaps = [wall_gap_one(a, hl, hw, arena) for a, hl, hw in zip(ta, hla.tolist(), hwa.tolist(), strict=True)]
    assert np.array_equal(np.array(gaps), wall_gap(pa, hla, hwa, arena))


def test_the_geometry_remembered_at_the_poses_is_forgotten_when_anybody_moves():
    """``Bodies.pair_depths`` / ``wall_gaps`` / ``within_reach`` are recomputed after a move in place."""
    scn = random_scenario(4, 901, shape="tee", noise=LITERATURE_NOISE)
    b = SimulatedPlant(scn, seed=0)._bodies
    d0, g0, r0 = b.pair_depths(), b.wall_gaps(), b.within_reach()
    assert b.pair_depths() is d0 and b.wall_gaps() is g0 and b.within_reach() is r0
    b.pose[1, 0] += 1e-9
    assert b.pair_depths() is not d0 and b.wall_gaps() is not g0 and b.within_reach() is not r0
    P = b.pose
    assert np.array_equal(b.pair_depths(), depth(P[b.I], P[b.J], b.hl[b.I], b.hw[b.I], b.hl[b.J], b.hw[b.J]))
    assert np.array_equal(b.wall_gaps(), wall_gap(P, b.hl, b.hw, b.arena))


def _contact_points_on_arrays(b, i, j):
    """The array form ``contact_points`` replaced (body_corners, point_rectangle_distance)."""
    P = b.pose
    ci = body_corners(P[i], 2 * b.hl[i], 2 * b.hw[i])[0]
    cj = body_corners(P[j], 2 * b.hl[j], 2 * b.hw[j])[0]
    eps = max(TOUCH_UM, 2.0 * b.pair_depth(i, j)) + 1e-9
    di = point_rectangle_distance(ci, P[j], 2 * b.hl[j], 2 * b.hw[j])[0]
    dj = point_rectangle_distance(cj, P[i], 2 * b.hl[i], 2 * b.hw[i])[0]
    pts = np.vstack([ci[di <= eps], cj[dj <= eps]])
    own = np.concatenate([np.ones(int((di <= eps).sum()), bool), np.zeros(int((dj <= eps).sum()), bool)])
    if pts.shape[0] == 0:
        pts = np.vstack([ci[[int(np.argmin(di))]], cj[[int(np.argmin(dj))]]])
        own = np.array([True, False])
    return pts, own


def test_contact_points_in_plain_floats_are_the_array_forms_bit_for_bit():
    """Touching corners of pairs placed flush, at a corner, crossing and apart (the fallback)."""
    scn = random_scenario(2, 902, shape="tee", noise=LITERATURE_NOISE)
    b = SimulatedPlant(scn, seed=0)._bodies
    rng = np.random.default_rng(6)
    hl0, hw0, hl1 = float(b.hl[0]), float(b.hw[0]), float(b.hl[1])
    for k in range(400):
        th = rng.uniform(0, 2 * np.pi)
        h = np.array([np.sin(th), np.cos(th)])
        b.pose[0] = (rng.uniform(100, 300), rng.uniform(100, 300), th)
        off = [hl0 + hl1, hl0 + hl1 + rng.normal(0, 1e-6), rng.uniform(0, 2 * (hl0 + hl1))][k % 3]
        side = rng.uniform(-hw0, hw0) * np.array([h[1], -h[0]])
        b.pose[1, :2] = b.pose[0, :2] + off * h + side
        b.pose[1, 2] = th + [np.pi, np.pi + rng.normal(0, 0.3), rng.uniform(0, 7)][k % 3]
        got, want = contact_points(b, 0, 1), _contact_points_on_arrays(b, 0, 1)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
