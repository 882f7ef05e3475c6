"""Broad random worlds: the scenes a user's robot cell holds, anywhere within the arm's reach.

The training worlds of :mod:`rayreach.scenarios.random_world` keep start, goal and obstacles in
a small box in front of the robot. A policy that is to work in a user's cell must also meet
tables, shelves of other shapes, open boxes, clutter and walls elsewhere in its reach; these
worlds draw such scenes, for evaluation and for widening the training distribution.

A world is ``n_obstacles`` scene elements. The first holds the goal (a ``table``, ``shelf`` or
``goal_box``), the others are ``clutter`` or a ``wall`` between start and goal. As in
``RandomWorlds``, every world has a reachable, collision-free start (6-D IK to a tool pose of
the robot's default orientation ``spec.tool_rpy``) and a collision-free position-IK goal
configuration, both checked in the caller's scene, and all randomness comes from the generator
passed in. Obstacles are static boxes and spheres only: the batched simulator handles those.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from rayreach.robots.spec import RobotSpec
from rayreach.scenarios.feasibility import goal_configuration
from rayreach.scenarios.random_world import WorldChecker, drawn_scenario
from rayreach.scenarios.schema import ObstacleSpec, Scenario
from rayreach.sim.kinematics import IKParams, Kinematics
from rayreach.sim.transforms import rpy_to_matrix

BROAD_KINDS = ("table", "shelf", "goal_box", "clutter", "wall")
"""table: a thin wide table top (with legs or without) and the goal 0.02 to 0.25 m above it;
shelf: a shelf of 1-3 x 1-3 compartments facing the robot's base, the goal in one
compartment; goal_box: an open box (bottom, 3 or 4 walls, no lid) with the goal inside below
its rim; clutter: 3 to 8 small boxes and spheres (2-8 cm), some near the straight start-goal
path; wall: a large upright plate (0.3-0.8 m wide) partly across the straight path. The first
three hold the goal and come first in a world; the last two are the other elements."""

GOAL_KINDS = ("table", "shelf", "goal_box")
"""The kinds a world's first element (the goal's scene) is drawn from."""
EXTRA_KINDS = ("clutter", "wall")
"""The kinds the other elements are drawn from."""

FLOOR_Z = 0.0
"""Height of the floor, m: both robots stand on it or above it (the UR5's base is 0.5 m up, on a
stand). Broad workspaces end here below, and tables, standing shelves and stands reach down to it."""

STAND_RADIUS = 0.1
"""Radius, m, of the column under a base that stands above the floor (the UR5's stand), kept
free of obstacles, starts and goals: the simulated robot has no stand, a real one does."""

_REACH_SLACK = 0.03
"""Starts and goals keep this far inside the reach, m: at full stretch IK hardly converges."""


def broad_kinds(scenario: Scenario) -> list[str]:
    """The kind (``BROAD_KINDS``) of each scene element of a broad world, in drawing order, read
    from the names this module gives its obstacles (``f"{kind}_{index}_..."``), so a table's top
    and legs or a shelf's boards count once. For telling which scenes a policy fails in."""
    kinds, seen = [], set()
    for obstacle in scenario.obstacles:
        name = obstacle.name or ""
        kind = max((k for k in BROAD_KINDS if name.startswith(k + "_")), key=len, default=None)
        index = name[len(kind) + 1:].split("_", 1)[0] if kind else ""
        if kind is None or not index.isdigit():
            raise ValueError(
                f"obstacle '{name}' is not one a broad world draws (kinds: {', '.join(BROAD_KINDS)})"
            )
        if (kind, index) not in seen:
            seen.add((kind, index))
            kinds.append(kind)
    return kinds


# ---------------------------------------------------------------------- reach and workspace
@dataclass(frozen=True)
class ArmReach:
    """Where an arm reaches: the tool tip lies within ``reach`` of its shoulder (the origin of DH
    frame 1, on joint 2's axis), which circles the base axis at ``offset`` and ``height``."""

    base_xy: tuple[float, float]
    """The base axis (the vertical through DH frame 0), world x, y."""
    offset: float
    """Horizontal distance of the shoulder from the base axis, m (KR16: 0.26, UR5: 0)."""
    height: float
    """World height of the shoulder, m."""
    reach: float
    """Largest distance of the tool tip from the shoulder, m."""

    def distance_beyond(self, point: np.ndarray) -> float:
        """How far ``point`` lies beyond the reach, m (negative: within it). The shoulder circles
        the base axis as joint 1 turns, so the nearest shoulder position counts."""
        rho = math.hypot(point[0] - self.base_xy[0], point[1] - self.base_xy[1])
        return math.hypot(rho - self.offset, point[2] - self.height) - self.reach


_REACH_CACHE: dict[tuple, ArmReach] = {}


def arm_reach(kin: Kinematics) -> ArmReach:
    """The arm's reach, from its kinematics: the largest distance of the tool tip from the
    shoulder over 1000 random configurations (joints 2-6 decide it), each of the five farthest
    refined by a random local search. The stretched arm is what this finds; a sampled bound
    alone falls a few centimetres short of it. Computed once per robot and base pose (~0.1 s)."""
    key = (kin.spec.name, kin.chain.key(), kin.spec.tool, kin.world0.tobytes())
    if key in _REACH_CACHE:
        return _REACH_CACHE[key]
    rng = np.random.default_rng(0)  # fixed: a robot always has the same reach
    low, high = np.maximum(kin.lower, -np.pi), np.minimum(kin.upper, np.pi)

    def distance(q: np.ndarray) -> float:
        frames = kin.frames(q)
        return float(np.linalg.norm(kin.ee_from_frames(frames)[:3, 3] - kin.joint_origin(frames, 1)))

    qs = rng.uniform(low, high, (1000, len(low)))
    values = np.array([distance(q) for q in qs])
    reach = float(values.max())
    for i in np.argsort(values)[-5:]:
        q, value, step = qs[i], values[i], 0.3
        for _ in range(80):
            candidate = np.clip(q + rng.normal(0.0, step, len(q)), low, high)
            d = distance(candidate)
            if d > value:
                q, value = candidate, d
            else:
                step *= 0.95
        reach = max(reach, value)
    frames = kin.frames(np.zeros(len(low)))
    axis, shoulder = frames[0][:3, 3], kin.joint_origin(frames, 1)
    result = ArmReach(
        base_xy=(float(axis[0]), float(axis[1])),
        offset=float(math.hypot(shoulder[0] - axis[0], shoulder[1] - axis[1])),
        height=float(shoulder[2]),
        reach=reach,
    )
    _REACH_CACHE[key] = result
    return result


def _workspace(kin: Kinematics) -> tuple[np.ndarray, np.ndarray]:
    reach = arm_reach(kin)
    half = reach.offset + reach.reach
    x, y = reach.base_xy
    low = np.array([x - half, y - half, max(FLOOR_Z, reach.height - reach.reach)])
    high = np.array([x + half, y + half, reach.height + reach.reach])
    spec = kin.spec  # never smaller than the training box, which the broad worlds extend
    return np.minimum(low, spec.workspace_low), np.maximum(high, spec.workspace_high)


def broad_workspace(spec: RobotSpec) -> tuple[np.ndarray, np.ndarray]:
    """The broad worlds' workspace box (low, high), world frame, robot at its default base: all
    around the base axis out to the shoulder's offset plus the reach (:func:`arm_reach`), from
    the floor (``FLOOR_Z``, or the lowest reachable height when that is higher) up to the
    shoulder's height plus the reach. The box holds every point above the floor that the tool
    tip reaches (to the search's precision, well under a centimetre), so an episode does not end
    at a bound the arm could cross; it contains the training workspace ``spec.workspace_low/high``."""
    return _workspace(Kinematics(spec))


# ---------------------------------------------------------------------- config
@dataclass(frozen=True)
class BroadWorldConfig:
    n_obstacles: int = 3
    """How many scene elements: the first is the goal's scene (table, shelf or goal_box), the
    rest are clutter or walls. 0: start and goal alone."""
    kinds: tuple[str, ...] = BROAD_KINDS
    """Kinds to draw from (see ``BROAD_KINDS``): the first element from those of ``GOAL_KINDS``
    here, the others from those of ``EXTRA_KINDS``; a kind listed twice is drawn twice as often."""
    min_goal_distance: float = 0.2
    """Least distance between start and goal, m."""
    margin: float = 0.03
    """Start and goal keep this far inside the workspace bounds, m."""
    start_clearance: float = 0.0
    """Least distance, m, between the robot at its start and every obstacle; 0: the start need
    only be free of collision (see ``RandomWorldConfig.start_clearance``)."""
    max_tries: int = 200
    """Draws of a world for one set of elements before ``sample`` draws the elements anew."""
    element_sets: int = 5
    """Sets of elements ``sample`` draws before it gives up. Some sets rarely fit (a shelf
    between two walls): a training run drew one of them after 23 M decisions and stopped."""
    start_tries: int = 3
    """Start poses tried per drawn goal scene: the scene is the costly part of a draw."""
    element_tries: int = 4
    """Draws of the other elements (clutter, walls) per goal scene and start that passed their
    checks: these elements fail most draws, and the scene, start and goal IK cost more."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "kinds", tuple(self.kinds))
        unknown = [k for k in self.kinds if k not in BROAD_KINDS]
        if unknown:
            raise ValueError(f"unknown broad world kind(s) {unknown}; known: {', '.join(BROAD_KINDS)}")
        if not any(k in GOAL_KINDS for k in self.kinds):
            raise ValueError(
                f"kinds {list(self.kinds)} hold no goal scene; give one of {', '.join(GOAL_KINDS)}"
            )
        if self.n_obstacles < 0:
            raise ValueError(f"n_obstacles must be >= 0, got {self.n_obstacles}")
        if self.n_obstacles > 1 and not any(k in EXTRA_KINDS for k in self.kinds):
            raise ValueError(
                f"n_obstacles {self.n_obstacles} needs other elements than the goal's scene; "
                f"add one of {', '.join(EXTRA_KINDS)} to kinds or set n_obstacles to 0 or 1"
            )
        for name in ("min_goal_distance", "margin", "start_clearance"):
            value = getattr(self, name)
            if not value >= 0:
                raise ValueError(f"{name} must be >= 0, got {value}")
        for name in ("max_tries", "element_sets", "start_tries", "element_tries"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")


StartSampler = Callable[[np.random.Generator], np.ndarray]


def _yaw_matrix(yaw: float) -> np.ndarray:
    return rpy_to_matrix((0.0, 0.0, yaw))


def _vec(v) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _box(name: str, centre, half, yaw: float = 0.0, rpy=None) -> ObstacleSpec:
    """A static box; turned about z by ``yaw`` unless ``rpy`` is given."""
    return ObstacleSpec("box", _vec(centre), rpy=(0.0, 0.0, float(yaw)) if rpy is None else _vec(rpy),
                        half_extents=_vec(half), name=name)


def _aabb(obstacle: ObstacleSpec) -> tuple[np.ndarray, np.ndarray]:
    centre = np.asarray(obstacle.position, dtype=float)
    if obstacle.shape == "sphere":
        half = np.full(3, float(obstacle.radius))  # type: ignore[arg-type]
    else:
        half = np.abs(rpy_to_matrix(obstacle.rpy)) @ np.asarray(obstacle.half_extents, dtype=float)
    return centre - half, centre + half


def _overlap(a: ObstacleSpec, b: ObstacleSpec) -> bool:
    (a_low, a_high), (b_low, b_high) = _aabb(a), _aabb(b)
    return bool(np.all(a_low < b_high) and np.all(b_low < a_high))


# ---------------------------------------------------------------------- the sampler
class BroadWorlds:
    """Draws broad scenarios for one robot, checking them in ``scene`` (which it modifies)."""

    def __init__(
        self, kin: Kinematics, scene: WorldChecker, config: BroadWorldConfig = BroadWorldConfig()
    ) -> None:
        self.kin = kin
        self.scene = scene
        self.config = config
        spec = kin.spec
        self.goal_kinds = [k for k in config.kinds if k in GOAL_KINDS]
        self.extra_kinds = [k for k in config.kinds if k in EXTRA_KINDS]
        self.reach = arm_reach(kin)
        self.workspace = _workspace(kin)
        self.low = self.workspace[0] + config.margin
        self.high = self.workspace[1] - config.margin
        self.tool_rot = rpy_to_matrix(spec.tool_rpy)
        self.home = np.asarray(spec.home, dtype=float)
        self._home_azimuth = self._azimuth(kin.fk(self.home)[:3, 3])
        self._ik = IKParams(tolerance=1e-4, max_iterations=200)
        self.scale = max(1.0, self.reach.reach)
        """Sizes of shelves, boxes and tables grow with the reach in metres (UR5 1.06, KR16
        1.71): the KR16's wrist needs compartments as roomy for it as the UR5's for its own."""
        self.room = spec.tool.radius + 0.02
        """Least distance, m, of a goal from the boards and walls around it."""
        base_z = float(kin.world0[2, 3])
        self.stand_top = base_z if base_z > FLOOR_Z + 0.01 else None

    # ------------------------------------------------------------------ the contract
    def sample(self, rng: np.random.Generator, n_obstacles: int | None = None) -> tuple[Scenario, np.ndarray]:
        """A feasible scenario and its start configuration; the scene holds its obstacles, the
        robot at the start."""
        n = self.config.n_obstacles if n_obstacles is None else n_obstacles
        if n < 0:
            raise ValueError(f"n_obstacles must be >= 0, got {n}")
        if n > 1 and not self.extra_kinds:
            raise ValueError(f"n_obstacles {n} needs one of {', '.join(EXTRA_KINDS)} among the kinds")
        drawn_sets = []
        for _ in range(self.config.element_sets):
            # drawn once per max_tries, not per try: a kind that is harder to place is then not drawn less often
            kinds = [str(rng.choice(self.goal_kinds))] if n else []
            kinds += [str(k) for k in rng.choice(self.extra_kinds, size=n - 1)] if n > 1 else []
            found = self._sample_with(rng, kinds)
            if found is not None:
                return found
            drawn_sets.append(kinds)
        raise RuntimeError(
            f"no feasible broad world for {self.kin.spec.name} in {self.config.max_tries} tries for each of "
            f"{len(drawn_sets)} sets of elements: {drawn_sets}"
        )

    def _sample_with(self, rng: np.random.Generator, kinds: list[str]) -> tuple[Scenario, np.ndarray] | None:
        """A feasible scenario of these elements and its start configuration; None after
        ``max_tries`` draws."""
        spec = self.kin.spec
        for _ in range(self.config.max_tries):
            drawn = self._goal_scene(kinds[0], rng) if kinds else self._no_scene(rng)
            if drawn is None:
                continue
            scene_obstacles, goal, start_sampler = drawn
            if not self._usable(goal) or not self._stand_free(scene_obstacles):
                continue
            for _ in range(self.config.start_tries):
                found = self._complete(rng, kinds, scene_obstacles, goal, start_sampler)
                if found is not None:
                    obstacles, q_start = found
                    scenario = drawn_scenario("broad", spec.name, q_start, goal, obstacles, *self.workspace,
                                              f"broad world: {', '.join(kinds) or 'no obstacles'}")
                    return scenario, q_start
        return None

    def _complete(
        self, rng: np.random.Generator, kinds: list[str], scene_obstacles: list[ObstacleSpec],
        goal: np.ndarray, start_sampler: StartSampler,
    ) -> tuple[list[ObstacleSpec], np.ndarray] | None:
        """A start for the goal scene, the other elements, and the checks; None when it fails."""
        target = start_sampler(rng)
        if not self._usable(target):
            return None
        q_start = self._start_ik(target)
        if q_start is None:
            return None
        start = self.kin.fk(q_start)[:3, 3]
        if np.linalg.norm(goal - start) < self.config.min_goal_distance or not self._inside(start):
            return None
        # The goal configuration is the one IK finds from the start, as goal_configuration and
        # the executor's goal_solutions try first: no random seeds, so whoever checks the world
        # finds this same configuration. A free one from a random seed is often the one of
        # many that is, where a reactive planner's IK will not go.
        q_goal = goal_configuration(self.kin, goal, q_start, rng, n_random_seeds=0)
        if q_goal is None:
            return None
        # the goal's scene alone first: when it fails, no other elements can mend it
        self.scene.set_obstacles(scene_obstacles)
        if not self._free(q_goal) or not self._free(q_start):
            return None
        for _ in range(self.config.element_tries if len(kinds) > 1 else 1):
            obstacles = list(scene_obstacles)
            for i, kind in enumerate(kinds[1:], start=1):
                obstacles += self._clutter(rng, start, goal, i, obstacles) if kind == "clutter" else \
                    [self._wall(rng, start, goal, i)]
            if not self._stand_free(obstacles):
                continue
            if len(obstacles) > len(scene_obstacles):
                self.scene.set_obstacles(obstacles)
                if not self._free(q_goal) or not self._free(q_start):
                    continue
            self.scene.set_joints(q_start)
            clearance = self.config.start_clearance
            if clearance > 0 and self.scene.clearance(clearance) < clearance:
                continue
            return obstacles, q_start
        return None

    def _free(self, q: np.ndarray) -> bool:
        self.scene.set_joints(q)
        return not self.scene.in_collision()

    def _start_ik(self, target: np.ndarray) -> np.ndarray | None:
        """6-D IK to ``target`` with the default tool orientation, from home and from home turned
        about the base axis towards the target: a start behind the robot is far from home."""
        turned = self.home.copy()
        sign = self.kin.base_turn_sign
        turn = (self._azimuth(target) - self._home_azimuth + math.pi) % (2 * math.pi) - math.pi
        turned[0] = np.clip(turned[0] + sign * turn, self.kin.lower[0], self.kin.upper[0])
        for seed in (self.home, turned):
            ik = self.kin.ik(target, self.tool_rot, seed, self._ik)
            if ik.converged:
                return ik.q
        return None

    def _azimuth(self, point: np.ndarray) -> float:
        return math.atan2(point[1] - self.reach.base_xy[1], point[0] - self.reach.base_xy[0])

    # ------------------------------------------------------------------ where points may go
    def _inside(self, point: np.ndarray) -> bool:
        return bool(np.all(point >= self.low) and np.all(point <= self.high))

    def _usable(self, point: np.ndarray) -> bool:
        """Inside the workspace, within reach, out of the stand's column."""
        if not self._inside(point) or self.reach.distance_beyond(point) > -_REACH_SLACK:
            return False
        if self.stand_top is not None and point[2] < self.stand_top:
            rho = math.hypot(point[0] - self.reach.base_xy[0], point[1] - self.reach.base_xy[1])
            return rho > STAND_RADIUS + 0.05
        return True

    def _reachable_point(self, rng: np.random.Generator) -> np.ndarray:
        """A uniform point of the workspace that is usable, or the last draw when 30 draws found
        none (the caller's checks then reject it)."""
        point = rng.uniform(self.low, self.high)
        for _ in range(29):
            if self._usable(point):
                break
            point = rng.uniform(self.low, self.high)
        return point

    def _stand_free(self, obstacles: list[ObstacleSpec]) -> bool:
        if self.stand_top is None:
            return True
        x, y = self.reach.base_xy
        for obstacle in obstacles:
            low, high = _aabb(obstacle)
            if low[2] < self.stand_top and low[0] < x + STAND_RADIUS and high[0] > x - STAND_RADIUS \
                    and low[1] < y + STAND_RADIUS and high[1] > y - STAND_RADIUS:
                return False
        return True

    # ------------------------------------------------------------------ goal scenes
    def _goal_scene(self, kind: str, rng: np.random.Generator
                    ) -> tuple[list[ObstacleSpec], np.ndarray, StartSampler] | None:
        if kind == "table":
            return self._table(rng, 0)
        if kind == "shelf":
            return self._shelf(rng, 0)
        return self._goal_box(rng, 0)

    def _no_scene(self, rng: np.random.Generator) -> tuple[list[ObstacleSpec], np.ndarray, StartSampler]:
        return [], self._reachable_point(rng), self._reachable_point

    def _table(self, rng: np.random.Generator, index: int
               ) -> tuple[list[ObstacleSpec], np.ndarray, StartSampler] | None:
        """A table top under a goal drawn first; the start above the top or beside the table
        (a start drawn under the top is lifted above it)."""
        goal = self._reachable_point(rng)
        half = np.array([rng.uniform(0.2, 0.45), rng.uniform(0.15, 0.35), 0.0]) * self.scale
        half[2] = rng.uniform(0.01, 0.025)
        top = goal[2] - rng.uniform(0.02, 0.25)
        if top - 2 * half[2] < FLOOR_Z:
            return None
        yaw = float(rng.uniform(0, math.pi))
        rot = _yaw_matrix(yaw)
        offset = rng.uniform(-1, 1, 3) * np.array([half[0] - 0.03, half[1] - 0.03, 0.0])
        centre = goal - rot @ offset
        centre[2] = top - half[2]
        prefix = f"table_{index}"
        boxes = [_box(f"{prefix}_top", centre, half, yaw)]
        leg_height = top - 2 * half[2] - FLOOR_Z
        if leg_height > 0.05 and rng.random() < 0.5:
            leg = 0.02 * self.scale
            for j, (sx, sy) in enumerate(((-1, -1), (1, -1), (-1, 1), (1, 1))):
                corner = centre + rot @ np.array([sx * (half[0] - leg), sy * (half[1] - leg), 0.0])
                corner[2] = FLOOR_Z + leg_height / 2
                boxes.append(_box(f"{prefix}_leg_{j}", corner, (leg, leg, leg_height / 2), yaw))

        def start(r: np.random.Generator) -> np.ndarray:
            if r.random() < 0.5:  # above the top
                point = centre + rot @ (r.uniform(-1, 1, 3) * np.array([half[0], half[1], 0.0]))
            else:  # beside the table
                point = self._reachable_point(r)
                local = rot.T @ (point - centre)
                if abs(local[0]) >= half[0] or abs(local[1]) >= half[1] or point[2] >= top + 0.05:
                    return point
            point[2] = top + r.uniform(0.05, 0.4)
            return point

        return boxes, goal, start

    def _shelf(self, rng: np.random.Generator, index: int
               ) -> tuple[list[ObstacleSpec], np.ndarray, StartSampler] | None:
        """A shelf built around a goal drawn first, its open face towards the base; the start in
        front of that face, at least 0.1 m off it (RandomWorlds._shelf says why)."""
        goal = self._reachable_point(rng)
        rows, cols = int(rng.integers(1, 4)), int(rng.integers(1, 4))
        cell_w, cell_h = rng.uniform(0.2, 0.4, 2) * self.scale
        depth = float(rng.uniform(0.15, 0.35)) * self.scale
        t = float(rng.uniform(0.015, 0.05))
        width, height = cols * cell_w + (cols + 1) * t, rows * cell_h + (rows + 1) * t
        # local frame: x along the boards, y into the shelf (open face at -y), z up
        towards_base = math.atan2(self.reach.base_xy[1] - goal[1], self.reach.base_xy[0] - goal[0])
        into = towards_base + math.pi + float(rng.uniform(-0.35, 0.35))
        yaw = into - math.pi / 2
        rot = _yaw_matrix(yaw)
        row, col = int(rng.integers(rows)), int(rng.integers(cols))
        cell = np.array([-width / 2 + t + cell_w / 2 + col * (cell_w + t), 0.0,
                         -height / 2 + t + cell_h / 2 + row * (cell_h + t)])
        room = self.room
        local_goal = cell + np.array([
            rng.uniform(-1, 1) * (cell_w / 2 - room),
            -depth / 2 + rng.uniform(0.03, max(0.04, min(depth - 0.03, 0.25 * self.scale))),
            rng.uniform(-1, 1) * (cell_h / 2 - room),
        ])
        centre = goal - rot @ local_goal
        bottom = centre[2] - height / 2
        if bottom < FLOOR_Z:
            return None
        standing = bool(rng.random() < 0.5)  # the outer walls stand on the floor
        prefix = f"shelf_{index}"
        parts: list[tuple[str, np.ndarray, tuple[float, float, float]]] = []
        for i in range(rows + 1):
            parts.append((f"board_{i}", np.array([0.0, 0.0, -height / 2 + t / 2 + i * (cell_h + t)]),
                          (width / 2, depth / 2, t / 2)))
        for j in range(cols + 1):
            x = -width / 2 + t / 2 + j * (cell_w + t)
            if standing and j in (0, cols):
                low = FLOOR_Z - centre[2]
                parts.append((f"wall_{j}", np.array([x, 0.0, (low + height / 2) / 2]),
                              (t / 2, depth / 2, (height / 2 - low) / 2)))
            else:
                parts.append((f"wall_{j}", np.array([x, 0.0, 0.0]), (t / 2, depth / 2, height / 2)))
        if rng.random() < 0.5:
            parts.append(("back", np.array([0.0, depth / 2 + t / 2, 0.0]), (width / 2, t / 2, height / 2)))
        boxes = [_box(f"{prefix}_{name}", centre + rot @ local, half, yaw) for name, local, half in parts]

        def start(r: np.random.Generator) -> np.ndarray:
            off = 0.1 + r.uniform(0.0, 0.4) * self.scale
            local = np.array([r.uniform(-width / 2, width / 2), -depth / 2 - off,
                              r.uniform(-height / 2, height / 2)])
            return centre + rot @ local

        return boxes, goal, start

    def _goal_box(self, rng: np.random.Generator, index: int
                  ) -> tuple[list[ObstacleSpec], np.ndarray, StartSampler] | None:
        """An open box built around a goal drawn first, the goal below its rim; the start outside
        it (not over its opening, below the rim plus 5 cm)."""
        goal = self._reachable_point(rng)
        inner = rng.uniform(0.08, 0.16, 2) * self.scale  # inner half sizes, x and y
        t = float(rng.uniform(0.01, 0.03))
        floor_top = goal[2] - rng.uniform(0.02, 0.1)
        rim = goal[2] + rng.uniform(0.03, 0.12) * self.scale
        if floor_top - t < FLOOR_Z:
            return None
        yaw = float(rng.uniform(0, 2 * math.pi))
        rot = _yaw_matrix(yaw)
        offset = rng.uniform(-1, 1, 2) * (inner - self.room)
        centre = goal - rot @ np.array([offset[0], offset[1], 0.0])
        centre[2] = 0.0  # heights are absolute below
        bottom = floor_top - t
        wall_mid, wall_half = (bottom + rim) / 2, (rim - bottom) / 2
        hx, hy = inner
        parts: list[tuple[str, np.ndarray, tuple[float, float, float]]] = [
            ("bottom", np.array([0.0, 0.0, floor_top - t / 2]), (hx + t, hy + t, t / 2)),
            ("wall_0", np.array([-(hx + t / 2), 0.0, wall_mid]), (t / 2, hy + t, wall_half)),
            ("wall_1", np.array([hx + t / 2, 0.0, wall_mid]), (t / 2, hy + t, wall_half)),
            ("wall_2", np.array([0.0, -(hy + t / 2), wall_mid]), (hx, t / 2, wall_half)),
            ("wall_3", np.array([0.0, hy + t / 2, wall_mid]), (hx, t / 2, wall_half)),
        ]
        if rng.random() < 0.5:  # three walls: one side open too
            del parts[1 + int(rng.integers(4))]
        if bottom - FLOOR_Z > 0.05 and rng.random() < 0.5:  # on a stand
            parts.append(("stand", np.array([0.0, 0.0, (FLOOR_Z + bottom) / 2]),
                          (0.6 * hx, 0.6 * hy, (bottom - FLOOR_Z) / 2)))
        boxes = []
        for name, local, half in parts:
            position = centre + rot @ np.array([local[0], local[1], 0.0])
            position[2] = local[2]
            boxes.append(_box(f"goal_box_{index}_{name}", position, half, yaw))

        def start(r: np.random.Generator) -> np.ndarray:
            point = self._reachable_point(r)
            local = rot.T @ (point - centre)
            over = abs(local[0]) < hx + t + 0.05 and abs(local[1]) < hy + t + 0.05
            if over and point[2] < rim + 0.05:
                point[2] = rim + r.uniform(0.05, 0.3)  # lifted above the opening
            return point

        return boxes, goal, start

    # ------------------------------------------------------------------ other elements
    def _clutter(self, rng: np.random.Generator, start: np.ndarray, goal: np.ndarray, index: int,
                 placed: list[ObstacleSpec]) -> list[ObstacleSpec]:
        """3 to 8 small boxes and spheres: half near the straight path, half in the box around
        start and goal (0.3 m wider), each moved (up to 8 times) off what is already there."""
        items = []
        low, high = np.minimum(start, goal) - 0.3, np.maximum(start, goal) + 0.3
        low[2] = max(low[2], FLOOR_Z + 0.04)
        for j in range(int(rng.integers(3, 9))):
            sphere = bool(rng.random() < 0.5)
            size = rng.uniform(0.01, 0.04, 3)
            rpy = rng.uniform(-math.pi, math.pi, 3)
            near = bool(rng.random() < 0.5)
            item = None
            for _ in range(8):
                if near:
                    centre = start + rng.uniform(0.2, 0.8) * (goal - start) + rng.uniform(-0.08, 0.08, 3)
                else:
                    centre = rng.uniform(low, np.maximum(low, high))
                centre[2] = max(centre[2], FLOOR_Z + 0.04)
                if sphere:
                    item = ObstacleSpec("sphere", _vec(centre), radius=float(size[0]),
                                        name=f"clutter_{index}_sphere_{j}")
                else:
                    item = _box(f"clutter_{index}_box_{j}", centre, size, rpy=rpy)
                if not any(_overlap(item, other) for other in placed + items):
                    break
            items.append(item)  # type: ignore[arg-type]
        return items

    def _wall(
        self, rng: np.random.Generator, start: np.ndarray, goal: np.ndarray, index: int
    ) -> ObstacleSpec:
        """An upright plate across the straight path between 30 % and 70 % of the way, shifted
        sideways and up or down by under half its size, so the path meets it and the arm can
        get round an edge."""
        width, height = float(rng.uniform(0.3, 0.8)), float(rng.uniform(0.3, 0.8))
        thickness = float(rng.uniform(0.005, 0.015))
        along = start + rng.uniform(0.3, 0.7) * (goal - start)
        path = goal - start
        level = math.hypot(path[0], path[1]) > 1e-3  # else straight up or down: any heading
        heading = math.atan2(path[1], path[0]) if level else float(rng.uniform(0, math.pi))
        yaw = heading + float(rng.uniform(-0.3, 0.3))
        side = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
        centre = along + rng.uniform(-0.45, 0.45) * width * side
        centre[2] += rng.uniform(-0.4, 0.4) * height
        centre[2] = max(centre[2], FLOOR_Z + height / 2)
        return _box(f"wall_{index}_plate", centre, (thickness, width / 2, height / 2), yaw)
