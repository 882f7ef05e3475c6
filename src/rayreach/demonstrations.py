"""Shelf demonstrations, cloned into a training checkpoint before PPO continues.

PPO alone did not learn to enter the KR16's shelf: the tool starts 30 degrees below
horizontal, so the wrist rides above it and strikes the board over a compartment's opening
(docs/training.md). A scripted controller that levels the tool, lines it up with the goal and
then pushes straight in reaches every random shelf goal; fitting the actor to its actions
(behaviour cloning, with DAgger rounds that label the cloned policy's own states) gives PPO a
start from which it can shorten and generalise the motion. Episodes in the robot's other
training worlds, labelled with the actor's actions from before cloning, keep it from
forgetting them.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np
from tqdm import tqdm

from rayreach.policy import CheckpointError, FinalApproach, Normalization, Policy, read_bundle_meta, save_bundle
from rayreach.train import CHECKPOINT

REPORT = "clone.json"


@dataclass(frozen=True)
class ShelfExpert:
    """Levels the tool along ``direction``, centres it on the goal across that direction, then
    moves straight in: the way a compartment is entered without touching its edges."""

    direction: tuple[float, float, float] = (0.0, 1.0, 0.0)
    """Into the shelf (exp4..exp7 and the random shelves open towards -y, facing the robot)."""
    position_tolerance: float = 0.003
    """Lateral offset, m, below which the tool may advance."""
    angle_tolerance: float = 0.02
    """Tool-axis misalignment, rad, below which the tool may advance."""
    ee_step: float = 0.005
    rot_step: float = 0.005

    def action(self, obs: np.ndarray, tool_axis: np.ndarray) -> np.ndarray:
        """``obs`` as ``ReachEnv`` gives it (goal offset at 6:9); ``tool_axis``: the tool's
        pointing direction (its z axis) in the world frame."""
        along = np.asarray(self.direction, dtype=float)
        offset = np.asarray(obs[6:9], dtype=float)
        turn = np.cross(tool_axis, along)  # rotation vector that turns the tool onto ``along``
        lateral = offset - along * float(offset @ along)
        if np.max(np.abs(lateral)) > self.position_tolerance or np.linalg.norm(turn) > self.angle_tolerance:
            offset = lateral
        action = np.concatenate([offset / self.ee_step, turn / self.rot_step])
        return np.clip(action, -1.0, 1.0).astype(np.float32)


@dataclass(frozen=True)
class CloneConfig:
    episodes: int = 150
    """Shelf episodes per round."""
    rounds: int = 3
    """Round 1 follows the expert; later rounds follow the cloned actor, labelled by the expert."""
    anchor_episodes: int = 60
    """Episodes in the robot's other training worlds, labelled by the actor before cloning."""
    eval_episodes: int = 60
    epochs: int = 20
    batch_size: int = 256
    learning_rate: float = 3e-4
    seed: int = 0


def _world_env(robot: str, n_obstacles: int, kinds: tuple[str, ...], goal_tolerance: float):
    from rayreach.env import EnvConfig, ReachEnv
    from rayreach.scenarios.random_world import RandomWorldConfig

    config = EnvConfig(goal_tolerance=goal_tolerance, random_world=RandomWorldConfig(n_obstacles=n_obstacles, kinds=kinds))
    return ReachEnv(robot=robot, scenario="random", config=config)


def _play(env, act: Callable[[np.ndarray], np.ndarray], label: Callable[[np.ndarray, Any], np.ndarray] | None,
          episodes: int, seed: int, desc: str, progress: bool) -> tuple[list[np.ndarray], list[np.ndarray], dict[str, float]]:
    """Play ``episodes``, acting with ``act``; record raw observations and ``label(obs, env)``."""
    observations, labels, outcomes = [], [], {"success": 0, "collision": 0}
    for episode in tqdm(range(episodes), desc=desc, disable=not progress, leave=False):
        obs, _ = env.reset(seed=seed + episode)
        done = False
        while not done:
            if label is not None:
                observations.append(obs)
                labels.append(label(obs, env))
            obs, _, terminated, truncated, info = env.step(act(obs))
            done = terminated or truncated
        outcomes["success"] += bool(info["is_success"])
        outcomes["collision"] += bool(info["collision"])
    return observations, labels, {k: v / max(episodes, 1) for k, v in outcomes.items()}


def clone_into_checkpoint(run: str | Path, config: CloneConfig = CloneConfig(), progress: bool = True) -> dict[str, Any]:
    """Fit the actor of ``run``'s checkpoint to shelf demonstrations and save it in place
    (same step count; the time spent is added to the run's training wall time). Returns the
    report, also written to ``run/clone.json``."""
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
    if "shelf" not in spec.training_kinds:
        raise ValueError(f"robot '{robot}' does not train on shelves; shelf demonstrations are for a robot that does")
    torch.manual_seed(config.seed)
    model = PPO.load(str(checkpoint), device="cpu")
    policy = model.policy
    expert = ShelfExpert(ee_step=spec.ee_step, rot_step=spec.rot_step)
    # acting as the DRL planner does (with the final approach), and the actor alone
    as_planner = Policy(model, normalize, meta, checkpoint, FinalApproach(ee_step=spec.ee_step))
    alone = replace(as_planner, final_approach=None)

    def actor_mean(raw: np.ndarray) -> torch.Tensor:
        return policy.get_distribution(torch.as_tensor(normalize(raw))).distribution.mean

    def expert_label(obs: np.ndarray, env) -> np.ndarray:
        return expert.action(obs, env.ee_rot[:, 2])

    n_obstacles = int(meta["state"]["obstacles"]["count"])
    goal_size = float(meta["state"]["goal"]["size"])
    others = tuple(k for k in spec.training_kinds if k != "shelf")
    anchor_env = _world_env(robot, n_obstacles, others, goal_size)  # judged as training judges them
    shelf_env = _world_env(robot, 1, ("shelf",), float(meta["config"]["goal"]["rho_min"]))  # the true task
    try:
        anchor_obs, _, anchor_before = _play(anchor_env, alone.act, lambda o, e: o, config.anchor_episodes,
                                             config.seed + 10_000, "anchor", progress)
        with torch.no_grad():
            anchor_labels = [actor_mean(np.asarray(anchor_obs)).numpy()] if anchor_obs else []
        _, _, shelf_before = _play(shelf_env, as_planner.act, None, config.eval_episodes, config.seed + 20_000, "before", progress)
        shelf_obs: list[np.ndarray] = []
        shelf_labels: list[np.ndarray] = []
        optimiser = torch.optim.Adam(policy.parameters(), lr=config.learning_rate)
        rounds = []
        for r in range(config.rounds):
            follow = (lambda o: expert_label(o, shelf_env)) if r == 0 else alone.act
            obs, labels, outcome = _play(shelf_env, follow, expert_label, config.episodes,
                                         config.seed + 1_000 * r, f"round {r + 1}", progress)
            shelf_obs += obs
            shelf_labels += labels
            x = torch.as_tensor(normalize(np.asarray(shelf_obs + anchor_obs)))
            y = torch.as_tensor(np.concatenate([np.asarray(shelf_labels)] + anchor_labels).astype(np.float32))
            loss = _fit(policy, optimiser, x, y, config.epochs, config.batch_size)
            rounds.append({"round": r + 1, "followed": "expert" if r == 0 else "cloned actor",
                           "success_rate": outcome["success"], "samples": len(y), "loss": loss})
        _, _, shelf_after = _play(shelf_env, as_planner.act, None, config.eval_episodes, config.seed + 20_000, "after", progress)
        _, _, anchor_after = _play(anchor_env, alone.act, None, config.anchor_episodes, config.seed + 10_000, "anchor after",
                                   progress)
    finally:
        anchor_env.close()
        shelf_env.close()
    elapsed = time.perf_counter() - started
    meta["state"]["wall_time"] = float(meta["state"]["wall_time"]) + elapsed
    meta["wall_time_s"] = round(meta["state"]["wall_time"], 1)
    save_bundle(model, checkpoint, meta, norm)
    report = {
        "timesteps": int(meta["timesteps"]),
        "wall_time_s": round(elapsed, 1),
        "config": asdict(config),
        "shelf_worlds": {"before": shelf_before, "after": shelf_after},
        "other_worlds": {"before": anchor_before, "after": anchor_after, "obstacles": n_obstacles},
        "rounds": rounds,
    }
    (run / REPORT).write_text(json.dumps(report, indent=2) + "\n")
    return report


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
