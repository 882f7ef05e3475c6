"""Scripted demonstrations, cloned into a training checkpoint.

PPO alone learned two motions badly (docs/training.md). The KR16 did not enter its shelf: the
tool starts 30 degrees below horizontal, so the wrist rides above it and strikes the board
over a compartment's opening. The UR5 did not descend between two upright plates to a goal
below their tops: with the curriculum's 0.1 m goal, hovering above the slot already counted as
reaching it. A scripted controller per world kind (``EXPERTS``) solves its worlds; fitting the
actor to its actions (behaviour cloning, with DAgger rounds that label the cloned policy's own
states) teaches the motion. Episodes in the robot's other training worlds, labelled with the
actor's actions from before cloning, keep it from forgetting them.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Protocol

import numpy as np
from tqdm import tqdm

from rayreach.learning.bundles import CheckpointError, Normalization, read_bundle_meta, save_bundle


from rayreach.learning.imitation import save_demos
from rayreach.learning.policy import Policy
from rayreach.env.decisions import HeldAction
from rayreach.env.episode import run_episode
from rayreach.learning.train import CHECKPOINT
from rayreach.scenarios import RANDOM
from rayreach.scenarios.suites import suite_kinds
from rayreach.sim.transforms import rpy_to_matrix


CLONES = "clones"
"""The key in a checkpoint's ``meta["state"]`` that holds the report of each clone in its actor."""


def report_name(kind: str) -> str:
    """The report ``clone_into_checkpoint`` writes into the run directory."""
    return f"clone-{kind}.json"


class Expert(Protocol):
    def accepts(self, env: Any) -> bool:
        """Whether the expert can solve the world ``env`` has just reset to."""

    def label(self, obs: np.ndarray, env: Any) -> np.ndarray:
        """The expert's action for ``obs`` in ``env`` (a ``ReachEnv``)."""


@dataclass(frozen=True)
class ShelfExpert:
    """Levels the tool along ``direction``, centres it on the goal across that direction, then
    moves straight in: the way a compartment is entered without touching its edges."""

    direction: tuple[float, float, float] | None = None
    """Into the shelf; None: +y turned by the yaw of the world's first obstacle, a board of
    the shelf (exp4..exp7 and the random shelves open towards -y, facing the robot; a broad
    world's shelf faces the robot's base from wherever it stands)."""
    position_tolerance: float = 0.003
    """Lateral offset, m, below which the tool may advance."""
    angle_tolerance: float = 0.02
    """Tool-axis misalignment, rad, below which the tool may advance."""
    standoff: float = 0.05
    """Until levelled and centred, the tool tip may advance up to this far in front of the
    shelf's open face, m: closing in while it turns shortens the path."""
    ee_step: float = 0.005
    rot_step: float = 0.005

    def action(self, obs: np.ndarray, tool_axis: np.ndarray, approach: float = 0.0,
               into: np.ndarray | None = None) -> np.ndarray:
        """``obs`` as ``ReachEnv`` gives it (goal offset at 6:9); ``tool_axis``: the tool's
        pointing direction (its z axis) in the world frame; ``approach``: how far, m, the tip
        may advance before it is levelled and centred (see ``label``); ``into``: the way into
        the shelf (default ``direction``, else +y)."""
        along = np.asarray(into if into is not None else self.direction or (0.0, 1.0, 0.0), dtype=float)
        offset = np.asarray(obs[6:9], dtype=float)
        turn = np.cross(tool_axis, along)  # rotation vector that turns the tool onto ``along``
        ahead = float(offset @ along)
        lateral = offset - along * ahead
        if np.max(np.abs(lateral)) > self.position_tolerance or np.linalg.norm(turn) > self.angle_tolerance:
            offset = lateral + along * min(max(approach, 0.0), max(ahead, 0.0))
        return _action(offset, turn, self.ee_step, self.rot_step)

    def accepts(self, env: Any) -> bool:
        return True

    def into(self, env: Any) -> np.ndarray:
        """The way into the shelf of ``env``'s world (see ``direction``)."""
        if self.direction is not None:
            return np.asarray(self.direction, dtype=float)
        yaw = float(env.scenario.obstacles[0].rpy[2])
        return np.array([-np.sin(yaw), np.cos(yaw), 0.0])

    def label(self, obs: np.ndarray, env: Any) -> np.ndarray:
        along = self.into(env)
        front = min(float((_corners(o) @ along).min()) for o in env.scenario.obstacles)
        approach = front - self.standoff - float(env.ee_pos @ along)
        return self.action(obs, env.ee_rot[:, 2], approach, along)


@dataclass(frozen=True)
class SlotExpert:
    """Keeps the tool pointing down, comes over the obstacles around the goal at ``clearance``
    above the highest, then descends straight onto the goal: the way into a slot between two
    upright plates (exp2). Far from the obstacles it climbs while it closes in, so the path is
    a diagonal, not a climb-then-cross L."""

    clearance: float = 0.04
    """Height of the tool tip over the highest obstacle while crossing, m."""
    margin: float = 0.03
    """Horizontal distance, m, outside the obstacles' farthest point from the goal where the
    tool must already be at crossing height."""
    ceiling_margin: float = 0.01
    """The crossing height must stay this far below the workspace's top, m."""
    position_tolerance: float = 0.003
    """Horizontal offset, m, below which the tool may descend."""
    ee_step: float = 0.005
    rot_step: float = 0.005

    def action(self, obs: np.ndarray, tool_axis: np.ndarray, height: float, crossing: float,
               reach: float) -> np.ndarray:
        """``height``: the tool tip's z; ``crossing``: the z to cross at; ``reach``: the
        horizontal radius around the goal within which the tool may only move at ``crossing``
        (see ``crossing_height`` and ``reach``)."""
        offset = np.asarray(obs[6:9], dtype=float)
        turn = np.cross(tool_axis, (0.0, 0.0, -1.0))
        across = float(np.linalg.norm(offset[:2]))
        if across > self.position_tolerance:
            climb = max(crossing - height, 0.0)
            level = climb < 0.5 * self.ee_step
            horizontal = offset[:2] if level or across - self.ee_step > reach else np.zeros(2)
            offset = np.array([horizontal[0], horizontal[1], climb])
        return _action(offset, turn, self.ee_step, self.rot_step)

    def crossing_height(self, env: Any) -> float:
        return max((top_of(o) for o in env.scenario.obstacles), default=-np.inf) + self.clearance

    def reach(self, env: Any) -> float:
        goal = env.goals[env.goal_index]
        return max((horizontal_reach(o, goal) for o in env.scenario.obstacles), default=0.0) + self.margin

    def accepts(self, env: Any) -> bool:
        return self.crossing_height(env) <= env.scenario.workspace_high[2] - self.ceiling_margin

    def label(self, obs: np.ndarray, env: Any) -> np.ndarray:
        height = float(env.ee_pos[2])
        return self.action(obs, env.ee_rot[:, 2], height, self.crossing_height(env), self.reach(env))


@dataclass(frozen=True)
class CoverExpert(SlotExpert):
    """The slot expert's way onto the goal, waiting where a moving obstacle lies over it: the
    tool hovers at crossing height above the goal until nothing over the goal is within
    ``gap`` of it horizontally, then descends. A goal under a plate that moves away (exp3)
    is reached once the plate has gone by, not by diving under it as it leaves."""

    gap: float = 0.03
    """Horizontal distance, m, every obstacle over the goal must keep from it before the
    tool descends: the tool's radius and a margin."""
    least_clearance: float = 0.015
    """Under a low ceiling the tool crosses lower than ``clearance``, down to this far over
    the highest obstacle, m."""

    def crossing_height(self, env: Any) -> float:
        ceiling = env.scenario.workspace_high[2] - self.ceiling_margin
        return min(super().crossing_height(env), ceiling)

    def accepts(self, env: Any) -> bool:
        highest = super().crossing_height(env) - self.clearance
        return self.crossing_height(env) >= highest + self.least_clearance

    def covered(self, env: Any) -> bool:
        """Whether an obstacle over the goal (its lowest point above the goal) lies within
        ``gap`` of it horizontally at the env's time."""
        goal = env.goals[env.goal_index]
        return any(bottom_of(o) > goal[2] and horizontal_gap(o, goal, env.time) < self.gap
                   for o in env.scenario.obstacles)

    def label(self, obs: np.ndarray, env: Any) -> np.ndarray:
        if self.covered(env):  # aim over the goal, at the crossing height
            obs = np.array(obs, dtype=float)
            obs[8] = self.crossing_height(env) - float(env.ee_pos[2])
        return super().label(obs, env)


def _corners(obstacle: Any) -> np.ndarray:
    """The eight corners of a box (world frame, at its start position)."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    offsets = signs * np.asarray(obstacle.half_extents)
    return np.asarray(obstacle.position) + offsets @ rpy_to_matrix(obstacle.rpy).T


def _heights(obstacle: Any) -> tuple[float, float]:
    """Lowest and highest z of a box or sphere (moving ones move horizontally only)."""
    if obstacle.shape == "sphere":
        centre, radius = float(obstacle.position[2]), float(obstacle.radius)
        return centre - radius, centre + radius
    z = _corners(obstacle)[:, 2]
    return float(z.min()), float(z.max())


def top_of(obstacle: Any) -> float:
    """Highest z of a box or sphere."""
    return _heights(obstacle)[1]


def bottom_of(obstacle: Any) -> float:
    """Lowest z of a box or sphere."""
    return _heights(obstacle)[0]


def horizontal_gap(obstacle: Any, point: np.ndarray, t: float = 0.0) -> float:
    """Horizontal distance from ``point`` to a box's footprint or a sphere at time ``t`` (0
    where the point lies under or over it). A box is taken by its yaw; a tilted box's
    footprint is larger than the rectangle this measures."""
    centre = np.asarray(obstacle.position_at(t), dtype=float)
    if obstacle.shape == "sphere":
        return max(float(np.linalg.norm(centre[:2] - point[:2])) - float(obstacle.radius), 0.0)
    yaw = float(obstacle.rpy[2])
    offset = point[:2] - centre[:2]
    local = np.array([np.cos(yaw) * offset[0] + np.sin(yaw) * offset[1],
                      -np.sin(yaw) * offset[0] + np.cos(yaw) * offset[1]])
    outside = np.maximum(np.abs(local) - np.asarray(obstacle.half_extents[:2]), 0.0)
    return float(np.linalg.norm(outside))


def horizontal_reach(obstacle: Any, point: np.ndarray) -> float:
    """Farthest horizontal distance from ``point`` to a box or sphere at its start position."""
    if obstacle.shape == "sphere":
        return float(np.linalg.norm(np.asarray(obstacle.position[:2]) - point[:2])) + float(obstacle.radius)
    return float(np.linalg.norm(_corners(obstacle)[:, :2] - point[:2], axis=1).max())


def _action(offset: np.ndarray, turn: np.ndarray, ee_step: float, rot_step: float) -> np.ndarray:
    action = np.concatenate([offset / ee_step, turn / rot_step])
    return np.clip(action, -1.0, 1.0).astype(np.float32)


EXPERTS: dict[str, Callable[..., Expert]] = {"shelf": ShelfExpert, "goal_slot": SlotExpert, "goal_cover": CoverExpert,
                                              "goal_box": SlotExpert}
"""The world kinds (``random_world.KINDS``, and the goal scenes of the broad suite,
``broad_world.GOAL_KINDS``) that have a scripted expert. Into an open box the slot expert's
way serves: over the rim, then straight down."""


@dataclass(frozen=True)
class CloneConfig:
    episodes: int = 150
    """Episodes per round in the expert's worlds."""
    rounds: int = 3
    """Round 1 follows the expert; later rounds follow the cloned actor, labelled by the expert."""
    anchor_episodes: int = 60
    """Episodes in the robot's other training worlds, labelled by the actor before cloning."""
    anchor_tolerance: float | None = None
    """Goal tolerance of the anchor episodes, m; None: the run's current curriculum goal size.
    At the true 0.01 m the last decimetre before the goal is in the anchor data too; without
    it, a clone whose expert descends only between walls stopped above free goals (UR5 exp2)."""
    eval_episodes: int = 60
    epochs: int = 20
    batch_size: int = 256
    learning_rate: float = 3e-4
    seed: int = 0


def _world_env(robot: str, suite: str, n_obstacles: int, kinds: tuple[str, ...], goal_tolerance: float, observation):
    """Drawn worlds of ``suite`` with the actor's observation: the paper's environment, for
    the expert and the DAgger rounds. Random worlds are of ``kinds``; broad worlds draw their
    own, and ``_play``'s ``accepts`` picks those of a goal scene."""
    from rayreach.env.reach import ReachEnv
    from rayreach.scenarios.random_world import RandomWorldConfig

    random_kinds = kinds if suite == RANDOM else None
    return ReachEnv(robot=robot, scenario=suite, goal_tolerance=goal_tolerance,
                    random_world=RandomWorldConfig(n_obstacles=n_obstacles, kinds=random_kinds), observation=observation)


def clonable_kinds(robot: str, suite: str) -> tuple[str, ...]:
    """The world kinds with an expert (``EXPERTS``) that a run of ``robot`` in ``suite``
    trains on: its random-world kinds, or the broad suite's goal scenes."""
    from rayreach.robots import get_robot
    from rayreach.scenarios.broad_world import GOAL_KINDS

    trained = get_robot(robot).training_kinds if suite == RANDOM else GOAL_KINDS
    return tuple(k for k in dict.fromkeys(trained) if k in EXPERTS)


def _acting(env):
    """``env`` as the DRL planner acted when the shipped demonstrations were cloned: with the
    final approach, without the other layers."""
    from rayreach.acting import LAYERS, ActingConfig, ActingEnv

    return ActingEnv(env, ActingConfig().without(*(layer for layer in LAYERS if layer != "final_approach")))


def _play(env, act: Callable[[np.ndarray], np.ndarray], label: Callable[[np.ndarray, Any], np.ndarray] | None,
          episodes: int, seed: int, desc: str, progress: bool, accepts: Callable[[Any], bool] = lambda env: True,
          ) -> tuple[list[np.ndarray], list[np.ndarray], dict[str, float]]:
    """Play ``episodes`` in worlds that ``accepts``, acting with ``act``; record raw
    observations and ``label(obs, env)`` (``accepts`` and ``label`` see the paper's
    environment, inside any acting wrapper)."""
    observations, labels, outcomes = [], [], {"success": 0, "collision": 0}
    base = env.unwrapped

    def record(obs: np.ndarray, _env: Any) -> None:
        if label is not None:
            observations.append(obs)
            labels.append(label(obs, base))

    for episode in tqdm(range(episodes), desc=desc, disable=not progress, leave=False):
        start = env.reset(seed=seed + episode)
        while not accepts(base):
            start = env.reset()
        info = run_episode(env, lambda obs, _info: act(obs), on_step=record, start=start).info
        outcomes["success"] += bool(info["is_success"])
        outcomes["collision"] += bool(info["collision"])
    return observations, labels, {k: v / max(episodes, 1) for k, v in outcomes.items()}


def clone_into_checkpoint(run: str | Path, kind: str, config: CloneConfig = CloneConfig(),
                          progress: bool = True) -> dict[str, Any]:
    """Fit the actor of ``run``'s checkpoint to the expert of world ``kind`` (see ``EXPERTS``)
    and save it in place (same step count; the time spent is added to the run's training wall
    time). Returns the report, also written to ``run/clone-KIND.json``."""
    import torch
    from stable_baselines3 import PPO

    from rayreach.robots import get_robot

    started = time.perf_counter()
    run = Path(run)
    checkpoint = run / CHECKPOINT
    meta, norm = read_bundle_meta(checkpoint)
    if meta.get("kind") != "checkpoint":
        raise CheckpointError(f"{checkpoint} is a {meta.get('kind')} bundle, not a training checkpoint")
    normalize = Normalization.from_arrays(norm)
    if normalize is None:
        raise CheckpointError(f"{checkpoint} carries no observation normalisation; cloning needs the one PPO sees")
    robot = str(meta["robot"])
    spec = get_robot(robot)
    if kind not in EXPERTS:
        raise ValueError(f"no expert for world kind '{kind}'; known: {', '.join(EXPERTS)}")
    suite = str(meta.get("config", {}).get("suite", RANDOM))
    if kind not in clonable_kinds(robot, suite):
        kinds = ", ".join(clonable_kinds(robot, suite))
        raise ValueError(f"robot '{robot}' does not train on '{kind}' worlds in the {suite} suite; "
                         f"its kinds with an expert: {kinds}")
    torch.manual_seed(config.seed)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # one observation per forward pass: more threads only spin (``load_policy``)
    model = PPO.load(str(checkpoint), device="cpu")
    policy = model.policy
    actor = Policy(model, normalize, meta, checkpoint)
    period = actor.decision_period  # an action is held this many control steps: the expert's step is that long
    expert: Expert = EXPERTS[kind](ee_step=spec.ee_step * period, rot_step=spec.rot_step * period)

    def actor_mean(raw: np.ndarray) -> torch.Tensor:
        return policy.get_distribution(torch.as_tensor(normalize(raw))).distribution.mean

    n_obstacles = int(meta["state"]["obstacles"]["count"])
    goal_size = float(meta["state"]["goal"]["size"])
    others = tuple(k for k in spec.training_kinds if k != kind)
    anchor_tolerance = goal_size if config.anchor_tolerance is None else config.anchor_tolerance
    anchor_env = HeldAction(_acting(_world_env(robot, suite, n_obstacles, others, anchor_tolerance,
                                               actor.observation)), period)
    expert_world = _world_env(robot, suite, 1, (kind,), float(meta["config"]["goal"]["rho_min"]),  # the true task
                              actor.observation)

    def in_expert_world(env: Any) -> bool:
        return suite_kinds(suite, env.scenario)[:1] == [kind] and expert.accepts(env)

    def in_other_world(env: Any) -> bool:
        return kind not in suite_kinds(suite, env.scenario)

    expert_env = HeldAction(expert_world, period)
    acting_expert_env = HeldAction(_acting(expert_world), period)
    try:
        anchor_obs, _, anchor_before = _play(anchor_env, actor.act, lambda o, e: o, config.anchor_episodes,
                                             config.seed + 10_000, "anchor", progress, in_other_world)
        with torch.no_grad():
            anchor_labels = [actor_mean(np.asarray(anchor_obs)).numpy()] if anchor_obs else []
        expert_before = _play(acting_expert_env, actor.act, None, config.eval_episodes, config.seed + 20_000, "before",
                              progress, in_expert_world)[2]
        expert_obs: list[np.ndarray] = []
        expert_labels: list[np.ndarray] = []
        optimiser = torch.optim.Adam(policy.parameters(), lr=config.learning_rate)
        rounds = []
        # the DAgger rounds follow the expert or the actor alone, in the paper's environment
        for r in range(config.rounds):
            follow = (lambda o: expert.label(o, expert_world)) if r == 0 else actor.act
            obs, labels, outcome = _play(expert_env, follow, expert.label, config.episodes,
                                         config.seed + 1_000 * r, f"round {r + 1}", progress, in_expert_world)
            expert_obs += obs
            expert_labels += labels
            x = torch.as_tensor(normalize(np.asarray(expert_obs + anchor_obs)))
            y = torch.as_tensor(np.concatenate([np.asarray(expert_labels)] + anchor_labels).astype(np.float32))
            loss = _fit(policy, optimiser, x, y, config.epochs, config.batch_size)
            rounds.append({"round": r + 1, "followed": "expert" if r == 0 else "cloned actor",
                           "success_rate": outcome["success"], "samples": len(y), "loss": loss})
        expert_after = _play(acting_expert_env, actor.act, None, config.eval_episodes, config.seed + 20_000, "after",
                             progress, in_expert_world)[2]
        _, _, anchor_after = _play(anchor_env, actor.act, None, config.anchor_episodes, config.seed + 10_000,
                                   "anchor after", progress, in_other_world)
    finally:
        anchor_env.close()
        expert_env.close()
        torch.set_num_threads(threads)
    elapsed = time.perf_counter() - started
    meta["state"]["wall_time"] = float(meta["state"]["wall_time"]) + elapsed
    meta["wall_time_s"] = round(meta["state"]["wall_time"], 1)
    report = {
        "timesteps": int(meta["timesteps"]),
        "wall_time_s": round(elapsed, 1),
        "config": asdict(config),
        "kind": kind,
        "suite": suite,
        "expert_worlds": {"before": expert_before, "after": expert_after},
        "other_worlds": {"before": anchor_before, "after": anchor_after, "obstacles": n_obstacles,
                         "goal_tolerance": anchor_tolerance},
        "rounds": rounds,
    }
    save_demos(run, kind, expert_obs, expert_labels)  # for an imitation term beside PPO (``imitation``)
    meta["state"].setdefault(CLONES, {})[kind] = report  # saved with the cloned actor: a stop after it loses nothing
    save_bundle(model, checkpoint, meta, norm)
    write_report(run, report)
    return report


def write_report(run: Path, report: dict[str, Any]) -> Path:
    """The clone's report as ``run/clone-KIND.json``."""
    path = Path(run) / report_name(report["kind"])
    path.write_text(json.dumps(report, indent=2) + "\n")
    return path


def _fit(policy, optimiser, x, y, epochs: int, batch_size: int) -> float:
    """Mean-squared error of the actor's mean action against the labels; returns the last epoch's."""
    import torch

    last = float("nan")
    for _ in range(epochs):
        order = torch.randperm(len(x))
        total = 0.0
        for start in range(0, len(x), batch_size):
            batch = order[start:start + batch_size]
            loss = torch.nn.functional.mse_loss(policy.get_distribution(x[batch]).distribution.mean, y[batch])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += loss.item() * len(batch)
        last = total / len(x)
    return round(last, 5)
