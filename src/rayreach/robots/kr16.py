"""KUKA KR16-2 from the ``rtb-data`` package (ROS-Industrial's kuka_kr16_support model)."""

from __future__ import annotations

import math
from pathlib import Path

from rayreach.robots.spec import DHTable, RobotSpec, SensorMount, ToolSpec


def _kr16_dir() -> Path:
    try:
        import rtbdata
    except ImportError as exc:
        raise FileNotFoundError("rtb-data is not installed; pip install rtb-data") from exc
    return Path(rtbdata.__file__).parent / "xacro" / "kuka_description" / "kuka_kr16"


KR16 = RobotSpec(
    name="kr16",
    urdf=lambda: _kr16_dir() / "urdf" / "kr16_2.urdf",
    package_dirs=lambda: {"kuka_kr16_support": _kr16_dir()},
    joint_names=("joint_a1", "joint_a2", "joint_a3", "joint_a4", "joint_a5", "joint_a6"),
    lower=(-3.22885911619, -2.70526034059, -2.26892802759, -6.10865238198, -2.26892802759, -6.10865238198),
    upper=(3.22885911619, 0.610865238198, 2.68780704807, 6.10865238198, 2.26892802759, 6.10865238198),
    velocity=(2.72271363311, 2.72271363311, 2.72271363311, 5.75958653158, 5.75958653158, 10.7337748998),
    flange_link="tool0",
    # Derived from the URDF's joint origins (0.675, 0.26, 0.68, 0.67/-0.035, 0.158).
    # Joints a1, a4 and a6 turn about -x/-z of their URDF frames, hence sign -1; a3's
    # DH x axis points along the link's -z, hence the +pi/2 offset. DH frame 0 = base_link.
    dh=DHTable(
        d=(0.675, 0.0, 0.0, 0.67, 0.0, 0.158),
        a=(0.26, 0.68, 0.035, 0.0, 0.0, 0.0),
        alpha=(-math.pi / 2, 0.0, math.pi / 2, -math.pi / 2, math.pi / 2, 0.0),
        offset=(0.0, 0.0, math.pi / 2, 0.0, 0.0, 0.0),
        sign=(-1.0, 1.0, 1.0, -1.0, 1.0, -1.0),
    ),
    dh_base_rpy=(0.0, 0.0, 0.0),
    tool=ToolSpec(length=0.2, radius=0.03),
    home=(0.0, -2 * math.pi / 3, 2 * math.pi / 3, 0.0, math.pi / 6, 0.0),
    base_position=(0.0, -1.0, 0.0),
    base_rpy=(0.0, 0.0, math.pi / 2),
    mounts={
        "wrist": SensorMount(link="link_6", frame=6, xyz=(0.0, 0.0, -0.16)),
        "tool": SensorMount(link="rayreach_tool", frame=6),
        # the upper arm runs along -x of DH frame 2 from the elbow, its tube 0.15 m beside the
        # joint axes (the mesh's, measured); the forearm along the a4 axis from the elbow to the
        # wrist, through link_3 and then link_4, which turns about that axis
        "upper_arm": SensorMount(link="link_2", frame=2, xyz=(0.0, 0.0, -0.15), rpy=(0.0, -math.pi / 2, 0.0),
                                 length=0.68),
        "forearm": SensorMount(link="link_3", frame=3, length=0.67),
    },
    workspace_low=(-0.8, -0.4, 0.4),
    workspace_high=(0.8, 0.8, 1.8),
    training_kinds=("shelf", "shelf", "shelf", "plate", "box", "sphere", "goal_wall"),  # the shelf in 3 of 7 draws
    task_obstacles=1,
    tool_rpy=(math.pi, math.pi / 3.0, -math.pi / 2.0),  # the home pose: tool 30 deg below horizontal, +y
    blind_links=("link_4", "link_5", "link_6"),
)
