"""Scenarios: the seven experiments of the paper, users' scene files and random worlds."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from rayreach.scenarios.schema import ObstacleSpec, Scenario, ScenarioError, StartSpec, load_scenario_file

EXPERIMENTS = tuple(f"exp{i}" for i in range(1, 8))
RANDOM = "random"
BROAD = "broad"
WORLD_SUITES = (RANDOM, BROAD)
"""Names that stand for worlds drawn at each reset (``rayreach.scenarios.suites``): the
training worlds, and broad worlds of tables, shelves, boxes, clutter and walls in the arm's reach."""


def check_suite(suite: str) -> str:
    """``suite`` where it is one of ``WORLD_SUITES``; else an error that names them."""
    if suite not in WORLD_SUITES:
        raise ValueError(f"unknown world suite '{suite}'; valid: {', '.join(WORLD_SUITES)}")
    return suite


def builtin_path(name: str) -> Path:
    return Path(str(resources.files("rayreach.scenarios") / "data" / f"{name}.json"))


def get_scenario(name: str | Path | Scenario) -> Scenario:
    """A built-in experiment by name (``exp1``..``exp7``), a scene file path, or a Scenario."""
    if isinstance(name, Scenario):
        return name
    text = str(name)
    if text in EXPERIMENTS:
        return load_scenario_file(builtin_path(text))
    if text.endswith(".json") or Path(text).is_file():
        return load_scenario_file(text)
    raise ScenarioError(
        f"unknown scenario '{text}'; known: {', '.join(EXPERIMENTS)}, {', '.join(WORLD_SUITES)}, "
        "or a path to a .json scene file"
    )


__all__ = ["BROAD", "EXPERIMENTS", "RANDOM", "WORLD_SUITES", "check_suite", "ObstacleSpec", "Scenario", "ScenarioError", "StartSpec",
           "get_scenario"]
