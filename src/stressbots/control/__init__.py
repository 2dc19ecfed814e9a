"""Control of the group through a plant: the Plant protocol and closed-loop assembly.

Modules: :mod:`~stressbots.control.runner` (the closed loop, :func:`assemble`), :mod:`~stressbots.control.pair`
(G_1, handed the loop; its stages :mod:`~stressbots.control.transfer` with its leg choice
:mod:`~stressbots.control.transfer_legs`, :mod:`~stressbots.control.rendezvous`, :mod:`~stressbots.control.departure`,
:mod:`~stressbots.control.holding`, :mod:`~stressbots.control.pair_recovery`),
:mod:`~stressbots.control.gross` (gross motion sigma_1, handed the loop; its ways off an obstacle and on,
:mod:`~stressbots.control.escapes`),
:mod:`~stressbots.control.single` (docking of the single robots D_k, k < n-1, handed the loop; where they aim and
what they can reach, :mod:`~stressbots.control.slot_approach`),
:mod:`~stressbots.control.loopview` (the protocols naming what each phase may use of the loop),
:mod:`~stressbots.control.queries` (pure geometric queries), :mod:`~stressbots.control.tuning`
(:class:`ControllerOptions` and the named thresholds :class:`Tuning`), :mod:`~stressbots.control.targets`
(slots from a nominal plan or the structure alone), :mod:`~stressbots.control.result`
(:class:`AssemblyResult`) and :mod:`~stressbots.control.determinism` (:func:`check_determinism`).

A *plant* is whatever the voltage signal drives and the camera watches: the built-in simulator
(:class:`stressbots.sim.SimulatedPlant`) or lab hardware (a waveform generator and a microscope camera).
The controller talks to it only through :class:`Plant`, so hardware can stand in for the simulator
unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from ..waveform import Segment

__all__ = ["Plant"]


@runtime_checkable
class Plant(Protocol):
    """What the controller may do with the robots: look at them and apply a voltage waveform.

    Methods
    -------
    observe() -> ndarray, shape (n, 3)
        One camera frame: ``(x_um, y_um, theta_rad)`` per robot in scenario order (theta clockwise
        from +y). A robot the camera does not see this frame is a row of NaN. Measurements carry the
        camera's error; they are all a controller ever learns about the robots.
    apply(waveform) -> None
        Send a waveform (a sequence of :class:`stressbots.waveform.Hold` / :class:`~stressbots.waveform.Drive`)
        and return when it has played. Arm states persist between calls (hysteresis), as on hardware.
    """

    def observe(self) -> np.ndarray: ...

    def apply(self, waveform: Sequence[Segment]) -> None: ...


# The closed-loop EDR controller (the paper's Appendix 3): its measured success rates and known limits
# are in docs/design.md and the README's Status section.
from .determinism import check_determinism  # noqa: E402
from .result import AssemblyResult  # noqa: E402
from .runner import assemble  # noqa: E402
from .targets import Targets, nominal_plan, structure_targets  # noqa: E402
from .tuning import ControllerOptions, Tuning  # noqa: E402

__all__ += ["AssemblyResult", "ControllerOptions", "Targets", "Tuning", "assemble", "check_determinism", "nominal_plan",
            "structure_targets"]
