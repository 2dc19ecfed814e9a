"""Plans: a control sequence of primitives with durations, and its file format ``plan.json``.

A plan is what the whole group receives: one primitive after another (SPEC 4: a primitive is an arm-state
pattern reached by a Hold, then a Drive), each for a duration. Which robots turn under each primitive is
written into the file, so an independent reader needs no voltage analysis to replay it. The format
(SPEC 7) is::

    {"format": "stressbots.plan/1",
     "robots": ["D1", "D2", "D3", "D4"],
     "primitives": [{"name": "P0", "turning": []}, {"name": "P1", "turning": ["D1"]}],
     "steps": [{"primitive": "P1", "duration_s": 2.5}]}

stressbots also writes ``"goals"`` (the slot of every robot, ``[x_um, y_um, heading_deg]``) and
``"provenance"`` (seed and versions); readers that do not know them can ignore them.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import StressbotsError
from .robots import Pose

FORMAT = "stressbots.plan/1"


@dataclass(frozen=True)
class PlanPrimitive:
    """A primitive as a plan names it: its name and the robots whose arm is down (turning)."""

    name: str
    turning: tuple[str, ...]


@dataclass(frozen=True)
class PlanStep:
    """Apply ``primitive`` for ``duration_s`` seconds of power delivery."""

    primitive: str
    duration_s: float


@dataclass(frozen=True)
class Plan:
    """A control sequence for the group, with the robots' slots.

    ``robots`` is the scenario order; ``goals`` maps robot name to its slot pose (rad).
    """

    robots: tuple[str, ...]
    primitives: tuple[PlanPrimitive, ...]
    steps: tuple[PlanStep, ...]
    goals: Mapping[str, Pose] = field(default_factory=dict)
    provenance: Mapping[str, Any] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return float(sum(s.duration_s for s in self.steps))

    def primitive(self, name: str) -> PlanPrimitive:
        for p in self.primitives:
            if p.name == name:
                return p
        raise KeyError(name)

    def turning_matrix(self) -> np.ndarray:
        """``(len(steps), n)`` bool: which robot (scenario order) turns during each step."""
        index = {name: i for i, name in enumerate(self.robots)}
        by_name = {p.name: p for p in self.primitives}
        out = np.zeros((len(self.steps), len(self.robots)), dtype=bool)
        for k, step in enumerate(self.steps):
            for name in by_name[step.primitive].turning:
                out[k, index[name]] = True
        return out

    def durations(self) -> np.ndarray:
        return np.array([s.duration_s for s in self.steps], dtype=np.float64)

    def goal_array(self) -> np.ndarray:
        """Slots ``(n, 3)`` in scenario order (rad); NaN rows for robots without a slot."""
        out = np.full((len(self.robots), 3), np.nan)
        for i, name in enumerate(self.robots):
            if name in self.goals:
                out[i] = self.goals[name]
        return out

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "format": FORMAT,
            "robots": list(self.robots),
            "primitives": [{"name": p.name, "turning": list(p.turning)} for p in self.primitives],
            "steps": [{"primitive": s.primitive, "duration_s": float(s.duration_s)} for s in self.steps],
        }
        if self.goals:
            d["goals"] = {name: Pose(*self.goals[name]).to_degrees() for name in self.robots if name in self.goals}
        if self.provenance:
            d["provenance"] = dict(self.provenance)
        return d


def merge_steps(steps: Sequence[PlanStep], *, min_duration_s: float = 0.0) -> tuple[PlanStep, ...]:
    """Join consecutive steps of the same primitive and drop steps not longer than ``min_duration_s``."""
    out: list[PlanStep] = []
    for s in steps:
        if s.duration_s <= min_duration_s:
            continue
        if out and out[-1].primitive == s.primitive:
            out[-1] = PlanStep(s.primitive, out[-1].duration_s + s.duration_s)
        else:
            out.append(s)
    return tuple(out)


def _fail(problem: str, source: str | None, field_: str | None = None) -> StressbotsError:
    return StressbotsError(problem, source=source, field=field_)


def from_dict(data: Any, *, source: str | None = None) -> Plan:
    """Validate a parsed plan.json; every problem is one line naming the field."""
    if not isinstance(data, dict):
        raise _fail("a plan must be a JSON object", source)
    if data.get("format") != FORMAT:
        raise _fail(f"must be {FORMAT!r}, got {data.get('format')!r}", source, "format")
    robots = data.get("robots")
    if not isinstance(robots, list) or not robots or not all(isinstance(r, str) and r for r in robots):
        raise _fail("must be a non-empty list of robot names", source, "robots")
    if len(set(robots)) != len(robots):
        raise _fail("robot names must be unique", source, "robots")
    prims_raw = data.get("primitives")
    if not isinstance(prims_raw, list) or not prims_raw:
        raise _fail("must be a non-empty list of {name, turning}", source, "primitives")
    prims: list[PlanPrimitive] = []
    for k, p in enumerate(prims_raw):
        where = f"primitives[{k}]"
        if not isinstance(p, dict) or not isinstance(p.get("name"), str) or not p["name"]:
            raise _fail("must be an object with a name", source, where)
        turning = p.get("turning")
        if not isinstance(turning, list) or not all(isinstance(t, str) for t in turning):
            raise _fail("must be a list of robot names", source, f"{where}.turning")
        unknown = [t for t in turning if t not in robots]
        if unknown:
            raise _fail(f"unknown robot {unknown[0]!r} (not in robots)", source, f"{where}.turning")
        prims.append(PlanPrimitive(p["name"], tuple(turning)))
    names = [p.name for p in prims]
    if len(set(names)) != len(names):
        raise _fail("primitive names must be unique", source, "primitives")
    steps_raw = data.get("steps")
    if not isinstance(steps_raw, list):
        raise _fail("must be a list of {primitive, duration_s}", source, "steps")
    steps: list[PlanStep] = []
    for k, s in enumerate(steps_raw):
        where = f"steps[{k}]"
        if not isinstance(s, dict):
            raise _fail("must be an object {primitive, duration_s}", source, where)
        if s.get("primitive") not in names:
            raise _fail(f"unknown primitive {s.get('primitive')!r}", source, f"{where}.primitive")
        d = s.get("duration_s")
        if isinstance(d, bool) or not isinstance(d, (int, float)) or not math.isfinite(d) or d < 0:
            raise _fail(f"must be a finite number >= 0, got {d!r}", source, f"{where}.duration_s")
        steps.append(PlanStep(s["primitive"], float(d)))
    goals: dict[str, Pose] = {}
    for name, g in (data.get("goals") or {}).items():
        if name not in robots or not isinstance(g, list) or len(g) != 3:
            raise _fail("must map robot names to [x_um, y_um, heading_deg]", source, f"goals.{name}")
        goals[name] = Pose.from_degrees(*g)
    return Plan(tuple(robots), tuple(prims), tuple(steps), goals, data.get("provenance") or {})


def load(path) -> Plan:
    """Read and validate a plan.json file."""
    p = Path(path)
    if not p.is_file():
        raise _fail("no such file" if not p.exists() else "not a file", str(path))
    try:
        data = json.loads(p.read_bytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise _fail(f"not valid JSON: {exc}", str(path)) from None
    return from_dict(data, source=str(path))


def save(plan: Plan, path) -> Path:
    from .outputs import write_json

    return write_json(path, plan.to_dict())


def check_against(plan: Plan, scenario, *, source: str | None = None) -> None:
    """Check that a plan's robots are the scenario's robots (any order), naming the first difference."""
    missing = [n for n in scenario.names if n not in plan.robots]
    extra = [n for n in plan.robots if n not in scenario.names]
    if missing or extra:
        what = f"robot {missing[0]!r} of the scenario is not in the plan" if missing else f"robot {extra[0]!r} is not in the scenario"
        raise _fail(what, source, "robots")
