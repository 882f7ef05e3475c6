"""The paper's MDP for N worlds in one object: ``ReachEnv``'s step, each stage computed for all
worlds at once.

``BatchedReachEnv(robot, n_worlds)`` is a stable-baselines3 ``VecEnv``: the same observation
(the paper's 142 values and what ``EnvConfig.observation`` adds, same order), action, reward
terms, episode ends and seeding as N ``ReachEnv`` objects, world ``i`` seeded as
``ReachEnv.reset(seed=seed + i)`` would be (``tests/test_batched_env.py`` steps both through
the same worlds). A single env pays numpy's per-call overhead on arrays of three to six
values in every part of a step; here each part is one call over all worlds:

=================  ============================================================================
IK                 ``sim.batch_kinematics``: Algorithm 1 per world, compiled
obstacles          ``sim.batch_obstacles``: moving obstacles advanced for all worlds
collision          ``sim.batch_collision``: spheres round the arm's links against each world's
                   obstacles; PyBullet's own query only for the worlds they come near, so the
                   answer is ``Scene.in_collision``'s
rays               ``sim.batch_rays``: the 129 rays of every world, cast against its obstacles
reward, end, obs   numpy over the world axis; the shaking window compiled
=================  ============================================================================

Random worlds are drawn at reset, one world at a time, by ``RandomWorlds``, checked where
the world is then tested (``CollisionWorlds.slot``: no PyBullet bodies, whose making is
most of what a single env's draw costs; docs/performance.md).

``infos``: ``{}`` while a world's episode goes on (a dict per world and step would cost
more than the step); at its end the info ``ReachEnv`` returns last, with
``terminal_observation``, ``TimeLimit.truncated`` and ``episode_reward_terms`` (each reward
term summed over the episode).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import time

import gymnasium as gym
import numba
import numpy as np
from gymnasium.utils import seeding
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from rayreach.env.goal_field import FieldBatch, GoalField, scenario_field
from rayreach.env.observation import Observer, nearest_ray, nearest_sightings
from rayreach.env.reach import (N_ROBOT_OBS, OBS_SIZE, REWARD_TERM_NAMES, EnvConfig, make_config,
                                observation_space, resolve_task)
from rayreach.env.rewards import ShakeCounter
from rayreach.scenarios import RANDOM, Scenario
from rayreach.scenarios.feasibility import solve_start, validate
from rayreach.scenarios.suites import suite_workspace, world_sampler
from rayreach.sim.batch_clearance import PER_SPHERE, SPEED_SCALE, clearance
from rayreach.sim.batch_collision import MARGIN, CollisionWorlds, candidates
from rayreach.sim.batch_kinematics import solve_steps
from rayreach.sim.batch_obstacles import ObstacleBatch
from rayreach.sim.batch_rays import RayArrays, cast_given, cast_worlds, place_rays
from rayreach.sim.goal_rays import N_GOAL_RAYS, goal_rays
from rayreach.sim.kinematics import Kinematics
from rayreach.sim.scene import Scene
from rayreach.sim.sensors import N_RAYS, RayModel

SHAKE_WINDOW = ShakeCounter().window
"""Movements the shaking counter compares."""

STAGES = ("ik", "obstacles", "collision_spheres", "collision_bullet", "rays", "reward_and_obs", "resets")
"""The parts of a step ``stage_seconds`` times (docs/performance.md)."""

BATCH_RAY_BACKENDS = ("auto", "numpy")
"""``EnvConfig.ray_backend`` values whose rays the batched caster reproduces."""

ENV_METHODS = ("set_goal_tolerance", "set_n_obstacles")
"""What ``env_method`` reaches: the curricula's setters, per world."""


class BatchedReachEnv(VecEnv):
    """``n_worlds`` reach tasks of one robot, random worlds or one fixed scenario for all."""

    def __init__(
        self,
        robot: str | None = None,
        n_worlds: int = 256,
        scenario: str | Path | Scenario = RANDOM,
        config: EnvConfig | None = None,
        seed: int | None = None,
        **overrides: Any,
    ) -> None:
        if n_worlds < 1:
            raise ValueError(f"n_worlds must be >= 1, got {n_worlds}")
        self.config = cfg = make_config(config, overrides)
        if cfg.ray_backend not in BATCH_RAY_BACKENDS:
            raise ValueError(f"the batched env casts its rays itself (ray_backend {' or '.join(BATCH_RAY_BACKENDS)}), "
                             f"not '{cfg.ray_backend}'; use ReachEnv for PyBullet's rays")
        spec, fixed = resolve_task(robot, scenario)
        self.spec_robot = spec
        self.random = fixed is None
        base_pos = fixed.base_position if fixed else None
        base_rpy = fixed.base_rpy if fixed else None
        self.kin = Kinematics(spec, base_pos, base_rpy)
        self.layout = RayArrays.of(RayModel(spec, cfg.ray_range))
        extra = RayModel.extra(spec, cfg.ray_range, cfg.observation.ray_sets)
        self.extra_layout = RayArrays.of(extra) if extra is not None else None
        self.collision = CollisionWorlds(spec, n_worlds, base_pos, base_rpy)
        self.spheres = self.collision.spheres
        self.samplers = [world_sampler(str(scenario), self.kin, self.collision.slot(i), cfg.random_world)
                         for i in range(n_worlds)] if self.random else []
        """World ``i`` is drawn where it is tested, as ``ReachEnv`` draws in its scene."""
        self.obstacles = ObstacleBatch(n_worlds)
        n = n_worlds
        ws_low, ws_high = ((np.asarray(fixed.workspace_low, dtype=float), np.asarray(fixed.workspace_high, dtype=float))
                           if fixed else suite_workspace(str(scenario), spec))
        self.step_scale = np.array([spec.ee_step] * 3 + [spec.rot_step] * 3)
        self.render_mode = None
        self.rngs: list[np.random.Generator | None] = [None] * n
        self.n_obstacles = np.full(n, cfg.random_world.n_obstacles, dtype=np.int64)
        self.goal_tolerance = np.full(n, cfg.goal_tolerance)
        """The success radius each world's next episode gets (the goal-size curriculum's)."""
        self.tolerance = np.zeros(n)
        self.true_goal_episode = np.zeros(n, dtype=bool)
        self.ws_low = np.tile(ws_low, (n, 1))
        self.ws_high = np.tile(ws_high, (n, 1))
        self.q = np.zeros((n, 6))
        self.frames = np.zeros((n, 7, 4, 4))
        self.ee_pos = np.zeros((n, 3))
        self.ee_rot = np.zeros((n, 3, 3))
        self.ref_rot_t = np.zeros((n, 3, 3))
        self.goals = np.zeros((n, 1, 3))
        self.n_goals = np.ones(n, dtype=np.int64)
        self.goal_index = np.zeros(n, dtype=np.int64)
        self.steps = np.zeros(n, dtype=np.int64)
        self.time = np.zeros(n)
        self.previous_distance = np.zeros(n)
        self.fields = FieldBatch(n) if cfg.rewards.progress_around_obstacles else None
        """Each world's goal field where the progress term goes round obstacles (``goal_field``)."""
        self.previous_way = np.zeros(n)
        """What the progress term measured last step: the way round obstacles, or the distance."""
        self._scenarios: list[Scenario | None] = [None] * n
        self._fixed_fields: dict[int, GoalField] = {}
        self.shake_queue = np.zeros((n, SHAKE_WINDOW + 1))
        self.shake_length = np.zeros(n, dtype=np.int64)
        self.fractions = np.ones((n, N_RAYS))
        self.extra_fractions = np.ones((n, cfg.observation.extra_rays))
        self.episode_terms = np.zeros((n, len(REWARD_TERM_NAMES)))
        self.converged = np.ones(n, dtype=bool)
        self.base_obs = np.zeros((n, OBS_SIZE), dtype=np.float32)
        """The paper's 142 values of each world; ``observer.obs`` is the observation."""
        self.observer = Observer(cfg.observation, n, N_RAYS, OBS_SIZE, spec.ee_step)
        self.privileged = np.zeros((n, PER_SPHERE * len(self.spheres.frame) if cfg.observation.privileged else 0))
        """A teacher's values after the observer's (``rayreach.sim.batch_clearance``); none without."""
        self._all = np.arange(n)
        self._actions = np.zeros((n, 6))
        self._fixed_start: np.ndarray | None = None
        self.stage_seconds = dict.fromkeys(STAGES, 0.0)
        """Seconds spent in each stage of ``step_wait`` so far (a few perf_counter calls a step)."""
        if fixed is not None:
            self._load_fixed(fixed)
        super().__init__(n, self._space(self.observer.space(observation_space(spec, ws_high - ws_low))),
                         gym.spaces.Box(-1.0, 1.0, (6,), np.float32))
        if seed is not None:
            self.seed(seed)

    def _space(self, observed: gym.spaces.Box) -> gym.spaces.Box:
        """``observed`` with the privileged values' bounds after it, where there are any."""
        k = self.privileged.shape[1] // PER_SPHERE
        if not k:
            return observed
        bound = np.tile(np.r_[np.ones(3), np.full(3, 1.0 / SPEED_SCALE)], k).astype(np.float32)
        return gym.spaces.Box(np.r_[observed.low, -bound], np.r_[observed.high, bound], dtype=np.float32)

    def _obs(self) -> np.ndarray:
        """Every world's observation now: the observer's, then the privileged values."""
        if not self.privileged.shape[1]:
            return self.observer.obs.copy()
        return np.concatenate((self.observer.obs, self.privileged.astype(np.float32)), axis=1)

    def _load_fixed(self, scenario: Scenario) -> None:
        self._fixed_start = q_start = solve_start(scenario, self.kin)
        scene = Scene(self.spec_robot, scenario.base_position, scenario.base_rpy)
        try:
            scene.set_obstacles(scenario.obstacles)
            validate(scenario, self.kin, scene, q_start)
        finally:
            scene.close()
        for i in range(len(self.q)):
            self._set_world(i, scenario)  # first: it names the shapes a batched world can hold
            self.collision.set_world(i, scenario.obstacles)

    def _set_world(self, i: int, scenario: Scenario) -> None:
        """World ``i``'s scenario into the arrays (``CollisionWorlds`` has its obstacles)."""
        self.obstacles.set_world(i, scenario.obstacles)
        goals = np.asarray(scenario.goals, dtype=float)
        if len(goals) > self.goals.shape[1]:
            grown = np.zeros((len(self.q), len(goals), 3))
            grown[:, : self.goals.shape[1]] = self.goals
            self.goals = grown
        self.goals[i, : len(goals)] = goals
        self.n_goals[i] = len(goals)
        self._scenarios[i] = scenario
        self.ws_low[i] = scenario.workspace_low
        self.ws_high[i] = scenario.workspace_high

    # ------------------------------------------------------------------ curricula
    def set_goal_tolerance(self, tolerance: float, indices: VecEnvIndices = None) -> None:
        """The success radius from each world's next episode on (goal-size curriculum)."""
        if not tolerance > 0:
            raise ValueError(f"goal_tolerance must be positive, got {tolerance}")
        self.goal_tolerance[list(self._get_indices(indices))] = float(tolerance)

    def set_n_obstacles(self, n: int, indices: VecEnvIndices = None) -> None:
        """Obstacles per random world from each world's next reset on (obstacle curriculum)."""
        if n < 0:
            raise ValueError(f"n_obstacles must be >= 0, got {n}")
        self.n_obstacles[list(self._get_indices(indices))] = int(n)

    # ------------------------------------------------------------------ VecEnv API
    def reset(self) -> np.ndarray:
        for i in range(self.num_envs):
            if self._seeds[i] is not None or self.rngs[i] is None:
                self.rngs[i], _ = seeding.np_random(self._seeds[i])
            self.reset_world(i)
        self._reset_seeds()
        self._reset_options()
        return self._obs()

    def reset_world(self, i: int) -> None:
        """``ReachEnv.reset`` for world ``i``, its observation written into ``observer.obs[i]``."""
        cfg = self.config
        rng = self.rngs[i]
        assert rng is not None
        if self.random:
            scenario, q_start = self.samplers[i].sample(rng, int(self.n_obstacles[i]))
            self._set_world(i, scenario)
        else:
            assert self._fixed_start is not None
            q_start = self._fixed_start
            for rows in (self.obstacles.boxes, self.obstacles.spheres):
                rows.pos[i] = rows.start[i]
        share = cfg.true_goal_share if self.random else 0.0
        self.true_goal_episode[i] = share > 0 and bool(rng.random() < share)
        self.tolerance[i] = cfg.true_goal_tolerance if self.true_goal_episode[i] else self.goal_tolerance[i]
        self.q[i] = q_start
        self.frames[i] = self.kin.frames(self.q[i])
        ee = self.kin.ee_from_frames(self.frames[i])
        self.ee_pos[i], self.ee_rot[i] = ee[:3, 3], ee[:3, :3]
        self.ref_rot_t[i] = self.ee_rot[i].T
        self.goal_index[i] = 0
        self.steps[i] = 0
        self.time[i] = 0.0
        self.shake_length[i] = 0
        self.episode_terms[i] = 0.0
        self.previous_distance[i] = float(np.linalg.norm(self.goals[i, 0] - self.ee_pos[i]))
        which = np.array([i])
        self.previous_way[i] = self._ways(which, self.previous_distance)[0]
        self._cast(which)
        self._observe(which, self.previous_distance)
        self.observer.reset(which, *self._observer_args(which))
        self._sense_privileged(which)

    def step_async(self, actions: np.ndarray) -> None:
        a = np.asarray(actions, dtype=float).reshape(self.num_envs, -1)
        if a.shape[1] != 6:
            raise ValueError(f"actions must be ({self.num_envs}, 6) (dx, dy, dz, droll, dpitch, dyaw), "
                             f"got shape {np.shape(actions)}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"actions of worlds {np.flatnonzero(~np.isfinite(a).all(axis=1)).tolist()} "
                             "contain NaN or infinity")
        np.multiply(np.clip(a, -1.0, 1.0), self.step_scale, out=self._actions)

    def step_wait(self):
        cfg, w = self.config, self.config.rewards
        clock = _Clock(self.stage_seconds)
        solve_steps(self.kin, cfg.ik, self._actions, self.q, self.frames, self.ee_pos, self.ee_rot,
                    self.converged)
        clock.lap("ik")
        self.steps += 1
        self.time = self.steps * cfg.control_period
        if self.obstacles.moving.any():
            self.obstacles.at_time(self.time)
        clock.lap("obstacles")
        collided = np.zeros(self.num_envs, dtype=bool)
        near = np.flatnonzero(candidates(self.frames, self.spheres, self.obstacles, MARGIN + cfg.collision_margin))
        clock.lap("collision_spheres")
        for i in near:
            collided[i] = self.collision.in_collision(int(i), self.q[i], float(self.time[i]), self.frames[i],
                                                      cfg.collision_margin)
        clock.lap("collision_bullet")
        outside = ~((self.ee_pos >= self.ws_low) & (self.ee_pos <= self.ws_high)).all(axis=1)
        distance = _distances(self.goals[self._all, self.goal_index] - self.ee_pos)
        way = self._ways(self._all, distance, new_goal=False)
        reached = distance < self.tolerance
        n_shakes = _shake(self.shake_queue, self.shake_length, distance, SHAKE_WINDOW)
        clock.lap("reward_and_obs")
        self._cast(self._all)
        clock.lap("rays")

        final_goal = self.goal_index == self.n_goals - 1
        success = reached & final_goal & ~collided
        terminated = collided | outside | success
        truncated = ~terminated & (self.steps >= cfg.max_steps)
        terms = np.empty((self.num_envs, len(REWARD_TERM_NAMES)))  # REWARD_TERM_NAMES order
        terms[:, 0] = np.where(collided, 0.0, np.where(reached, w.success, 0.0))
        terms[:, 1] = np.where(collided, w.collision, 0.0)
        terms[:, 2] = w.distance * distance
        terms[:, 3] = w.shaking * n_shakes
        terms[:, 4] = np.where(outside, w.out_of_bounds, 0.0)
        terms[:, 5] = np.where(truncated, w.exhausted, 0.0)
        with np.errstate(invalid="ignore"):  # inf - inf: a step next to an obstacle counts nothing
            progress = self.previous_way - way
        terms[:, 6] = w.progress * np.where(np.isfinite(progress), progress, 0.0)
        terms[:, 7] = w.proximity * np.maximum(0.0, 1.0 - self.fractions.min(axis=1) / w.proximity_range)
        rewards = terms[:, 0].copy()
        for k in range(1, terms.shape[1]):  # summed in ReachEnv's order
            rewards += terms[:, k]
        self.episode_terms += terms

        switch = np.flatnonzero(reached & ~final_goal)
        if len(switch):
            self.goal_index[switch] += 1
            self.shake_length[switch] = 0
            distance[switch] = _distances(self.goals[switch, self.goal_index[switch]] - self.ee_pos[switch])
            way[switch] = self._ways(switch, distance, new_goal=True)
        self.previous_distance = distance
        self.previous_way = way
        self._observe(self._all, distance)
        self.observer.step(self._all, *self._observer_args(self._all))
        self._sense_privileged(self._all)
        obs = self._obs()

        dones = terminated | truncated
        clock.lap("reward_and_obs")
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(dones):
            infos[i] = {
                "reward_terms": dict(zip(REWARD_TERM_NAMES, terms[i].tolist())),
                "episode_reward_terms": dict(zip(REWARD_TERM_NAMES, self.episode_terms[i].tolist())),
                "distance": float(distance[i]),
                "is_success": bool(success[i]),
                "collision": bool(collided[i]),
                "out_of_bounds": bool(outside[i]),
                "goal_reached": bool(reached[i]),
                "goal_tolerance": float(self.tolerance[i]),
                "true_goal_episode": bool(self.true_goal_episode[i]),
                "goal_index": int(self.goal_index[i]),
                "ee_position": self.ee_pos[i].copy(),
                "goal": self.goals[i, self.goal_index[i]].copy(),
                "ik_converged": bool(self.converged[i]),
                "n_shakes": int(n_shakes[i]),
                "time": float(self.time[i]),
                "TimeLimit.truncated": bool(truncated[i]),
                "terminal_observation": obs[i].copy(),
            }
            self.reset_world(int(i))
        if dones.any():
            obs = self._obs()  # the reset worlds' first observation
        clock.lap("resets")
        return obs, rewards.astype(np.float32), dones, infos

    def _ways(self, which: np.ndarray, distance: np.ndarray, new_goal: bool = True) -> np.ndarray:
        """What the progress term measures for worlds ``which``: the way round the obstacles to
        the current goal (a field built first where ``new_goal``), or ``distance[which]``."""
        if self.fields is None:
            return distance[which]
        if new_goal:
            for i in which:
                self.fields.set_world(int(i), self._goal_field(int(i)))
        return self.fields.distances(self.ee_pos[which], which)

    def _goal_field(self, i: int) -> GoalField:
        index = int(self.goal_index[i])
        if self.random:
            return scenario_field(self._scenarios[i], index)  # type: ignore[arg-type]
        if index not in self._fixed_fields:  # one scenario for all worlds: each goal's field once
            self._fixed_fields[index] = scenario_field(self._scenarios[i], index)  # type: ignore[arg-type]
        return self._fixed_fields[index]

    @property
    def scenarios(self) -> list[Scenario]:
        """Each world's current scenario (drawn at its last reset, or the fixed one)."""
        return [s for s in self._scenarios if s is not None]

    def _cast(self, which: np.ndarray) -> None:
        """Worlds ``which``'s ray fractions (and those of the rays beyond the 129, where the observation has them)."""
        cfg = self.config
        cast_worlds(self.layout, self.frames, self.obstacles, cfg.ray_range, which, self.fractions)
        if self.extra_layout is not None:
            cast_worlds(self.extra_layout, self.frames, self.obstacles, cfg.ray_range, which, self.extra_fractions)

    def _sense_privileged(self, which: np.ndarray) -> None:
        if self.privileged.shape[1]:
            clearance(self.frames, self.spheres, self.obstacles, self.time, self.ee_rot, which, self.privileged)

    def _observer_args(self, which: np.ndarray) -> tuple:
        """Worlds ``which``'s rows of ``Observer.reset``'s and ``step``'s arguments after ``which``."""
        extra = self.extra_fractions[which] if self.extra_layout is not None else None
        nearest = self._nearest(which) if self.observer.config.sightings else None
        goal_clear = self.goal_clear(which) if self.observer.config.goal_sight else None
        return (self.base_obs[which], self.ee_pos[which], self.fractions[which], self.ws_low[which],
                self.ws_high[which], extra, nearest, goal_clear)

    def goal_clear(self, which: np.ndarray) -> np.ndarray:
        """Worlds ``which``'s goal rays' fractions now (``rayreach.sim.goal_rays``), (k, 3), whether or
        not the observation holds them."""
        n = self.num_envs
        origins, directions, lengths = np.zeros((n, N_GOAL_RAYS, 3)), np.zeros((n, N_GOAL_RAYS, 3)), np.ones(n)
        origins[which], directions[which], lengths[which] = goal_rays(
            self.ee_pos[which], self.ee_rot[which, :, 2], self.goals[which, self.goal_index[which]],
            self.spec_robot.tool.length)
        fractions = np.ones((n, N_GOAL_RAYS))
        cast_given(origins, directions, lengths, self.obstacles, which, fractions)
        return fractions[which]

    def _nearest(self, which: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Worlds ``which``'s nearest sightings over the 129 and the fixed rays beyond them the policy
        reads, not the goal rays (``rayreach.env.observation.nearest_sightings``), placing only the
        nearest ray of each."""
        fractions = self.fractions[which]
        if self.extra_layout is not None:
            fractions = np.concatenate((fractions, self.extra_fractions[which]), axis=1)
        best = nearest_ray(fractions)
        fraction = fractions[np.arange(len(which)), best]
        origins, directions = np.empty((len(which), 3)), np.empty((len(which), 3))
        paper = best < N_RAYS
        origins[paper], directions[paper] = place_rays(self.layout, self.frames, which[paper], best[paper])
        if self.extra_layout is not None:
            origins[~paper], directions[~paper] = place_rays(self.extra_layout, self.frames, which[~paper],
                                                             best[~paper] - N_RAYS)
        return nearest_sightings(fraction[:, None], origins[:, None], directions[:, None], self.config.ray_range)

    def _observe(self, which: np.ndarray, distance: np.ndarray) -> None:
        """The paper's 142 values of worlds ``which`` into ``base_obs``."""
        obs = self.base_obs
        obs[which, 0:6] = self.q[which]
        obs[which, 6:9] = self.goals[which, self.goal_index[which]] - self.ee_pos[which]
        obs[which, 9:12] = _rpy(np.matmul(self.ref_rot_t[which], self.ee_rot[which]))
        obs[which, 12] = distance[which]
        obs[which, N_ROBOT_OBS:] = self.fractions[which]

    def close(self) -> None:
        self.collision.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """Per world: a row of the per-world arrays (``n_obstacles``, ``goal_tolerance``, ...),
        else the env's own attribute, which all worlds share."""
        value = getattr(self, attr_name)
        per_world = isinstance(value, np.ndarray) and value.shape[:1] == (self.num_envs,)
        return [value[i] if per_world else value for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"BatchedReachEnv sets no attribute '{attr_name}' per world; its per-world "
                             f"setters are env_method's {', '.join(ENV_METHODS)}")

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None,
                   **method_kwargs) -> list[Any]:
        if method_name not in ENV_METHODS:
            raise AttributeError(f"BatchedReachEnv has no per-world method '{method_name}'; "
                                 f"it has {', '.join(ENV_METHODS)}")
        getattr(self, method_name)(*method_args, indices=indices, **method_kwargs)
        return [None for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]


class _Clock:
    """Adds the seconds since the last lap to a stage's total."""

    def __init__(self, totals: dict[str, float]) -> None:
        self.totals = totals
        self.last = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.totals[stage] += now - self.last
        self.last = now


def _distances(offsets: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("ij,ij->i", offsets, offsets))


def _rpy(rot: np.ndarray) -> np.ndarray:
    """``transforms.matrix_to_rpy`` of each of ``rot`` (n, 3, 3)."""
    sin_pitch = -rot[:, 2, 0]
    pitch = np.arcsin(np.clip(sin_pitch, -1.0, 1.0))
    locked = np.abs(rot[:, 2, 0]) >= 1.0 - 1e-12
    roll = np.where(locked, 0.0, np.arctan2(rot[:, 2, 1], rot[:, 2, 2]))
    yaw = np.where(locked, np.arctan2(-rot[:, 0, 1], rot[:, 1, 1]), np.arctan2(rot[:, 1, 0], rot[:, 0, 0]))
    return np.stack((roll, pitch, yaw), axis=1)


@numba.njit(cache=True)
def _shake(queue, length, distance, window):  # pragma: no cover - compiled
    """``ShakeCounter.update`` for every world: n_s after appending ``distance``."""
    out = np.zeros(len(distance), dtype=np.int64)
    for w in range(len(distance)):
        if length[w] > window:
            for k in range(length[w] - 1):
                queue[w, k] = queue[w, k + 1]
            length[w] -= 1
        queue[w, length[w]] = distance[w]
        length[w] += 1
        count = 0
        previous = -1
        for k in range(length[w] - 1):
            label = 0 if queue[w, k + 1] - queue[w, k] >= 0 else 1
            if previous >= 0 and label != previous:
                count += 1
            previous = label
        out[w] = count
    return out
