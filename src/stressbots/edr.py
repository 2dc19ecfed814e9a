"""Former home of the closed-loop controller, kept so that ``import stressbots.edr`` goes on working.

The controller is the :mod:`stressbots.control` package now (issue 12); import from there.
"""

from __future__ import annotations

from .control import (
    AssemblyResult,
    ControllerOptions,
    Targets,
    Tuning,
    assemble,
    check_determinism,
    nominal_plan,
    structure_targets,
)

__all__ = ["AssemblyResult", "ControllerOptions", "Targets", "Tuning", "assemble", "check_determinism", "nominal_plan", "structure_targets"]
