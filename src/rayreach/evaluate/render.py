"""Pictures of a scene (PyBullet's headless camera image with the rays drawn over it) and GIFs of runs."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from rayreach.env.reach import ReachEnv, camera_for
from rayreach.sim.scene import project_points

if TYPE_CHECKING:
    from rayreach.evaluate.executor import Executor, RunRecord

HIT_COLOR = "#e8322b"
FREE_COLOR = "#2bb24c"


def draw_scene(env: ReachEnv, out: str | Path, title: str | None = None,
               trajectory: Sequence[Sequence[float]] | None = None, width: int = 960, height: int = 720) -> Path:
    """Write a PNG of the env's current state: robot, obstacles, goal(s), the 129 rays
    (green: free within range, red: hit, drawn up to the hit point) and an optional
    end-effector trajectory."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scene = env.scene
    image, view, proj = scene.camera_image(width=width, height=height, **camera_for(env.scenario))
    origins, directions = env.rays.world_rays(env.frames)
    fractions = env.caster.cast(origins, directions, env.rays.ray_range)
    ends = origins + directions * (fractions[:, None] * env.rays.ray_range)

    fig, ax = plt.subplots(figsize=(width / 100, height / 100), dpi=100)
    ax.imshow(image)
    start_px = project_points(origins, view, proj, width, height)
    end_px = project_points(ends, view, proj, width, height)
    for s, e, f in zip(start_px, end_px, fractions):
        ax.plot([s[0], e[0]], [s[1], e[1]], color=HIT_COLOR if f < 1.0 else FREE_COLOR, lw=0.7, alpha=0.8)
    goals_px = project_points(np.asarray(env.goals), view, proj, width, height)
    ax.scatter(goals_px[:, 0], goals_px[:, 1], marker="*", s=220, c="gold", edgecolors="black", zorder=5, label="goal")
    if trajectory is not None and len(trajectory) > 1:
        path_px = project_points(np.asarray(trajectory, dtype=float), view, proj, width, height)
        ax.plot(path_px[:, 0], path_px[:, 1], color="#1f5fd6", lw=2.0, label="end effector")
        ax.scatter(path_px[:1, 0], path_px[:1, 1], c="#1f5fd6", s=60, zorder=5, label="start")
    hits = int((fractions < 1.0).sum())
    ax.set_title(title or f"{env.scenario.name if env.scenario else ''}: {hits} of {len(fractions)} rays hit")
    ax.legend(loc="lower right", fontsize=8)
    ax.set_axis_off()
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


def write_video(executor: "Executor", record: "RunRecord", out: str | Path, frame_every: int = 4,
                width: int = 480, height: int = 360, fps: int = 30) -> Path:
    """Replay a run's joint path (obstacles where they were at each step) into a GIF, one
    frame per ``frame_every`` control steps, from PyBullet's headless renderer."""
    from PIL import Image

    scene = executor.scene
    camera = camera_for(executor.env.scenario)
    frames = []
    indices = list(range(0, len(record.joint_path), frame_every))
    if indices and indices[-1] != len(record.joint_path) - 1:
        indices.append(len(record.joint_path) - 1)
    for i in indices:
        scene.set_time(i * executor.period)
        scene.set_joints(record.joint_path[i])
        frames.append(Image.fromarray(scene.camera_image(width=width, height=height, **camera)[0]))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    frames[0].save(out, save_all=True, append_images=frames[1:], duration=int(1000 / fps), loop=0)
    return out
