"""How one park move of a waiting orbit is found and its wait driven (the policy of
:meth:`~stressbots.control.runner._Runner.park_orbits`; the geometry is :func:`~stressbots.control.parking.park_move`).

A park move is a wait (everyone orbits until the robot heads away from trouble) and a group straight. Found here:
the full shift, else shorter ones; no other mover's orbit left near trouble. Driven here: the wait, then the straight
checked again from the measured poses and, when it is not clear, the move planned again from there.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .parking import ParkMove, park_move

__all__ = ["ParkTries"]


class ParkTries:
    """Finding and driving the wait of one park move for the closed loop ``loop`` (its ``tune``, ``drive``, ``log`` and
    scenario names); ``group_move(move_fn, i, k, **settings)`` plans a group move of waiting robot ``i`` in D_k's phase
    from the present estimates."""

    def __init__(self, loop: Any, group_move: Callable[..., ParkMove | None]):
        self.loop = loop
        self.group_move = group_move

    def find(self, i: int, k: int, gap: float, margin: float) -> tuple[ParkMove | None, dict]:
        """``(move, settings)``: the park move of waiting robot ``i`` (D_k's phase, its orbit ``gap`` um from trouble) and
        the ``park_move`` settings it was found with; ``(None, settings)`` when none is clear. No other mover's orbit may
        end within ``margin`` um of trouble (the margin that called for this move) unless it was closer already. The full
        ``Tuning.park_shift_um`` first, then each of ``Tuning.park_short_shifts_um``: the straight of a low-ranked robot
        drives every higher-ranked one too, and at t = 0 no full shift of D_1 was clear for all eight movers while its
        orbit, 65 um from the edge, drifted into it within 51 s (tuning 69:0 at 1x)."""
        tune = self.loop.tune
        park: dict = {}
        for shift in (tune.park_shift_um, *tune.park_short_shifts_um):
            park = {"shift_um": shift, "clearance_um": tune.park_clearance_um, "keep_um": margin if tune.park_keeps_others else 0.0}
            move_ = None
            if gap < 0.0:  # it may be held where its disc meets the obstacle: a straight as it heads, if clear
                move_ = self.group_move(park_move, i, k, held=True, **park)
            if move_ is None:
                move_ = self.group_move(park_move, i, k, **park)
            if move_ is not None:
                return move_, park
        return None, park

    def drive_wait(self, i: int, k: int, move_: ParkMove | None, park: dict) -> ParkMove | None:
        """Drive the wait of park move ``move_`` of waiting robot ``i`` (D_k's phase); the move to drive then, or None.

        The straight is checked again from the measured poses: the other movers' headings after the wait were
        predicted with rates identified from little motion (one start-up park ran D_(n-1)'s orbit into the edge).
        When it is not clear, the move is planned again from there, wait and all, up to
        ``Tuning.park_replans_after_wait`` times. A move without a wait (a held robot's straight as it heads) has
        nothing predicted to check."""
        replans = self.loop.tune.park_replans_after_wait
        for replan in range(replans + 1):
            if move_ is None or move_.wait_s <= 0.0:
                return move_
            self.loop.drive([(k, move_.wait_s)])
            held = self.group_move(park_move, i, k, held=True, **park)
            if held is not None or replan == replans:
                return held
            move_ = self.group_move(park_move, i, k, **park)
            if move_ is not None:
                self.loop.log("park", i, f"after the wait the straight of {self.loop.scn.names[i]}'s orbit move is not clear: "
                                         "planned again from here")
        return None
