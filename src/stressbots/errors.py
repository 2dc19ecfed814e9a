"""The user-facing error taxonomy.

Every problem a user can cause (a bad file, a bad CLI argument, an impossible design, an unreachable goal)
is raised as a :class:`StressbotsError`. The CLI turns it into one ``error:`` line on stderr and exit
status 2, with no traceback. Library code raises these (or ``ValueError`` for programming errors in pure
functions); it never prints or exits.
"""

from __future__ import annotations


class StressbotsError(Exception):
    """A problem with the user's input, reported as one line.

    Parameters
    ----------
    problem:
        What is wrong, in words a user understands.
    source:
        The file (or CLI option) the problem is in, if any.
    field:
        The dotted field path inside that source (``robots[2].release_V``), if any.
    """

    def __init__(self, problem: str, *, source: str | None = None, field: str | None = None):
        self.problem = problem
        self.source = source
        self.field = field
        super().__init__(self.message)

    def __str__(self) -> str:  # current even when ``source`` is filled in later (e.g. by the CLI)
        return self.message

    @property
    def message(self) -> str:
        parts = [p for p in (self.source, self.field) if p]
        where = ": ".join(parts)
        return f"{where}: {self.problem}" if where else self.problem


class ScenarioError(StressbotsError):
    """A scenario file that cannot be read or does not describe a valid system."""


class DesignError(StressbotsError):
    """A voltage design that cannot work (thresholds, margins, drive band, limits)."""


class PlanningError(StressbotsError):
    """No plan could be found; the message says what blocks it."""


class WaveformError(StressbotsError):
    """A waveform that cannot be synthesised within the hardware's limits or does not decode."""
