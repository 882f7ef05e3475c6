"""A scripted episode (no learning): shows the environment, its rays and its rewards at work."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rayreach.env.episode import run_episode
from rayreach.env.reach import ReachEnv
from rayreach.evaluate.render import draw_scene


def scripted_actions(env: ReachEnv, clearance_z: float) -> list[np.ndarray]:
    """Waypoint actions: rise to ``clearance_z``, cross above each goal in turn, descend.

    Not a planner: it ignores the rays and knows only where the goals are.
    """
    step_size = env.spec_robot.ee_step
    actions: list[np.ndarray] = []
    ee = env.ee_pos.copy()
    for goal in env.goals:
        for target in (np.array([ee[0], ee[1], clearance_z]), np.array([goal[0], goal[1], clearance_z]), goal):
            while np.linalg.norm(target - ee) > 1e-6:
                step = np.clip((target - ee) / step_size, -1.0, 1.0)
                actions.append(np.concatenate((step, np.zeros(3))))
                ee = ee + step * step_size
    return actions


@dataclass(frozen=True)
class EpisodeSummary:
    steps: int
    success: bool
    collision: bool
    path_length: float
    total_reward: float
    picture: Path


def scripted_episode(scenario: str, out_dir: str | Path, clearance_z: float = 0.45) -> EpisodeSummary:
    """Run the scripted episode on a built-in scenario and draw its trajectory."""
    env = ReachEnv(scenario=scenario)
    try:
        start = env.reset(seed=0)
        actions = iter(scripted_actions(env, clearance_z))
        episode = run_episode(env, lambda obs, info: next(actions, None), start=start)
        path, info, total = episode.ee_path, episode.info, episode.total_reward
        picture = draw_scene(env, Path(out_dir) / f"{scenario}-scripted.png", trajectory=path,
                             title=f"{scenario}: scripted episode, {len(path) - 1} steps")
        return EpisodeSummary(episode.steps, bool(info.get("is_success")), bool(info.get("collision")),
                              episode.path_length, total, picture)
    finally:
        env.close()
