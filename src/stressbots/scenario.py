"""Scenario files: the TOML format of SPEC section 5, loaded into immutable values.

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
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

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
]


@dataclass(frozen=True)
class Noise:
    """Control error and sensing error (SPEC section 5 ``[noise]``); all zero means nominal.

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

    def scaled(self, factor: float) -> "Noise":
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
    """Closed-loop controller settings (SPEC section 5 ``[control]``)."""

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

    def with_noise(self, noise: Noise) -> "Scenario":
        return replace(self, noise=noise)

    def with_robots(self, robots) -> "Scenario":
        return replace(self, robots=tuple(robots))


# ----------------------------------------------------------------------------------------------------
# File schema (pydantic). Kept private: the public values are the frozen dataclasses above.

_Finite = Annotated[float, Field(allow_inf_nan=False)]
_Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
_NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=False)


def _pose_list(v: Any) -> Any:
    if v is None:
        return v
    if not isinstance(v, list):
        raise ValueError("must be a list [x_um, y_um, heading_deg]")
    if len(v) != 3:
        raise ValueError(f"must have 3 numbers [x_um, y_um, heading_deg], got {len(v)}")
    for k, x in enumerate(v):
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise ValueError(f"item {k} must be a number, got {type(x).__name__}")
        if not math.isfinite(x):
            raise ValueError(f"item {k} must be finite, got {x}")
    return [float(x) for x in v]


class _RobotDefaults(_Strict):
    length_um: _Positive | None = None
    width_um: _Positive | None = None
    speed_um_s: _Positive | None = None
    turn_radius_um: _Positive | None = None
    snap_down_V: _NonNegative | None = None
    release_V: _NonNegative | None = None


class _RobotFile(_RobotDefaults):
    name: str = Field(min_length=1)
    start: list[float] | None = None
    goal: list[float] | None = None

    @field_validator("start", "goal", mode="before")
    @classmethod
    def _poses(cls, v):
        return _pose_list(v)

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        if not v.strip():
            raise ValueError("must not be blank")
        if v != v.strip():
            raise ValueError("must not start or end with spaces")
        return v


class _ElectrodesFile(_Strict):
    max_V: _Positive = 200.0
    margin_V: _NonNegative = 5.0
    drive_low_V: _NonNegative = 75.0
    drive_high_V: _Positive = 105.0
    drive_frequency_hz: _Positive = 10000.0
    hold_s: _Positive = 0.001


class _NoiseFile(_Strict):
    speed_rel_sd: _NonNegative = 0.0
    turn_radius_rel_sd: _NonNegative = 0.0
    heading_drift_deg_per_mm: _NonNegative = 0.0
    camera_position_sd_um: _NonNegative = 0.0
    camera_heading_sd_deg: _NonNegative = 0.0
    camera_dropout: Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)] = 0.0


class _ControlFile(_Strict):
    replan_interval_s: _Positive = 1.0


class _StructureFile(_Strict):
    shape: str = Field(min_length=1)
    at: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0])

    @field_validator("at", mode="before")
    @classmethod
    def _at(cls, v):
        return _pose_list(v)


class _ScenarioFile(_Strict):
    name: str = "scenario"
    arena_um: list[_Positive] | None = None
    robot_defaults: _RobotDefaults = Field(default_factory=_RobotDefaults)
    electrodes: _ElectrodesFile = Field(default_factory=_ElectrodesFile)
    robots: list[_RobotFile] = Field(min_length=1)
    structure: _StructureFile | None = None
    noise: _NoiseFile = Field(default_factory=_NoiseFile)
    control: _ControlFile = Field(default_factory=_ControlFile)

    @field_validator("arena_um")
    @classmethod
    def _arena(cls, v):
        if v is not None and len(v) != 2:
            raise ValueError(f"must be [width_um, height_um], got {len(v)} numbers")
        return v


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
                    label += f" ({node['name']})"
            else:
                node = None
            if parts:
                parts[-1] += label
            else:
                parts.append(label)
        else:
            parts.append(str(item))
            node = node.get(item) if isinstance(node, dict) else None
    return ".".join(parts)


def _friendly(err: dict) -> str:
    kind = err.get("type", "")
    inp = err.get("input")
    if kind == "missing":
        return "missing: this field is required"
    if kind == "extra_forbidden":
        return "unknown field (check the spelling; see SPEC section 5)"
    if kind in ("finite_number",):
        return f"must be a finite number, got {inp!r}"
    msg = err.get("msg", "invalid value")
    msg = msg.removeprefix("Value error, ")
    if kind.endswith("_type") or kind.endswith("_parsing"):
        return f"{msg[0].lower()}{msg[1:]}, got {type(inp).__name__} {inp!r}"
    return f"{msg[0].lower()}{msg[1:]}"


def from_dict(data: dict, *, source: str | None = None) -> Scenario:
    """Validate a parsed TOML document and build a :class:`Scenario`."""
    try:
        model = _ScenarioFile.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        raise ScenarioError(_friendly(err), source=source, field=_field_path(err["loc"], data)) from None

    d = model.robot_defaults
    robots: list[Robot] = []
    seen: dict[str, int] = {}
    for i, rf in enumerate(model.robots):
        where = f"robots[{i}] ({rf.name})"
        if rf.name in seen:
            raise ScenarioError(
                f"duplicate robot name (also robots[{seen[rf.name]}])", source=source, field=f"{where}.name"
            )
        seen[rf.name] = i

        def pick(key: str, default: float | None) -> float:
            own = getattr(rf, key)
            if own is not None:
                return float(own)
            shared = getattr(d, key)
            if shared is not None:
                return float(shared)
            if default is None:
                raise ScenarioError(
                    "missing: give it per robot or in [robot_defaults]", source=source, field=f"{where}.{key}"
                )
            return default

        v_d = pick("snap_down_V", None)
        v_u = pick("release_V", None)
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
                length_um=pick("length_um", 260.0),
                width_um=pick("width_um", 60.0),
                speed_um_s=pick("speed_um_s", 100.0),
                turn_radius_um=pick("turn_radius_um", 200.0),
                start=Pose.from_degrees(*rf.start) if rf.start is not None else None,
                goal=Pose.from_degrees(*rf.goal) if rf.goal is not None else None,
            )
        )

    e = model.electrodes
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
    electrodes = Electrodes(**e.model_dump())

    arena = tuple(float(a) for a in model.arena_um) if model.arena_um is not None else None
    if arena is not None:
        for i, r in enumerate(robots):
            for which in ("start", "goal"):
                p = getattr(r, which)
                if p is not None and not (0.0 <= p.x <= arena[0] and 0.0 <= p.y <= arena[1]):
                    raise ScenarioError(
                        f"({p.x:g}, {p.y:g}) is outside the arena [0, {arena[0]:g}] x [0, {arena[1]:g}] um",
                        source=source,
                        field=f"robots[{i}] ({r.name}).{which}",
                    )

    structure = None
    if model.structure is not None:
        structure = StructureSpec(shape=model.structure.shape, at=Pose.from_degrees(*model.structure.at))
        with_goals = [i for i, r in enumerate(robots) if r.goal is not None]
        if with_goals:
            i = with_goals[0]
            raise ScenarioError(
                "conflicts with [structure]: give either per-robot goals or a named structure, not both",
                source=source,
                field=f"robots[{i}] ({robots[i].name}).goal",
            )

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
        arena_um=arena,  # type: ignore[arg-type]
        structure=structure,
        noise=noise,
        control=ControlSettings(replan_interval_s=model.control.replan_interval_s),
        source=source,
    )


def loads(text: str, *, source: str | None = None) -> Scenario:
    """Parse and validate scenario TOML text."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"not valid TOML: {exc}", source=source) from None
    return from_dict(data, source=source)


def load(path) -> Scenario:
    """Load and validate a scenario file (SPEC section 5).

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
