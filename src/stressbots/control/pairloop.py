"""What the G_1 pair phase uses of the closed loop (:class:`PairLoop`), and how one of its stages says it
has no solution from where the robots are (:class:`Replan`: the pair's gross motion is planned again).

Shared by :mod:`~stressbots.control.pair` and its stages (:mod:`~stressbots.control.transfer`,
:mod:`~stressbots.control.transfer_legs`, :mod:`~stressbots.control.rendezvous`, :mod:`~stressbots.control.departure`,
:mod:`~stressbots.control.holding`, :mod:`~stressbots.control.pair_recovery`), so none imports another's module for them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from .loopview import DockingLoop

__all__ = ["PairLoop", "Replan"]


class Replan(Exception):
    """A stage of G_1 has no solution from here: the pair's gross motion is planned again (not a failure yet)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class PairLoop(DockingLoop, Protocol):
    """What the pair phase uses of the closed loop (:class:`~stressbots.control.loop.PlantLoop` and the controller)."""

    n: int
    rank: np.ndarray
    t: float
    replans: int
    nominal_goals: np.ndarray
    gross: Any
    """The loop's gross motion (:class:`~stressbots.control.gross.GrossMotion`): its roadmap routes."""

    @property
    def rstar(self) -> np.ndarray: ...

    def predicted_track(self, steps: Sequence[tuple[int, float]], dt_s: float = 0.1) -> np.ndarray:
        """Every robot's predicted poses (S, n, 3) along ``steps`` (:meth:`stressbots.control.loop.PlantLoop.predicted_track`)."""

    def park_orbits(self, k: int, top: int | None = None, margin_um: float | None = None, among: Sequence[int] = ()) -> None:
        """Move waiting orbits that drifted near trouble (:meth:`stressbots.control.runner._Runner.park_orbits`)."""
