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

__all__ = ["G1Stop", "g1_failure"]


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
