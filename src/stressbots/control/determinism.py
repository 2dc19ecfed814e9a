"""Bit-for-bit reproducibility of closed-loop runs (in the spirit of Gymnasium's env checker)."""

from __future__ import annotations

import numpy as np

from ..errors import PlanningError
from .result import AssemblyResult
from .runner import assemble
from .targets import nominal_plan, structure_targets
from .tuning import ControllerOptions

__all__ = ["check_determinism"]


class _Recorder:
    """A plant wrapper recording every waveform applied and every frame observed (for determinism checks)."""

    def __init__(self, inner):
        self._inner = inner
        self.waveforms: list = []
        self.frames: list = []

    def observe(self):
        frame = np.asarray(self._inner.observe(), dtype=np.float64)
        self.frames.append(frame.copy())
        return frame

    def apply(self, waveform):
        self.waveforms.append(tuple(waveform))
        self._inner.apply(waveform)


def check_determinism(scenario, seed: int, *, plan=None, options: ControllerOptions | None = None, plant_factory=None) -> AssemblyResult:
    """Prove that a seed fixes a closed-loop run bit for bit (like :func:`stressbots.sim.check_determinism`).

    Two fresh plants with the same seed (``plant_factory(scenario, seed=...)``, default
    :class:`stressbots.sim.SimulatedPlant`) are driven by two runs of :func:`assemble`; every waveform the
    controller sends, every frame it receives, its event log, trace and result must be identical.
    Returns the first run's result.

    Raises
    ------
    AssertionError
        Naming the first quantity that differs.
    """
    if plant_factory is None:
        from ..sim import SimulatedPlant as plant_factory
    if plan is None:
        try:
            plan = nominal_plan(scenario)
        except PlanningError:
            plan = structure_targets(scenario)
    runs = []
    for _ in range(2):
        rec = _Recorder(plant_factory(scenario, seed=seed))
        res = assemble(scenario, rec, seed=seed, plan=plan, options=options)
        runs.append((rec, res))
    (ra, a), (rb, b) = runs
    if len(ra.waveforms) != len(rb.waveforms):
        raise AssertionError(f"seed {seed}: two runs differ: {len(ra.waveforms)} vs {len(rb.waveforms)} waveforms applied")
    for k, (wa, wb) in enumerate(zip(ra.waveforms, rb.waveforms, strict=True)):
        if wa != wb:
            raise AssertionError(f"seed {seed}: two runs differ: waveform {k} differs")
    for k, (fa, fb) in enumerate(zip(ra.frames, rb.frames, strict=False)):
        if not np.array_equal(fa, fb, equal_nan=True):
            raise AssertionError(f"seed {seed}: two runs differ: camera frame {k} differs")
    if a.events != b.events:
        if len(a.events) == len(b.events):
            first = next(k for k, (x, y) in enumerate(zip(a.events, b.events, strict=True)) if x != y)
        else:
            first = min(len(a.events), len(b.events))
        raise AssertionError(f"seed {seed}: two runs differ: event logs differ from event {first}")
    if not (np.array_equal(a.trace_t, b.trace_t) and np.array_equal(a.trace_poses, b.trace_poses)):
        raise AssertionError(f"seed {seed}: two runs differ: traces differ")
    if (a.success, a.failure, a.duration_s, a.replans) != (b.success, b.failure, b.duration_s, b.replans):
        raise AssertionError(f"seed {seed}: two runs differ: results differ")
    return a
