"""Independent reference implementations and Hypothesis strategies for the electrostatic tests.

Nothing here calls :mod:`stressbots.electrostatics`: the brute force enumerates a fine grid of levels with
plain Python, so it can disagree with the library's cell analysis and bitset search.
"""

from __future__ import annotations

import itertools
from collections import deque

import numpy as np
from hypothesis import strategies as st

from stressbots.electrostatics import Electrodes


def hysteresis(state: tuple[int, ...], volts: float, vd, vu) -> tuple[int, ...]:
    """SPEC 4 literally: down if V >= V_d, up if V <= V_u, else unchanged."""
    return tuple(1 if volts >= d else (0 if volts <= u else s) for s, d, u in zip(state, vd, vu, strict=False))


def grid_levels(vd, vu, max_V: float, margin: float, step: float = 0.5) -> list[float]:
    """Every grid level in [0, max_V] at least ``margin`` from every threshold.

    Exhaustive (it hits every cell of admissible levels) for integer thresholds and ``max_V`` and a
    margin that is a multiple of 0.5 with ``step = 0.5``: every admissible interval then has an endpoint
    on the grid, and every open gap between distinct integers contains a half-integer.
    """
    ts = list(vd) + list(vu)
    count = int(round(max_V / step))
    return [k * step for k in range(count + 1) if all(abs(k * step - t) >= margin for t in ts)]


def brute_force_states(vd, vu, max_V: float, margin: float, step: float = 0.5) -> set[tuple[int, ...]]:
    """Accessible control states by BFS over the grid levels (plain Python)."""
    levels = grid_levels(vd, vu, max_V, margin, step)
    start = tuple(0 for _ in vd)
    seen = {start}
    todo = deque([start])
    while todo:
        s = todo.popleft()
        for v in levels:
            s2 = hysteresis(s, v, vd, vu)
            if s2 not in seen:
                seen.add(s2)
                todo.append(s2)
    return seen


def brute_shortest(vd, vu, max_V: float, margin: float, start, target, step: float = 0.5) -> int | None:
    """Fewest grid levels from ``start`` to ``target`` (None if unreachable)."""
    levels = grid_levels(vd, vu, max_V, margin, step)
    start, target = tuple(int(x) for x in start), tuple(int(x) for x in target)
    dist = {start: 0}
    todo = deque([start])
    while todo:
        s = todo.popleft()
        if s == target:
            return dist[s]
        for v in levels:
            s2 = hysteresis(s, v, vd, vu)
            if s2 not in dist:
                dist[s2] = dist[s] + 1
                todo.append(s2)
    return None


def string_orders(vd, vu, e: Electrodes) -> list[tuple[int, ...]]:
    """All orderings D_1..D_n that make the design STRING (SPEC 4 + the [0, max_V] ends), by permutation."""
    n = len(vd)
    m = e.margin_V
    tol = 1e-9
    for vals in (sorted(set(vd)), sorted(set(vu))):
        if any(b - a < 2 * m - 2 * tol for a, b in zip(vals, vals[1:], strict=False)):
            return []
    if max(vu) > e.drive_low_V - 2 * m + tol or min(vd) < e.drive_high_V + 2 * m - tol:
        return []
    if max(vu) >= e.drive_low_V or min(vd) <= e.drive_high_V:  # the band itself would flip an arm
        return []
    if min(vu) < m - tol or max(vd) > e.max_V - m + tol:
        return []
    good = []
    for perm in itertools.permutations(range(n)):
        d = [vd[i] for i in perm]
        u = [vu[i] for i in perm]
        if all(d[k] <= d[k + 1] and u[k] <= u[k + 1] and not (d[k] == d[k + 1] and u[k] == u[k + 1]) for k in range(n - 1)):
            good.append(perm)
    return good


# ----------------------------------------------------------------------------------------------------
# Strategies


@st.composite
def integer_designs(draw, max_n: int = 5):
    """Random designs (STRING or not) with integer thresholds, so :func:`grid_levels` is exhaustive."""
    n = draw(st.integers(1, max_n))
    vu = [draw(st.integers(0, 70)) for _ in range(n)]
    vd = [u + draw(st.integers(1, 70)) for u in vu]
    max_v = draw(st.integers(max(5, min(vd) - 10), 150))
    margin = draw(st.sampled_from([0.0, 0.0, 0.5, 1.0, 2.0, 3.0, 5.0]))
    low = draw(st.integers(0, max_v - 1))
    high = draw(st.integers(low + 1, max_v))
    e = Electrodes(max_V=float(max_v), margin_V=margin, drive_low_V=float(low), drive_high_V=float(high))
    return [float(x) for x in vd], [float(x) for x in vu], e


@st.composite
def string_integer_designs(draw, max_n: int = 5):
    """STRING designs with integer thresholds (ties allowed), in shuffled file order."""
    n = draw(st.integers(1, max_n))
    margin = draw(st.sampled_from([0, 1, 2, 3]))
    gap = 2 * margin if margin else 1
    u, d = [draw(st.integers(margin, margin + 5))], [0]
    for _ in range(n - 1):
        kind = draw(st.sampled_from(["both", "both", "share_d", "share_u"]))
        du = 0 if kind == "share_u" else draw(st.integers(gap, gap + 4))
        dd = 0 if kind == "share_d" else draw(st.integers(gap, gap + 4))
        u.append(u[-1] + du)
        d.append(d[-1] + dd)
    low = u[-1] + 2 * margin + draw(st.integers(0 if margin else 1, 3))
    high = low + draw(st.integers(1, 10))
    base = high + 2 * margin + draw(st.integers(0 if margin else 1, 3))
    d = [base + x for x in d]
    max_v = d[-1] + margin + draw(st.integers(0, 5))
    perm = draw(st.permutations(range(n)))
    e = Electrodes(max_V=float(max_v), margin_V=float(margin), drive_low_V=float(low), drive_high_V=float(high))
    return [float(d[i]) for i in perm], [float(u[i]) for i in perm], e


@st.composite
def string_float_designs(draw, max_n: int = 8):
    """STRING designs with real-valued thresholds, margins on or off, ties allowed, shuffled order.

    Returns ``(vd, vu, electrodes, order)`` where ``order`` is D_1..D_n as file indices.
    """
    n = draw(st.integers(1, max_n))
    margin = draw(st.one_of(st.just(0.0), st.floats(0.1, 4.0)))
    step = st.floats(2 * margin + 1e-3, 2 * margin + 15.0)
    u, d = [margin + draw(st.floats(0.0, 10.0))], [0.0]
    for _ in range(n - 1):
        kind = draw(st.sampled_from(["both", "both", "share_d", "share_u"]))
        u.append(u[-1] + (0.0 if kind == "share_u" else draw(step)))
        d.append(d[-1] + (0.0 if kind == "share_d" else draw(step)))
    low = u[-1] + 2 * margin + draw(st.floats(0.0 if margin else 0.01, 5.0))
    high = low + draw(st.floats(1.0, 20.0))
    base = high + 2 * margin + draw(st.floats(0.0 if margin else 0.01, 5.0))
    d = [base + x for x in d]
    max_v = d[-1] + margin + draw(st.floats(0.0, 10.0))
    perm = draw(st.permutations(range(n)))
    e = Electrodes(max_V=max_v, margin_V=margin, drive_low_V=low, drive_high_V=high)
    vd = np.array([d[i] for i in perm])
    vu = np.array([u[i] for i in perm])
    inverse = np.argsort(perm)  # file index of D_k is inverse[k]
    return vd, vu, e, tuple(int(i) for i in inverse)
