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
13-141   the 129 ray hit fractions in [0, 1] (order: ``rayreach.sensors``)
=======  ====================================================================

## Rewards (paper eq. "total reward"), episode end

success +10 when the distance is below ``goal_tolerance`` (the episode ends at the last goal;
earlier goals of a sequence switch to the next one), collision -10 (ends), distance
-0.01 d, leaving the workspace -10 (ends), step budget ``max_steps`` used up -5 (truncated),
shaking -0.005 n_s; plus optional progress, proximity and shielded terms for training
(weight 0 by default, as in the paper).
``info`` carries every term (``reward_terms``), ``distance``,
``is_success``, ``collision``, ``out_of_bounds``, ``ee_position`` and ``goal``.

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

from rayreach import rewards as R
from rayreach.arm_guard import ArmCapsules, ArmGuard
from rayreach.detour import Detour, DetourState
from rayreach.kinematics import IKParams, IKResult, Kinematics
from rayreach.policy import FinalApproach
from rayreach.robots import RobotSpec, get_robot
from rayreach.robots.urdf import TOOL_LINK
from rayreach.safety import HitMemory, SafetyLayer
from rayreach.scenarios import RANDOM, Scenario, ScenarioError, get_scenario
from rayreach.scenarios.feasibility import solve_start, validate
from rayreach.scenarios.random_world import RandomWorldConfig, RandomWorlds
from rayreach.scene import Scene
from rayreach.sensors import N_RAYS, RAY_RANGE, RayModel
from rayreach.transforms import matrix_to_rpy, rotvec_to_matrix

N_ROBOT_OBS = 13
OBS_SIZE = N_ROBOT_OBS + N_RAYS


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
    ik: IKParams = IKParams(tolerance=1e-4, max_iterations=10)
    """IK per step: 0.1 mm is ample for a 5 mm step, which one iteration nearly always reaches
    (the damping shrinks for small errors); an unconverged step still moves (``info["ik_converged"]``)."""
    safety: SafetyLayer = SafetyLayer()
    """Not in the paper: what the controller does to an action before the arm moves; off in
    training (unless ``TrainConfig.acting_layers``), ``rayreach.safety.ACTING_SAFETY`` in
    the executor and ``rollout``."""
    final_approach: FinalApproach | None = None
    """Not in the paper: replace the action by the straight step at the goal when
    ``rayreach.policy.FinalApproach`` says so; on in the executor and ``rollout``, off in
    training unless ``TrainConfig.acting_layers``."""
    detour: Detour | None = None
    """Not in the paper: once the policy stalls, follow a path planned round what the rays
    have seen (``rayreach.detour.Detour``); off unless given."""
    rewards: R.RewardWeights = R.RewardWeights()
    random_world: RandomWorldConfig = field(default_factory=RandomWorldConfig)

    def __post_init__(self) -> None:
        if not self.goal_tolerance > 0:
            raise ValueError(f"goal_tolerance must be positive, got {self.goal_tolerance}")
        if not 0.0 <= self.true_goal_share <= 1.0:
            raise ValueError(f"true_goal_share must be in [0, 1], got {self.true_goal_share}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if not self.control_period > 0:
            raise ValueError(f"control_period must be positive, got {self.control_period}")


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
        self.random = isinstance(scenario, str) and scenario == RANDOM
        fixed = None if self.random else get_scenario(scenario)
        if robot is None:
            if fixed is None:
                raise ValueError("a random-world environment needs a robot (ur5 or kr16)")
            robot = fixed.robot
        self.spec_robot = get_robot(robot)
        if fixed is not None and fixed.robot != self.spec_robot.name:
            raise ScenarioError(f"scenario '{fixed.name}' is for robot '{fixed.robot}', not '{self.spec_robot.name}'")
        base_pos = fixed.base_position if fixed else None
        base_rpy = fixed.base_rpy if fixed else None
        self.kin = Kinematics(self.spec_robot, base_pos, base_rpy)
        self.scene = Scene(self.spec_robot, base_pos, base_rpy, gui=render_mode == "human")
        self.rays = RayModel(self.spec_robot, self.config.ray_range)
        self._watched_links = ArmCapsules(self.scene, (*self.spec_robot.blind_links, TOOL_LINK))  # the arm's rule
        self.worlds = RandomWorlds(self.kin, self.scene, self.config.random_world) if self.random else None
        self.n_obstacles = self.config.random_world.n_obstacles

        self.action_space = gym.spaces.Box(-1.0, 1.0, (6,), dtype=np.float32)
        ws_low = np.asarray(fixed.workspace_low if fixed else self.spec_robot.workspace_low)
        ws_high = np.asarray(fixed.workspace_high if fixed else self.spec_robot.workspace_high)
        self.observation_space = observation_space(self.spec_robot, ws_high - ws_low)
        self._step_scale = np.array([self.spec_robot.ee_step] * 3 + [self.spec_robot.rot_step] * 3)
        self.set_final_approach(self.config.final_approach)

        self.scenario: Scenario | None = None
        self._fixed_start: np.ndarray | None = None
        if fixed is not None:
            self._load_fixed(fixed)
        self._shake = R.ShakeCounter()
        self._detour: DetourState | None = None
        self._ready = False

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

    def set_final_approach(self, approach: FinalApproach | None) -> None:
        """Act with ``approach`` (None: the actions as they come) from the next step on."""
        self.config = make_config(self.config, {"final_approach": approach})
        tool = self.spec_robot.tool
        self._final_approach = None if approach is None else replace(
            approach, ee_step=self.spec_robot.ee_step, rot_step=self.spec_robot.rot_step,
            tool_length=tool.length, tool_radius=tool.radius,
            radius=self.spec_robot.final_approach_radius if approach.radius is None else approach.radius,
            axial_radius=(self.spec_robot.final_approach_axial_radius if approach.axial_radius is None
                          else approach.axial_radius))

    def set_detour(self, detour: Detour | None) -> None:
        """Take a stalled policy round what the rays see with ``detour`` (None: never) from the
        next reset on."""
        self.config = make_config(self.config, {"detour": detour})

    def set_safety(self, layer: SafetyLayer) -> None:
        """Pass each action through ``layer`` (``SafetyLayer()``: off) from the next step on
        (remembering hits from then on)."""
        self.config = make_config(self.config, {"safety": layer})
        self._start_memories()

    @property
    def final_approach(self) -> FinalApproach | None:
        """The final approach as applied: ``config.final_approach`` with the robot's step and tool,
        and its radii unless the config gives them."""
        return self._final_approach

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
        self._start_memories()
        self._ready = True
        distance = float(np.linalg.norm(self.goals[0] - self.ee_pos))
        self._previous_distance = distance
        self._distances = [distance]  # to the current goal, one per step (the final approach's stall rule)
        info = {"distance": distance, "ee_position": self.ee_pos.copy(), "goal": self.goals[0].copy(),
                "is_success": False}
        observation = self._observation(distance, self._cast_rays())
        self._remember_hits()
        self._start_detour()
        return observation, info

    def step(self, action: np.ndarray):
        if not self._ready:
            raise RuntimeError("call reset() before step() (and after an episode ends)")
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (6,):
            raise ValueError(f"action must have 6 values (dx, dy, dz, droll, dpitch, dyaw), got shape {np.shape(action)}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action contains NaN or infinity: {a.tolist()}; the scene is unchanged")
        offset = self.goals[self.goal_index] - self.ee_pos
        straight, stalled, detour = None, False, None
        if self._final_approach is not None:
            straight = self._final_approach.action(offset, self.ray_hits(), self.ee_rot[:, 2])
        if straight is not None:
            a = straight
        elif self._detour is not None and (detour := self._detour.action(
                self.steps, self.ee_pos, self.goals[self.goal_index], self.ee_rot[:, 2], self._distances)) is not None:
            a = detour
        elif self._final_approach is not None and self._final_approach.stalled(self._distances):
            stalled = True
            a = FinalApproach.towards(offset)
        delta = np.clip(a, -1.0, 1.0) * self._step_scale
        cfg = self.config
        w = cfg.rewards
        shielded = 0.0
        rules = None
        layer = cfg.safety if detour is None else self._detour.detour.shield(cfg.safety)  # type: ignore[union-attr]
        if layer.active:
            scenario = self.scenario
            commanded = delta[:3]
            travel = None if straight is None else float(np.linalg.norm(offset))  # the straight step, in all
            towards_goal = (None if straight is not None or detour is not None
                            else FinalApproach.towards(offset)[:3] * self._step_scale[:3])
            rules = (self.ee_pos, np.asarray(scenario.workspace_low), np.asarray(scenario.workspace_high),  # type: ignore[union-attr]
                     *self._hit_memory.rays(self.ee_pos, self._ray_origins, self._ray_directions,
                                            self._ray_lengths, cfg.safety.ray_shield), travel)
            # the final approach's turn was tested against every hit: the shield keeps it
            delta = layer.filter(delta, *rules, towards_goal, keep_rotation=straight is not None)
            if straight is None and detour is None and not stalled:  # the policy's own step
                shielded = R.shielded_reward(commanded, delta[:3], w)

        ik, ee, taken = self._move(delta, straight is not None, layer, rules)
        for share in self.SHORTER if taken is None else ():
            # the arm's rule refused the step: a deterministic policy would repeat it, held, until
            # its step budget ran out (a KR16 tool stopped 0.5 mm short of the goal's tolerance)
            ik, ee, taken = self._move(delta * share, straight is not None, layer, rules)
            if taken:
                break
        if taken:
            self.q, self.frames = ik.q, ik.frames
            self.ee_pos, self.ee_rot = ee[:3, 3], ee[:3, :3]

        self.steps += 1
        self.time = self.steps * cfg.control_period
        if self.scene.has_moving_obstacles:
            self.scene.set_time(self.time)
        self.scene.set_joints(self.q)
        collided = self.scene.in_collision()
        outside = not self.scenario.in_workspace(self.ee_pos)  # type: ignore[union-attr]

        goal = self.goals[self.goal_index]
        distance = float(np.linalg.norm(goal - self.ee_pos))
        reached = distance < self.tolerance
        n_shakes = self._shake.update(distance)
        rays = self._cast_rays()
        if taken:  # a held arm sees what it saw: the memory ages only as the arm moves
            self._remember_hits()
        if self._detour is not None:
            self._detour.see(self._ray_origins, self._ray_directions, self._ray_lengths)
        terms = {
            "success": 0.0 if collided else R.success_reward(distance, self.tolerance, w),
            "collision": R.collision_reward(collided, w),
            "distance": R.distance_reward(distance, w),
            "shaking": R.shaking_reward(n_shakes, w),
            "out_of_bounds": R.out_of_bounds_reward(outside, w),
            "exhausted": 0.0,
            "progress": R.progress_reward(self._previous_distance, distance, w),
            "proximity": R.proximity_reward(float(rays.min()), w),
            "shielded": shielded,
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
            self._distances = []
        self._previous_distance = distance
        self._distances.append(distance)
        if terminated or truncated:
            self._ready = False
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
        return self._observation(distance, rays), float(sum(terms.values())), terminated, truncated, info

    SHORTER = (0.5, 0.25, 0.125)
    """Shares of a step the arm's rule refused that are tried in turn, the longest first:
    a shorter step may keep every blind link outside the rule's clearance."""

    def _move(self, delta: np.ndarray, straight: bool, layer: SafetyLayer,
              rules: tuple | None) -> tuple[IKResult, np.ndarray, bool | None]:
        """IK for the end-effector step ``delta``: the solution, its tool pose, and whether the
        step may be taken (True), not (False), or not by the arm's rule alone (None). Leaves
        the scene's joints where they were or at the solution."""
        cfg = self.config
        target_pos = self.ee_pos + delta[:3]
        target_rot = rotvec_to_matrix(delta[3:]) @ self.ee_rot
        ik = self.kin.ik(target_pos, target_rot, self.q, cfg.ik, start_frames=self.frames)
        if not ik.converged and straight:
            # the final approach moves the tip and keeps the tool's orientation only where IK
            # can: a pose out of its reach stopped a KR16 tool 8 cm short of its goal for good
            ik = self.kin.ik(target_pos, None, self.q, cfg.ik, start_frames=self.frames)
        ee = self.kin.ee_from_frames(ik.frames)
        # an unconverged IK step may move the tool where the layer did not let it: then it holds still
        if not (rules is None or ik.converged or layer.allows(ee[:3, 3] - self.ee_pos, *rules)):
            return ik, ee, False
        if self._arm_guard is not None and not self._arm_guard.allows(self.q, ik.q, tool=not straight):  # moves the joints
            return ik, ee, None
        return ik, ee, True

    def _cast_rays(self) -> np.ndarray:
        """Hit fractions of the rays in the current state (kept, with the rays and how far
        each sees in metres, for the final approach, the safety layer and the detour)."""
        self._ray_origins, self._ray_directions = self.rays.world_rays(self.frames)
        self._ray_fractions = self.caster.cast(self._ray_origins, self._ray_directions, self.config.ray_range)
        self._ray_lengths = self._ray_fractions * self.config.ray_range  # the range where nothing is seen
        return self._ray_fractions

    def _start_memories(self) -> None:
        """Empty memories for the safety layer's shield and, when it is on, its arm's rule
        (which starts from the scene's joints as they are)."""
        layer = self.config.safety
        self._hit_memory = HitMemory(layer.memory_steps)
        self._arm_guard = (ArmGuard(self._watched_links, layer.arm_clearance, layer.arm_memory_steps, layer.guard_tool,
                                    layer.tool_clearance) if layer.arm_clearance > 0 else None)

    def _start_detour(self) -> None:
        """A fresh detour for the episode, which has seen what the rays see at the start."""
        detour, approach = self.config.detour, self._final_approach
        self._detour = None
        if detour is None:
            return
        cfg, spec = self.config, self.spec_robot
        arrive = spec.final_approach_radius if approach is None else approach.radius
        guard = cfg.safety.workspace_guard + spec.ee_step  # the grid keeps a step inside the guard
        low = np.asarray(self.scenario.workspace_low) + guard  # type: ignore[union-attr]
        high = np.asarray(self.scenario.workspace_high) - guard  # type: ignore[union-attr]
        self._detour = DetourState(detour, spec.tool.length, spec.tool.radius, arrive, cfg.ray_range, low, high)
        self._detour.see(self._ray_origins, self._ray_directions, self._ray_lengths)

    def _remember_hits(self) -> None:
        """Keep what the rays hit now for the arm's rule (``SafetyLayer.arm_clearance``)."""
        if self._arm_guard is not None:
            self._arm_guard.seen.add(self._hit_points())

    def _hit_points(self) -> np.ndarray:
        """The points the rays see now, in the world, m, shape (n, 3); rays that see nothing
        within range are left out."""
        hit = self._ray_fractions < 1.0
        return self._ray_origins[hit] + self._ray_directions[hit] * self._ray_lengths[hit, None]

    def ray_hits(self) -> np.ndarray:
        """The points the rays see now, relative to the end effector, m, shape (n, 3)."""
        return self._hit_points() - self.ee_pos

    def _observation(self, distance: float, rays: np.ndarray) -> np.ndarray:
        obs = np.empty(OBS_SIZE, dtype=np.float32)
        obs[0:6] = self.q
        obs[6:9] = self.goals[self.goal_index] - self.ee_pos
        obs[9:12] = matrix_to_rpy(self.ref_rot_t @ self.ee_rot)
        obs[12] = distance
        obs[N_ROBOT_OBS:] = rays
        return obs

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
