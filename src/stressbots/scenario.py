"""Scenario files: the TOML format of the README's "Scenario files", loaded into immutable values.

A scenario names the robots (body, motion and electrostatic parameters, optional start and goal poses),
the electrode limits, an optional target structure, the control error model and the controller's
settings. Files write angles in degrees; the loaded :class:`Scenario` holds radians.

Validation happens here, once: every later stage can trust a :class:`Scenario`. Any problem is raised
as a :class:`~stressbots.errors.ScenarioError` naming the file, the field and the problem, e.g.
``four.toml: robots[2] (D3).release_V: must be below snap_down_V (120.0)``.

Examples
--------
>>> from stressbots.scenario import loads
>>> s = loads('''
... [[robots]]
... name = "A"
... snap_down_V = 120.0
... release_V = 30.0
... ''')
>>> s.robots[0].turn_radius_um
200.0
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, NamedTuple

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, field_validator

from .electrostatics import Electrodes
from .errors import ScenarioError
from .robots import Pose, Robot

__all__ = [
    "Noise",
    "ControlSettings",
    "StructureSpec",
    "Scenario",
    "load",
    "loads",
    "from_dict",
    "check_movable",
    "crossing_s",
    "check_starts",
    "LIMITS",
    "Range",
]


@dataclass(frozen=True)
class Noise:
    """Control error and sensing error (``[noise]``); all zero means nominal.

    Relative standard deviations are fractions (0.05 = 5 %). Heading drift is in rad per um driven in
    the Python API (the file gives deg/mm).
    """

    speed_rel_sd: float = 0.0
    turn_radius_rel_sd: float = 0.0
    heading_drift_rad_per_um: float = 0.0
    camera_position_sd_um: float = 0.0
    camera_heading_sd_rad: float = 0.0
    camera_dropout: float = 0.0

    @property
    def is_nominal(self) -> bool:
        return all(v == 0.0 for v in self.__dict__.values())

    def to_file_units(self) -> dict[str, float]:
        """The ``[noise]`` table as the file writes it (deg, deg/mm)."""
        return {
            "speed_rel_sd": self.speed_rel_sd,
            "turn_radius_rel_sd": self.turn_radius_rel_sd,
            "heading_drift_deg_per_mm": math.degrees(self.heading_drift_rad_per_um) * 1000.0,
            "camera_position_sd_um": self.camera_position_sd_um,
            "camera_heading_sd_deg": math.degrees(self.camera_heading_sd_rad),
            "camera_dropout": self.camera_dropout,
        }

    def scaled(self, factor: float) -> Noise:
        """Every error level multiplied by ``factor`` (dropout capped below 1)."""
        return Noise(
            speed_rel_sd=self.speed_rel_sd * factor,
            turn_radius_rel_sd=self.turn_radius_rel_sd * factor,
            heading_drift_rad_per_um=self.heading_drift_rad_per_um * factor,
            camera_position_sd_um=self.camera_position_sd_um * factor,
            camera_heading_sd_rad=self.camera_heading_sd_rad * factor,
            camera_dropout=min(self.camera_dropout * factor, 0.95),
        )


@dataclass(frozen=True)
class ControlSettings:
    """Closed-loop controller settings (``[control]``)."""

    replan_interval_s: float = 1.0


@dataclass(frozen=True)
class StructureSpec:
    """A named target shape placed in the arena (``[structure]``); ``at`` is the structure's frame."""

    shape: str
    at: Pose


@dataclass(frozen=True)
class Scenario:
    """A validated scenario. Robots are in file order (the "scenario order" of the contracts)."""

    name: str
    robots: tuple[Robot, ...]
    electrodes: Electrodes = field(default_factory=Electrodes)
    arena_um: tuple[float, float] | None = None
    structure: StructureSpec | None = None
    noise: Noise = field(default_factory=Noise)
    control: ControlSettings = field(default_factory=ControlSettings)
    source: str | None = None

    @property
    def n(self) -> int:
        return len(self.robots)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.robots)

    def index(self, name: str) -> int:
        """Scenario-order index of the robot called ``name``."""
        return self.names.index(name)

    def robot(self, name: str) -> Robot:
        return self.robots[self.index(name)]

    @property
    def snap_down_V(self) -> np.ndarray:
        return np.array([r.snap_down_V for r in self.robots], dtype=np.float64)

    @property
    def release_V(self) -> np.ndarray:
        return np.array([r.release_V for r in self.robots], dtype=np.float64)

    @property
    def lengths_um(self) -> np.ndarray:
        return np.array([r.length_um for r in self.robots], dtype=np.float64)

    @property
    def widths_um(self) -> np.ndarray:
        return np.array([r.width_um for r in self.robots], dtype=np.float64)

    @property
    def speeds_um_s(self) -> np.ndarray:
        return np.array([r.speed_um_s for r in self.robots], dtype=np.float64)

    @property
    def turn_radii_um(self) -> np.ndarray:
        return np.array([r.turn_radius_um for r in self.robots], dtype=np.float64)

    @property
    def has_starts(self) -> bool:
        return all(r.start is not None for r in self.robots)

    @property
    def starts(self) -> np.ndarray:
        """Start poses ``(n, 3)`` (rad); raises :class:`ScenarioError` when a robot has none."""
        return self._poses("start")

    @property
    def goals(self) -> np.ndarray:
        """Explicit goal poses ``(n, 3)`` (rad); raises when a robot has none."""
        return self._poses("goal")

    def _poses(self, which: str) -> np.ndarray:
        rows = []
        for i, r in enumerate(self.robots):
            p = getattr(r, which)
            if p is None:
                raise ScenarioError(
                    f"missing: this command needs a {which} pose for every robot",
                    source=self.source,
                    field=f"robots[{i}] ({r.name}).{which}",
                )
            rows.append(p)
        return np.array(rows, dtype=np.float64).reshape(len(rows), 3)

    def with_noise(self, noise: Noise) -> Scenario:
        return replace(self, noise=noise)

    def with_robots(self, robots) -> Scenario:
        return replace(self, robots=tuple(robots))


# ----------------------------------------------------------------------------------------------------
# Accepted ranges. Every number a scenario file gives must lie in its range: the ranges are physically
# plausible for MEMS microrobots on an electrode array, and they bound what any command can be asked to
# compute (robots, arena extent, travel times, random draws), so no input makes a run allocate absurdly
# or take forever. The README's "Scenario files" section lists the same table (a test checks it).


class Range(NamedTuple):
    """Accepted closed interval ``[low, high]`` of a scenario field, in the file's ``unit``.

    ``open_low`` makes the low end exclusive (``low < value``)."""

    low: float
    high: float
    unit: str
    open_low: bool = False

    def text(self) -> str:
        lo = "(" if self.open_low else "["
        unit = f" {self.unit}" if self.unit else ""
        return f"{lo}{self.low:g}, {self.high:g}]{unit}"

    def contains(self, value: float) -> bool:
        above = value > self.low if self.open_low else value >= self.low
        return above and value <= self.high


#: Longest scenario, robot or structure name (characters); names are printed in tables and file names.
MAX_NAME_CHARS = 64
#: Most robots a scenario file may hold (voltage analysis and design; the accessible-state search of a
#: non-STRING design is capped separately).
MAX_ROBOTS = 100
#: Most robots the commands that move them (simulate, run, bounds, montecarlo) accept: the controller's
#: and the simulator's work grows quickly with N (checked by :func:`check_movable`).
MAX_MOVING_ROBOTS = 8
#: Most robots ``stressbots plan`` accepts (:func:`check_movable` with ``planning_only``): the planner
#: plans 4 of the 5 generated 16-robot layouts of benchmarks/bench_planner.py in 4-30 s of CPU.
MAX_PLANNED_ROBOTS = 16
#: Longest crossing (s, :func:`crossing_s`) ``stressbots plan`` accepts: a plan is not simulated in
#: closed loop, so only the replay's length grows with it (generated 16-robot layouts cross in ~150 s).
MAX_PLANNED_CROSSING_S = 400.0
#: Largest scenario file read (bytes): a scenario of MAX_ROBOTS robots is a few kB.
MAX_FILE_BYTES = 1_000_000
#: Longest crossing of the layout at the slowest robot's speed (s, :func:`crossing_s`) that the commands
#: moving robots accept: a run lasts a few crossings, so this bounds its simulated time (the example: 42 s).
MAX_CROSSING_S = 100.0
#: Most camera measurements (re-plans) per crossing (crossing / replan_interval_s; the example: 42): the
#: controller's work grows with them.
MAX_MEASUREMENTS_PER_CROSSING = 200

#: The accepted range of every numeric field, by its name in the file (``x``/``y``/``heading`` are the
#: items of the start, goal and ``[structure] at`` poses). The noise levels go up to about ten times the
#: literature's (speed 5 %, radius 3 %, drift 3.7 deg/mm, camera 2 um / 1 deg, 2 % dropout).
LIMITS: dict[str, Range] = {
    "arena_um": Range(200.0, 20_000.0, "um"),
    "x_um, y_um": Range(-20_000.0, 20_000.0, "um"),
    "heading_deg": Range(-3600.0, 3600.0, "deg"),
    "length_um": Range(10.0, 2_000.0, "um"),
    "width_um": Range(5.0, 1_000.0, "um"),
    "speed_um_s": Range(10.0, 5_000.0, "um/s"),
    "turn_radius_um": Range(10.0, 10_000.0, "um"),
    "snap_down_V": Range(0.0, 1_000.0, "V"),
    "release_V": Range(0.0, 1_000.0, "V"),
    "max_V": Range(1.0, 1_000.0, "V"),
    "margin_V": Range(0.0, 100.0, "V"),
    "drive_low_V": Range(0.0, 1_000.0, "V"),
    "drive_high_V": Range(0.0, 1_000.0, "V", open_low=True),
    "drive_frequency_hz": Range(1.0, 50_000.0, "Hz"),
    "hold_s": Range(1e-5, 1.0, "s"),
    "speed_rel_sd": Range(0.0, 0.3, ""),
    "turn_radius_rel_sd": Range(0.0, 0.3, ""),
    "heading_drift_deg_per_mm": Range(0.0, 50.0, "deg/mm"),
    "camera_position_sd_um": Range(0.0, 50.0, "um"),
    "camera_heading_sd_deg": Range(0.0, 20.0, "deg"),
    "camera_dropout": Range(0.0, 0.5, ""),
    "replan_interval_s": Range(0.25, 60.0, "s"),
}


def _show(v: Any) -> str:
    """A short, printable rendering of a user value (never a 10,000-digit integer or a newline)."""
    try:
        text = repr(v)
    except ValueError:  # int too large to print
        return "a huge integer"
    if not text.isprintable():
        text = text.encode("unicode_escape").decode("ascii")
    return text if len(text) <= 40 else text[:37] + "..."


def number_in(key: str, v: Any) -> float:
    """``v`` as a float if it is a real number (not a bool or a string) within ``LIMITS[key]``."""
    rng = LIMITS[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"must be a number in {rng.text()}, got {type(v).__name__} {_show(v)}")
    if isinstance(v, float) and not math.isfinite(v):
        raise ValueError(f"must be a finite number in {rng.text()}, got {_show(v)}")
    if not rng.contains(v):  # compares exactly, also for integers too large for a float
        raise ValueError(f"must be in {rng.text()}, got {_show(v)}")
    return float(v)


def _num(key: str):
    return Annotated[float, BeforeValidator(lambda v: number_in(key, v))]


def _name_check(v: Any) -> str:
    if not isinstance(v, str):
        raise ValueError(f"must be a string, got {type(v).__name__} {_show(v)}")
    if not v.strip():
        raise ValueError("must not be blank")
    if len(v) > MAX_NAME_CHARS:
        raise ValueError(f"must have at most {MAX_NAME_CHARS} characters, got {len(v)}")
    if not v.isprintable():
        raise ValueError(f"must be printable (no newline, tab or control characters), got {_show(v)}")
    if v != v.strip():
        raise ValueError("must not start or end with spaces")
    return v


_Name = Annotated[str, BeforeValidator(_name_check)]


def _is_clean_name(v: str) -> bool:
    try:
        return _name_check(v) == v
    except ValueError:
        return False


def _pose_list(v: Any) -> Any:
    if v is None:
        return v
    if not isinstance(v, list):
        raise ValueError(f"must be a list [x_um, y_um, heading_deg], got {type(v).__name__} {_show(v)}")
    if len(v) != 3:
        raise ValueError(f"must have 3 numbers [x_um, y_um, heading_deg], got {len(v)}")
    out = []
    for k, (x, key) in enumerate(zip(v, ("x_um, y_um", "x_um, y_um", "heading_deg"), strict=True)):
        try:
            out.append(number_in(key, x))
        except ValueError as exc:
            raise ValueError(f"item {k} ({('x_um', 'y_um', 'heading_deg')[k]}) {exc}") from None
    return out


# ----------------------------------------------------------------------------------------------------
# File schema (pydantic). Kept private: the public values are the frozen dataclasses above.


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class _RobotDefaults(_Strict):
    length_um: _num("length_um") | None = None  # type: ignore[valid-type]
    width_um: _num("width_um") | None = None  # type: ignore[valid-type]
    speed_um_s: _num("speed_um_s") | None = None  # type: ignore[valid-type]
    turn_radius_um: _num("turn_radius_um") | None = None  # type: ignore[valid-type]
    snap_down_V: _num("snap_down_V") | None = None  # type: ignore[valid-type]
    release_V: _num("release_V") | None = None  # type: ignore[valid-type]


class _RobotFile(_RobotDefaults):
    name: _Name
    start: list[float] | None = None
    goal: list[float] | None = None

    @field_validator("start", "goal", mode="before")
    @classmethod
    def _poses(cls, v):
        return _pose_list(v)


class _ElectrodesFile(_Strict):
    max_V: _num("max_V") = 200.0  # type: ignore[valid-type]
    margin_V: _num("margin_V") = 5.0  # type: ignore[valid-type]
    drive_low_V: _num("drive_low_V") = 75.0  # type: ignore[valid-type]
    drive_high_V: _num("drive_high_V") = 105.0  # type: ignore[valid-type]
    drive_frequency_hz: _num("drive_frequency_hz") = 10000.0  # type: ignore[valid-type]
    hold_s: _num("hold_s") = 0.001  # type: ignore[valid-type]


class _NoiseFile(_Strict):
    speed_rel_sd: _num("speed_rel_sd") = 0.0  # type: ignore[valid-type]
    turn_radius_rel_sd: _num("turn_radius_rel_sd") = 0.0  # type: ignore[valid-type]
    heading_drift_deg_per_mm: _num("heading_drift_deg_per_mm") = 0.0  # type: ignore[valid-type]
    camera_position_sd_um: _num("camera_position_sd_um") = 0.0  # type: ignore[valid-type]
    camera_heading_sd_deg: _num("camera_heading_sd_deg") = 0.0  # type: ignore[valid-type]
    camera_dropout: _num("camera_dropout") = 0.0  # type: ignore[valid-type]


class _ControlFile(_Strict):
    replan_interval_s: _num("replan_interval_s") = 1.0  # type: ignore[valid-type]


class _StructureFile(_Strict):
    shape: _Name
    at: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0])

    @field_validator("at", mode="before")
    @classmethod
    def _at(cls, v):
        return _pose_list(v)


def _robot_list(v: Any) -> Any:
    if isinstance(v, list) and len(v) > MAX_ROBOTS:
        raise ValueError(f"at most {MAX_ROBOTS} robots are supported, got {len(v)}")
    return v


def _arena_list(v: Any) -> Any:
    if v is None:
        return v
    if not isinstance(v, list) or len(v) != 2:
        raise ValueError(f"must be [width_um, height_um], got {_show(v)}")
    return [number_in("arena_um", x) for x in v]


class _ScenarioFile(_Strict):
    name: _Name = "scenario"
    arena_um: Annotated[list[float] | None, BeforeValidator(_arena_list)] = None
    robot_defaults: _RobotDefaults = Field(default_factory=_RobotDefaults)
    electrodes: _ElectrodesFile = Field(default_factory=_ElectrodesFile)
    robots: Annotated[list[_RobotFile], BeforeValidator(_robot_list)] = Field(min_length=1)
    structure: _StructureFile | None = None
    noise: _NoiseFile = Field(default_factory=_NoiseFile)
    control: _ControlFile = Field(default_factory=_ControlFile)


def _field_path(loc: tuple, data: Any) -> str:
    """Dotted path of a pydantic error location, naming robots by index and name."""
    parts: list[str] = []
    node = data
    for item in loc:
        if isinstance(item, int):
            label = f"[{item}]"
            if isinstance(node, list) and 0 <= item < len(node):
                node = node[item]
                if isinstance(node, dict) and isinstance(node.get("name"), str):
                    label += f" ({node['name']})" if _is_clean_name(node["name"]) else f" ({_show(node['name'])})"
            else:
                node = None
            if parts:
                parts[-1] += label
            else:
                parts.append(label)
        else:
            parts.append(str(item) if str(item).isprintable() and len(str(item)) <= 64 else _show(item))
            node = node.get(item) if isinstance(node, dict) else None
    return ".".join(parts)


def _friendly(err: Mapping[str, Any]) -> str:
    kind = err.get("type", "")
    inp = err.get("input")
    if kind == "missing":
        return "missing: this field is required"
    if kind == "extra_forbidden":
        return "unknown field (check the spelling; the README's 'Scenario files' lists every field)"
    if kind in ("finite_number",):
        return f"must be a finite number, got {inp!r}"
    msg = err.get("msg", "invalid value")
    msg = msg.removeprefix("Value error, ")
    if kind.endswith("_type") or kind.endswith("_parsing"):
        return f"{msg[0].lower()}{msg[1:]}, got {type(inp).__name__} {_show(inp)}"
    return f"{msg[0].lower()}{msg[1:]}"


def from_dict(data: dict, *, source: str | None = None) -> Scenario:
    """Validate a parsed TOML document and build a :class:`Scenario`."""
    try:
        model = _ScenarioFile.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        raise ScenarioError(_friendly(err), source=source, field=_field_path(err["loc"], data)) from None
    robots = _robots(model, source)
    electrodes = _electrodes(model.electrodes, source)
    arena = (float(model.arena_um[0]), float(model.arena_um[1])) if model.arena_um is not None else None
    if arena is not None:
        _check_in_arena(robots, arena, source)
    structure = _structure(model.structure, robots, source)
    nf = model.noise
    noise = Noise(
        speed_rel_sd=nf.speed_rel_sd,
        turn_radius_rel_sd=nf.turn_radius_rel_sd,
        heading_drift_rad_per_um=math.radians(nf.heading_drift_deg_per_mm) / 1000.0,
        camera_position_sd_um=nf.camera_position_sd_um,
        camera_heading_sd_rad=math.radians(nf.camera_heading_sd_deg),
        camera_dropout=nf.camera_dropout,
    )
    return Scenario(
        name=model.name,
        robots=tuple(robots),
        electrodes=electrodes,
        arena_um=arena,
        structure=structure,
        noise=noise,
        control=ControlSettings(replan_interval_s=model.control.replan_interval_s),
        source=source,
    )


def _pick(rf: _RobotFile, defaults: _RobotDefaults, key: str, default: float | None, where: str, source: str | None) -> float:
    """A robot's value: its own, else ``[robot_defaults]``'s, else ``default`` (None: required)."""
    for holder in (rf, defaults):
        value = getattr(holder, key)
        if value is not None:
            return float(value)
    if default is None:
        raise ScenarioError("missing: give it per robot or in [robot_defaults]", source=source, field=f"{where}.{key}")
    return default


def _robots(model: _ScenarioFile, source: str | None) -> list[Robot]:
    robots: list[Robot] = []
    seen: dict[str, int] = {}
    d = model.robot_defaults
    for i, rf in enumerate(model.robots):
        where = f"robots[{i}] ({rf.name})"
        if rf.name in seen:
            raise ScenarioError(f"duplicate robot name (also robots[{seen[rf.name]}])", source=source, field=f"{where}.name")
        seen[rf.name] = i
        v_d = _pick(rf, d, "snap_down_V", None, where, source)
        v_u = _pick(rf, d, "release_V", None, where, source)
        if v_u >= v_d:
            raise ScenarioError(
                f"must be below snap_down_V ({v_d:g} V), got {v_u:g} V (V_u < V_d is required for hysteresis)",
                source=source,
                field=f"{where}.release_V",
            )
        robots.append(
            Robot(
                name=rf.name,
                snap_down_V=v_d,
                release_V=v_u,
                length_um=_pick(rf, d, "length_um", 260.0, where, source),
                width_um=_pick(rf, d, "width_um", 60.0, where, source),
                speed_um_s=_pick(rf, d, "speed_um_s", 100.0, where, source),
                turn_radius_um=_pick(rf, d, "turn_radius_um", 200.0, where, source),
                start=Pose.from_degrees(*rf.start) if rf.start is not None else None,
                goal=Pose.from_degrees(*rf.goal) if rf.goal is not None else None,
            )
        )
    return robots


def _electrodes(e: _ElectrodesFile, source: str | None) -> Electrodes:
    if e.drive_low_V >= e.drive_high_V:
        raise ScenarioError(
            f"must be below drive_high_V ({e.drive_high_V:g} V), got {e.drive_low_V:g} V",
            source=source,
            field="electrodes.drive_low_V",
        )
    if e.drive_high_V > e.max_V:
        raise ScenarioError(
            f"must not exceed max_V ({e.max_V:g} V), got {e.drive_high_V:g} V",
            source=source,
            field="electrodes.drive_high_V",
        )
    return Electrodes(**e.model_dump())


def _check_in_arena(robots: list[Robot], arena: tuple[float, float], source: str | None) -> None:
    for i, r in enumerate(robots):
        for which in ("start", "goal"):
            p = getattr(r, which)
            if p is not None and not (0.0 <= p.x <= arena[0] and 0.0 <= p.y <= arena[1]):
                raise ScenarioError(
                    f"({p.x:g}, {p.y:g}) is outside the arena [0, {arena[0]:g}] x [0, {arena[1]:g}] um",
                    source=source,
                    field=f"robots[{i}] ({r.name}).{which}",
                )


def _structure(sf: _StructureFile | None, robots: list[Robot], source: str | None) -> StructureSpec | None:
    if sf is None:
        return None
    with_goals = [i for i, r in enumerate(robots) if r.goal is not None]
    if with_goals:
        i = with_goals[0]
        raise ScenarioError(
            "conflicts with [structure]: give either per-robot goals or a named structure, not both",
            source=source,
            field=f"robots[{i}] ({robots[i].name}).goal",
        )
    return StructureSpec(shape=sf.shape, at=Pose.from_degrees(*sf.at))


def crossing_s(scenario: Scenario) -> float:
    """How long (s) the slowest robot takes to cross the layout in a straight line: the arena's diagonal,
    or without an arena the diagonal of the box around every start and goal, over the smallest speed.

    A closed-loop run lasts a few crossings (the example: 42 s crossing, about 110-180 s runs), so this
    is the measure of a run's length that the limits below bound.
    """
    if scenario.arena_um is not None:
        extent = math.hypot(*scenario.arena_um)
    else:
        pts = [(p.x, p.y) for r in scenario.robots for p in (r.start, r.goal) if p is not None]
        if scenario.structure is not None:
            pts.append((scenario.structure.at.x, scenario.structure.at.y))
        if len(pts) < 2:
            return 0.0
        xs, ys = zip(*pts, strict=True)
        extent = math.hypot(max(xs) - min(xs), max(ys) - min(ys)) + 2.0 * max(r.length_um for r in scenario.robots)
    return extent / min(r.speed_um_s for r in scenario.robots)


def check_movable(scenario: Scenario, *, source: str | None = None, planning_only: bool = False) -> Scenario:
    """Refuse, before any computation, a scenario too large to plan and simulate in reasonable time.

    Checks :data:`MAX_MOVING_ROBOTS`, the crossing time at the slowest speed (:func:`crossing_s`,
    at most :data:`MAX_CROSSING_S`) and the measurements per crossing (crossing / replan_interval_s,
    at most :data:`MAX_MEASUREMENTS_PER_CROSSING`), and says which limit is exceeded. With
    ``planning_only`` (``stressbots plan``: nothing runs in closed loop) the limits are
    :data:`MAX_PLANNED_ROBOTS` and :data:`MAX_PLANNED_CROSSING_S`, and the camera's rate is not checked.
    """
    where = source or scenario.source
    most = MAX_PLANNED_ROBOTS if planning_only else MAX_MOVING_ROBOTS
    if scenario.n > most:
        what, others = ("planning", "") if planning_only else ("simulating", f"`stressbots plan` plans up to {MAX_PLANNED_ROBOTS}, ")
        raise ScenarioError(
            f"{scenario.n} robots: {what} takes at most {most} robots ({others}`stressbots states` analyses up to {MAX_ROBOTS})",
            source=where,
            field="robots",
        )
    cross = crossing_s(scenario)
    longest = MAX_PLANNED_CROSSING_S if planning_only else MAX_CROSSING_S
    if cross > longest:
        i = min(range(scenario.n), key=lambda k: scenario.robots[k].speed_um_s)
        r = scenario.robots[i]
        what = "the arena's diagonal" if scenario.arena_um is not None else "the spread of the start and goal poses"
        raise ScenarioError(
            f"{r.speed_um_s:g} um/s is too slow for {what}: crossing it takes {cross:.0f} s, at most {longest:g} s "
            f"are accepted (a faster robot, at least {r.speed_um_s * cross / longest:.0f} um/s, or a smaller layout)",
            source=where,
            field=f"robots[{i}] ({r.name}).speed_um_s",
        )
    t_x = scenario.control.replan_interval_s
    if not planning_only and cross / t_x > MAX_MEASUREMENTS_PER_CROSSING:
        raise ScenarioError(
            f"{t_x:g} s is too short for this layout: {cross / t_x:.0f} measurements per crossing of {cross:.0f} s, at most "
            f"{MAX_MEASUREMENTS_PER_CROSSING} (use at least {cross / MAX_MEASUREMENTS_PER_CROSSING:.2g} s)",
            source=where,
            field="control.replan_interval_s",
        )
    return scenario


def check_starts(scenario: Scenario, *, source: str | None = None) -> np.ndarray:
    """The start poses ``(n, 3)``, refusing robots whose start bodies overlap (as the planner does).

    Raises :class:`ScenarioError` naming the first robot without a start or the first overlapping pair.
    """
    from .collision import pairwise_overlaps

    starts = scenario.starts
    for i, j, depth in pairwise_overlaps(starts, scenario.lengths_um, scenario.widths_um, tol_um=1e-6):
        a, b = scenario.robots[i], scenario.robots[j]
        raise ScenarioError(
            f"the start bodies of {a.name} and {b.name} overlap by {depth:.1f} um; robots must start apart",
            source=source or scenario.source,
            field=f"robots[{j}] ({b.name}).start",
        )
    return starts


def loads(text: str, *, source: str | None = None) -> Scenario:
    """Parse and validate scenario TOML text."""
    if len(text) > MAX_FILE_BYTES:
        raise ScenarioError(f"too large ({len(text)} characters; a scenario has at most {MAX_FILE_BYTES})", source=source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"not valid TOML: {' '.join(str(exc).split())}", source=source) from None
    except RecursionError:
        raise ScenarioError("not valid TOML: nested too deeply", source=source) from None
    try:
        return from_dict(data, source=source)
    except RecursionError:
        raise ScenarioError("nested too deeply to be a scenario", source=source) from None


def load(path) -> Scenario:
    """Load and validate a scenario file (the README's "Scenario files").

    Raises :class:`~stressbots.errors.ScenarioError` for a missing or unreadable file, text that is not
    UTF-8 TOML, or any invalid field.
    """
    p = Path(path)
    source = str(path)
    if not p.exists():
        raise ScenarioError("no such file", source=source)
    if p.is_dir():
        raise ScenarioError("is a directory, expected a scenario .toml file", source=source)
    try:
        if p.stat().st_size > MAX_FILE_BYTES:
            raise ScenarioError(f"too large ({p.stat().st_size} bytes; a scenario has at most {MAX_FILE_BYTES})", source=source)
        raw = p.read_bytes()
    except OSError as exc:
        raise ScenarioError(f"cannot read: {exc.strerror}", source=source) from None
    if b"\x00" in raw:
        raise ScenarioError("not a text file (binary data); expected scenario TOML", source=source)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"not UTF-8 text (byte {exc.start}); expected scenario TOML", source=source) from None
    return loads(text, source=source)


def to_toml(scenario: Scenario) -> str:
    """Write a scenario back as TOML (angles in degrees). ``loads(to_toml(s))`` equals ``s`` up to rounding."""

    def num(x: float) -> str:
        return repr(float(x))

    def pose(p: Pose) -> str:
        return "[" + ", ".join(num(v) for v in p.to_degrees()) + "]"

    lines = [f"name = {_toml_str(scenario.name)}"]
    if scenario.arena_um is not None:
        lines.append(f"arena_um = [{num(scenario.arena_um[0])}, {num(scenario.arena_um[1])}]")
    e = scenario.electrodes
    lines += ["", "[electrodes]"]
    for key in ("max_V", "margin_V", "drive_low_V", "drive_high_V", "drive_frequency_hz", "hold_s"):
        lines.append(f"{key} = {num(getattr(e, key))}")
    for r in scenario.robots:
        lines += ["", "[[robots]]", f"name = {_toml_str(r.name)}"]
        for key in ("snap_down_V", "release_V", "length_um", "width_um", "speed_um_s", "turn_radius_um"):
            lines.append(f"{key} = {num(getattr(r, key))}")
        if r.start is not None:
            lines.append(f"start = {pose(r.start)}")
        if r.goal is not None:
            lines.append(f"goal = {pose(r.goal)}")
    if scenario.structure is not None:
        lines += ["", "[structure]", f"shape = {_toml_str(scenario.structure.shape)}", f"at = {pose(scenario.structure.at)}"]
    lines += ["", "[noise]"] + [f"{key} = {num(value)}" for key, value in scenario.noise.to_file_units().items()]
    lines += [
        "",
        "[control]",
        f"replan_interval_s = {num(scenario.control.replan_interval_s)}",
    ]
    return "\n".join(lines) + "\n"


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'
