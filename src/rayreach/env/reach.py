"""The Gymnasium environment of the paper: reach a goal, seeing obstacles only through 129 rays.

## Action space

``Box(-1, 1, (6,), float32)``: an end-effector pose step in the world frame. ``a[0:3]`` times
``ee_step`` (0.005 m) is the translation; ``a[3:6]`` times ``rot_step`` (0.005 rad) is a
rotation about the world x, y and z axes (roll, pitch, yaw increments), applied to the
current tool orientation. The stepped pose becomes joint angles through damped-least-squares
IK (paper Algorithm 1); the robot moves to them at once (a kinematic arm, as in the paper).
A NaN or infinite action raises ``ValueError`` and changes nothing.

## Observation space

``Box(142,) float32``, in this order:

=======  ====================================================================
0-5      joint angles, rad
6-8      goal position minus end-effector position, m (world frame)
9-11     end-effector orientation as roll, pitch, yaw of R_ref^T R, rad, where
         R_ref is the tool orientation at the episode start: zero at the start
         and continuous, unlike raw Euler angles of a tool pointing down,
         whose roll jumps between +pi and -pi
12       distance from end effector to goal, m
13-141   the 129 ray hit fractions in [0, 1] (order: ``rayreach.sim.sensors``)
=======  ====================================================================

``EnvConfig.observation`` may append more (``rayreach.env.observation``: the goal's
direction, the workspace's walls, the arm's motion, remembered scans); the default is the
paper's 142 values alone.

## Rewards (paper eq. "total reward"), episode end

success +10 when the distance is below ``goal_tolerance`` (the episode ends at the last goal;
earlier goals of a sequence switch to the next one), collision -10 (ends), distance
-0.01 d, leaving the workspace -10 (ends), step budget ``max_steps`` used up -5 (truncated),
shaking -0.005 n_s; plus optional progress and proximity terms for training (weight 0 by
default, as in the paper).
``info`` carries every term (``reward_terms``), ``distance``,
``is_success``, ``collision``, ``out_of_bounds``, ``ee_position`` and ``goal``; an episode's
last ``info`` also sums each term over the episode (``episode_reward_terms``).

## Acting from outside

Nothing here is outside the paper's MDP. The layers that act between a policy and the arm
(``rayreach.acting``) wrap this environment and use three parts of a step on their own:
``perceive()`` (what the rays see, once per step), ``solve(delta)`` (the IK step, without
taking it) and ``advance(ik, taken)`` (the rest of the step, with the solution taken or
the arm held); ``step(action)`` is the three in a row.

## Time

Each step is one control period (``control_period``, default 1/240 s, PyBullet's default
step); moving obstacles advance by that much per step.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from rayreach.env import rewards as R
from rayreach.env.goal_field import GoalField, scenario_field
from rayreach.env.observation import (N_ROBOT_OBS, OBS_SIZE, ONE_WORLD, ObservationConfig,  # noqa: F401
                                      Observer, one_world_sighting, paper_observation)
from rayreach.env.perception import Perception
from rayreach.robots import ROBOTS, RobotSpec, get_robot
from rayreach.scenarios import RANDOM, WORLD_SUITES, Scenario, ScenarioError, get_scenario
from rayreach.scenarios.feasibility import solve_start, validate
from rayreach.scenarios.random_world import RandomWorldConfig
from rayreach.scenarios.suites import suite_workspace, world_sampler
from rayreach.sim.goal_rays import goal_rays
from rayreach.sim.kinematics import STEP_IK, IKParams, IKResult, Kinematics
from rayreach.sim.scene import Scene
from rayreach.sim.sensors import N_RAYS, RAY_RANGE, RayModel

REWARD_TERM_NAMES = ("success", "collision", "distance", "shaking", "out_of_bounds", "exhausted", "progress",
                     "proximity")
"""The reward terms of a step, in the order they are summed (``info["reward_terms"]``)."""


@dataclass(frozen=True)
class EnvConfig:
    """Everything that shapes an episode; the paper's values are the defaults."""

    goal_tolerance: float = 0.01
    """Success radius, m (the paper's final target size; the training curriculum changes it)."""
    true_goal_share: float = 0.0
    """Share of random-world episodes played at ``true_goal_tolerance`` whatever
    ``goal_tolerance`` the curriculum set (training: the policy keeps practising the last
    centimetre while the goal is enlarged); 0 for fixed scenarios and evaluation."""
    true_goal_tolerance: float = 0.01
    max_steps: int = 1024
    """Step budget per episode."""
    control_period: float = 1.0 / 240.0
    """Simulated seconds per step (moving obstacles advance this much)."""
    ray_backend: str = "auto"
    """``auto`` (numpy when every obstacle is a primitive), ``numpy`` or ``bullet``."""
    ray_range: float = RAY_RANGE
    ik: IKParams = STEP_IK
    """IK per step (``info["ik_converged"]`` tells whether it met its tolerance)."""
    rewards: R.RewardWeights = R.RewardWeights()
    random_world: RandomWorldConfig = field(default_factory=RandomWorldConfig)
    observation: ObservationConfig = ObservationConfig()
    """Parts of the observation beyond the paper's 142 values (``rayreach.env.observation``;
    the default: none, the paper's observation)."""
    collision_margin: float = 0.0
    """Distance, m, within which the robot coming to an obstacle counts as a collision (not in
    the paper; training only): 0, a penetration. A margin makes grazing a moving plate fail
    in training as touching it does, where it would have passed a few millimetres before."""

    def __post_init__(self) -> None:
        if not self.goal_tolerance > 0:
            raise ValueError(f"goal_tolerance must be positive, got {self.goal_tolerance}")
        if not 0.0 <= self.true_goal_share <= 1.0:
            raise ValueError(f"true_goal_share must be in [0, 1], got {self.true_goal_share}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if not self.control_period > 0:
            raise ValueError(f"control_period must be positive, got {self.control_period}")
        if not 0.0 <= self.collision_margin < 0.1:
            raise ValueError(f"collision_margin must be in [0, 0.1) m, got {self.collision_margin}")



OUTCOMES = ("success", "collision", "out_of_bounds", "timeout")
"""How an episode can end (``episode_outcome``)."""


def episode_outcome(info: dict[str, Any]) -> str:
    """One of ``OUTCOMES`` from an episode's last ``info`` (a goal reached in contact is a
    collision; ``timeout``: the step budget ran out)."""
    return ("success" if info.get("is_success") else "collision" if info.get("collision")
            else "out_of_bounds" if info.get("out_of_bounds") else "timeout")


def observation_space(spec: RobotSpec, workspace_size: np.ndarray) -> gym.spaces.Box:
    """Finite bounds: joint limits; the goal offset and distance within the workspace (plus
    the one step that may leave it); Euler angles; ray fractions in [0, 1]."""
    reach = workspace_size + 2 * spec.ee_step
    low = np.concatenate((spec.lower_array, -reach, [-np.pi, -np.pi / 2, -np.pi], [0.0], np.zeros(N_RAYS)))
    high = np.concatenate(
        (spec.upper_array, reach, [np.pi, np.pi / 2, np.pi], [np.linalg.norm(reach)], np.ones(N_RAYS))
    )
    return gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)


def make_config(config: EnvConfig | None, overrides: dict[str, Any]) -> EnvConfig:
    """``config`` with keyword overrides; unknown keys name the valid ones."""
    base = config or EnvConfig()
    valid = {f.name for f in fields(EnvConfig)}
    unknown = sorted(set(overrides) - valid)
    if unknown:
        raise TypeError(f"unknown environment option(s) {unknown}; valid: {', '.join(sorted(valid))}")
    return replace(base, **overrides)


def resolve_task(robot: str | RobotSpec | None, scenario: str | Path | Scenario) -> tuple[RobotSpec, Scenario | None]:
    """The robot and the fixed scenario (None for a suite of drawn worlds, ``WORLD_SUITES``)
    an environment is made for; the robot may be left out where the scenario names it."""
    fixed = None if isinstance(scenario, str) and scenario in WORLD_SUITES else get_scenario(scenario)
    if robot is None:
        if fixed is None:
            raise ValueError(f"an environment of {scenario} worlds needs a robot ({', '.join(ROBOTS)})")
        robot = fixed.robot
    spec = get_robot(robot)
    if fixed is not None and fixed.robot != spec.name:
        raise ScenarioError(f"scenario '{fixed.name}' is for robot '{fixed.robot}', not '{spec.name}'")
    return spec, fixed


class ReachEnv(gym.Env):
    """Reach one goal (or a sequence) with a UR5 or KR16; see the module docstring."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 30}

    def __init__(
        self,
        robot: str | RobotSpec | None = None,
        scenario: str | Path | Scenario = RANDOM,
        render_mode: str | None = None,
        config: EnvConfig | None = None,
        **overrides: Any,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unknown render_mode '{render_mode}'; valid: {self.metadata['render_modes']}")
        self.config = make_config(config, overrides)
        self.render_mode = render_mode
        self.spec_robot, fixed = resolve_task(robot, scenario)
        self.random = fixed is None
        base_pos = fixed.base_position if fixed else None
        base_rpy = fixed.base_rpy if fixed else None
        self.kin = Kinematics(self.spec_robot, base_pos, base_rpy)
        self.scene = Scene(self.spec_robot, base_pos, base_rpy, gui=render_mode == "human")
        self.rays = RayModel(self.spec_robot, self.config.ray_range)
        self.suite = str(scenario) if self.random else None
        """``random`` or ``broad`` (``WORLD_SUITES``) where worlds are drawn at reset."""
        self.worlds = (world_sampler(self.suite, self.kin, self.scene, self.config.random_world)
                       if self.suite else None)
        self.n_obstacles = self.config.random_world.n_obstacles

        self.action_space = gym.spaces.Box(-1.0, 1.0, (6,), dtype=np.float32)
        ws_low, ws_high = ((np.asarray(fixed.workspace_low), np.asarray(fixed.workspace_high)) if fixed
                           else suite_workspace(self.suite, self.spec_robot))
        self._paper_space = observation_space(self.spec_robot, ws_high - ws_low)
        self.set_observation(self.config.observation)
        self.step_scale = np.array([self.spec_robot.ee_step] * 3 + [self.spec_robot.rot_step] * 3)
        """Metres and radians per unit of action: an action times this is the pose step."""

        self.scenario: Scenario | None = None
        self._fixed_start: np.ndarray | None = None
        if fixed is not None:
            self._load_fixed(fixed)
        self._shake = R.ShakeCounter()
        self._fields: dict[int, GoalField] = {}
        """The fixed scenario's goal fields by goal index (random worlds: this episode's)."""
        self._field: GoalField | None = None
        self._previous_way = 0.0
        self._ready = False
        self.episodes = 0
        """Resets so far (a wrapper acting on the env tells its own episode from another's)."""

    # ------------------------------------------------------------------ setup
    def _load_fixed(self, scenario: Scenario) -> None:
        q_start = solve_start(scenario, self.kin)
        self.scene.set_obstacles(scenario.obstacles)
        validate(scenario, self.kin, self.scene, q_start)
        self.scenario = scenario
        self._fixed_start = q_start
        self.caster = self.scene.caster(self.config.ray_backend)
        self.scene.set_goal_markers(scenario.goals)

    def set_goal_tolerance(self, tolerance: float) -> None:
        """Change the success radius (used by the goal-size curriculum between episodes)."""
        self.config = make_config(self.config, {"goal_tolerance": float(tolerance)})

    def set_observation(self, observation: ObservationConfig) -> None:
        """What the observation holds from the next reset on (a policy's ``observation``)."""
        if observation.privileged:
            raise ValueError("the privileged observation (a teacher's, ObservationConfig.privileged) is computed by "
                             "BatchedReachEnv only; step a teacher there, or use its student's observation "
                             "(ObservationConfig.deployable)")
        self.config = make_config(self.config, {"observation": observation})
        self.observer = Observer(observation, 1, N_RAYS, OBS_SIZE, self.spec_robot.ee_step)
        self.observation_space = self.observer.space(self._paper_space)
        self._extra = RayModel.extra(self.spec_robot, self.config.ray_range, observation.ray_sets)
        self._ready = False

    def set_n_obstacles(self, n: int) -> None:
        """Obstacles per random world from the next reset on (obstacle curriculum)."""
        if n < 0:
            raise ValueError(f"n_obstacles must be >= 0, got {n}")
        self.n_obstacles = int(n)

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if self.random:
            assert self.worlds is not None
            scenario, q_start = self.worlds.sample(self.np_random, self.n_obstacles)
            self.scenario = scenario
            self._fields = {}
            self.caster = self.scene.caster(self.config.ray_backend)
            self.scene.set_goal_markers(scenario.goals)
        else:
            assert self._fixed_start is not None
            q_start = self._fixed_start
        share = self.config.true_goal_share if self.random else 0.0
        self.true_goal_episode = share > 0 and bool(self.np_random.random() < share)
        self.tolerance = self.config.true_goal_tolerance if self.true_goal_episode else self.config.goal_tolerance
        self.scene.set_time(0.0)
        self.q = np.array(q_start, dtype=float)
        self.scene.set_joints(self.q)
        self.frames = self.kin.frames(self.q)
        ee = self.kin.ee_from_frames(self.frames)
        self.ee_pos, self.ee_rot = ee[:3, 3].copy(), ee[:3, :3].copy()
        self.ref_rot_t = self.ee_rot.T.copy()
        self.goal_index = 0
        self.goals = np.asarray(self.scenario.goals, dtype=float)  # type: ignore[union-attr]
        self.steps = 0
        self.time = 0.0
        self._shake.reset()
        self._episode_terms = dict.fromkeys(REWARD_TERM_NAMES, 0.0)
        self._ready = True
        distance = float(np.linalg.norm(self.goals[0] - self.ee_pos))
        self._field = self._goal_field(0)
        self._previous_way = self._way(distance)
        self.episodes += 1
        info = {"distance": distance, "ee_position": self.ee_pos.copy(), "goal": self.goals[0].copy(),
                "goal_index": 0, "is_success": False, "collision": False, "out_of_bounds": False}
        rays = self._cast_rays()
        self.observer.reset(*self._observer_args(distance, rays))
        return self.observer.obs[0].copy(), info

    def step(self, action: np.ndarray):
        """The paper's step: the pose step ``action`` (times ``step_scale``) solved by IK and taken."""
        a = self.check_action(action)
        ik = self.solve(np.clip(a, -1.0, 1.0) * self.step_scale)
        return self.advance(ik, taken=True)

    def check_action(self, action: np.ndarray) -> np.ndarray:
        """``action`` as a float array of 6, after ``reset``; a clear error for anything else."""
        if not self._ready:
            raise RuntimeError("call reset() before step() (and after an episode ends)")
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (6,):
            raise ValueError(f"action must have 6 values (dx, dy, dz, droll, dpitch, dyaw), got shape {np.shape(action)}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action contains NaN or infinity: {a.tolist()}; the scene is unchanged")
        return a

    def solve(self, delta: np.ndarray, keep_orientation: bool = True) -> IKResult:
        """DLS IK (Algorithm 1) for the end-effector step ``delta`` (dx, dy, dz in m, then a
        rotation vector in rad) from where the arm is; ``keep_orientation`` False solves for
        the position only. Nothing moves."""
        return self.kin.step_ik(delta, self.q, self.frames, self.ee_pos, self.ee_rot, self.config.ik, keep_orientation)

    def tool_pose(self, ik: IKResult) -> np.ndarray:
        """The end effector's 4 x 4 pose where ``ik``'s solution puts it."""
        return self.kin.ee_from_frames(ik.frames)

    def advance(self, ik: IKResult, taken: bool = True):
        """The rest of a step: the arm moves to ``ik``'s solution if ``taken`` (else it holds
        still), time passes one control period, then collision, workspace, goal, reward and
        the new observation, as ``step`` returns them."""
        cfg = self.config
        w = cfg.rewards
        if taken:
            ee = self.kin.ee_from_frames(ik.frames)
            self.q, self.frames = ik.q, ik.frames
            self.ee_pos, self.ee_rot = ee[:3, 3], ee[:3, :3]

        self.steps += 1
        self.time = self.steps * cfg.control_period
        if self.scene.has_moving_obstacles:
            self.scene.set_time(self.time)
        self.scene.set_joints(self.q)
        collided = self.scene.in_collision(cfg.collision_margin)
        outside = not self.scenario.in_workspace(self.ee_pos)  # type: ignore[union-attr]

        goal = self.goals[self.goal_index]
        distance = float(np.linalg.norm(goal - self.ee_pos))
        reached = distance < self.tolerance
        n_shakes = self._shake.update(distance)
        rays = self._cast_rays()
        way = self._way(distance)
        terms = {
            "success": 0.0 if collided else R.success_reward(distance, self.tolerance, w),
            "collision": R.collision_reward(collided, w),
            "distance": R.distance_reward(distance, w),
            "shaking": R.shaking_reward(n_shakes, w),
            "out_of_bounds": R.out_of_bounds_reward(outside, w),
            "exhausted": 0.0,
            "progress": R.progress_reward(self._previous_way, way, w),
            "proximity": R.proximity_reward(float(rays.min()), w),
        }
        final_goal = self.goal_index == len(self.goals) - 1
        success = reached and final_goal and not collided  # a goal reached in contact is no success
        terminated = collided or outside or success
        truncated = not terminated and self.steps >= cfg.max_steps
        if truncated:
            terms["exhausted"] = R.exhausted_reward(True, w)
        if reached and not final_goal:
            self.goal_index += 1
            self._shake.reset()
            distance = float(np.linalg.norm(self.goals[self.goal_index] - self.ee_pos))
            self._field = self._goal_field(self.goal_index)
            way = self._way(distance)
        self._previous_way = way
        for key, value in terms.items():
            self._episode_terms[key] += value
        info = {
            "reward_terms": terms,
            "distance": distance,
            "is_success": success,
            "collision": collided,
            "out_of_bounds": outside,
            "goal_reached": reached,
            "goal_tolerance": self.tolerance,
            "true_goal_episode": self.true_goal_episode,
            "goal_index": self.goal_index,
            "ee_position": self.ee_pos.copy(),
            "goal": self.goals[self.goal_index].copy(),
            "ik_converged": ik.converged,
            "n_shakes": n_shakes,
            "time": self.time,
        }
        if terminated or truncated:
            self._ready = False
            info["episode_reward_terms"] = dict(self._episode_terms)
        self.observer.step(*self._observer_args(distance, rays))
        return self.observer.obs[0].copy(), float(sum(terms.values())), terminated, truncated, info

    def _goal_field(self, index: int) -> GoalField | None:
        """Goal ``index``'s field where the progress term goes round obstacles, else None."""
        if not self.config.rewards.progress_around_obstacles:
            return None
        if index not in self._fields:
            self._fields[index] = scenario_field(self.scenario, index)  # type: ignore[arg-type]
        return self._fields[index]

    def _way(self, distance: float) -> float:
        """What the progress term measures: the way round the obstacles, or ``distance``."""
        return self._field.distance(self.ee_pos) if self._field is not None else distance

    def _cast_rays(self) -> np.ndarray:
        """Hit fractions of the rays in the current state (kept, with the rays and how far
        each sees in metres, for ``perceive``)."""
        self._ray_origins, self._ray_directions = self.rays.world_rays(self.frames)
        self._ray_fractions = self.caster.cast(self._ray_origins, self._ray_directions, self.config.ray_range)
        self._ray_lengths = self._ray_fractions * self.config.ray_range  # the range where nothing is seen
        if self._extra is not None:
            self._extra_rays = self._extra.world_rays(self.frames)
            self._extra_fractions = self.caster.cast(*self._extra_rays, self.config.ray_range)
        return self._ray_fractions

    def perceive(self) -> Perception:
        """What the arm senses now, for layers acting from outside: the last observation's
        rays in the world (no new cast), the pose, the goal and the workspace."""
        scenario = self.scenario
        return Perception(step=self.steps, q=self.q, ee_position=self.ee_pos, ee_rotation=self.ee_rot,
                          goal=self.goals[self.goal_index], origins=self._ray_origins,
                          directions=self._ray_directions, lengths=self._ray_lengths, fractions=self._ray_fractions,
                          workspace_low=np.asarray(scenario.workspace_low),  # type: ignore[union-attr]
                          workspace_high=np.asarray(scenario.workspace_high))  # type: ignore[union-attr]

    def _observer_args(self, distance: float, rays: np.ndarray) -> tuple:
        """This world's row of ``Observer.reset``'s and ``step``'s arguments."""
        scenario = self.scenario
        assert scenario is not None
        extra = self._extra_fractions[None] if self._extra is not None else None
        nearest = None
        if self.observer.config.sightings:  # over the fixed layouts the policy reads, not the goal rays
            beyond = [(*self._extra_rays, self._extra_fractions)] if self._extra is not None else []
            nearest = one_world_sighting(self.config.ray_range, (self._ray_origins, self._ray_directions, rays),
                                         *beyond)
        goal_clear = self._goal_clear()[None] if self.observer.config.goal_sight else None
        return (ONE_WORLD, self._observation(distance, rays)[None], self.ee_pos[None], rays[None],
                np.asarray(scenario.workspace_low)[None], np.asarray(scenario.workspace_high)[None], extra, nearest,
                goal_clear)

    def _goal_clear(self) -> np.ndarray:
        """The goal rays' fractions now (``rayreach.sim.goal_rays``), (3,)."""
        origins, directions, lengths = goal_rays(self.ee_pos[None], self.ee_rot[None, :, 2],
                                                 self.goals[self.goal_index][None], self.spec_robot.tool.length)
        return self.caster.cast(origins[0], directions[0], float(lengths[0]))

    def _observation(self, distance: float, rays: np.ndarray) -> np.ndarray:
        """The paper's 142 values."""
        return paper_observation(self.q, self.goals[self.goal_index], self.ee_pos, self.ee_rot, self.ref_rot_t,
                                 distance, rays)

    # ------------------------------------------------------------------ rendering
    def render(self):
        if self.render_mode == "rgb_array":
            return self.scene.camera_image(**camera_for(self.scenario))[0]
        return None  # "human": the PyBullet GUI shows the scene live

    def close(self) -> None:
        self.scene.close()


def camera_for(scenario: Scenario | None) -> dict[str, Any]:
    """A camera aimed at the middle of the scenario's workspace, far enough to see it whole."""
    if scenario is None:
        return {}
    low, high = np.asarray(scenario.workspace_low), np.asarray(scenario.workspace_high)
    centre = (low + high) / 2
    return {"target": tuple(centre), "distance": float(max(1.0, 1.25 * np.linalg.norm(high - low)))}
