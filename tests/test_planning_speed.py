"""The planner's fast collision checks and lazy roadmap search give the answers of the brute-force ones.

Truth: every edge sampled in full and every sample tested against every obstacle (no pruning), and a
Dijkstra search over the roadmap with every edge checked first (the eager search the lazy one replaces).
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from stressbots import paths as pathlib
from stressbots.planning import Obstacles, PlannerOptions
from stressbots.routing import _batch_samples, _edges_clear, _roadmap_edges, _roadmap_search

RADIUS, LENGTH, WIDTH = 200.0, 260.0, 60.0
OPTS = PlannerOptions()


def _obstacles(rng: np.random.Generator, k: int, b: int) -> Obstacles:
    return Obstacles(
        rng.uniform(300, 2700, (k, 2)), rng.uniform(150, 320, k), tuple(f"disc {i}" for i in range(k)),
        np.column_stack([rng.uniform(300, 2700, (b, 2)), rng.uniform(0, 2 * np.pi, b)]), np.full(b, LENGTH), np.full(b, WIDTH),
        tuple(f"box {i}" for i in range(b)), (3000.0, 3000.0),
    )


def _poses(rng: np.random.Generator, m: int) -> np.ndarray:
    return np.column_stack([rng.uniform(0, 3000, (m, 2)), rng.uniform(0, 2 * np.pi, m)])


def _brute_edges_clear(obst: Obstacles, starts, goals, recheck) -> np.ndarray:
    """The two-stage check without any pruning: every sample of every edge against every obstacle."""
    words, seg = pathlib.shortest_path_segments(starts, goals, RADIUS)

    def blocked(idx, step, clearance):
        poses, owner, _ = _batch_samples(starts[idx], seg[idx], np.asarray(words)[idx], RADIUS, step)
        bad = obst.hits(poses, LENGTH, WIDTH, clearance)
        return np.bincount(owner[bad], minlength=len(idx)) > 0

    step = 4.0 * OPTS.sample_um
    inflate = 0.5 * step * (1.0 + 0.5 * np.hypot(LENGTH, WIDTH) / RADIUS)
    clear = ~blocked(np.arange(len(starts)), step, OPTS.clearance_um + inflate)
    again = np.flatnonzero(~clear & recheck)
    clear[again] = ~blocked(again, OPTS.sample_um, OPTS.clearance_um)
    return clear


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31), k=st.integers(0, 8), b=st.integers(0, 4))
def test_pruned_edge_checks_match_brute_force(seed, k, b):
    rng = np.random.default_rng(seed)
    obst = _obstacles(rng, k, b)
    starts, goals = _poses(rng, 150), _poses(rng, 150)
    recheck = rng.random(150) < 0.5
    fast = _edges_clear(obst, starts, goals, RADIUS, LENGTH, WIDTH, OPTS, recheck=recheck)
    assert np.array_equal(fast, _brute_edges_clear(obst, starts, goals, recheck))


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**31), k=st.integers(1, 7))
def test_lazy_roadmap_search_finds_the_eager_route(seed, k):
    rng = np.random.default_rng(seed)
    obst = _obstacles(rng, k, 1)
    ns = 3
    nodes = _poses(rng, 60)
    nodes = nodes[~obst.hits(nodes, LENGTH, WIDTH, OPTS.clearance_um)]
    costs = rng.uniform(0, 300, ns)
    lazy = _roadmap_search(nodes, ns, costs, RADIUS, LENGTH, WIDTH, obst, OPTS, None, [], [])
    # eager: check every edge, then one Dijkstra over the clear ones
    pairs, lengths = _roadmap_edges(nodes, ns, RADIUS)
    ends = (pairs[:, 0] < ns) | (pairs[:, 1] == ns)
    ok = _edges_clear(obst, nodes[pairs[:, 0]], nodes[pairs[:, 1]], RADIUS, LENGTH, WIDTH, OPTS, recheck=ends)
    n = len(nodes)
    rows = np.concatenate([pairs[ok, 0], np.full(ns, n)])
    cols = np.concatenate([pairs[ok, 1], np.arange(ns)])
    vals = np.concatenate([lengths[ok], costs + 1e-9]) + 1e-9
    dist, pred = dijkstra(csr_matrix((vals, (rows, cols)), shape=(n + 1, n + 1)), indices=n, return_predecessors=True)
    if not np.isfinite(dist[ns]):
        assert lazy is None
        return
    assert lazy is not None
    seq = [ns]
    while pred[seq[-1]] != n:
        seq.append(int(pred[seq[-1]]))
    seq = seq[::-1]
    s, path, way = lazy
    assert s == seq[0]
    assert [tuple(w) for w in way] == [tuple(nodes[q]) for q in seq[1:]]
    assert abs(path.length - (dist[ns] - costs[s] - 1e-9 * len(seq) - 2e-9)) < 1e-6
