"""Plan a scene built in code with the DRL policy and with OMPL's RRTConnect, and plot both.

The scene is one thin plate between start and goal in front of a UR5: obstacles are
``ObstacleSpec`` dataclasses, the scene a ``Scenario``, validated as a scene file would be.
``rayreach.plan`` runs each planner through the evaluation's executor, so the paths drawn are
the motions executed in simulation, collision-checked at every control step.

    python examples/plan_scene_in_code.py --out plate.png
"""

from __future__ import annotations

import argparse
import itertools
import math
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the figure only goes to a file
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import rayreach  # noqa: E402
from rayreach.scenarios import ObstacleSpec, Scenario, StartSpec  # noqa: E402

TOOL_DOWN = (math.pi, 0.0, math.pi)
"""The tool pointing down, as in the paper's experiments."""


def plate_scene() -> Scenario:
    """A UR5 reaching 0.3 m sideways past a 24 cm x 10 cm plate standing across its way."""
    plate = ObstacleSpec("box", position=(0.0, 0.45, 0.3), half_extents=(0.002, 0.12, 0.05), name="plate")
    return Scenario(name="plate-in-code", robot="ur5", obstacles=(plate,),
                    start=StartSpec(position=(0.15, 0.45, 0.3), rpy=TOOL_DOWN), goals=((-0.15, 0.45, 0.3),),
                    workspace_low=(-0.4, 0.3, 0.2), workspace_high=(0.4, 0.7, 0.5))


def box_edges(obstacle: ObstacleSpec) -> list[np.ndarray]:
    """The 12 edges of an axis-aligned box obstacle, for drawing."""
    centre, half = np.asarray(obstacle.position), np.asarray(obstacle.half_extents)
    signs = list(itertools.product((-1, 1), repeat=3))
    return [np.array([centre + half * a, centre + half * b]) for a, b in itertools.combinations(signs, 2)
            if sum(x != y for x, y in zip(a, b)) == 1]  # corners that differ along one axis


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(Path(tempfile.gettempdir()) / "plan_scene_in_code.png"),
                        help="PNG to write")
    parser.add_argument("--planners", default="drl,ompl-rrtconnect", help="comma-separated planner names")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    scene = plate_scene()
    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    edges = box_edges(scene.obstacles[0])
    for edge in edges:
        ax.plot(*edge.T, color="0.4", lw=1)
    points, statuses = [np.vstack(edges)], []
    for name in args.planners.split(","):
        outcome = rayreach.plan(scene, planner=name, seed=args.seed)
        print(f"{name}: {outcome.status}, path {outcome.path_length:.3f} m, "
              f"planning {outcome.planning_time:.3f} s")
        statuses.append(outcome.status)
        if len(outcome.ee_path):  # nothing moved after "no plan"
            ax.plot(*outcome.ee_path.T, lw=2, label=f"{name} ({outcome.status}, {outcome.path_length:.2f} m)")
            points.append(outcome.ee_path)
    start, goal = scene.start.position, scene.goals[0]
    ax.scatter(*start, color="k", marker="o", label="start")
    ax.scatter(*goal, color="k", marker="*", s=80, label="goal")
    ax.set_box_aspect(np.ptp(np.vstack(points), axis=0))  # metres alike on every axis
    ax.set(xlabel="x (m)", ylabel="y (m)", zlabel="z (m)", title=f"{scene.name}: tool-tip paths")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")
    return 0 if all(s == "success" for s in statuses) else 1  # both planners solve this scene


if __name__ == "__main__":
    raise SystemExit(main())
