"""The ray layout as a picture: the 129 rays in the flange frame, for a user who mounts or
emulates the sensors (docs/rays.md). Matplotlib only: no simulator."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rayreach.robots import RobotSpec, get_robot
from rayreach.sim.sensors import RAY_RANGE, layout_rows

COLOURS = {"wrist": "tab:blue", "wraparound": "tab:orange", "tip": "tab:green"}
DRAWN = 0.08
"""Length the rays are drawn, m: at their range of 0.4 m they would hide the tool."""


def ray_layout_figure(robot: str | RobotSpec, out: str | Path) -> Path:
    """Three views of the rays in the flange frame (z along the tool): in 3-D, from the side
    (x-z) and along the tool (x-y), each sensor in its colour, the tool drawn as its axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spec = get_robot(robot)
    rows = layout_rows(spec)
    fig = plt.figure(figsize=(13, 4.6))
    axes = [fig.add_subplot(1, 3, 1, projection="3d"), fig.add_subplot(1, 3, 2), fig.add_subplot(1, 3, 3)]
    views = [(0, 1, 2), (0, 2), (0, 1)]
    length = spec.tool.length
    for ax, view in zip(axes, views):
        tool = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length]])
        ax.plot(*tool[:, view].T, color="black", linewidth=6 if len(view) == 2 else 4, alpha=0.35,
                solid_capstyle="butt")
        for sensor, colour in COLOURS.items():
            mine = [r for r in rows if r["sensor"] == sensor]
            origin = np.array([r["origin_flange"] for r in mine])
            end = origin + DRAWN * np.array([r["direction_flange"] for r in mine])
            for a, b in zip(origin, end):
                ax.plot(*np.stack([a, b])[:, view].T, color=colour, linewidth=0.8)
            ax.scatter(*origin[:, view].T, color=colour, s=6,
                       label=f"{sensor}: rays {mine[0]['index']}-{mine[-1]['index']}")
        names = "xyz"
        ax.set_xlabel(f"{names[view[0]]} (m)")
        ax.set_ylabel(f"{names[view[1]]} (m)")
        if len(view) == 3:
            ax.set_zlabel("z (m)")
            ax.view_init(elev=18, azim=-60)
        else:
            ax.set_aspect("equal")
            ax.grid(alpha=0.3)
    axes[0].set_title("3-D")
    axes[1].set_title("side: x-z (tool along +z)")
    axes[2].set_title("along the tool: x-y")
    axes[2].legend(loc="upper right", fontsize=8)
    fig.suptitle(f"{spec.name}: the 129 rays in the flange frame ({spec.flange_link}); drawn {DRAWN} m long, "
                 f"they see {RAY_RANGE} m; tool {length} m x {spec.tool.radius} m")
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
