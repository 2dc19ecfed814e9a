"""Hysteresis, admissible levels, accessible control states, STRING, primitives, shortest level sequences.

The truth here is independent of the library: a plain-Python BFS over a fine grid of levels
(:mod:`tests.electro_reference`) and a STRING classifier that tries every permutation.
"""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import stressbots.electrostatics as es
from stressbots.electrostatics import (
    Electrodes,
    admissible_levels,
    analyse,
    analyse_scenario,
    analyse_thresholds,
    apply_level,
    classify_string,
    level_sequence,
    reachable_states,
)
from stressbots.errors import DesignError, WaveformError
from stressbots.scenario import load

from .conftest import EXAMPLES
from .electro_reference import (
    brute_force_states,
    brute_shortest,
    hysteresis,
    integer_designs,
    string_float_designs,
    string_integer_designs,
    string_orders,
)


def prefix_states(order, n):
    """The n+1 states "D_1..D_k down" of Lemma 1, scenario order."""
    out = set()
    for k in range(n + 1):
        s = [0] * n
        for i in order[:k]:
            s[i] = 1
        out.add(tuple(s))
    return out


# ----------------------------------------------------------------------------------------------------
# Hysteresis and levels


def test_hysteresis_rule_at_and_between_thresholds():
    vd, vu = np.array([100.0, 150.0]), np.array([20.0, 40.0])
    assert apply_level([0, 0], 100.0, vd, vu).tolist() == [1, 0]  # V == V_d snaps down
    assert apply_level([1, 1], 40.0, vd, vu).tolist() == [1, 0]  # V == V_u releases
    assert apply_level([1, 0], 60.0, vd, vu).tolist() == [1, 0]  # between: unchanged
    assert apply_level([0, 1], 60.0, vd, vu).tolist() == [0, 1]
    assert apply_level([1, 1], 0.0, vd, vu).tolist() == [0, 0]
    # Broadcasts over fabricated sets (trials, n).
    many = apply_level(np.zeros((3, 2)), 120.0, np.array([[100, 150], [130, 150], [90, 110]]), vu)
    assert many.tolist() == [[1, 0], [0, 0], [1, 1]]


def test_admissible_levels_of_the_example():
    s = load(EXAMPLES / "four-robots.toml")
    t = admissible_levels(s.snap_down_V, s.release_V, s.electrodes)
    # 0 V below the lowest V_u, mid-gaps, the middle of the big gap, max_V above the highest V_d.
    assert t.volts.tolist() == [0.0, 22.5, 37.5, 52.5, 90.0, 130.0, 150.0, 172.5, 200.0]
    thresholds = np.concatenate([s.snap_down_V, s.release_V])
    assert np.all(np.abs(t.volts[:, None] - thresholds[None, :]) >= 5.0)
    assert t.changes.tolist() == [True] * 4 + [False] + [True] * 4


def test_a_level_exactly_margin_from_two_thresholds_counts():
    # Snap-down voltages 100 and 110 with margin 5: only 105 V separates them, exactly 5 V from both.
    e = Electrodes(max_V=200.0, margin_V=5.0, drive_low_V=40.0, drive_high_V=60.0)
    a = analyse_thresholds([100.0, 110.0], [10.0, 20.0], e)
    assert a.is_string and a.count == 3
    assert 105.0 in a.levels.volts.tolist()
    assert a.raise_levels_V is not None and a.raise_levels_V[1] == 105.0
    # A hair closer (both kinds) and no level tells them apart: only all-up and all-down remain.
    b = analyse_thresholds([100.0, 109.99], [10.0, 19.99], e)
    assert not b.is_string and b.count == 2
    assert {tuple(r) for r in b.accessible_states} == {(0, 0), (1, 1)}
    # Only the snap-down voltages close: "first only" is still reached by overshooting (raise both, release
    # the second), but the design is not STRING.
    c = analyse_thresholds([100.0, 109.99], [10.0, 20.0], e)
    assert c.count == 3 and not c.is_string
    assert level_sequence(c, [0, 0], [1, 0]) == (200.0, 15.0)


def test_margin_zero_allows_levels_on_thresholds():
    # A releases at 20 V and B snaps down at 20 V: with margin 0 the level 20 V does both at once.
    e = Electrodes(max_V=50.0, margin_V=0.0, drive_low_V=25.0, drive_high_V=26.0)
    vd, vu = [30.0, 20.0], [20.0, 5.0]
    a = analyse_thresholds(vd, vu, e, names=["A", "B"])
    truth = brute_force_states(vd, vu, 50.0, 0.0)
    assert {tuple(r) for r in a.accessible_states} == truth
    assert 20.0 in a.levels.volts.tolist()


def test_no_admissible_level_leaves_only_all_up():
    e = Electrodes(max_V=20.0, margin_V=50.0, drive_low_V=1.0, drive_high_V=2.0)
    a = analyse_thresholds([10.0, 15.0], [5.0, 8.0], e)
    assert len(a.levels) == 0 and a.accessible_states.tolist() == [[0, 0]]


# ----------------------------------------------------------------------------------------------------
# The example and STRING classification


def test_example_is_string_with_five_states():
    a = analyse_scenario(load(EXAMPLES / "four-robots.toml"))
    assert a.is_string and a.method == "lemma1"
    assert a.order == ("B", "D", "A", "C")
    assert a.count == 5
    assert [p.turning for p in a.primitives] == [(), ("B",), ("B", "D"), ("B", "D", "A"), ("B", "D", "A", "C")]
    assert a.primitives[2].state == (0, 1, 0, 1)  # scenario order A B C D
    # M[i][k] = 1 iff i <= k (1-based): D_i turns under P_k.
    expected = np.array([[1 if i <= k else 0 for k in range(5)] for i in range(1, 5)])
    assert np.array_equal(a.control_matrix, expected)
    j = a.to_json_dict()
    assert j == {
        "robots": ["A", "B", "C", "D"],
        "string": True,
        "order": ["B", "D", "A", "C"],
        "accessible_states": [[0, 0, 0, 0], [0, 1, 0, 0], [0, 1, 0, 1], [1, 1, 0, 1], [1, 1, 1, 1]],
        "count": 5,
    }
    assert all(type(x) is int for row in j["accessible_states"] for x in row)


@pytest.mark.parametrize(
    "vd, vu, words",
    [
        ([120.0, 140.0], [40.0, 30.0], "do not rise"),
        ([120.0, 120.0], [30.0, 30.0], "share both"),
        ([120.0, 125.0], [30.0, 45.0], "snap-down voltages closer than 2*margin_V"),
        ([120.0, 140.0], [30.0, 33.0], "release voltages closer"),
        ([120.0, 140.0], [30.0, 70.0], "drive_low_V - 2*margin_V = 65"),
        ([110.0, 140.0], [30.0, 40.0], "drive_high_V + 2*margin_V = 115"),
        ([120.0, 140.0], [3.0, 40.0], "below the lowest release voltage"),
        ([120.0, 198.0], [30.0, 40.0], "above the highest snap-down voltage"),
    ],
)
def test_not_string_reasons(vd, vu, words):
    v = classify_string(vd, vu, Electrodes(), names=["X", "Y"])
    assert not v.is_string
    assert any(words in r for r in v.reasons), v.reasons
    a = analyse_thresholds(vd, vu, Electrodes(), names=["X", "Y"])
    assert a.order is None and a.method == "search"
    assert {tuple(r) for r in a.accessible_states} == {p.state for p in a.primitives}
    assert a.primitives[0].state == (0, 0)  # P0 is all up


def test_margin_zero_drive_band_rule_is_strict():
    # With margin 0 a snap-down voltage equal to drive_high_V would be snapped by the band itself.
    e = Electrodes(max_V=200.0, margin_V=0.0, drive_low_V=75.0, drive_high_V=105.0)
    assert classify_string([106.0, 150.0], [10.0, 75.0 - 1e-6], e).is_string
    v = classify_string([105.0, 150.0], [10.0, 20.0], e, names=["X", "Y"])
    assert not v.is_string and "X (105 V)" in v.reasons[0]
    assert not classify_string([120.0, 150.0], [10.0, 75.0], e).is_string


def test_d1_has_lowest_snap_down_ties_broken_by_release():
    e = Electrodes()
    v = classify_string([140.0, 140.0, 120.0], [50.0, 30.0, 15.0], e, names=["a", "b", "c"])
    assert v.is_string and v.order == (2, 1, 0)


# ----------------------------------------------------------------------------------------------------
# Lemma 1 and general designs against the brute force


@settings(max_examples=120)
@given(string_float_designs())
def test_lemma1_string_systems_have_exactly_the_prefix_states(design):
    """Lemma 1 via the GENERAL search (not the closed form), on real-valued random STRING systems."""
    vd, vu, e, order = design
    n = len(vd)
    searched = analyse_thresholds(vd, vu, e, method="search")
    assert searched.is_string
    assert searched.order_index == order
    assert {tuple(r) for r in searched.accessible_states} == prefix_states(order, n)
    assert searched.count == n + 1
    fast = analyse_thresholds(vd, vu, e)
    assert fast.method == "lemma1"
    assert np.array_equal(fast.accessible_states, searched.accessible_states)
    assert fast.to_json_dict() == searched.to_json_dict()


@settings(max_examples=200)
@given(integer_designs())
def test_general_designs_match_brute_force(design):
    vd, vu, e = design
    n = len(vd)
    a = analyse_thresholds(vd, vu, e)
    truth = brute_force_states(vd, vu, e.max_V, e.margin_V)
    got = [tuple(r) for r in a.accessible_states.tolist()]
    assert set(got) == truth
    assert got == sorted(got)  # sorted like Python sorts lists (the JSON contract)
    assert a.count == len(truth)
    orders = string_orders(vd, vu, e)
    assert a.is_string == bool(orders)
    if a.is_string:
        assert a.order_index in orders
        assert set(got) == prefix_states(a.order_index, n)  # Lemma 1 on the brute force too
    assert a.to_json_dict()["accessible_states"] == [list(s) for s in got]


@settings(max_examples=120)
@given(string_integer_designs())
def test_string_integer_designs_match_brute_force_and_permutation_classifier(design):
    vd, vu, e = design
    a = analyse_thresholds(vd, vu, e)
    orders = string_orders(vd, vu, e)
    assert a.is_string and orders == [a.order_index]
    assert {tuple(r) for r in a.accessible_states} == brute_force_states(vd, vu, e.max_V, e.margin_V)


@settings(max_examples=60)
@given(integer_designs(max_n=4), st.data())
def test_shortest_level_sequence_matches_brute_force(design, data):
    vd, vu, e = design
    a = analyse_thresholds(vd, vu, e)
    start = a.accessible_states[data.draw(st.integers(0, a.count - 1))]
    target = a.accessible_states[data.draw(st.integers(0, a.count - 1))]
    best = brute_shortest(vd, vu, e.max_V, e.margin_V, start, target)
    try:
        levels = level_sequence(a, start, target)
    except WaveformError:
        assert best is None
        return
    assert len(levels) == best
    s = tuple(int(x) for x in start)
    for v in levels:
        assert 0.0 <= v <= e.max_V
        assert all(abs(v - t) >= e.margin_V - 1e-9 for t in list(vd) + list(vu))
        s = hysteresis(s, v, vd, vu)
    assert s == tuple(int(x) for x in target)


@settings(max_examples=80)
@given(string_float_designs(max_n=6), st.data())
def test_string_closed_form_matches_search(design, data):
    """SPEC 4's closed form (one Hold, two across a tie) is as short as the general search."""
    vd, vu, e, order = design
    a = analyse_thresholds(vd, vu, e)
    j = data.draw(st.integers(0, a.n))
    k = data.draw(st.integers(0, a.n))
    sj, sk = np.array(a.primitives[j].state), np.array(a.primitives[k].state)
    closed = level_sequence(a, sj, sk)
    searched = es._search(a.levels.snaps, a.levels.releases, sj, target=sk)
    assert searched is not None and len(closed) == len(searched)
    assert a.raise_levels_V is not None and a.release_levels_V is not None
    assert len(closed) == (0 if j == k else 1 if (np.isfinite(a.raise_levels_V[k]) if k > j else np.isfinite(a.release_levels_V[k])) else 2)
    s = tuple(int(x) for x in sj)
    for v in closed:
        assert 0.0 <= v <= e.max_V
        assert np.all(np.abs(v - np.concatenate([vd, vu])) >= e.margin_V - 1e-9)
        s = hysteresis(s, v, vd, vu)
    assert s == a.primitives[k].state


def test_unreachable_target_raises():
    a = analyse_scenario(load(EXAMPLES / "four-robots.toml"))
    with pytest.raises(WaveformError, match="no admissible level sequence"):
        level_sequence(a, [0, 0, 0, 0], [0, 0, 1, 0])  # C alone down is not accessible


# ----------------------------------------------------------------------------------------------------
# Scale: nested designs, more than 64 robots, the state cap


def nested(n, margin=1.0):
    """Nested hysteresis windows: every one of the 2^n states is reachable."""
    vu = 5.0 + 4.0 * np.arange(n)
    vd = 195.0 - 4.0 * np.arange(n)
    return vd, vu, Electrodes(max_V=200.0, margin_V=margin, drive_low_V=90.0, drive_high_V=100.0)


def test_nested_design_reaches_every_state():
    vd, vu, e = nested(8)
    a = analyse_thresholds(vd, vu, e)
    assert not a.is_string and a.count == 2**8
    assert a.control_matrix.shape == (8, 256)
    assert a.primitives[0].state == (0,) * 8
    assert {tuple(r) for r in a.accessible_states} == brute_force_states(vd, vu, 200.0, 1.0)


def test_state_cap_gives_a_clear_error():
    vd, vu, e = nested(12)
    with pytest.raises(DesignError, match="more than 1000 accessible control states"):
        analyse_thresholds(vd, vu, e, max_states=1000, source="big.toml")
    with pytest.raises(DesignError, match="big.toml"):
        reachable_states(vd, vu, e, max_states=1000, source="big.toml")


def test_more_than_64_robots_uses_multiword_bitsets():
    n = 70
    vu = np.linspace(1.0, 60.0, n)
    vd = np.linspace(120.0, 190.0, n)
    perm = np.random.default_rng(3).permutation(n)
    e = Electrodes(margin_V=0.1)
    a = analyse_thresholds(vd[perm], vu[perm], e, method="search")
    assert a.is_string and a.count == n + 1
    assert np.array_equal(a.accessible_states, analyse_thresholds(vd[perm], vu[perm], e).accessible_states)
    # Not STRING (drive band too low for the top release voltages), same states, found by search.
    b = analyse_thresholds(vd[perm], vu[perm], Electrodes(margin_V=0.1, drive_low_V=50.0))
    assert not b.is_string and b.method == "search" and b.count == n + 1
    # Shortest path across 64-bit words: from all down to P3 is one release level.
    order = np.argsort(vd[perm])
    target = np.zeros(n, np.uint8)
    target[order[:3]] = 1
    assert len(level_sequence(b, np.ones(n, np.uint8), target)) == 1
    # 66 nested windows plus the search cap: a clean error, not a memory blow-up.
    vd2 = 199.0 - 1.2 * np.arange(66)
    vu2 = 1.0 + 1.2 * np.arange(66)
    with pytest.raises(DesignError):
        analyse_thresholds(vd2, vu2, Electrodes(margin_V=0.1, drive_low_V=90, drive_high_V=100), max_states=5000)


def test_analyse_accepts_robots_and_names_them():
    s = load(EXAMPLES / "four-robots.toml")
    a = analyse(s.robots, s.electrodes)
    assert a.names == ("A", "B", "C", "D")
    assert a.primitive("P2").turning == ("B", "D")
    p2 = a.primitive_for_state([0, 1, 0, 1])
    assert p2 is not None and p2.name == "P2"
    assert a.primitive_for_state([0, 0, 1, 0]) is None
    assert a.is_accessible(a.state_of(["B", "D"])) and not a.is_accessible(a.state_of(["C"]))
    with pytest.raises(KeyError):
        a.primitive("P9")


def test_docstring_examples():
    assert doctest.testmod(es).failed == 0
