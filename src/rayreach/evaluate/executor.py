"""One executor for every planner: same scene, control period, speed limits and measurements.

A run starts from the scenario's start configuration at t = 0. A global planner plans on the
scene as it is at t = 0 (obstacles frozen), then its joint path is timed: each control period
(``EnvConfig.control_period``) the arm moves its end effector at most ``ee_step`` (0.005 m)
along each axis, the DRL action's bound, and at most ``velocity * period`` in every joint. A reactive
planner acts once per control period through :class:`~rayreach.env.reach.ReachEnv`, wrapped
in the acting layers it asks for (``ReactivePlanner.acting``, ``rayreach.acting``). Either way the
arm is checked for collision at every control step against the obstacles where they are at
that time. Definitions of the recorded metrics: ``docs/metrics.md``.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rayreach.acting import ActingConfig, ActingEnv
from rayreach.env.reach import ReachEnv
from rayreach.env.episode import run_episode
from rayreach.sim.kinematics import Kinematics
from rayreach.planners import GlobalPlanner, PlanResult, ReactivePlanner, Status
from rayreach.planners.collision import CollisionChecker
from rayreach.scenarios import Scenario
from rayreach.scenarios.feasibility import goal_solutions


@dataclass(frozen=True)
class ExecutionConfig:
    goal_tolerance: float = 0.01
    """Success radius around each goal, m (the paper's final target size)."""
    goal_ik_seeds: int = 16
    """Random IK seeds (after the start configuration) for a goal's joint configuration."""
    goal_ik_more_seeds: int = 256
    """Further random IK seeds, tried one by one only when those above gave no collision-free
    solution (tables, shelves, boxes around the goal); 0: the first seeds alone. Measured in
    ``docs/metrics.md`` (``rayreach bench-goals``)."""
    replan: bool = False
    """Replan when the remaining path becomes invalid (moving obstacles); off as in the paper."""
    lookahead: int = 24
    """Control steps of the remaining path checked each step in replanning mode (0.1 s)."""
    max_replans: int = 10


@dataclass
class RunRecord:
    """What one run of one planner did; the row of the results database."""

    planner: str
    scenario: str
    seed: int
    outcome: str
    """``success``, ``collision``, ``timeout`` (DRL step budget), ``out of bounds`` (DRL left
    the workspace), ``outside training`` (DRL refused a start or goal outside its training
    workspace; see ``message``) or ``no plan`` (see ``plan_status``)."""
    plan_status: str
    """The planner's :class:`Status` value (``solved`` for the DRL planner)."""
    success: bool
    collision: bool
    path_length: float
    """End-effector path length of the executed motion, m."""
    path_length_unsmoothed: float
    """The same for the planner's path before smoothing (equal when not smoothed), m."""
    joint_path_length: float
    planning_time: float
    motion_time: float
    execution_time: float
    steps: int
    replans: int = 0
    message: str = ""
    config: dict[str, Any] = field(default_factory=dict)
    acting_share: dict[str, float] = field(default_factory=dict)
    """Reactive planners: the share of steps by what chose the executed motion (``policy``,
    ``final_approach``, ``detour``, ...; ``held``: the arm held still), summing to 1; empty
    for global planners (``rayreach.acting``)."""
    ee_path: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    joint_path: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))

    def summary(self) -> dict[str, Any]:
        """The scalar fields (no trajectories, no config)."""
        data = asdict(self)
        for key in ("ee_path", "joint_path", "config", "acting_share"):
            data.pop(key)
        return data


def polyline_length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()) if len(points) > 1 else 0.0


def time_path(kin: Kinematics, path: list[np.ndarray], velocity: np.ndarray, period: float,
              ee_step: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint configurations, one per control step (the first is ``path[0]``), moving along the
    straight joint segments of ``path`` at the speed limits; and their tool positions.

    The end-effector limit is the DRL action's bound: at most ``ee_step`` along each world
    axis per step."""
    qs, ees = [np.asarray(path[0], dtype=float)], [kin.fk(path[0])[:3, 3]]
    for qa, qb in zip(path[:-1], path[1:]):
        n = max(1, math.ceil(float(np.max(np.abs(qb - qa) / (velocity * period)))))
        while True:  # more steps until no step moves the end effector more than ee_step along an axis
            seg_q = qa + (qb - qa) * (np.arange(1, n + 1)[:, None] / n)
            seg_q[-1] = qb  # exactly: the executor recognises reached goals by equality
            seg_ee = np.array([kin.fk(q)[:3, 3] for q in seg_q])
            longest = float(np.max(np.abs(np.diff(np.vstack((ees[-1], seg_ee)), axis=0))))
            if longest <= ee_step:
                break
            n = math.ceil(n * longest / ee_step * 1.02) + 1
        qs.extend(seg_q)
        ees.extend(seg_ee)
    return np.asarray(qs), np.asarray(ees)


class Executor:
    """Runs planners on one scenario (a built-in experiment, a scene file or ``random``)."""

    def __init__(self, scenario: str | Path | Scenario, robot: str | None = None,
                 config: ExecutionConfig = ExecutionConfig()) -> None:
        self.config = config
        self.env = ReachEnv(robot=robot, scenario=scenario, goal_tolerance=config.goal_tolerance)
        self.kin = self.env.kin
        self.scene = self.env.scene
        self.checker = CollisionChecker(self.scene)
        self.spec = self.env.spec_robot
        self.period = self.env.config.control_period
        self._acting: dict[ActingConfig, ActingEnv] = {}

    def acting_env(self, config: ActingConfig) -> ActingEnv:
        """The scene's environment acting through ``config``, made once per configuration."""
        if config not in self._acting:
            self._acting[config] = ActingEnv(self.env, config)
        return self._acting[config]

    @property
    def robot(self) -> str:
        return self.spec.name

    def close(self) -> None:
        self.env.close()

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ query
    def reset(self, seed: int) -> np.ndarray:
        """Put the scenario (for ``random``: world ``seed``) at t = 0; the start configuration."""
        self.env.reset(seed=seed)
        return self.env.q.copy()

    def goal_configuration(self, goal: np.ndarray, q_seed: np.ndarray, rng: np.random.Generator,
                           more_rng: np.random.Generator | None = None
                           ) -> tuple[np.ndarray | None, Status | None]:
        """The first collision-free IK solution for ``goal`` over the seeds (``q_seed`` first,
        then ``goal_ik_seeds`` from ``rng``, then ``goal_ik_more_seeds`` from ``more_rng``),
        else the reason: unreachable (no seed converged) or in collision (all did, all collide)."""
        converged = False
        for q in goal_solutions(self.kin, goal, q_seed, rng, self.config.goal_ik_seeds,
                                more_rng, self.config.goal_ik_more_seeds):
            converged = True
            if self.checker.valid(q):
                return q, None
        return None, Status.GOAL_IN_COLLISION if converged else Status.GOAL_UNREACHABLE

    def goal_configurations(self, seed: int, q_first: np.ndarray | None = None
                            ) -> tuple[list[np.ndarray], Status | None, str]:
        """Joint goals for the current query, the same for every planner of run ``seed``; the
        first goal's IK is seeded from ``q_first`` (default: the start configuration), each
        next one's from the goal before.

        The further seeds have a stream of their own, so a goal the first seeds solve gets the
        configuration it got before they existed."""
        rng, more_rng = np.random.default_rng([seed, 7]), np.random.default_rng([seed, 7, 1])
        q, goals = (self.env.q.copy() if q_first is None else q_first), []
        for i, goal in enumerate(self.env.goals):
            q_goal, bad = self.goal_configuration(goal, q, rng, more_rng)
            if q_goal is None:
                return goals, bad, f"goal {i} at {np.round(goal, 3).tolist()}: {bad.value}"  # type: ignore[union-attr]
            goals.append(q_goal)
            q = q_goal
        return goals, None, ""

    # ------------------------------------------------------------------ runs
    def run(self, planner: GlobalPlanner | ReactivePlanner, seed: int) -> RunRecord:
        """One run of ``planner`` with world, goal IK and planner randomness from ``seed``."""
        if isinstance(planner, ReactivePlanner):
            return self._run_reactive(planner, seed)  # its episode resets the world
        self.reset(seed)
        return self._run_global(planner, seed)

    @staticmethod
    def _acting_record(env: ActingEnv) -> dict[str, Any]:
        """What acted between a reactive planner and the arm, for its run records."""
        config, approach = env.config, env.final_approach
        return {"safety": asdict(config.safety),
                "final_approach": asdict(approach) if approach is not None else None,
                "detour": asdict(config.detour) if config.detour is not None else None}

    def _record(self, planner, seed: int, **values: Any) -> RunRecord:
        values.setdefault("config", planner.config())
        values["execution_time"] = values["planning_time"] + values["motion_time"]
        scenario = self.env.suite if self.env.random else self.env.scenario.name
        return RunRecord(planner=planner.name, scenario=scenario,
                         seed=seed, **values)

    def _run_reactive(self, planner: ReactivePlanner, seed: int) -> RunRecord:
        env = self.acting_env(planner.acting)
        if self.env.config.observation != planner.observation:
            self.env.set_observation(planner.observation)
        planner.reset(seed)
        start = env.reset(seed=seed)
        why = planner.refusal(self.env.ee_pos, self.env.goals)
        if why:
            refused = Status.OUTSIDE_TRAINING.value
            return self._record(planner, seed, config={**planner.config(), **self._acting_record(env)},
                                outcome=refused, plan_status=refused, success=False, collision=False,
                                path_length=math.nan, path_length_unsmoothed=math.nan, joint_path_length=math.nan,
                                planning_time=0.0, motion_time=0.0, steps=0, message=why)
        episode = run_episode(env, planner.act, seed, start=start)
        info = episode.info
        length = episode.path_length
        return self._record(planner, seed, config={**planner.config(), **self._acting_record(env)},
                            outcome=episode.outcome.replace("_", " "), plan_status=Status.SOLVED.value,
                            success=bool(info["is_success"]), collision=bool(info["collision"]),
                            path_length=length, path_length_unsmoothed=length,
                            joint_path_length=polyline_length(episode.joint_path), planning_time=episode.compute_time,
                            motion_time=episode.steps * self.period, steps=episode.steps, ee_path=episode.ee_path,
                            joint_path=episode.joint_path, acting_share=episode.acting_share)

    def _plan(self, planner: GlobalPlanner, waypoints: list[np.ndarray], rng: np.random.Generator
              ) -> tuple[list[np.ndarray] | None, list[np.ndarray] | None, PlanResult]:
        """Plan every leg start -> goal 1 -> goal 2 ...; the joined path, the joined raw path
        (before smoothing; the joined path itself when nothing was smoothed) and the last
        leg's result (the failing one, if any)."""
        path: list[np.ndarray] = [waypoints[0]]
        raw: list[np.ndarray] = [waypoints[0]]
        planning, smoothed = 0.0, False
        result: PlanResult | None = None
        for qa, qb in zip(waypoints[:-1], waypoints[1:]):
            result = planner.plan(self.checker, qa, qb, rng)
            planning += result.planning_time
            if not result.solved:
                result.planning_time = planning
                return None, None, result
            assert result.path is not None
            path.extend(result.path[1:])
            raw.extend((result.raw_path or result.path)[1:])
            smoothed = smoothed or result.raw_path is not None
        assert result is not None
        result.planning_time = planning
        return path, raw if smoothed else path, result

    def _run_global(self, planner: GlobalPlanner, seed: int) -> RunRecord:
        q_start = self.env.q.copy()
        t0 = time.perf_counter()
        goals, bad, message = self.goal_configurations(seed)
        ik_time = time.perf_counter() - t0
        empty = {"success": False, "collision": False, "path_length": math.nan, "path_length_unsmoothed": math.nan,
                 "joint_path_length": math.nan, "motion_time": 0.0, "steps": 0}
        if bad is not None:
            return self._record(planner, seed, outcome="no plan", plan_status=bad.value, planning_time=ik_time,
                                message=message, **empty)
        rng = np.random.default_rng([seed, 11])
        self.scene.set_time(0.0)
        path, raw, result = self._plan(planner, [q_start, *goals], rng)
        planning = ik_time + result.planning_time
        if path is None:
            return self._record(planner, seed, outcome="no plan", plan_status=result.status.value,
                                planning_time=planning, message=result.message, config=result.config, **empty)
        assert raw is not None
        velocity = np.asarray(self.spec.velocity)
        qs, ees = time_path(self.kin, path, velocity, self.period, self.spec.ee_step)
        raw_length = (polyline_length(ees) if raw is path
                      else polyline_length(time_path(self.kin, raw, velocity, self.period, self.spec.ee_step)[1]))
        goal_index, replans, plan_status = 0, 0, Status.SOLVED.value
        executed_q, executed_ee = [qs[0]], [ees[0]]
        collided, message = False, ""
        i = 1
        while i < len(qs):
            t = len(executed_q) * self.period
            self.scene.set_time(t)
            if self.config.replan and not self._ahead_valid(qs[i: i + self.config.lookahead]):
                if replans == self.config.max_replans:
                    message = f"gave up after {replans} replans"
                    break
                replans += 1
                remaining = [executed_q[-1], *goals[goal_index:]]
                new_path, _, result = self._plan(planner, remaining, rng)
                planning += result.planning_time
                if new_path is None:
                    message = f"replan {replans}: {result.status.value}"
                    plan_status = result.status.value
                    break
                qs, ees = time_path(self.kin, new_path, velocity, self.period, self.spec.ee_step)
                i = 1
                continue
            self.scene.set_joints(qs[i])
            executed_q.append(qs[i])
            executed_ee.append(ees[i])
            if goal_index < len(goals) and np.array_equal(qs[i], goals[goal_index]):
                goal_index += 1
            if self.scene.in_collision():
                collided = True
                break
            i += 1
        ee_path = np.asarray(executed_ee)
        reached = (not collided and goal_index == len(goals)
                   and float(np.linalg.norm(ee_path[-1] - self.env.goals[-1])) < self.config.goal_tolerance)
        outcome = "success" if reached else "collision" if collided else "no plan"
        return self._record(planner, seed, outcome=outcome, plan_status=plan_status, success=reached,
                            collision=collided, path_length=polyline_length(ee_path),
                            path_length_unsmoothed=raw_length if not replans else math.nan,
                            joint_path_length=polyline_length(np.asarray(executed_q)), planning_time=planning,
                            motion_time=(len(executed_q) - 1) * self.period, steps=len(executed_q) - 1,
                            replans=replans, message=message, config=result.config, ee_path=ee_path,
                            joint_path=np.asarray(executed_q))

    def _ahead_valid(self, upcoming: np.ndarray) -> bool:
        """The next configurations are free of the obstacles where they are now."""
        return all(self.checker.valid(q) for q in upcoming)


def bench_goals(suite: str = "broad", robot: str = "ur5", worlds: int = 100, first_seed: int = 1_000_000,
                more_seeds: tuple[int, ...] = (0, ExecutionConfig.goal_ik_more_seeds),
                from_home: bool = False) -> dict[str, Any]:
    """How many of ``worlds`` worlds of ``suite`` (seeds from ``first_seed``; 1,000,000: the
    validation split) end with no goal configuration, by ``goal_ik_more_seeds`` count, and the
    milliseconds the goal IK takes per world: to choose that count by measurement. No planning.

    The broad and random worlds are drawn so that IK seeded from the start is collision-free;
    ``from_home`` seeds it from the robot's home configuration instead, as for a scene whose
    start says nothing about the goal's free posture."""
    from dataclasses import replace

    out: dict[str, Any] = {"suite": suite, "robot": robot, "worlds": worlds, "first_seed": first_seed,
                           "from_home": from_home, "counts": {}}
    with Executor(suite, robot=robot) as ex:
        for n in more_seeds:
            ex.config = replace(ex.config, goal_ik_more_seeds=n)
            statuses: dict[str, int] = {}
            seconds = 0.0
            for seed in range(first_seed, first_seed + worlds):
                ex.reset(seed)
                t0 = time.perf_counter()
                q_first = np.asarray(ex.spec.home, dtype=float) if from_home else None
                bad = ex.goal_configurations(seed, q_first)[1]
                seconds += time.perf_counter() - t0
                key = "ok" if bad is None else bad.value
                statuses[key] = statuses.get(key, 0) + 1
            out["counts"][str(n)] = {"statuses": dict(sorted(statuses.items())),
                                     "ms_per_world": round(1000 * seconds / worlds, 2)}
    return out
