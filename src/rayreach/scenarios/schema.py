"""Scene files: the typed form of a scenario and its validation from JSON.

A scenario names a robot, a start (joint angles or an end-effector pose), one or more goals
reached in sequence, obstacles and workspace bounds. The built-in experiments exp1..exp7 are
files in this format (``scenarios/data``), so a user's file goes through the same code.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

Vec3 = tuple[float, float, float]

SHAPES = ("box", "sphere", "cylinder", "mesh")


class ScenarioError(ValueError):
    """A scene file or scenario that cannot be used; the message names the bad field."""


@dataclass(frozen=True)
class ObstacleSpec:
    """One obstacle. Sizes by shape: box ``half_extents``; sphere ``radius``; cylinder
    ``radius`` and ``height`` (along its local z); mesh ``file`` and ``scale``.

    A moving obstacle has a ``velocity`` (m/s); with ``travel`` (m) it goes back and forth
    over that distance from its start, without it it keeps going.
    """

    shape: str
    position: Vec3
    rpy: Vec3 = (0.0, 0.0, 0.0)
    half_extents: Vec3 | None = None
    radius: float | None = None
    height: float | None = None
    file: str | None = None
    scale: Vec3 = (1.0, 1.0, 1.0)
    velocity: Vec3 = (0.0, 0.0, 0.0)
    travel: float | None = None
    name: str = ""

    @property
    def moving(self) -> bool:
        return any(v != 0.0 for v in self.velocity)

    def position_at(self, t: float) -> Vec3:
        """Centre at time ``t`` seconds after the episode start."""
        if not self.moving:
            return self.position
        speed = math.sqrt(sum(v * v for v in self.velocity))
        s = speed * t
        if self.travel is not None and self.travel > 0:
            s = s % (2 * self.travel)
            s = s if s <= self.travel else 2 * self.travel - s
        return tuple(p + v / speed * s for p, v in zip(self.position, self.velocity))  # type: ignore[return-value]


@dataclass(frozen=True)
class StartSpec:
    """Start as joint angles (rad) or as an end-effector pose (position m, roll-pitch-yaw rad)."""

    joints: tuple[float, ...] | None = None
    position: Vec3 | None = None
    rpy: Vec3 | None = None


@dataclass(frozen=True)
class Scenario:
    name: str
    robot: str
    start: StartSpec
    goals: tuple[Vec3, ...]
    obstacles: tuple[ObstacleSpec, ...]
    workspace_low: Vec3
    workspace_high: Vec3
    description: str = ""
    base_position: Vec3 | None = None
    base_rpy: Vec3 | None = None

    def in_workspace(self, point: tuple[float, ...]) -> bool:
        return all(lo <= x <= hi for x, lo, hi in zip(point, self.workspace_low, self.workspace_high))

    @property
    def has_moving_obstacles(self) -> bool:
        return any(o.moving for o in self.obstacles)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (what :func:`scenario_from_dict` reads)."""
        obstacles = []
        for obs in self.obstacles:
            d = {k: v for k, v in asdict(obs).items() if v is not None}
            for key, default in (("rpy", (0.0, 0.0, 0.0)), ("scale", (1.0, 1.0, 1.0)), ("velocity", (0.0, 0.0, 0.0))):
                if tuple(d[key]) == default:
                    del d[key]
            if not d["name"]:
                del d["name"]
            obstacles.append(d)
        start = {k: v for k, v in asdict(self.start).items() if v is not None}
        out: dict[str, Any] = {
            "name": self.name,
            "description": self.description,
            "robot": self.robot,
            "start": start,
            "goals": [list(g) for g in self.goals],
            "workspace": {"low": list(self.workspace_low), "high": list(self.workspace_high)},
            "obstacles": obstacles,
        }
        if self.base_position is not None:
            out["base_position"] = list(self.base_position)
        if self.base_rpy is not None:
            out["base_rpy"] = list(self.base_rpy)
        return out


# ---------------------------------------------------------------------- validation from JSON
def _number(value: Any, where: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScenarioError(f"{where}: expected a finite number, got {value!r}")
    if positive and value <= 0:
        raise ScenarioError(f"{where}: must be positive, got {value}")
    return float(value)


def _vector(value: Any, where: str, n: int = 3, positive: bool = False) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ScenarioError(f"{where}: expected a list of {n} numbers, got {value!r}")
    return tuple(_number(v, f"{where}[{i}]", positive) for i, v in enumerate(value))


def _check_keys(data: dict[str, Any], allowed: set[str], where: str) -> None:
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ScenarioError(f"{where}: unknown field(s) {', '.join(unknown)}; allowed: {', '.join(sorted(allowed))}")


def _obstacle(data: Any, where: str, base_dir: Path | None) -> ObstacleSpec:
    if not isinstance(data, dict):
        raise ScenarioError(f"{where}: expected an object, got {data!r}")
    allowed = {"shape", "position", "rpy", "half_extents", "radius", "height", "file", "scale",
               "velocity", "travel", "name"}
    _check_keys(data, allowed, where)
    shape = data.get("shape")
    if shape not in SHAPES:
        raise ScenarioError(f"{where}.shape: unknown shape {shape!r}; known: {', '.join(SHAPES)}")
    if "position" not in data:
        raise ScenarioError(f"{where}.position: missing")
    kwargs: dict[str, Any] = {
        "shape": shape,
        "position": _vector(data["position"], f"{where}.position"),
        "rpy": _vector(data.get("rpy", [0, 0, 0]), f"{where}.rpy"),
        "velocity": _vector(data.get("velocity", [0, 0, 0]), f"{where}.velocity"),
        "name": str(data.get("name", "")),
    }
    needs = {"box": ("half_extents",), "sphere": ("radius",), "cylinder": ("radius", "height"), "mesh": ("file",)}
    for key in needs[shape]:
        if key not in data:
            raise ScenarioError(f"{where}.{key}: missing (a {shape} needs {', '.join(needs[shape])})")
    if shape == "box":
        kwargs["half_extents"] = _vector(data["half_extents"], f"{where}.half_extents", positive=True)
    if shape in ("sphere", "cylinder"):
        kwargs["radius"] = _number(data["radius"], f"{where}.radius", positive=True)
    if shape == "cylinder":
        kwargs["height"] = _number(data["height"], f"{where}.height", positive=True)
    if shape == "mesh":
        path = Path(str(data["file"]))
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        if not path.is_file():
            raise ScenarioError(f"{where}.file: no such file {path}")
        kwargs["file"] = str(path)
        kwargs["scale"] = _vector(data.get("scale", [1, 1, 1]), f"{where}.scale", positive=True)
    if "travel" in data:
        kwargs["travel"] = _number(data["travel"], f"{where}.travel", positive=True)
    return ObstacleSpec(**kwargs)


def scenario_from_dict(data: Any, source: str = "scenario", base_dir: Path | None = None) -> Scenario:
    """Validate a decoded scene file; every error names the field (``exp.json: goals[1]: ...``)."""
    from rayreach.robots import ROBOTS

    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: expected a JSON object at the top level")
    allowed = {"name", "description", "robot", "start", "goals", "workspace", "obstacles",
               "base_position", "base_rpy"}
    _check_keys(data, allowed, source)
    for key in ("robot", "start", "goals", "workspace"):
        if key not in data:
            raise ScenarioError(f"{source}: missing field '{key}'")
    robot = str(data["robot"]).lower()
    if robot not in ROBOTS:
        raise ScenarioError(f"{source}.robot: unknown robot {data['robot']!r}; known: {', '.join(sorted(ROBOTS))}")

    start_data = data["start"]
    if not isinstance(start_data, dict):
        raise ScenarioError(f"{source}.start: expected an object with 'joints' or 'position' (+ 'rpy')")
    _check_keys(start_data, {"joints", "position", "rpy"}, f"{source}.start")
    if "joints" in start_data:
        start = StartSpec(joints=_vector(start_data["joints"], f"{source}.start.joints", n=6))
    elif "position" in start_data:
        start = StartSpec(
            position=_vector(start_data["position"], f"{source}.start.position"),  # type: ignore[arg-type]
            rpy=_vector(start_data.get("rpy", [math.pi, 0, math.pi]), f"{source}.start.rpy"),  # type: ignore[arg-type]
        )
    else:
        raise ScenarioError(f"{source}.start: give 'joints' (6 angles) or 'position' (+ optional 'rpy')")

    goals_data = data["goals"]
    if not isinstance(goals_data, list) or not goals_data:
        raise ScenarioError(f"{source}.goals: expected a non-empty list of [x, y, z] positions")
    goals = tuple(_vector(g, f"{source}.goals[{i}]") for i, g in enumerate(goals_data))

    ws = data["workspace"]
    if not isinstance(ws, dict) or set(ws) != {"low", "high"}:
        raise ScenarioError(f"{source}.workspace: expected {{'low': [x, y, z], 'high': [x, y, z]}}")
    low = _vector(ws["low"], f"{source}.workspace.low")
    high = _vector(ws["high"], f"{source}.workspace.high")
    for i, axis in enumerate("xyz"):
        if low[i] >= high[i]:
            raise ScenarioError(f"{source}.workspace: low.{axis} {low[i]} must be below high.{axis} {high[i]}")

    obstacles_data = data.get("obstacles", [])
    if not isinstance(obstacles_data, list):
        raise ScenarioError(f"{source}.obstacles: expected a list")
    obstacles = tuple(_obstacle(o, f"{source}.obstacles[{i}]", base_dir) for i, o in enumerate(obstacles_data))

    scenario = Scenario(
        name=str(data.get("name", source)),
        description=str(data.get("description", "")),
        robot=robot,
        start=start,
        goals=goals,  # type: ignore[arg-type]
        obstacles=obstacles,
        workspace_low=low,  # type: ignore[arg-type]
        workspace_high=high,  # type: ignore[arg-type]
        base_position=_vector(data["base_position"], f"{source}.base_position") if "base_position" in data else None,  # type: ignore[arg-type]
        base_rpy=_vector(data["base_rpy"], f"{source}.base_rpy") if "base_rpy" in data else None,  # type: ignore[arg-type]
    )
    for i, goal in enumerate(scenario.goals):
        if not scenario.in_workspace(goal):
            raise ScenarioError(
                f"{source}.goals[{i}]: {list(goal)} lies outside the workspace {list(low)} .. {list(high)}"
            )
    if start.position is not None and not scenario.in_workspace(start.position):
        raise ScenarioError(f"{source}.start.position: {list(start.position)} lies outside the workspace")
    return scenario


def load_scenario_file(path: str | Path) -> Scenario:
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"scene file {path} does not exist")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ScenarioError(f"{path.name}: not valid JSON ({exc})") from exc
    return scenario_from_dict(data, source=path.name, base_dir=path.parent)
