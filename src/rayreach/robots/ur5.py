"""Universal Robots UR5 from the ``example-robot-data`` package."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from rayreach.robots.spec import DHTable, RobotSpec, SensorMount, ToolSpec

_SHARE = Path("cmeel.prefix") / "share" / "example-robot-data"


def _share_dir() -> Path:
    """example-robot-data 6.x has no Python module: its files lie under site-packages."""
    for entry in sys.path:
        candidate = Path(entry) / _SHARE
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(
        "example-robot-data is not installed (no cmeel.prefix/share/example-robot-data on sys.path); "
        "pip install example-robot-data"
    )


UR5 = RobotSpec(
    name="ur5",
    urdf=lambda: _share_dir() / "robots" / "ur_description" / "urdf" / "ur5_robot.urdf",
    package_dirs=lambda: {"example-robot-data": _share_dir()},
    joint_names=(
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    ),
    lower=(-2 * math.pi, -2 * math.pi, -math.pi, -2 * math.pi, -2 * math.pi, -2 * math.pi),
    upper=(2 * math.pi, 2 * math.pi, math.pi, 2 * math.pi, 2 * math.pi, 2 * math.pi),
    velocity=(3.15, 3.15, 3.15, 3.2, 3.2, 3.2),
    flange_link="tool0",
    # Universal Robots' published DH parameters; DH frame 0 is the URDF's "base" link,
    # which sits at base_link turned by -pi about z.
    dh=DHTable(
        d=(0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823),
        a=(0.0, -0.425, -0.39225, 0.0, 0.0, 0.0),
        alpha=(math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0),
    ),
    dh_base_rpy=(0.0, 0.0, -math.pi),
    tool=ToolSpec(length=0.13, radius=0.02),
    home=(1.3781, -0.958, 1.9323, -2.5451, -1.5708, -3.3343),
    base_position=(0.0, -0.12, 0.5),
    mounts={
        "wrist": SensorMount(link="wrist_3_link", frame=6, xyz=(0.0, 0.0, -0.09)),
        "tool": SensorMount(link="rayreach_tool", frame=6),
        # along the DH x axes of the upper arm and the forearm, at the URDF's lateral offsets
        # of their tubes (shoulder 0.13585, elbow -0.1197), from the distal joint back
        "upper_arm": SensorMount(link="upper_arm_link", frame=2, xyz=(0.0, 0.0, 0.13585), rpy=(0.0, math.pi / 2, 0.0),
                                 length=0.425),
        "forearm": SensorMount(link="forearm_link", frame=3, xyz=(0.0, 0.0, 0.01615), rpy=(0.0, math.pi / 2, 0.0),
                               length=0.39225),
    },
    workspace_low=(-0.4, 0.3, 0.2),
    workspace_high=(0.4, 0.7, 0.5),
    blind_links=("forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link"),
)
