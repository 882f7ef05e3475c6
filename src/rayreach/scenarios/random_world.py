"""Random training worlds: plates, moving plates, shelves and clutter between start and goal.

Every world drawn here has a reachable, collision-free start (6-D IK to a tool pose of the
robot's default orientation) and a reachable, collision-free goal configuration (position
IK), checked in the caller's scene; all randomness comes from the generator passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np

from rayreach.sim.kinematics import IKParams, Kinematics
from rayreach.scenarios.feasibility import goal_configuration
from rayreach.scenarios.schema import ObstacleSpec, Scenario, StartSpec
from rayreach.sim.transforms import rpy_to_matrix

KINDS = ("plate", "moving_plate", "box", "sphere", "shelf", "goal_cover", "goal_wall", "goal_slot")
"""plate / moving_plate: upright or flat plates across the straight path (moving sideways);
box, sphere: clutter near the path; shelf: a 2 x 2 shelf holding the goal; goal_cover: a flat
plate just over the goal that moves away (as in exp3); goal_wall: an upright plate beside the
goal; goal_slot: two parallel upright plates either side of the goal (as in exp2). A kind
listed twice in a robot's ``training_kinds`` is drawn twice as often."""


def check_kinds(kinds: Sequence[str], where: str = "") -> None:
    """Refuses kinds this module does not draw (``KINDS``), naming those it does; ``where``
    says whose kinds they are."""
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        raise ValueError(f"unknown obstacle kind(s) {unknown}{where}; known: {', '.join(KINDS)}")


def world_kinds(scenario: Scenario) -> list[str]:
    """The kind (``KINDS``) of each obstacle a random world drew, in drawing order, read from
    the names this module gives its obstacles: a goal slot's two plates and a shelf's boards
    and walls count once. For telling which kinds of world a policy fails in."""
    kinds, seen = [], set()
    for obstacle in scenario.obstacles:
        name = obstacle.name or ""
        kind = max((k for k in KINDS if name.startswith(k + "_")), key=len, default=None)
        if kind is None:
            raise ValueError(f"obstacle '{name}' is not one a random world draws (kinds: {', '.join(KINDS)})")
        group = kind if kind == "shelf" else name.rsplit("_", 1)[0] if kind == "goal_slot" else name
        if group not in seen:
            seen.add(group)
            kinds.append(kind)
    return kinds


SHELF_DEPTH = 0.3
"""Depth of a shelf along y, m (exp4..exp7)."""


@dataclass(frozen=True)
class RandomWorldConfig:
    n_obstacles: int = 3
    """How many obstacles (a shelf counts as one); the obstacle curriculum drives it."""
    kinds: tuple[str, ...] | None = None
    """Obstacle kinds to draw from (see ``KINDS``); None: the robot's ``training_kinds``."""
    min_goal_distance: float = 0.2
    """Least distance between start and goal, m."""
    margin: float = 0.03
    """Start and goal keep this far inside the workspace bounds, m."""
    speed: tuple[float, float] = (0.05, 0.2)
    """Speed range of moving plates, m/s."""
    cover_speed: tuple[float, float] | None = None
    """Speed range of goal covers, m/s; None: ``speed``. A slower cover takes longer to clear
    the goal, so diving under it fails more often (a training option, docs/training.md)."""
    start_clearance: float = 0.0
    """Least distance, m, between the robot at its start and every obstacle at t = 0; 0: the
    start need only be free of collision. The authors' generator kept obstacles 5 cm from the
    start: a start the tool or arm begins beside an obstacle no ray sees is a collision the
    rays cannot prevent (docs/log/2026-11-random-worlds.md,
    "Starts beside an obstacle")."""
    max_tries: int = 200

    def __post_init__(self) -> None:
        for name in ("speed", "cover_speed"):
            bounds = getattr(self, name)
            if bounds is not None and not (len(bounds) == 2 and 0 <= bounds[0] <= bounds[1]):
                raise ValueError(f"{name} must be (low, high) m/s with 0 <= low <= high, got {bounds}")
        if not self.start_clearance >= 0:
            raise ValueError(f"start_clearance must be >= 0 (0 = off), got {self.start_clearance}")


def shelf_boxes(
    center: tuple[float, float, float],
    width: float = 1.0,
    height: float = 1.0,
    depth: float = SHELF_DEPTH,
    thickness: float = 0.06,
    prefix: str = "",
) -> tuple[list[ObstacleSpec], list[tuple[float, float, float]]]:
    """A 2 x 2 shelf open towards +-y: three boards, three walls, and its compartment centres
    (lower left, lower right, upper left, upper right; left = -x)."""
    cx, cy, cz = center
    boxes = [
        ObstacleSpec("box", (cx, cy, cz + dz), half_extents=(width / 2, depth / 2, thickness / 2), name=f"{prefix}board_{i}")
        for i, dz in enumerate((-height / 2, 0.0, height / 2))
    ]
    boxes += [
        ObstacleSpec("box", (cx + dx, cy, cz), half_extents=(thickness / 2, depth / 2, height / 2), name=f"{prefix}wall_{i}")
        for i, dx in enumerate((-width / 2, 0.0, width / 2))
    ]
    centres = [(cx + sx * width / 4, cy, cz + sz * height / 4) for sz in (-1, 1) for sx in (-1, 1)]
    return boxes, centres


def drawn_scenario(name: str, robot: str, q_start: np.ndarray, goal: np.ndarray, obstacles: Sequence[ObstacleSpec],
                   low: Sequence[float], high: Sequence[float], description: str) -> Scenario:
    """A drawn world as a ``Scenario``: one goal, the start as joint angles."""
    return Scenario(
        name=name,
        robot=robot,
        start=StartSpec(joints=tuple(float(v) for v in q_start)),
        goals=(tuple(float(v) for v in goal),),  # type: ignore[arg-type]
        obstacles=tuple(obstacles),
        workspace_low=tuple(float(v) for v in low),  # type: ignore[arg-type]
        workspace_high=tuple(float(v) for v in high),  # type: ignore[arg-type]
        description=description,
    )


class WorldChecker(Protocol):
    """Where a drawn world is checked: a ``Scene``, or one world of the batched env's
    ``CollisionWorlds`` (``WorldSlot``); both answer as PyBullet's contact query does."""

    def set_obstacles(self, obstacles: Sequence[ObstacleSpec]) -> None: ...

    def set_joints(self, q: Sequence[float]) -> None: ...

    def in_collision(self) -> bool: ...

    def clearance(self, within: float) -> float: ...


class RandomWorlds:
    """Draws random scenarios for one robot, checking them in ``scene`` (which it modifies)."""

    def __init__(self, kin: Kinematics, scene: WorldChecker, config: RandomWorldConfig = RandomWorldConfig()) -> None:
        self.kin = kin
        self.scene = scene
        self.config = config
        spec = kin.spec
        self.kinds = config.kinds if config.kinds is not None else spec.training_kinds
        check_kinds(self.kinds)
        self.low = np.asarray(spec.workspace_low) + config.margin
        self.high = np.asarray(spec.workspace_high) - config.margin
        self.tool_rot = rpy_to_matrix(spec.tool_rpy)
        self._ik = IKParams(tolerance=1e-4, max_iterations=100)

    def sample(self, rng: np.random.Generator, n_obstacles: int | None = None) -> tuple[Scenario, np.ndarray]:
        """A feasible scenario and its start configuration; the scene holds its obstacles."""
        n = self.config.n_obstacles if n_obstacles is None else n_obstacles
        if n < 0:
            raise ValueError(f"n_obstacles must be >= 0, got {n}")
        spec = self.kin.spec
        for _ in range(self.config.max_tries):
            kinds = [str(k) for k in rng.choice(self.kinds, size=n)] if n and self.kinds else []
            obstacles: list[ObstacleSpec] = []
            start_low, start_high = self.low, self.high
            goal = None
            if "shelf" in kinds:  # at most one shelf; the goal goes into one of its compartments
                others = [k for k in self.kinds if k != "shelf"]
                kinds = [str(k) for k in rng.choice(others, size=n - 1)] if others else []
                boxes, goal, (start_low, start_high) = self._shelf(rng)
                obstacles += boxes
            start = rng.uniform(start_low, start_high)
            ik = self.kin.ik(start, self.tool_rot, np.asarray(spec.home), self._ik)
            if not ik.converged:
                continue
            q_start = ik.q
            start = self.kin.fk(q_start)[:3, 3]
            if goal is None:
                goal = rng.uniform(self.low, self.high)
            if np.linalg.norm(goal - start) < self.config.min_goal_distance or not self._inside(goal):
                continue
            for i, kind in enumerate(kinds):
                obstacles += self._goal_slot(rng, goal, i) if kind == "goal_slot" else [self._obstacle(kind, rng, start, goal, i)]
            q_goal = goal_configuration(self.kin, goal, q_start, rng, n_random_seeds=2)
            if q_goal is None:
                continue
            # the goal configuration must be free of static obstacles (moving ones pass by);
            # the start configuration must be free at t = 0
            self.scene.set_obstacles([o for o in obstacles if not o.moving])
            self.scene.set_joints(q_goal)
            if self.scene.in_collision():
                continue
            self.scene.set_obstacles(obstacles)
            self.scene.set_joints(q_start)
            if self.scene.in_collision():
                continue
            clearance = self.config.start_clearance
            if clearance > 0 and self.scene.clearance(clearance) < clearance:
                continue
            scenario = drawn_scenario("random", spec.name, q_start, goal, obstacles, spec.workspace_low,
                                      spec.workspace_high, f"random world with {n} obstacle(s)")
            return scenario, q_start
        raise RuntimeError(
            f"no feasible random world for {spec.name} with {n} obstacle(s) in {self.config.max_tries} tries"
        )

    def _inside(self, point: np.ndarray) -> bool:
        return bool(np.all(point >= self.low) and np.all(point <= self.high))

    def _shelf(
        self, rng: np.random.Generator
    ) -> tuple[list[ObstacleSpec], np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """The shelf's boxes, a goal in it, and the box the start is drawn from: in front of the
        open face that looks at the robot (-y), at least 0.1 m off it, as in exp4..exp7. A start
        anywhere in the workspace put the tool above or behind the shelf, where reaching in
        teaches nothing about entering a compartment."""
        centre = (float(rng.uniform(-0.2, 0.2)), float(rng.uniform(0.15, 0.35)), float(rng.uniform(1.0, 1.2)))
        boxes, compartments = shelf_boxes(centre, prefix="shelf_")
        cx, cy, cz = compartments[int(rng.integers(len(compartments)))]
        # inside the compartment or up to 0.2 m behind its far face (exp4..exp7: 0.1 m behind)
        depth_offset = float(rng.uniform(0.0, 0.35))
        goal = np.array([cx, cy + depth_offset, cz]) + rng.uniform(-0.1, 0.1, 3) * np.array([1.0, 0.0, 1.0])
        front = centre[1] - SHELF_DEPTH / 2 - 0.1
        start_low = np.maximum(self.low, [centre[0] - 0.5, self.low[1], centre[2] - 0.5])
        start_high = np.minimum(self.high, [centre[0] + 0.5, front, centre[2] + 0.5])
        return boxes, goal, (start_low, start_high)

    def _goal_slot(self, rng: np.random.Generator, goal: np.ndarray, index: int) -> list[ObstacleSpec]:
        side = float(rng.uniform(0, math.pi))
        scale = float(rng.uniform(0.8, 1.2))
        return [_wall_beside(goal, side + turn, float(rng.uniform(0.08, 0.12)), scale, f"goal_slot_{index}_{j}")
                for j, turn in enumerate((0.0, math.pi))]

    def _obstacle(
        self, kind: str, rng: np.random.Generator, start: np.ndarray, goal: np.ndarray, index: int
    ) -> ObstacleSpec:
        along = start + rng.uniform(0.3, 0.7) * (goal - start)
        centre = tuple(float(v) for v in along + rng.uniform(-0.05, 0.05, 3))
        heading = math.atan2(goal[1] - start[1], goal[0] - start[0])
        scale = float(rng.uniform(0.8, 1.2))
        if kind in ("plate", "moving_plate"):
            if rng.random() < 0.5:  # upright, facing along the straight path
                half = (0.002, 0.08 * scale, 0.05 * scale)
                rpy = (0.0, 0.0, heading)
            else:  # lying flat
                half = (0.06 * scale, 0.06 * scale, 0.002)
                rpy = (0.0, 0.0, float(rng.uniform(0, math.pi)))
            velocity = (0.0, 0.0, 0.0)
            travel = None
            if kind == "moving_plate":
                speed = float(rng.uniform(*self.config.speed))
                side = heading + math.pi / 2
                velocity = (speed * math.cos(side), speed * math.sin(side), 0.0)
                travel = float(rng.uniform(0.1, 0.3))
            return ObstacleSpec("box", centre, rpy=rpy, half_extents=half, velocity=velocity, travel=travel,
                                name=f"{kind}_{index}")
        if kind == "goal_cover":
            # A static cover was dropped: one low enough to matter sits where the wrist of a
            # down-pointing tool must be, unseen by every ray (docs/log/2026-11-training-runs.md,
            # "2026-11-25: what held the UR5 policy back, measured").
            lift = float(rng.uniform(0.04, 0.07))
            direction = float(rng.uniform(0, 2 * math.pi))
            speed = float(rng.uniform(*(self.config.cover_speed or self.config.speed)))
            return ObstacleSpec("box", (float(goal[0]), float(goal[1]), float(goal[2]) + lift),
                                half_extents=(0.05 * scale, 0.05 * scale, 0.002),
                                velocity=(speed * math.cos(direction), speed * math.sin(direction), 0.0),
                                name=f"goal_cover_{index}")
        if kind == "goal_wall":
            side = float(rng.uniform(0, 2 * math.pi))
            return _wall_beside(goal, side, float(rng.uniform(0.04, 0.08)), scale, f"goal_wall_{index}")
        if kind == "box":
            half = tuple(float(v) for v in rng.uniform(0.02, 0.05, 3))
            return ObstacleSpec("box", centre, rpy=(0.0, 0.0, float(rng.uniform(0, math.pi))), half_extents=half,
                                name=f"box_{index}")  # type: ignore[arg-type]
        return ObstacleSpec("sphere", centre, radius=0.04 * scale, name=f"sphere_{index}")


def _wall_beside(goal: np.ndarray, side: float, gap: float, scale: float, name: str) -> ObstacleSpec:
    """An upright plate ``gap`` from the goal in direction ``side`` (rad), facing the goal."""
    centre = (float(goal[0] + gap * math.cos(side)), float(goal[1] + gap * math.sin(side)), float(goal[2]) + 0.01)
    return ObstacleSpec("box", centre, rpy=(0.0, 0.0, side), half_extents=(0.002, 0.1 * scale, 0.05 * scale), name=name)
