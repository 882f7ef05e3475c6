"""Robot registry: a name resolves to a :class:`RobotSpec`; unknown names list the valid ones."""

from __future__ import annotations

from rayreach.robots.kr16 import KR16
from rayreach.robots.spec import DHTable, RobotSpec, SensorMount, ToolSpec
from rayreach.robots.ur5 import UR5
from rayreach.robots.ur10 import UR10

ROBOTS: dict[str, RobotSpec] = {spec.name: spec for spec in (UR5, KR16, UR10)}


def get_robot(name: str | RobotSpec) -> RobotSpec:
    if isinstance(name, RobotSpec):
        return name
    key = str(name).lower()
    if key not in ROBOTS:
        raise ValueError(f"unknown robot '{name}'; known: {', '.join(sorted(ROBOTS))}")
    return ROBOTS[key]


__all__ = ["ROBOTS", "DHTable", "RobotSpec", "SensorMount", "ToolSpec", "get_robot"]
