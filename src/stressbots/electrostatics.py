"""Electrostatic control: arm hysteresis, accessible control states, STRING designs, primitives.

SPEC section 4. Every robot sees the same voltage. A robot's steering arm snaps down when the applied
level reaches its snap-down voltage ``V_d`` and releases when the level falls to its release voltage
``V_u`` (``V_u < V_d``); in between it keeps its state. At 0 V every arm is up.

What this module computes, exactly, for any design:

- the *admissible levels*: every level in ``[0, max_V]`` at least ``margin_V`` from every threshold.
  They fall into at most ``4n + 1`` cells (the gaps between consecutive distinct thresholds, and the
  thresholds themselves when the margin is 0), each with one effect on the arms: the arms it snaps
  down (``V >= V_d``) and the arms it releases (``V <= V_u``). A level maps a control state ``s`` to
  ``(s & ~releases) | snaps``;
- the *accessible control states*: a breadth-first search over arm states (packed bitsets, vectorised
  with numpy) from all-up, applying every cell;
- the *STRING* verdict and the order ``D_1..D_n``; for a STRING design Lemma 1 gives the accessible
  states in closed form (the ``n + 1`` prefix states "D_1..D_k down"), which the tests check against
  the search;
- the *primitives* ``P_0..P_n`` and the control matrix ``M``;
- the shortest level sequence between two control states (fewest level changes).

Voltages are compared with a tolerance of :data:`TOLERANCE_V` (1 nV) where a margin is concerned, so a
level exactly ``margin_V`` from a threshold counts as admissible despite rounding. The hysteresis itself
(:func:`apply_level`) uses the exact thresholds.

Examples
--------
>>> from stressbots.electrostatics import Electrodes, analyse_thresholds
>>> a = analyse_thresholds([160.0, 120.0], [45.0, 15.0], Electrodes(), names=["A", "B"])
>>> a.is_string, a.order, a.count
(True, ('B', 'A'), 3)
>>> [p.turning for p in a.primitives]
[(), ('B',), ('B', 'A')]
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple

import numpy as np

from .errors import DesignError, WaveformError

__all__ = [
    "TOLERANCE_V",
    "DEFAULT_MAX_STATES",
    "Electrodes",
    "LevelTable",
    "StringVerdict",
    "Primitive",
    "ControlAnalysis",
    "apply_level",
    "admissible_levels",
    "classify_string",
    "reachable_states",
    "analyse",
    "analyse_thresholds",
    "analyse_scenario",
    "level_sequence",
]

#: Slack (volts) allowed when checking a margin, so that ``t + margin_V`` itself is admissible.
TOLERANCE_V = 1e-9

#: The state search stops with a :class:`~stressbots.errors.DesignError` beyond this many states.
DEFAULT_MAX_STATES = 1 << 21


@dataclass(frozen=True)
class Electrodes:
    """The electrode array's electrical limits (volts, hertz, seconds).

    Attributes
    ----------
    max_V:
        Largest level the hardware may apply. No waveform ever leaves ``[0, max_V]``.
    margin_V:
        delta_v: every applied level keeps at least this distance from every threshold, so that
        fabrication scatter does not flip an arm by accident.
    drive_low_V, drive_high_V:
        The power-delivery band. The scratch drives move while the signal oscillates between the two.
    drive_frequency_hz:
        Oscillation frequency of the power-delivery waveform.
    hold_s:
        How long a setting level is held to let arms snap or release (robots do not move meanwhile).
    """

    max_V: float = 200.0
    margin_V: float = 5.0
    drive_low_V: float = 75.0
    drive_high_V: float = 105.0
    drive_frequency_hz: float = 10000.0
    hold_s: float = 0.001


# ----------------------------------------------------------------------------------------------------
# Hysteresis


def apply_level(states, volts, snap_down_V, release_V) -> np.ndarray:
    """Arm states after applying one level: the hysteresis of SPEC 4, with the exact thresholds.

    ``s_i = 1`` if ``V >= V_d,i``; ``s_i = 0`` if ``V <= V_u,i``; otherwise unchanged. Broadcasts, so it
    serves one robot set (``states`` of shape ``(n,)``) as well as many fabricated sets at once
    (``(trials, n)`` thresholds).

    Parameters
    ----------
    states:
        Current arm states, 0 = up (straight), 1 = down (turning).
    volts:
        The applied level (V), a scalar or an array broadcastable against ``states``.
    snap_down_V, release_V:
        Thresholds ``V_d`` and ``V_u`` (V) per robot.

    Returns
    -------
    numpy.ndarray
        New arm states, ``uint8``.
    """
    v = np.asarray(volts, dtype=np.float64)
    vd = np.asarray(snap_down_V, dtype=np.float64)
    vu = np.asarray(release_V, dtype=np.float64)
    s = np.asarray(states, dtype=np.uint8)
    return np.where(v >= vd, np.uint8(1), np.where(v <= vu, np.uint8(0), s)).astype(np.uint8)


# ----------------------------------------------------------------------------------------------------
# Admissible levels


@dataclass(frozen=True, eq=False)
class LevelTable:
    """The admissible levels of a design, one row per distinct effect on the arms.

    Attributes
    ----------
    volts:
        ``(L,)`` the representative level of each cell (V): the admissible level furthest from every
        threshold (0 V below the lowest threshold, ``max_V`` above the highest, mid-gap in between).
        Sorted ascending.
    ranges_V:
        ``(L, 2)`` the admissible interval ``[low, high]`` of the cell (a single point for a threshold
        cell, which exists only when ``margin_V`` is 0).
    clearance_V:
        ``(L,)`` distance from the representative level to the nearest threshold (V).
    snaps, releases:
        ``(L, n)`` bool: arms the level snaps down (``V >= V_d``) / releases (``V <= V_u``), scenario order.
    """

    volts: np.ndarray
    ranges_V: np.ndarray
    clearance_V: np.ndarray
    snaps: np.ndarray
    releases: np.ndarray

    def __len__(self) -> int:
        return int(self.volts.shape[0])

    @property
    def changes(self) -> np.ndarray:
        """``(L,)`` bool: the level changes some arm state (not the identity)."""
        return np.asarray(self.snaps.any(axis=1) | self.releases.any(axis=1))


def _thresholds(snap_down_V, release_V) -> tuple[np.ndarray, np.ndarray]:
    vd = np.asarray(snap_down_V, dtype=np.float64).reshape(-1)
    vu = np.asarray(release_V, dtype=np.float64).reshape(-1)
    if vd.shape != vu.shape:
        raise ValueError(f"snap_down_V and release_V differ in length ({vd.size} vs {vu.size})")
    if not (np.all(np.isfinite(vd)) and np.all(np.isfinite(vu))):
        raise ValueError("thresholds must be finite")
    return vd, vu


def _level_cells(t: np.ndarray, max_v: float, m_eff: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The admissible level cells between the sorted distinct thresholds ``t`` (V): ``(volts (L,),
    ranges (L, 2), clearances (L,))``, one per gap that holds a level, plus, when the required distance
    ``m_eff`` (margin minus tolerance) is not positive, the thresholds within ``[0, max_v]`` as points.

    A gap's representative is its midpoint clipped to the admissible interval (0 V below the lowest
    threshold, ``max_v`` above the highest); with margin 0 a clipped level that lands on a threshold
    moves to the middle of its interval, so it stays inside the open gap.
    """
    a = np.concatenate([[-np.inf], t])  # cell (a, b)
    b = np.concatenate([t, [np.inf]])
    if m_eff > 0:
        lo = np.maximum(a + m_eff, 0.0)
        hi = np.minimum(b - m_eff, max_v)
    else:
        lo = np.maximum(a, 0.0)
        hi = np.minimum(b, max_v)
    with np.errstate(invalid="ignore"):
        mid = 0.5 * (a + b)  # -inf below the lowest threshold, +inf above the highest
    rep = np.clip(mid, lo, hi)
    ok = (lo <= hi) & (rep > a) & (rep < b)
    if m_eff <= 0:  # margin 0: a clipped level may sit on a threshold; move it inside the open cell
        inside = (rep > a) & (rep < b)
        rep = np.where(inside, rep, 0.5 * (lo + hi))
        ok = (lo <= hi) & (rep > a) & (rep < b)
    volts = [rep[ok]]
    ranges = [np.stack([lo[ok], hi[ok]], axis=1)]
    clear = [np.minimum(rep[ok] - a[ok], b[ok] - rep[ok])]
    if m_eff <= 0:  # the thresholds themselves are admissible levels
        pts = t[(t >= 0.0) & (t <= max_v)]
        volts.append(pts)
        ranges.append(np.stack([pts, pts], axis=1))
        clear.append(np.zeros_like(pts))
    return np.concatenate(volts), np.concatenate(ranges).reshape(-1, 2), np.concatenate(clear)


def admissible_levels(snap_down_V, release_V, electrodes: Electrodes) -> LevelTable:
    """Every distinct effect an admissible level can have, with the best level for each.

    A level ``V`` is admissible when ``0 <= V <= max_V`` and ``|V - t| >= margin_V`` for every
    threshold ``t`` (up to :data:`TOLERANCE_V`). Between two consecutive distinct thresholds ``a < b``
    every level has the same effect, so the admissible levels form at most ``2n + 1`` interval cells
    ``[a + margin, b - margin]`` (clipped to ``[0, max_V]``) plus, when the margin is 0, the ``<= 2n``
    threshold points themselves. Cells with the same effect are merged, keeping the level with the
    larger clearance.

    Parameters
    ----------
    snap_down_V, release_V:
        ``(n,)`` thresholds (V), scenario order.
    electrodes:
        Supplies ``max_V`` and ``margin_V``.
    """
    vd, vu = _thresholds(snap_down_V, release_V)
    m_eff = float(electrodes.margin_V) - TOLERANCE_V  # required distance, with the tolerance
    v, r, c = _level_cells(np.unique(np.concatenate([vd, vu])), float(electrodes.max_V), m_eff)
    snaps = v[:, None] >= vd[None, :]
    rel = v[:, None] <= vu[None, :]
    # Merge cells with one effect (threshold points share the effect of a neighbouring gap).
    best: dict[bytes, int] = {}
    keys = np.packbits(np.concatenate([snaps, rel], axis=1), axis=1)
    for j in range(v.shape[0]):
        k = keys[j].tobytes()
        if k not in best or c[j] > c[best[k]]:
            best[k] = j
    keep = np.array(sorted(best.values(), key=lambda j: v[j]), dtype=np.intp)
    return LevelTable(
        volts=v[keep], ranges_V=r[keep], clearance_V=c[keep], snaps=snaps[keep], releases=rel[keep]
    )


# ----------------------------------------------------------------------------------------------------
# STRING classification


@dataclass(frozen=True)
class StringVerdict:
    """Whether a design is STRING (SPEC 4), the order ``D_1..D_n``, and why not if it is not.

    ``order`` holds scenario indices sorted by snap-down voltage (ties by release voltage, then file
    order); it is the STRING order when ``is_string``.
    """

    is_string: bool
    order: tuple[int, ...]
    reasons: tuple[str, ...]


def _listed(items: list[str], limit: int = 3) -> str:
    shown = "; ".join(items[:limit])
    return shown + (f"; and {len(items) - limit} more" if len(items) > limit else "")


def _volts(x: float) -> str:
    return f"{x:g} V"


def _order_reasons(sd: np.ndarray, su: np.ndarray, nm: list[str]) -> list[str]:
    """STRING rules 1 and 2 on the thresholds sorted by ``V_d`` (ties by ``V_u``): release voltages that
    fall along the order, and neighbours that share both thresholds."""
    reasons = []
    bad = [
        f"{nm[k]} (V_d {_volts(sd[k])}, V_u {_volts(su[k])}) comes before {nm[k + 1]} (V_d {_volts(sd[k + 1])}, "
        f"V_u {_volts(su[k + 1])})"
        for k in np.flatnonzero(su[1:] < su[:-1])
    ]
    if bad:
        reasons.append("release voltages do not rise with snap-down voltages: " + _listed(bad))
    same = [
        f"{nm[k]} and {nm[k + 1]} (V_d {_volts(sd[k])}, V_u {_volts(su[k])})"
        for k in np.flatnonzero((sd[1:] == sd[:-1]) & (su[1:] == su[:-1]))
    ]
    if same:
        reasons.append("robots share both thresholds, so no level tells them apart: " + _listed(same))
    return reasons


def _spacing_reasons(vd: np.ndarray, vu: np.ndarray, names: list[str], m: float) -> list[str]:
    """STRING rule 3: distinct thresholds of one kind closer than ``2 m`` (V), with no level between them."""
    reasons = []
    for kind, vals in (("snap-down", vd), ("release", vu)):
        uniq, first = np.unique(vals, return_index=True)
        gaps = np.diff(uniq)
        close = [
            f"{names[first[k]]} ({_volts(uniq[k])}) and {names[first[k + 1]]} ({_volts(uniq[k + 1])})"
            for k in np.flatnonzero(gaps < 2.0 * m - 2.0 * TOLERANCE_V)
        ]
        if close:
            reasons.append(
                f"{kind} voltages closer than 2*margin_V = {_volts(2 * m)}, so no level fits between them: " + _listed(close)
            )
    return reasons


def _drive_band_reasons(vd: np.ndarray, vu: np.ndarray, names: list[str], e: Electrodes) -> list[str]:
    """STRING rule 4: thresholds the drive band could cross (release above ``drive_low_V - 2 margin``,
    snap-down below ``drive_high_V + 2 margin``), strictly even with margin 0: a drive level equal to a
    threshold flips the arm."""
    m, tol = float(e.margin_V), TOLERANCE_V
    reasons = []
    u_max = e.drive_low_V - 2.0 * m
    high = [f"{names[i]} ({_volts(vu[i])})" for i in np.flatnonzero((vu > u_max + tol) | (vu >= e.drive_low_V))]
    if high:
        reasons.append(
            f"release voltages above drive_low_V - 2*margin_V = {_volts(u_max)} (the drive band could release the arm): "
            + _listed(high)
        )
    d_min = e.drive_high_V + 2.0 * m
    low = [f"{names[i]} ({_volts(vd[i])})" for i in np.flatnonzero((vd < d_min - tol) | (vd <= e.drive_high_V))]
    if low:
        reasons.append(
            f"snap-down voltages below drive_high_V + 2*margin_V = {_volts(d_min)} (the drive band could snap the arm "
            "down): " + _listed(low)
        )
    return reasons


def _crossing_reasons(vd: np.ndarray, vu: np.ndarray, names: list[str], e: Electrodes) -> list[str]:
    """STRING rule 5: no level >= 0 V below the lowest release voltage, or none <= ``max_V`` above the
    highest snap-down voltage (margins included)."""
    m, tol = float(e.margin_V), TOLERANCE_V
    reasons = []
    i_lo = int(np.argmin(vu))
    if vu[i_lo] < m - tol:
        reasons.append(
            f"no level >= 0 V fits below the lowest release voltage ({names[i_lo]}, {_volts(vu[i_lo])}) with margin_V {_volts(m)}"
        )
    i_hi = int(np.argmax(vd))
    if vd[i_hi] > e.max_V - m + tol:
        reasons.append(
            f"no level <= max_V ({_volts(e.max_V)}) fits above the highest snap-down voltage ({names[i_hi]}, {_volts(vd[i_hi])}) "
            f"with margin_V {_volts(m)}"
        )
    return reasons


def classify_string(snap_down_V, release_V, electrodes: Electrodes, names: Sequence[str] | None = None) -> StringVerdict:
    """Classify a design as STRING or not (SPEC 4), with the reasons when not.

    A STRING design can be ordered ``D_1..D_n`` so that

    1. both ``V_d`` and ``V_u`` are non-decreasing (the order is forced: by ``V_d``, ties by ``V_u``);
    2. no two robots share both values;
    3. distinct values of the same kind differ by at least ``2 margin_V`` (a level fits between them);
    4. the drive-band rule holds: every ``V_u <= drive_low_V - 2 margin_V`` and every
       ``V_d >= drive_high_V + 2 margin_V``, so one drive band serves every state (strictly
       ``V_u < drive_low_V`` and ``V_d > drive_high_V`` when the margin is 0: a drive level equal to a
       threshold would flip that arm, SPEC 4 "preserves every arm only if high_V < V_d ...");
    5. every threshold can be crossed: a level ``>= 0`` fits below the lowest ``V_u`` and a level
       ``<= max_V`` above the highest ``V_d`` (margins included).

    Rule 5 is SPEC 4's "a level fits with margin on each side" applied at the ends of ``[0, max_V]``;
    without it ``D_n`` could never snap down (or the group never return to ``P_0``), and Lemma 1's
    ``n + 1`` primitives would not all be usable.
    """
    vd, vu = _thresholds(snap_down_V, release_V)
    n = vd.size
    names = [str(x) for x in (names if names is not None else [f"#{i}" for i in range(n)])]
    order = np.lexsort((np.arange(n), vu, vd))  # by V_d, then V_u, then file order
    reasons = (
        _order_reasons(vd[order], vu[order], [names[i] for i in order])
        + _spacing_reasons(vd, vu, names, float(electrodes.margin_V))
        + _drive_band_reasons(vd, vu, names, electrodes)
        + _crossing_reasons(vd, vu, names, electrodes)
    )
    return StringVerdict(is_string=not reasons, order=tuple(int(i) for i in order), reasons=tuple(reasons))


# ----------------------------------------------------------------------------------------------------
# State search over packed bitsets


def _words(n: int) -> int:
    return max(1, -(-n // 64))


def _pack(bits: np.ndarray, n: int) -> np.ndarray:
    """``(k, n)`` 0/1 -> ``(k, W)`` uint64 bitsets; bit ``i % 64`` of word ``i // 64`` is arm ``i``."""
    bits = np.asarray(bits, dtype=np.uint8).reshape(-1, n)
    w = _words(n)
    padded = np.zeros((bits.shape[0], 64 * w), dtype=np.uint8)
    padded[:, :n] = bits
    return np.packbits(padded, axis=1, bitorder="little").view("<u8").astype(np.uint64).reshape(-1, w)


def _unpack(words: np.ndarray, n: int) -> np.ndarray:
    w = np.ascontiguousarray(words, dtype="<u8")
    return np.unpackbits(w.view(np.uint8), axis=1, bitorder="little")[:, :n].astype(np.uint8)


def _keys(words: np.ndarray) -> np.ndarray:
    """One sortable, hashable-by-numpy key per bitset row (the word itself when ``W == 1``)."""
    if words.shape[1] == 1:
        return words[:, 0]
    return np.ascontiguousarray(words).view(np.dtype((np.void, 8 * words.shape[1]))).ravel()


def _too_many(max_states: int, source: str | None) -> DesignError:
    return DesignError(
        f"more than {max_states} accessible control states; the search stops there (this design is far from "
        "STRING: most arm patterns are reachable)",
        source=source,
    )


class _BitsetLevels(NamedTuple):
    """The levels that change some arm, as bitset operations on packed states: a level ``j`` takes a
    state ``s`` to ``(s & keep[j]) | snaps[j]`` (it releases the arms outside ``keep``)."""

    useful: np.ndarray  # (L,) indices of these levels in the level table
    snaps: np.ndarray  # (L, W) uint64
    keep: np.ndarray  # (L, W) uint64


def _bitset_levels(snaps: np.ndarray, releases: np.ndarray) -> _BitsetLevels:
    n = snaps.shape[1]
    useful = np.flatnonzero(snaps.any(axis=1) | releases.any(axis=1))
    return _BitsetLevels(useful, _pack(snaps[useful], n), ~_pack(releases[useful], n))


def _fresh_successors(f: np.ndarray, levels: _BitsetLevels, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The successors of the frontier states ``f`` ``(F, W)`` under every level that ``seen`` (sorted keys)
    does not hold, each once: ``(keys, states, candidate index j = frontier row * L + level)``, or
    ``None`` when all are known."""
    W = levels.snaps.shape[1]
    cand = ((f[:, None, :] & levels.keep[None, :, :]) | levels.snaps[None, :, :]).reshape(-1, W)
    uk, first = np.unique(_keys(cand), return_index=True)
    pos = np.minimum(np.searchsorted(seen, uk), seen.shape[0] - 1)
    fresh = seen[pos] != uk
    if not fresh.any():
        return None
    idx = first[fresh]
    return uk[fresh], cand[idx], idx


@dataclass
class _NewLayer:
    """The states one breadth-first layer discovers, gathered chunk by chunk of the frontier: key, bitset,
    parent (row of the previous layer) and level index of each. Chunks may find the same state."""

    keys: list[np.ndarray] = field(default_factory=list)
    states: list[np.ndarray] = field(default_factory=list)
    parents: list[np.ndarray] = field(default_factory=list)
    levels: list[np.ndarray] = field(default_factory=list)
    pending: int = 0  # states gathered so far, counting a state once per chunk that found it

    def add(self, keys: np.ndarray, states: np.ndarray, parents: np.ndarray, levels: np.ndarray) -> None:
        self.keys.append(keys)
        self.states.append(states)
        self.parents.append(parents)
        self.levels.append(levels)
        self.pending += int(keys.size)

    def distinct(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(keys, states, parents, levels)`` of the distinct states, sorted by key (first finding kept)."""
        k_all, first = np.unique(np.concatenate(self.keys), return_index=True)
        return k_all, np.concatenate(self.states)[first], np.concatenate(self.parents)[first], np.concatenate(self.levels)[first]

    def compact(self) -> None:
        """Keep the distinct states only, so that :attr:`pending` counts each once."""
        k_all, states, parents, levels = self.distinct()
        self.keys, self.states, self.parents, self.levels = [k_all], [states], [parents], [levels]
        self.pending = int(k_all.size)

    def path_to(self, key, layers: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[int] | None:
        """The level indices from the start to the state ``key`` if the last chunk found it, backtracking
        through the completed ``layers`` (parent rows, level indices); else ``None``."""
        hit = np.flatnonzero(self.keys[-1] == key)
        if not hit.size:
            return None
        path = [int(self.levels[-1][hit[0]])]
        parent = int(self.parents[-1][hit[0]])
        for par, lev in reversed(layers):
            path.append(int(lev[parent]))
            parent = int(par[parent])
        return path[::-1]


def _search(
    snaps: np.ndarray,
    releases: np.ndarray,
    start: np.ndarray,
    *,
    target: np.ndarray | None = None,
    max_states: int | None = None,
    source: str | None = None,
):
    """Breadth-first search over arm states.

    ``snaps``/``releases`` are ``(L, n)`` bool level effects, ``start``/``target`` ``(n,)`` states.
    Without a target returns every reachable state ``(k, n)`` uint8 (unsorted). With a target returns the
    level indices of a shortest path to it, or ``None`` when it is unreachable.
    """
    max_states = DEFAULT_MAX_STATES if max_states is None else int(max_states)
    n = snaps.shape[1]
    levels = _bitset_levels(snaps, releases)
    L, W = levels.snaps.shape
    s0 = _pack(start, n)
    t_key = _keys(_pack(target, n))[0] if target is not None else None
    if t_key is not None and _keys(s0)[0] == t_key:
        return []
    seen = np.sort(_keys(s0))  # every state found so far, sorted, for O(log V) membership tests
    found = [s0]
    layers: list[tuple[np.ndarray, np.ndarray]] = []  # per BFS layer: parent index, level index
    frontier = s0
    chunk = max(1, 4_000_000 // max(1, L * W))  # bounds the candidate array to ~4M rows
    while frontier.shape[0] and L:
        layer = _NewLayer()
        for c0 in range(0, frontier.shape[0], chunk):
            fresh = _fresh_successors(frontier[c0 : c0 + chunk], levels, seen)
            if fresh is None:
                continue
            keys, states, idx = fresh
            layer.add(keys, states, c0 + idx // L, levels.useful[idx % L])
            if seen.shape[0] + layer.pending > max_states:
                layer.compact()  # chunks may share new states: count the distinct ones before giving up
                if seen.shape[0] + layer.pending > max_states:
                    raise _too_many(max_states, source)
            if t_key is not None and (path := layer.path_to(t_key, layers)) is not None:
                return path
        if not layer.keys:
            break
        new_keys, frontier, parents, level_idx = layer.distinct()  # dedupe across chunks
        if seen.shape[0] + new_keys.shape[0] > max_states:
            raise _too_many(max_states, source)
        layers.append((parents, level_idx))
        found.append(frontier)
        seen = np.sort(np.concatenate([seen, new_keys]))
    if t_key is not None:
        return None
    return _unpack(np.concatenate(found), n)


def _sorted_rows(states: np.ndarray) -> np.ndarray:
    """Rows sorted lexicographically (first robot most significant), as Python sorts lists."""
    if states.shape[0] <= 1:
        return states
    return states[np.lexsort(states.T[::-1])]


def reachable_states(
    snap_down_V,
    release_V,
    electrodes: Electrodes,
    *,
    start=None,
    max_states: int | None = None,
    source: str | None = None,
) -> np.ndarray:
    """Every control state reachable by admissible levels, by exhaustive search (any design).

    Parameters
    ----------
    snap_down_V, release_V:
        ``(n,)`` thresholds (V), scenario order.
    electrodes:
        ``max_V`` and ``margin_V`` bound the admissible levels.
    start:
        Initial arm states (default all up, the state at 0 V).
    max_states:
        Give up with a :class:`~stressbots.errors.DesignError` beyond this many states.

    Returns
    -------
    numpy.ndarray
        ``(k, n)`` uint8, rows sorted lexicographically, scenario order.
    """
    vd, vu = _thresholds(snap_down_V, release_V)
    table = admissible_levels(vd, vu, electrodes)
    s0 = np.zeros(vd.size, dtype=np.uint8) if start is None else np.asarray(start, dtype=np.uint8)
    return _sorted_rows(_search(table.snaps, table.releases, s0, max_states=max_states, source=source))


# ----------------------------------------------------------------------------------------------------
# The analysis


@dataclass(frozen=True)
class Primitive:
    """A control primitive: reach a control state, then drive.

    Attributes
    ----------
    name:
        ``"P0"``, ``"P1"``, ...
    index:
        ``k`` in ``P_k``. For a STRING design ``P_k`` has ``D_1..D_k`` down.
    state:
        Arm states in scenario order (1 = down = turning).
    turning:
        Names of the robots that turn under it (STRING: ``D_1..D_k`` in that order; otherwise scenario
        order).
    """

    name: str
    index: int
    state: tuple[int, ...]
    turning: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class ControlAnalysis:
    """Everything the global signal can do for one design.

    Attributes
    ----------
    names:
        Robot names, scenario order.
    snap_down_V, release_V:
        ``(n,)`` thresholds (V), scenario order.
    electrodes:
        The limits the analysis honours.
    is_string:
        The STRING verdict (:func:`classify_string`).
    order, order_index:
        ``D_1..D_n`` as names / scenario indices when STRING, else ``None``.
    reasons:
        Why the design is not STRING (empty when it is).
    accessible_states:
        ``(k, n)`` uint8, every accessible control state, rows sorted, scenario order.
    primitive_states:
        ``(k, n)`` uint8, row ``j`` is the arm state of ``P_j``. STRING: ``P_j`` has ``D_1..D_j`` down.
        Otherwise the accessible states themselves, ``P0`` = all up, then in sorted order. The
        :class:`Primitive` values are built on demand (:attr:`primitives`, :meth:`primitive_at`), since a
        non-STRING design can have millions.
    control_matrix:
        ``M``: STRING ``(n, n + 1)``, rows ``D_1..D_n``, ``M[i, k] = 1`` iff ``D_(i+1)`` turns under ``P_k``.
        Otherwise ``(n, k)``, rows in scenario order, columns the primitives.
    levels:
        The admissible levels (:func:`admissible_levels`).
    method:
        ``"lemma1"`` (closed form for a STRING design) or ``"search"``.
    raise_levels_V, release_levels_V:
        STRING only, ``(n + 1,)``: the one level that brings the group to ``P_k`` from a lower / higher
        primitive (NaN where ``P_k`` needs two levels because of a tie, or for ``k = 0`` / ``k = n``).
    """

    names: tuple[str, ...]
    snap_down_V: np.ndarray
    release_V: np.ndarray
    electrodes: Electrodes
    is_string: bool
    order: tuple[str, ...] | None
    order_index: tuple[int, ...] | None
    reasons: tuple[str, ...]
    accessible_states: np.ndarray
    primitive_states: np.ndarray
    control_matrix: np.ndarray
    levels: LevelTable
    method: str
    raise_levels_V: np.ndarray | None = None
    release_levels_V: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def count(self) -> int:
        """Number of accessible control states."""
        return int(self.accessible_states.shape[0])

    def to_json_dict(self) -> dict:
        """The ``states --json`` object of SPEC 7."""
        return {
            "robots": list(self.names),
            "string": bool(self.is_string),
            "order": list(self.order) if self.order is not None else None,
            "accessible_states": self.accessible_states.astype(int).tolist(),
            "count": self.count,
        }

    def primitive_at(self, k: int) -> Primitive:
        """``P_k`` (``IndexError`` if there is none)."""
        k = int(k)
        if not 0 <= k < self.primitive_states.shape[0]:
            raise IndexError(k)
        row = self.primitive_states[k]
        if self.is_string:
            assert self.order is not None  # a STRING design always has its order
            turning = self.order[:k]
        else:
            turning = tuple(self.names[i] for i in np.flatnonzero(row))
        return Primitive(f"P{k}", k, tuple(row.tolist()), turning)

    @cached_property
    def primitives(self) -> tuple[Primitive, ...]:
        """Every primitive, ``P_0, P_1, ...`` (see :attr:`primitive_states`)."""
        return tuple(self.primitive_at(k) for k in range(self.primitive_states.shape[0]))

    def primitive(self, name: str) -> Primitive:
        """The primitive called ``name``, e.g. ``"P2"`` (``KeyError`` if none)."""
        if name[:1] == "P" and name[1:].isdigit() and str(int(name[1:])) == name[1:]:
            k = int(name[1:])
            if k < self.primitive_states.shape[0]:
                return self.primitive_at(k)
        raise KeyError(name)

    def state_of(self, turning: Iterable[str]) -> np.ndarray:
        """Arm states ``(n,)`` with exactly the named robots down (``KeyError`` for an unknown name)."""
        index = {nm: i for i, nm in enumerate(self.names)}
        s = np.zeros(self.n, dtype=np.uint8)
        for nm in turning:
            s[index[nm]] = 1
        return s

    def primitive_for_state(self, state) -> Primitive | None:
        """The primitive with these arm states, or ``None`` when the state is not accessible."""
        s = np.asarray(state).reshape(1, -1)
        if s.shape[1] != self.n:
            return None
        hit = np.flatnonzero(np.all(self.primitive_states == s, axis=1))
        return self.primitive_at(int(hit[0])) if hit.size else None

    def is_accessible(self, state) -> bool:
        s = np.asarray(state, dtype=np.uint8).reshape(1, -1)
        if s.shape[1] != self.n:
            return False
        return bool(np.any(np.all(self.accessible_states == s, axis=1)))


def _string_levels(table: LevelTable, order: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For a STRING design: the level reaching ``P_k`` from below / from above, NaN where none."""
    n = order.size
    raise_v = np.full(n + 1, np.nan)
    release_v = np.full(n + 1, np.nan)
    ns = table.snaps[:, order].sum(axis=1)
    nr = table.releases[:, order].sum(axis=1)
    for j in range(len(table)):
        if nr[j] == 0 and ns[j] > 0:
            raise_v[ns[j]] = table.volts[j]
        elif ns[j] == 0 and nr[j] > 0:
            release_v[n - nr[j]] = table.volts[j]
    return raise_v, release_v


def _string_analysis(vd: np.ndarray, vu: np.ndarray, electrodes: Electrodes, names: tuple[str, ...], verdict: StringVerdict,
                     table: LevelTable, *, search: bool, max_states: int | None, source: str | None) -> ControlAnalysis:
    """The analysis of a STRING design: Lemma 1's ``n + 1`` prefix states ``P_k`` (D_1..D_k down), its
    control matrix and the one Hold level that sets each primitive. With ``search`` the accessible
    states come from the exhaustive search instead (to check Lemma 1)."""
    n = vd.size
    order = np.asarray(verdict.order, dtype=np.intp)
    rank = np.empty(n, dtype=np.intp)
    rank[order] = np.arange(n)
    prefix = (rank[None, :] < np.arange(n + 1)[:, None]).astype(np.uint8)  # (n+1, n): P_k
    if search:
        states = _sorted_rows(_search(table.snaps, table.releases, np.zeros(n, np.uint8), max_states=max_states, source=source))
    else:
        states = _sorted_rows(prefix)
    raise_v, release_v = _string_levels(table, order)
    return ControlAnalysis(
        names=names,
        snap_down_V=vd,
        release_V=vu,
        electrodes=electrodes,
        is_string=True,
        order=tuple(names[i] for i in order),
        order_index=tuple(int(i) for i in order),
        reasons=(),
        accessible_states=states,
        primitive_states=prefix,
        control_matrix=(np.arange(n)[:, None] < np.arange(n + 1)[None, :]).astype(np.uint8),
        levels=table,
        method="search" if search else "lemma1",
        raise_levels_V=raise_v,
        release_levels_V=release_v,
    )


def _searched_analysis(vd: np.ndarray, vu: np.ndarray, electrodes: Electrodes, names: tuple[str, ...], verdict: StringVerdict,
                       table: LevelTable, *, max_states: int | None, source: str | None) -> ControlAnalysis:
    """The analysis of a design that is not STRING: every accessible state by exhaustive search, each one
    a primitive (``P0`` = all up first), the control matrix their transpose."""
    states = _sorted_rows(_search(table.snaps, table.releases, np.zeros(vd.size, np.uint8), max_states=max_states, source=source))
    return ControlAnalysis(
        names=names,
        snap_down_V=vd,
        release_V=vu,
        electrodes=electrodes,
        is_string=False,
        order=None,
        order_index=None,
        reasons=verdict.reasons,
        accessible_states=states,
        primitive_states=states,
        control_matrix=np.ascontiguousarray(states.T),
        levels=table,
        method="search",
    )


def analyse_thresholds(
    snap_down_V,
    release_V,
    electrodes: Electrodes,
    *,
    names: Sequence[str] | None = None,
    method: str = "auto",
    max_states: int | None = None,
    source: str | None = None,
) -> ControlAnalysis:
    """Analyse a design given as threshold arrays (scenario order).

    Parameters
    ----------
    method:
        ``"auto"``: Lemma 1's closed form for a STRING design, the exhaustive search otherwise.
        ``"search"``: always search (used to check Lemma 1).
    max_states:
        Bound on the search (:class:`~stressbots.errors.DesignError` beyond it).
    source:
        Names the input in error messages (e.g. the scenario file).
    """
    if method not in ("auto", "search"):
        raise ValueError(f"method must be 'auto' or 'search', got {method!r}")
    vd, vu = _thresholds(snap_down_V, release_V)
    n = vd.size
    if n == 0:
        raise ValueError("a design needs at least one robot")
    names_t = tuple(str(x) for x in names) if names is not None else tuple(f"R{i + 1}" for i in range(n))
    verdict = classify_string(vd, vu, electrodes, names_t)
    table = admissible_levels(vd, vu, electrodes)
    if verdict.is_string:
        return _string_analysis(vd, vu, electrodes, names_t, verdict, table, search=method == "search", max_states=max_states,
                                source=source)
    return _searched_analysis(vd, vu, electrodes, names_t, verdict, table, max_states=max_states, source=source)


def analyse(robots, electrodes: Electrodes, **kwargs) -> ControlAnalysis:
    """Analyse a group of :class:`~stressbots.robots.Robot` (scenario order). See :func:`analyse_thresholds`."""
    robots = tuple(robots)
    return analyse_thresholds(
        [r.snap_down_V for r in robots],
        [r.release_V for r in robots],
        electrodes,
        names=[r.name for r in robots],
        **kwargs,
    )


def analyse_scenario(scenario, **kwargs) -> ControlAnalysis:
    """Analyse a loaded :class:`~stressbots.scenario.Scenario`."""
    kwargs.setdefault("source", scenario.source)
    return analyse(scenario.robots, scenario.electrodes, **kwargs)


# ----------------------------------------------------------------------------------------------------
# Shortest level sequences


def _prefix_length(state: np.ndarray, order: np.ndarray) -> int | None:
    """``k`` if ``state`` is the prefix state "D_1..D_k down", else ``None``."""
    s = state[order]
    k = int(s.sum())
    return k if bool(np.all(s[:k] == 1)) else None


def _string_path(analysis: ControlAnalysis, j: int, k: int) -> list[float] | None:
    """SPEC 4's closed form between prefix states ``j`` and ``k`` of a STRING design (None: use search)."""
    up, down = analysis.raise_levels_V, analysis.release_levels_V
    assert up is not None and down is not None  # a STRING design always has its levels
    n = analysis.n
    if k == j:
        return []
    if k > j:
        if np.isfinite(up[k]):
            return [float(up[k])]  # one Hold between V_d,k and V_d,k+1
        # V_d,k == V_d,k+1: raise through the tie, then release the extra arms.
        top = next(q for q in range(k + 1, n + 1) if np.isfinite(up[q]))
        return [float(up[top]), float(down[k])] if np.isfinite(down[k]) else None
    if np.isfinite(down[k]):
        return [float(down[k])]  # one Hold between V_u,k and V_u,k+1
    # V_u,k == V_u,k+1: release below the tie, then raise back to P_k.
    bottom = next((q for q in range(k - 1, -1, -1) if np.isfinite(down[q])), None)
    if bottom is None or not np.isfinite(up[k]):
        return None
    return [float(down[bottom]), float(up[k])]


def level_sequence(analysis: ControlAnalysis, start, target, *, max_states: int | None = None) -> tuple[float, ...]:
    """The fewest admissible levels (V) that take the arms from ``start`` to ``target``.

    For a STRING design between primitives this is SPEC 4's closed form: one level between ``V_d,k``
    and ``V_d,k+1`` when raising to ``P_k``, one between ``V_u,k`` and ``V_u,k+1`` when releasing to it;
    two levels when a tie makes ``P_k`` reachable only by overshooting. Otherwise a breadth-first search
    over the level cells. Every level is a cell's representative (:class:`LevelTable`), so it honours
    ``margin_V`` and ``[0, max_V]``.

    Raises
    ------
    WaveformError
        When no admissible level sequence reaches ``target`` from ``start``.
    """
    s0 = np.asarray(start, dtype=np.uint8).reshape(-1)
    s1 = np.asarray(target, dtype=np.uint8).reshape(-1)
    if s0.size != analysis.n or s1.size != analysis.n:
        raise ValueError(f"states must have {analysis.n} entries")
    if analysis.is_string:
        order = np.asarray(analysis.order_index, dtype=np.intp)
        j, k = _prefix_length(s0, order), _prefix_length(s1, order)
        if j is not None and k is not None:
            path = _string_path(analysis, j, k)
            if path is not None:
                return tuple(path)
    t = analysis.levels
    path = _search(t.snaps, t.releases, s0, target=s1, max_states=max_states)
    if path is None:
        down = [analysis.names[i] for i in np.flatnonzero(s1)]
        raise WaveformError(
            f"no admissible level sequence reaches the arm state with {', '.join(down) or 'no arm'} down "
            f"from the current state (margin_V {analysis.electrodes.margin_V:g} V, max_V {analysis.electrodes.max_V:g} V)"
        )
    return tuple(float(t.volts[i]) for i in path)
