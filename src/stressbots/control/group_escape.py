"""D_n's way out when it cannot get out alone: a group manoeuvre of D_n with the robots hemming it in.

During G_1, D_n is the only free one-way robot: under P_n everyone orbits in place, under P_{n-1} D_n runs
straight while the rest orbit. When D_n's orbit overlaps another robot's orbit disc and that robot's body
sweeps through every way out (D_{n-1} passing just behind D_n at the end of a transfer leg, a waiting
orbit beside D_n at t = 0), no turn-then-straight of D_n alone is clear
(:func:`~stressbots.control.escape_search.escape_manoeuvre` finds none): every pair frame then failed at the
same instant with nothing moved ("cannot reach a clear track in time", "found no timed path": 16 of the
tuning set's 1x and 2x G_1 failures). Under the STRING design, P_k drives every robot above D_k straight
(D_{k+1} .. D_n) and keeps D_1 .. D_k orbiting: so D_n can also leave *together with* the robot beside it,
each along its own heading. :func:`group_escape` searches that: a wait under P_n (everyone orbits), then
P_k for k = n-2 .. 0, D_n's body compared with every other body at the same instants, the other movers'
orbit discs carried along their tracks (as a park move checks them,
:mod:`~stressbots.control.parking`); the quickest that leaves D_n's orbit the gaps it needs wins. A pure
function of a snapshot; the pair phase re-plans D_{n-1}'s station from wherever it ends.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..collision import arena_gap, penetration_depth, point_rectangle_distance
from ..kinematics import move
from ..plans import join_steps
from ..robots import TWO_PI, turning_centres
from .escape_search import Orbiting, orbit_slack

_NO_ORBITS = Orbiting(np.zeros((0, 3)), *(np.zeros(0),) * 6)

__all__ = ["EscapeSequence", "Group", "GroupMove", "group_escape", "group_escape_sequence"]


class Group(NamedTuple):
    """The undocked robots in docking order: ``order`` (robot indices of D_1 .. D_n, D_n last) into the measured
    poses (n, 3), speeds (um/s), turning radii (um), body lengths and widths (um), orbit-disc radii ``r*`` (um) and
    the gap (um) D_n's orbit disc needs from each one's (``need``, indexed like ``poses``)."""

    order: tuple[int, ...]
    poses: np.ndarray
    speeds: np.ndarray
    radii: np.ndarray
    lengths: np.ndarray
    widths: np.ndarray
    rstar: np.ndarray
    need: np.ndarray


class GroupMove(NamedTuple):
    """Wait ``wait_s`` under P_n (everyone orbits), then drive ``straight_s`` under P_``k`` (D_(k+1) .. D_n straight, the
    rest orbiting); afterwards D_n's orbit disc has ``slack_um`` (>= 0) over the gaps it needs."""

    k: int
    wait_s: float
    straight_s: float
    slack_um: float

    @property
    def total_s(self) -> float:
        """Duration of the whole manoeuvre (s)."""
        return self.wait_s + self.straight_s


def _floors(g: Group, N: int, body_clearance: float) -> np.ndarray:
    """Gap (um) D_n's body keeps from each other body: ``body_clearance``, or less if it is closer already."""
    floor = np.full(len(g.poses), body_clearance)
    for j in g.order[:-1]:
        sep = -float(penetration_depth(g.poses[N][None], g.lengths[N], g.widths[N], g.poses[j][None], g.lengths[j], g.widths[j])[0])
        floor[j] = min(body_clearance, sep - 1e-6)
    return floor


def _first_hit(mine: np.ndarray, theirs: dict[int, np.ndarray], g: Group, N: int, floor: np.ndarray, arena_um,
               edge_floor: float, docked) -> int:
    """Index of the first sample where D_n's body (``mine`` (S, 3)) comes within its floor of another body
    (``theirs[j]`` (S, 3), same instants), the arena edge or a docked body; S when never."""
    hit = np.zeros(len(mine), dtype=bool)
    for j, pj in theirs.items():
        hit |= penetration_depth(mine, g.lengths[N], g.widths[N], pj, g.lengths[j], g.widths[j]) > -floor[j]
    if arena_um is not None:
        hit |= arena_gap(mine, g.lengths[N], g.widths[N], arena_um) < edge_floor
    for p, Lj, Wj in zip(*docked, strict=True):
        hit |= penetration_depth(mine, g.lengths[N], g.widths[N], np.asarray(p)[None, :], Lj, Wj) > -edge_floor
    return int(np.argmax(hit)) if hit.any() else len(mine)


def _disc_gaps(c: np.ndarray, rs: float, arena_um, docked, discs_c: np.ndarray, discs_r: np.ndarray) -> np.ndarray:
    """Gap (um, (S,)) of a disc of radius ``rs`` about each of ``c`` (S, 2) to the arena edge, the docked bodies and
    the discs ``(discs_c (S, D, 2), discs_r (D,))`` at the same instants."""
    gap = np.full(len(c), np.inf)
    if arena_um is not None:
        w, h = arena_um
        gap = np.minimum(gap, np.min(np.stack([c[:, 0], w - c[:, 0], c[:, 1], h - c[:, 1]], axis=1), axis=1) - rs)
    for p, Lj, Wj in zip(*docked, strict=True):
        gap = np.minimum(gap, point_rectangle_distance(c, np.asarray(p)[None, :], Lj, Wj)[:, 0] - rs)
    if discs_c.shape[1]:
        gap = np.minimum(gap, (np.hypot(*(c[:, None, :] - discs_c).transpose(2, 0, 1)) - rs - discs_r[None, :]).min(axis=1))
    return gap


def group_escape(g: Group, arena_um, *, edge_need: float, body_clearance: float, edge_clearance: float, disc_clearance: float,
                 docked=None, wait_steps: int = 24, max_straight_um: float = 600.0, sample_um: float = 20.0,
                 alone: bool = False) -> GroupMove | None:
    """The quickest group manoeuvre that takes D_n's orbit clear (:func:`~stressbots.control.escape_search.orbit_slack`
    >= 0); None when none.

    Candidates: a wait of ``wait_steps`` evenly spaced fractions of D_n's orbit period under P_n (everyone orbits), then
    P_k for k = n-2 .. 0 (D_(k+1) .. D_n straight along the headings they have then, D_1 .. D_k orbiting) up to
    ``max_straight_um`` of D_n's travel, sampled every ``sample_um``. A candidate counts while D_n's body keeps
    ``body_clearance`` from every other body at the same instants (or, if closer already, does not get closer) and
    ``edge_clearance`` from the arena edge and the docked bodies (likewise), and every other mover's orbit disc,
    carried along its track, keeps ``disc_clearance`` (or its present gap, if smaller) from the arena edge, the docked
    bodies and the other discs but D_n's (D_n's own disc must end clear of them with ``g.need``, ``edge_need``).
    ``docked``: ``(poses, L, W)`` of the docked bodies. ``alone``: P_(n-1) too (D_n straight alone, the rest
    orbiting), which :func:`~stressbots.control.escape_search.escape_manoeuvre` covers from the measured poses but
    not after another manoeuvre (:func:`group_escape_sequence`).

    >>> poses = np.array([[0.0, 0.0, 0.0], [0.0, -300.0, np.pi]])   # back to back, D_n's orbit 40 um short of its gap
    >>> g = Group((0, 1), poses, np.full(2, 100.0), np.full(2, 100.0), np.full(2, 200.0), np.full(2, 50.0),
    ...           np.full(2, 180.0), np.array([40.0, 0.0]))
    >>> group_escape(g, None, edge_need=40.0, body_clearance=10.0, edge_clearance=10.0, disc_clearance=25.0)  # doctest: +ELLIPSIS
    GroupMove(k=0, wait_s=0.0, straight_s=0.4, slack_um=...)
    """
    order = list(g.order)
    n = len(order)
    N = order[-1]
    docked = docked if docked is not None else (np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    centres = turning_centres(g.poses, g.radii)
    others = [j for j in order if j != N]
    orb_need = g.need[others]
    floor = _floors(g, N, body_clearance)
    edge_floor = edge_clearance if arena_um is None else min(edge_clearance, float(arena_gap(g.poses[N][None], g.lengths[N], g.widths[N],
                                                                                               arena_um)[0]) - 1e-6)
    vN, rN = float(g.speeds[N]), float(g.radii[N])
    period = TWO_PI * rN / vN
    max_wait = _longest_wait(g, order, N, others, floor, arena_um, edge_floor, docked, period, vN)
    s_run = np.arange(0.0, max_straight_um + 1e-9, sample_um)
    t_run = s_run / vN
    best: GroupMove | None = None
    for w in np.linspace(0.0, period, wait_steps, endpoint=False):
        if w > max_wait or (best is not None and w >= best.total_s):
            break
        after = {j: move(g.poses[j], g.speeds[j] * w, 1.0 / g.radii[j]) for j in order}
        for k in range(n - 1 if alone else n - 2, -1, -1):
            movers = order[k:]
            tracks = {j: move(after[j], g.speeds[j] * t_run, 0.0 if j in movers else 1.0 / g.radii[j]) for j in order}
            free = _first_hit(tracks[N], {j: tracks[j] for j in others}, g, N, floor, arena_um, edge_floor, docked)
            if free == 0:
                continue
            mc = {j: turning_centres(tracks[j][:free], g.radii[j]) if j in movers else np.broadcast_to(centres[j], (free, 2))
                  for j in order}
            ok = _movers_discs_clear(g, movers, others, mc, free, arena_um, docked, disc_clearance)
            slack = _disc_slack(g, N, others, mc, tracks[N][:free], rN, orb_need, arena_um, edge_need, docked)
            good = np.flatnonzero(ok & (slack >= 0.0))
            if not len(good):
                continue
            i = int(good[0])
            m = GroupMove(k, float(w), float(t_run[i]), float(slack[i]))
            if best is None or m.total_s < best.total_s:
                best = m
    return best


class EscapeSequence(NamedTuple):
    """A way out in steps: ``steps`` ``((k, seconds), ...)`` drive P_k in turn (k = n: everyone orbits; k = n-1: D_n
    straight alone; k < n-1: D_(k+1) .. D_n straight); afterwards D_n's orbit disc has ``slack_um`` (>= 0) over the
    gaps it needs."""

    steps: tuple[tuple[int, float], ...]
    slack_um: float

    @property
    def total_s(self) -> float:
        """Duration of the whole sequence (s)."""
        return float(sum(d for _, d in self.steps))


def group_escape_sequence(g: Group, arena_um, *, edge_need: float, body_clearance: float, edge_clearance: float,
                          disc_clearance: float, docked=None, wait_steps: int = 24, max_straight_um: float = 600.0,
                          cut_um: float = 60.0, two_step: bool = True) -> EscapeSequence | None:
    """The quickest way out of at most two manoeuvres: a first primitive (any P_k, k = n .. 0, driven up to one of D_n's
    orbit periods and cut every ``cut_um`` of D_n's travel), then a :func:`group_escape` (with P_(n-1) alone) from
    where it leaves everyone; the :func:`group_escape` itself when that exists (and only that when ``two_step`` is
    False). None when none is found.

    Every way out of one manoeuvre can be closed while a two-step one is open: two robots whose orbits overlap by
    half meet within a second if both orbit, and D_n's straight alone runs through the other's disc; D_n straight
    alone for a second and then both straight leaves them clear (below). Each step is checked as
    :func:`group_escape` checks its own (bodies at the same instants, D_n's edge and docked gaps, the other movers'
    discs), so the sequence keeps its clearances throughout.

    >>> poses = np.array([[1500.0, 1500.0, 3.3], [1254.33, 1825.48, 2.52]])   # D_1, D_2: orbit discs overlap
    >>> g = Group((0, 1), poses, np.array([100.0, 110.0]), np.full(2, 200.0), np.full(2, 250.0), np.full(2, 60.0),
    ...           np.full(2, 260.0), np.array([25.0, 40.0]))
    >>> kw = dict(edge_need=40.0, body_clearance=10.0, edge_clearance=10.0, disc_clearance=25.0)
    >>> group_escape(g, (3000.0, 3000.0), **kw) is None
    True
    >>> seq = group_escape_sequence(g, (3000.0, 3000.0), **kw)
    >>> [k for k, _ in seq.steps], seq.slack_um >= 0.0   # D_2 straight alone (P_1), then both straight (P_0)
    ([1, 0], True)
    """
    kw = dict(edge_need=edge_need, body_clearance=body_clearance, edge_clearance=edge_clearance, disc_clearance=disc_clearance,
              docked=docked, wait_steps=wait_steps, max_straight_um=max_straight_um)
    one = group_escape(g, arena_um, **kw)
    if one is not None or not two_step:
        return None if one is None else EscapeSequence(_move_steps(one, len(g.order)), one.slack_um)
    best: EscapeSequence | None = None
    for k in range(len(g.order), -1, -1):
        for dt, after in _cuts(g, k, arena_um, body_clearance, edge_clearance, disc_clearance, docked, cut_um):
            if best is not None and dt >= best.total_s:
                break
            m = group_escape(g._replace(poses=after), arena_um, alone=True, **kw)
            if m is not None:
                seq = EscapeSequence(join_steps(((k, dt), *_move_steps(m, len(g.order)))), m.slack_um)
                if best is None or seq.total_s < best.total_s:
                    best = seq
                break
    return best


def _move_steps(m: GroupMove, n: int) -> tuple[tuple[int, float], ...]:
    """A :class:`GroupMove` as steps ``((n, wait_s), (k, straight_s))``, parts of no duration left out."""
    return tuple((k, d) for k, d in ((n, m.wait_s), (m.k, m.straight_s)) if d > 1e-9)


def _cuts(g: Group, k: int, arena_um, body_clearance: float, edge_clearance: float, disc_clearance: float, docked,
          cut_um: float):
    """``(seconds, poses)`` every ``cut_um`` of D_n's travel along P_k (k = n: everyone orbits), up to one of D_n's orbit
    periods or the first sample that breaks :func:`group_escape`'s checks (bodies, edges, the other movers' discs)."""
    order = list(g.order)
    n, N = len(order), order[-1]
    docked = docked if docked is not None else (np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    movers = order[k:] if k < n else []
    others = [j for j in order if j != N]
    vN = float(g.speeds[N])
    ts = np.arange(0.0, TWO_PI * float(g.radii[N]) / vN, 10.0 / vN)
    tracks = {j: move(g.poses[j], g.speeds[j] * ts, 0.0 if j in movers else 1.0 / g.radii[j]) for j in order}
    edge_floor = edge_clearance if arena_um is None else min(edge_clearance, float(arena_gap(g.poses[N][None], g.lengths[N],
                                                                                               g.widths[N], arena_um)[0]) - 1e-6)
    free = _first_hit(tracks[N], {j: tracks[j] for j in others}, g, N, _floors(g, N, body_clearance), arena_um, edge_floor, docked)
    if free > 1 and len(movers) > 1:
        centres = turning_centres(g.poses, g.radii)
        mc = {j: turning_centres(tracks[j][:free], g.radii[j]) if j in movers else np.broadcast_to(centres[j], (free, 2))
              for j in order}
        ok = _movers_discs_clear(g, movers, others, mc, free, arena_um, docked, disc_clearance)
        free = free if ok.all() else int(np.argmin(ok))
    step = max(1, int(round(cut_um / 10.0)))
    for i in range(step, free, step):
        yield float(ts[i]), np.stack([tracks[j][i] if j in tracks else g.poses[j] for j in range(len(g.poses))])


def _longest_wait(g: Group, order: list[int], N: int, others: list[int], floor: np.ndarray, arena_um, edge_floor: float, docked,
                  period: float, vN: float) -> float:
    """How long (s) D_n may wait under P_n (everyone orbits, D_n's orbit of ``period`` s at ``vN`` um/s) before its body
    first comes within its floors (um) of another body, the arena edge or a docked body; -1 when not even at once."""
    # the wait: everyone orbits; D_n's body checked every ~10 um of its arc, up to its first contact
    tw_dense = np.arange(0.0, period, 10.0 / vN)
    orbit_at = {j: move(g.poses[j], g.speeds[j] * tw_dense, 1.0 / g.radii[j]) for j in order}
    free_wait = _first_hit(orbit_at[N], {j: orbit_at[j] for j in others}, g, N, floor, arena_um, edge_floor, docked)
    return float(tw_dense[free_wait - 1]) if free_wait > 0 else -1.0


def _movers_discs_clear(g: Group, movers: list[int], others: list[int], mc: dict[int, np.ndarray], free: int, arena_um, docked,
                        disc_clearance: float) -> np.ndarray:
    """Mask (free,): up to each sample, every mover but D_n kept its orbit disc (centres ``mc[j]`` (free, 2) along its
    track) ``disc_clearance`` um (or its present gap, if smaller) from the arena edge, the docked bodies and the other
    discs but D_n's."""
    ok = np.ones(free, dtype=bool)
    for j in movers[:-1]:
        rest = [b for b in others if b != j]
        dc = np.stack([mc[b] for b in rest], axis=1) if rest else np.zeros((free, 0, 2))
        gaps = _disc_gaps(mc[j], float(g.rstar[j]), arena_um, docked, dc, g.rstar[rest])
        ok &= np.minimum.accumulate(gaps) >= min(disc_clearance, float(gaps[0]) - 1e-6)
    return ok


def _disc_slack(g: Group, N: int, others: list[int], mc: dict[int, np.ndarray], track_N: np.ndarray, rN: float,
                orb_need: np.ndarray, arena_um, edge_need: float, docked) -> np.ndarray:
    """Smallest surplus (um, (free,)) of D_n's orbit disc, D_n at each of ``track_N`` (free, 3), over the gaps it needs:
    ``orb_need`` from the other robots' discs (centres ``mc``) and ``edge_need`` from the arena edge and the docked
    bodies (:func:`~stressbots.control.escape_search.orbit_slack`)."""
    oc = np.stack([mc[b] for b in others], axis=1)  # (free, n-1, 2)
    cN = turning_centres(track_N, rN)
    slack = (np.hypot(*(cN[:, None, :] - oc).transpose(2, 0, 1)) - float(g.rstar[N]) - g.rstar[others][None, :]
             - orb_need[None, :]).min(axis=1)
    slack = np.minimum(slack, orbit_slack(cN, float(g.rstar[N]), _NO_ORBITS, arena_um, edge_need, docked))
    return slack


