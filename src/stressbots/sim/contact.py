"""Contact rules: at a contact instant, who pushes into whom and what each pushing robot does next.

:meth:`ContactRules.evaluate` is called whenever the first-contact search (:mod:`.search`) stops the
motion, and at the end of every Drive. It builds the touch graph (whom each robot's own motion pushes
into, by moving it alone by :data:`~.bodies.PROBE_UM`), applies the rules of :mod:`stressbots.sim` in
order (self-aligning compliance, turning robots, the arena edge, straight robots against static bodies
through :mod:`.compliance`, any other push) and returns how everyone moves next (:class:`~.search.Motion`).

Outcomes repeat while nothing near a pair moves, so the expensive ones are remembered per pair under a
key of the poses that could change them (:meth:`ContactRules.rule_key`), and contact events are logged
only when a pair's outcome changes.
"""

from __future__ import annotations

import math

import numpy as np

from ..drift import HeadingDrift
from ..kinematics import follow_ends
from . import compliance
from .bodies import (
    ARENA,
    FLUSH_TOL_RAD,
    NEAR_UM,
    PROBE_UM,
    PUSH_EPS_UM,
    TOUCH_UM,
    Bodies,
    Trig,
    depth_one,
    local,
    wall_gap_one,
    with_trig,
)
from .search import FREE, HELD, SLIDE, DriveRates, Motion

Outcomes = dict[tuple[int, int], tuple[str, str]]
"""``(i, j) -> (kind, detail)`` of the pairs in contact at one evaluation (``j = -1``: the arena edge)."""


class ContactRules:
    """The contact rules over shared :class:`~.bodies.Bodies`, with the per-pair memory they need.

    Parameters
    ----------
    bodies : Bodies
        The state the rules read and change (compliance moves, ``docked``, ``stuck``, events).
    drift : stressbots.drift.HeadingDrift
        Heading drift: its curvature now is part of each robot's own motion when probing a push.
    """

    def __init__(self, bodies: Bodies, drift: HeadingDrift):
        self.b = bodies
        self.drift = drift
        self.contacts: dict[tuple[int, int], str] = {}  # outcome kind remembered per pair (for the log)
        self._rule_cache: dict[tuple[int, int], tuple[bytes, tuple[str, str]]] = {}
        self._flush_cache: dict[tuple[int, int], tuple[bytes, bool]] = {}

    def evaluate(self, ctx: DriveRates, t_abs: float, forced: set[int]) -> Motion:
        """Apply the contact rules at the current poses; return how everyone moves next."""
        b = self.b
        speed, kappa, straight, _ = ctx
        n = b.n
        mode = np.full(n, FREE)
        mode[speed <= 0] = HELD
        for k in forced:
            mode[k] = HELD
        slide_v = np.zeros((n, 2))
        slide_end = np.full(n, math.inf)
        excluded: set = set()
        d0, g0 = b.pair_depths(), b.wall_gaps()
        if not ((d0 > -NEAR_UM).any() or (g0 < NEAR_UM).any()):  # nothing near anything: all free
            self.contacts = {}
            return Motion(mode, slide_v, slide_end, excluded, False)
        push, approach = self.touch_graph(kappa, d0, g0)
        pushers = set(push)
        static = pushers | set(np.flatnonzero(speed <= 0).tolist()) | forced
        outcomes: Outcomes = {}
        done: set[int] = set(forced)

        # 1. Self-aligning compliance: two free straight robots meeting head-on.
        for i, j in sorted({(min(a, c), max(a, c)) for a in pushers for c in push[a] if c != ARENA}):
            if i in done or j in done or not self.head_on(i, j, straight, speed, approach):
                continue
            outcomes[(i, j)] = outcomes[(j, i)] = self.self_align_cached(i, j, straight)
            mode[i] = mode[j] = HELD
            done |= {i, j}

        # 2. Each remaining robot that pushes into something.
        slide_partner: dict[int, int] = {}
        for i in sorted(pushers - done):
            mode[i] = HELD
            slide = self.push_outcome(i, push[i], static, ctx, outcomes)
            if slide is not None:
                j, (slide_v[i], slide_end[i]) = slide
                mode[i] = SLIDE
                slide_partner[i] = j
                excluded.add((min(i, j), max(i, j)))

        # A slide is along a body that stays put; if the partner moves after all, stop instead.
        for i in np.flatnonzero(mode == SLIDE).tolist():
            j = slide_partner[i]
            if mode[j] != HELD:
                mode[i] = HELD
                slide_end[i] = math.inf
                excluded.discard((min(i, j), max(i, j)))
                outcomes[(i, j)] = ("contact", "stopped against a moving robot")
        self.remember(outcomes, t_abs, d0, g0)
        recheck = any(mode[i] == HELD and j >= 0 and mode[j] != HELD for (i, j) in outcomes)
        return Motion(mode, slide_v, slide_end, excluded, recheck)

    def touch_graph(self, kappa: np.ndarray, d0: np.ndarray, g0: np.ndarray):
        """``(push, approach)`` of the touching pairs: whom each robot's own motion pushes into (the arena
        edge last) and the approach rate of each ordered pair (um per um driven). Base curvatures ``kappa``
        (1/um), depths ``d0`` of every pair and wall gaps ``g0`` (um) now.

        Each touching robot is moved alone by :data:`~.bodies.PROBE_UM` on its arc (drift included) and
        the depths are taken again. A handful of pairs per evaluation: plain floats
        (:func:`~.bodies.depth_one`), bit-identical to the array kernels at a fraction of their cost.
        """
        b = self.b
        push: dict[int, list[int]] = {}
        approach: dict[tuple[int, int], float] = {}
        t = np.flatnonzero(d0 > -TOUCH_UM)
        pairs = list(zip(b.I[t].tolist(), b.J[t].tolist(), d0[t].tolist(), strict=True))
        walls = np.flatnonzero(g0 < TOUCH_UM).tolist() if b.arena is not None else []
        if not (pairs or walls):
            return push, approach
        now, probe = self._probes(sorted({k for a, c, _ in pairs for k in (a, c)} | set(walls)), kappa)
        hl, hw = b.hl.tolist(), b.hw.tolist()
        for x, y, d in pairs:
            rx = depth_one(probe[x], now[y], hl[x], hw[x], hl[y], hw[y]) - d
            ry = depth_one(now[x], probe[y], hl[x], hw[x], hl[y], hw[y]) - d
            approach[(x, y)] = rx / PROBE_UM
            approach[(y, x)] = ry / PROBE_UM
            if rx > PUSH_EPS_UM:
                push.setdefault(x, []).append(y)
            if ry > PUSH_EPS_UM:
                push.setdefault(y, []).append(x)
        g = g0.tolist()
        for i in walls:
            if g[i] - wall_gap_one(probe[i], hl[i], hw[i], b.arena) > PUSH_EPS_UM:
                push.setdefault(i, []).append(ARENA)
        return push, approach

    def _probes(self, robots: list[int], kappa: np.ndarray) -> tuple[dict[int, Trig], dict[int, Trig]]:
        """The poses of ``robots`` now and each moved alone by :data:`~.bodies.PROBE_UM` on its arc of base
        curvature ``kappa`` plus its drift's (as :func:`~stressbots.kinematics.move` would), with their
        sines and cosines."""
        b = self.b
        odo = b.odo.tolist()
        now = [tuple(b.pose[k].tolist()) for k in robots]
        ahead = follow_ends(now, [[(PROBE_UM, float(kappa[k]) + self.drift.curvature_one(k, odo[k]))] for k in robots])
        trig = with_trig(now + ahead)
        m = len(robots)
        return dict(zip(robots, trig[:m], strict=True)), dict(zip(robots, trig[m:], strict=True))

    def self_align_cached(self, i: int, j: int, straight) -> tuple[str, str]:
        """``(kind, detail)`` of self-aligning compliance between i and j, remembered while nothing moves."""
        key = self.rule_key(i, j, straight)
        hit = self._rule_cache.get((i, j))
        if hit is not None and hit[0] == key:
            return hit[1]
        kind, detail = compliance.self_align(self.b, i, j)
        self._rule_cache[(i, j)] = (self.rule_key(i, j, straight), (kind, detail))
        return kind, detail

    def push_outcome(self, i: int, cs: list[int], static: set[int], ctx: DriveRates, outcomes: Outcomes):
        """The outcome of robot i pushing into the bodies ``cs`` (written to ``outcomes``); ``(j, (slide
        velocity, slide end))`` when i slides along body j, else None (i is held)."""
        b = self.b
        straight = ctx[2]
        if not straight[i]:
            return self._turning_push(i, cs, static, straight, outcomes)
        if ARENA in cs:
            b.arena_hit[i] = True
            for j in cs:
                outcomes[(i, j)] = ("arena", "stopped at the arena edge") if j == ARENA else ("contact", "stopped")
            return None
        fronts = [j for j in cs if j in static]
        if len(cs) == 1 and fronts:
            j = cs[0]
            key = self.rule_key(i, j, straight)
            hit = self._rule_cache.get((i, j))
            if hit is not None and hit[0] == key:
                (kind, detail), slide = hit[1], None
            else:
                kind, detail, slide = compliance.dock_rule(b, i, j, ctx[0])
                if slide is None:  # held outcomes repeat while nothing moves; slides are recomputed
                    self._rule_cache[(i, j)] = (self.rule_key(i, j, straight), (kind, detail))
            outcomes[(i, j)] = (kind, detail)
            return None if slide is None else (j, slide)
        if len(cs) > 1 and len(fronts) == len(cs):
            flush = [j for j in cs if b.docked[j] and self.flush_cached(i, j, straight)]
            for j in cs:
                outcomes[(i, j)] = ("dock", "flush against the structure") if flush else ("stuck", "pushing into several bodies")
            b.docked[i] = bool(flush)
            b.stuck[i] = not flush
            return None
        for j in cs:
            outcomes[(i, j)] = ("contact", "stopped against a moving robot" if j not in static else "stopped")
        return None

    def _turning_push(self, i: int, cs: list[int], static: set[int], straight, outcomes: Outcomes) -> None:
        """A turning robot pushing into ``cs`` is blocked, or docked when flush against a static body."""
        # Arriving flush in its slot is docking, whatever the arm does (SPEC 6): a robot that turns
        # into its slot on an arc is docked there, and stays docked while it keeps pushing.
        flush = [j for j in cs if j != ARENA and j in static and self.b.docked[j] and self.flush_cached(i, j, straight)]
        for j in cs:
            outcomes[(i, j)] = (
                ("dock", "arrived flush against the structure") if j in flush
                else ("blocked", "a turning robot cannot pivot off an obstacle")
            )
        if flush:
            self.b.docked[i] = True
            self.b.stuck[i] = False
        return None

    def remember(self, outcomes: Outcomes, t_abs: float, d0: np.ndarray, g0: np.ndarray) -> None:
        """Log changes of outcome. Outcomes are remembered while the pair stays within NEAR_UM (depths
        ``d0`` of every pair, wall gaps ``g0``), so two robots jostling against each other do not log
        every touch."""
        b = self.b
        for pair in sorted(outcomes):
            kind, detail = outcomes[pair]
            if self.contacts.get(pair) != kind:
                b.log(t_abs, pair[0], kind, pair[1], detail)
        memory = {k: v[0] for k, v in outcomes.items()}
        gone = [(pair, kind) for pair, kind in self.contacts.items() if pair not in memory]
        if gone:  # usually none: the same pairs touch again
            close = np.flatnonzero(d0 > -NEAR_UM)
            near_pairs = set(zip(b.I[close].tolist(), b.J[close].tolist(), strict=True))
            arena_near = set(np.flatnonzero(g0 < NEAR_UM).tolist())
            for (a, c), kind in gone:
                if (a in arena_near) if c == ARENA else ((min(a, c), max(a, c)) in near_pairs):
                    memory[(a, c)] = kind
        self.contacts = memory

    def head_on(self, i: int, j: int, straight, speed, approach) -> bool:
        """Whether touching robots i and j meet head-on (the situation of self-aligning compliance).

        Both drive straight and neither is docked (a structure's member is a static body: rule 4), their
        headings are opposed, the pair closes (at least one pushes, and together they approach), and
        every contact point lies in the front half of both bodies: front edge on front edge, a front
        corner on a front corner, or a front corner on the other's long side near its front. Whether
        they then form G_1 is decided by the seed's limits (:func:`.compliance.self_align`), not here.
        """
        if not (straight[i] and straight[j]) or speed[i] <= 0 or speed[j] <= 0:
            return False
        b = self.b
        if b.docked[i] or b.docked[j]:
            return False
        P = b.pose
        if math.cos(P[i, 2] - P[j, 2]) >= 0.0 or approach[(i, j)] + approach[(j, i)] <= 0.0:
            return False
        pts, _ = compliance.contact_points(b, i, j)
        return bool((local(pts, P[i])[0] >= 0.0).all() and (local(pts, P[j])[0] >= 0.0).all())

    def rule_key(self, i: int, j: int, straight) -> bytes:
        """What a contact rule's outcome depends on: the arm kinds of i and j and, bit for bit, the poses
        of every robot a compliance move of i or j could reach (itself included)."""
        b = self.b
        within = b.within_reach()
        near = np.flatnonzero(within[i] | within[j])
        return (bytes([bool(straight[i]), bool(straight[j])]) + near.tobytes() + b.pose[near].tobytes()
                + b.docked[near].tobytes())

    def flush_cached(self, i: int, j: int, straight) -> bool:
        """:func:`.compliance.flush`, remembered while nothing near the pair moves (a blocked robot is
        asked every evaluation); headings not square to each other are not flush (cheap test first)."""
        P = self.b.pose
        d = (P[i, 2] - P[j, 2]) % (0.5 * math.pi)
        if min(d, 0.5 * math.pi - d) > FLUSH_TOL_RAD:
            return False
        key = self.rule_key(i, j, straight)
        hit = self._flush_cache.get((i, j))
        if hit is None or hit[0] != key:
            hit = (key, compliance.flush(self.b, i, j))
            self._flush_cache[(i, j)] = hit
        return hit[1]
