"""Universal Robots UR10 from the ``example-robot-data`` package, defined by its URDF alone.

No DH table: the kinematics come from the URDF's joint origins and axes
(``rayreach.robots.chain``). What a spec adds to the URDF is the tool, the sensor mounts, a
home configuration and the training workspace.
"""

from __future__ import annotations

from rayreach.robots.spec import RobotSpec, SensorMount, ToolSpec
from rayreach.robots.ur5 import UR5, _share_dir

UR10 = RobotSpec(
    name="ur10",
    urdf=lambda: _share_dir() / "robots" / "ur_description" / "urdf" / "ur10_robot.urdf",
    package_dirs=UR5.package_dirs,
    joint_names=UR5.joint_names,
    lower=UR5.lower,
    upper=UR5.upper,
    velocity=(2.16, 2.16, 3.15, 3.2, 3.2, 3.2),
    base_link="base_link",
    flange_link="tool0",
    tool=ToolSpec(length=0.13, radius=0.02),
    home=(1.3562, -0.7802, 1.9909, -2.7815, -1.5708, -3.3561),  # tool down over the workspace centre
    base_position=(0.0, -0.12, 0.6),
    mounts={
        "wrist": SensorMount(link="wrist_3_link", frame=6, xyz=(0.0, 0.0, -0.1)),
        "tool": SensorMount(link="rayreach_tool", frame=6),
        # the URDF's link frames: z runs from the joint up each tube to the next joint
        "upper_arm": SensorMount(link="upper_arm_link", frame=2, length=0.612),
        "forearm": SensorMount(link="forearm_link", frame=3, length=0.5723),
    },
    workspace_low=(-0.5, 0.4, 0.2),
    workspace_high=(0.5, 0.9, 0.6),
    blind_links=UR5.blind_links,
)
