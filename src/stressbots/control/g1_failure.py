"""Why G_1 did not form, in words: the failure message of the pair phase (issue 12, goals 1 and 6).

The pair phase re-plans G_1 whenever a stage has no solution (a transfer with no clear way, no timed path to
the approach line, a missed rendezvous: :meth:`~stressbots.control.pair.PairPhase.form`), falls back on a holding
orbit between rounds of pair frames, and gives up only when re-planning cannot change anything: D_n could not
move, it is boxed in against the arena edge, no pair frame is left, or every round failed. The message says that
first, then what hems D_n in (the notes), and only last why the last frame failed: a stage's symptom ("found no
timed path") is never the reason given for the failure.
"""

from __future__ import annotations

from enum import Enum
from typing import Any

from ..robots import turning_centres
from .pair_geometry import deepest_overlap, pressed_together

__all__ = ["G1Stop", "boxed_note", "g1_failure", "overlap_note", "wedge_note"]


class G1Stop(Enum):
    """Why the pair phase stopped re-planning G_1."""

    ROUNDS = "rounds"
    """Every round of pair frames (``Tuning.pair_rounds``) failed, D_n waiting on a free orbit between them."""
    UNMOVED = "unmoved"
    """D_n could not move off where a round failed (no clear way to a holding orbit, no way out of the orbits around
    it): the next round would plan from the same poses and fail the same way."""
    BOXED = "boxed"
    """D_n is boxed in against the arena edge: nothing a re-plan does frees a one-way robot there."""
    NO_FRAMES = "no frames"
    """No pair frame is left whose station, approach and slots are clear of the orbits as measured."""


def g1_failure(name: str, stop: G1Stop, frames: int, rounds: int, notes: str, last: str) -> str:
    """The failure message of a G_1 that did not form: ``name`` (D_n's robot name) stopped for ``stop`` after
    ``frames`` pair frames in ``rounds`` rounds; ``notes`` (``'...; '`` clauses, may be empty) say what hems D_n in,
    ``last`` why the last frame failed.

    >>> g1_failure("R7", G1Stop.UNMOVED, 6, 1, "R7's orbit lies 30 um into R4's as measured; ",
    ...            "R7 cannot reach a clear track in time for R6's move")  # doctest: +NORMALIZE_WHITESPACE
    "G_1 not formed: R7 could not move off where 6 pair frame(s) failed (no clear way to a holding orbit, no way out
    of the orbits around it); R7's orbit lies 30 um into R4's as measured; the last frame failed because R7 cannot
    reach a clear track in time for R6's move"
    >>> g1_failure("R3", G1Stop.ROUNDS, 9, 2, "", "R3 found no timed path to its approach line").split("; ")[0]
    'G_1 not formed: 2 rounds of pair frames (9 frames) failed, R3 waiting on a free orbit between them'
    """
    why = {
        G1Stop.ROUNDS: f"{rounds} rounds of pair frames ({frames} frames) failed, {name} waiting on a free orbit between them",
        G1Stop.UNMOVED: (f"{name} could not move off where {frames} pair frame(s) failed (no clear way to a holding orbit, "
                         "no way out of the orbits around it)"),
        G1Stop.BOXED: f"no re-plan frees {name} after {frames} pair frame(s)",
        G1Stop.NO_FRAMES: f"no pair frame is left clear of the orbits as measured after {frames} pair frame(s)",
    }[stop]
    tail = f"the last frame failed because {last}" if last else "no frame was tried"
    return f"G_1 not formed: {why}; {notes}{tail}"


# -- what hems D_n in: the notes, queries of the loop's estimates ----------------------------------------------------

def overlap_note(loop: Any, N: int) -> str:
    """'R4's orbit lies 150 um into R3's as measured; ' when D_n's (robot ``N``'s) orbit disc overlaps another undocked
    robot's in ``loop`` (:func:`~stressbots.control.pair_geometry.deepest_overlap`), else '': D_n hemmed in by an orbit it
    cannot leave (held-out 38:3 at 2x: R4 beside R3, every pair frame and hold refused at 88 s) otherwise ended with the
    last stage's symptom alone ("found no timed path")."""
    others = [j for j in range(loop.n) if j != N and not loop.docked[j]]
    hit = deepest_overlap(turning_centres(loop.est, loop.r_hat), loop.rstar, N, others)
    if hit is None:
        return ""
    names = loop.scn.names
    return f"{names[N]}'s orbit lies {hit[1]:.0f} um into {names[hit[0]]}'s as measured; "


def boxed_note(loop: Any, N: int) -> str:
    """'R5 is boxed in against the arena edge ...; ' when D_n (robot ``N`` of ``loop``) can neither turn nor drive on for
    the arena edge (and the docked bodies) alone (:meth:`~stressbots.control.escapes.Escapes.boxed_in` with no orbits),
    else ''. Nothing G_1 re-plans frees a one-way robot there (tuning 116:0 at 1x: D_n pinned against the bottom edge at
    21 s, G_1 gave up at 185 s)."""
    if not loop.gross.escapes.boxed_in(N, loop.est[N], []):
        return ""
    return (f"{loop.scn.names[N]} is boxed in against the arena edge (no clockwise turn and straight of it keeps "
            f"{loop.tune.viable_clearance_um:.0f} um from it); ")


def wedge_note(names, N: int, M: int, d_n, d_prev, within_um: float) -> str:
    """'R7 is pressed against R6 (...); ' when D_n and D_{n-1} (robots ``N``, ``M``; ``d_n``, ``d_prev`` = ``(pose, body)``
    with ``body`` = ``(length_um, width_um, speed_um_s, radius_um)``) are wedged
    (:func:`~stressbots.control.pair_geometry.pressed_together` within ``within_um``), else ''.

    >>> import numpy as np
    >>> n, m = (237.8, 69.3, 144.9, 263.5), (286.3, 68.6, 143.1, 200.4)   # held-out 55:1 at 2x noise, t = 12 s
    >>> wedge_note(("R6", "R7"), 1, 0, (np.array([2382.2, 1866.1, 0.263]), n), (np.array([2304.2, 1976.0, 4.151]), m), 10.0)
    'R7 is pressed against R6 (6 um into each other as measured) and every primitive drives them closer; '
    """
    sep = pressed_together(d_n[0], d_n[1], d_prev[0], d_prev[1], within_um=within_um)
    if sep is None:
        return ""
    gap = f"{sep:.0f} um apart" if sep >= 0.0 else f"{-sep:.0f} um into each other"
    return f"{names[N]} is pressed against {names[M]} ({gap} as measured) and every primitive drives them closer; "
