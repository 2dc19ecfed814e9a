"""Plans: a control sequence of primitives with durations, and its file format ``plan.json``.

A plan is what the whole group receives: one primitive after another (a primitive is an arm-state
pattern reached by Holds, then a Drive), each for a duration. Which robots turn under each primitive is
written into the file, so an independent reader needs no voltage analysis to replay it. The format
is::

    {"format": "stressbots.plan/1",
     "robots": ["D1", "D2", "D3", "D4"],
     "primitives": [{"name": "P0", "turning": []}, {"name": "P1", "turning": ["D1"]}],
     "steps": [{"primitive": "P1", "duration_s": 2.5}]}

stressbots also writes ``"goals"`` (the slot of every robot, ``[x_um, y_um, heading_deg]``) and
``"provenance"`` (seed and versions); readers that do not know them can ignore them.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, StringConstraints, ValidationError

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


def join_steps(steps: Sequence[tuple[int, float]]) -> tuple[tuple[int, float], ...]:
    """Primitive steps ``(k, duration_s)`` (``P_k`` by index, as planner and controller build them) with neighbours
    under the same primitive joined into one; durations are kept as given (none dropped).

    >>> join_steps([(3, 1.0), (3, 0.5), (2, 2.0), (3, 1.0)])
    ((3, 1.5), (2, 2.0), (3, 1.0))
    """
    out: list[tuple[int, float]] = []
    for k, d in steps:
        if out and out[-1][0] == k:
            out[-1] = (k, out[-1][1] + d)
        else:
            out.append((k, d))
    return tuple(out)


def _fail(problem: str, source: str | None, field_: str | None = None) -> StressbotsError:
    return StressbotsError(problem, source=source, field=field_)


#: Longest plan (sum of its drive durations, s) a file may hold: an hour of drives is far beyond any
#: assembly (the example's plan takes about two minutes) and bounds what replaying it may cost.
MAX_PLAN_S = 3600.0
#: Most steps and primitives a plan file may list.
MAX_STEPS = 100_000
MAX_PRIMITIVES = 4096
#: Largest plan file read (bytes).
MAX_PLAN_BYTES = 20_000_000


def _short(v: Any) -> str:
    try:
        text = repr(v)
    except ValueError:  # an integer too large to print
        return "a huge integer"
    if not text.isprintable():
        text = text.encode("unicode_escape").decode("ascii")
    return text if len(text) <= 40 else text[:37] + "..."


def _robot_name(v: Any) -> str:
    from .scenario import _name_check

    return _name_check(v)


def _duration(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"must be a number of seconds in [0, {MAX_PLAN_S:g}], got {type(v).__name__} {_short(v)}")
    if not (0 <= v <= MAX_PLAN_S):  # exact for integers too large for a float; False for NaN
        raise ValueError(f"must be a number of seconds in [0, {MAX_PLAN_S:g}], got {_short(v)}")
    return float(v)


def _pose3(v: Any) -> list[float]:
    from .scenario import _pose_list

    if v is None:
        raise ValueError("must be [x_um, y_um, heading_deg], got null")
    return _pose_list(v)


_Name = Annotated[str, BeforeValidator(_robot_name)]


class _Model(BaseModel):
    model_config = ConfigDict(strict=True, extra="allow")


class _PrimitiveFile(_Model):
    name: Annotated[str, StringConstraints(min_length=1, max_length=64)]
    turning: Annotated[list[str], Field(max_length=64)]


class _StepFile(_Model):
    primitive: Annotated[str, StringConstraints(max_length=64)]
    duration_s: Annotated[float, BeforeValidator(_duration)]


class _PlanFile(_Model):
    format: Literal["stressbots.plan/1"]
    robots: Annotated[list[_Name], Field(min_length=1, max_length=64)]
    primitives: Annotated[list[_PrimitiveFile], Field(min_length=1, max_length=MAX_PRIMITIVES)]
    steps: Annotated[list[_StepFile], Field(max_length=MAX_STEPS)]
    goals: dict[str, Annotated[list[float], BeforeValidator(_pose3)]] | None = None
    provenance: dict[str, Any] | None = None


def _where(loc: tuple) -> str:
    out = ""
    for item in loc:
        key = str(item) if str(item).isprintable() and len(str(item)) <= 64 else _short(item)
        out += f"[{item}]" if isinstance(item, int) else (("." if out else "") + key)
    return out


def _problem(err: Mapping[str, Any]) -> str:
    kind, inp = err.get("type", ""), err.get("input")
    if kind == "missing":
        return "missing: this field is required"
    if kind == "literal_error":
        return f"must be {FORMAT!r}, got {_short(inp)}"
    msg = str(err.get("msg", "invalid value")).removeprefix("Value error, ")
    msg = msg[0].lower() + msg[1:]
    if kind.endswith("_type"):
        return f"{msg}, got {type(inp).__name__} {_short(inp)}"
    return msg


def from_dict(data: Any, *, source: str | None = None) -> Plan:
    """Validate a parsed plan.json; every problem is one line naming the field and what is accepted."""
    if not isinstance(data, dict):
        raise _fail(f"a plan must be a JSON object, got {type(data).__name__}", source)
    try:
        model = _PlanFile.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        raise _fail(_problem(err), source, _where(err["loc"]) or None) from None
    except RecursionError:
        raise _fail("nested too deeply to be a plan", source) from None
    robots = model.robots
    if len(set(robots)) != len(robots):
        raise _fail("robot names must be unique", source, "robots")
    prims: list[PlanPrimitive] = []
    for k, p in enumerate(model.primitives):
        unknown = [t for t in p.turning if t not in robots]
        if unknown:
            raise _fail(f"unknown robot {_short(unknown[0])} (not in robots)", source, f"primitives[{k}].turning")
        prims.append(PlanPrimitive(p.name, tuple(p.turning)))
    names = [p.name for p in prims]
    if len(set(names)) != len(names):
        raise _fail("primitive names must be unique", source, "primitives")
    steps: list[PlanStep] = []
    total = 0.0
    for k, st in enumerate(model.steps):
        if st.primitive not in names:
            raise _fail(f"unknown primitive {_short(st.primitive)} (not in primitives)", source, f"steps[{k}].primitive")
        total += st.duration_s
        if total > MAX_PLAN_S:
            raise _fail(f"the plan's drives add up to more than {MAX_PLAN_S:g} s (the longest plan accepted)", source,
                        f"steps[{k}].duration_s")
        steps.append(PlanStep(st.primitive, st.duration_s))
    goals: dict[str, Pose] = {}
    for name, g in (model.goals or {}).items():
        if name not in robots:
            raise _fail(f"unknown robot {_short(name)} (not in robots)", source, "goals")
        goals[name] = Pose.from_degrees(*g)
    return Plan(tuple(robots), tuple(prims), tuple(steps), goals, model.provenance or {})


def load(path) -> Plan:
    """Read and validate a plan.json file (errors name the file and the field)."""
    p = Path(path)
    source = str(path)
    if not p.is_file():
        raise _fail("no such file" if not p.exists() else "not a file", source)
    try:
        if p.stat().st_size > MAX_PLAN_BYTES:
            raise _fail(f"too large ({p.stat().st_size} bytes; a plan file has at most {MAX_PLAN_BYTES})", source)
        raw = p.read_bytes()
    except OSError as exc:
        raise _fail(f"cannot read: {exc.strerror}", source) from None
    try:
        data = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise _fail(f"not UTF-8 text (byte {exc.start}); expected plan JSON", source) from None
    except json.JSONDecodeError as exc:
        raise _fail(f"not valid JSON: {exc}", source) from None
    except RecursionError:
        raise _fail("not valid JSON: nested too deeply", source) from None
    except ValueError as exc:  # e.g. an integer with more digits than Python converts
        raise _fail(f"not valid JSON: {' '.join(str(exc).split())}", source) from None
    return from_dict(data, source=source)


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
