"""``ArmController``: the planner on a real arm. Joint angles, the goal and the 129 ray readings
go in; the next joint target comes out, with the acting layers applied. No simulator.

The controller runs what ``ActingEnv`` runs in simulation, the same pipeline
(``rayreach.acting.pipeline.choose``) on the same perception: the rays placed by the joint
chain's forward kinematics (``rayreach.sim.sensors``, the layout of docs/rays.md), the
readings as hit fractions, the policy's observation. Two things differ, both because there is
no simulated scene: the arm's rule measures the seen points against capsules round the links
(``rayreach.acting.arm_guard.ChainCapsules``, shipped per robot) instead of PyBullet's
meshes, which never lets a link nearer than the meshes would; and the episode has no
collision test, which the real arm's own safety provides. Where the arm's rule keeps the upper
arm and the forearm clear too (``SafetyLayer.arm_rays``), the controller reads the 64 rays
round those links as well (``n_readings`` says how many readings a step takes).

    controller = ArmController("path/to/ur5.onnx")          # or a Policy, or a model .zip
    controller.reset(q_now, goal)
    while True:
        step = controller.step(q_now, readings)              # 129 fractions (or unit="m")
        if step.reached or step.outside:
            break
        send_joint_target(step.q_target); q_now = read_joints(); readings = read_rays()

The policy may be an ``OnnxPolicy`` (onnxruntime, no torch) or a ``Policy``; anything with
``robot``, ``observation``, ``act(obs, deterministic=True)`` and ``sample(obs, rng)`` will do.
The controller needs numpy, numba, gymnasium (for the observation's space) and the robot's
model package; with an ``OnnxPolicy``, onnxruntime and not torch. It keeps no step budget:
the caller decides how long a query may take.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rayreach.acting.arm_guard import ChainCapsules, guarded_links
from rayreach.acting.config import ActingConfig
from rayreach.acting.layers import acting_components
from rayreach.acting.memory import RayMemory
from rayreach.acting.pipeline import Episode, choose, held_by
from rayreach.acting.resample import ActingPolicy
from rayreach.env.observation import OBS_SIZE, ONE_WORLD, Observer, one_world_sighting, paper_observation
from rayreach.env.perception import Perception, seen_points
from rayreach.env.rewards import RewardWeights
from rayreach.robots import RobotSpec, get_robot
from rayreach.sim.goal_rays import N_GOAL_RAYS, SHORTEST, goal_rays
from rayreach.sim.kinematics import STEP_IK, IKParams, IKResult, Kinematics
from rayreach.sim.sensors import N_ARM, N_RAYS, RAY_RANGE, RayModel, arm_layout, extra_sets

UNITS = ("fraction", "m")
"""How ray readings may come: hit fractions of the range in [0, 1], or metres."""


@dataclass(frozen=True)
class ControlStep:
    """One control step's answer."""

    q_target: np.ndarray
    """The joint angles to command next, rad (6,); the measured ones where the arm holds."""
    source: str
    """What chose the motion (``rayreach.acting.SOURCES``), or ``reached`` / ``outside``."""
    held: bool
    """The arm is to hold still this step."""
    distance: float
    """Tool tip to goal, m, as measured this step."""
    reached: bool
    """The tip is within the goal tolerance: the query is done."""
    outside: bool
    """The tip has left the workspace: the controller holds the arm and the query has failed."""
    held_by: str = ""
    """Where a step of the pipeline held the arm: what held it (``rayreach.acting.pipeline.held_by``)."""


def load_controller_policy(policy: Any) -> Any:
    """A policy object as ``ArmController`` takes it: an ``.onnx`` path loads on onnxruntime, a
    robot name or a ``.zip`` with torch (``rayreach.planners.drl.resolve_model``); an object
    passes through."""
    if not isinstance(policy, (str, Path)):
        return policy
    if str(policy).endswith(".onnx"):
        from rayreach.learning.onnx_export import OnnxPolicy

        return OnnxPolicy(policy)
    from rayreach.learning.policy import load_policy
    from rayreach.planners.drl import resolve_model

    return load_policy(resolve_model(policy))


class ArmController:
    """The planner for one arm: a policy and the acting layers of ``acting``.

    ``robot`` defaults to the policy's; ``base_position``/``base_rpy`` place the arm's base in
    the frame the goal and workspace are given in (default: the robot's spec). ``capsules``
    are the links the arm's rule keeps clear (default: the shipped ones of the robot).
    """

    def __init__(self, policy: Any, robot: str | RobotSpec | None = None, acting: ActingConfig = ActingConfig(),
                 *, goal_tolerance: float = 0.01, ray_range: float = RAY_RANGE,
                 base_position: tuple[float, float, float] | None = None,
                 base_rpy: tuple[float, float, float] | None = None, ik: IKParams = STEP_IK,
                 capsules: ChainCapsules | None = None, seed: int = 0) -> None:
        self.policy = load_controller_policy(policy)
        self.spec = get_robot(robot if robot is not None else self.policy.robot)
        if self.spec.name != self.policy.robot:
            raise ValueError(f"the policy was trained for '{self.policy.robot}', not '{self.spec.name}'")
        if not goal_tolerance > 0:
            raise ValueError(f"goal_tolerance must be positive, got {goal_tolerance}")
        self.kin = Kinematics(self.spec, base_position, base_rpy)
        self.rays = RayModel(self.spec, ray_range)
        observation = self.policy.observation
        self.extra_rays = RayModel.extra(self.spec, ray_range, observation.ray_sets)
        self.ray_range, self.goal_tolerance, self.ik = float(ray_range), float(goal_tolerance), ik
        self.acting = acting
        guard_arm = acting.safety.reads_arm_rays
        self.arm_rays = RayModel(self.spec, ray_range, arm_layout(self.spec)) if guard_arm else None
        """The rays round the upper arm and the forearm that the arm's rule reads
        (``SafetyLayer.arm_rays``): the policy's own where it observes them, else 64 readings more."""
        if capsules is None and acting.safety.arm_clearance > 0:
            capsules = ChainCapsules.shipped(self.kin, guarded_links(self.spec, guard_arm))
        self.components, self.final_approach, _ = acting_components(acting, self.spec, self.ray_range,
                                                                    RewardWeights(), capsules)
        self.actor = ActingPolicy.acting(self.policy, acting)
        self.observer = Observer(self.policy.observation, 1, N_RAYS, OBS_SIZE, self.spec.ee_step)
        self.n_goal_rays = N_GOAL_RAYS * observation.goal_sight
        self.reading_sets = observation.ray_sets + (("arm_rays",) if guard_arm and not observation.arm_rays else ())
        """The ray sets read after the paper's 129: the policy's, and the arm's rule's."""
        self.n_readings = N_RAYS + sum(n for _, n, _ in extra_sets(self.reading_sets)) + self.n_goal_rays
        """Ray readings a step takes: the paper's 129, then the rays the policy observes beyond
        them, the 24 tip-back, the 32 slanted and the 64 along the arm (``rayreach rays --tip-back
        --slanted --arm-rays``; the 64 also where only the arm's rule reads them), then the 3
        aimed at the goal (``goal_rays``); the acting layers read the 129 (and the 64)."""
        self.step_scale = np.array([self.spec.ee_step] * 3 + [self.spec.rot_step] * 3)
        self.seed = seed
        self._goal: np.ndarray | None = None

    def _nearest(self, frames: np.ndarray, origins: np.ndarray, directions: np.ndarray, fractions: np.ndarray,
                 extra: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
        """The nearest sighting over every ray the policy reads, where it remembers sightings."""
        if not self.policy.observation.sightings:
            return None
        beyond = ([(*self.extra_rays.world_rays(frames), extra[0])]
                  if extra is not None and self.extra_rays is not None else [])
        return one_world_sighting(self.ray_range, (origins, directions, fractions), *beyond)

    def goal_rays(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Where to cast the 3 rays aimed at the goal with the arm at joints ``q``, for a policy
        that reads them (``observation.goal_sight``): origins and unit directions (3, 3), m, and
        their length, m (``rayreach.sim.goal_rays``). Their readings go last in ``step``'s."""
        if self._goal is None:
            raise RuntimeError("call reset(q, goal) before goal_rays()")
        ee = self.kin.fk(self._q_checked(q))
        origins, directions, lengths = goal_rays(ee[None, :3, 3], ee[None, :3, 2], self._goal[None],
                                                 self.spec.tool.length)
        return origins[0], directions[0], float(lengths[0])

    # ------------------------------------------------------------------ a query
    def reset(self, q: np.ndarray, goal: np.ndarray, workspace_low: np.ndarray | None = None,
              workspace_high: np.ndarray | None = None, seed: int | None = None) -> None:
        """Start a query from joints ``q`` (rad) to ``goal`` (m, base frame of the spec's
        placement) inside the workspace box (default: the robot's training workspace). The
        tool's orientation at ``q`` is the observation's reference, as at an episode's start.
        ``seed`` seeds the draws where the arm was held (default: the controller's)."""
        q = self._q_checked(q)
        self._ref_rot_t = self.kin.fk(q)[:3, :3].T.copy()
        goal = self._vector(goal, 3, "goal")
        low = self._vector(self.spec.workspace_low if workspace_low is None else workspace_low, 3, "workspace_low")
        high = self._vector(self.spec.workspace_high if workspace_high is None else workspace_high, 3,
                            "workspace_high")
        if not np.all(low < high):
            raise ValueError(f"workspace_low {low.tolist()} must lie below workspace_high {high.tolist()} on every axis")
        self._goal, self._low, self._high = goal, low, high
        self._episode: Episode | None = None
        self._steps = 0
        self._held = False
        self._taken = True
        self.actor.reset(self.seed if seed is None else seed)

    def step(self, q: np.ndarray, readings: np.ndarray, unit: str = "fraction") -> ControlStep:
        """The next joint target from the measured joints ``q`` (rad) and the ``n_readings``
        ray ``readings``: the 129, then the tip-back, slanted and arm ones where the policy has them,
        then the goal rays cast from ``goal_rays(q)`` where it has those (``unit``: ``fraction``
        of the range, or of the goal rays' length, 1 for nothing seen; or ``m``, where anything at
        or beyond that reads as nothing seen)."""
        if self._goal is None:
            raise RuntimeError("call reset(q, goal) before step()")
        q = self._q_checked(q)
        frames = self.kin.frames(q)
        ee = self.kin.ee_from_frames(frames)
        ee_pos, ee_rot = ee[:3, 3].copy(), ee[:3, :3].copy()
        distance = float(np.linalg.norm(self._goal - ee_pos))
        fractions = self._fractions(readings, unit, distance)
        goal_clear = fractions[None, self.n_readings - self.n_goal_rays:] if self.n_goal_rays else None
        fractions = fractions[: self.n_readings - self.n_goal_rays]
        arm_points = np.zeros((0, 3))
        if self.arm_rays is not None:  # the arm's rays are the last before the goal rays (EXTRA_RAYS' order)
            arm_points = seen_points(*self.arm_rays.world_rays(frames), fractions[-N_ARM:], self.ray_range)
        fractions = fractions[: N_RAYS + self.policy.observation.extra_rays]
        extra = fractions[None, N_RAYS:] if len(fractions) > N_RAYS else None
        fractions = fractions[:N_RAYS]
        origins, directions = self.rays.world_rays(frames)
        now = Perception(step=self._steps, q=q, ee_position=ee_pos, ee_rotation=ee_rot, goal=self._goal,
                         origins=origins, directions=directions, lengths=fractions * self.ray_range,
                         fractions=fractions, workspace_low=self._low, workspace_high=self._high,
                         arm_points=arm_points)
        first = self._episode is None
        base = paper_observation(q, self._goal, ee_pos, ee_rot, self._ref_rot_t, distance, fractions)[None]
        nearest = self._nearest(frames, origins, directions, fractions, extra)
        args = (ONE_WORLD, base, ee_pos[None], fractions[None], self._low[None], self._high[None], extra, nearest,
                goal_clear)
        if first:
            memory = RayMemory()
            memory.add(now, moved=True)
            self._episode = Episode(memory, [distance], self.step_scale)
            for component in self.components:
                component.reset(self._episode)
            self.observer.reset(*args)
        else:
            self._episode.memory.add(now, moved=self._taken)
            self._episode.distances.append(distance)
            self.observer.step(*args)
        self._steps += 1
        reached = distance < self.goal_tolerance
        outside = bool(np.any(ee_pos < self._low) or np.any(ee_pos > self._high))
        if reached or outside:
            return ControlStep(q.copy(), "reached" if reached else "outside", True, distance, reached, outside)

        action = self.actor.act(self.observer.obs[0].copy(), {"acting": {"held": self._held}})

        def solve(delta: np.ndarray, keep_orientation: bool) -> IKResult:
            return self.kin.step_ik(delta, q, frames, ee_pos, ee_rot, self.ik, keep_orientation)

        chosen = choose(self.components, self._episode, np.asarray(action, dtype=float).reshape(6), solve,
                        lambda ik: self.kin.ee_from_frames(ik.frames))
        target = chosen.ik.q.copy() if chosen.taken else q.copy()
        self._taken = chosen.taken
        self._held = not chosen.taken or np.array_equal(target, q)
        return ControlStep(target, "held" if self._held else chosen.command.source, self._held, distance, False,
                           False, held_by(chosen) if self._held else "")

    # ------------------------------------------------------------------ checks
    def _vector(self, value: Any, n: int, name: str) -> np.ndarray:
        v = np.array(value, dtype=float).reshape(-1)  # a copy: the memory keeps it, the caller may refill its own
        if v.shape != (n,) or not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be {n} finite numbers, got {np.asarray(value).tolist()}")
        return v

    def _q_checked(self, q: Any) -> np.ndarray:
        q = self._vector(q, self.spec.n_joints, f"q (joint angles of {', '.join(self.spec.joint_names)}, rad)")
        outside = np.flatnonzero((q < self.kin.lower - 1e-9) | (q > self.kin.upper + 1e-9))
        if outside.size:
            names = ", ".join(f"{self.spec.joint_names[i]}={q[i]:.3f} not in [{self.kin.lower[i]:.3f}, "
                              f"{self.kin.upper[i]:.3f}]" for i in outside)
            raise ValueError(f"joint angles outside the robot's limits: {names}")
        return q

    def _fractions(self, readings: Any, unit: str, goal_distance: float) -> np.ndarray:
        """``readings`` as fractions: of the range, and of the goal rays' length (``goal_distance``,
        at least ``SHORTEST``) for those."""
        if unit not in UNITS:
            raise ValueError(f"unknown unit '{unit}'; valid: {', '.join(UNITS)}")
        r = np.array(readings, dtype=float).reshape(-1)  # a copy, as in _vector
        if r.shape != (self.n_readings,):
            what = f"{N_RAYS} rays" + "".join(f", then the {n} {name.removesuffix('-rays')} rays"
                                              for name, n, _ in extra_sets(self.reading_sets))
            what += f", then the {N_GOAL_RAYS} goal rays" if self.n_goal_rays else ""
            raise ValueError(f"readings must hold the {what} in the layout's order (docs/rays.md, rayreach rays), "
                             f"got {np.asarray(readings).shape}")
        if not np.all(np.isfinite(r)) or np.any(r < 0):
            bad = np.flatnonzero(~np.isfinite(r) | (r < 0))
            raise ValueError(f"ray readings must be finite and >= 0; rays {bad.tolist()[:10]} are not")
        if unit == "m":
            lengths = np.full(len(r), self.ray_range)
            lengths[len(r) - self.n_goal_rays:] = max(goal_distance, SHORTEST)
            return np.minimum(r / lengths, 1.0)
        if np.any(r > 1.0):
            raise ValueError(f"fractions must lie in [0, 1] (1: nothing within {self.ray_range} m); rays "
                             f"{np.flatnonzero(r > 1.0).tolist()[:10]} exceed 1 (metres? pass unit='m')")
        return r
