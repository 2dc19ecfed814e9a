"""What the controller's phases may use of the closed loop: typing protocols, nothing that runs.

Each phase (:mod:`~stressbots.control.gross`, :mod:`~stressbots.control.single`,
:mod:`~stressbots.control.pair`) is handed the loop (:class:`~stressbots.control.loop.PlantLoop` and the
controller built on it) and names what it reads and calls through a :class:`typing.Protocol`, so that no
phase imports the runner. :class:`LoopView` is what every phase uses (the scenario, the estimates, the
log, the one ``drive``); :class:`DockingLoop` adds what the phases that dock robots share (the slots,
obstacle queries, steering). Each phase's own protocol extends one of them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import numpy as np

from .tuning import ControllerOptions, Tuning

if TYPE_CHECKING:
    from .gross import SteerOutcome
    from .straight_drift import StraightDrift

__all__ = ["DockingLoop", "Look", "LoopView", "Steps"]

Steps = list[tuple[int, float]]
"""Primitive steps ``(k, duration_s)``: apply P_k for that long."""


class Look(NamedTuple):
    """What a policy yields instead of steps to have the loop read ``frames`` camera frames while nobody moves
    (:meth:`~stressbots.control.loop.PlantLoop.look`): the estimate of a robot about to dock, sharpened."""

    frames: int
    prior_frames: float
    """How many frames' worth the estimate counts against their mean."""


class LoopView(Protocol):
    """What every phase uses of the closed loop: the scenario, the estimates (um, rad, um/s), the log and ``drive``."""

    scn: Any
    L: np.ndarray
    W: np.ndarray
    docked: np.ndarray
    tx: float
    tune: Tuning
    opts: ControllerOptions

    @property
    def est(self) -> np.ndarray: ...

    @property
    def v_hat(self) -> np.ndarray: ...

    @property
    def r_hat(self) -> np.ndarray: ...

    def log(self, kind: str, robot: int | None = None, detail: str = "") -> None: ...

    def drive(self, steps: Sequence[tuple[int, float]]) -> None: ...


class DockingLoop(LoopView, Protocol):
    """What the phases that dock robots (single robots, the G_1 pair) share: slots, motion, obstacles, steering."""

    by_rank: dict[int, int]
    v: np.ndarray
    r: np.ndarray
    goals: np.ndarray
    motion: tuple[float, np.ndarray, np.ndarray] | None
    straight_drift: StraightDrift

    @property
    def omega_hat(self) -> np.ndarray: ...

    def abort(self, reason: str) -> Exception: ...

    def orbiting_below(self, k: int) -> list[int]: ...

    def obstacles_hit(self, samples: np.ndarray, i: int, orbiting: Sequence[int], *, extra_discs=(), clearance: float | None = None,
                      target=None) -> bool: ...

    def interpolated_steps(self, rho_turn: float, duration: float, turn_k: int, straight_k: int) -> Steps: ...

    def steer(self, i: int, target: np.ndarray, turn_k: int, straight_k: int, orbiting: Sequence[int], *, extra_discs=(),
              max_cycles: int = 400, ready: Callable[[], bool] | None = None, via: bool = True,
              clearance: float | None = None, ready_if_blocked: Callable[[], tuple[str, str] | None] | None = None,
              waypoint: bool = False, region: np.ndarray | None = None) -> SteerOutcome: ...
