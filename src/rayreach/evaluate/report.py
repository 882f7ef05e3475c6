"""From the results database to what people read: runs.csv, table.md and the figures.

Means and standard deviations are over successful runs (the paper's convention); a planner
with no success in an experiment shows "/". Best means per experiment are in bold.
"""

from __future__ import annotations

import csv
import json
import math
import textwrap
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from rayreach.evaluate.executor import polyline_length
from rayreach.evaluate.store import COLUMNS, ResultsStore
from rayreach.scenarios import ObstacleSpec, Scenario
from rayreach.sim.transforms import rpy_to_matrix

PAPER = {
    "execution_time": {"drl": [0.84, 2.15, 3.05, 1.29, 1.29, 1.30, 1.33],
                       "rrt": [3.38, 6.59, None, 22.38, 25.34, 25.58, 21.59],
                       "ncrrt": [1.97, 4.54, None, 6.76, 6.36, 5.46, 4.70]},
    "path_length": {"drl": [0.45, 0.85, 1.18, 0.91, 0.93, 0.95, 0.98],
                    "rrt": [3.88, 6.65, None, 1.45, 1.34, 1.35, 1.30],
                    "ncrrt": [2.27, 3.08, None, 1.29, 1.32, 1.36, 1.12]},
}
"""The paper's Table "Mean values from 30 runs" (None: the planner failed)."""
PAPER_NAMES = {"drl": "DRL", "rrt": "RRT", "ncrrt": "NC-RRT"}
METRICS = {"execution_time": ("execution time", "s"), "path_length": ("path length", "m")}


def paper_value(metric: str, planner: str, experiment: str) -> float | None:
    if not experiment.startswith("exp"):
        return None
    return PAPER[metric][planner][int(experiment[3:]) - 1]


def summarise(rows: list[dict[str, Any]]) -> dict[tuple[str, str], dict[str, Any]]:
    """Per (experiment, planner): runs, successes, collisions, outcome counts, mean/std of
    execution time and path length over successful runs, and ``policy_share``: the mean over
    all runs of the share of steps the policy chose (None for global planners and for runs
    stored without their shares)."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        groups[(row["experiment"], row["planner"])].append(row)
    out = {}
    for key, items in groups.items():
        good = [r for r in items if r["solved"]]
        entry: dict[str, Any] = {"runs": len(items), "successes": len(good),
                                 "collisions": sum(r["collision"] for r in items),
                                 "outcomes": dict(sorted(_count(r["status"] for r in items).items()))}
        for metric, column in (("execution_time", "execution_time"), ("path_length", "solution_length"),
                               ("planning_time", "time")):
            values = np.array([r[column] for r in good], dtype=float)
            entry[metric] = (float(values.mean()), float(values.std())) if len(values) else None
        shares = [r["acting_share"].get("policy", 0.0) for r in items if r.get("acting_share")]
        entry["policy_share"] = float(np.mean(shares)) if shares else None
        out[key] = entry
    return out


def _count(values) -> dict[str, int]:
    counts: dict[str, int] = defaultdict(int)
    for v in values:
        counts[v] += 1
    return counts


def _order(rows: list[dict[str, Any]], field: str) -> list[str]:
    seen = list(dict.fromkeys(r[field] for r in rows))
    if field == "experiment":
        return sorted(seen, key=lambda e: (not e.startswith("exp"), int(e[3:]) if e[3:].isdigit() else 0, e))
    from rayreach.planners import PLANNER_NAMES

    return sorted(seen, key=lambda p: PLANNER_NAMES.index(p) if p in PLANNER_NAMES else len(PLANNER_NAMES))


def write_csv(rows: list[dict[str, Any]], path: Path) -> Path:
    """One line per run; ``acting_share`` as JSON (empty where there is none)."""
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            share = row["acting_share"]
            writer.writerow({**row, "acting_share": json.dumps(share, sort_keys=True) if share else ""})
    return path


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The paper's table, one block per metric, with the paper's columns beside ours."""
    stats = summarise(rows)
    experiments, planners = _order(rows, "experiment"), _order(rows, "planner")
    paper_cols = [p for p in PAPER_NAMES if any(e.startswith("exp") for e in experiments)]
    lines = []
    for metric, (title, unit) in METRICS.items():
        lines += [f"### Mean {title} in [{unit}] over successful runs (± std)", "",
                  "| " + " | ".join(["experiment", *planners, *(f"paper {PAPER_NAMES[p]}" for p in paper_cols)]) + " |",
                  "|---" * (1 + len(planners) + len(paper_cols)) + "|"]
        for e in experiments:
            means = {p: stats[(e, p)][metric][0] for p in planners if (e, p) in stats and stats[(e, p)][metric]}
            best = min(means.values()) if means else None
            cells = []
            for p in planners:
                value = stats.get((e, p), {}).get(metric)
                if value is None:
                    cells.append("/" if (e, p) in stats else "")
                    continue
                text = f"{value[0]:.2f} ± {value[1]:.2f}" if value[0] >= 0.01 else f"{value[0]:.4f} ± {value[1]:.4f}"
                cells.append(f"**{text}**" if value[0] == best else text)
            paper = [paper_value(metric, p, e) for p in paper_cols]
            cells += ["/" if v is None and e.startswith("exp") else "" if v is None else f"{v:.2f}" for v in paper]
            lines.append(f"| {e} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["### Successes (no collision, goal within 0.01 m) and collisions per runs; for reactive "
              "planners the policy's mean share of steps", "",
              "| experiment | " + " | ".join(planners) + " |", "|---" * (1 + len(planners)) + "|"]
    for e in experiments:
        cells = []
        for p in planners:
            s = stats.get((e, p))
            share = "" if not s or s["policy_share"] is None else f"; policy {s['policy_share']:.0%}"
            cells.append(f"{s['successes']}/{s['runs']} ({s['collisions']} coll.{share})" if s else "")
        lines.append(f"| {e} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _colours(planners: list[str]) -> dict[str, Any]:
    """A distinct colour per planner (tab10, tab20 past ten planners)."""
    import matplotlib.pyplot as plt

    cmap = plt.get_cmap("tab10" if len(planners) <= 10 else "tab20")
    return {p: cmap(i % cmap.N) for i, p in enumerate(planners)}


def bar_chart(rows: list[dict[str, Any]], path: Path) -> Path:
    """Path length and execution time per experiment and planner (mean ± std, successes only);
    the execution-time axis is logarithmic, as the planners differ by orders of magnitude. A
    planner without a successful run in an experiment gets a cross at the axis, not a bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stats = summarise(rows)
    experiments, planners = _order(rows, "experiment"), _order(rows, "planner")
    colours = _colours(planners)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    width = 0.8 / len(planners)
    x = np.arange(len(experiments))
    for ax, metric in zip(axes, ("path_length", "execution_time")):
        for i, p in enumerate(planners):
            values = [stats.get((e, p), {}).get(metric) for e in experiments]
            means = [v[0] if v else np.nan for v in values]
            stds = [v[1] if v else np.nan for v in values]
            at = x + (i - (len(planners) - 1) / 2) * width
            ax.bar(at, means, width, yerr=stds, label=p, color=colours[p], capsize=2)
            none = [k for k, v in enumerate(values) if not v]
            ax.plot(at[none], np.full(len(none), 0.02), "x", color=colours[p], transform=ax.get_xaxis_transform())
        title, unit = METRICS[metric]
        ax.set_xticks(x, experiments)
        ax.set_ylabel(f"{title} [{unit}]")
        ax.set_title(f"{title} (mean ± std of successful runs; ×: none)")
        if metric == "execution_time" and any(stats[key][metric] for key in stats):  # log of nothing fails
            ax.set_yscale("log")
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def representative(runs: list[tuple[bool, np.ndarray]]) -> int:
    """Index of the run that stands for a planner in the trajectory figure: the median-length
    successful one (the shorter middle one of an even count), else the median-length run.
    A real run, not an average: paths passing an obstacle on different sides average to one
    through it."""
    if not runs:
        raise ValueError("no runs to choose a representative from")
    pool = [i for i, (success, _) in enumerate(runs) if success] or list(range(len(runs)))
    pool.sort(key=lambda i: polyline_length(runs[i][1]))
    return pool[(len(pool) - 1) // 2]


def box_corners(centre, half, rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The 8 corners of a box posed like PyBullet's (``rpy`` about fixed x, y, z); corner
    ``4 ix + 2 iy + iz`` lies on the side ``(-1, +1)[i]`` of each local axis."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    return (signs * np.asarray(half)) @ rpy_to_matrix(rpy).T + np.asarray(centre)


BOX_FACES = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))
"""Corner indices (:func:`box_corners`) of a box's six faces, each in order round the face."""


def _grid_faces(grid: np.ndarray) -> list[np.ndarray]:
    """The quads of a (rows, cols, 3) grid of surface points."""
    return [np.array([grid[i, j], grid[i, j + 1], grid[i + 1, j + 1], grid[i + 1, j]])
            for i in range(grid.shape[0] - 1) for j in range(grid.shape[1] - 1)]


def obstacle_faces(obstacle: ObstacleSpec, resolution: int = 16) -> list[np.ndarray]:
    """Polygons (each k x 3, m) of ``obstacle``'s surface where it is at t = 0: a box's six
    faces, a sphere or cylinder in ``resolution`` segments round; none for a mesh (its file
    is not read)."""
    centre = np.asarray(obstacle.position_at(0.0), dtype=float)
    rot = rpy_to_matrix(obstacle.rpy)
    if obstacle.shape == "box":
        corners = box_corners(centre, obstacle.half_extents, obstacle.rpy)
        return [corners[list(face)] for face in BOX_FACES]
    around = np.linspace(0.0, 2 * np.pi, resolution + 1)
    if obstacle.shape == "sphere":
        assert obstacle.radius is not None
        polar = np.linspace(0.0, np.pi, resolution // 2 + 1)[:, None]
        unit = np.stack([np.sin(polar) * np.cos(around), np.sin(polar) * np.sin(around),
                         np.cos(polar) * np.ones_like(around)], axis=-1)
        return _grid_faces(centre + obstacle.radius * unit)
    if obstacle.shape == "cylinder":
        assert obstacle.radius is not None and obstacle.height is not None
        ring = np.stack([obstacle.radius * np.cos(around), obstacle.radius * np.sin(around),
                         np.zeros_like(around)], axis=-1)
        ends = [ring + (0.0, 0.0, z) for z in (-obstacle.height / 2, obstacle.height / 2)]
        local = _grid_faces(np.stack(ends)) + [end[:-1] for end in ends]
        return [face @ rot.T + centre for face in local]
    return []


def _draw_obstacle(ax, obstacle: ObstacleSpec) -> None:
    """A shaded, see-through solid (a marker for a mesh), with an arrow along a moving
    obstacle's velocity over 1 s."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    faces = obstacle_faces(obstacle)
    if faces:
        box = obstacle.shape == "box"  # edges only where they are the shape's, not the polygons'
        ax.add_collection3d(Poly3DCollection(faces, facecolors="0.55", edgecolors="0.3" if box else "0.55",
                                             linewidths=0.5 if box else 0.0, alpha=0.35, shade=True, zorder=2))
    else:
        ax.scatter(*obstacle.position_at(0.0), marker="s", s=30, color="0.4", zorder=2)
    if obstacle.moving:
        ax.quiver(*obstacle.position_at(0.0), *obstacle.velocity, color="0.2", lw=1.2, arrow_length_ratio=0.3,
                  zorder=2)


def _limits(points: list[np.ndarray], pad: float = 0.05) -> np.ndarray:
    """(3, 2) axis limits round ``points`` (each n x 3) with ``pad`` of their extent either side."""
    stacked = np.vstack(points)
    low, high = stacked.min(axis=0), stacked.max(axis=0)
    margin = pad * max(float((high - low).max()), 0.1)
    return np.stack([low - margin, high + margin], axis=1)


VIEWS = (("oblique", 25.0, -60.0), ("from above", 90.0, -90.0))
"""(name, elevation, azimuth in degrees) of the trajectory figure's rows: the oblique view
shows who went over or under, the view from above who went round which side."""


def _scene_limits(scenario: Scenario, runs: dict[str, list[tuple[bool, np.ndarray]]]) -> np.ndarray:
    """(3, 2) axis limits holding the goals, the obstacles (and their arrows) and the bold paths."""
    shown = [np.asarray(scenario.goals, dtype=float)]
    for obstacle in scenario.obstacles:
        shown.extend(obstacle_faces(obstacle))
        shown.append(np.add(obstacle.position_at(0.0), obstacle.velocity)[None])
    shown.extend(runs[p][representative(runs[p])][1] for p in runs)
    return _limits(shown)


def _panel(ax, scenario: Scenario, runs: dict[str, list[tuple[bool, np.ndarray]]], colours: dict[str, Any],
           limits: np.ndarray, view: tuple[str, float, float]) -> None:
    """One view of one experiment (see :func:`trajectory_figure`)."""
    from matplotlib.ticker import MaxNLocator

    for obstacle in scenario.obstacles:
        _draw_obstacle(ax, obstacle)
    for rank, planner in enumerate(runs):  # the first listed on top
        best = representative(runs[planner])
        for i, (_, points) in enumerate(runs[planner]):
            if i != best:
                ax.plot(*points.T, color=colours[planner], lw=0.5, alpha=0.25, zorder=1, axlim_clip=True)
        success, points = runs[planner][best]
        ax.plot(*points.T, color=colours[planner], lw=2.4, ls="-" if success else "--", zorder=3 - rank / 100)
    goals = np.asarray(scenario.goals, dtype=float)
    ax.scatter(*goals.T, marker="*", s=160, color="red", edgecolors="black", linewidths=0.5, zorder=4)
    for i, goal in enumerate(goals if len(goals) > 1 else []):
        ax.text(*goal, f"  {i + 1}", fontsize=9, zorder=4)
    if runs:
        ax.scatter(*next(iter(runs.values()))[0][1][0], marker="o", s=50, color="black", zorder=4)
    _, elevation, azimuth = view
    ax.set(xlim=limits[0], ylim=limits[1], zlim=limits[2])
    ax.set_box_aspect(limits[:, 1] - limits[:, 0], zoom=1.3 if elevation == 90.0 else 1.0)
    ax.view_init(elev=elevation, azim=azimuth)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5))
    ax.set_xlabel("x [m]", fontsize=8)
    ax.set_ylabel("y [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    if elevation == 90.0:  # a map: no depth to show
        ax.set_proj_type("ortho")
        ax.set_zticks([])
    else:
        ax.set_zlabel("z [m]", fontsize=8)


def _row_height(view: tuple[str, float, float], limits: list[np.ndarray]) -> float:
    """Height of a view's row relative to its width: a map as tall as its widest scene needs."""
    if view[1] != 90.0:
        return 1.0
    sizes = np.array([lim[:, 1] - lim[:, 0] for lim in limits])
    return float(np.clip(np.max(sizes[:, 1] / sizes[:, 0]), 0.45, 1.2))


def trajectory_figure(store: ResultsStore, experiments: list[str], planners: list[str], path: Path) -> Path:
    """One column per experiment, one row per view (:data:`VIEWS`): the scene's obstacles as
    solids where they are at t = 0 (arrows: moving ones' velocity over 1 s), per planner one
    representative run (:func:`representative`) bold, dashed when none of its runs succeeded,
    its other runs thin in the same colour; the start (circle) and goals (stars). The axes hold
    the scene and the bold paths; thin ones that stray further are clipped."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from rayreach.scenarios import get_scenario

    colours = _colours(planners)
    scenes, limits = [], []
    for experiment in experiments:
        stored: dict[str, list[tuple[bool, np.ndarray]]] = defaultdict(list)
        for planner, _, success, points in store.paths(experiment):
            if planner in colours and len(points):
                stored[planner].append((success, points))
        scenario, runs = get_scenario(experiment), {p: stored[p] for p in planners if p in stored}
        scenes.append((scenario, runs))
        limits.append(_scene_limits(scenario, runs))
    handles = [Line2D([], [], color=colours[p], lw=2.4, label=p) for p in planners]
    handles += [Line2D([], [], color="0.2", lw=2.4, label="median-length success"),
                Line2D([], [], color="0.2", lw=2.4, ls="--", label="median-length run (no success)"),
                Line2D([], [], color="0.2", lw=0.5, alpha=0.5, label="other runs"),
                Line2D([], [], marker="o", color="black", ls="", label="start"),
                Line2D([], [], marker="*", color="red", markeredgecolor="black", ms=12, ls="", label="goal")]
    cols = len(experiments)
    width = max(4.6 * cols, 6.0)
    legend_cols = min(math.ceil(len(handles) / 2), 3 * cols)
    legend_height = 0.25 * math.ceil(len(handles) / legend_cols) + 0.3  # inches
    heights = [_row_height(view, limits) for view in VIEWS]
    title_height = 1.0
    fig = plt.figure(figsize=(width, 3.6 * sum(heights) + title_height + 0.3 * len(VIEWS) + legend_height))
    height = fig.get_figheight()
    grid = fig.add_gridspec(len(VIEWS), cols, height_ratios=heights, left=0.02, right=0.96, wspace=0.15,
                            hspace=0.25, bottom=legend_height / height, top=1 - title_height / height)
    for k, (experiment, (scenario, runs)) in enumerate(zip(experiments, scenes)):
        for row, view in enumerate(VIEWS):
            ax = fig.add_subplot(grid[row, k], projection="3d", computed_zorder=False)
            _panel(ax, scenario, runs, colours, limits[k], view)
            title = [Path(experiment).name, *textwrap.wrap(scenario.description, 50)] if row == 0 else []
            ax.set_title("\n".join([*title, view[0]]), fontsize=8)
    fig.legend(handles=handles, loc="lower center", ncol=legend_cols, fontsize=8, frameon=False)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(out: str | Path) -> dict[str, Path]:
    """runs.csv, table.md, bars.png and the trajectory figures of ``out/results.db``."""
    out = Path(out)
    store = ResultsStore(out / "results.db")
    try:
        rows = store.rows()
        written = {"csv": write_csv(rows, out / "runs.csv")}
        table = out / "table.md"
        table.write_text(markdown_table(rows))
        written["table"] = table
        if not rows:
            return written
        written["bars"] = bar_chart(rows, out / "bars.png")
        experiments, planners = _order(rows, "experiment"), _order(rows, "planner")
        fixed = [e for e in experiments if e.startswith("exp")]
        from rayreach.robots import ROBOTS
        from rayreach.scenarios import get_scenario

        for robot in ROBOTS:
            mine = [e for e in fixed if get_scenario(e).robot == robot]
            if mine:
                written[f"trajectories_{robot}"] = trajectory_figure(store, mine, planners,
                                                                     out / f"trajectories_{robot}.png")
        return written
    finally:
        store.close()
