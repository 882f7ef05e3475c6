"""From the results database to what people read: runs.csv, table.md and the figures.

Means and standard deviations are over successful runs (the paper's convention); a planner
with no success in an experiment shows "/". Best means per experiment are in bold.
"""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from rayreach.evaluate.store import COLUMNS, ResultsStore
from rayreach.transforms import rpy_to_matrix

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
    """Per (experiment, planner): runs, successes, collisions, outcome counts, and mean/std of
    execution time and path length over successful runs."""
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
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
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
    lines += ["### Successes (no collision, goal within 0.01 m) and collisions per runs", "",
              "| experiment | " + " | ".join(planners) + " |", "|---" * (1 + len(planners)) + "|"]
    for e in experiments:
        cells = []
        for p in planners:
            s = stats.get((e, p))
            cells.append(f"{s['successes']}/{s['runs']} ({s['collisions']} coll.)" if s else "")
        lines.append(f"| {e} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _colours(planners: list[str]) -> dict[str, Any]:
    import matplotlib.pyplot as plt

    cmap = plt.get_cmap("tab10")
    return {p: cmap(i) for i, p in enumerate(planners)}


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
        if metric == "execution_time":
            ax.set_yscale("log")
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def resample(points: np.ndarray, n: int = 100) -> np.ndarray:
    """``n`` points evenly spaced by arc length along a polyline."""
    if len(points) < 2:
        return np.repeat(points[:1], n, axis=0)
    s = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))))
    if s[-1] == 0:
        return np.repeat(points[:1], n, axis=0)
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, points[:, k]) for k in range(3)], axis=1)


def box_edges(centre, half, rpy=(0.0, 0.0, 0.0)) -> list[tuple[np.ndarray, np.ndarray]]:
    """The 12 edges of a box posed like PyBullet's (``rpy`` about fixed x, y, z), as point pairs."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    corners = (signs * np.asarray(half)) @ rpy_to_matrix(rpy).T + np.asarray(centre)
    return [(corners[i], corners[j]) for i in range(8) for j in range(i + 1, 8)
            if np.count_nonzero(signs[i] != signs[j]) == 1]


def _draw_box(ax, centre, half, rpy, colour="0.5") -> None:
    for a, b in box_edges(centre, half, rpy):
        ax.plot(*zip(a, b), color=colour, lw=0.6)


def trajectory_figure(store: ResultsStore, experiments: list[str], planners: list[str], path: Path) -> Path:
    """One 3-D panel per experiment: every run's end-effector path (thin), the mean of the
    successful runs per planner (thick), start (circle) and goals (stars); boxes drawn as edges."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rayreach.scenarios import get_scenario

    colours = _colours(planners)
    cols = min(len(experiments), 4)
    rows_n = math.ceil(len(experiments) / cols)
    fig = plt.figure(figsize=(4.6 * cols, 4.4 * rows_n))
    for k, experiment in enumerate(experiments):
        ax = fig.add_subplot(rows_n, cols, k + 1, projection="3d")
        scenario = get_scenario(experiment)
        for obstacle in scenario.obstacles:
            if obstacle.shape == "box" and not obstacle.moving:
                _draw_box(ax, obstacle.position, obstacle.half_extents, obstacle.rpy)
        by_planner: dict[str, list[np.ndarray]] = defaultdict(list)
        for planner, _, success, points in store.paths(experiment):
            if planner not in colours or len(points) == 0:
                continue
            ax.plot(*points.T, color=colours[planner], lw=0.4, alpha=0.35)
            if success:
                by_planner[planner].append(resample(points))
        for planner, paths in by_planner.items():
            ax.plot(*np.mean(paths, axis=0).T, color=colours[planner], lw=2.2, label=f"{planner} (mean)")
        goals = np.asarray(scenario.goals)
        ax.scatter(*goals.T, marker="*", s=120, color="red", label="goal")
        first = next(iter(store.paths(experiment)), None)
        if first is not None and len(first[3]):
            ax.scatter(*first[3][0], marker="o", s=40, color="black", label="start")
        ax.set_title(experiment)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        if k == 0:
            ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
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
        from rayreach.scenarios import get_scenario

        for robot in ("ur5", "kr16"):
            mine = [e for e in fixed if get_scenario(e).robot == robot]
            if mine:
                written[f"trajectories_{robot}"] = trajectory_figure(store, mine, planners,
                                                                     out / f"trajectories_{robot}.png")
        return written
    finally:
        store.close()
