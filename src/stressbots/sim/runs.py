"""Runs of the simulated plant: a plan's waveform, a plan run open loop, and the determinism check."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..waveform import Segment
from .plant import SimulatedPlant


def plan_waveform(scenario, plan, *, source: str | None = None) -> tuple[Segment, ...]:
    """The voltage waveform of a plan on this scenario's design (synthesised from all-up)."""
    from ..electrostatics import analyse_scenario
    from ..waveform import steps_from_plan, synthesize

    analysis = analyse_scenario(scenario)
    return synthesize(analysis, steps_from_plan(plan, analysis, source=source))


def run_plan(scenario, plan, *, seed: int | None = 0, record: bool = False, source: str | None = None) -> SimulatedPlant:
    """Execute a plan open loop: its whole waveform on a fresh plant from the start poses."""
    plant = SimulatedPlant(scenario, seed=seed, record=record)
    plant.apply(plan_waveform(scenario, plan, source=source))
    return plant


def _state(plant: SimulatedPlant, obs) -> dict[str, Any]:
    return {
        "true poses": plant.true_poses(),
        "observation": obs,
        "time_s": np.array([plant.time_s]),
        "docked": plant.docked,
        "stuck": plant.stuck,
        "arm states": plant.arm_states,
        "events": plant.events,
    }


def _first_difference(a: dict[str, Any], b: dict[str, Any], names: Sequence[str]) -> str | None:
    """The first quantity that differs between two states, bit for bit (NaN equals NaN)."""
    for key in a:
        x, y = a[key], b[key]
        if key == "events":
            if x != y:
                k = next((m for m, (p, q) in enumerate(zip(x, y, strict=False)) if p != q), min(len(x), len(y)))
                px = x[k] if k < len(x) else "nothing"
                py = y[k] if k < len(y) else "nothing"
                return f"event {k} differs: {px} vs {py}"
            continue
        if x is None and y is None:
            continue
        xa, ya = np.atleast_1d(np.asarray(x)), np.atleast_1d(np.asarray(y))
        if xa.shape != ya.shape:
            return f"{key}: shapes {xa.shape} vs {ya.shape}"
        for r in range(xa.shape[0]):
            if xa[r].tobytes() != ya[r].tobytes():
                who = f" of robot {names[r]}" if key != "time_s" else ""
                return f"{key}{who}: {xa[r].tolist()} vs {ya[r].tolist()}"
    return None


def check_determinism(
    scenario,
    waveforms: Sequence[Sequence[Segment]],
    seed: int,
    *,
    observe: bool = True,
    plant_factory=None,
) -> None:
    """Prove that a seed fixes a run bit for bit (in the spirit of Gymnasium's ``check_env``).

    Two plants with the same seed receive the same waveforms (and, with ``observe``, a camera frame after
    each); after every step their true poses, observations, time, flags, arm states and event logs must
    be bit-identical. A :meth:`SimulatedPlant.copy` taken halfway must then replay the second half
    bit-identically too.

    ``plant_factory(scenario, seed=...)`` builds the plants (default :class:`SimulatedPlant`; a subclass
    must keep its methods and ``copy``).

    Raises
    ------
    AssertionError
        Naming the first step and quantity that differ.
    """
    make = SimulatedPlant if plant_factory is None else plant_factory
    wfs = [tuple(w) for w in waveforms]
    a = make(scenario, seed=seed)
    b = make(scenario, seed=seed)
    half = len(wfs) // 2
    snapshot: list[dict[str, Any]] = []
    twin = None
    for k, wf in enumerate(wfs):
        if k == half:
            twin = a.copy()
        sa: list[Any] = []
        sb: list[Any] = []
        for plant, out in ((a, sa), (b, sb)):
            plant.apply(wf)
            out.append(_state(plant, plant.observe() if observe else None))
        diff = _first_difference(sa[0], sb[0], a.names)
        if diff is not None:
            raise AssertionError(f"seed {seed}, waveform {k}: two runs differ: {diff}")
        snapshot.append(sa[0])
    if twin is None:
        return
    for k in range(half, len(wfs)):
        twin.apply(wfs[k])
        st = _state(twin, twin.observe() if observe else None)
        diff = _first_difference(snapshot[k], st, a.names)
        if diff is not None:
            raise AssertionError(f"seed {seed}, waveform {k}: a copy taken before waveform {half} diverges: {diff}")

